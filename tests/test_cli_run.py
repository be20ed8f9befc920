"""`slr run FILE` (an example file's rules, events and expected answers) and the warning of
`slr load` about facts written like events. Real subprocesses."""
from __future__ import annotations

from pathlib import Path

from test_cli import ROOT, slr

COLOR = ROOT / "examples" / "color.slr"


def test_run_prints_each_query_its_answers_and_a_summary():
    r = slr("run", str(COLOR))
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0] == f"% {COLOR}: 3 events, 5 queries"
    assert lines[1:3] == ["ok    ?- color(cup1, C)^12.5.", "        C = green"]
    assert lines[-1] == "5 of 5 expected answers matched"


def test_run_exits_1_and_shows_expected_and_got_on_a_mismatch(tmp_path):
    wrong = tmp_path / "wrong.slr"
    wrong.write_text(COLOR.read_text(encoding="utf-8").replace(
        '%% expect: [{"C": "red"}]', '%% expect: [{"C": "blue"}]'), encoding="utf-8")
    r = slr("run", str(wrong), "-q")
    assert r.returncode == 1
    assert r.stdout.splitlines() == [
        f"FAIL  {wrong}:15: ?- color(cup1, C)^5.",
        '      expected [{"C": "blue"}]',
        "      got      C = red",
        "4 of 5 expected answers matched"]


def test_run_reports_a_rejected_event_with_its_line(tmp_path):
    bad = tmp_path / "bad.slr"
    bad.write_text("p(X)^T :- prev(q(X)^_, T).\n%% events\nq(a)^1.\nq(B)^2.\n"
                   "%% query: p(X)^5\n%% expect: [{\"X\": \"a\"}]\n", encoding="utf-8")
    r = slr("run", str(bad), "-q")
    assert r.returncode == 1
    assert r.stderr.startswith(f"{bad}:4: event rejected: ")
    assert r.stdout == "1 of 1 expected answers matched; 1 events rejected\n"


def test_run_keeps_the_store_with_db_and_refuses_an_existing_one(tmp_path):
    db = str(tmp_path / "color.db")
    assert slr("run", str(COLOR), "--db", db, "-q").returncode == 0
    assert slr("query", db, "obj(O, _, C)^T", "--limit", "1").stdout == "O = cup1, C = red, T = 2.0\n"
    again = slr("run", str(COLOR), "--db", db)
    assert again.returncode == 1
    assert again.stderr == f"error: {db} exists; slr run wants a fresh store (remove it first)\n"


def test_load_warns_about_facts_written_like_events_and_says_how_to_run_them(tmp_path):
    db = str(tmp_path / "robot.db")
    r = slr("load", db, str(COLOR))
    assert r.returncode == 0
    assert r.stderr.splitlines() == [
        f"warning: {COLOR}:8: obj(cup1, cup, red)^2.0. is a fact (and 2 more), not an event: "
        "prev and next see only events",
        f"  to load its rules and add the events after '%% events' into a new store: "
        f"slr run {COLOR} --db NEW.db"]


def test_load_of_a_plain_program_with_an_event_like_fact_suggests_add_or_ingest(tmp_path):
    db = str(tmp_path / "robot.db")
    program = Path(tmp_path / "p.slr")
    program.write_text("near(X) :- seen(X)^_.\nseen(a)^[1, 2].\n", encoding="utf-8")
    r = slr("load", db, str(program))
    assert r.stderr.splitlines()[0] == (f"warning: {program}:2: seen(a)^[1, 2]. is a fact, not an "
                                        "event: prev and next see only events")
    assert f"slr ingest {db} FILE" in r.stderr


def test_load_of_rules_only_says_nothing(tmp_path):
    program = tmp_path / "rules.slr"
    program.write_text("color(O, C)^T :- prev(obj(O, _, C)^_, T).\nfact(1).\nstamp(a^1).\n",
                       encoding="utf-8")
    r = slr("load", str(tmp_path / "robot.db"), str(program))
    assert (r.returncode, r.stderr) == (0, "")
