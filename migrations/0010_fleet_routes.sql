-- slr_sql schema, version 10: one route per robot into a fleet store (docs/fleet.md, "One
-- route per robot").
-- Per robot whose rows this store holds from shipments: the one shipping robot they come
-- through, and the rows stored of it that way. A fleet store keeps its positions per
-- shipping robot, so the rows of robot r1 coming both directly (via = r1) and relayed by a
-- site store (via = the site) would be stored twice: rows of a robot through any other route
-- than its first are refused.
--   robot    the robot of the rows (their robot column)
--   via      the robot that shipped them here: the robot itself, or the store relaying them
--   shipped  rows of the robot stored here through via (from this version on)
CREATE TABLE slr_fleet_routes (
    robot   TEXT PRIMARY KEY,
    via     TEXT NOT NULL,
    shipped INTEGER NOT NULL DEFAULT 0
) WITHOUT ROWID;

-- The robots that shipped rows here before: their own rows came directly (the rows they
-- relayed are recorded with their next shipment)
INSERT INTO slr_fleet_routes (robot, via) SELECT robot, robot FROM slr_fleet_robots
    WHERE shipped > 0;
