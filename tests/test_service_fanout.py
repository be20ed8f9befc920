"""Fan-out to many subscribers: answers taken in batches (``Subscription.next_answers``), the
same answer dicts shared by the subscriptions of one pattern, and the service encoding each
answer's JSON once for all its WebSocket subscribers — each subscriber must still receive
exactly its own answers, numbered in its own sequence. Also: the service's JSON (orjson
where it reads and writes as Python's json does) against Python's json."""
from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import math
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from websockets.sync.client import connect as ws_connect

import slr_sql
from slr_sql import ManualClock, SLRError
from slr_sql.subscriptions import SubscriptionState
from slr_sql.service.app import _AnswerTexts
from slr_sql.service.encoding import dumps, loads

from service_helpers import HTTP, ServiceProcess, complete_only_as_marked

_tags = itertools.count()
DEADLINE = 30.0


@pytest.fixture
def kb(tmp_path):
    with slr_sql.open(tmp_path / "fanout.db", clock=ManualClock(0)) as kb:
        yield kb


async def _turns_until(condition, what: str) -> None:
    """Give the event loop turns until ``condition()`` holds: its tasks need a few turns, not
    time, so a thousand turns without it fail the test (not a hang until the suite's
    timeout)."""
    for _ in range(1000):
        if condition():
            return
        await asyncio.sleep(0)
    raise AssertionError(f"not within 1000 turns of the event loop: {what}")


def drained(kb) -> None:
    assert kb._subscriptions.drain(DEADLINE)


# -- Subscription.next_answers --------------------------------------------------------------

def test_next_answers_takes_what_is_queued_in_order_up_to_the_limit(kb):
    sub = kb.subscribe("p(X)^T", since=0)
    kb.add_many([f"p({i})^{i}" for i in range(1, 8)])
    drained(kb)

    async def take() -> list:
        batches = [await sub.next_answers(3)]
        batches.append(await sub.next_answers(3))
        batches.append(await sub.next_answers(3))
        return batches
    batches = asyncio.run(take())
    assert [[a["X"] for a in b] for b in batches] == [[1, 2, 3], [4, 5, 6], [7]]
    assert sub.delivered == 7
    sub.close()


def test_a_batch_that_empties_the_queue_registers_the_next_calls_wait(kb):
    """Taking the batch that empties the queue registers, under the same lock, the wait of the
    next call (one lock per frame of the service): an answer queued while the consumer is
    away is taken by the next call at once, and one queued while it waits wakes it."""
    kb.add("p(0)^0")
    sub = kb.subscribe("p(X)^T", since=0.5)
    drained(kb)

    async def take() -> tuple:
        loop = asyncio.get_running_loop()
        await loop.run_in_executor(None, kb.add_many, ["p(1)^1", "p(2)^2"])
        await loop.run_in_executor(None, drained, kb)
        first = await sub.next_answers(10)
        registered = sub._async_waiter is not None
        await loop.run_in_executor(None, kb.add, "p(3)^3")     # queued while it is away
        await loop.run_in_executor(None, drained, kb)
        second = await asyncio.wait_for(sub.next_answers(10), DEADLINE)
        waiting = asyncio.ensure_future(sub.next_answers(10))
        await _turns_until(lambda: sub._async_waiter is not None and not sub._queue,
                           "the wait registered, nothing queued")
        await asyncio.sleep(0)                                  # (it waits now)
        await loop.run_in_executor(None, kb.add, "p(4)^4")     # queued while it waits
        third = await asyncio.wait_for(waiting, DEADLINE)
        return registered, [[a["X"] for a in b] for b in (first, second, third)]
    registered, batches = asyncio.run(take())
    assert registered
    assert batches == [[1, 2], [3], [4]]
    sub.close()


