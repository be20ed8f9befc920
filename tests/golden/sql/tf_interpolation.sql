-- tf(cam, base, TF)^10.5
-- at: None
SELECT 0 AS b, t0.arg3 AS v0, 0 AS k0, t0.t_end AS k1, t0.t_start AS k2, t0.seq AS k3, NULL AS k4 FROM "tf" AS t0 WHERE t0.arg1 = :c0 AND t0.arg2 = :c1 AND t0.t_start = :c2 AND t0.t_end = :c2
UNION ALL
SELECT 1 AS b, slr_det(#, 0, p2.arg3, p2.t_start, p4.arg3, p4.t_start) AS v0, 1 AS k0, p2.t_start AS k1, p2.seq AS k2, p4.t_end AS k3, p4.seq AS k4 FROM "tf" AS p2 CROSS JOIN "tf" AS p4 WHERE p2.arg1 = :c0 AND p2.arg2 = :c1 AND p2.t_start = p2.t_end AND p2.t_end = (SELECT q1.t_end FROM "tf" AS q1 WHERE q1.arg1 = :c0 AND q1.arg2 = :c1 AND q1.t_start = q1.t_end AND q1.t_end <= :c2 ORDER BY q1.t_end DESC LIMIT 1) AND p4.arg1 = :c0 AND p4.arg2 = :c1 AND p4.t_start = p4.t_end AND p4.t_start = (SELECT q3.t_start FROM "tf" AS q3 WHERE q3.arg1 = :c0 AND q3.arg2 = :c1 AND q3.t_start = q3.t_end AND q3.t_start >= :c2 AND q3.t_start <= :c3 AND q3.t_end <= :c3 ORDER BY q3.t_start LIMIT 1) AND p4.t_end <= :c3 AND slr_det(#, -1, p2.arg3, p2.t_start, p4.arg3, p4.t_start) IS NOT NULL
ORDER BY k0, k1, k2, k3, k4;
-- parameters: :c0 = 'cam', :c1 = 'base', :c2 = 10.5, :c3 = inf
