-- slr_sql PostgreSQL schema, version 15: robots retired from a fleet store (the counterpart
-- of 0015_fleet_retired.sql, which says why; docs/fleet.md, "Retiring a robot").
CREATE TABLE slr_fleet_retired (
    robot      TEXT PRIMARY KEY,
    retired_at DOUBLE PRECISION NOT NULL
);
