"""A fleet store asked about one robot answers as that robot's own store (SPEC §10).

tests/test_fleet.py checks queries per robot and origin/2 on one hand-made fleet (SQL ==
interpreter; PostgreSQL == SQLite on its fixed goals). Here hypothesis draws the robots'
streams (points and intervals, ties, some events of the fleet's own with no robot), shipped
in random batches to a fleet store in a SQLite file and to one in a PostgreSQL schema (a
robot sometimes retired after part of its stream shipped, then sometimes reinstated to ship
the rest: docs/fleet.md, "Retiring a robot"), and goals over event goals, prev, next and a
rule reading prev. For each goal G and robot r,
on both fleet stores, compiled and interpreted:

* ``fleet.query(G, robot=r)`` == ``G`` on r's own store (every event goal, prev and next of
  G, also inside rules, sees r's events only);
* ``origin(r, G)`` on the fleet == ``G`` on r's store, for G an event goal, prev or next;
* ``origin(R, G)`` with R unbound == r's answers with ``R = r``, robot by robot in name order;
* the PostgreSQL fleet's answers to G == the SQLite fleet's.
"""
from __future__ import annotations

import itertools
import os
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import slr_sql
from slr_sql import Atom, fleet
from slr_sql.terms import format_term

# the second robot's name is beyond ASCII and longer than 63 characters (PostgreSQL keys
# such texts through slr_key()); origin/2 enumerates the robots in name order
ROBOTS = ["r1", "ロボット_" + "é" * 64]
PROGRAM = "last_at(P, W)^T :- prev(seen(P, W)^_, T).\nwhere_now(P, W) :- last_at(P, W)^3.\n"
FACTOR = int(os.environ.get("SLR_DIFF_FACTOR", "1"))   # SLR_DIFF_FACTOR=20: a longer hunt
_SCHEMAS = itertools.count()


@pytest.fixture(scope="module")
def database(postgres_server):
    """One database for the module's examples, a schema each."""
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


def opened(where, **options):
    return slr_sql.open(where, clock=slr_sql.ManualClock(1000.0), **options)


# values at their edges too: -0.0 beside 0.0, 1 beside 1.0 and '1', integers beyond 64 bits,
# texts beyond ASCII and longer than 63 characters, nested compounds, [] beside '[]'
WHERE = ["dock", "aisle", "1", "1.0", "'1'", "-0.0", "0.0", "1.0e308", "18446744073709551619",
         "'" + "é" * 70 + "'", '"日本語"', "f(g([]), \"s\", -1)", "[]", "'[]'", "[1, [2.5]]"]
event = st.tuples(st.sampled_from(["pallet7", "pallet8"]), st.sampled_from(WHERE),
                  st.sampled_from([0.0, 1.0, 2.0, 2.0, 3.0]), st.sampled_from([0.0, 0.0, 1.0]))


@st.composite
def goals(draw):
    """An event goal, prev or next (may go inside origin/2), or any goal (may not)."""
    p = draw(st.sampled_from(["P", "pallet7"]))
    stamp = draw(st.sampled_from(["T", "[S, E]"]))
    w = draw(st.sampled_from(["W", "W", "W"] + WHERE))
    atom = f"seen({p}, {w})^{stamp}"
    kind = draw(st.integers(0, 6))
    t = draw(st.sampled_from(["0", "1.5", "2", "3", "inf"]))
    a, b = draw(st.sampled_from([("0", "inf"), ("1", "3"), ("2", "2"), ("1.5", "inf")]))
    if kind == 0:
        return True, atom
    if kind == 1:
        return True, f"prev({atom}, {t})"
    if kind == 2:
        return True, f"prev({atom}, [{a}, {b}])"
    if kind == 3:
        return True, draw(st.sampled_from([f"next({atom}, [{a}, {b}])", f"next({atom}, {a}, {b})"]))
    if kind == 4:
        return False, draw(st.sampled_from([f"last_at({p}, W)^{t}", "where_now(P, W)"]))
    if kind == 5:
        return False, f"findall(W-{stamp}, {atom}, L)"
    return False, "seen(P, W)^T, prev(seen(P, W2)^T2, T)"


