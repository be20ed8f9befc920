"""Synchronized queries (SPEC §4) on PostgreSQL answer as on SQLite: the same generated events,
marks and goals on a SQLite file and on a database of the suite's server; each query waits,
is released by the marks, and its answers (values with their Prolog types: 1, 1.0 and '1'
differ) are the same on both backends and the same as ``kb.query(at=)`` once complete."""
from __future__ import annotations

import random

import pytest

import slr_sql
from slr_sql import ManualClock

PROGRAM = """
:- max_delay(pos/2, 1). :- max_delay(seen/1, 1).
at_time(O, P, T) :- prev(pos(O, P)^_, T).
after(O, P, T) :- B is T + 3, next(pos(O, P)^_, [T, B]).
both(O, X) :- seen(O)^T, prev(pos(O, X)^_, T).
run(G) :- call(G).
"""

GOALS = [
    "pos(O, P)^T",
    "at_time(O, P, {t})",
    "after(O, P, {t})",
    "both(O, X)",
    "G = seen(O)^_, run(G)",
    "findall(P, pos(o1, P)^_, L)",
    "aggregate_all(count, pos(_, _)^_, N)",
]

VALUES = [1, 1.0, 2, "'1'", "a", "'2.0'", 2.5, "f(1)", "[1, 2.0]"]


def _events(rng: random.Random) -> list[str]:
    out = []
    for i in range(40):
        t = round(rng.uniform(0, 20), 1)
        if rng.random() < 0.75:
            out.append(f"pos(o{rng.randint(1, 3)}, {rng.choice(VALUES)})^{t}")
        else:
            out.append(f"seen(o{rng.randint(1, 3)})^{t}")
    return out


def _answers(target: str, events: list[str], goals: list[tuple[str, float]]) -> list:
    clock = ManualClock(0.0)
    with slr_sql.open(target, clock=clock) as kb:
        kb.load(PROGRAM)
        kb.add_many(events)
        pending = [kb.submit(goal, at=at) for goal, at in goals]
        waiting = [not p.done() for p in pending]
        kb.mark_complete("pos/2", 30.0)
        kb.mark_complete("seen/1", 30.0)
        got = [sorted(map(repr, p.result(timeout=10))) for p in pending]
        direct = [sorted(map(repr, kb.query(goal, at=at))) for goal, at in goals]
    return [got, direct, waiting]


@pytest.mark.parametrize("seed", range(3))
def test_synchronized_answers_are_the_same_on_both_backends(seed, tmp_path, postgres_url):
    rng = random.Random(seed)
    events = _events(rng)
    goals = [(g.format(t=round(rng.uniform(0, 22), 1)), round(rng.uniform(5, 25), 1))
             for g in GOALS]
    sqlite_got, sqlite_direct, sqlite_waiting = _answers(str(tmp_path / "s.db"), events, goals)
    pg_got, pg_direct, pg_waiting = _answers(postgres_url, events, goals)
    assert pg_got == sqlite_got
    assert pg_direct == sqlite_direct
    assert sqlite_got == sqlite_direct
    assert pg_waiting == sqlite_waiting and all(sqlite_waiting)
    assert any(answers for answers in sqlite_got)
