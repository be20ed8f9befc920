"""Many knowledge bases, processes and threads on one file: the file is the truth.

Each knowledge base sees, at its next call, the programs, declarations, buffers, learned
delays and completeness marks another one (in this process or another) wrote; delays and
marks only grow; one kb's load never removes what another loaded; threads sharing one kb do
not break each other's statements; lock waits are bounded and reported as ``SLRBusy``.
"""
from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
from pathlib import Path

import pytest

import slr_sql
from slr_sql import EventRejected, ManualClock, SLRBusy, SLRError

REPO = Path(__file__).resolve().parent.parent

TEA = "findall(O, (obj(O, T)^_, usedFor(T, tea)), L)"


def opened(path, **options):
    """A store at ``path`` (None: in memory) with a ManualClock: the events here are stamped
    1, 2, ... (not wall-clock times, which would make each type's first event "decades
    late", a LearnedDelayWarning), and no test here waits on the store's time."""
    return slr_sql.open(path, clock=ManualClock(0.0), **options)


def answers(kb, goal):
    """The answers of ``goal`` through the compiled SQL and through the interpreter."""
    out = []
    for sql in (True, False):
        kb.sql_enabled = sql
        try:
            out.append(kb.query(goal))
        finally:
            kb.sql_enabled = True
    return out


def python(code: str, *args: str, stdin=None, **popen) -> subprocess.Popen:
    """A Python child process running ``code`` with this checkout importable."""
    prelude = f"import sys; sys.path.insert(0, {str(REPO)!r})\n"
    return subprocess.Popen([sys.executable, "-c", prelude + textwrap.dedent(code), *args],
                            stdin=stdin, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, cwd=str(REPO), **popen)


# ------------------------------------------------------------------ programs of other kbs

def test_every_kb_answers_on_the_union_of_the_stored_programs(db_path):
    a, b = opened(db_path), opened(db_path)
    try:
        a.load("usedFor(cup, tea). usedFor(pan, tea). usedFor(pot, tea). "
               "usedFor(jar, tea). usedFor(bowl, tea).")
        b.load("usedFor(mug, tea). usedFor(glass, tea). usedFor(flask, tea). "
               "usedFor(tumbler, tea). usedFor(beaker, tea).")
        a.load("x(1).")   # used to rewrite the shared fact tables from a's program alone
        b.add_many(["obj(m1, mug)^1", "obj(c1, cup)^2"])
        expected = [{"L": ["m1", "c1"]}]
        with opened(db_path) as c:
            for kb in (a, b, c):
                assert answers(kb, TEA) == [expected, expected]
    finally:
        a.close()
        b.close()


def test_a_program_loaded_by_another_process_is_seen_at_the_next_call(db_path, tmp_path):
    with opened(db_path) as kb:
        kb.add("obj(m1, mug)^1")
        assert kb.query("obj(O, mug)^_") == [{"O": "m1"}]
        program = tmp_path / "tea.slr"
        program.write_text("usedFor(mug, tea).\nready :- true.\n", encoding="utf-8")
        loader = subprocess.run([sys.executable, "-m", "slr_sql", "load", str(db_path),
                                 str(program)], cwd=str(REPO), capture_output=True, text=True)
        assert loader.returncode == 0, loader.stderr
        assert kb.query("ready") == [{}]
        assert answers(kb, TEA) == [[{"L": ["m1"]}]] * 2


def test_declarations_of_another_kb_are_seen_at_the_next_call(db_path):
    clock = ManualClock(100.0)
    a, b = slr_sql.open(db_path, clock=clock), slr_sql.open(db_path, clock=clock)
    try:
        assert b.complete_until("p/1") == 100.0
        a.load(":- max_delay(p/1, 5).")
        assert b.complete_until("p/1") == 95.0
        a.load(":- event(r/2).")
        assert b.complete_until("r") == 100.0  # r/2 is known: one arity, no error
    finally:
        a.close()
        b.close()


def test_marks_and_learned_delays_of_another_kb_are_seen_at_the_next_call(db_path):
    clock = ManualClock(100.0)
    a, b = slr_sql.open(db_path, clock=clock), slr_sql.open(db_path, clock=clock)
    try:
        assert b.complete_until("p/1") == 100.0 and b.complete_until("q/1") == 100.0
        a.mark_complete("p/1", 150.0)
        a.add("q(1)^90")          # arrives at 100: a delay of 10 s is learned
        assert b.complete_until("p/1") == 150.0
        assert b.complete_until("q/1") == 90.0
    finally:
        a.close()
        b.close()