def test_a_wait_left_registered_on_a_closed_loop_is_not_waited_on(kb):
    """The wait a batch registered belongs to its loop: a call on another loop (the first
    closed) registers its own, and the next answer wakes it."""
    sub = kb.subscribe("p(X)^T", since=0)
    kb.add("p(1)^1")
    drained(kb)
    assert [a["X"] for a in asyncio.run(sub.next_answers(10))] == [1]

    async def wait_for_the_next() -> list:
        waiting = asyncio.ensure_future(sub.next_answers(10))
        await asyncio.sleep(0)
        # (it waits, on this loop, before the answer comes: the answer must wake it)
        assert sub._async_waiter is not None and not waiting.done()
        assert sub._async_waiter[0] is asyncio.get_running_loop()
        await asyncio.get_running_loop().run_in_executor(None, kb.add, "p(2)^2")
        return await asyncio.wait_for(waiting, DEADLINE)
    assert [a["X"] for a in asyncio.run(wait_for_the_next())] == [2]
    sub.close()


def test_shared_answers_are_the_same_dicts_and_copies_are_not(kb):
    kb.add("p(0)^0")                  # the type exists: every subscription starts live
    subs = [kb.subscribe("p(X)^T", since=0.5) for _ in range(3)]
    other = kb.subscribe("p(X)^T", where="X > 2", since=0.5)
    drained(kb)                       # all four in the shared read of the journal
    kb.add_many([f"p({i})^{i}" for i in range(1, 5)])
    drained(kb)

    async def take() -> tuple:
        shared = [await s.next_answers(10, copy=False) for s in subs[:2]]
        copied = await subs[2].next_answers(10)
        own = await other.next_answers(10, copy=False)
        return shared, copied, own
    (first, second), copied, own = asyncio.run(take())
    assert [a["X"] for a in first] == [1, 2, 3, 4] and len(first) == len(second)
    assert all(a is b for a, b in zip(first, second))           # one dict per answer
    assert copied == first and all(a is not b for a, b in zip(copied, first))
    assert [a["X"] for a in own] == [3, 4]                       # its own condition
    for s in subs + [other]:
        s.close()


def test_a_batch_counts_as_handled_when_the_next_one_is_asked_for(tmp_path):
    path = tmp_path / "durable.db"
    with slr_sql.open(path, clock=ManualClock(0)) as kb:
        sub = kb.subscribe("p(X)^T", since=0, id="batches")
        kb.add_many([f"p({i})^{i}" for i in range(1, 6)])
        drained(kb)

        async def take() -> tuple:
            got = await sub.next_answers(2)
            before = sub.position()                 # the batch is still in the consumer's hands
            await sub.next_answers(2)
            return got, before, sub.position()
        got, before, after = asyncio.run(take())
        assert [a["X"] for a in got] == [1, 2]
        assert before < after
        sub.close(ack=False)                        # the second batch was not handled
    with slr_sql.open(path, clock=ManualClock(0)) as kb:
        sub = kb.subscribe("p(X)^T", since=0, id="batches")
        drained(kb)
        assert [a["X"] for a in asyncio.run(sub.next_answers(10))] == [3, 4, 5]
        sub.close()


def test_the_end_and_the_ending_error_come_after_the_answers_queued_before_them(kb):
    ends = kb.subscribe("p(X)^T", since=0, until=3)
    fails = kb.subscribe("p(X)^T", since=0, max_queue=2, max_lag=3)
    kb.add_many([f"p({i})^{i}" for i in range(1, 3)])
    kb.mark_complete("p/1", 3)
    kb.add_many([f"p({i})^{i}" for i in range(4, 11)])   # fails falls behind, then too far
    drained(kb)
    drained(kb)

    async def take(sub) -> list:
        out: list = []
        while True:
            try:
                batch = await sub.next_answers(100)
            except SLRError as exc:
                return out + [type(exc).__name__]
            if not batch:
                return out + ["end"]
            out.extend(a["X"] for a in batch)
    assert asyncio.run(take(ends)) == [1, 2, "end"]
    got = asyncio.run(take(fails))
    assert got[-1] == "SubscriptionOverflow" and got[:-1] == list(range(1, len(got)))


class _Marker:
    """A waker that is no future (what the service's fan-out gives take_answers)."""

    def done(self) -> bool:
        return False

    def set_result(self, _) -> None:
        pass


