-- slr_sql schema, version 8: nothing to change on SQLite. Its counterpart on PostgreSQL
-- (pg_0008_buffers.sql) adds the JSON helpers the buffers' trigger functions call; SQLite's
-- triggers use its own json_* functions.
SELECT 1;
