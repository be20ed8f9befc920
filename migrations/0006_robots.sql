-- slr_sql schema, version 6: robots and fleets (SPEC §10, see docs/fleet.md).
-- A statement naming {event_table} runs once per event table of slr_event_types, with the
-- quoted table name in its place (the runner does this: SQL has no loop over tables).

-- The robot that observed or derived each event: the store's name (slr_meta key 'robot')
-- for events added to a named store, the shipping robot's name for events shipped to a
-- fleet store, NULL for events of a store that has no name.
ALTER TABLE {event_table} ADD COLUMN robot TEXT;

-- Every robot whose events a store holds, in name order for origin/2 with an unbound robot:
-- the store's own name, and each robot that shipped to it.
CREATE TABLE slr_robots (
    name TEXT PRIMARY KEY
) WITHOUT ROWID;

-- Fleet shipping: per robot and event type, the greatest sequence (seq in the robot's own
-- store) shipped; a batch's rows and its position commit in one transaction, so a batch
-- is stored exactly once whichever side is killed.
CREATE TABLE slr_fleet_positions (
    robot      TEXT NOT NULL,
    type_name  TEXT NOT NULL,
    type_arity INTEGER NOT NULL,
    position   INTEGER NOT NULL,
    PRIMARY KEY (robot, type_name, type_arity)
) WITHOUT ROWID;

-- Per robot that shipped to this store:
--   shipped        events (incoming and complex) stored here from it
--   last_arrival   the robot's arrival time of the latest event stored here from it
--   pending        events its store held that were not shipped yet, at the last contact
--   head_arrival   the robot's arrival time of its latest event, at the last contact
--   contact_at     wall-clock time (seconds since the epoch) of the last contact
CREATE TABLE slr_fleet_robots (
    robot        TEXT PRIMARY KEY,
    shipped      INTEGER NOT NULL DEFAULT 0,
    last_arrival REAL,
    pending      INTEGER NOT NULL DEFAULT 0,
    head_arrival REAL,
    contact_at   REAL
) WITHOUT ROWID;
