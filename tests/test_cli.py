"""The `slr` command line, run as real subprocesses (`python -m slr_sql ...`) on a temporary store."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import copy_of_store

import slr_sql

ROOT = Path(__file__).resolve().parent.parent

PROGRAM = """\
% colors persist; locations are valid for 5 s
color(O, C)^T :- prev(obj(O, _, C)^_Z, T).
location(O, L)^T :- prev(seg(O, L)^Z, T), T - Z =< 5, !.
location(O, "outdated")^T :- prev(seg(O, _)^Z, T), T - Z > 5, !.
location(_, "never-observed")^_.
"""


def slr(*args: str, stdin: str | None = None, cwd: Path = ROOT, env_extra: dict | None = None,
        timeout: float = 120) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("SLR_HISTORY", os.devnull)
    env["COLUMNS"] = "200"
    if env_extra:
        env.update(env_extra)
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], input=stdin if stdin is not None else "",
                          capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)


@pytest.fixture
def db(tmp_path) -> str:
    return str(tmp_path / "robot.db")


@pytest.fixture(scope="module")
def loaded_store(tmp_path_factory) -> Path:
    """The store of ``loaded_db``, made once for the module by ``slr load`` and ``slr add``."""
    folder = tmp_path_factory.mktemp("loaded")
    db = folder / "robot.db"
    program = folder / "robot.slr"
    program.write_text(PROGRAM, encoding="utf-8")
    r = slr("load", str(db), str(program))
    assert r.returncode == 0, r.stderr
    r = slr("add", str(db), "obj(cup1, cup, red)^2.0", "obj(cup1, cup, green)^9.0", "seg(cup1, [0.4, 0.1, 0.9])^10")
    assert r.returncode == 0, r.stderr
    return db


@pytest.fixture
def loaded_db(tmp_path, loaded_store) -> str:
    """A store holding PROGRAM and three events: the test's own copy of ``loaded_store``."""
    return copy_of_store(loaded_store, tmp_path)


def test_help_lists_every_command():
    r = slr("--help")
    assert r.returncode == 0
    for command in ("demo", "load", "add", "ingest", "query", "explain", "shell", "sql"):
        assert command in r.stdout


def test_query_prints_one_answer_per_line(loaded_db):
    r = slr("query", loaded_db, "color(cup1, C)^12.5")
    assert (r.returncode, r.stdout.strip()) == (0, "C = green"), r.stderr
    r = slr("query", loaded_db, "color(cup1, C)^5.")  # a final full stop is fine
    assert r.stdout.strip() == "C = red"
    r = slr("query", loaded_db, "member(X-Y, [a-[1,2], b-\"s t\"])")
    assert r.stdout.splitlines() == ['X = a, Y = [1,2]', 'X = b, Y = "s t"']


def test_query_strings_are_quoted_and_atoms_are_not(loaded_db):
    r = slr("query", loaded_db, "location(cup1, L)^20")
    assert r.stdout.strip() == 'L = "outdated"'
    r = slr("query", loaded_db, "location(cup1, L)^12")
    assert r.stdout.strip() == "L = [0.4,0.1,0.9]"


def test_query_true_and_false(loaded_db):
    assert slr("query", loaded_db, "color(cup1, green)^12").stdout.strip() == "true."
    r = slr("query", loaded_db, "color(cup1, blue)^12")
    assert (r.returncode, r.stdout.strip()) == (0, "false.")
    assert slr("query", loaded_db, "color(nothing, C)^12").stdout.strip() == "false."


def test_query_at_limits_the_stream_view(loaded_db):
    r = slr("query", loaded_db, "findall(C, obj(cup1, _, C)^_, L)", "--at", "5")
    assert r.stdout.strip() == "L = [red]"
    r = slr("query", loaded_db, "findall(C, obj(cup1, _, C)^_, L)")
    assert r.stdout.strip() == "L = [red,green]"