def test_take_answers_says_take_again_when_the_end_is_behind_and_a_close_meanwhile_ends(kb):
    """A batch followed by the subscription's end registers no waker (nothing will wake
    it): waits_with says take again, and a close() landing between the two takes (the
    client's, from another thread) leaves the next take ending, not waiting forever."""
    sub = kb.subscribe("p(X)^T", since=0, until=3)
    kb.add_many(["p(1)^1", "p(2)^2"])
    kb.mark_complete("p/1", 3)
    deadline = time.monotonic() + DEADLINE
    while sub.state is not SubscriptionState.ENDED:      # the end queued behind the answers
        assert time.monotonic() < deadline
        drained(kb)
    loop = asyncio.new_event_loop()
    try:
        waker = (loop, _Marker())
        assert [a["X"] for a in sub.take_answers(10, waker)] == [1, 2]
        assert not sub.waits_with(waker)
        sub.close()
        assert sub.take_answers(10, waker) is None
        assert sub.take_answers(10, waker) is None
    finally:
        loop.close()


def test_a_whole_batch_offered_hands_its_waiting_async_consumer_over_at_once(kb):
    """The hub's shared read queues a batch and takes the waiting async consumer's waker
    under the same lock (``offer_all(..., loops)``): its future goes to ``loops`` for the
    pass to resolve, it is no longer registered, and the wake after it finds nothing to do.
    Without ``loops`` the waker stays for :meth:`Subscription.wake`."""
    sub = kb.subscribe("p(X)^T", since=0)
    drained(kb)
    loop = asyncio.new_event_loop()
    try:
        waker = (loop, loop.create_future())
        assert sub.take_answers(10, waker) == [] and sub.waits_with(waker)
        answer = {"X": 1, "T": 1.0}
        assert sub.offer_all([10**9, answer], 1, 10**9)          # (no loops: left for wake)
        assert sub.waits_with(waker)
        assert sub.take_answers(10, waker) == [answer]
        loops: dict = {}
        assert sub.offer_all([10**9 + 1, answer], 1, 10**9 + 1, loops)
        assert loops == {loop: [waker[1]]} and not sub.waits_with(waker)
        woken: dict = {}
        sub.wake(woken)
        assert woken == {}
    finally:
        loop.close()
    sub.close()


def test_a_consumer_handed_over_is_woken_when_the_rest_of_its_pass_fails(kb):
    """The shared read hands a waiting async consumer over to the pass (``offer_all``'s
    ``loops``): it is no longer registered with its subscription, so only that pass can wake
    it. A failure later in the same pass (the store busy for the read of a subscriber behind,
    retried on the next tick) must not drop it: the consumer would wait for ever, whatever
    is queued after, and close() would not reach it either."""
    hub = kb._subscriptions
    sub = kb.subscribe("p(X)^T", since=0)
    behind = kb.subscribe("p(X)^T", since=0, max_queue=1)
    kb.add_many(["p(1)^1", "p(2)^2"])
    drained(kb)
    assert behind.state is SubscriptionState.LAGGING     # read apart from the shared read
    loop = asyncio.new_event_loop()
    read = hub._journal_rows
    reads: list = []

    def busy_for_the_one_behind(info, after_jid, limit):
        if after_jid == behind_at:
            reads.append(after_jid)
            raise SLRError("the store is busy (injected)")
        return read(info, after_jid, limit)
    try:
        assert [a["X"] for a in sub.take_answers(10, (loop, loop.create_future()))] == [1, 2]
        waker = (loop, loop.create_future())
        assert sub.take_answers(10, waker) == [] and sub.waits_with(waker)
        behind_at = behind.scanned
        hub._journal_rows = busy_for_the_one_behind
        try:
            # room for one more: the passes from now on read for it after the shared read
            assert [a["X"] for a in behind.take_answers(10, (loop, loop.create_future()))] == [1]
            kb.add_many(["p(3)^3"])
            drained(kb)
        finally:
            hub._journal_rows = read
        assert reads                    # a pass failed after its shared read queued p(3)
        loop.run_until_complete(asyncio.wait_for(asyncio.shield(waker[1]), DEADLINE))
        assert [a["X"] for a in sub.take_answers(10, waker)] == [3]
    finally:
        loop.close()
    sub.close()
    behind.close()


