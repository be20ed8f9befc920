-- slr_sql schema on PostgreSQL, version 3: subscriptions (as 0003_subscriptions.sql).
CREATE TABLE slr_subscriptions (
    id           TEXT PRIMARY KEY,
    durable      INTEGER NOT NULL,
    pattern      TEXT NOT NULL,
    where_goal   TEXT,
    since        DOUBLE PRECISION NOT NULL,
    until        DOUBLE PRECISION,
    type_name    TEXT NOT NULL,
    type_arity   INTEGER NOT NULL,
    history_top  BIGINT NOT NULL,
    history_pos  BIGINT NOT NULL DEFAULT 0,
    history_done INTEGER NOT NULL DEFAULT 0,
    live_start   BIGINT NOT NULL,
    live_pos     BIGINT NOT NULL,
    finished     INTEGER NOT NULL DEFAULT 0,
    owner        TEXT,
    lease_until  DOUBLE PRECISION,
    created_at   DOUBLE PRECISION
);
CREATE INDEX slr_subscriptions_by_type ON slr_subscriptions (type_name, type_arity);
