"""Subscriptions over the WebSocket ``/subscribe`` of a real ``slr serve`` process, through
``slr_sql.connect(url).subscribe``: history then live, where, until released by
``mark_complete`` over HTTP, a durable id resumed after the server was SIGKILLed, clients
that vanish or stop reading, and many subscribers at once."""
from __future__ import annotations

import itertools
import subprocess
import sys
import threading

import pytest

import slr_sql
from slr_sql import Atom
from slr_sql.service.errors import ServiceError

from service_helpers import ServiceProcess, complete_only_as_marked, slr_env

_tags = itertools.count()
DEADLINE = 30.0


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("service_subscribe") / "subs.db"
    with ServiceProcess(db) as s:
        yield s


@pytest.fixture
def remote(server):
    with slr_sql.connect(server.url) as client:
        yield client


@pytest.fixture
def tag() -> str:
    return f"s{next(_tags)}_"


def consume(sub, out: list) -> threading.Thread:
    """Iterate ``sub`` on a thread of its own, appending each answer to ``out`` (and the
    error that ended it, if any)."""
    def run() -> None:
        try:
            for answer in sub:
                out.append(answer)
        except slr_sql.SLRError as exc:
            out.append(exc)
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread


@pytest.mark.parametrize("batch", [1, 256])
def test_history_then_live_with_where_until_completeness(remote, tag, batch):
    complete_only_as_marked(remote, f"{tag}p/1")
    remote.add_many([f"{tag}p({i})^{i}" for i in range(4)])            # history: 0..3
    remote.subscribe_batch = batch
    with remote.subscribe(f"{tag}p(X)^T", where="X > 1", since=1, until=20) as sub:
        remote.add_many([f"{tag}p({i})^{i}" for i in range(4, 12)])    # live: 4..11
        remote.add(f"{tag}p(1)^12")                                    # fails where
        remote.add(f"{tag}p(99)^25")                                   # after until
        got: list = []
        reader = consume(sub, got)
        remote.mark_complete(f"{tag}p/1", 20)                          # releases the end
        reader.join(DEADLINE)
        assert not reader.is_alive()
    assert got == [{"X": i, "T": float(i)} for i in range(2, 12)]


def test_answers_keep_their_terms(remote, tag):
    remote.add(f'{tag}q(cup, "a string", [1, 2.5], f(g(x)), 3)^1')
    with remote.subscribe(f"{tag}q(A, S, L, C, N)^T", since=0, until=1) as sub:
        remote.mark_complete(f"{tag}q/5", 1)
        (answer,) = list(sub)
    local = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    local.add(f'{tag}q(cup, "a string", [1, 2.5], f(g(x)), 3)^1')
    assert answer == local.query(f"{tag}q(A, S, L, C, N)^T")[0]
    assert answer["A"] == Atom("cup") and type(answer["A"]) is Atom
    local.close()


def test_close_ends_an_iteration_blocked_in_another_thread(remote, tag):
    sub = remote.subscribe(f"{tag}p(X)^T")
    got: list = []
    reader = consume(sub, got)
    remote.add(f"{tag}p(1)^1")
    sub.close()
    reader.join(DEADLINE)
    assert not reader.is_alive()
    assert all(not isinstance(a, BaseException) for a in got)
    assert got in ([], [{"X": 1, "T": 1.0}])


def test_bad_batch_is_refused_in_words(remote, tag):
    with pytest.raises(ServiceError) as info:
        remote.subscribe_batch = 0
        remote.subscribe(f"{tag}p(X)^T")
    assert info.value.status == 400 and '"batch"' in str(info.value)