def test_next_answers_after_take_answers_waits_on_its_own_future(kb):
    """take_answers leaves no waiter for next_answers to await (the fan-out's wakers are
    not awaitable): the two mix on one subscription."""
    sub = kb.subscribe("p(X)^T", since=0)
    kb.add("p(1)^1")
    drained(kb)
    loop = asyncio.new_event_loop()
    try:
        assert [a["X"] for a in sub.take_answers(10, (loop, _Marker()))] == [1]

        async def then_next() -> list:
            task = asyncio.ensure_future(sub.next_answers(10))
            await asyncio.sleep(0)               # it waits: nothing is queued
            assert sub._async_waiter is not None and sub._async_waiter[0] is loop
            assert not task.done()
            await loop.run_in_executor(None, kb.add, "p(2)^2")
            return await asyncio.wait_for(task, DEADLINE)
        assert [a["X"] for a in loop.run_until_complete(then_next())] == [2]
    finally:
        sub.close()
        loop.close()


def test_a_patterns_matcher_lives_as_long_as_its_subscriptions(kb):
    hub = kb._subscriptions
    subs = [kb.subscribe(f"p{i % 3}(X)^T", where="X > 1") for i in range(6)]
    assert len(hub._matchers) == 3
    for s in subs[:3]:
        s.close()
    assert len(hub._matchers) == 3                   # each pattern still has one open
    for s in subs[3:]:
        s.close()
    assert hub._matchers == {}


# -- the service: one text per answer, each subscriber its own frames -----------------------

def test_answer_texts_encode_each_answer_once():
    texts = _AnswerTexts(size=4)
    a, b = {"X": 1, "S": "s"}, {"X": 1, "S": "s"}
    one = texts.frame(1, [a, b])
    assert texts.frame(9, [a, b]) == one.replace('"seq":1', '"seq":9')
    assert texts.encoded == 2                        # equal dicts are still two answers
    assert json.loads(one) == {"type": "answers", "seq": 1,
                               "answers": [{"X": 1, "S": {"$string": "s"}}] * 2}
    many = [{"X": i} for i in range(10)]
    texts.frame(1, many)
    assert len(texts._texts) <= 4                    # bounded


def test_answer_texts_join_a_batch_once_for_all_the_subscribers_that_take_it(kb):
    """The subscribers of one pattern take the same batch one after the other: its texts
    are joined once; each frame still carries its subscriber's own sequence number, and a
    batch that differs (another count, another answer inside) is joined anew."""
    kb.add("p(0)^0")
    subs = [kb.subscribe("p(X)^T", since=0.5) for _ in range(5)]
    drained(kb)
    kb.add_many([f"p({i})^{i}" for i in range(1, 6)])
    drained(kb)
    texts = _AnswerTexts()

    async def take(s, limit) -> list:
        return await s.next_answers(limit, copy=False)
    batches = [asyncio.run(take(s, 10)) for s in subs]
    frames = [texts.frame(1 + k, b) for k, b in enumerate(batches)]
    assert texts.joined == 1 and texts.encoded == 5
    for k, frame in enumerate(frames):
        assert json.loads(frame) == {"type": "answers", "seq": 1 + k,
                                     "answers": [{"X": i, "T": float(i)} for i in range(1, 6)]}
    whole = batches[0]
    shorter = whole[:1] + whole[2:]           # the same first and last, one fewer
    other_middle = whole[:2] + [dict(whole[2], X=99)] + whole[3:]   # as many, another inside
    for batch in (shorter, other_middle, whole):
        assert json.loads(texts.frame(1, batch))["answers"] == \
            [{"X": a["X"], "T": a["T"]} for a in batch]
    assert texts.joined == 4
    for s in subs:
        s.close()


