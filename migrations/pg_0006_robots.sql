-- slr_sql schema on PostgreSQL, version 6: robots and fleets (as 0006_robots.sql).
-- The robot column of every event table that exists already (new tables are created with it).
DO $$
DECLARE t TEXT;
BEGIN
    FOR t IN SELECT table_name FROM slr_event_types LOOP
        EXECUTE format('ALTER TABLE %I ADD COLUMN IF NOT EXISTS robot TEXT', t);
    END LOOP;
END $$;

CREATE TABLE slr_robots (
    name TEXT PRIMARY KEY
);

CREATE TABLE slr_fleet_positions (
    robot      TEXT NOT NULL,
    type_name  TEXT NOT NULL,
    type_arity INTEGER NOT NULL,
    position   BIGINT NOT NULL,
    PRIMARY KEY (robot, type_name, type_arity)
);

CREATE TABLE slr_fleet_robots (
    robot        TEXT PRIMARY KEY,
    shipped      BIGINT NOT NULL DEFAULT 0,
    last_arrival DOUBLE PRECISION,
    pending      BIGINT NOT NULL DEFAULT 0,
    head_arrival DOUBLE PRECISION,
    contact_at   DOUBLE PRECISION
);
