"""Event rules over ``in_order`` types whose events tie at the same end time.

End-time order admits ties (two objects seen in one camera frame): after an event of an
in_order type ending at L, another one ending at L may still come. So the type is complete
*before* L, not *through* L, and a decision for a terminator ending at L waits for a later
event of it (or a mark, or the clock) wherever a part that may end with the terminator is of
that type -- while parts in the left of a ``seq`` (ending before the terminator starts)
decide at once (docs/events.md, "in_order and ties"). Every stream here must derive the same
complex events added one by one, all at once, and without ``in_order`` (the differential
contract), on SQLite and on PostgreSQL.
"""
from __future__ import annotations

import random
import threading

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock
from test_cep_differential import TYPES, _event_text, _typed, reference, rule_text

IN_ORDER = "".join(f":- in_order({t}/{n}).\n" for t, n in TYPES.items())


def _declarations(types: str, in_order: bool) -> str:
    return "".join((f":- in_order({t}/1).\n" if in_order else "")
                   + f":- max_delay({t}/1, 1000).\n" for t in types)


def _rows(kb, name: str) -> list:
    return sorted((r["X"], r["S"], r["E"]) for r in kb.query(f"{name}(X)^[S, E]"))


def derive(store, rules_text: str, stream: list, how: str, types: str = "abe",
           policy: str = "recent", heads: str = "cd") -> dict:
    """The complex events of ``heads`` over ``stream``: added one by one (``one``) or in one
    add_many (``once``) with its types in_order, or one by one without in_order (``plain``);
    then the clock is moved past every max_delay."""
    clock = ManualClock(0.0)
    with slr_sql.open(store, clock=clock) as kb:
        kb.load(f":- consumption({policy}).\n{_declarations(types, how != 'plain')}"
                f"{rules_text}\n")
        if how == "once":
            assert kb.add_many(stream) == []
        else:
            for event in stream:
                kb.add(event)
        clock.set(1100.0)
        kb.add("tick^1100")   # (a round after the clock moved, on every backend)
        return {h: _rows(kb, h) for h in heads}


def _store(backend: str, tmp_path, how: str) -> str:
    """A fresh store of the backend for each run (a file, or a new PostgreSQL database)."""
    if backend.startswith("postgresql"):
        return _fresh_database(backend, how)
    return str(tmp_path / f"{how}.db")


def _fresh_database(url: str, how: str) -> str:
    import re

    import psycopg
    name = re.search(r"/([^/?]+)(\?|$)", url).group(1)
    fresh = f"{name}_{how}"
    admin = re.sub(r"/[^/?]+(\?|$)", r"/postgres\1", url, count=1)
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute(f'CREATE DATABASE "{fresh}"')
    return re.sub(r"/[^/?]+(\?|$)", rf"/{fresh}\1", url, count=1)


def _three_ways(backend, tmp_path, rules_text, stream, **kw) -> list:
    return [derive(_store(backend, tmp_path, how), rules_text, stream, how, **kw)
            for how in ("one", "once", "plain")]


# ------------------------------------------------------------------------ the operators

@pytest.mark.parametrize("op", ["and", "par", "equals", "meets", "during", "starts",
                                "finishes"])
def test_a_partner_tied_with_the_terminator_is_not_lost_one_by_one(op):
    """b(1)^3 terminates; a(2)^3 then makes a complete *before* 3 only: an a(1)^3 may still
    come (and does), so b(1)^3 waits for it instead of being decided with no partner."""
    stream = ["b(1)^3", "a(2)^3", "a(1)^3"]
    rule = f"c(X) <- a(X) {op} b(X)."
    one, once, plain = (derive(None, rule, stream, how, heads="c")
                        for how in ("one", "once", "plain"))
    assert one == once == plain == {"c": [(1, 3.0, 3.0)]}


