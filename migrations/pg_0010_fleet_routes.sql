-- slr_sql PostgreSQL schema, version 10: one route per robot into a fleet store (the
-- counterpart of 0010_fleet_routes.sql; see docs/fleet.md, "One route per robot").
-- Per robot whose rows this store holds from shipments: the one shipping robot they come
-- through (the robot itself, or the store relaying them), and the rows stored of it that way.
CREATE TABLE slr_fleet_routes (
    robot   TEXT PRIMARY KEY,
    via     TEXT NOT NULL,
    shipped BIGINT NOT NULL DEFAULT 0
);

-- The robots that shipped rows here before: their own rows came directly.
INSERT INTO slr_fleet_routes (robot, via) SELECT robot, robot FROM slr_fleet_robots
    WHERE shipped > 0;
