-- slr_sql schema, version 11: nothing to change on SQLite. Its counterpart on PostgreSQL
-- (pg_0011_pending_notify.sql) notifies the other sessions when the event rules' pending
-- rows change; on SQLite they see it through PRAGMA data_version, which costs no I/O.
SELECT 1;
