-- slr_sql schema, version 15: robots retired from a fleet store (docs/fleet.md, "Retiring a
-- robot"; the counterpart of pg_0015_fleet_retired.sql).
-- The fleet store's own mark of a type is the least of the marks of the robots it knows, and
-- a robot that goes quiet does not stop counting: a robot scrapped or renamed would hold the
-- fleet's marks back for good. `slr fleet retire FLEET ROBOT` writes a row here: the marks
-- stop waiting for the robot (its events and marks stay), and shipments of it are refused
-- until `slr fleet reinstate FLEET ROBOT` deletes the row.
--   robot       the retired robot's name
--   retired_at  wall-clock time (seconds since the epoch) of the retirement
CREATE TABLE slr_fleet_retired (
    robot      TEXT PRIMARY KEY,
    retired_at REAL NOT NULL
) WITHOUT ROWID;