def test_a_tied_decision_waits_for_one_later_event_not_for_the_clock():
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(":- consumption(recent).\n" + _declarations("ab", True)
                + "c(X) <- a(X) and b(X).")
        for event in ["b(1)^3", "a(2)^3", "a(1)^3"]:
            kb.add(event)
        # a and b are complete before 3, not through 3: b(1)^3 and a(1)^3 wait
        assert _rows(kb, "c") == [] and kb.event_rules()[0]["pending"] == 3
        kb.add("a(9)^4")
        assert _rows(kb, "c") == []   # b's newest event still ends at 3
        kb.add("b(9)^4")
        assert _rows(kb, "c") == [(1, 3.0, 3.0)]
        assert clock.now() == 0.0


def test_seq_decides_at_once_at_a_tie():
    """a(X) ends before b(X) starts: an a ending at b's end can never be its partner, so
    b(1)^3 and b(2)^3 are decided as soon as an a ends at 3 -- no later event needed."""
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(":- consumption(recent).\n" + _declarations("ab", True)
                + "c(X) <- a(X) seq b(X).")
        for event in ["a(1)^2", "a(2)^2", "b(1)^3", "b(2)^3"]:
            kb.add(event)
        assert _rows(kb, "c") == []   # a may still get an event ending in (2, 3)
        kb.add("a(3)^3")
        assert _rows(kb, "c") == [(1, 2.0, 3.0), (2, 2.0, 3.0)]
        assert kb.event_rules()[0]["pending"] == 0


def test_a_part_in_a_seq_s_left_decides_at_once_the_right_part_waits():
    """In (a seq b) and e, a ends before the match ends; b and e may end with it."""
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(":- consumption(recent).\n" + _declarations("abe", True)
                + "c(X) <- (a(X) seq b(X)) and e(X).")
        explained = "\n".join(kb.explain("c(X) <- (a(X) seq b(X)) and e(X)").splitlines())
        assert "through its end: b/1, e/1; before it: a/1" in explained
        for event in ["a(1)^1", "e(1)^3", "b(1)^3", "a(5)^4"]:
            kb.add(event)
        assert _rows(kb, "c") == []
        kb.add_many(["b(5)^4", "e(5)^4"])
        assert _rows(kb, "c") == [(1, 1.0, 3.0)]


# ------------------------------------------------------------------------ chronological

def test_chronological_terminators_tied_at_their_end_are_taken_in_occurrence_order():
    """a b(1)^3 arriving after b(2)^3 comes first in occurrence order (same end, smaller
    value) and takes the a: b(2)^3 must not have taken it already."""
    stream = ["a(0)^1", "b(2)^3", "a(0)^4", "b(1)^3"]
    rule = "c(X) <- a(_) seq b(X)."
    runs = [derive(None, rule, stream, how, types="ab", policy="chronological", heads="c")
            for how in ("one", "once", "plain")]
    assert runs == [{"c": [(1, 1.0, 3.0)]}] * 3


def test_chronological_waits_for_the_terminators_of_every_alternative():
    """The alternatives share the used events: a k(2)^4 arriving late (k is not in order)
    comes before a(1)^5 in occurrence order and takes b(0)^1, so a(1)^5 waits for k."""
    clock = ManualClock(0.0)
    program = (":- consumption(chronological).\n:- in_order(a/1). :- in_order(b/1).\n"
               ":- max_delay(a/1, 1000). :- max_delay(b/1, 1000). :- max_delay(k/1, 1000).\n"
               "c(X) <- b(_) seq (a(X) or k(X)).")
    stream = ["b(0)^1", "a(1)^5", "a(9)^6", "b(0)^6", "k(2)^4"]
    with slr_sql.open(clock=clock) as kb:
        kb.load(program)
        for event in stream:
            kb.add(event)
        clock.set(1100.0)
        kb.add("tick^1100")
        one = _rows(kb, "c")
    with slr_sql.open(clock=ManualClock(0.0)) as kb:
        kb.load(program)
        kb.add_many(stream)
        assert _rows(kb, "c") == [] and kb.event_rules()[0]["pending"] > 0
        kb.clock.set(1100.0)
        kb.add("tick^1100")
        assert one == _rows(kb, "c") == [(2, 1.0, 4.0)]


# ------------------------------------------------------------------------ hierarchies

