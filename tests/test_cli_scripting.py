"""`slr` in scripts: query --json/--limit, sql output formats, ingest from standard input and
its progress report, typo warnings. Real subprocesses on a real store file."""
from __future__ import annotations

import csv
import io
import json
import os
import sys
from pathlib import Path

import pexpect
import pytest
from conftest import copy_of_store
from test_cli import ROOT, slr

from slr_sql.service.encoding import decode_answers


@pytest.fixture(scope="module")
def prepared_store(tmp_path_factory) -> Path:
    """The store of ``store``, made once for the module by ``slr load`` and ``slr add``."""
    folder = tmp_path_factory.mktemp("scripting")
    db = str(folder / "robot.db")
    program = folder / "robot.slr"
    program.write_text("color(O, C)^T :- prev(obj(O, _, C)^_Z, T).\n", encoding="utf-8")
    assert slr("load", db, str(program)).returncode == 0
    r = slr("add", db, "obj(cup1, cup, red)^2.0", 'obj(cup2, "a cup", [1, 2.5])^3.0',
            "obj(cup1, cup, green)^9.0")
    assert r.returncode == 0, r.stderr
    return Path(db)


@pytest.fixture
def store(tmp_path, prepared_store) -> str:
    """A store of a rule and three events: the test's own copy of ``prepared_store``."""
    return copy_of_store(prepared_store, tmp_path)


# -- query --json / --limit ----------------------------------------------------------------

def test_query_json_prints_one_object_per_answer_in_the_service_encoding(store):
    r = slr("query", store, "obj(O, K, C)^T", "--json")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 3
    objects = [json.loads(line) for line in lines]
    assert objects[1] == {"O": "cup2", "K": {"$string": "a cup"}, "C": [1, 2.5], "T": 3.0}
    # the same decoder the service's clients use reads it back
    assert decode_answers(objects)[0]["C"] == "red"


def test_query_json_with_no_answer_prints_nothing(store):
    r = slr("query", store, "obj(nothing, K, C)^T", "--json")
    assert (r.returncode, r.stdout) == (0, "")


def test_query_limit_stops_an_endless_goal_at_once(store):
    r = slr("query", store, "between(1, inf, X)", "--limit", "3", timeout=30)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["X = 1", "X = 2", "X = 3"]


def test_query_limit_counts_answers_of_stored_events(store):
    r = slr("query", store, "obj(O, _, C)^T", "--limit", "2", "--json")
    assert [json.loads(line)["T"] for line in r.stdout.splitlines()] == [2.0, 3.0]


def test_query_timeout_prints_the_answers_found_then_the_timeout(store):
    r = slr("query", store, "between(1, inf, X)", "--timeout", "0.3")
    assert r.returncode == 1
    lines = r.stdout.splitlines()
    assert len(lines) > 10 and lines[:2] == ["X = 1", "X = 2"]
    assert lines[-1] == f"X = {len(lines)}"
    assert "timed out" in r.stderr and f"{len(lines)} answers printed before it" in r.stderr


# -- typos ---------------------------------------------------------------------------------

@pytest.mark.parametrize("goal, written, near", [
    ("colour(cup2, C)^20", "colour/2", "color/2"),
    ("color(cup2)^20", "color/1", "color/2"),
    ("prev(ojb(O, K, C)^Z, 5)", "ojb/3", "obj/3"),
])
def test_a_typo_warns_with_the_nearest_name_and_still_answers_false(store, goal, written, near):
    r = slr("query", store, goal)
    assert r.returncode == 0
    assert r.stdout == "false.\n"
    assert f"warning: no events or rules of {written}; did you mean {near}?" in r.stderr


def test_a_known_goal_gives_no_warning(store):
    r = slr("query", store, "color(cup1, C)^5")
    assert (r.returncode, r.stdout, r.stderr) == (0, "C = red\n", "")


def test_the_library_hint_about_a_missing_stamp_reaches_the_user(store):
    r = slr("query", store, "color(cup2, C)")
    assert r.returncode == 1
    assert r.stderr.strip() == ("error: unknown procedure color/2; color/2 is defined with ^T: "
                                "did you mean color(cup2, C)^T?")


# -- sql output formats --------------------------------------------------------------------

SELECT = "SELECT arg1, arg2, t_end FROM obj ORDER BY t_end"


def test_sql_into_a_pipe_is_plain_tab_separated_text(store):
    r = slr("sql", store, SELECT)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[:2] == ["arg1\targ2\tt_end", "cup1\tcup\t2.0"]
    assert "┃" not in r.stdout


@pytest.mark.parametrize("option, dialect", [("--csv", "excel"), ("--tsv", "excel-tab")])
def test_sql_csv_and_tsv_read_back_with_a_header(store, option, dialect):
    r = slr("sql", store, SELECT, option)
    rows = list(csv.reader(io.StringIO(r.stdout), dialect=dialect))
    assert rows[0] == ["arg1", "arg2", "t_end"]
    stored = json.loads(slr("sql", store, SELECT, "--json").stdout)[1]["arg2"]
    assert rows[2] == ["cup2", stored, "3.0"] and "a cup" in stored


