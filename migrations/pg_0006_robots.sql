-- slr_sql PostgreSQL schema, version 6: robots and fleets (the counterpart of 0006_robots.sql;
-- see docs/fleet.md). Event tables get their robot column when they are created.

-- The robot column of every event table that exists already (tables created later have it).
DO $$
DECLARE t TEXT;
BEGIN
    FOR t IN SELECT table_name FROM slr_event_types LOOP
        EXECUTE format('ALTER TABLE %I ADD COLUMN IF NOT EXISTS robot TEXT', t);
    END LOOP;
END $$;

-- Every robot whose events the store holds, in name order for origin/2.
CREATE TABLE slr_robots (
    name TEXT PRIMARY KEY
);

-- Fleet shipping: per robot and event type, the greatest sequence (seq in the robot's own
-- store) stored here; moved in the transaction that stores a batch.
CREATE TABLE slr_fleet_positions (
    robot      TEXT NOT NULL,
    type_name  TEXT NOT NULL,
    type_arity INTEGER NOT NULL,
    position   BIGINT NOT NULL,
    PRIMARY KEY (robot, type_name, type_arity)
);

-- Per robot that shipped here: events stored from it, the robot's arrival time of the latest
-- of them, and what its pusher reported at its last contact.
CREATE TABLE slr_fleet_robots (
    robot        TEXT PRIMARY KEY,
    shipped      BIGINT NOT NULL DEFAULT 0,
    last_arrival DOUBLE PRECISION,
    pending      BIGINT NOT NULL DEFAULT 0,
    head_arrival DOUBLE PRECISION,
    contact_at   DOUBLE PRECISION
);
