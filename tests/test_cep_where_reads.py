"""Event rules whose ``where`` reads the store, against a reference, on both backends.

tests/test_cep_differential.py's reference covers where goals that compare the pattern's
values; a where goal that reads stored events (prev, next, an event goal, an aggregate over
them: docs/events.md, "Negation, where goals that read the store, and completeness") is
tested there only on hand-made streams (tests/test_events.py). Here hypothesis draws a
pattern (one event, or a seq of two), a where goal over a third type ``c`` -- a negated
prev or next, a count of event goals (seen through the stream view: end ≤ the match's
end), a count of prev's tied answers, the first answer of prev in store order -- and a
stream added in a random arrival order, in random batches, with completeness marks or
without; the clock passes everything at the end. The complex events must be the
reference's (written here from SPEC §1-§3 and §6), on SQLite and on PostgreSQL.
"""
from __future__ import annotations

import itertools
import os

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock

TYPES = {"a": 1, "b": 1, "c": 1}
FACTOR = int(os.environ.get("SLR_DIFF_FACTOR", "1"))   # SLR_DIFF_FACTOR=20: a longer hunt
_SCHEMAS = itertools.count()

# where goal -> (head arguments, goal text); X is the pattern's value, T its start, E its end
WHERES = {
    "no_prev": ("X", "\\+ prev(c(X)^[_, _], T)"),
    "no_prev_point": ("X", "\\+ prev(c(X)^_, T)"),
    "no_next": ("X", "\\+ next(c(X)^[_, _], [T, T + 2])"),
    "count_view": ("X, N", "aggregate_all(count, c(X)^[_, _], N)"),
    "count_prev": ("X, N", "aggregate_all(count, prev(c(_)^_, T), N)"),
    "first_prev": ("X, Y", "(prev(c(Y)^[_, _], T) -> true)"),
    "first_next": ("X, Y", "(next(c(Y)^[_, _], T, E + 1) -> true)"),
}


def _same(x, y) -> bool:
    return type(x) is type(y) and x == y


def _key(ev) -> tuple:
    """Newer is greater: by end, start, then the value (integer before float)."""
    return (ev[3], ev[2], ev[1][0], type(ev[1][0]) is float)


def reference(pattern: str, where: str, events: list, order: list[int],
              policy: str = "unrestricted") -> list:
    """The complex events (head values, start, end), sorted. The policy chooses among the
    matches whose where goal holds (docs/events.md): per terminating b, the newest a
    (recent), or the oldest a not yet used, terminators in occurrence order (chronological)."""
    arrival = {i: k for k, i in enumerate(order)}
    cs = sorted((ev[3], ev[2], arrival[i], ev) for i, ev in enumerate(events) if ev[0] == "c")
    cs = [ev for _, _, _, ev in cs]   # store order: end, start, arrival
    out = []
    if pattern == "single":
        for a in (ev for ev in events if ev[0] == "a"):
            out += _decide(where, cs, a[1][0], a[2], a[3])
        return sorted(out, key=repr)
    a_s = [(i, ev) for i, ev in enumerate(events) if ev[0] == "a"]
    b_s = sorted(((i, ev) for i, ev in enumerate(events) if ev[0] == "b"),
                 key=lambda ib: _key(ib[1]))
    used: set[int] = set()
    for j, b in b_s:
        valid = [(i, a, found) for i, a in a_s
                 if _same(a[1][0], b[1][0]) and a[3] < b[2]
                 and (found := _decide(where, cs, a[1][0], a[2], b[3]))]
        if policy == "unrestricted":
            out += [d for _, _, found in valid for d in found]
        elif policy == "recent" and valid:
            out += max(valid, key=lambda v: _key(v[1]))[2]
        elif policy == "chronological":
            free = [v for v in valid if v[0] not in used]
            if free:
                i, _, found = min(free, key=lambda v: _key(v[1]))
                used.add(i)
                out += found
    return sorted(out, key=repr)