@st.composite
def fleets(draw):
    """The robots' streams (each split where a retirement may come), the fleet's own
    events, the shipments' batch size, the goals, and which robot is retired after its
    first part shipped (None: none) and whether it is then reinstated and ships the rest."""
    streams = {r: draw(st.lists(event, max_size=6)) for r in ROBOTS}
    own = draw(st.lists(event, max_size=2))
    batch = draw(st.integers(1, 4))
    queries = draw(st.lists(goals(), min_size=1, max_size=4))
    retired = draw(st.sampled_from([None, None] + ROBOTS))
    cut = {r: draw(st.integers(0, len(streams[r]))) for r in ROBOTS}
    reinstated = draw(st.booleans())
    return streams, own, batch, queries, (retired, cut, reinstated)


def _text(ev) -> str:
    p, w, s, d = ev
    return f"seen({p}, {w})^" + (repr(s) if d == 0 else f"[{s!r}, {s + d!r}]")


def _answers(kb, goal: str, interpreted: bool, **options) -> list:
    kb.sql_enabled = not interpreted
    try:
        # repr keeps -0.0 and 0.0 apart, and an Atom from a str (a variable's name is the
        # engine's own)
        return [{k: re.sub(r"Var\('[^']*'\)", "Var", repr(v)) for k, v in a.items()}
                for a in kb.query(goal, **options)]
    finally:
        kb.sql_enabled = True


@settings(max_examples=10 * FACTOR, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(fleets())
def test_a_fleet_asked_about_one_robot_answers_as_its_own_store(database, tmp_path_factory,
                                                                 case):
    streams, own_events, batch, queries, (retired, cut, reinstated) = case
    folder: Path = tmp_path_factory.mktemp("fleet")
    fleets_ = [str(folder / "fleet.db"),
               database + ("&" if "?" in database else "?") + f"schema=f{next(_SCHEMAS)}"]
    robots = {}
    try:
        # a retired robot's history stays on the fleet and is asked as before; one
        # reinstated ships the rest of its stream after it (its own store has no more
        # than the fleet got)
        first = {r: streams[r][:cut[r]] if r == retired else streams[r] for r in ROBOTS}
        for r in ROBOTS:
            robots[r] = opened(folder / f"{r}.db", robot=r)
            robots[r].load(PROGRAM)
            if first[r]:
                assert robots[r].add_many([_text(ev) for ev in first[r]]) == []
        for where in fleets_:
            for r in ROBOTS:
                fleet.push(str(folder / f"{r}.db"), where, batch=batch)
            with opened(where) as kb:
                kb.load(PROGRAM)
                if own_events:
                    assert kb.add_many([_text(ev) for ev in own_events]) == []
            if retired is not None:
                assert fleet.retire(where, retired)["already"] is False
        if retired is not None and reinstated:
            rest = streams[retired][cut[retired]:]
            if rest:
                assert robots[retired].add_many([_text(ev) for ev in rest]) == []
            for where in fleets_:
                assert fleet.reinstate(where, retired)["reinstated"] is True
                fleet.push(str(folder / f"{retired}.db"), where, batch=batch)
        answers_of = {}
        for where in fleets_:
            with opened(where) as kb:
                for event_goal, goal in queries:
                    for interpreted in (False, True):
                        context = f"{where.split('?')[0]}: {goal} (interpreted: {interpreted})"
                        answers_of.setdefault(goal, _answers(kb, goal, interpreted))
                        assert _answers(kb, goal, interpreted) == answers_of[goal], context
                        for r in ROBOTS:
                            mine = _answers(robots[r], goal, interpreted)
                            assert _answers(kb, goal, interpreted, robot=r) == mine, \
                                f"robot={r} {context}"
                            if event_goal:
                                assert _answers(kb, f"origin({format_term(Atom(r))}, {goal})",
                                                interpreted) == \
                                    mine, f"origin({r}, ..) {context}"
                        if event_goal:
                            each = [{"R": repr(Atom(r)), **a} for r in ROBOTS
                                    for a in _answers(robots[r], goal, interpreted)]
                            assert _answers(kb, f"origin(R, {goal})", interpreted) == each, \
                                f"origin(R, ..) {context}"
    finally:
        for kb in robots.values():
            kb.close()