TIE_STREAM = ["b(2)^1", "b(2)^2", "b(2)^2.5", "e(1)^2.5", "e(2)^2.5", "b(1)^3", "e(1)^3",
              "e(1)^3", "a(2)^3", "a(1)^3"]
AND_HIERARCHY = "c(X) <- a(X) and b(X).\nd(X) <- e(X) seq c(X)."


def test_a_hierarchy_over_tied_events_derives_the_same_three_ways(backend, tmp_path):
    one, once, plain = _three_ways(backend, tmp_path, AND_HIERARCHY, TIE_STREAM)
    assert one == once == plain == {"c": [(1, 3.0, 3.0), (2, 2.5, 3.0)],
                                     "d": [(1, 2.5, 3.0)]}


def test_a_complex_type_is_not_complete_through_a_tie_of_its_inputs():
    """A synchronized query over c at 3 must wait for the c(1)^3 that b(1)^3 and a later
    a(1)^3 make: c is complete through 3 only once a and b are."""
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(":- consumption(recent).\n" + _declarations("ab", True)
                + "c(X) <- a(X) and b(X).")
        for event in ["b(1)^3", "a(2)^3"]:
            kb.add(event)
        answer = kb.submit("findall(X, c(X)^_, L)", at=3.0)
        assert not answer.done() and kb.complete_until("c/1") <= 3.0
        kb.add("a(1)^3")
        assert not answer.done()
        kb.add_many(["a(7)^4", "b(7)^4"])
        assert answer.result(timeout=10) == [{"L": [1]}]


def test_a_seq_hierarchy_reads_its_complex_terminator_at_once():
    """d(X) <- e(X) seq c(X) over c(X) <- a(X) seq b(X): c ends a match of d, so d needs c
    complete only before c's end, which its inputs' newest ends give (no later event)."""
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(":- consumption(recent).\n" + _declarations("abe", True)
                + "c(X) <- a(X) seq b(X).\nd(X) <- e(X) seq c(X).")
        kb.add_many(["e(1)^0.5", "a(1)^1", "a(7)^2", "e(9)^2"])
        kb.add("b(1)^2")
        assert _rows(kb, "d") == [(1, 0.5, 2.0)]


# ------------------------------------------------------------------------ random streams

@st.composite
def tied_rules(draw):
    """Rules deciding by completeness (recent, chronological) over two or three atoms of
    a and b with any operators, sometimes a cnot, a where or a window: mostly parts that
    may end with the terminator."""
    atom = st.builds(lambda name, v: ("leaf", name, (v,)), st.sampled_from(["a", "b"]),
                     st.sampled_from(["X", "X", "_", 0]))
    ops = st.sampled_from(["and", "and", "par", "equals", "meets", "during", "starts",
                           "finishes", "seq"])
    pattern = (draw(ops), draw(atom), draw(atom))
    if draw(st.booleans()):
        pattern = (draw(ops), pattern, draw(atom)) if draw(st.booleans()) else \
            (draw(ops), draw(atom), pattern)
    bound = "X" in repr(pattern)
    where = []
    if bound and draw(st.integers(0, 3)) == 0:
        where.append((draw(st.sampled_from(["<", ">=", "=<"])), "X", draw(st.sampled_from([0, 1]))))
    cnot = None
    if draw(st.integers(0, 3)) == 0:
        cnot = ("c", (draw(st.sampled_from(["X", "_"] if bound else ["_"])),))
    return {"pattern": pattern, "head": ["X"] if bound else [], "where": where, "cnot": cnot,
            "within": draw(st.sampled_from([None, None, 1, 2])),
            "policy": draw(st.sampled_from(["recent", "chronological"]))}


@st.composite
def tied_streams(draw):
    """Events over a few end times (many ties), in end-time order, ties in any order."""
    out = []
    for _ in range(draw(st.integers(2, 9))):
        name = draw(st.sampled_from(["a", "a", "b", "b", "c"]))
        args = tuple(draw(st.sampled_from([0, 1])) for _ in range(TYPES[name]))
        e = float(draw(st.integers(1, 3)))
        out.append((name, args, e - float(draw(st.sampled_from([0, 0, 0, 1]))), e))
    order = draw(st.permutations(range(len(out))))
    return sorted((out[i] for i in order), key=lambda ev: ev[3])


