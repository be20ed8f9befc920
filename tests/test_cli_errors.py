"""Bad input to the `slr` command line, run as real subprocesses: every error is words on stderr
and exit status 1 (never a traceback); commands that only read never create a store; `slr sql`
only reads unless --write; `slr ingest` keeps every good line whatever the bad ones hold."""
from __future__ import annotations

import json
import math
import random
import re
from pathlib import Path

import pytest

from conftest import copy_of_store
from test_cli import ROOT, slr

import slr_sql

TRACEBACK = "Traceback (most recent call last)"


def fails_in_words(r, *words: str) -> str:
    """Exit status 1, no traceback, every word in stderr; returns stderr without the
    ``warning:`` lines (event times far from the wall clock's are warned about)."""
    assert r.returncode == 1, (r.returncode, r.stdout, r.stderr)
    assert TRACEBACK not in r.stderr and TRACEBACK not in r.stdout, r.stderr
    for word in words:
        assert word in r.stderr, r.stderr
    return "".join(line for line in r.stderr.splitlines(keepends=True)
                   if not line.startswith("warning: "))


@pytest.fixture
def db(tmp_path) -> str:
    return str(tmp_path / "robot.db")


@pytest.fixture(scope="module")
def prepared_store(tmp_path_factory) -> Path:
    """The store of ``stored_db``, made once for the module by ``slr add``."""
    db = tmp_path_factory.mktemp("errors") / "robot.db"
    r = slr("add", str(db), "obj(cup1, cup, red)^2.0", "obj(cup2, cup, blue)^3.0", "p(4)^1", "p(6)^2")
    assert r.returncode == 0, r.stderr
    return db


@pytest.fixture
def stored_db(tmp_path, prepared_store) -> str:
    """Four events: the test's own copy of ``prepared_store``, at ``db``'s path."""
    return copy_of_store(prepared_store, tmp_path)


# ---------------------------------------------------------------- ingest

def ingest_lines(tmp_path: Path, lines: list) -> tuple[Path, list[int]]:
    """Write ``lines`` (str or bytes) one per line; returns the file and the numbers of the
    lines that are marked bad (a tuple ("bad", line))."""
    path = tmp_path / "events.txt"
    bad = []
    with path.open("wb") as handle:
        for number, line in enumerate(lines, start=1):
            if isinstance(line, tuple):
                bad.append(number)
                line = line[1]
            handle.write((line.encode("utf-8") if isinstance(line, str) else line) + b"\n")
    return path, bad


def json_event(args, **times) -> str:
    return json.dumps({"name": "p", "args": args, **(times or {"time": 1.0})})


def test_ingest_keeps_every_good_line_and_numbers_the_bad_ones_exactly(db, tmp_path):
    nested = "[" * 5000 + "]" * 5000
    path, bad = ingest_lines(tmp_path, [
        "p(1)^1",
        ("bad", '{"name":"p","args":[' + nested + '],"time":2}'),          # JSON nested 5,000 deep
        "p(3)^3",
        ("bad", '{"name":"p","args":[' + "9" * 5000 + '],"time":4}'),       # a 5,000-digit number
        json_event([5], time=5.0),
        ("bad", "p(oops^6"),                                                  # SLR syntax error
        "p(7)^7",
        ("bad", "p(8)^[9,8]"),                                                # start after end
        "p(9)^9",
        ("bad", "p(" + "9" * 5000 + ")^10"),                                  # 5,000 digits in SLR
        ("bad", "p(" + "[" * 5000 + "]" * 5000 + ")^11"),                    # SLR nested 5,000 deep
        ("bad", json_event(["\ud800"], time=12.0)),                           # a lone surrogate
        ("bad", '{"name":"p","args":[13],"time":' + "1" * 400 + "}"),        # a time beyond floats
        ("bad", b'p(\xff\xfe)^14'),                                           # not UTF-8
        ("bad", json_event([15], start=16.0, end=15.0)),                      # start after end
        json_event([[[[[[16]]]]]], time=16.0),
        "p(17)^17",
    ])
    r = slr("ingest", db, str(path))
    stderr = fails_in_words(r)
    assert [int(line[len(str(path)) + 1:].split(":")[0]) for line in stderr.splitlines()] == bad, \
        stderr
    assert f"ingested 7 events, {len(bad)} bad lines" in r.stdout
    q = slr("query", db, "findall(X, p(X)^_, L)")
    assert q.stdout.strip() == "L = [1,3,5,7,9,[[[[[16]]]]],17]"
    reasons = dict(line[len(str(path)) + 1:].split(": ", 1) for line in stderr.splitlines())
    assert "too deep" in reasons["2"] or "nested" in reasons["2"], reasons["2"]
    assert "digits" in reasons["4"], reasons["4"]
    assert "after end time" in reasons["8"] and "after end time" in reasons["15"]
    assert "surrogate" in reasons["12"]
    assert "UTF-8" in reasons["14"]


