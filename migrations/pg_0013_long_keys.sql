-- slr_sql PostgreSQL schema, version 13: values of any length in indexed positions (the
-- counterpart of 0013_long_keys.sql, which changes nothing: SQLite's B-tree keys have no
-- length limit). A B-tree entry of PostgreSQL holds at most ~2,704 bytes, so a text that
-- users choose (an event's data argument, an event type's name, a durable subscription's
-- id, a program's name, a completeness mark naming a type) is no longer
-- a B-tree key as it is: a key of the catalog is a unique index over slr_key(text), an
-- index over data arguments holds the short texts as they are and the long ones' slr_key
-- (docs/postgres.md, "Long values").

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
-- slr_cep_ix__ ones) is made again as the key indexes of slr_sql/store/dialect.py: a
-- partial index over the rows whose texts have fewer than 64 characters, as it was, and
-- (over one text) one over slr_key of every row, named with _k after it. A short value is
-- still read from the index alone, its statistics kept; a join searches slr_key's
-- (docs/postgres.md, "Long values").
DO $$
DECLARE
    ix RECORD;
    columns TEXT[];
    keys TEXT[];
    rest TEXT[];
BEGIN
    FOR ix IN
        SELECT c.relname AS name, t.relname AS tbl,
               substring(pg_get_indexdef(i.indexrelid) FROM 'USING btree \((.*)\)$') AS cols
        FROM pg_index i
        JOIN pg_class t ON t.oid = i.indrelid
        JOIN pg_class c ON c.oid = i.indexrelid
        WHERE t.relnamespace = (SELECT oid FROM pg_namespace WHERE nspname = current_schema())
          AND t.relname IN (SELECT table_name FROM slr_event_types)
          AND i.indpred IS NULL
          AND pg_get_indexdef(i.indexrelid) ~ 'USING btree \((arg[0-9]+, .*)\)$'
    LOOP
        columns := string_to_array(ix.cols, ', ');
        keys := ARRAY(SELECT c FROM unnest(columns) AS c WHERE c ~ '^arg[0-9]+$');
        rest := ARRAY(SELECT c FROM unnest(columns) AS c WHERE c !~ '^arg[0-9]+$');
        IF cardinality(keys) + cardinality(rest) <> cardinality(columns)
           OR EXISTS (SELECT 1 FROM unnest(rest) AS c WHERE c !~ '^t_(start|end)$') THEN
            CONTINUE;   -- (an index the store did not make)
        END IF;
        EXECUTE format('DROP INDEX %I', ix.name);
        IF cardinality(keys) = 1 THEN
            EXECUTE format('CREATE INDEX %I ON %I (%s) WHERE char_length(%s) < 64',
                           ix.name, ix.tbl, ix.cols, keys[1]);
            EXECUTE format('CREATE INDEX %I ON %I (slr_key(%s), %s)',
                           ix.name || '_k', ix.tbl, keys[1], array_to_string(rest, ', '));
        ELSE
            EXECUTE format('CREATE INDEX %I ON %I (%s) WHERE %s', ix.name, ix.tbl, ix.cols,
                           (SELECT string_agg(format('char_length(%s) < 64', k), ' AND ')
                            FROM unnest(keys) AS k));
        END IF;
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
