"""Event goals, prev and next against a brute-force oracle that implements SPEC §1/§2 literally.

Hypothesis draws event streams (two types, small int/atom arguments, points and intervals,
ties on start and end, insertion out of time order, several batches) and goals with partially
bound arguments:

* ``p(..)^T`` / ``p(..)^[S,E]`` (optionally with a stream view ``at=z``: only end <= z);
* ``prev(p(..)^Z, T)`` -- the matching events with the greatest end <= T, ties all, store order;
* ``prev(p(..)^Z, [A,B])`` -- the latest matching event with A <= start and end <= B;
* ``next(p(..)^Z, [A,B])`` and ``next(p(..)^Z, A, B)`` -- smallest start with A <= start and
  end <= B, ties all, store order.

Store order is (end, start, arrival). A stamp ``^T`` matches only events with start = end
(equal to T by value: ``^2`` matches a stored 2.0); ``^[S,E]`` matches any. prev/next ignore
the stream view (SPEC §2).
"""
from __future__ import annotations

import math

from hypothesis import HealthCheck, given, settings, strategies as st

import slr_sql
from slr_sql import Atom

TYPES = {"a": 1, "b": 2}
VALUES = [0, 1, "p", "q"]
TIMES = [0.0, 1.0, 1.5, 2.0, 3.0]
INT_TIMES = [0, 1, 2, 3]
BOUNDS = [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, math.inf]


def fmt(v) -> str:
    if v == math.inf:
        return "inf"
    return repr(v) if isinstance(v, float) else str(v)


events_st = st.lists(
    st.tuples(st.sampled_from(sorted(TYPES)), st.lists(st.sampled_from(VALUES), min_size=2,
                                                       max_size=2),
              st.sampled_from(TIMES), st.sampled_from([0.0, 0.0, 0.5, 1.0])),
    min_size=2, max_size=14)


@st.composite
def pattern(draw, type_name: str | None = None):
    """(type, args) where each arg is ('var', name) or ('const', value)."""
    name = type_name or draw(st.sampled_from(sorted(TYPES)))
    args = []
    for i in range(TYPES[name]):
        if draw(st.integers(0, 3)) == 0:
            args.append(("const", draw(st.sampled_from(VALUES))))
        elif draw(st.integers(0, 5)) == 0 and i > 0:
            args.append(args[0] if args[0][0] == "var" else ("var", f"A{i}"))  # repeated var
        else:
            args.append(("var", f"A{i}"))
    return name, args


@st.composite
def goals(draw):
    name, args = draw(pattern())
    stamp_kind = draw(st.sampled_from(["point", "interval", "interval", "point_const",
                                       "interval_const"]))
    if stamp_kind == "point":
        stamp = ("point", ("var", "T"))
    elif stamp_kind == "point_const":
        # integer times too: they match the stored float times by value (SPEC: times)
        stamp = ("point", ("const", draw(st.sampled_from(TIMES + INT_TIMES))))
    elif stamp_kind == "interval_const":
        stamp = ("interval", ("const", draw(st.sampled_from(TIMES + INT_TIMES))), ("var", "E"))
    else:
        stamp = ("interval", ("var", "S"), ("var", "E"))
    kind = draw(st.sampled_from(["plain", "plain_at", "prev", "prev_iv", "next2", "next3"]))
    extra = {}
    if kind == "plain_at":
        extra["at"] = draw(st.sampled_from(BOUNDS[:-1]))
    elif kind == "prev":
        extra["t"] = draw(st.sampled_from([math.inf, 3.0, 2.5, 2.0] + BOUNDS))
    else:
        a = draw(st.sampled_from(BOUNDS[:-1]))
        b = draw(st.sampled_from([x for x in BOUNDS if x >= a] + [0.5]))
        extra["a"], extra["b"] = a, b
    return kind, name, args, stamp, extra


def term_text(x) -> str:
    return x[1] if x[0] == "var" else fmt(x[1])


def goal_text(goal) -> str:
    kind, name, args, stamp, extra = goal
    atom = f"{name}({', '.join(term_text(a) for a in args)})"
    if stamp[0] == "point":
        ev = f"{atom}^{term_text(stamp[1])}"
    else:
        ev = f"{atom}^[{term_text(stamp[1])}, {term_text(stamp[2])}]"
    if kind in ("plain", "plain_at"):
        return ev
    if kind == "prev":
        return f"prev({ev}, {fmt(extra['t'])})"
    if kind == "prev_iv":
        return f"prev({ev}, [{fmt(extra['a'])}, {fmt(extra['b'])}])"
    if kind == "next2":
        return f"next({ev}, [{fmt(extra['a'])}, {fmt(extra['b'])}])"
    return f"next({ev}, {fmt(extra['a'])}, {fmt(extra['b'])})"


def same_value(x, y) -> bool:
    return type(x) is type(y) and x == y


