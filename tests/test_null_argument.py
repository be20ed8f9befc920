"""A stored row with a NULL argument (written by hand: `slr sql --write`, another SQLite
client) is no event: a goal that reads it stops with NotAnEvent naming the type, the row's
seq, the column and the fix, the same words whichever path met it (compiled SQL, the
interpreter, prev/next, a lazy `solutions`, the command line); goals that do not meet it
answer as before, on both paths alike."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock, NotAnEvent

from test_cli import slr
from test_cli_errors import fails_in_words

RULES = """
r(X) :- p(X)^_.
s(X, T) :- p(X)^T.
u(X) :- p(X)^_, atom(X).
"""


@pytest.fixture
def kb(tmp_path):
    kb = slr_sql.open(tmp_path / "k.db", clock=ManualClock(10))
    for event in ("p(a)^1", "p(b)^2", "p(c)^3", "q(x, 1)^1"):
        kb.add(event)
    kb.sql("UPDATE p SET arg1 = NULL WHERE seq = 2", write=True)
    kb.load(RULES)
    yield kb
    kb.close()


def expect_not_an_event(kb, goal: str, where: str = "query") -> str:
    with pytest.raises(NotAnEvent) as caught:
        kb.query(goal)
    message = str(caught.value)
    assert message.startswith(f"{where}: p/1: the stored row of seq 2 is not an event: its "
                              f"arg1 is NULL"), message
    assert 'DELETE FROM "p" WHERE arg1 IS NULL' in message
    assert "ValueError" not in message
    return message


@pytest.mark.parametrize("goal", [
    "p(X)^T", "r(X)", "s(X, T)", "u(X)", "findall(X, p(X)^_, L)", "p(X)^_, X == b",
    "prev(p(X)^T, 2.5)", "next(p(X)^T, [1.5, 5])", "q(A, B)^_, p(X)^_",
])
def test_a_goal_that_reads_the_row_says_which_row_on_both_paths(kb, goal):
    said = []
    for compiled in (True, False):
        kb.sql_enabled = compiled
        said.append(expect_not_an_event(kb, goal))
    assert said[0] == said[1]


@pytest.mark.parametrize("goal, answers", [
    ("p(b)^T", []),
    ("p(a)^T", [{"T": 1.0}]),
    ("prev(p(a)^T, 2.5)", [{"T": 1.0}]),
    ("prev(p(X)^T, 3.5)", [{"X": slr_sql.Atom("c"), "T": 3.0}]),
    ("q(X, Y)^T", [{"X": slr_sql.Atom("x"), "Y": 1, "T": 1.0}]),
])
def test_a_goal_that_does_not_meet_the_row_answers_alike_on_both_paths(kb, goal, answers):
    for compiled in (True, False):
        kb.sql_enabled = compiled
        assert kb.query(goal) == answers


def test_solutions_say_it_as_query_does(kb):
    kb.sql_enabled = False
    with pytest.raises(NotAnEvent, match=r"^solutions: p/1: the stored row of seq 2"):
        list(kb.solutions("p(X)^T"))


def test_the_row_deleted_the_goal_answers(kb):
    expect_not_an_event(kb, "p(X)^T")
    kb.sql('DELETE FROM "p" WHERE arg1 IS NULL', write=True)
    assert [a["X"] for a in kb.query("p(X)^T")] == [slr_sql.Atom("a"), slr_sql.Atom("c")]


def test_the_command_line_says_it_in_words(tmp_path):
    db = str(tmp_path / "robot.db")
    assert slr("add", db, "p(a)^1", "p(b)^2").returncode == 0
    r = slr("sql", db, "UPDATE p SET arg2 = 1", "--write")
    assert r.returncode == 1   # no such column: the write changed nothing
    r = slr("sql", db, "UPDATE p SET arg1 = NULL WHERE seq = 2", "--write")
    assert r.returncode == 0, r.stderr
    fails_in_words(slr("query", db, "p(X)^T"),
                   "p/1: the stored row of seq 2 is not an event: its arg1 is NULL")