def test_query_wait_answers_once_complete(db, tmp_path):
    program = tmp_path / "colors.slr"
    # A fixed delay of 0: with the wall clock far past these event times, obj/3 is complete.
    program.write_text(":- max_delay(obj/3, 0).\ncolor(O, C)^T :- prev(obj(O, _, C)^_Z, T).\n",
                       encoding="utf-8")
    assert slr("load", db, str(program)).returncode == 0
    assert slr("add", db, "obj(cup1, cup, red)^2.0", "obj(cup1, cup, green)^9.0").returncode == 0
    r = slr("query", db, "color(cup1, C)^12", "--at", "12", "--wait", "--timeout", "20")
    assert (r.returncode, r.stdout.strip()) == (0, "C = green"), r.stderr
    r = slr("query", db, "color(cup1, C)^12", "--wait", "--timeout", "20")  # complete up to now
    assert (r.returncode, r.stdout.strip()) == (0, "C = green"), r.stderr


def test_query_timeout_is_an_error(db, tmp_path):
    program = tmp_path / "spin.slr"
    program.write_text("spin :- spin.\n", encoding="utf-8")
    assert slr("load", db, str(program)).returncode == 0
    r = slr("query", db, "spin", "--timeout", "0.5")
    assert r.returncode == 1
    assert r.stderr.startswith("error: ")


def test_syntax_error_in_a_file_points_at_it(db, tmp_path):
    bad = tmp_path / "bad.slr"
    bad.write_text("a(1).\nb(2) :- .\n", encoding="utf-8")
    r = slr("load", db, str(bad))
    assert r.returncode == 1
    first, *rest = r.stderr.splitlines()
    assert first.startswith(f"{bad}:2:"), r.stderr
    assert any(line.strip() == "^" for line in rest), r.stderr
    assert "Traceback" not in r.stderr


def test_syntax_error_in_a_goal(loaded_db):
    r = slr("query", loaded_db, "color(cup1, C")
    assert r.returncode == 1
    assert "^" in r.stderr and ":1:" in r.stderr.splitlines()[0]
    assert "Traceback" not in r.stderr


def test_evaluation_error_is_reported(loaded_db):
    r = slr("query", loaded_db, "prev(obj(cup1, _, C)^_, T)")  # T unbound: instantiation error
    assert r.returncode == 1
    assert r.stderr.startswith("error: ") and "Traceback" not in r.stderr


def test_add_rejects_a_bad_event(db):
    r = slr("add", db, "seen(X)^2")
    assert r.returncode == 1
    assert r.stderr.startswith("error: ")


def test_ingest_text_json_and_bad_lines(db, tmp_path):
    events = tmp_path / "events.txt"
    events.write_text("\n".join([
        "% a recording",
        "seg(cup1,[0.4,0.1,0.9])^12.31",
        '{"name":"seg","args":["cup2",[0.5,0.1,0.9]],"start":12.5,"end":12.5}',
        "seg(cup3, [0.6, 0.1, 0.9])^13.",
        "seg(cup4, oops(^13",                        # line 5: not SLR
        '{"name":"seg","args":["cup5"],"start":"x"}',  # line 6: time is not a number
        "seen(bob)^[14, 15]",
        '{"name":"note","args":[{"$string":"a b"},{"f":["x",1]}],"time":16}',
        "",
    ]), encoding="utf-8")
    r = slr("ingest", db, str(events))
    assert r.returncode == 1
    bad = [line for line in r.stderr.splitlines() if not line.startswith("warning: ")]
    assert [line.split(": ")[0] for line in bad] == [f"{events}:5", f"{events}:6"], r.stderr
    # times like 12.31 on a store with a wall clock: said once per type, with the fix
    warned = [line for line in r.stderr.splitlines() if line.startswith("warning: ")]
    assert sorted(line.split(":")[1].strip() for line in warned) == ["note/2", "seen/1",
                                                                     "seg/2"], r.stderr
    assert all("StreamClock" in line and "max_delay" in line for line in warned)
    assert "ingested 5 events" in r.stdout
    q = slr("query", db, "findall(O, seg(O, _)^_, L)")
    assert q.stdout.strip() == "L = [cup1,cup2,cup3]"
    q = slr("query", db, "seen(W)^[S, E]")
    assert q.stdout.strip() == "W = bob, S = 14.0, E = 15.0"
    q = slr("query", db, "note(S, F)^_")
    assert q.stdout.strip() == 'S = "a b", F = f(x,1)'