def test_many_concurrent_subscribers_receive_every_event(server, remote, tag):
    n_subs, n_events = 20, 600
    complete_only_as_marked(remote, f"{tag}e/1")
    remote.add(f"{tag}e(-1)^0")
    subs = []
    for k in range(n_subs):
        remote.subscribe_batch = 1 if k % 2 else 64
        subs.append(remote.subscribe(f"{tag}e(I)^T", since=1, until=n_events))
    outs = [[] for _ in subs]
    readers = [consume(s, o) for s, o in zip(subs, outs)]

    def writer(part: int) -> None:
        with slr_sql.connect(server.url) as client:
            for start in range(part, n_events, 40):
                client.add_many([f"{tag}e({i})^{i + 1}" for i in range(start, start + 20)])
    writers = [threading.Thread(target=writer, args=(part,)) for part in (0, 20)]
    for w in writers:
        w.start()
    for w in writers:
        w.join(DEADLINE)
    remote.mark_complete(f"{tag}e/1", n_events)
    for r in readers:
        r.join(DEADLINE)
    expected = sorted(range(n_events))
    for out in outs:
        assert not any(isinstance(a, BaseException) for a in out)
        assert sorted(a["I"] for a in out) == expected       # every event, once
    first = [a["I"] for a in outs[0]]
    assert all([a["I"] for a in out] == first for out in outs)  # one arrival order for all


VANISHING_CLIENT = r"""
import json, sys
from websockets.sync.client import connect
with connect(sys.argv[1]) as ws:
    ws.send(json.dumps({"op": "subscribe", "pattern": sys.argv[2], "since": 0}))
    print(json.loads(ws.recv())["type"], flush=True)
    sys.stdin.read()                 # never reads the socket again; killed by the test
"""


def test_clients_that_vanish_or_stop_reading_do_not_stop_the_others(server, remote, tag):
    ws_url = server.url.replace("http", "ws") + "/subscribe"
    pattern = f"{tag}big(I, S)^T"
    complete_only_as_marked(remote, f"{tag}big/2")
    remote.add(f'{tag}big(-1, "")^0')
    clients = [subprocess.Popen([sys.executable, "-c", VANISHING_CLIENT, ws_url, pattern],
                                stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=slr_env())
               for _ in range(3)]
    try:
        for c in clients:
            assert c.stdout.readline().strip() == b"subscribed"
        with remote.subscribe(pattern, since=0, until=3000) as sub:
            got: list = []
            reader = consume(sub, got)
            payload = "x" * 400                  # enough to fill the stalled sockets
            for start in range(0, 1500, 100):
                remote.add_many([f'{tag}big({i}, "{payload}")^{i}' for i in
                                 range(start, start + 100)])
            clients[0].kill()                    # vanishes mid-subscription
            clients[0].wait(DEADLINE)
            for start in range(1500, 3000, 100):
                remote.add_many([f'{tag}big({i}, "{payload}")^{i}' for i in
                                 range(start, start + 100)])
            remote.mark_complete(f"{tag}big/2", 3000)
            reader.join(DEADLINE)
            assert [a["I"] for a in got] == list(range(-1, 3000))
        assert server.healthy()
        assert remote.query(f"{tag}big(2999, _)^T") == [{"T": 2999.0}]
    finally:
        for c in clients:
            c.kill()
            c.wait(DEADLINE)
            c.stdout.close()
            c.stdin.close()


