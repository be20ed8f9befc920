"""PostgreSQL keeps what SQLite keeps: random buffers over random event streams, with an
event rule reading the buffered type and completeness marks, added one by one or in batches,
on both backends side by side (the differential contract PostgreSQL == SQLite).

One database for the module; each example opens its stores in a schema of its own.
"""
from __future__ import annotations

import itertools
from urllib.parse import parse_qsl, urlencode, urlsplit, urlunsplit

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql import ManualClock
from slr_sql.parser import parse_term
from slr_sql.terms import format_term, from_python
from slr_sql.unify import copy_term, unify

from conftest import postgres_database
from test_buffers import VALUES, add_buffers, buffer_strategy, time_strategy

RULE = "r(X) <- (p(X, _)) seq (q(X))."

# few distinct values: events often share a buffer's key, so buffers have work to do
FEW = st.sampled_from([VALUES[0], VALUES[1], VALUES[2], VALUES[4], VALUES[6], VALUES[8]])
event_strategy = st.tuples(st.sampled_from(["p", "p", "p", "q"]), FEW, FEW, time_strategy,
                           st.sampled_from([0, 0, 0, 0.5, 2]))
op_strategy = st.one_of(
    st.tuples(st.just("add"), st.lists(event_strategy, min_size=1, max_size=10)),
    st.tuples(st.just("tick"), st.sampled_from([0, 0.5, 1, 2.5, 4])),
    st.tuples(st.just("mark"), st.sampled_from(["p/2", "q/1"])),
)
_schemas = itertools.count(1)


@pytest.fixture(scope="module")
def pg_database(postgres_server):
    return postgres_database(postgres_server[1])


def in_schema(url: str, schema: str) -> str:
    parts = urlsplit(url)
    query = parse_qsl(parts.query) + [("schema", schema)]
    return urlunsplit(parts._replace(query=urlencode(query)))


def typed(value):
    """A comparison key that keeps 1, 1.0, the atom a and the string "a" apart."""
    return format_term(from_python(value)) + ":" + type(value).__name__


def contents(kb) -> dict:
    """What the store holds: the rows of every type (decoded), and each buffer's counters."""
    out = {}
    for name, arity in (("p", 2), ("q", 1), ("r", 1)):
        if kb.store.table_for(name, arity) is not None:
            out[name] = sorted((tuple(typed(a) for a in args), start, end)
                               for args, start, end, *_ in kb.store.scan(name, arity, {}))
    out["buffers"] = sorted((b.kind, b.pattern, b.pruned, b.dropped) for b in kb.buffers())
    return out


@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                 HealthCheck.function_scoped_fixture])
@given(buffers=st.lists(buffer_strategy, min_size=1, max_size=3),
       ops=st.lists(op_strategy, min_size=1, max_size=10), one_by_one=st.booleans())
def test_postgres_keeps_and_derives_what_sqlite_does(pg_database, buffers, ops, one_by_one):
    terms = [parse_term(text, "<x>")[0] for _, text, _ in buffers]
    for i, j in itertools.combinations(range(len(terms)), 2):
        assume(not unify(copy_term(terms[i]), copy_term(terms[j]), []))
    url = in_schema(pg_database, f"example{next(_schemas)}")
    stores = [slr_sql.open(None, clock=ManualClock(0.0)),
              slr_sql.open(url, clock=ManualClock(0.0))]
    try:
        for kb in stores:
            kb.load(RULE)
            add_buffers(kb, buffers)
        for step, (op, arg) in enumerate(ops):
            for kb in stores:
                if op == "tick":
                    kb.clock.advance(arg)
                elif op == "mark":
                    kb.add(f"fullyUpdated({arg})^{kb.clock.now() + 1}")
                else:
                    batch = [(name, [a1, a2] if name == "p" else [a1],
                              float(max(0.0, end - length)), float(end))
                             for name, a1, a2, end, length in arg]
                    if one_by_one:
                        for event in batch:
                            assert kb.add_many([event]) == []
                    else:
                        assert kb.add_many(batch) == []
            sqlite, postgres = (contents(kb) for kb in stores)
            assert postgres == sqlite, f"after step {step}: {op} {arg}"
        for kb in stores:
            kb.clock.set(100.0)   # every decision waiting for time is made
        sqlite, postgres = (contents(kb) for kb in stores)
        assert postgres == sqlite
    finally:
        for kb in stores:
            kb.close()



@pytest.mark.parametrize("pattern", ["p(f(X), X)", "p([X, _], X)", "p([X, 1.0], _)",
                                     "p(g(1.0, K), _)", "p(g(X, K), X)"])
