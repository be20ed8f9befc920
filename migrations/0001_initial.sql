-- slr_sql schema, version 1.
-- Internal tables start with slr_; every other table is one event type (see slr_event_types).
-- Applied by slr_sql.store.EventStore on open, in one transaction, recorded in PRAGMA user_version.

-- Small persisted settings and state (learned delays, completeness marks, ...), values in JSON.
CREATE TABLE slr_meta (
    key   TEXT PRIMARY KEY,
    value TEXT
);

-- The loaded program, in load order: reopening the file reloads these sources.
CREATE TABLE slr_program (
    id        INTEGER PRIMARY KEY,
    source    TEXT NOT NULL,
    filename  TEXT,
    loaded_at REAL
);

-- Event type name/arity (arity = number of data arguments) -> the table holding its events.
-- declared = 1 when the program declared the type (:- event p/N.), 0 when it was created by
-- the first event of that type.
CREATE TABLE slr_event_types (
    name       TEXT NOT NULL,
    arity      INTEGER NOT NULL,
    table_name TEXT NOT NULL UNIQUE,
    declared   INTEGER NOT NULL DEFAULT 0,
    PRIMARY KEY (name, arity)
);
