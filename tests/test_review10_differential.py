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