@pytest.mark.parametrize("installed", ["before the events", "after the events"])
def test_count_buffers_indexed_inside_a_compound_keep_what_sqlite_does(pg_database, pattern,
                                                                       installed):
    """A count buffer whose key lies inside a compound gets a partial index over the rows it
    governs. Its predicate named slr_json_same (a variable both whole and inside a compound)
    or slr_json_float (a float inside one): SQL functions that call the store's other
    helpers by their bare names, which CREATE INDEX does not find from PostgreSQL 17 on (it
    runs with search_path = pg_catalog, pg_temp), so every add of the type failed with "the
    store failed (function slr_typeof(text) does not exist)", and so did a buffer installed
    over stored rows."""
    events = ["p(f(1), 1)^1", "p(f(1), 1)^2", "p(f(2), 1)^3", "p([1, 1.0], 1)^4",
              "p([1, 1.0], 2)^5", "p([2, 1.0], 2)^6", "p(g(1.0, k), 1.0)^7",
              "p(g(1.0, k), 1.0)^8", "p(g(1, k), 1)^9", "p(g(1, k), 1)^10", "p(1, f(1))^11",
              "p([5, x], 5)^12", "p([5, y], 5)^13"]
    url = in_schema(pg_database, f"example{next(_schemas)}")
    stores = [slr_sql.open(None, clock=ManualClock(0.0)),
              slr_sql.open(url, clock=ManualClock(0.0))]
    try:
        for kb in stores:
            if installed == "before the events":
                kb.add_buffer(pattern, keep_last=1)
                assert kb.add_many(events[:5]) == []
                assert [kb.add(event) for event in events[5:]] == [None] * 8
            else:
                assert kb.add_many(events) == []
                kb.add_buffer(pattern, keep_last=1)
                assert kb.add_many(["p(f(3), 3)^14", "p([3, 1.0], 3)^15"]) == []
        sqlite, postgres = (contents(kb) for kb in stores)
        assert postgres == sqlite
        assert sqlite["buffers"][0][2] > 0   # (the buffer pruned)
    finally:
        for kb in stores:
            kb.close()


def test_concurrent_writers_keep_the_count_of_a_key(postgres_url):
    """Two connections add events of one key of a count buffer while the first's transaction
    is open: the second waits for it and prunes what it stored (without the buffer's lock,
    each would keep its own newest event and the key would hold two)."""
    import threading
    import time

    import psycopg

    first = slr_sql.open(postgres_url, clock=ManualClock(10.0))
    second = slr_sql.open(postgres_url, clock=ManualClock(10.0))
    try:
        first.add_buffer("p(K, _)", keep_last=1)
        first.add("p(a, 1)^1")
        second.buffers()   # (the program and buffers as stored)
        done = threading.Event()
        errors: list = []

        def write() -> None:
            try:
                second.add("p(a, 3)^3")
            except Exception as exc:  # noqa: BLE001 - reported by the assertion below
                errors.append(exc)
            done.set()

        with first.store.transaction():
            first.add("p(a, 2)^2")
            writer = threading.Thread(target=write)
            writer.start()
            # until the second writer waits on a lock (a deadline, no pause): the first's
            # transaction is open, so a writer that finishes meanwhile did not wait for it
            with psycopg.connect(postgres_url, autocommit=True) as watch:
                deadline = time.monotonic() + 20.0
                while not watch.execute(
                        "SELECT count(*) FROM pg_stat_activity WHERE datname = "
                        "current_database() AND wait_event_type = 'Lock'").fetchone()[0]:
                    assert not done.is_set(), \
                        f"the second writer finished without waiting for the first: {errors}"
                    assert time.monotonic() < deadline, "the second writer never waited on a lock"
                    done.wait(0.01)
        writer.join(20.0)
        assert not writer.is_alive() and errors == []
        assert [a["V"] for a in first.query("p(a, V)^T")] == [3]
        (info,) = first.buffers()
        assert (info.pruned, info.dropped) == (2, 0)
    finally:
        first.close()
        second.close()


def test_a_writer_records_its_now_for_a_time_buffer_another_process_added(postgres_url):
    """A writer that had no time buffer when it last looked still records its clock's now
    once another connection added one, so the buffer judges its events by it."""
    writer = slr_sql.open(postgres_url, clock=ManualClock(200.0))
    other = slr_sql.open(postgres_url, clock=ManualClock(100.0))
    try:
        writer.add("p(a)^190")                       # no buffer yet: nothing to record
        other.add_buffer("p(_)", keep_seconds=5)     # recorded now: the other's 100
        assert writer.add_many([("p", ("b",), 150.0, 150.0), ("p", ("c",), 199.0, 199.0)]) == []
        # judged at the writer's 200: 150 < 200 - 5 is late, 199 is kept; 190 expired
        assert [a["X"] for a in writer.query("p(X)^T")] == ["c"]
        (info,) = writer.buffers()
        assert (info.pruned, info.dropped) == (1, 1)
    finally:
        writer.close()
        other.close()
