-- slr_sql PostgreSQL schema, version 11: the event rules' pending rows tell other sessions
-- when they change (docs/events.md, "Several processes").
-- A process may store decisions pending (their inputs' histories not complete yet) and
-- stop; another process's rules decide them once its clock or its events complete them,
-- if it knows they are there. SQLite's PRAGMA data_version tells it without I/O; here
-- each statement that inserts or updates pending rows (one row or more) notifies channel
-- slr_pending with the store's schema (one notification per transaction and schema: the
-- server folds equal ones), and each store connection LISTENs: its check reads what its
-- socket holds, no round trip. (Deletes are decisions made: a session that missed one at most looks again
-- for a decision that is gone.)
CREATE FUNCTION slr_cep_pending_notify() RETURNS trigger LANGUAGE plpgsql AS $$
BEGIN
    -- (a statement that changed no row, as most of the rules' inserts: nothing to tell)
    IF EXISTS (SELECT 1 FROM slr_changed_rows) THEN
        PERFORM pg_notify('slr_pending', TG_TABLE_SCHEMA);
    END IF;
    RETURN NULL;
END
$$;

-- (a trigger with a transition table has one event)
CREATE TRIGGER slr_cep_pending_inserted AFTER INSERT ON slr_cep_pending
    REFERENCING NEW TABLE AS slr_changed_rows
    FOR EACH STATEMENT EXECUTE FUNCTION slr_cep_pending_notify();
CREATE TRIGGER slr_cep_pending_updated AFTER UPDATE ON slr_cep_pending
    REFERENCING NEW TABLE AS slr_changed_rows
    FOR EACH STATEMENT EXECUTE FUNCTION slr_cep_pending_notify();
