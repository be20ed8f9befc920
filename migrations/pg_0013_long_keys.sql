-- slr_sql PostgreSQL schema, version 13: values of any length in indexed positions (the
-- counterpart of 0013_long_keys.sql, which changes nothing: SQLite's B-tree keys have no
-- length limit). A B-tree entry of PostgreSQL holds at most ~2,704 bytes, so a text that
-- users choose (an event's data argument, an event type's name, a durable subscription's
-- id, a program's name, a completeness mark naming a type) is no longer
-- a B-tree key as it is: a B-tree holds slr_key(text) instead, and a statement that
-- searches it compares slr_key(column) = slr_key(value) AND column = value (the exact
-- comparison decides; docs/postgres.md, "Long values").

-- A text of fewer than 64 characters as it is; a longer one as the SHA-256 of its UTF-8
-- bytes in 64 hex digits (at most 252 bytes either way). The two kinds cannot meet (64
-- characters against fewer), so two texts have one slr_key only if they are equal or their
-- SHA-256 collide: a unique index on slr_key(column) is as exact as one on the column.
-- Built-in immutable functions only, named without a schema: the server inlines the body
-- (a query's slr_key(column) then matches the index's), and CREATE INDEX runs it with
-- search_path = pg_catalog. decode(.., 'escape') of the text with its backslashes doubled
-- is its bytes (convert_to would be the same, but is not immutable).
CREATE FUNCTION slr_key(v TEXT) RETURNS TEXT LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT CASE WHEN char_length(v) < 64 THEN v
                ELSE encode(sha256(decode(replace(v, '\', '\\'), 'escape')), 'hex') END
$$;

-- Event tables (and complex event types' tables): every B-tree index over data arguments
-- (the store's (arg1, t_end, t_start) and (arg1, t_start, t_end), the event rules'
-- slr_cep_ix__ ones) is made again over slr_key(argN).
DO $$
DECLARE
    ix RECORD;
    head TEXT;
BEGIN
    FOR ix IN
        SELECT i.indexrelid::regclass AS name, pg_get_indexdef(i.indexrelid) AS def
        FROM pg_index i
        JOIN pg_class t ON t.oid = i.indrelid
        WHERE t.relnamespace = (SELECT oid FROM pg_namespace WHERE nspname = current_schema())
          AND t.relname IN (SELECT table_name FROM slr_event_types)
          AND pg_get_indexdef(i.indexrelid) ~ 'USING btree \((arg[0-9]+[,)]|.*, arg[0-9]+[,)])'
    LOOP
        head := substr(ix.def, 1, strpos(ix.def, ' USING btree (') + 13);
        EXECUTE 'DROP INDEX ' || ix.name::text;
        EXECUTE head || regexp_replace(substr(ix.def, length(head) + 1),
                                       '(^|, )(arg[0-9]+)(?=[,)])', '\1slr_key(\2)', 'g');
    END LOOP;
END $$;

-- The catalog: unique keys over slr_key(column), and a hash index (read by =, entries of 4
-- bytes) where statements look a row up by the text.
ALTER TABLE slr_meta DROP CONSTRAINT slr_meta_pkey;
ALTER TABLE slr_meta ALTER COLUMN key SET NOT NULL;
CREATE UNIQUE INDEX slr_meta_key ON slr_meta (slr_key(key));
CREATE INDEX slr_meta_by_key ON slr_meta USING hash (key);

ALTER TABLE slr_event_types DROP CONSTRAINT slr_event_types_pkey;
CREATE UNIQUE INDEX slr_event_types_key ON slr_event_types (slr_key(name), arity);
CREATE INDEX slr_event_types_by_name ON slr_event_types USING hash (name);

DROP INDEX slr_buffers_by_type;
CREATE INDEX slr_buffers_by_type ON slr_buffers USING hash (type_name) WHERE removed_at IS NULL;

ALTER TABLE slr_subscriptions DROP CONSTRAINT slr_subscriptions_pkey;
ALTER TABLE slr_subscriptions ALTER COLUMN id SET NOT NULL;
CREATE UNIQUE INDEX slr_subscriptions_key ON slr_subscriptions (slr_key(id));
CREATE INDEX slr_subscriptions_by_id ON slr_subscriptions USING hash (id);
DROP INDEX slr_subscriptions_by_type;
CREATE INDEX slr_subscriptions_by_type ON slr_subscriptions USING hash (type_name);

DROP INDEX slr_program_by_name;
CREATE INDEX slr_program_by_name ON slr_program USING hash (name);

-- (a robot's name has at most 255 characters, a key of its own; the type's name is not)
ALTER TABLE slr_fleet_positions DROP CONSTRAINT slr_fleet_positions_pkey;
ALTER TABLE slr_fleet_positions ALTER COLUMN robot SET NOT NULL;
ALTER TABLE slr_fleet_positions ALTER COLUMN type_name SET NOT NULL;
CREATE UNIQUE INDEX slr_fleet_positions_key
    ON slr_fleet_positions (robot, slr_key(type_name), type_arity);
