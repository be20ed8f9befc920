"""The complex events handed to the add listeners are exactly the rows stored.

A round copies its matches from the provenance table into the head's event table. Without a
trigger on that table every match is stored and the copy is read back from the provenance
rows; with a buffer's trigger (which may refuse a row) the rows stored are taken from the
insert itself. Either way the listeners see what the table holds, in provenance order.
"""
from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

import slr_sql
from slr_sql import ManualClock
from slr_sql.encoding import decode
from slr_sql.terms import format_term, from_python

RULE = "c(X, Y) <- a(X, Y) seq b(X)."
EVENTS = ["a(1, p(q))^1", "b(1)^2", "a(2, \"s\")^47", "a(2, 1.5)^48", "b(2)^49"]


@pytest.mark.parametrize("policy", ["unrestricted", "recent"])
@pytest.mark.parametrize("buffer, kept", [
    ("", [("1", "p(q)", 1.0, 2.0), ("2", '"s"', 47.0, 49.0), ("2", "1.5", 48.0, 49.0)]),
    ("tBuffer(c(_, _), 5).", [("2", '"s"', 47.0, 49.0), ("2", "1.5", 48.0, 49.0)]),
])
def test_listeners_get_the_stored_complex_events(policy, buffer, kept):
    clock = ManualClock(50.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(f":- consumption({policy}).\n{RULE}\n{buffer}")
        got = []
        kb.add_listeners.append(lambda evs: got.extend(e for e in evs if e[0] == "c"))
        kb.add_many(EVENTS)
        clock.set(51.0)   # recent decides once its inputs are complete (nothing expires)
        if policy == "recent":
            kept = [k for k in kept if k[2] != 47.0]   # the most recent a(2, _) only
        heard = [tuple(format_term(from_python(a)) for a in args) + (s, e)
                 for _, args, s, e in got]
        assert heard == kept
        assert all(type(s) is float and type(e) is float for _, _, s, e in got)
        stored = [tuple(format_term(decode(v)) for v in row[:2]) + row[2:] for row in
                  kb.sql("SELECT arg1, arg2, t_start, t_end FROM c ORDER BY seq")[1]]
        assert stored == kept


@given(st.lists(st.integers(0, 20), max_size=40), st.integers(-1, 21), st.sets(st.integers(0, 60)))
def test_the_ready_terminators_are_those_a_walk_finds_with_few_checks(ends, limit, seen_before):
    # recent terminators of a group are decided up to the first not ready (ascending end
    # times): the bisection finds the same rows, marks the same rows seen, and asks the
    # trackers O(log n) times instead of once per row
    from slr_sql.cep.runtime import ready_prefix

    rows = [(i, 0, "term", 0, "[1]", float(t), float(t)) for i, t in enumerate(sorted(ends))]
    rows = [row for row in rows if row[0] not in seen_before]
    walked, walk_seen = [], set(seen_before)
    for row in rows:
        walk_seen.add(row[0])
        if not row[6] <= limit:
            break
        walked.append(row)
    checks = []

    def ready(t: float) -> bool:
        checks.append(t)
        return t <= limit

    seen = set(seen_before)
    assert ready_prefix(rows, ready, seen) == walked
    assert seen == walk_seen
    assert len(checks) <= 2 + max(len(rows), 1).bit_length()