def test_sql_json_and_nl(store):
    whole = json.loads(slr("sql", store, SELECT, "--json").stdout)
    lines = [json.loads(line) for line in slr("sql", store, SELECT, "--nl").stdout.splitlines()]
    assert whole == lines
    assert lines[0] == {"arg1": "cup1", "arg2": "cup", "t_end": 2.0}


@pytest.mark.parametrize("option", ["--json", "--nl"])
def test_sql_json_writes_sums_and_averages_as_numbers_on_both_backends(backend, option):
    # On PostgreSQL sum and avg of an integer column are NUMERICs (psycopg's Decimal), which
    # the JSON writer refused: the command died with "TypeError: (this is a bug ...)"
    assert slr("add", backend, "seen(a)^1", "seen(b)^2", "seen(c)^3").returncode == 0
    r = slr("sql", backend, "SELECT count(*) AS n, sum(seq) AS total, avg(seq) AS mean, "
            "min(t_end) AS first FROM seen", option)
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout) if option == "--json" else [json.loads(r.stdout)]
    assert rows == [{"n": 3, "total": 6, "mean": 2.0, "first": 1.0}]
    assert type(rows[0]["total"]) is int


def test_sql_json_writes_postgresql_values_json_has_no_type_for_as_text(postgres_url):
    assert slr("add", postgres_url, "seen(a)^1").returncode == 0
    r = slr("sql", postgres_url, "SELECT date '2026-11-29' AS day, '1.5'::numeric AS x, "
            "'NaN'::numeric AS nan, ARRAY[2.5::numeric] AS xs, "
            "'123e4567-e89b-12d3-a456-426614174000'::uuid AS id", "--nl")
    assert r.returncode == 0, r.stderr
    row = json.loads(r.stdout)
    assert row["day"] == "2026-11-29" and row["x"] == 1.5 and row["xs"] == [2.5]
    assert row["id"] == "123e4567-e89b-12d3-a456-426614174000" and row["nan"] == {"$float": "nan"}


def test_sql_table_is_the_default_on_a_terminal_and_asked_for_in_a_pipe(store):
    assert "┃ arg1" in slr("sql", store, SELECT, "--table").stdout
    child = _spawn("sql", store, SELECT)
    child.expect(pexpect.EOF)
    assert "┏━━━━━━┳" in child.before and "│ cup2 │" in child.before


def test_sql_read_only_message_is_said_once_in_the_command_lines_words(store):
    r = slr("sql", store, "DELETE FROM obj")
    assert r.returncode == 1
    assert r.stderr.count("read-only") == 1
    assert "write=True" not in r.stderr and "slr sql --write" in r.stderr


# -- ingest from standard input, progress ----------------------------------------------------

def test_ingest_dash_reads_standard_input(store):
    lines = 'seg(cup1, [0.4, 0.1, 0.9])^10\n{"name": "seg", "args": ["cup2", [1, 2, 3]], "time": 11}\nbad(\n'
    r = slr("ingest", store, "-", stdin=lines)
    assert r.returncode == 1
    assert r.stdout.strip() == "ingested 2 events, 1 bad line"
    # times like 10 on a store with the wall clock: a warning first (tests/test_time_traps.py)
    errors = [line for line in r.stderr.splitlines() if not line.startswith("warning: ")]
    assert errors[0].startswith("<stdin>:3: ") and r.stderr.startswith("warning: seg/2: ")
    assert slr("query", store, "seg(O, _)^T", "--json").stdout.count("\n") == 2


def _events_file(path, n: int) -> str:
    path.write_text("".join(f"seg(cup{i % 7}, [0.4, 0.1, {i}])^{i}.5\n" for i in range(n)),
                    encoding="utf-8")
    return str(path)


def test_ingest_progress_is_reported_on_request_even_into_a_log(store, tmp_path):
    events = _events_file(tmp_path / "events.txt", 3000)
    quiet = slr("ingest", store, events)
    # into a pipe: no bar unless asked (times like 1.5 on a store with the wall clock are
    # warned about once, when the store first learns the capped delay)
    assert [line for line in quiet.stderr.splitlines()
            if not line.startswith("warning: seg/2: ")] == []
    r = slr("ingest", store, events, "--progress")
    assert r.returncode == 0, r.stderr
    percents = [line.split(": ")[1].split("%")[0] for line in r.stderr.splitlines()
                if line.startswith("ingesting")]
    assert percents[-1] == "100" and len(percents) >= 10


