-- (obj(O, cup, _)^Z ; seg(O, _)^Z), Z =< 11
-- at: None
SELECT 0 AS b, t0.arg1 AS v0, t0.t_start AS v1, 0 AS k0, t0.t_end AS k1, t0.t_start AS k2, t0.seq AS k3 FROM "obj" AS t0 WHERE t0.arg2 = :c0 AND t0.t_start = t0.t_end AND t0.t_start <= :c1
UNION ALL
SELECT 1 AS b, t1.arg1 AS v0, t1.t_start AS v1, 1 AS k0, t1.t_end AS k1, t1.t_start AS k2, t1.seq AS k3 FROM "seg" AS t1 WHERE t1.t_start = t1.t_end AND t1.t_start <= :c1
ORDER BY k0, k1, k2, k3;
-- parameters: :c0 = 'cup', :c1 = 11
