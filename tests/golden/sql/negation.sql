-- obj(O, T, _)^Z, \+ usedFor(T, tea), Z > 10.5
-- at: None
SELECT 0 AS b, t0.arg1 AS v0, t0.arg2 AS v1, t0.t_start AS v2, t0.t_end AS k0, t0.t_start AS k1, t0.seq AS k2 FROM "obj" AS t0 WHERE t0.t_start = t0.t_end AND NOT EXISTS (SELECT 1 WHERE t0.arg2 = :c0) AND t0.t_start > :c3
ORDER BY k0, k1, k2;
-- parameters: :c0 = 'cup', :c1 = 'mug', :c2 = 'glass', :c3 = 10.5
