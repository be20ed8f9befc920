"""Acknowledged WebSocket subscriptions (``"ack": true``) on a real ``slr serve`` process: a
durable subscriber killed mid-stream loses nothing it had not acknowledged, the server sends
at most ``subscribe_queue`` unacknowledged answers, bad acks are refused in words (4400), the
protocol without acks is unchanged, and ``slr_sql.connect(url).subscribe`` acknowledges what
its consumer handled."""
from __future__ import annotations

import itertools
import json
import subprocess
import sys
import time

import pytest
from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect as ws_connect

import slr_sql

from service_helpers import ServiceProcess, slr_env

_tags = itertools.count()
DEADLINE = 30.0
BOUND = 1000          # the server's default subscribe_queue: answers unacknowledged at most


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("service_ack") / "ack.db"
    with ServiceProcess(db) as s:
        yield s


@pytest.fixture
def client(server):
    with slr_sql.connect(server.url) as c:
        yield c


@pytest.fixture
def tag() -> str:
    return f"k{next(_tags)}_"


def ws_url(server) -> str:
    return server.url.replace("http", "ws", 1) + "/subscribe"


def subscribe(server, **request):
    """A raw WebSocket subscribed with ``request``; returns (socket, the subscribed message)."""
    ws = ws_connect(ws_url(server)).__enter__()
    ws.send(json.dumps({"op": "subscribe", **request}))
    return ws, json.loads(ws.recv(timeout=DEADLINE))


def frame(ws) -> tuple[str, int, list]:
    """(type, seq of its first answer, answers) of the next message."""
    msg = json.loads(ws.recv(timeout=DEADLINE))
    if msg["type"] == "answers":
        return "answers", msg["seq"], msg["answers"]
    if msg["type"] == "answer":
        return "answers", msg["seq"], [msg["answer"]]
    return msg["type"], 0, [msg]


def receive(ws, count: int, first_seq: int = 1, acked: int = 0) -> list:
    """The next ``count`` answers, numbered from ``first_seq`` (checking that no frame goes
    past ``acked`` + BOUND: flow control)."""
    got: list = []
    while len(got) < count:
        kind, seq, answers = frame(ws)
        assert kind == "answers", answers
        assert seq == first_seq + len(got)
        got.extend(answers)
        assert seq + len(answers) - 1 <= acked + BOUND
    return got


def error_and_close_code(ws) -> tuple[dict, int]:
    """The error message the server sends, then the code it closes with."""
    while True:
        kind, _, answers = frame(ws)
        if kind == "error":
            break
        assert kind == "answers"
    with pytest.raises(ConnectionClosed) as info:
        ws.recv(timeout=DEADLINE)
    return answers[0]["error"], info.value.rcvd.code


def resubscribe(server, **request):
    """Subscribe again with a durable id once the server closed the previous connection's
    subscription (it notices a vanished client at once; a deadline loop, not a pause)."""
    deadline = time.monotonic() + DEADLINE
    while True:
        ws, first = subscribe(server, **request)
        if first["type"] == "subscribed":
            return ws
        ws.close()
        # a condition that may pass: retryable, as the loop here does (its words are the
        # service's general ones for the kind, "delivered elsewhere now")
        assert (first["error"]["kind"], first["error"]["status"]) == \
            ("SLRSubscriptionInUse", 503), first
        assert time.monotonic() < deadline, first


ACKING_CLIENT = r"""
import json, sys
from websockets.sync.client import connect
url, pattern, sid = sys.argv[1:4]
receive, ack = int(sys.argv[4]), int(sys.argv[5])
ws = connect(url).__enter__()
ws.send(json.dumps({"op": "subscribe", "pattern": pattern, "since": 0, "id": sid,
                    "ack": True, "batch": 50}))
assert json.loads(ws.recv())["type"] == "subscribed"
got = []
def more():
    msg = json.loads(ws.recv())
    got.extend(msg["answers"] if msg["type"] == "answers" else [msg["answer"]])
while len(got) < receive:
    more()
ws.send(json.dumps({"op": "ack", "seq": ack}))
more()        # the server sent more: it took the ack (it was at its bound)
print(json.dumps([a["I"] for a in got]), flush=True)
sys.stdin.read()                       # killed by the test, acks and socket as they are
"""