def test_a_cancelled_wait_leaves_no_waiter_and_the_next_wait_is_woken(kb):
    kb.add("p(0)^0")
    sub = kb.subscribe("p(X)^T", since=0.5)
    drained(kb)

    async def cancel_then_take() -> list:
        waiting = asyncio.ensure_future(sub.next_answers(10))
        await _turns_until(lambda: sub._async_waiter is not None,   # it waits for the hub
                           "the wait registered")
        waiting.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await waiting
        assert sub._async_waiter is None
        taking = asyncio.ensure_future(sub.next_answers(10))
        await _turns_until(lambda: sub._async_waiter is not None, "the second wait registered")
        await asyncio.get_running_loop().run_in_executor(None, kb.add, "p(7)^7")
        return await asyncio.wait_for(taking, DEADLINE)
    assert [a["X"] for a in asyncio.run(cancel_then_take())] == [7]
    sub.close()


@pytest.mark.parametrize("take", ["async for", "next_answers"])
def test_a_cancelled_waiter_does_not_take_away_the_later_waiters_wake(kb, take):
    """Two coroutines wait on one subscription (the later one's wait replaces the first's);
    cancelling the first leaves the second waiting, and the next answer wakes it."""
    kb.add("p(0)^0")
    sub = kb.subscribe("p(X)^T", since=0.5)
    drained(kb)

    async def one() -> list:
        if take == "async for":
            return [await sub.__anext__()]
        return await sub.next_answers(10)

    async def run() -> list:
        first = asyncio.ensure_future(one())
        await _turns_until(lambda: sub._async_waiter is not None, "the first wait registered")
        mine = sub._async_waiter
        second = asyncio.ensure_future(one())
        await _turns_until(lambda: sub._async_waiter is not mine, "the second wait registered")
        first.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await first
        assert sub._async_waiter is not None      # the second still waits
        await asyncio.get_running_loop().run_in_executor(None, kb.add, "p(5)^5")
        return await asyncio.wait_for(second, DEADLINE)
    assert [a["X"] for a in asyncio.run(run())] == [5]
    sub.close()


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    db = tmp_path_factory.mktemp("service_fanout") / "fanout.db"
    with ServiceProcess(db) as s:
        yield s


def receive_all(ws) -> list:
    """The answers of every frame until the end frame, checking each frame's seq."""
    answers: list = []
    while True:
        msg = json.loads(ws.recv(timeout=DEADLINE))
        if msg["type"] == "end":
            return answers
        batch = msg["answers"] if msg["type"] == "answers" else [msg["answer"]]
        assert msg["seq"] == len(answers) + 1          # its own numbering, no gap
        answers.extend(batch)


@pytest.mark.parametrize("batch", [1, 64])
def test_subscribers_sharing_answer_texts_each_get_exactly_their_own(server, batch):
    tag = f"f{next(_tags)}_"
    until = 300
    requests = [
        {"pattern": f"{tag}v(I, V)^T", "where": "V > 5", "since": 1},      # A
        {"pattern": f"{tag}v(I, V)^T", "where": "V > 5", "since": 1},      # A again
        {"pattern": f"{tag}v(I, V)^T", "where": "V > 5", "since": 150},    # A, later since
        {"pattern": f"{tag}v(I, V)^T", "since": 1},                          # every event
        {"pattern": f"{tag}v(I, 7)^T", "since": 1},                          # a constant
        {"pattern": f"{tag}v(I, V)^T", "where": "V =< 5", "since": 1},      # the others
    ]
    with slr_sql.connect(server.url) as client, contextlib.ExitStack() as stack:
        complete_only_as_marked(client, f"{tag}v/2")
        client.add(f"{tag}v(0, 0)^0")
        sockets = []
        for r in requests:
            ws = stack.enter_context(ws_connect(server.url.replace("http", "ws") + "/subscribe"))
            sockets.append(ws)
            ws.send(json.dumps({"op": "subscribe", "until": until, "batch": batch, **r}))
            assert json.loads(ws.recv(timeout=DEADLINE))["type"] == "subscribed"
        events = [(i, (i * 7) % 11) for i in range(1, until + 1)]
        for k in range(0, len(events), 25):
            client.add_many([f"{tag}v({i}, {v})^{i}" for i, v in events[k:k + 25]])
        client.mark_complete(f"{tag}v/2", until)
        got = [receive_all(ws) for ws in sockets]

    def answers(keep, since=1, bind_v=True) -> list:
        return [{"I": i, "V": v, "T": float(i)} if bind_v else {"I": i, "T": float(i)}
                for i, v in events if i >= since and keep(v)]
    assert got[0] == got[1] == answers(lambda v: v > 5)
    assert got[2] == answers(lambda v: v > 5, since=150)
    assert got[3] == answers(lambda v: True)
    assert got[4] == answers(lambda v: v == 7, bind_v=False)
    assert got[5] == answers(lambda v: v <= 5)


