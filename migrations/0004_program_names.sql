-- slr_sql schema, version 4: named programs, and the version counters other processes watch.
-- (Numbered 0004 so that it does not clash with 0003, which another change adds; the runner
-- applies every script not applied yet, in number order, whatever the gaps.)

-- A program is the texts loaded under one name, in load order; the whole program is every
-- name's texts in the order of their ids. Texts stored before this migration are "main".
ALTER TABLE slr_program ADD COLUMN name TEXT NOT NULL DEFAULT 'main';
CREATE INDEX slr_program_by_name ON slr_program (name, id);

-- version/program counts the changes of slr_program (a knowledge base compares it with the
-- version its loaded program was built from, and re-reads the texts when it moved);
-- facts/version is the program version the slr_facts_* tables and the views were built for.
-- A store that already has texts starts at 1 with its fact tables not built for it yet.
INSERT INTO slr_meta (key, value)
    SELECT 'version/program', '1' WHERE EXISTS (SELECT 1 FROM slr_program);