def test_learned_delays_and_marks_never_go_back(db_path):
    clock = ManualClock(100.0)
    a, b = slr_sql.open(db_path, clock=clock), slr_sql.open(db_path, clock=clock)
    try:
        b.add("q(0)^100")         # b learns delay 0 and knows no mark: stale from now on
        a.add("q(1)^90")          # a learns 10
        a.mark_complete("p/1", 50.0)
        b.add("q(2)^99")          # b sees a delay of 1
        b.mark_complete("p/1", 20.0)
        b.close()
        with opened(db_path) as c:
            assert c.complete_until("q/1") == -10.0   # now 0 - learned delay 10
            assert c.complete_until("p/1") == 50.0    # the mark
    finally:
        a.close()


def test_a_stale_writer_cannot_lower_what_is_stored(db_path):
    """The store keeps the maximum even when a writer's own copy is behind (two stores on
    one file, the second never re-reading)."""
    from slr_sql.store import EventStore

    with EventStore(db_path) as first, EventStore(db_path) as second:
        assert first.meta_raise("sync/learned/q/1", 10.0) == 10.0
        assert second.meta_raise("sync/learned/q/1", 1.0) == 10.0
        assert second.meta_raise("sync/mark/p/1", 50.0) == 50.0
        assert first.meta_raise("sync/mark/p/1", 20.0) == 50.0
        assert first.meta_raise("sync/mark/p/1", float("inf")) == float("inf")
        assert second.meta_raise("sync/mark/p/1", 1e308) == float("inf")
        assert first.meta_get("sync/learned/q/1") == 10.0


def test_one_kbs_load_keeps_the_buffers_of_another(db_path):
    a, b = opened(db_path), opened(db_path)
    try:
        a.load("cBuffer(p(_), 2).")
        b.load("q(1).")
        for kb in (a, b):
            assert [(info.kind, info.pattern) for info in kb.buffers()] == [("cBuffer", "p(_)")]
        b.add_many([f"p({i})^{i}" for i in range(5)])
        assert b.sql("SELECT arg1 FROM p ORDER BY t_end")[1] == [(3,), (4,)]
        b.load("r(1).")
        a.add("p(9)^9")
        assert a.sql("SELECT arg1 FROM p ORDER BY t_end")[1] == [(4,), (9,)]
    finally:
        a.close()
        b.close()


def test_fact_tables_follow_the_stored_programs_not_a_stale_copy(db_path):
    a, b = opened(db_path), opened(db_path)
    try:
        facts = " ".join(f"f({i})." for i in range(6))
        a.load(facts)
        b.load("g(1).")   # b had not seen f/1: it must not drop a's fact table
        b.add_many([f"e({i})^{i}" for i in range(8)])
        goal = "findall(X, (e(X)^_, f(X)), L)"
        for kb in (a, b):
            assert answers(kb, goal) == [[{"L": [0, 1, 2, 3, 4, 5]}]] * 2
    finally:
        a.close()
        b.close()


# ------------------------------------------------------------------ threads

@pytest.fixture(params=["memory", "file"])
def shared_kb(request, tmp_path):
    kb = opened(None if request.param == "memory" else tmp_path / "robot.db")
    try:
        yield kb
    finally:
        kb.close()


def run_paused_query(kb, goal):
    """Start ``goal`` in a thread; it stops inside its first call of ``pause/1`` (its event
    scan is open then) until the returned ``go`` event is set."""
    paused, go = threading.Event(), threading.Event()
    result: dict = {}

    def pause(x):
        if not paused.is_set():
            paused.set()
            assert go.wait(60)
        return True

    kb.define("pause", 1, pause)

    def run():
        try:
            result["answers"] = kb.query(goal)
        except BaseException as exc:  # reported by the test
            result["error"] = exc

    thread = threading.Thread(target=run)
    thread.start()
    assert paused.wait(60), result
    return thread, go, result


@pytest.mark.parametrize("interfere", ["rejected atomic batch", "load twice", "buffer"])
def test_a_write_in_one_thread_does_not_break_a_query_in_another(shared_kb, interfere):
    kb = shared_kb
    kb.add_many([f"p({i})^{i}" for i in range(100)])
    kb.sql_enabled = False   # the interpreter: an event scan stays open across pause/1
    thread, go, result = run_paused_query(kb, "findall(X, (p(X)^_, pause(X)), L)")
    try:
        if interfere == "rejected atomic batch":
            # creates the table of a new type, then rolls back: a schema change undone
            with pytest.raises(EventRejected):
                kb.add_many(["fresh(1)^1", ("fresh", [slr_sql.Var("X")], 2.0, 2.0)],
                            atomic=True)
        elif interfere == "load twice":
            facts = " ".join(f"f({i})." for i in range(6))
            kb.load(facts)
            kb.load("g(1).")   # rebuilds the fact tables
        else:
            kb.add_buffer("p(_)", keep_last=200)
            kb.add_many([f"p({i})^{i}" for i in range(100, 110)])
    finally:
        go.set()
        thread.join(60)
    assert "error" not in result, result.get("error")
    found = result["answers"][0]["L"]
    assert found[:100] == list(range(100))