# -- orjson and Python's json read and write the same ----------------------------------------

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(min_value=-(2 ** 80), max_value=2 ** 80)
    | st.floats(allow_nan=False, allow_infinity=False) | st.text(),
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.text(max_size=5), inner, max_size=4),
    max_leaves=20)


def same_json(a, b) -> bool:
    if type(a) is not type(b):
        return False
    if type(a) is float:
        return a == b and math.copysign(1, a) == math.copysign(1, b)
    if type(a) is list:
        return len(a) == len(b) and all(same_json(x, y) for x, y in zip(a, b))
    if type(a) is dict:
        return a.keys() == b.keys() and all(same_json(a[k], b[k]) for k in a)
    return a == b


@settings(max_examples=300, deadline=None)
@given(json_values, st.booleans())
def test_the_service_json_reads_and_writes_as_pythons_json(value, spaced):
    text = json.dumps(value, ensure_ascii=spaced, separators=(", ", ": ") if spaced else
                      (",", ":"))
    assert same_json(loads(text.encode("utf-8")), json.loads(text))   # bytes, as bodies come
    assert same_json(loads(text), json.loads(text))
    assert same_json(json.loads(dumps(value)), value)


@pytest.mark.parametrize("text, value", [
    (b"[123456789012345678901234567890]", [123456789012345678901234567890]),
    (b"[-9223372036854775809, 18446744073709551616]", [-9223372036854775809, 2 ** 64]),
    (b'{"a": 1e999}', {"a": math.inf}),
    (b"[" * 40 + b"1" + b"]" * 40, [[[[1]]]]),
])
def test_what_orjson_would_read_differently_is_read_by_json(text, value):
    got = loads(text)
    if text.startswith(b"[" * 40):
        for _ in range(36):
            got = got[0]
    assert got == value and [type(x) for x in got] == [type(x) for x in value] \
        if isinstance(value, list) else got == value


def test_a_stray_non_finite_float_is_never_written():
    with pytest.raises(ValueError):
        dumps({"a": [1.0, math.nan]})
    assert dumps({"a": None, "b": 10 ** 30}) == b'{"a":null,"b":' + b"1" + b"0" * 30 + b"}"


# -- add_many: arguments used as parsed ------------------------------------------------------

@pytest.mark.parametrize("atomic", [None, False])
def test_plain_event_arguments_are_atoms_and_their_rejections_say_so(server, atomic):
    tag = f"a{next(_tags)}_"
    events = [{"name": f"{tag}o", "args": ["cup1", [1, 2.5, "x"]], "start": 1.0},
              {"name": f"{tag}o", "args": ["cup2", []], "start": 6.0, "end": 5.0}]
    body = {"events": events} if atomic is None else {"events": events, "atomic": atomic}
    reply = HTTP.post(server.url + "/add_many", content=json.dumps(body),
                      headers={"Content-Type": "application/json"}, timeout=DEADLINE).json()
    assert reply["accepted"] == 1
    (rejection,) = reply["rejected"]
    assert rejection["index"] == 1
    assert rejection["message"].startswith(f"{tag}o(cup2,[])^[6.0,5.0]: ")
    with slr_sql.connect(server.url) as client:
        (answer,) = client.query(f"{tag}o(O, L)^T")
    local = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    local.add(f"{tag}o(cup1, [1, 2.5, x])^1")
    assert answer == local.query(f"{tag}o(O, L)^T")[0] and type(answer["O"]) is slr_sql.Atom
    local.close()