@pytest.mark.parametrize("digits", ["1e5", "1_000", " 7", "0x10", ""])
def test_ingest_a_big_integer_that_is_not_decimal_digits_says_so(db, tmp_path, digits):
    path, _ = ingest_lines(tmp_path, [json.dumps({"name": "p", "args": [{"$int": digits}],
                                                  "time": 1.0}),
                                      json.dumps({"name": "p", "args": [{"$int": "-12"}],
                                                  "time": 2.0})])
    r = slr("ingest", db, str(path))
    assert f'bad argument: {{"$int": {json.dumps(digits)}}}: $int must be decimal digits' \
        in fails_in_words(r)
    assert "ingested 1 event" in r.stdout and "int()" not in r.stderr


def test_ingest_a_binary_file_reports_bad_lines_without_a_traceback(db, tmp_path):
    path = tmp_path / "noise.bin"
    path.write_bytes(random.Random(11).randbytes(4000))
    r = slr("ingest", db, str(path))
    fails_in_words(r)
    assert "ingested 0 events" in r.stdout


def test_ingest_a_missing_file_is_an_error_in_words(db, tmp_path):
    fails_in_words(slr("ingest", db, str(tmp_path / "nope.txt")), "nope.txt")


# ---------------------------------------------------------------- files that are not stores

def test_a_store_in_a_missing_directory_is_an_error_in_words(tmp_path):
    path = tmp_path / "missing" / "robot.db"
    fails_in_words(slr("add", str(path), "p(1)^1"), "no such directory")
    assert not path.parent.exists()


@pytest.mark.parametrize("command", [["query", "p(X)"], ["add", "p(1)^1"], ["stats"],
                                     ["sql", "SELECT 1"], ["explain", "p(X)"]])
def test_a_file_that_is_not_sqlite_is_refused_in_words_and_left_alone(tmp_path, command):
    path = tmp_path / "notes.txt"
    path.write_text("shopping list: tea, cups\n" * 20, encoding="utf-8")
    before = path.read_bytes()
    fails_in_words(slr(command[0], str(path), *command[1:]), "not an SQLite database", str(path))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


@pytest.mark.parametrize("command", [
    ["query", "p(X)"], ["explain", "p(X)"], ["stats"], ["sql", "SELECT 1"], ["shell"],
])
def test_reading_commands_on_a_missing_path_create_nothing(tmp_path, command):
    path = tmp_path / "robot.db"
    fails_in_words(slr(command[0], str(path), *command[1:]), f"no such store: {path}")
    assert list(tmp_path.iterdir()) == []


def test_load_of_a_binary_program_file_is_an_error_in_words(db, tmp_path):
    program = tmp_path / "robot.slr"
    program.write_bytes(random.Random(2).randbytes(2000))
    fails_in_words(slr("load", db, str(program)), str(program))


def test_load_of_a_missing_program_file_is_an_error_in_words(db, tmp_path):
    fails_in_words(slr("load", db, str(tmp_path / "nope.slr")), "nope.slr")


# ---------------------------------------------------------------- query options and runtime errors

@pytest.mark.parametrize("options", [
    pytest.param(["--at", "nan"], id="at nan"),
    pytest.param(["--timeout", "nan"], id="timeout nan"),
    pytest.param(["--timeout", "-1"], id="timeout -1"),
    pytest.param(["--timeout=-inf"], id="timeout -inf"),
])
def test_query_options_out_of_range_are_errors_in_words(stored_db, options):
    fails_in_words(slr("query", stored_db, "p(X)^T", *options), "error: ")


def _infinity_spelled_three_ways_answers_as_without(stored_db, option: str):
    """``slr query p(X)^T`` with ``option`` given +∞ as ``inf``, ``1e400`` and an integer
    beyond a float answers as without it; returns the run without it."""
    plain = slr("query", stored_db, "p(X)^T")
    assert plain.returncode == 0 and plain.stdout == "X = 4, T = 1.0\nX = 6, T = 2.0\n", \
        plain.stderr
    for spelled in ("inf", "1e400", "1" + "0" * 400):
        r = slr("query", stored_db, "p(X)^T", option, spelled)
        assert (r.returncode, r.stdout) == (0, plain.stdout), (spelled, r.stderr)
    return plain


