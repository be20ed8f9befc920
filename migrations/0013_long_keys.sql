-- slr_sql schema, version 13 (the counterpart of pg_0013_long_keys.sql): nothing to change.
-- SQLite's B-tree keys have no length limit; PostgreSQL's indexes over texts that users
-- choose (event arguments, type names, subscription ids, program names) are made over a
-- bounded form of the text there.
SELECT 1;