def test_a_killed_client_gets_again_every_answer_it_did_not_acknowledge(server, client, tag):
    n, acked = 1200, 400
    pattern = f"{tag}a(I)^T"
    client.add_many([f"{tag}a({i})^{i}" for i in range(1, n + 1)])
    proc = subprocess.Popen([sys.executable, "-c", ACKING_CLIENT, ws_url(server), pattern,
                             f"{tag}durable", str(BOUND), str(acked)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=slr_env())
    try:
        received = json.loads(proc.stdout.readline())
    finally:
        proc.kill()                      # SIGKILL: no close frame
        proc.wait(DEADLINE)
        proc.stdout.close()
        proc.stdin.close()
    # the server stopped at its bound until the ack, then went on
    assert received[:BOUND] == list(range(1, BOUND + 1)) and len(received) > BOUND
    ws = resubscribe(server, pattern=pattern, since=0, id=f"{tag}durable", ack=True,
                     batch=100)
    try:
        resumed = [a["I"] for a in receive(ws, n - acked)]
    finally:
        ws.close()
    # every answer after the last acknowledged one, again; nothing acknowledged twice
    assert resumed == list(range(acked + 1, n + 1))


def test_a_closed_durable_subscription_resumes_after_the_last_ack(server, client, tag):
    pattern = f"{tag}c(I)^T"
    client.add_many([f"{tag}c({i})^{i}" for i in range(1, 31)])
    ws, first = subscribe(server, pattern=pattern, since=0, id=f"{tag}d", ack=True, batch=5)
    assert first["type"] == "subscribed" and first["ack_window"] == BOUND
    assert [a["I"] for a in receive(ws, 30)] == list(range(1, 31))
    ws.send(json.dumps({"op": "ack", "seq": 12}))
    ws.send(json.dumps({"op": "close"}))          # a clean close: unacked stay unhandled
    ws.close()
    ws = resubscribe(server, pattern=pattern, since=0, id=f"{tag}d", ack=True, batch=5)
    try:
        assert [a["I"] for a in receive(ws, 18)] == list(range(13, 31))
    finally:
        ws.close()


def test_without_ack_the_protocol_is_unchanged(server, client, tag):
    """No ack_window, ack messages ignored, no flow control by acks: a client that never
    acknowledges gets everything up to the end."""
    n = BOUND + 300
    pattern = f"{tag}b(I)^T"
    client.add_many([f"{tag}b({i})^{i}" for i in range(1, n + 1)])
    ws, first = subscribe(server, pattern=pattern, since=0, until=n, batch=100)
    try:
        assert first == {"type": "subscribed", "pattern": pattern, "id": None}
        ws.send(json.dumps({"op": "ack", "seq": 10 ** 9}))       # ignored
        client.mark_complete(f"{tag}b/1", n)
        got = []
        while True:
            kind, seq, answers = frame(ws)
            if kind == "end":
                break
            assert kind == "answers" and seq == len(got) + 1
            got.extend(a["I"] for a in answers)
        assert got == list(range(1, n + 1))
    finally:
        ws.close()


@pytest.mark.parametrize("ack", [
    {"op": "ack", "seq": "3"}, {"op": "ack", "seq": 2.0}, {"op": "ack", "seq": True},
    {"op": "ack"}, {"op": "ack", "seq": 4}, {"op": "ack", "seq": 2}, "not json with \"ack\""],
    ids=["string", "float", "bool", "missing", "beyond-sent", "backwards", "not-json"])
def test_a_bad_ack_is_an_error_and_4400_and_the_server_serves_on(server, client, tag, ack):
    pattern = f"{tag}e(I)^T"
    client.add_many([f"{tag}e({i})^{i}" for i in range(1, 4)])
    ws, first = subscribe(server, pattern=pattern, since=0, ack=True)
    try:
        assert [a["I"] for a in receive(ws, 3)] == [1, 2, 3]   # all sent: none beyond 3
        ws.send(json.dumps({"op": "ack", "seq": 3}))
        ws.send(ack if isinstance(ack, str) else json.dumps(ack))
        error, code = error_and_close_code(ws)
    finally:
        ws.close()
    assert code == 4400 and error["kind"] == "BadRequest" and "bad ack" in error["message"]
    assert server.healthy()
    other, first = subscribe(server, pattern=pattern, since=0, ack=True)
    try:
        assert [a["I"] for a in receive(other, 3)] == [1, 2, 3]
    finally:
        other.close()


def test_ack_must_be_a_boolean(server, tag):
    ws, first = subscribe(server, pattern=f"{tag}x(I)^T", ack="yes")
    try:
        assert first["type"] == "error" and '"ack"' in first["error"]["message"]
        with pytest.raises(ConnectionClosed) as info:
            ws.recv(timeout=DEADLINE)
        assert info.value.rcvd.code == 4400
    finally:
        ws.close()


def test_flow_control_a_client_that_does_not_ack_gets_at_most_the_bound(server, client, tag):
    n = BOUND + 500
    pattern = f"{tag}f(I)^T"
    client.add_many([f"{tag}f({i})^{i}" for i in range(1, n + 1)])
    ws, first = subscribe(server, pattern=pattern, since=0, until=n, ack=True, batch=64)
    try:
        client.mark_complete(f"{tag}f/1", n)
        got = [a["I"] for a in receive(ws, BOUND)]            # all waiting, bound reached
        ws.send(json.dumps({"op": "ack", "seq": 300}))
        got += [a["I"] for a in receive(ws, 300, BOUND + 1, acked=300)]   # 300 more, not one beyond
        # the server sent exactly 1300: an ack of 1301 is "beyond what was sent"
        ws.send(json.dumps({"op": "ack", "seq": BOUND + 301}))
        error, code = error_and_close_code(ws)
        assert code == 4400 and f"({BOUND + 300})" in error["message"]
        assert got == list(range(1, BOUND + 301))
    finally:
        ws.close()
    # acking as it goes, a client gets everything, then the end
    ws, first = subscribe(server, pattern=pattern, since=0, until=n, ack=True, batch=64)
    try:
        got, acked = [], 0
        while True:
            kind, seq, answers = frame(ws)
            if kind == "end":
                break
            assert seq == len(got) + 1 and seq + len(answers) - 1 <= acked + BOUND
            got.extend(a["I"] for a in answers)
            if len(got) - acked >= 400:
                acked = len(got)
                ws.send(json.dumps({"op": "ack", "seq": acked}))
            elif len(got) == n:
                ws.send(json.dumps({"op": "ack", "seq": n}))   # the end waits for it
        assert got == list(range(1, n + 1))
    finally:
        ws.close()


CONSUMER = r"""
import sys, slr_sql
url, pattern, sid, until, stop = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
client = slr_sql.connect(url)
sub = client.subscribe(pattern, since=0, until=until, id=sid)
for k, answer in enumerate(sub, 1):
    print(answer["I"], flush=True)
    if k == stop:
        print("stop", flush=True)
        sys.stdin.read()               # mid-stream, holding an answer: killed by the test
"""


def test_a_remote_consumer_killed_mid_stream_resumes_with_no_gap(server, client, tag):
    n, stop = 2500, 700
    pattern = f"{tag}r(I)^T"
    client.add_many([f"{tag}r({i})^{i}" for i in range(1, n + 1)])
    proc = subprocess.Popen([sys.executable, "-c", CONSUMER, server.url, pattern, f"{tag}rid",
                             str(n), str(stop)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=slr_env())
    printed: list = []
    try:
        for line in proc.stdout:
            if line.strip() == b"stop":
                break
            printed.append(int(line))
    finally:
        proc.kill()
        proc.wait(DEADLINE)
        proc.stdout.close()
        proc.stdin.close()
    assert printed == list(range(1, stop + 1))
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            sub = client.subscribe(pattern, since=0, until=n, id=f"{tag}rid")
            break
        except slr_sql.SLRSubscriptionInUse as exc:   # until the server saw the client vanish
            assert time.monotonic() < deadline, exc
    with sub:
        client.mark_complete(f"{tag}r/1", n)
        resumed = [a["I"] for a in sub]
    # at least once, no gap: it resumes at or before the answer the consumer held
    assert resumed and resumed[0] <= stop
    assert resumed == list(range(resumed[0], n + 1))


def test_a_remote_subscription_acknowledges_what_its_consumer_handled(server, client, tag):
    pattern = f"{tag}h(I)^T"
    client.add_many([f"{tag}h({i})^{i}" for i in range(1, 21)])
    with client.subscribe(pattern, since=0, until=20, id=f"{tag}hid") as sub:
        got = [next(sub)["I"] for _ in range(8)]
    assert got == list(range(1, 9))
    # closed normally: the eighth counts as handled too; the rest comes again
    deadline = time.monotonic() + DEADLINE
    while True:
        try:
            sub = client.subscribe(pattern, since=0, until=20, id=f"{tag}hid")
            break
        except slr_sql.SLRSubscriptionInUse as exc:   # until the server saw it closed
            assert time.monotonic() < deadline, exc
    with sub:
        client.mark_complete(f"{tag}h/1", 20)
        assert [a["I"] for a in sub] == list(range(9, 21))


def test_a_remote_subscription_batches_its_acknowledgements(server, client, tag):
    n = 3000
    pattern = f"{tag}m(I)^T"
    client.add_many([f"{tag}m({i})^{i}" for i in range(1, n + 1)])
    with client.subscribe(pattern, since=0, until=n) as sub:
        client.mark_complete(f"{tag}m/1", n)
        got = [a["I"] for a in sub]
        assert got == list(range(1, n + 1))
        # one per half window (500) handled, or per wait for answers that did not come
        assert 1 <= sub.acks_sent <= n // 50
