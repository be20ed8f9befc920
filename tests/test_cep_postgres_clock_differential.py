"""PostgreSQL == SQLite for event rules whose decisions the clock makes mid-stream.

Random rules of tests/test_cep_differential.py (any policy, negation, within, where goals
in SQL or run by the interpreter) plus a second rule reading the first one's complex events,
random streams added in a random arrival order in batches, with declared max delays and a
ManualClock that moves between batches: decisions are made at the adds and at the clock's
moves, late events may arrive after a history was complete. What is decided depends on that
sequence of operations -- the same on both engines: the same complex events of both rules,
and nothing pending once the clock passed everything.
"""
from __future__ import annotations

import itertools

import pytest
import test_cep_differential as cepdiff
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql import ManualClock

_SCHEMAS = itertools.count()


@pytest.fixture(scope="module")
def database(postgres_server):
    """One database for the module's examples, a schema each."""
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


def _run(where: str, program: str, steps: list, head_arity: int) -> tuple:
    clock = ManualClock(0.0)
    with slr_sql.open(where, clock=clock) as kb:
        kb.load(program)
        for batch, now in steps:
            if len(batch) == 1:
                kb.add(batch[0])
            elif batch:
                assert kb.add_many(batch) == []
            clock.set(now)
        clock.set(100.0)
        r = sorted(((tuple(args), s, e) for args, s, e, _ in kb.store.scan("r", head_arity)),
                   key=repr)
        h = sorted(((s, e) for _, s, e, _ in kb.store.scan("h", 0)))
        pending = kb.sql("SELECT count(*) FROM slr_cep_pending")[1][0][0]
    return cepdiff._typed(r), h, pending


@settings(max_examples=20, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(st.one_of(cepdiff.rules(), cepdiff.where_rules()), cepdiff.streams(), st.data())
def test_rules_decided_as_the_clock_moves_store_alike_on_both_engines(database,
                                                                       tmp_path_factory,
                                                                       rule, events, data):
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    delay = data.draw(st.sampled_from([0, 1, 3]), label="max delay")
    texts = [cepdiff._event_text(events[i]) for i in order]
    steps, start, now = [], 0, 0.0
    while start < len(texts):
        stop = start + data.draw(st.integers(1, 3), label="batch")
        now += data.draw(st.sampled_from([0.0, 0.5, 1.0, 2.0, 4.0]), label="clock step")
        steps.append((texts[start:stop], now))
        start = stop
    arity = len(rule["head"])
    reading = "r(" + ", ".join(["_"] * arity) + ")" if arity else "r"
    program = (f":- consumption({rule['policy']}).\n"
               + "".join(f":- max_delay({t}/{n}, {delay}).\n"
                         for t, n in cepdiff.TYPES.items())
               + cepdiff.rule_text(rule) + f"\nh <- {reading} seq b(_).\n"
               + (cepdiff.WHERE_PROGRAM + "\n" if rule.get("interpret") else ""))
    local = _run(str(tmp_path_factory.mktemp("d") / "s.db"), program, steps, arity)
    url = database + ("&" if "?" in database else "?") + f"schema=d{next(_SCHEMAS)}"
    server = _run(url, program, steps, arity)
    assert server == local, (program, steps)
    assert local[2] == 0


def _rejections_and_matches(where: str) -> tuple:
    with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
        kb.load(":- consumption(recent).\nc(X) <- a(X) seq b(X).\n")
        events = []
        for i in range(24):   # (16 or more alternating: the batch is grouped by type)
            s = e = float(i)
            args: tuple = (i // 4,)
            if i % 7 == 3:
                s = e + 1                   # start after end
            if i % 11 == 5:
                args = (float("nan"),)
            if i % 13 == 6:
                args = (1, 2)               # another arity: a type of its own
            events.append(("a" if i % 2 == 0 else "b", args, s, e))
        errors = [(error.index, str(error)) for error in kb.add_many(events)]
        derived = sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]"))
        counts = [kb.store.count(name, n) for name, n in (("a", 1), ("b", 1), ("b", 2))]
    return errors, derived, counts


def test_a_batch_with_rejected_events_stores_and_derives_alike(postgres_url, tmp_path):
    """Bad events among a batch's rows (rejected one by one, with their index) and the
    rule's round over the others: the same rejections, rows and complex events."""
    local = _rejections_and_matches(str(tmp_path / "s.db"))
    assert len(local[0]) == 5 and local[1]
    assert _rejections_and_matches(postgres_url) == local


def _where_raising(where: str, policy: str) -> tuple:
    def ok(x):
        if x == 2:
            raise ZeroDivisionError("refused")
        return True
    clock = ManualClock(0.0)
    with slr_sql.open(where, clock=clock) as kb:
        kb.define("ok", 1, ok)
        kb.load(f":- consumption({policy}).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n"
                "c(X) <- a(X) seq b(X) where ok(X).\n")
        kb.add_many(["a(1)^1", "b(1)^2", "a(2)^3", "b(2)^4", "a(3)^5", "b(3)^6"])
        clock.set(10.0)   # (one decision round: the where raises for its second match)
        derived = sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]"))
        info = kb.event_rules()[0]
        pending = kb.sql("SELECT count(*) FROM slr_cep_pending")[1][0][0]
    return derived, info["errors"], pending