def test_timeout_inf_is_no_limit_as_in_the_library(stored_db, tmp_path):
    """`slr query --timeout inf` was refused ("--timeout must be a finite number") while
    `kb.query(timeout=inf)` takes it (SPEC: inf is +∞ where a number is expected): no limit,
    spelled inf, 1e400 or an integer beyond a float, with and without --wait; `slr plot
    --timeout` the same (and `kb.plot(timeout=inf)`, refused by the library too). NaN and
    negative timeouts are refused in the library's words."""
    plain = _infinity_spelled_three_ways_answers_as_without(stored_db, "--timeout")
    assert slr("add", stored_db, "fullyUpdated(p/1)^5").returncode == 0   # (complete up to 5)
    r = slr("query", stored_db, "p(X)^T", "--at", "5", "--wait", "--timeout", "inf")
    assert (r.returncode, r.stdout) == (0, plain.stdout), r.stderr
    out = tmp_path / "plot.png"
    r = slr("plot", stored_db, "p", "--query", "p(X)^T", "--every", "1", "--timeout", "inf",
            "-o", str(out))
    assert r.returncode == 0 and out.exists(), r.stderr
    with slr_sql.open(stored_db) as kb:
        assert kb.query("p(X)^T", timeout=math.inf) == kb.query("p(X)^T")
        assert kb.plot(query="p(X)^T", every=1, timeout=math.inf) is not None
        for bad in (math.nan, -1.0):
            with pytest.raises(slr_sql.SLRError) as refused:
                kb.query("p(X)^T", timeout=bad)
            for command in (["query", stored_db, "p(X)^T"],
                            ["plot", stored_db, "--query", "p(X)^T", "-o", str(out)]):
                assert fails_in_words(slr(*command, "--timeout", str(bad))) == \
                    f"error: --{refused.value}\n"


def test_at_inf_is_the_view_of_every_stored_event_as_in_the_library_and_the_shell(stored_db):
    """`slr query --at inf` was refused ("--at must be a finite number") while
    `kb.query(at=inf)` and the shell's `at inf` take it: ⟨Q, +∞⟩ sees every stored event
    (SPEC: inf is +∞ where a number is expected). It answers as without --at, 1e400 (a
    float's inf) and -inf (no event) too; NaN is refused in the library's words."""
    _infinity_spelled_three_ways_answers_as_without(stored_db, "--at")
    r = slr("query", stored_db, "p(X)^T", "--at=-inf")
    assert (r.returncode, r.stdout) == (0, "false.\n"), r.stderr
    with slr_sql.open(stored_db) as kb:
        assert kb.query("p(X)^T", at=math.inf) == kb.query("p(X)^T")
        with pytest.raises(slr_sql.SLRError) as refused:
            kb.query("p(X)^T", at=math.nan)
    assert fails_in_words(slr("query", stored_db, "p(X)^T", "--at", "nan")) == \
        f"error: --{refused.value}\n"


def test_a_wait_at_inf_runs_out_of_its_timeout_in_words(stored_db):
    """No history is complete up to +∞: a synchronized query at inf waits until its
    timeout, then says so (as `kb.submit(goal, at=inf, timeout=1)` does)."""
    fails_in_words(slr("query", stored_db, "p(X)^T", "--at", "inf", "--wait", "--timeout", "1"),
                   "not answerable within 1 s")


def test_a_huge_but_finite_at_does_not_crash_the_timer_thread(stored_db):
    r = slr("query", stored_db, "p(X)^T", "--at", "1e300", "--wait", "--timeout", "0.5")
    stderr = fails_in_words(r, "not answerable")
    assert "Exception in thread" not in stderr


@pytest.mark.parametrize("goal, words", [
    ("nosuch(1)", "unknown procedure nosuch/1"),
    ("X is 1/0", "division by zero"),
    ("X is foo + 1", "type error"),
    ("atom_length(X, Y)", "not sufficiently instantiated"),
    ("throw(my_ball)", "my_ball"),
])
def test_runtime_errors_are_words_not_iso_terms(stored_db, goal, words):
    stderr = fails_in_words(slr("query", stored_db, goal), words)
    assert stderr.startswith("error: ")
    assert "error(" not in stderr


# ---------------------------------------------------------------- add

def test_add_says_which_events_were_stored_and_which_rejected(db):
    r = slr("add", db, "p(1)^1", "p(2)^[3,2]", "p(3)^3", "p(oops^4", "p(5)^5")
    stderr = fails_in_words(r, "event 2", "after end time", "event 4")
    assert "event 1" not in stderr and "event 3" not in stderr
    assert "stored 3 of 5 events (1, 3, 5); rejected 2 (2, 4)" in r.stdout
    q = slr("query", db, "findall(X, p(X)^_, L)")
    assert q.stdout.strip() == "L = [1,3,5]"


