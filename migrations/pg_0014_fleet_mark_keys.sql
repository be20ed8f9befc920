-- slr_sql PostgreSQL schema, version 14: unambiguous keys of the marks a fleet store keeps
-- per robot (the counterpart of 0014_fleet_mark_keys.sql, which says why and how; the same
-- rule as slr_sql.store.schema.old_fleet_mark_reading, here in PL/pgSQL).
-- fleet/mark/R/p/N becomes fleet/mark/E/p/N, E being R with '%' as %25 and '/' as %2F; a key
-- of more than three '/'-separated segments after fleet/mark/ is read as the mark of the one
-- known robot it can start with, and dropped when several or none can.
DO $$
DECLARE
    m RECORD;
    segments TEXT[];
    n INTEGER;
    k INTEGER;
    hits INTEGER;
    who TEXT;
    mark TEXT;
    candidate TEXT;
    new_key TEXT;
    known TEXT[];
    old_keys TEXT[] := '{}';
    new_keys TEXT[] := '{}';
    new_values TEXT[] := '{}';
BEGIN
    known := ARRAY(SELECT name FROM slr_robots UNION SELECT robot FROM slr_fleet_robots
                   UNION SELECT robot FROM slr_fleet_routes UNION SELECT via FROM slr_fleet_routes
                   UNION SELECT value::jsonb #>> '{}' FROM slr_meta
                         WHERE key = 'robot' AND jsonb_typeof(value::jsonb) = 'string');
    FOR m IN SELECT key, value FROM slr_meta WHERE substr(key, 1, 11) = 'fleet/mark/' LOOP
        segments := string_to_array(substr(m.key, 12), '/');
        n := coalesce(cardinality(segments), 0);
        who := NULL;
        IF n >= 3 AND (segments[n] = '*' OR segments[n] ~ '^[0-9]+$') THEN
            IF n = 3 THEN
                who := segments[1];
                mark := segments[2] || '/' || segments[3];
            ELSE
                hits := 0;
                FOR k IN 1 .. n - 2 LOOP
                    candidate := array_to_string(segments[1:k], '/');
                    IF candidate = ANY (known) THEN
                        hits := hits + 1;
                        who := candidate;
                        mark := array_to_string(segments[k + 1:n], '/');
                    END IF;
                END LOOP;
                IF hits <> 1 THEN
                    who := NULL;
                END IF;
            END IF;
        END IF;
        IF who IS NULL THEN
            new_key := NULL;
        ELSE
            new_key := 'fleet/mark/' || replace(replace(who, '%', '%25'), '/', '%2F') || '/' || mark;
        END IF;
        IF new_key IS DISTINCT FROM m.key THEN
            old_keys := old_keys || m.key;
            IF new_key IS NOT NULL THEN
                new_keys := new_keys || new_key;
                new_values := new_values || m.value::text;
            END IF;
        END IF;
    END LOOP;
    -- every old key out first: a new key may be the old key of another mark
    DELETE FROM slr_meta WHERE key = ANY (old_keys);
    INSERT INTO slr_meta (key, value) SELECT * FROM unnest(new_keys, new_values);
END $$;
