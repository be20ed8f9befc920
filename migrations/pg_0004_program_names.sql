-- slr_sql schema on PostgreSQL, version 4: named programs (as 0004_program_names.sql).
ALTER TABLE slr_program ADD COLUMN name TEXT NOT NULL DEFAULT 'main';
CREATE INDEX slr_program_by_name ON slr_program (name, id);
INSERT INTO slr_meta (key, value)
    SELECT 'version/program', '1' WHERE EXISTS (SELECT 1 FROM slr_program);
