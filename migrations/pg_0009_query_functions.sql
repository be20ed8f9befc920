-- Functions the compiled queries call on PostgreSQL (slr_sql/store/query_printers.py): the
-- counterparts of the Python functions SQLite's compiled statements call, where SQL can
-- compute the same value exactly. What would need Python (Prolog arithmetic beyond
-- comparisons, det builtins, the aggregates) is answered by the interpreter instead.

-- A float as Python's repr writes it (the column text of to_column). PostgreSQL prints the
-- same shortest digits, except: exponent form from 1e15 on (Python from 1e16), all the
-- digits of an integral value below 1e17, and no '.0' on integral values.
CREATE FUNCTION slr_float_text(f DOUBLE PRECISION) RETURNS TEXT LANGUAGE plpgsql IMMUTABLE PARALLEL SAFE AS $$
DECLARE
    t TEXT;
    n NUMERIC;
    c NUMERIC;
    d TEXT;
BEGIN
    IF f IS NULL THEN
        RETURN NULL;
    ELSIF f = 'Infinity'::float8 THEN
        RETURN 'inf';
    ELSIF f = '-Infinity'::float8 THEN
        RETURN '-inf';
    ELSIF f <> f THEN
        RETURN 'nan';
    ELSIF abs(f) >= 1e16 AND abs(f) < 1e17 THEN
        -- the shortest digits that read back as f: the nearest value of p digits, p = 1..17
        n := f::text::numeric;
        FOR p IN 1..17 LOOP
            c := round(n, p - 17);
            EXIT WHEN c::float8 = f;
        END LOOP;
        d := rtrim(abs(c)::text, '0');
        RETURN CASE WHEN c < 0 THEN '-' ELSE '' END || left(d, 1)
               || CASE WHEN length(d) > 1 THEN '.' || substr(d, 2) ELSE '' END || 'e+16';
    END IF;
    t := CASE WHEN abs(f) >= 1e15 AND abs(f) < 1e16 THEN f::text::numeric::text
              ELSE f::text END;
    RETURN CASE WHEN t ~ '[.e]' THEN t ELSE t || '.0' END;
END
$$;

-- A float inside JSON (encode_json): its repr, infinities as 1e999 and -1e999.
CREATE FUNCTION slr_float_json(f DOUBLE PRECISION) RETURNS TEXT LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT CASE WHEN f = 'Infinity'::float8 THEN '1e999'
                WHEN f = '-Infinity'::float8 THEN '-1e999'
                ELSE slr_float_text(f) END
$$;

-- slr_j: a stored value's encoding inside JSON (a list element, a compound argument).
CREATE FUNCTION slr_j(v TEXT) RETURNS TEXT LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT CASE WHEN v IS NULL THEN NULL
                WHEN left(v, 10) = '{"$atom":"' THEN ((v::json) -> '$atom')::text
                WHEN left(v, 1) IN ('[', '{') THEN v
                WHEN left(v, 1) = '"' THEN '{"$string":' || v || '}'
                WHEN v = 'inf' THEN '1e999'
                WHEN v = '-inf' THEN '-1e999'
                WHEN slr_typeof(v) IN ('integer', 'real') THEN v
                ELSE to_json(v)::text END
$$;

-- slr_num: a stored value used as a number; anything else is an error (the query is then
-- answered by the interpreter, which raises Prolog's type error or answers).
CREATE FUNCTION slr_num(v TEXT) RETURNS NUMERIC LANGUAGE plpgsql IMMUTABLE PARALLEL SAFE AS $$
BEGIN
    IF v = 'inf' THEN
        RETURN 'Infinity'::numeric;
    ELSIF v = '-inf' THEN
        RETURN '-Infinity'::numeric;
    ELSIF slr_typeof(v) IN ('integer', 'real') THEN
        RETURN v::numeric;
    END IF;
    RAISE EXCEPTION 'slr_num: not a number: %', v USING ERRCODE = '22023';
END
$$;
