"""Values of kilobytes in indexed positions: PostgreSQL answers as SQLite does. A B-tree
entry of PostgreSQL holds at most ~2.7 KB, so a long key must not reach one as it is: a
fact's first argument has a hash index, every other B-tree over a text users choose holds
slr_key(text) (migration pg_0013; docs/postgres.md, "Long values")."""
from __future__ import annotations

import random
import string


import slr_sql
from slr_sql import ManualClock, fleet

# random letters: a repeated letter would be compressed by PostgreSQL below the limit and prove
# nothing
LONG = "".join(random.Random(7).choices(string.ascii_lowercase, k=10_000))
OTHER = "".join(random.Random(8).choices(string.ascii_lowercase, k=10_000))


def test_a_fact_whose_first_argument_is_ten_kilobytes_loads_and_answers_on_both(backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(f"f('{LONG}', 1).\nf(short, 2).\n")
        assert [a["N"] for a in kb.query(f"f('{LONG}', N)")] == [1]
        assert [a["N"] for a in kb.query("f(short, N)")] == [2]
        assert sorted(len(a["X"]) for a in kb.query("f(X, _)")) == [5, 10_000]


def test_an_event_whose_first_argument_is_ten_kilobytes_is_stored_and_found(backend):
    """Stored alone and in a batch (it was the event's EventRejected on PostgreSQL), found
    by an event goal, prev and next, compiled and interpreted."""
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.add_event("e", [LONG, 1], 1.0, 1.0)
        assert kb.add_many([("e", [OTHER, 2], 2.0, 2.0), "e(short, 3)^3.0",
                            ("e", [LONG, 4], 4.0, 4.0)]) == []
        for compiled in (True, False):
            kb.sql_enabled = compiled
            assert [a["N"] for a in kb.query(f"e('{LONG}', N)^T")] == [1, 4]
            assert [a["N"] for a in kb.query(f"prev(e('{LONG}', N)^T, 3.5)")] == [1]
            assert [a["N"] for a in kb.query(f"next(e('{OTHER}', N)^T, [0, 9])")] == [2]
            assert [a["N"] for a in kb.query("e(short, N)^T")] == [3]
            for value, found in ((LONG, [1, 4]), ("short", [3]), (OTHER, [2])):   # (args)
                assert [a["N"] for a in kb.query("e(X, N)^T", args={"X": value})] == found
                assert [a["N"] for a in kb.query("prev(e(X, N)^S, T)",
                                                 args={"X": value, "T": 9})] == found[-1:]
            assert sorted(len(a["X"]) for a in kb.query("e(X, _)^T")) == [5] + [10_000] * 3
        assert [a["N"] for a in kb.query("e(X, N)^T, e(X, M)^T2, M > N")] == [1]


def test_an_event_type_whose_name_is_ten_kilobytes(backend):
    name = "t" + LONG
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.add_event(name, [1], 1.0)
        assert [a["X"] for a in kb.query(f"{name}(X)^T")] == [1]


def test_a_complex_event_whose_first_value_is_ten_kilobytes(backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(":- consumption(recent).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n"
                "c(X) <- a(X) seq b(X).\n")
        kb.add_event("a", [LONG], 1.0, 1.0)
        kb.add_event("b", [LONG], 2.0, 2.0)
        assert [len(a["X"]) for a in kb.query("c(X)^[S, E]")] == [10_000]


def test_a_complete_history_of_a_type_named_by_ten_kilobytes(backend):
    """A completeness mark is kept under a key naming its type."""
    name = "t" + LONG
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        kb.mark_complete(f"{name}/1", 5.0)
        assert kb.complete_until(f"{name}/1") == 5.0


def test_an_event_rule_joining_on_a_later_argument_of_ten_kilobytes(backend):
    """The rule searches b by its second argument (an index of its own, built by the rule)."""
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(":- max_delay(a/2, 0).\n:- max_delay(b/2, 0).\nc(X) <- a(_, X) seq b(_, X).\n")
        kb.add_many([("a", [1, LONG], 1.0, 1.0), ("a", [2, OTHER], 1.5, 1.5), ("b", [3, LONG], 2.0, 2.0)])
        assert [(a["X"] == LONG, a["S"], a["E"]) for a in kb.query("c(X)^[S, E]")] == [
            (True, 1.0, 2.0)]


def test_a_count_buffer_keyed_by_a_first_argument_of_ten_kilobytes(backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.add_buffer("e(K, _)", keep_last=1)
        kb.add_many([("e", [LONG, 1], 1.0, 1.0), ("e", [LONG, 2], 2.0, 2.0),
                     ("e", [OTHER, 3], 3.0, 3.0), "e(short, 4)^4.0"])
        assert sorted((len(a["K"]), a["N"]) for a in kb.query("e(K, N)^T")) == [
            (5, 4), (10_000, 2), (10_000, 3)]


def test_a_count_buffer_keyed_by_a_later_argument_of_ten_kilobytes(backend):
    """Its key has an index of its own (slr_bix_N; on PostgreSQL two, short and long keys),
    made once: a store opened again finds the buffer's objects as this version makes them."""
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        buffer = kb.add_buffer("e(_, K)", keep_last=1)
        kb.add_many([("e", [1, LONG], 1.0, 1.0), ("e", [2, LONG], 2.0, 2.0),
                     ("e", [3, OTHER], 3.0, 3.0), "e(4, short)^4.0"])
        assert [a["N"] for a in kb.query("e(N, _)^T")] == [2, 3, 4]
        objects = kb.store.buffer_objects(buffer)
        assert (f"slr_bix_{buffer}_k" in objects) == backend.startswith("postgres")
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        assert kb.store.buffer_objects(buffer) == objects
        kb.add_event("e", [5, LONG], 5.0)
        assert [a["N"] for a in kb.query("e(N, _)^T")] == [3, 4, 5]


def test_a_durable_subscription_whose_id_is_ten_kilobytes(backend):
    """Its position is kept under its id: a second subscription of the id resumes after the
    answer handled (closed normally), and it is removed by the id."""
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        with kb.subscribe("p(X)^T", id=LONG, since=0) as sub:
            kb.add_event("p", [1], 1.0)
            assert sub.get(timeout=30) == {"X": 1, "T": 1.0}
        kb.add_event("p", [2], 2.0)
        with kb.subscribe("p(X)^T", id=LONG, since=0) as again:
            assert again.id == LONG
            assert again.get(timeout=30) == {"X": 2, "T": 2.0}
        kb.unsubscribe(LONG)
        with kb.subscribe("p(X)^T", id=LONG, since=0) as fresh:   # (from the start again)
            assert fresh.get(timeout=30) == {"X": 1, "T": 1.0}


def test_a_program_named_by_ten_kilobytes(backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load("p(1).\n", name=LONG)
        kb.load("p(2).\n", name=OTHER)
        assert [a["X"] for a in kb.query("p(X)")] == [1, 2]
        kb.unload(LONG)
        assert [a["X"] for a in kb.query("p(X)")] == [2]
        assert set(kb.programs()) == {OTHER}


def test_a_robot_ships_a_type_named_by_ten_kilobytes_to_a_fleet_store(tmp_path, backend):
    name = "t" + LONG
    robot = tmp_path / "r1.db"
    with slr_sql.open(robot, robot="r1", clock=ManualClock(1000.0)) as kb:
        kb.add_event(name, [LONG], 10.0)
    assert fleet.push(str(robot), backend).shipped == 1
    with slr_sql.open(robot, robot="r1", clock=ManualClock(1000.0)) as kb:
        kb.add_event(name, [OTHER], 20.0)
    assert fleet.push(str(robot), backend).shipped == 1     # (from its position on)
    with slr_sql.open(backend, clock=ManualClock(1000.0)) as kb:
        assert [(a["R"], a["X"] == LONG, a["T"]) for a in kb.query(f"origin(R, {name}(X)^T)")] \
            == [("r1", True, 10.0), ("r1", False, 20.0)]
