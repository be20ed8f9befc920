-- Version 9: nothing to change on SQLite. PostgreSQL's migration 9 installs the functions
-- its compiled queries call (pg_0009_query_functions.sql); SQLite's compiled queries call
-- Python functions that slr_sql registers on each connection (slr_sql/planner.py).
SELECT 1;