def _spawn(*args: str) -> pexpect.spawn:
    env = dict(os.environ, PYTHONPATH=str(ROOT), SLR_HISTORY=os.devnull, COLUMNS="120",
               LINES="40", TERM="xterm")
    return pexpect.spawn(sys.executable, ["-m", "slr_sql", *args], env=env, cwd=str(ROOT),
                         encoding="utf-8", timeout=60, dimensions=(40, 120))


def test_ingest_shows_a_bar_on_a_terminal_for_a_long_file(store, tmp_path):
    events = _events_file(tmp_path / "long.txt", 12000)   # past the bar's size threshold
    child = _spawn("ingest", store, events)
    child.expect("ingesting long.txt")
    child.expect("ingested 12000 events")
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0


def strict_json(text: str):
    """``text`` read as JSON proper: ``Infinity``, ``-Infinity`` and ``NaN`` are refused."""
    def refuse(constant: str):
        raise AssertionError(f"{constant} is not JSON: {text}")
    return json.loads(text, parse_constant=refuse)


def test_sql_json_and_nl_write_infinities_and_nan_as_json(backend):
    """JSON has no infinity nor NaN: a store's infinite values (SQLite keeps event arguments
    as REAL; PostgreSQL gives float8 values, NaN too, which SQLite makes NULL) come out as
    the service's encoding writes them."""
    import slr_sql

    with slr_sql.open(backend, clock=slr_sql.ManualClock(100)) as kb:
        kb.add_event("v", [float("inf")], 1.0)
        kb.add_event("v", [float("-inf")], 2.0)
        kb.add_event("v", [1.5], 3.0)
    if backend.startswith("postgresql"):
        select = ("SELECT x, 'NaN'::float8 AS n FROM (VALUES ('Infinity'::float8, 1), "
                  "('-Infinity'::float8, 2), (1.5::float8, 3)) AS t(x, k) ORDER BY k")
        nan = {"$float": "nan"}
    else:
        select = "SELECT arg1 AS x, NULL AS n FROM v ORDER BY t_end"
        nan = None
    whole = strict_json(slr("sql", backend, select, "--json").stdout)
    lines = [strict_json(line) for line in slr("sql", backend, select, "--nl").stdout.splitlines()]
    assert whole == lines
    assert [row["x"] for row in lines] == [{"$float": "inf"}, {"$float": "-inf"}, 1.5]
    assert [row["n"] for row in lines] == [nan] * 3
    # what slr query --json writes of the stored values
    answers = [strict_json(line)["X"] for line in
               slr("query", backend, "v(X)^T", "--json").stdout.splitlines()]
    assert answers == [{"$float": "inf"}, {"$float": "-inf"}, 1.5]


# -- cells that are no plain number or text: csv/tsv/table text, JSON as the service's ------

def test_sql_writes_blobs_and_postgresql_booleans_json_and_arrays_as_text_a_reader_takes(backend):
    """CSV, TSV and the table printed Python's notation (``b'\\x00\\xff'``, ``True``,
    ``{'a': 1}``, ``[1, 2]``); --json wrote a blob as sqlite-utils' ``{"$base64": ...}``
    where the service writes ``{"$bytes": hex}``."""
    from slr_sql.service.encoding import decode_plain, encode_plain

    assert slr("add", backend, "seen(a)^1").returncode == 0
    if backend.startswith("postgresql"):
        select = ("SELECT '\\x00ff'::bytea AS b, true AS t, false AS f, "
                  "'{\"a\": [1, \"x,y\"]}'::jsonb AS j, ARRAY[1, 2] AS arr, "
                  "ARRAY['Infinity'::float8, NULL] AS xs, ARRAY['\\x01'::bytea] AS bs")
        texts = ["\\x00ff", "true", "false", '{"a": [1, "x,y"]}', "[1, 2]",
                 '[{"$float": "inf"}, null]', '[{"$bytes": "01"}]']
        values = [b"\x00\xff", True, False, {"a": [1, "x,y"]}, [1, 2], [float("inf"), None],
                  [b"\x01"]]
    else:
        select = "SELECT x'00ff' AS b, 1 = 1 AS t, 1 = 0 AS f, CAST(x'' AS BLOB) AS e"
        texts = ["\\x00ff", "1", "0", "\\x"]   # (SQLite's comparisons are the integers 1, 0)
        values = [b"\x00\xff", 1, 0, b""]
    for option, dialect in [("--csv", "excel"), ("--tsv", "excel-tab")]:
        r = slr("sql", backend, select, option)
        assert r.returncode == 0, r.stderr
        header, row = list(csv.reader(io.StringIO(r.stdout), dialect=dialect))
        assert row == texts, option
    table = slr("sql", backend, select, "--table").stdout
    assert all(f" {text} " in table for text in texts)
    assert "b'" not in table and "True" not in table
    row = json.loads(slr("sql", backend, select, "--json").stdout)[0]
    assert row["b"] == {"$bytes": "00ff"} and list(row.values()) == encode_plain(values)
    assert decode_plain(list(row.values())) == values
