"""Event rules on PostgreSQL against the naive reference, and several writers against one.

tests/test_cep_differential.py holds the reference evaluator and runs its comparisons on
SQLite in memory; tests/test_postgres.py runs the plain operator rules on the server in two
batches, and tests/test_cep_postgres_clock_differential.py compares the server with SQLite. Here the
rest of that differential contract runs on the server itself, each example in a schema of
its own database:

* every operator (seq, and, par, or, equals, meets, during, starts, finishes, cnot, where,
  within) under every consumption policy, in a random arrival order, cut in random batches
  or added one event at a time, with completeness marks interleaved or none == the
  reference; the same for where goals run by the interpreter;
* any arrival order == in-order arrival;
* one add_many == the same events added one by one, with a count buffer pruning a type
  the rule reads;
* two rules in two named programs, each with its own consumption policy == the reference
  under each rule's own policy;
* several writers: the stream's events shared out between two knowledge bases on one store
  (each its own connection, as two processes have), their adds interleaved, detect what the
  reference detects -- each match once -- on SQLite files and on PostgreSQL.
"""
from __future__ import annotations

import itertools
import os

import pytest
import test_cep_differential as cepdiff
from hypothesis import HealthCheck, example, given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock

_SCHEMAS = itertools.count()
# a longer hunt: SLR_DIFF_FACTOR=20 runs each test with twenty times its examples
FACTOR = int(os.environ.get("SLR_DIFF_FACTOR", "1"))
SETTINGS = dict(deadline=None, suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def database(postgres_server):
    """One database for the module's examples, a schema each."""
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


def _schema(database: str) -> str:
    return database + ("&" if "?" in database else "?") + f"schema=e{next(_SCHEMAS)}"


@settings(max_examples=20 * FACTOR, **SETTINGS)
@given(cepdiff.rules(), cepdiff.streams(), st.data())
def test_every_operator_and_policy_on_postgres_equals_the_reference(database, rule, events,
                                                                    data):
    cepdiff.equals_the_reference(rule, events, data, may_add_one_by_one=True,
                                 where=_schema(database))


@settings(max_examples=15 * FACTOR, **SETTINGS)
@given(cepdiff.where_rules(), cepdiff.ab_streams(), st.data())
def test_where_run_by_the_interpreter_on_postgres_equals_the_reference(database, rule, events,
                                                                       data):
    cepdiff.equals_the_reference(rule, events, data, may_add_one_by_one=True,
                                 where=_schema(database))


@settings(max_examples=10 * FACTOR, **SETTINGS)
@given(cepdiff.rules(), cepdiff.streams(), st.data())
def test_any_arrival_order_on_postgres_gives_the_in_order_complex_events(database, rule,
                                                                         events, data):
    in_order = sorted(range(len(events)), key=lambda i: (events[i][3], events[i][2]))
    permuted = data.draw(st.permutations(range(len(events))), label="arrival order")
    first = cepdiff.run(rule, events, in_order, [], False, False, where=_schema(database))
    again = cepdiff.run(rule, events, permuted, [1, 3], True, False, where=_schema(database))
    assert cepdiff._typed(first) == cepdiff._typed(again), cepdiff.rule_text(rule)


@settings(max_examples=10 * FACTOR, **SETTINGS)
@given(cepdiff.two_type_rules(), cepdiff.ab_points(), st.data())
def test_a_batch_on_postgres_derives_what_its_events_derive_one_by_one_with_buffers(
        database, rule, events, data):
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    name = data.draw(st.sampled_from(["a", "b"]), label="buffered type")
    key = data.draw(st.sampled_from(["_", "K"]), label="buffer key")
    keep = data.draw(st.integers(1, 2), label="keep last")
    buffer = f"\ncBuffer({name}({key}), {keep})."
    one = cepdiff.run(rule, events, order, [], False, True, buffer, where=_schema(database))
    batch = cepdiff.run(rule, events, order, [len(events)], False, False, buffer,
                        where=_schema(database))
    assert cepdiff._typed(one) == cepdiff._typed(batch), cepdiff.rule_text(rule) + buffer


@settings(max_examples=10 * FACTOR, **SETTINGS)
@given(cepdiff.program_cases())
@example(cepdiff.TWO_POLICIES)
def test_two_programs_on_postgres_each_pair_events_by_their_own_policy(database, case):
    cepdiff.programs_equal_the_reference(case, where=_schema(database))


# ------------------------------------------------------------------ several writers

def run_shared(where: str, rule: dict, events: list, order: list[int], writers: list[int],
               marks: bool) -> list:
    """``events`` added in ``order`` through two knowledge bases on one store, the k-th
    add through ``writers[k]`` (a mark after an event through the same writer); the clock
    then passes everything. The stored complex events, as cepdiff.run returns them."""
    clock = ManualClock(0.0)
    kbs = [slr_sql.open(where, clock=clock) for _ in range(2)]
    try:
        kbs[0].load(f":- consumption({rule['policy']}).\n" + cepdiff.rule_text(rule)
                    + ("\n" + cepdiff.WHERE_PROGRAM if rule.get("interpret") else ""))
        sequence = [events[i] for i in order]
        for k, ev in enumerate(sequence):
            kb = kbs[writers[k]]
            items = [cepdiff._event_text(ev)]
            if marks:
                rest = [x for x in sequence[k + 1:] if x[0] == ev[0]]
                t = min([x[3] for x in rest], default=100.0) - 0.5
                if t > 0:
                    items.append(f"fullyUpdated({ev[0]}/{cepdiff.TYPES[ev[0]]})^{t}")
            assert kb.add_many(items) == []
        clock.set(100.0)
        for kb in kbs:   # each writer's next call sees the clock's decisions made
            kb.query("true")
        arity = len(rule["head"])
        rows = list(kbs[1].store.scan("r", arity))
    finally:
        for kb in kbs:
            kb.close()
    return sorted(((tuple(args), s, e) for args, s, e, _ in rows), key=repr)


@st.composite
def shared_streams(draw):
    """A rule, a stream, an arrival order and which of two writers adds each event: by
    type (one producer per sensor) or at random."""
    rule = draw(st.one_of(cepdiff.rules(), cepdiff.where_rules()))
    events = draw(cepdiff.streams())
    order = draw(st.permutations(range(len(events))))
    if draw(st.booleans()):
        owner = {name: draw(st.integers(0, 1)) for name in cepdiff.TYPES}
        writers = [owner[events[i][0]] for i in order]
    else:
        writers = [draw(st.integers(0, 1)) for _ in order]
    return rule, events, order, writers, draw(st.booleans())


def _shared_equals_the_reference(where: str, case) -> None:
    rule, events, order, writers, marks = case
    got = run_shared(where, rule, events, order, writers, marks)
    want = sorted(((tuple(h), s, e) for h, s, e in cepdiff.reference(rule, events)), key=repr)
    assert cepdiff._typed(got) == cepdiff._typed(want), (cepdiff.rule_text(rule), order,
                                                          writers)


@settings(max_examples=20 * FACTOR, **SETTINGS)
@given(shared_streams())
def test_two_writers_on_one_sqlite_file_detect_what_the_reference_detects(tmp_path_factory,
                                                                          case):
    _shared_equals_the_reference(str(tmp_path_factory.mktemp("w") / "s.db"), case)


@settings(max_examples=10 * FACTOR, **SETTINGS)
@given(shared_streams())
def test_two_writers_on_postgres_detect_what_the_reference_detects(database, case):
    _shared_equals_the_reference(_schema(database), case)


# ------------------------------------------------------------------ values of colliding kinds

@st.composite
def mixed_streams(draw):
    """cepdiff.streams with data values that SQL may confuse: 1, 1.0 and the atoms '1'
    and 'a' (PostgreSQL stores each as typed text, SQLite 1 and '1' in one column)."""
    out = []
    for _ in range(draw(st.integers(1, 8))):
        name = draw(st.sampled_from(["a", "b", "c", "d"]))
        args = tuple(draw(st.sampled_from([0, 1, 1.0, "1", "a"]))
                     for _ in range(cepdiff.TYPES[name]))
        s = float(draw(st.integers(0, 6)))
        out.append((name, args, s, s + float(draw(st.sampled_from([0, 0, 1, 2])))))
    return out


def _kinds(rows):
    """Rows with each value's kind: an atom read back (slr_sql.Atom) is the str it was."""
    return [(tuple(("atom" if isinstance(v, str) else type(v).__name__, v) for v in args), s, e)
            for args, s, e in rows]


@settings(max_examples=15 * FACTOR, **SETTINGS)
@given(cepdiff.rules(), mixed_streams(), st.data())
def test_values_of_colliding_kinds_match_as_prolog_terms_on_both_backends(database, rule,
                                                                          events, data):
    rule = {**rule, "where": []}   # (a comparison with an atom is a type error)
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    cuts = data.draw(st.lists(st.integers(0, len(events)), max_size=2), label="batches")
    _match_as_prolog_terms(database, rule, events, order, cuts)


def _match_as_prolog_terms(database, rule, events, order, cuts):
    want = cepdiff.reference(rule, events)
    for where in (None, _schema(database)):
        got = cepdiff.run(rule, events, order, cuts, False, False, where=where)
        # (sorted by kind and value: the rows as read, an Atom('1') beside a 0, and the
        # reference's, a str '1', sort apart by repr)
        assert sorted(_kinds(got), key=repr) == sorted(_kinds(want), key=repr), (
            where, cepdiff.rule_text(rule))


def test_an_atom_and_a_number_of_one_rule_are_compared_as_terms_not_in_read_order(database):
    rule = {"pattern": ("seq", ("leaf", "b", ("X",)), ("leaf", "a", ("_",))), "head": ["X"],
            "where": [], "cnot": None, "within": None, "policy": "unrestricted"}
    events = [("a", (0,), 1.0, 1.0), ("b", (0,), 0.0, 0.0), ("b", ("1",), 0.0, 0.0)]
    _match_as_prolog_terms(database, rule, events, [0, 1, 2], [])