def test_add_all_good_still_says_added(db):
    r = slr("add", db, "p(1)^1", "p(2)^2")
    assert (r.returncode, r.stdout.strip()) == (0, "added 2 events")


# ---------------------------------------------------------------- sql

def test_sql_is_read_only_unless_write(stored_db):
    fails_in_words(slr("sql", stored_db, "DROP TABLE obj"), "read-only", "--write")
    fails_in_words(slr("sql", stored_db, "PRAGMA max_page_count = 1000000"), "read-only")
    # (the store's journal, durability and migration number are its own: not even with --write)
    fails_in_words(slr("sql", stored_db, "--write", "PRAGMA journal_mode = DELETE"),
                   "PRAGMA journal_mode with an argument is not allowed")
    fails_in_words(slr("sql", stored_db, "--write", "PRAGMA synchronous = OFF"),
                   "PRAGMA synchronous with an argument is not allowed")
    fails_in_words(slr("sql", stored_db, "PRAGMA user_version = 7"),
                   "PRAGMA user_version with an argument is not allowed")
    fails_in_words(slr("sql", stored_db, "ATTACH 'other.db' AS other"), "read-only")
    q = slr("query", stored_db, "findall(O, obj(O, _, _)^_, L)")
    assert q.stdout.strip() == "L = [cup1,cup2]"
    r = slr("sql", stored_db, "--write", "DELETE FROM obj WHERE arg1 = 'cup2'")
    assert r.returncode == 0, r.stderr
    q = slr("query", stored_db, "findall(O, obj(O, _, _)^_, L)")
    assert q.stdout.strip() == "L = [cup1]"


def test_after_a_written_drop_table_commands_fail_in_words(stored_db):
    assert slr("sql", stored_db, "--write", "DROP TABLE obj").returncode == 0
    for command in (["query", "obj(O, T, C)^S"], ["query", "findall(O, obj(O, _, _)^_, L)"],
                    ["add", "obj(cup3, cup, red)^4"], ["stats"]):
        fails_in_words(slr(command[0], stored_db, *command[1:]), "error: ")


def test_sql_printed_by_explain_runs_in_slr_sql(stored_db):
    goal = "findall(Y, (p(X)^_, Y is X / 2), L)"
    explained = slr("explain", stored_db, goal)
    assert explained.returncode == 0, explained.stderr
    text = explained.stdout
    sql = text.split("sql:\n", 1)[1].split("\nparameters:", 1)[0]
    sql = " ".join(line.strip() for line in sql.splitlines())
    assert "slr_" in sql  # it needs the store's SQL functions
    # the parameters line, e.g. ":c0 = 2, :c1 = '/'", pasted in as SQL literals
    parameters = re.findall(r"(:\w+) = ('(?:[^']|'')*'|[-\d.e+]+)", text.split("parameters:", 1)[1])
    for name, literal in sorted(parameters, key=lambda p: -len(p[0])):
        sql = sql.replace(name, literal)
    r = slr("sql", stored_db, sql, "--json")
    assert r.returncode == 0, r.stderr
    (row,) = json.loads(r.stdout)
    answer = slr("query", stored_db, goal).stdout.strip()
    assert answer == "L = [2,3]" and row["v0"] == "[2,3]"


# ---------------------------------------------------------------- stats and the README

def readme_commands() -> list[str]:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    table = readme.split("## Command line", 1)[1].split("\n\n", 2)[1]
    return re.findall(r"^\| `slr (\w+)", table, flags=re.M)


def test_every_command_is_in_the_readme_table():
    r = slr("--help")
    commands = re.findall(r"^  (\w+)\s", r.stdout.split("Commands:", 1)[1], flags=re.M)
    assert "stats" in commands
    assert sorted(readme_commands()) == sorted(commands)


def test_stats_prints_what_the_readme_shows(db):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    shown = readme.split("$ slr stats robot.db\n", 1)[1].split("```", 1)[0].splitlines()
    r = slr("add", db, "obj(cup1, cup, red)^2.0", "obj(cup1, cup, green)^9.0",
            "seg(cup1, [0.4, 0.1, 0.9])^10")
    assert r.returncode == 0, r.stderr
    r = slr("stats", db)
    assert r.returncode == 0, r.stderr
    printed = r.stdout.splitlines()

    def shape(line: str) -> str:  # numbers and the file name vary; the wording must not
        return re.sub(r"\d+(\.\d+)?(e[-+]?\d+)?", "N", line.replace(db, "robot.db"))

    assert [shape(line) for line in printed] == [shape(line) for line in shown]
    # the README's numbers are current: the same file, pages and events (not the clock)
    assert [line.replace(db, "robot.db") for line in printed
            if not line.startswith("buffer clock")] == [
        line for line in shown if not line.startswith("buffer clock")]