@pytest.mark.parametrize("policy", ["recent", "chronological", "unrestricted"])
def test_a_where_raising_midway_through_a_decision_round_spoils_only_its_match(
        postgres_url, tmp_path, policy):
    """A where goal that raises for one candidate of a decision round: that match is not
    derived and counted as the rule's error; the round's other decisions stand, nothing
    stays pending -- alike on both engines."""
    local = _where_raising(str(tmp_path / "s.db"), policy)
    assert local == ([(1, 1.0, 2.0), (3, 5.0, 6.0)], 1, 0)
    assert _where_raising(postgres_url, policy) == local


def _compared_in_where(where: str, policy: str, goal: str) -> tuple:
    with slr_sql.open(where, clock=ManualClock(0.0)) as kb:
        kb.load(f":- consumption({policy}).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n"
                f"r(X, Y) <- a(X)^T1 seq b(Y)^T2 where ({goal}).\n")
        kb.add_many(["a(1)^1", "a(x)^2", "a(f(1))^3", "a(100000000000000000000001)^4",
                     "a(1.0e300)^5", "a(pi)^6", "b(0)^7", "b(1.0e308)^8"])
        kb.clock.set(100.0)
        derived = [(r["X"], r["Y"], r["S"], r["E"]) for r in kb.query("r(X, Y)^[S, E]")]
        info = kb.event_rules()[0]
    return derived, info["errors"], info["last_error"]


@pytest.mark.parametrize("goal", ["X < 5", "X =\\= Y", "X + 1 > Y", "X - T2 < 1.0e300",
                                  "100000000000000000000000 =< X", "X > 100000000000000000000000"])
@pytest.mark.parametrize("policy", ["unrestricted", "recent"])
def test_a_where_comparison_of_a_non_number_is_no_match_on_both_engines(postgres_url, tmp_path,
                                                                        policy, goal):
    """A where comparison of the pattern's values is decided in SQLite's statement, a value
    that is no plain number by slr_cep_cmp / slr_cep_arith as Prolog evaluates it, a type
    error (an atom, f(1)) there no match and no error of the rule. PostgreSQL, which calls
    no Python from SQL, ran the comparison as a where goal, and counted each such candidate
    as the rule's error: the same complex events, other counts. An integer beyond 64 bits in
    the comparison was a parameter SQLite refused, and every add the rule decided failed."""
    local = _compared_in_where(str(tmp_path / "s.db"), policy, goal)
    assert local[0] and local[1:] == (0, None)
    assert _compared_in_where(postgres_url, policy, goal) == local
