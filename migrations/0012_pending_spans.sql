-- slr_sql schema, version 12: a pending decision may be a span of terminators.
-- An add whose new terminators are none of them complete yet (a live stream: the clock has
-- not passed them) keeps them as one row of kind 'span' -- their first and last seq and
-- their count in rowids, their latest end in t_start, their earliest in t_end -- instead of
-- one row each (docs/events.md, "Pending decisions"). SQLite cannot change a CHECK in
-- place: the table is made again with the same columns and index.
CREATE TABLE slr_cep_pending_v12 (
    id          INTEGER PRIMARY KEY,
    rule        TEXT NOT NULL,
    alt         INTEGER NOT NULL,
    kind        TEXT NOT NULL CHECK (kind IN ('match', 'term', 'span')),
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
INSERT INTO slr_cep_pending_v12 (id, rule, alt, kind, pos, rowids, t_start, t_end, wait_type,
                                 wait_arity, wait_time, wait_reason, created_at)
    SELECT id, rule, alt, kind, pos, rowids, t_start, t_end, wait_type, wait_arity, wait_time,
           wait_reason, created_at FROM slr_cep_pending;
DROP TABLE slr_cep_pending;
-- (legacy renaming: a view or another table's trigger naming slr_cep_pending -- one of
-- yours -- would fail the rename, the name not existing between the drop and the rename,
-- as migration 0007 found; it names the new table once renamed)
PRAGMA legacy_alter_table = ON;
ALTER TABLE slr_cep_pending_v12 RENAME TO slr_cep_pending;
PRAGMA legacy_alter_table = OFF;
CREATE INDEX slr_cep_pending_by_rule ON slr_cep_pending (rule, t_end, t_start);
