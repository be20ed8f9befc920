-- aggregate_all(count, (obj(_, cup, _)^_), N)
-- at: 14
SELECT 0 AS b, (SELECT count(*) FROM (SELECT 1 FROM "obj" AS t0 WHERE t0.arg2 = :c0 AND t0.t_start = t0.t_end AND t0.t_end <= :at)) AS v0;
-- parameters: :c0 = 'cup'
