-- color(cup1, C)^12.5
-- at: None
SELECT 0 AS b, p1.arg3 AS v0, 1 AS k0, p1.t_start AS k1, p1.seq AS k2 FROM "obj" AS p1 WHERE p1.arg1 = :c1 AND p1.t_start = p1.t_end AND p1.t_end = (SELECT q0.t_end FROM "obj" AS q0 WHERE q0.arg1 = :c1 AND q0.t_start = q0.t_end AND q0.t_end <= :c0 ORDER BY q0.t_end DESC LIMIT 1)
ORDER BY k0, k1, k2;
-- parameters: :c0 = 12.5, :c1 = 'cup1'
