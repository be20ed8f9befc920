-- slr_sql PostgreSQL schema, version 8: what the buffers' trigger functions call (the
-- counterpart of 0008_buffers.sql; see slr_sql/store/buffering.py and docs/buffers.md).
-- A buffer pattern looks inside compound arguments, stored as JSON text. These helpers read
-- it without ever raising: a value of another shape (or text that is not JSON, inserted by
-- another tool) reads as NULL, so the row does not match. Types are named as SQLite's
-- json_type names them ('integer' and 'real' from the number's spelling), so that the two
-- backends keep Prolog's 1 \= 1.0 inside compounds alike.

-- The JSON of a stored value: NULL unless it is JSON (a compound, list, string...). In
-- plpgsql, not SQL: the planner would fold the cast of a constant text inside a CASE arm
-- (and raise) even where the arm's condition is false.
DO $$
BEGIN
    IF current_setting('server_version_num')::int >= 160000 THEN
        EXECUTE $f$CREATE FUNCTION slr_json(v TEXT) RETURNS json LANGUAGE plpgsql IMMUTABLE
            PARALLEL SAFE AS $b$
            BEGIN
                IF left(v, 1) IN ('[', '{', '"') AND pg_input_is_valid(v, 'json') THEN
                    RETURN v::json;
                END IF;
                RETURN NULL;
            END $b$ $f$;
    ELSE
        EXECUTE $f$CREATE FUNCTION slr_json(v TEXT) RETURNS json LANGUAGE plpgsql IMMUTABLE
            PARALLEL SAFE AS $b$
            BEGIN
                IF left(v, 1) IN ('[', '{', '"') THEN RETURN v::json; END IF;
                RETURN NULL;
            EXCEPTION WHEN others THEN RETURN NULL;
            END $b$ $f$;
    END IF;
END $$;

-- SQLite's json_type of a JSON value: null, true, false, integer, real, text, array, object.
CREATE FUNCTION slr_json_type(x json) RETURNS TEXT LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT CASE json_typeof(x)
        WHEN 'number' THEN CASE WHEN (x #>> '{}') ~ '^-?[0-9]+$' THEN 'integer' ELSE 'real' END
        WHEN 'string' THEN 'text'
        WHEN 'boolean' THEN x #>> '{}'
        ELSE json_typeof(x) END
$$;

-- A JSON number as an exact number (NULL for anything else).
CREATE FUNCTION slr_json_number(x json) RETURNS NUMERIC LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT CASE WHEN json_typeof(x) = 'number' THEN (x #>> '{}')::numeric END
$$;

-- A JSON number as a float: 1e999 (how slr_sql writes infinity inside JSON) is infinity.
CREATE FUNCTION slr_json_float(x json) RETURNS DOUBLE PRECISION LANGUAGE sql IMMUTABLE
    PARALLEL SAFE AS $$
    SELECT CASE WHEN n IS NULL THEN NULL
                WHEN n > 1.7976931348623157e308 THEN 'Infinity'::float8
                WHEN n < -1.7976931348623157e308 THEN '-Infinity'::float8
                WHEN abs(n) < 4.9e-324 THEN 0.0::float8
                ELSE n::float8 END
    FROM (SELECT slr_json_number(x) AS n) AS number
$$;

-- The length of a JSON array (NULL for anything else).
CREATE FUNCTION slr_json_length(x json) RETURNS INTEGER LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT CASE WHEN json_typeof(x) = 'array' THEN json_array_length(x) END
$$;

-- Whether the stored value a (a whole column) is the same term as the JSON value x (inside
-- a compound): the two encodings of one term differ (an atom is plain text at the top and
-- a JSON string inside, a string is a JSON string at the top and {"$string": ...} inside).
CREATE FUNCTION slr_json_same(a TEXT, x json) RETURNS BOOLEAN LANGUAGE sql IMMUTABLE
    PARALLEL SAFE AS $$
    SELECT coalesce(CASE slr_typeof(a)
        WHEN 'integer' THEN slr_json_type(x) = 'integer' AND slr_json_number(x) = a::numeric
        WHEN 'real' THEN slr_json_type(x) = 'real' AND slr_json_float(x) = a::float8
        WHEN 'text' THEN CASE
            WHEN left(a, 1) = '"' AND slr_json(a) IS NOT NULL THEN
                slr_json_type(x -> '$string') = 'text'
                AND (x ->> '$string') = (slr_json(a) #>> '{}')
            WHEN left(a, 1) IN ('[', '{') AND slr_json(a) IS NOT NULL THEN CASE
                WHEN slr_json_type(slr_json(a) -> '$atom') = 'text' THEN
                    slr_json_type(x) = 'text' AND (x #>> '{}') = (slr_json(a) ->> '$atom')
                ELSE slr_json(a)::text = x::text END
            WHEN left(a, 1) IN ('[', '{', '"') THEN FALSE
            ELSE slr_json_type(x) = 'text' AND (x #>> '{}') = a END
        ELSE FALSE END, FALSE)
$$;
