-- slr_sql schema, version 3: subscriptions (see docs/subscriptions.md).
-- The per-type journals (slr_subj_<table>, filled by the AFTER INSERT trigger slr_subt_<table>)
-- are created by slr_sql.subscriptions while some row below subscribes to that type, and
-- dropped when none does.

-- Every open subscription (durable or not) and every durable one, open or not.
--   id            the durable id given by the user, or a generated one (durable = 0)
--   pattern, where_goal, since, until   what it delivers (until NULL: no end)
--   type_name, type_arity               the event type of the pattern
--   history_top   the type's greatest arrival sequence (seq) when it was created: its
--                 history is the stored events with seq <= history_top
--   history_pos   the last history seq passed (delivered and acknowledged, or not matching)
--   history_done  1 once every history event was passed
--   live_start    the journal position when it was created: live events are journal rows
--                 with jid > live_start
--   live_pos      the last journal jid passed (the journal keeps every row after the smallest
--                 live_pos of the rows subscribing to its type)
--   finished      1 once everything up to `until` was delivered
--   owner         host:pid:token of the process delivering it now, NULL when none
--   lease_until   wall-clock time (seconds since the epoch) until which the owner's claim holds;
--                 the owner renews it; an expired non-durable row is removed by any process
CREATE TABLE slr_subscriptions (
    id           TEXT PRIMARY KEY,
    durable      INTEGER NOT NULL,
    pattern      TEXT NOT NULL,
    where_goal   TEXT,
    since        REAL NOT NULL,
    until        REAL,
    type_name    TEXT NOT NULL,
    type_arity   INTEGER NOT NULL,
    history_top  INTEGER NOT NULL,
    history_pos  INTEGER NOT NULL DEFAULT 0,
    history_done INTEGER NOT NULL DEFAULT 0,
    live_start   INTEGER NOT NULL,
    live_pos     INTEGER NOT NULL,
    finished     INTEGER NOT NULL DEFAULT 0,
    owner        TEXT,
    lease_until  REAL,
    created_at   REAL
);
CREATE INDEX slr_subscriptions_by_type ON slr_subscriptions (type_name, type_arity);
