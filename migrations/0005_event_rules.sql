-- slr_sql schema, version 5: event rules (complex event processing). See docs/events.md.
-- Per rule, slr_sql.cep also creates slr_cep_m_<key> (one row per complex event derived:
-- the rule's alternative, the rowids of its constituent events r1..rN, its interval and head
-- arguments h1..hN, and when it was detected) and, for chronological rules, slr_cep_u_<key>
-- (the rows already used).

-- Every event rule installed in this file (key: a hash of the rule's text and policy).
CREATE TABLE slr_cep_rules (
    key          TEXT PRIMARY KEY,
    head         TEXT NOT NULL,      -- name/arity of the complex event type
    rule         TEXT NOT NULL,      -- the rule, as text
    policy       TEXT NOT NULL CHECK (policy IN ('unrestricted', 'recent', 'chronological')),
    source       TEXT,               -- file:line
    prov_table   TEXT NOT NULL,
    installed_at REAL
);

-- Candidate matches and terminating events whose decision waits for completeness
-- (a negated type, a where goal reading the store, or a consumption policy). A row is
-- deleted in the transaction that decides it.
--   kind      'match': a whole match (rowids of every position) waiting for cnot/where;
--             'term': a row at position pos that may end a match of a recent or
--             chronological rule (rowids = [its rowid])
--   wait_*    the history the decision waits for, when known (NULL: the rule's inputs, or
--             its negated types, up to t_end)
CREATE TABLE slr_cep_pending (
    id          INTEGER PRIMARY KEY,
    rule        TEXT NOT NULL,
    alt         INTEGER NOT NULL,
    kind        TEXT NOT NULL CHECK (kind IN ('match', 'term')),
    pos         INTEGER,
    rowids      TEXT NOT NULL,
    t_start     REAL NOT NULL,
    t_end       REAL NOT NULL,
    wait_type   TEXT,
    wait_arity  INTEGER,
    wait_time   REAL,
    wait_reason TEXT,
    created_at  REAL
);
CREATE INDEX slr_cep_pending_by_rule ON slr_cep_pending (rule, t_end, t_start);