def match(goal, event) -> dict | None:
    """Bindings if the event unifies with the goal's event pattern (stamp included)."""
    _, name, args, stamp, _ = goal
    ename, eargs, start, end = event
    if ename != name:
        return None
    binding: dict = {}

    def unify(p, value) -> bool:
        if p[0] == "const":
            return same_value(p[1], value)
        if p[1] in binding:
            return same_value(binding[p[1]], value)
        binding[p[1]] = value
        return True

    def unify_time(p, stored: float) -> bool:
        # a stored time matches a goal's time by numeric value (5 matches 5.0)
        if p[0] == "const":
            return p[1] == stored
        if p[1] in binding:
            return binding[p[1]] == stored
        binding[p[1]] = stored
        return True

    for p, v in zip(args, eargs):
        if not unify(p, v):
            return None
    if stamp[0] == "point":
        if not (unify_time(stamp[1], start) and unify_time(stamp[1], end)):
            return None
    elif not (unify_time(stamp[1], start) and unify_time(stamp[2], end)):
        return None
    return binding


def oracle(goal, stored: list) -> list[dict]:
    """stored: events in store order as (name, args, start, end)."""
    kind, _, _, _, extra = goal
    matching = [(ev, b) for ev in stored if (b := match(goal, ev)) is not None]
    if kind == "plain":
        return [b for _, b in matching]
    if kind == "plain_at":
        return [b for ev, b in matching if ev[3] <= extra["at"]]
    if kind in ("prev", "prev_iv"):
        if kind == "prev":
            cands = [(ev, b) for ev, b in matching if ev[3] <= extra["t"]]
        else:
            cands = [(ev, b) for ev, b in matching
                     if extra["a"] <= ev[2] and ev[3] <= extra["b"]]
        if not cands:
            return []
        best = max(ev[3] for ev, _ in cands)
        return [b for ev, b in cands if ev[3] == best]
    cands = [(ev, b) for ev, b in matching if extra["a"] <= ev[2] and ev[3] <= extra["b"]]
    if not cands:
        return []
    first = min(ev[2] for ev, _ in cands)
    return [b for ev, b in cands if ev[2] == first]


def normal(answers: list[dict]) -> list[dict]:
    return [{k: (type(v).__name__ if type(v) is not Atom else "atom", v) for k, v in a.items()}
            for a in answers]


def expected_normal(answers: list[dict]) -> list[dict]:
    return [{k: ("atom" if isinstance(v, str) else type(v).__name__, v) for k, v in a.items()}
            for a in answers]


@settings(max_examples=120, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(events=events_st, batches=st.integers(1, 3),
       queries=st.lists(goals(), min_size=1, max_size=8))
def test_event_goals_prev_next_match_the_oracle(events, batches, queries):
    stream = [(name, args[:TYPES[name]], start, start + dur)
              for name, args, start, dur in events]
    order = sorted(range(len(stream)), key=lambda i: (stream[i][3], stream[i][2], i))
    stored = [stream[i] for i in order]
    # small times, not the wall clock's: a ManualClock (unsynchronized queries: where it
    # stands changes no answer)
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        size = max(1, -(-len(stream) // batches))
        for i in range(0, len(stream), size):
            texts = [f"{n}({', '.join(fmt(a) for a in args)})^[{s!r}, {e!r}]"
                     if s != e or (i // size) % 2 else
                     f"{n}({', '.join(fmt(a) for a in args)})^{s!r}"
                     for n, args, s, e in stream[i:i + size]]
            assert kb.add_many(texts) == []
        for goal in queries:
            text = goal_text(goal)
            at = goal[4].get("at")
            got = kb.query(text, at=at) if at is not None else kb.query(text)
            want = oracle(goal, stored)
            assert normal(got) == expected_normal(want), \
                f"\ngoal: {text} at={at}\nstore order: {stored}\n got: {got}\nwant: {want}"


def test_out_of_order_and_ties_example():
    """A hand-made stream: ties on end and on start, arrival out of time order."""
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many(["a(p)^[1.0, 2.0]", "a(q)^2.0", "a(p)^[0.0, 2.0]", "a(q)^[1.0, 2.0]",
                     "a(p)^1.0", "a(q)^3.0"])
        # store order: a(p)^1; then end 2: start 0 (p), start 1 (p, then q, by arrival), 2 (q)
        assert [(x["X"], x["S"], x["E"]) for x in kb.query("a(X)^[S, E]")] == [
            ("p", 1.0, 1.0), ("p", 0.0, 2.0), ("p", 1.0, 2.0), ("q", 1.0, 2.0),
            ("q", 2.0, 2.0), ("q", 3.0, 3.0)]
        assert [(x["X"], x["S"]) for x in kb.query("prev(a(X)^[S, E], 2.5)")] == [
            ("p", 0.0), ("p", 1.0), ("q", 1.0), ("q", 2.0)]
        assert [(x["X"], x["T"]) for x in kb.query("prev(a(X)^T, 2.5)")] == [("q", 2.0)]
        # next: smallest start >= 0.5, ties in store order
        assert [(x["X"], x["E"]) for x in kb.query("next(a(X)^[S, E], [0.5, inf])")] == [
            ("p", 1.0), ("p", 2.0), ("q", 2.0)]
        assert [x["X"] for x in kb.query("next(a(X)^T, 1.5, 2.0)")] == ["q"]
        # the stream view restricts plain event goals, not prev/next
        assert [x["X"] for x in kb.query("a(X)^T", at=1.5)] == ["p"]
        assert [x["X"] for x in kb.query("prev(a(X)^T, 10)", at=1.5)] == ["q"]
