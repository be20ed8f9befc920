-- findall(O, (obj(O, Type, _)^_, usedFor(Type, coffee)), L)
-- at: 14
SELECT 0 AS b, (SELECT '[' || coalesce(group_concat(v0, ','), '') || ']' FROM (SELECT slr_j(t0.arg1) AS v0, t0.t_end AS k0, t0.t_start AS k1, t0.seq AS k2, 1 AS k3 FROM "obj" AS t0 WHERE t0.t_start = t0.t_end AND t0.t_end <= :at AND t0.arg2 = :c0 UNION ALL SELECT slr_j(t0.arg1) AS v0, t0.t_end AS k0, t0.t_start AS k1, t0.seq AS k2, 2 AS k3 FROM "obj" AS t0 WHERE t0.t_start = t0.t_end AND t0.t_end <= :at AND t0.arg2 = :c1 ORDER BY k0, k1, k2, k3)) AS v0;
-- parameters: :c0 = 'cup', :c1 = 'mug', :c2 = 'glass'