def run_in_order(rule, events, one_by_one: bool, store=None) -> list:
    clock = ManualClock(0.0)
    with slr_sql.open(store, clock=clock) as kb:
        kb.load(f":- consumption({rule['policy']}).\n{IN_ORDER}" + rule_text(rule))
        texts = [_event_text(ev) for ev in events]
        if one_by_one:
            for text in texts:
                kb.add(text)
        else:
            assert kb.add_many(texts) == []
        clock.set(100.0)
        kb.add("tick^100")
        head = rule["head"]
        goal = (f"r({', '.join(head)})" if head else "r") + "^[TS, TE]"
        rows = kb.query(goal)
    return sorted(((tuple(r[v] for v in head), r["TS"], r["TE"]) for r in rows), key=repr)


@settings(max_examples=40, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(tied_rules(), tied_streams())
def test_in_order_streams_with_ties_derive_the_reference_one_by_one(rule, events):
    expected = _typed([(tuple(h), s, e) for h, s, e in reference(rule, events)])
    assert _typed(run_in_order(rule, events, True)) == expected, rule_text(rule)


OPERATORS = ["and", "par", "equals", "meets", "during", "starts", "finishes", "seq"]


@settings(max_examples=20, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.sampled_from(OPERATORS), st.sampled_from(OPERATORS), st.booleans(),
       st.sampled_from(["recent", "chronological", "unrestricted"]),
       st.lists(st.tuples(st.sampled_from("abe"), st.integers(0, 1), st.integers(1, 3),
                          st.sampled_from([0, 0, 1])), min_size=2, max_size=8),
       st.randoms(use_true_random=False))
def test_hierarchies_over_tied_streams_derive_the_same_three_ways(low, high, swap, policy,
                                                                  events, rnd):
    """c(X) <- a(X) op b(X) and d(X) <- e(X) op c(X) (or c first): one by one, at once and
    without in_order, the same c and d events."""
    rnd.shuffle(events)
    events.sort(key=lambda ev: ev[2])
    stream = [f"{n}({v})^{float(e)}" if d == 0 else f"{n}({v})^[{float(e - d)}, {float(e)}]"
              for n, v, e, d in events]
    rules_text = (f"c(X) <- a(X) {low} b(X).\nd(X) <- "
                  + (f"c(X) {high} e(X)." if swap else f"e(X) {high} c(X)."))
    one, once, plain = (derive(None, rules_text, stream, how, policy=policy)
                        for how in ("one", "once", "plain"))
    assert one == once == plain, (rules_text, stream)


def test_in_order_streams_with_ties_on_postgresql_derive_the_reference(postgres_url):
    """Seeded random rules and tied streams, one by one on PostgreSQL, against the
    reference (the SQLite side is the hypothesis test above)."""
    rng = random.Random(12)   # (a seed whose streams lose events without the rule)
    patterns = [("and", "a", "b"), ("equals", "b", "a"), ("during", "b", "a")]
    for n, (op, left, right) in enumerate(patterns):
        rule = {"pattern": (op, ("leaf", left, ("X",)), ("leaf", right, ("X",))),
                "head": ["X"], "where": [], "cnot": None, "within": None,
                "policy": rng.choice(["recent", "chronological"])}
        events = []
        for _ in range(8):
            e = float(rng.randint(1, 3))
            events.append((rng.choice("ab"), (rng.randint(0, 1),),
                           e - rng.choice([0.0, 0.0, 1.0]), e))
        rng.shuffle(events)
        events.sort(key=lambda ev: ev[3])
        expected = _typed([(tuple(h), s, e) for h, s, e in reference(rule, events)])
        got = run_in_order(rule, events, True, _fresh_database(postgres_url, f"r{n}"))
        assert _typed(got) == expected, (rule_text(rule), events)


class _UntickedClock(slr_sql.clocks.Clock):
    """A clock that moves without telling its listeners, as a WallClock does: decisions
    that wait for it are made by the synchronizer's timer."""

    def __init__(self, t: float):
        super().__init__()
        self.t = t

    def now(self) -> float:
        return self.t


def test_the_timer_wakes_a_chronological_decision_for_another_alternatives_type(tmp_path):
    """a(1)^5 waits for k (the other alternative's terminator type) to be complete up to 5:
    on a clock that moves silently, the timer must be set for k's max_delay, not only for
    the types of a(1)^5's own alternative, or the decision waits for the next add."""
    clock = _UntickedClock(5.0)
    with slr_sql.open(str(tmp_path / "k.db"), clock=clock) as kb:
        kb.load(":- consumption(chronological).\n:- in_order(a/1). :- in_order(b/1).\n"
                ":- max_delay(a/1, 1000). :- max_delay(b/1, 1000). :- max_delay(k/1, 0.05).\n"
                "c(X) <- b(_) seq (a(X) or k(X)).")
        derived = threading.Event()
        sub = kb.subscribe("c(X)^[S, E]", since=0.0, callback=lambda answer: derived.set())
        kb.add_many(["b(0)^1", "a(1)^5", "a(9)^6", "b(0)^6"])
        assert _rows(kb, "c") == [] and kb.event_rules()[0]["pending"] > 0
        clock.t = 6.0   # past 5 + max_delay(k): k is complete up to 5, nobody is told
        assert derived.wait(timeout=20), "the timer did not decide a(1)^5"
        assert _rows(kb, "c") == [(1, 1.0, 5.0)]
        sub.close()


# Events of the same times are told apart by their stored values, in SQLite's order (numbers
# by value, then text byte by byte): PostgreSQL's text columns must order them alike, not as
# text (12 before 9, and the atom '9', stored tagged there, after every letter).
TIED_BY_VALUE = [
    ("numbers", [9, 12, 10.0, 100]),
    ("atoms", ["9", "A", "b"]),
    ("numbers and atoms", [12, "12", 9, "9", 1.5]),
]


@pytest.mark.parametrize("policy", ["recent", "chronological"])
@pytest.mark.parametrize("values", [v for _, v in TIED_BY_VALUE],
                         ids=[name for name, _ in TIED_BY_VALUE])
def test_partners_of_the_same_times_are_chosen_by_value_as_on_sqlite(backend, policy, values):
    from test_cep_differential import run

    rule = {"pattern": ("seq", ("leaf", "a", ("X",)), ("leaf", "b", ("Y",))), "head": ["X", "Y"],
            "where": [], "cnot": None, "within": None, "policy": policy}
    events = [("a", (v,), 1.0, 1.0) for v in values] + [("b", (k,), 2.0 + k, 2.0 + k)
                                                         for k in range(len(values) - 1)]
    expected = [(tuple(h), s, e) for h, s, e in reference(rule, events)]
    got = run(rule, events, list(reversed(range(len(events)))), [], False, False, where=backend)
    assert sorted(_typed(_plain(got))) == sorted(_typed(expected))


@pytest.mark.parametrize("values", [v for _, v in TIED_BY_VALUE],
                         ids=[name for name, _ in TIED_BY_VALUE])
def test_chronological_terminators_of_the_same_times_go_by_value_as_on_sqlite(backend, values):
    from test_cep_differential import run

    rule = {"pattern": ("seq", ("leaf", "a", ("_",)), ("leaf", "b", ("Y",))), "head": ["Y"],
            "where": [], "cnot": None, "within": None, "policy": "chronological"}
    events = [("a", (0,), 1.0, 1.0)] + [("b", (v,), 2.0, 2.0) for v in values]
    expected = [(tuple(h), s, e) for h, s, e in reference(rule, events)]
    got = run(rule, events, list(reversed(range(len(events)))), [], False, False, where=backend)
    assert sorted(_typed(_plain(got))) == sorted(_typed(expected))


def _plain(rows: list) -> list:
    """Rows read from a store with their atoms as the reference's str."""
    return [(tuple(str(v) if isinstance(v, str) else v for v in h), s, e) for h, s, e in rows]