def test_ingest_all_good_exits_zero(db, tmp_path):
    events = tmp_path / "events.jsonl"
    events.write_text("\n".join(
        json.dumps({"name": "pos", "args": ["a", i], "start": float(i), "end": float(i)}) for i in range(1200)),
        encoding="utf-8")
    r = slr("ingest", db, str(events))
    assert r.returncode == 0, r.stderr
    assert "ingested 1200 events" in r.stdout
    q = slr("query", db, "aggregate_all(count, pos(a, _)^_, N)")
    assert q.stdout.strip() == "N = 1200"


def test_explain_prints_a_plan(loaded_db):
    r = slr("explain", loaded_db, "color(cup1, C)^5")
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip()


def test_sql_table_and_json(loaded_db):
    r = slr("sql", loaded_db, "SELECT count(*) AS n FROM obj")
    assert r.returncode == 0, r.stderr
    assert "n" in r.stdout and "2" in r.stdout
    r = slr("sql", loaded_db, "SELECT arg1, arg3 FROM obj ORDER BY t_end", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout) == [{"arg1": "cup1", "arg3": "red"}, {"arg1": "cup1", "arg3": "green"}]


def test_sql_error_is_reported(loaded_db):
    r = slr("sql", loaded_db, "SELECT * FROM no_such_table")
    assert r.returncode == 1
    assert r.stderr.startswith("error: ")


def test_shell_reads_plain_lines_when_stdin_is_not_a_terminal(db, tmp_path):
    program = tmp_path / "colors.slr"
    program.write_text("color(O, C)^T :- prev(obj(O, _, C)^_Z, T).\n", encoding="utf-8")
    script = "\n".join([
        f"load {program}",
        "add obj(cup1, cup, red)^2.0",
        "add obj(cup1, cup, green)^9.0",
        "color(cup1, C)^5.",
        "color(cup1,",       # a goal over two lines
        "      C)^12.",
        ":- event seg/2.",
        "assert((usedFor(cup, tea) :- true)).",
        "usedFor(cup, X).",
        "color(cup1, blue)^12.",
        "at 5",
        "findall(C, obj(cup1, _, C)^_, L).",
        "oops(.",
        "halt.",
        "color(cup1, C)^12.",  # after halt: not run
    ]) + "\n"
    slr_sql.open(db).close()  # shell does not create a store
    r = slr("shell", db, stdin=script)
    assert r.returncode == 0, r.stderr
    out = r.stdout.splitlines()
    assert "C = red ." in out
    assert "C = green ." in out
    assert "X = tea ." in out
    assert "false." in out
    assert "L = [red] ." in out
    assert out.count("C = green .") == 1
    assert "^" in r.stderr  # the syntax error was shown with its caret, and the shell went on


def test_python_m_and_console_script_agree():
    r = slr("--version")
    assert r.returncode == 0 and "slr" in r.stdout


def test_demo_answers_the_cups_question():
    r = slr("demo", timeout=300)
    assert r.returncode == 0, r.stderr
    assert "Which cups did you see on table1" in r.stdout
    cups_block = re.split(r"\n\s*\]\s*\n", r.stdout.split("Cups = [", 1)[1], maxsplit=1)[0]
    assert "cup1-[1.947,0.304,0.8]" in cups_block and "cup2-[2.314,-0.121,0.8]" in cups_block
    assert "cup3" not in cups_block  # cup3 was seen, but on the next table
    assert 'L = "outdated"' in r.stdout and 'L = "never-observed"' in r.stdout
    assert "C = blue" in r.stdout


