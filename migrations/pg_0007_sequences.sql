-- slr_sql PostgreSQL schema, version 7 (the counterpart of 0007_sequences.sql): nothing to
-- change. An event table's seq is an identity column, whose sequence never hands a value out
-- twice, whatever rows are deleted; the SQLite stores needed AUTOINCREMENT for the same.
SELECT 1;