def _decide(where: str, cs: list, x, t: float, e: float) -> list:
    """The complex events of one match: its where goal's one solution, or none."""
    out = []
    if where == "no_prev":
        if not any(_same(c[1][0], x) and c[3] <= t for c in cs):
            out.append(((x,), t, e))
    elif where == "no_prev_point":
        if not any(_same(c[1][0], x) and c[2] == c[3] and c[3] <= t for c in cs):
            out.append(((x,), t, e))
    elif where == "no_next":
        if not any(_same(c[1][0], x) and t <= c[2] and c[3] <= t + 2 for c in cs):
            out.append(((x,), t, e))
    elif where == "count_view":
        out.append(((x, sum(_same(c[1][0], x) and c[3] <= e for c in cs)), t, e))
    elif where == "count_prev":
        points = [c for c in cs if c[2] == c[3] and c[3] <= t]
        latest = max((c[3] for c in points), default=None)
        out.append(((x, sum(c[3] == latest for c in points)), t, e))
    elif where == "first_prev":
        before = [c for c in cs if c[3] <= t]
        if before:
            latest = max(c[3] for c in before)
            out.append(((x, next(c for c in before if c[3] == latest)[1][0]), t, e))
    else:   # first_next
        inside = [c for c in cs if t <= c[2] and c[3] <= e + 1]
        if inside:
            first = min(c[2] for c in inside)
            out.append(((x, next(c for c in inside if c[2] == first)[1][0]), t, e))
    return out


def rule_text(pattern: str, where: str, policy: str = "unrestricted") -> str:
    head, goal = WHERES[where]
    if pattern == "single":
        body = "a(X)^[T, E]"
    else:
        body = "a(X)^[T, _] seq b(X)^[_, E]"
    return f":- consumption({policy}).\nr({head}) <- {body} where {goal}."


def _event_text(ev) -> str:
    name, (x,), s, e = ev
    return f"{name}({x!r})^" + (repr(s) if s == e else f"[{s!r}, {e!r}]")


def run(where_: str | None, pattern: str, where: str, events: list, order: list[int],
        cuts: list[int], marks: bool, policy: str) -> list:
    clock = ManualClock(0.0)
    with slr_sql.open(where_, clock=clock) as kb:
        kb.load(rule_text(pattern, where, policy))
        sequence = [events[i] for i in order]
        items = []
        for k, ev in enumerate(sequence):
            items.append(_event_text(ev))
            if marks:   # complete up to just before the next event of the type still to come
                rest = [x for x in sequence[k + 1:] if x[0] == ev[0]]
                t = min([x[3] for x in rest], default=100.0) - 0.5
                if t > 0:
                    items.append(f"fullyUpdated({ev[0]}/1)^{t}")
        start = 0
        for cut in sorted(set(cuts)) + [len(items)]:
            if start < cut <= len(items):
                assert kb.add_many(items[start:cut]) == []
                start = cut
        clock.set(100.0)
        arity = len(WHERES[where][0].split(", "))
        rows = list(kb.store.scan("r", arity))
        pending = kb.sql("SELECT count(*) FROM slr_cep_pending")[1][0][0]
    assert int(pending) == 0
    return sorted(((tuple(args), s, e) for args, s, e, _ in rows), key=repr)


@st.composite
def cases(draw):
    events = []
    for _ in range(draw(st.integers(1, 9))):
        name = draw(st.sampled_from(["a", "b", "c", "c"]))
        s = float(draw(st.integers(0, 6)))
        e = s + float(draw(st.sampled_from([0, 0, 1, 2])))
        events.append((name, (draw(st.sampled_from([0, 1, 1.0])),), s, e))
    order = draw(st.permutations(range(len(events))))
    cuts = draw(st.lists(st.integers(0, 2 * len(events)), max_size=3))
    pattern = draw(st.sampled_from(["single", "seq", "seq"]))
    policy = "unrestricted"
    if pattern == "seq":
        policy = draw(st.sampled_from(["unrestricted", "recent", "chronological"]))
    return (pattern, draw(st.sampled_from(sorted(WHERES))), events, order, cuts,
            draw(st.booleans()), policy)


def _typed(rows):
    return [(tuple((type(v).__name__, v) for v in args), s, e) for args, s, e in rows]


def check(where_: str | None, case) -> None:
    pattern, where, events, order, cuts, marks, policy = case
    got = run(where_, pattern, where, events, order, cuts, marks, policy)
    want = reference(pattern, where, events, order, policy)
    assert _typed(got) == _typed(want), rule_text(pattern, where, policy)


@pytest.fixture(scope="module")
def database(postgres_server):
    """One database for the module's examples, a schema each."""
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


@settings(max_examples=40 * FACTOR, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(cases())
def test_a_where_reading_the_store_equals_the_reference_on_sqlite(case):
    check(None, case)


@settings(max_examples=20 * FACTOR, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(cases())
def test_a_where_reading_the_store_equals_the_reference_on_postgres(database, case):
    check(database + ("&" if "?" in database else "?") + f"schema=w{next(_SCHEMAS)}", case)