def test_threads_adding_and_querying_one_kb_get_no_raw_errors(tmp_path):
    kb = opened(tmp_path / "robot.db")
    errors: list = []
    stop = threading.Event()

    def writer():
        try:
            for i in range(60):
                kb.add_many([f"p({i})^{i}"])
                with pytest.raises(EventRejected):
                    kb.add_many([f"t{i}(1)^1", ("x", [slr_sql.Var("V")], 1.0, 1.0)],
                                atomic=True)
        except BaseException as exc:
            errors.append(exc)
        finally:
            stop.set()

    def reader():
        try:
            while not stop.is_set():
                kb.sql_enabled = False
                kb.query("findall(X, p(X)^_, L)")
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=writer), threading.Thread(target=reader)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    kb.close()
    assert errors == []


# ------------------------------------------------------------------ locks and close

HOLD_WRITE_LOCK = """
    import sqlite3, sys
    conn = sqlite3.connect(sys.argv[1], isolation_level=None)
    conn.execute("BEGIN IMMEDIATE")
    conn.execute("INSERT INTO slr_meta (key, value) VALUES ('held', '1')")
    print("locked", flush=True)
    sys.stdin.readline()
    conn.execute("ROLLBACK")
"""

HOLD_READ_TRANSACTION = """
    import sqlite3, sys, os
    uri = "file:" + os.path.abspath(sys.argv[1]) + "?mode=ro"
    conn = sqlite3.connect(uri, uri=True, isolation_level=None)
    conn.execute("BEGIN")
    conn.execute("SELECT count(*) FROM slr_meta").fetchall()
    print("reading", flush=True)
    sys.stdin.readline()
    conn.execute("COMMIT")
"""


def holding(code: str, path: Path) -> subprocess.Popen:
    child = python(code, str(path), stdin=subprocess.PIPE)
    line = child.stdout.readline()
    assert line.strip() in ("locked", "reading"), child.stderr.read()
    return child


def release(child: subprocess.Popen) -> None:
    child.stdin.write("\n")
    child.stdin.flush()
    child.wait(60)
    child.stdout.close()
    child.stderr.close()
    child.stdin.close()


def test_open_and_read_while_another_process_holds_the_write_lock(db_path):
    with opened(db_path) as kb:
        kb.load("usedFor(cup, tea). cBuffer(obj(_, _), 5). ready.")
        kb.add("obj(c1, cup)^1")
    child = holding(HOLD_WRITE_LOCK, db_path)
    try:
        with opened(db_path, busy_timeout=0.2) as kb:   # no write needed to open
            assert answers(kb, TEA) == [[{"L": ["c1"]}]] * 2
            assert kb.query("ready") == [{}]
            with pytest.raises(SLRBusy) as info:
                kb.add("obj(c2, cup)^2")
            assert str(db_path) in str(info.value)
            with pytest.raises(SLRBusy):
                kb.load("more(1).")
            with pytest.raises(SLRBusy):
                kb.mark_complete("obj/2", 5.0)
    finally:
        release(child)
    with opened(db_path) as kb:
        kb.add("obj(c2, cup)^2")
        assert answers(kb, TEA) == [[{"L": ["c1", "c2"]}]] * 2


def test_slrbusy_is_an_slrerror_exported_by_the_package():
    assert issubclass(SLRBusy, SLRError) and "SLRBusy" in slr_sql.__all__


def test_busy_timeout_must_be_a_duration(db_path):
    with pytest.raises(SLRError):
        slr_sql.open(db_path, busy_timeout=-1)


def test_close_does_not_wait_for_a_reader_in_another_process(db_path):
    kb = opened(db_path, busy_timeout=60)
    kb.add_many([f"p({i})^{i}" for i in range(1000)])
    child = holding(HOLD_READ_TRANSACTION, db_path)
    try:
        closer = threading.Thread(target=kb.close)
        closer.start()
        closer.join(20)   # a hang guard: close used to wait busy_timeout for the reader
        assert not closer.is_alive(), "close() waited for another process's reader"
    finally:
        release(child)
    with opened(db_path) as again:
        assert again.query("findall(X, p(X)^_, L), length(L, N)")[0]["N"] == 1000