def test_demo_into_a_file_keeps_a_readable_store(tmp_path):
    db = tmp_path / "demo.db"
    r = slr("demo", "--db", str(db), timeout=300)
    assert r.returncode == 0, r.stderr
    q = slr("sql", str(db), "SELECT arg1 FROM obj ORDER BY t_end", "--json")
    assert [row["arg1"] for row in json.loads(q.stdout)][:2] == ["cup1", "cup2"]
    again = slr("demo", "--db", str(db))
    assert again.returncode == 2 and "fresh store" in again.stderr


def test_demo_synchronized_part_runs():
    """The demo's synchronized cups question, in process: submitted before the perception
    components are done, answered only after both send fullyUpdated."""
    import io

    from rich.console import Console

    from slr_sql.demo import run_demo

    out = io.StringIO()
    results = run_demo(Console(file=out, width=200), db_path=None)
    synchronized = results[0]
    assert synchronized.query.title.startswith("(synchronized)")
    # answered only after both perception components declared themselves complete
    assert [note.endswith("True") for note in synchronized.notes] == [False, False, False, True]
    [answer] = synchronized.answers
    assert [str(item.args[0]) for item in answer["Cups"]] == ["cup1", "cup2"]
    assert "fullyUpdated(seg/2)^14" in out.getvalue()


FAST_PATH_SAMPLES = [
    "seg(cup1,[0.4,0.1,0.9])^12.31", "seg(cup1, [0.4, 0.1, 0.9])^12",
    "tf(cam, base, pose([0.1, 0.0, 1.2], [0.0, 0.0, 0.0, 1.0]))^10.0", "tick^3", "seen(y)^[1, 2]",
    "p([])^1", "p(-1, -2.5e3)^[-4, 5]", "p(a) ^ 1", "p(f(g(h)))^[1.5,2.5]", "p(a)^1.5e2",
    "p('A')^1", 'p("s")^1', "p(a-b)^1", "p(0x1A)^1", "p(1e10)^1", "p([a|b])^1", "p(0'a)^1",
    "p([1, e])^1", "p([2.5, e1, 3])^1",
]


def parse_term_event(text):
    """The event through the full parser (lark), as (name, args, start, end)."""
    from slr_sql.arith import evaluate
    from slr_sql.parser import parse_term
    from slr_sql.program import event_key, split_event_atom

    atom, s, e = split_event_atom(parse_term(text, "<event>")[0])
    args = tuple(atom.args) if isinstance(atom, slr_sql.Struct) else ()
    return event_key(atom)[0], args, float(evaluate(s)), float(evaluate(e))


@pytest.mark.parametrize("text", FAST_PATH_SAMPLES)
def test_ingest_fast_path_reads_events_like_the_parser(text):
    """ingest reads simple event lines without the full parser; it must store the same rows."""
    import slr_sql
    from slr_sql.cli import parse_event_line

    rows = []
    full = parse_term_event(text)
    for add in (lambda kb: kb.add_many([full]), lambda kb: kb.add_many([parse_event_line(text)])):
        with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
            add(kb)
            [(table,)] = kb.sql("SELECT table_name FROM slr_event_types")[1]
            columns, data = kb.sql(f'SELECT * FROM "{table}"')
            rows.append([{c: v for c, v in zip(columns, row) if c not in ("seq", "arrival")} for row in data])
    assert rows[0] == rows[1]
    assert [type(v) for v in rows[0][0].values()] == [type(v) for v in rows[1][0].values()]


def test_the_demo_prints_goals_plans_and_notes_as_text_not_markup():
    """A list [cup1, cup2] in a goal, a plan or a note read as a rich markup tag (an unknown
    style): it vanished from what the demo printed."""
    import io

    from rich.console import Console

    from slr_sql.demo import DemoQuery, DemoResult, _print_result

    out = io.StringIO()
    query = DemoQuery("[bold]title", "member(X, [cup1, cup2])", None, "why [cup1]")
    _print_result(Console(file=out, width=200),
                  DemoResult(query, [{"X": 1}], plan="plan [cup1, cup2]", notes=["[a, b]"]))
    printed = out.getvalue()
    for text in ("[bold]title", "member(X, [cup1, cup2]).", "why [cup1]",
                 "plan [cup1, cup2]", "[a, b]"):
        assert text in printed, printed
