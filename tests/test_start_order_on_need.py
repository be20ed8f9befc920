"""The start-ordered indexes of a complex event type are built on first need.

The table the event-rule engine creates for a rule's head type gets only its end-ordered
indexes ``(t_end, t_start)`` and ``(arg1, t_end, t_start)``; ``(t_start, t_end)`` and
``(arg1, t_start, t_end)`` are built by the first reader in start order (a ``next`` lookup,
the ties at a start, ``bracket``, compiled ``next``, a rule reading the type). Answers are
those of a store whose type was declared up front (all four indexes from the start), on
SQLite and PostgreSQL, through SQL and through the interpreter; a build rolled back leaves
no belief behind, another process's build is found in the catalog, and a reader that cannot
build (another writer holds the lock) still answers.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import slr_sql
from store_holders import table_written
from conftest import postgres_database
from slr_sql import ManualClock

REPO = Path(__file__).resolve().parent.parent

RULE = ":- consumption(unrestricted).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X).\n"
DECLARED = ":- event c/1.\n" + RULE
# a(K)^I and b(K)^(I + 0.5), K = I mod 3: unrestricted pairs every earlier a(K) with a b(K),
# so that many complex events share a start or an end
EVENTS = [f"a({i % 3})^{i}" for i in range(1, 13)] + \
         [f"b({i % 3})^{i + 0.5}" for i in range(4, 13)]
END_INDEXES = {"slr_ix__c__end", "slr_ix__c__a1_end"}
START_INDEXES = {"slr_ix__c__start", "slr_ix__c__a1_start"}
INTERVALS = [(0.0, 100.0), (2.5, 9.0), (5.0, 13.0), (11.5, 100.0)]


def _opened(location: str, program: str, **options) -> slr_sql.KnowledgeBase:
    kb = slr_sql.open(location, clock=ManualClock(100.0), **options)
    kb.load(program)
    kb.add_many(EVENTS)
    return kb


@pytest.fixture
def reference(request, backend, tmp_path):
    """The same store with c/1 declared up front, on the same backend (ties between rows
    go by arrival there): its table has all four indexes."""
    if backend.startswith("postgresql"):
        location = postgres_database(request.getfixturevalue("postgres_server")[1])
    else:
        location = str(tmp_path / "declared.db")
    kb = _opened(location, DECLARED)
    assert END_INDEXES | START_INDEXES <= kb.store.index_names("c")
    yield kb
    kb.close()


def _indexes(kb) -> set[str]:
    """The store's own indexes of c's table (PostgreSQL also lists its primary key's)."""
    return {name for name in kb.store.index_names("c") if name.startswith("slr_ix__")}


def _next(kb, lo: float, hi: float, bound=None) -> list:
    return [row[:3] for row in kb.store.next_candidates("c", 1, bound, lo, hi)]


def _lookups(kb) -> list:
    """Every lookup in start order, over several intervals, bound and not."""
    out = []
    for lo, hi in INTERVALS:
        out.append(_next(kb, lo, hi))
        out.append(_next(kb, lo, hi, {0: 1}))
        first = next(kb.store.next_candidates("c", 1, None, lo, hi), None)
        if first is not None:
            out.append([row[:3] for row in kb.store.rows_at_start("c", 1, None, first[1], hi)])
            out.append([row[:3] for row in kb.store.rows_at_start("c", 1, {0: 1}, first[1], hi)])
    for t in (0.0, 4.5, 7.0, 50.0):
        out.append(kb.store.bracket("c", 1, {0: 2}, t))
    return out


def _queries(kb) -> list:
    return [kb.query(f"next(c(X)^[S, E], [{lo}, {hi}])") for lo, hi in INTERVALS] + \
        [kb.query(f"next(c(2)^[S, E], [{lo}, {hi}])") for lo, hi in INTERVALS]


def test_a_rule_head_table_has_no_start_ordered_index_after_detections(backend):
    with _opened(backend, RULE) as kb:
        assert kb.store.count("c", 1) > 20
        assert _indexes(kb) == END_INDEXES
        # a type created by an added event, or declared, keeps all four
        assert {"slr_ix__a__start", "slr_ix__a__a1_start"} <= kb.store.index_names("a")
        kb.load(":- event d/1.")
        assert {"slr_ix__d__start", "slr_ix__d__a1_start"} <= kb.store.index_names("d")
        # readers in end order build nothing
        assert kb.query("prev(c(X)^[S, E], 9)") and kb.query("c(1)^[S, E]")
        assert _indexes(kb) == END_INDEXES


@pytest.mark.parametrize("reader", ["lookups", "compiled", "interpreted"])
def test_the_first_reader_in_start_order_builds_them_and_answers_as_before(
        backend, reference, reader):
    with _opened(backend, RULE) as kb:
        assert _indexes(kb) == END_INDEXES
        if reader == "lookups":
            assert _lookups(kb) == _lookups(reference)
        else:
            kb.sql_enabled = reader == "compiled"
            if reader == "compiled":
                assert "engine: sql" in kb.explain("next(c(X)^[S, E], [0, 10])")
            answers = _queries(kb)
            assert answers == _queries(reference)
            kb.sql_enabled = True
            assert _queries(kb) == answers   # SQL == interpreter
        assert _indexes(kb) == END_INDEXES | START_INDEXES
        assert _lookups(kb) == _lookups(reference)
        if kb.store.dialect.index_hints:
            assert 'INDEXED BY "slr_ix__c__a1_start"' in kb.store.lookup_sql(
                "next", "c", 1, {0: 1})


def test_a_bracket_builds_them(backend, reference):
    with _opened(backend, RULE) as kb:
        assert kb.store.bracket("c", 1, {0: 1}, 6.0) == reference.store.bracket("c", 1, {0: 1}, 6.0)
        assert _indexes(kb) == END_INDEXES | START_INDEXES


def _in_another_process(location: str, code: str) -> object:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    done = subprocess.run(
        [sys.executable, "-c", "import json, sys\nfrom slr_sql.store import EventStore\n"
         f"store = EventStore({location!r})\n{code}\nstore.close()"],
        env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_another_process_builds_them_and_this_one_finds_them_in_the_catalog(backend):
    with _opened(backend, RULE, busy_timeout=0.3) as kb:
        assert _indexes(kb) == END_INDEXES   # created here: known to lack them
        built = _in_another_process(backend, (
            'rows = [row[:3] for row in store.next_candidates("c", 1, None, 0, 100)]\n'
            'print(json.dumps([sorted(n for n in store.index_names("c") if n[:4] == "slr_"),'
            ' len(rows)]))'))
        assert built == [sorted(END_INDEXES | START_INDEXES), kb.store.count("c", 1)]
        other = table_written(backend)
        try:
            # a build now would wait for the lock past the busy timeout and give up: found
            # in the catalog instead, the indexes are used at once
            assert kb.store.ensure_start_order("c", 1)
            if kb.store.dialect.index_hints:
                assert "INDEXED BY" in kb.store.lookup_sql("next", "c", 1)
        finally:
            other.rollback()
            other.close()
        assert len(_next(kb, 0, 100)) == kb.store.count("c", 1)


def test_a_reader_that_cannot_build_still_answers(backend, reference):
    with _opened(backend, RULE, busy_timeout=0.3) as kb:
        other = table_written(backend)
        try:
            assert _lookups(kb) == _lookups(reference)
            assert _queries(kb) == _queries(reference)
            assert _indexes(kb) == END_INDEXES
            if kb.store.dialect.index_hints:   # (naming a missing index is an error)
                assert "INDEXED BY" not in kb.store.lookup_sql("next", "c", 1)
        finally:
            other.rollback()
            other.close()
        kb.clock.advance(1)   # (a busy build is tried again once the store's clock moved on)
        assert _lookups(kb) == _lookups(reference)
        assert _indexes(kb) == END_INDEXES | START_INDEXES


def test_a_rolled_back_build_leaves_no_belief_behind(backend, reference):
    with _opened(backend, RULE) as kb:
        expected = _next(reference, 0, 100)
        with pytest.raises(RuntimeError):
            with kb.store.transaction():
                stream = kb.store.next_candidates("c", 1, None, 0, 100)
                first = [next(stream)[:3]]   # (built inside the transaction)
                assert _indexes(kb) == END_INDEXES | START_INDEXES
                raise RuntimeError("undo")
        assert _indexes(kb) == END_INDEXES
        # the stream goes on after the rollback, the lookups work: neither names an index
        # the rollback took, and the next reader builds them again
        assert first + [row[:3] for row in stream] == expected
        assert _lookups(kb) == _lookups(reference)
        assert _indexes(kb) == END_INDEXES | START_INDEXES


def test_a_rule_reading_the_complex_type_builds_them(backend, reference):
    with _opened(backend, RULE) as kb:
        assert _indexes(kb) == END_INDEXES
        kb.load(":- max_delay(e/1, 0).\nd(X) <- c(X) seq e(X).")
        assert _indexes(kb) == END_INDEXES | START_INDEXES
        kb.add_many(["e(1)^20", "e(2)^21"])
        derived = sorted((r["X"], r["S"], r["E"]) for r in kb.query("d(X)^[S, E]"))
        # every c(1) and c(2) ends before e's start: one d per c of the same argument
        ends = {1: 20.0, 2: 21.0}
        assert derived == sorted((r["X"], r["S"], ends[r["X"]])
                                 for r in reference.query("c(X)^[S, _]") if r["X"] in ends)
        assert len(derived) > 10
        assert _lookups(kb) == _lookups(reference)
