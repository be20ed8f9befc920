-- slr_sql schema, version 2: event-history management (tBuffer / cBuffer / runtime policies).
-- See docs/buffers.md. The per-buffer triggers (slr_buf_<id>_*) and indexes (slr_bix_<id>)
-- are created by slr_sql.buffers from the rows of slr_buffers.

-- Every buffer ever installed. Active buffers have removed_at NULL.
--   kind    tBuffer (keep while end >= now - amount), cBuffer (keep the last `amount` per key),
--           window (keep events whose occurrence [start, end] lies inside [t1, t2])
--   source  program (a tBuffer/cBuffer clause of the loaded program) or runtime (kb.add_buffer)
--   cutoff  tBuffer only: every matching row with t_end < cutoff has been removed already,
--           so time-driven pruning only scans t_end in [cutoff, now - amount).
CREATE TABLE slr_buffers (
    id           INTEGER PRIMARY KEY AUTOINCREMENT,
    kind         TEXT NOT NULL CHECK (kind IN ('tBuffer', 'cBuffer', 'window')),
    source       TEXT NOT NULL CHECK (source IN ('program', 'runtime')),
    pattern_text TEXT NOT NULL,
    type_name    TEXT NOT NULL,
    type_arity   INTEGER NOT NULL,
    amount       REAL,
    t1           REAL,
    t2           REAL,
    origin       TEXT NOT NULL,
    cutoff       REAL NOT NULL DEFAULT -9e999,
    created_at   REAL,
    removed_at   REAL
);
CREATE INDEX slr_buffers_by_type ON slr_buffers (type_name, type_arity) WHERE removed_at IS NULL;

-- Counters per buffer (kept after the buffer is removed):
--   pruned   rows deleted by the buffer after they were stored
--   dropped  events refused on arrival (late: already older than the buffer keeps; or, for
--            a window, outside [t1, t2])
CREATE TABLE slr_counters (
    buffer_id INTEGER PRIMARY KEY,
    pruned    INTEGER NOT NULL DEFAULT 0,
    dropped   INTEGER NOT NULL DEFAULT 0
);

-- The store clock's "now" as last recorded (on each add batch and each clock move). Triggers
-- read it; rows inserted by other tools through SQL are judged against this value.
CREATE TABLE slr_clock (
    id  INTEGER PRIMARY KEY CHECK (id = 1),
    now REAL NOT NULL
);
INSERT INTO slr_clock (id, now) VALUES (1, -9e999);

-- A clock that moves back (a reopen with an earlier clock): lower the tBuffer cutoffs so that
-- events the earlier "now" admits are still pruned later.
CREATE TRIGGER slr_clock_back AFTER UPDATE OF now ON slr_clock WHEN NEW.now < OLD.now
BEGIN
    UPDATE slr_buffers SET cutoff = NEW.now - amount
    WHERE kind = 'tBuffer' AND removed_at IS NULL AND cutoff > NEW.now - amount;
END;