def test_a_client_killed_while_its_sends_are_held_back_ends_quietly(tmp_path):
    """A client that stopped reading holds back its own subscription's sends (the server
    waits for its socket to drain); killed, it is found gone by that send or by the server's
    read, whichever comes first: its subscription ends without a word in the server's log
    (no error, no traceback), and the server serves on."""
    with ServiceProcess(tmp_path / "held_back.db") as server:
        with slr_sql.connect(server.url) as remote:
            complete_only_as_marked(remote, "big/2")
            remote.add('big(-1, "")^0')
            client = subprocess.Popen([sys.executable, "-c", VANISHING_CLIENT,
                                       server.url.replace("http", "ws") + "/subscribe",
                                       "big(I, S)^T"],
                                      stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      env=slr_env())
            try:
                assert client.stdout.readline().strip() == b"subscribed"
                with remote.subscribe("big(I, S)^T", since=0, until=3000) as sub:
                    got: list = []
                    reader = consume(sub, got)
                    payload = "x" * 400              # enough to fill the stalled socket
                    for start in range(0, 3000, 100):
                        remote.add_many([f'big({i}, "{payload}")^{i}' for i in
                                         range(start, start + 100)])
                    remote.mark_complete("big/2", 3000)
                    reader.join(DEADLINE)            # everything went out to the reader
                    assert [a["I"] for a in got] == list(range(-1, 3000))
                    client.kill()
                    client.wait(DEADLINE)
                    remote.add_many(['big(3000, "")^3000'])
                    assert server.healthy()
            finally:
                client.kill()
                client.wait(DEADLINE)
                client.stdout.close()
                client.stdin.close()
    log = server.log.read_text()
    assert "Traceback" not in log and "error" not in log.lower(), log


def test_durable_subscription_resumes_after_the_server_is_killed(tmp_path):
    db = tmp_path / "durable.db"
    pattern, n = "d(I)^T", 60
    received: list = []
    server = ServiceProcess(db)
    try:
        with slr_sql.connect(server.url) as client:
            complete_only_as_marked(client, "d/1")
            client.add("d(0)^0")
            client.subscribe_batch = 8
            sub = client.subscribe(pattern, since=1, until=n, id="resume-me")
            client.add_many([f"d({i})^{i}" for i in range(1, 31)])    # answered writes
            for answer in sub:
                received.append(answer["I"])
                if len(received) == 10:
                    server.kill()                                     # SIGKILL
            # the iteration ended with an error once the connection was gone: every answer
            # the server had sent before it died was still handed over
    except ServiceError as exc:
        assert exc.status == 0
    finally:
        server.stop()
    assert received == list(range(1, len(received) + 1)) and len(received) >= 10

    with ServiceProcess(db) as again, slr_sql.connect(again.url) as client:
        client.add_many([f"d({i})^{i}" for i in range(31, n + 1)])
        with client.subscribe(pattern, since=1, until=n, id="resume-me") as sub:
            client.mark_complete("d/1", n)
            resumed = [a["I"] for a in sub]
    # at least once, no gap: it resumes at or before the first answer not received
    assert resumed and resumed[0] <= received[-1] + 1
    assert resumed == list(range(resumed[0], n + 1))
    assert set(received) | set(resumed) == set(range(1, n + 1))


def test_a_client_gone_before_the_handshake_is_accepted_leaves_no_error(tmp_path, caplog):
    """A client that closes its connection between its upgrade request and the server's
    accept: uvicorn's send of the accept raises ClientDisconnected. Nobody is left to answer,
    so /subscribe ends quietly: no "internal error" line with a traceback in the server's
    log (any client can do this). The app is called as uvicorn calls it, with uvicorn's own
    exception for the vanished peer."""
    import asyncio
    import logging

    from uvicorn.protocols.utils import ClientDisconnected

    from slr_sql.service.app import create_app

    kb = slr_sql.open(tmp_path / "gone.db")
    sent: list[dict] = []

    async def receive() -> dict:
        return {"type": "websocket.connect"}

    async def send(message: dict) -> None:
        sent.append(message)
        raise ClientDisconnected()

    scope = {"type": "websocket", "path": "/subscribe", "raw_path": b"/subscribe",
             "query_string": b"", "headers": [], "scheme": "ws", "server": ("127.0.0.1", 80),
             "client": ("127.0.0.1", 5000), "root_path": "", "subprotocols": [],
             "asgi": {"version": "3.0"}}
    try:
        with caplog.at_level(logging.DEBUG, logger="slr_sql"):
            asyncio.run(create_app(kb)(scope, receive, send))
    finally:
        kb.close()
    assert [m["type"] for m in sent] == ["websocket.accept"]
    assert [r for r in caplog.records if r.levelno >= logging.WARNING or r.exc_info] == []
