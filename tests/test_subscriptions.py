"""Subscriptions (docs/subscriptions.md): iterator, async and callback delivery, conditions,
history then live with no gap at the seam, until by completeness, durable positions across a
reopen and a SIGKILL, slow consumers, cross-process delivery and ``slr subscribe``.

Time is a ManualClock wherever completeness matters; every wait has a deadline (``get(timeout)``,
``Event.wait``, ``join``), never a fixed pause.
"""
from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from hypothesis import given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock, SLRError, SLREvaluationError, SLRSubscriptionInUse, SLRSyntaxError
from slr_sql.encoding import decode
from slr_sql import subscriptions
from slr_sql.subscriptions import SubscriptionOverflow, answer_json, journal_table
from slr_sql.terms import Atom, String, Struct, make_list, to_python

ROOT = Path(__file__).resolve().parent.parent
DEADLINE = 20.0


def take(sub, n: int, timeout: float = DEADLINE) -> list[dict]:
    """The next ``n`` answers, each within the deadline (SLRTimeout otherwise)."""
    out = []
    end = time.monotonic() + timeout
    while len(out) < n:
        answer = sub.get(timeout=max(end - time.monotonic(), 0.001))
        assert answer is not None, f"the subscription ended after {out}"
        out.append(answer)
    return out


def ends(sub, timeout: float = DEADLINE) -> bool:
    """True when the subscription ends (its next item is the end) within the deadline."""
    return sub.get(timeout=timeout) is None


def xs(answers: list[dict], name: str = "X") -> list:
    return [a[name] for a in answers]


def _open(where=None, **options) -> slr_sql.KnowledgeBase:
    """A store with a ManualClock (unless given one): the events here carry small times
    (1, 2, ...), "decades late" on the wall clock (a LearnedDelayWarning)."""
    options.setdefault("clock", ManualClock(0.0))
    return slr_sql.open(where, **options)


@pytest.fixture
def clock():
    return ManualClock(0.0)


@pytest.fixture(params=["by end time", "by arrival sequence"])
def history_read(request, monkeypatch):
    """Both ways a history is read: few events in the window (the end-time index) or many
    (walking the table by seq)."""
    if request.param == "by arrival sequence":
        monkeypatch.setattr(subscriptions.hub, "FEW_HISTORY", -1)
    return request.param


@pytest.fixture
def kb(clock):
    k = slr_sql.open(clock=clock)
    yield k
    k.close()


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


class Lines:
    """The stdout lines of a child process, read by a thread so the test can wait on them with
    a deadline."""

    def __init__(self, child: subprocess.Popen):
        self.child = child
        self.lines: list[str] = []
        self.cond = threading.Condition()
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()

    def _read(self) -> None:
        with self.child.stdout:         # closed at the end of the output: no ResourceWarning
            for line in self.child.stdout:
                with self.cond:
                    self.lines.append(line.rstrip("\n"))
                    self.cond.notify_all()
        with self.cond:
            self.lines.append(None)
            self.cond.notify_all()

    def wait_for(self, n: int, timeout: float = DEADLINE) -> list[str]:
        end = time.monotonic() + timeout
        with self.cond:
            while len([x for x in self.lines if x is not None]) < n:
                if None in self.lines:
                    raise AssertionError(f"the child ended after {self.lines}: "
                                         f"{self.child.stderr.read()}")
                left = end - time.monotonic()
                assert left > 0, f"only {self.lines} within {timeout} s"
                self.cond.wait(left)
            return [x for x in self.lines if x is not None]


def start_cli(*args: str) -> tuple[subprocess.Popen, Lines]:
    child = subprocess.Popen([sys.executable, "-m", "slr_sql", *args], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, cwd=str(ROOT), env=_env())
    return child, Lines(child)


def errors_of(child: subprocess.Popen) -> str:
    """What an ended child wrote to stderr; the pipe is closed."""
    with child.stderr:
        return child.stderr.read()


# -- the three ways to consume --------------------------------------------------------------------

def test_callback_gets_matching_events_from_a_delivery_thread(kb):
    got, names, seen = [], [], threading.Event()

    def on_answer(answer):
        got.append(answer)
        names.append(threading.current_thread().name)
        if answer["F"] == "carl":
            seen.set()

    sub = kb.subscribe("face(F, R)^T", where="R > 60", since=0, callback=on_answer)
    adder = threading.current_thread().name
    kb.add_many(["face(bob, 20)^1", "face(antonio, 65)^2"])
    kb.add("face(carl, 90)^3")
    assert seen.wait(DEADLINE)
    sub.close()
    assert [(a["F"], a["R"], a["T"]) for a in got] == [("antonio", 65, 2.0), ("carl", 90, 3.0)]
    assert all(n != adder and n.startswith("slr-subscription") for n in names)
    with pytest.raises(SLRError, match="callback"):
        iter(sub)


def test_a_callback_may_add_events_itself(kb):
    """Callbacks never run inside kb.add's transaction: adding from one cannot deadlock."""
    done = threading.Event()

    def echo(answer):
        kb.add(f"echo({answer['X']})^{answer['T']}")

    sub = kb.subscribe("p(X)^T", since=0, callback=echo)
    probe = kb.subscribe("echo(X)^T", since=0, callback=lambda a: done.set())
    kb.add("p(1)^1")
    assert done.wait(DEADLINE)
    sub.close()
    probe.close()


def test_iterator_blocks_until_events_arrive_and_stops_at_close(kb):
    got, started, five = [], threading.Event(), threading.Event()
    sub = kb.subscribe("p(X)^T", since=0)

    def consume():
        started.set()
        for answer in sub:
            got.append(answer["X"])
            if len(got) == 5:
                five.set()

    consumer = threading.Thread(target=consume)
    consumer.start()
    assert started.wait(DEADLINE)
    for i in range(5):
        kb.add(f"p({i})^{i}")
    assert five.wait(DEADLINE)
    sub.close()                          # the blocked iteration stops
    consumer.join(DEADLINE)
    assert not consumer.is_alive()
    assert got == [0, 1, 2, 3, 4]


def test_async_iteration_does_not_block_the_event_loop(kb):
    # Another task must run while the iteration waits for its first answer; the events are added
    # only after that task saw the wait still open, so no timing decides the outcome (a blocking
    # iterator would hold the loop until the adder gives up waiting and adds anyway).
    async def main():
        sub = kb.subscribe("p(X)^T", since=0)
        loop_ran_while_waiting = threading.Event()
        first = asyncio.create_task(sub.__anext__())

        async def other_task():
            await asyncio.sleep(0)
            if not first.done():
                loop_ran_while_waiting.set()

        def adder():
            loop_ran_while_waiting.wait(DEADLINE)
            for i in range(20):
                kb.add(f"p({i})^{i}")

        threading.Thread(target=adder).start()
        other = asyncio.create_task(other_task())
        got = [(await first)["X"]]
        async for answer in sub:
            got.append(answer["X"])
            if len(got) == 20:
                break
        await other
        sub.close()
        return got, loop_ran_while_waiting.is_set()

    got, loop_ran = asyncio.run(asyncio.wait_for(main(), DEADLINE))
    assert got == list(range(20))
    assert loop_ran


def test_async_iteration_ends_at_until(kb, clock):
    async def main():
        sub = kb.subscribe("p(X)^T", since=0, until=3)
        kb.add("p(a)^1")
        clock.set(10)
        return [a["X"] async for a in sub]

    assert asyncio.run(asyncio.wait_for(main(), DEADLINE)) == ["a"]


# -- patterns, conditions, values -----------------------------------------------------------------

def test_where_filters_and_may_bind_more_variables(kb):
    kb.load("size(cup1, small). size(cup2, large).")
    sub = kb.subscribe("obj(O, C)^T", where="size(O, S), S \\= large")
    kb.add_many(["obj(cup2, red)^1", "obj(cup1, blue)^2", "obj(cup3, green)^3"])
    assert take(sub, 1) == [{"O": "cup1", "C": "blue", "T": 2.0, "S": "small"}]
    kb.add("obj(cup1, red)^4")
    assert take(sub, 1)[0]["C"] == "red"     # cup2 and cup3 were never delivered


def test_a_string_condition_as_in_the_paper(kb):
    sub = kb.subscribe("relFace(F)^T", where='F = "Antonio"')
    kb.add_event("relFace", [String("Bob")], 1.0)
    kb.add_event("relFace", [String("Antonio")], 2.0)
    [answer] = take(sub, 1)
    assert answer == {"F": "Antonio", "T": 2.0} and type(answer["F"]) is str


def test_a_failing_condition_ends_the_subscription_with_its_error(kb):
    sub = kb.subscribe("p(X)^T", where="X > 1", since=0)
    kb.add_many(["p(2)^1", "p(a)^2"])
    assert xs(take(sub, 1)) == [2]
    with pytest.raises(SLREvaluationError):
        sub.get(timeout=DEADLINE)
    assert sub.closed


@pytest.mark.parametrize("condition", ["repeat, fail", "between(1, inf, _), fail"])
def test_an_endless_condition_ends_its_subscription_not_every_delivery(
        kb, monkeypatch, condition):
    """A condition runs on the delivery thread all subscriptions share: one that never ends
    ran there for ever, and no subscription of the knowledge base (on a server, no client's)
    got another answer. It now ends its own subscription with an SLRTimeout at its budget."""
    monkeypatch.setattr(subscriptions.matching, "WHERE_TIMEOUT", 0.2)
    endless = kb.subscribe("hostile(X)^T", where=condition, since=0)
    other = kb.subscribe("ok(X)^T", since=0)
    kb.add("hostile(1)^1")
    kb.add("ok(1)^2")
    assert xs(take(other, 1)) == [1]
    with pytest.raises(slr_sql.SLRTimeout, match=r"^the subscription's where condition did "
                                                 r"not end within its limit \(.*0\.2 s"):
        endless.get(timeout=DEADLINE)
    assert endless.closed
    kb.add("ok(2)^3")
    assert xs(take(other, 1)) == [2]


def test_times_match_by_value_and_point_patterns_bind_the_end(kb):
    at5 = kb.subscribe("p(X)^5", since=0)
    interval = kb.subscribe("p(X)^[S, E]", since=0)
    point = kb.subscribe("p(X)^T", since=0)
    kb.add_many(["p(a)^5.0", "p(b)^[1, 5]", "p(c)^[4, 6]"])
    assert xs(take(at5, 2)) == ["a", "b"]    # 5 == 5.0; ^5 is the end of [1, 5]
    assert [(a["X"], a["S"], a["E"]) for a in take(interval, 3)] == \
        [("a", 5.0, 5.0), ("b", 1.0, 5.0), ("c", 4.0, 6.0)]
    assert [(a["X"], a["T"]) for a in take(point, 3)] == [("a", 5.0), ("b", 5.0), ("c", 6.0)]


def test_data_arguments_keep_prologs_rule(kb):
    sub = kb.subscribe("p(1, Y)^T", since=0)
    kb.add_many(["p(1.0, float)^1", "p(1, int)^2"])
    assert xs(take(sub, 1), "Y") == ["int"]


def test_values_come_back_as_kb_query_gives_them(kb):
    sub = kb.subscribe("note(A, S, N, L, C)^T", since=0)
    kb.add_event("note", ["x", String("text"), 3, [1, 2.5, "y"], Struct("f", ("a", 1))], 1.0)
    [answer] = take(sub, 1)
    assert answer == kb.query("note(A, S, N, L, C)^T")[0]
    assert type(answer["A"]) is Atom and type(answer["S"]) is str
    assert answer["C"] == Struct("f", (Atom("a"), 1))


def test_arrival_order_not_end_time_order(kb):
    kb.add_many(["p(1)^5", "p(2)^1"])
    sub = kb.subscribe("p(X)^T", since=0)
    kb.add_many(["p(3)^9", "p(4)^2"])
    assert xs(take(sub, 4)) == [1, 2, 3, 4]


@pytest.mark.parametrize("pattern", ["p(X", "p(X)", "p(X)^foo", "p(X)^[a, b]", "X^T", "42^T",
                                     "p(X)^(T+1)"])
def test_a_bad_pattern_is_a_syntax_error(kb, pattern):
    with pytest.raises(SLRSyntaxError):
        kb.subscribe(pattern)


@pytest.mark.parametrize("kwargs, message", [
    ({"where": "X >"}, None),
    ({"where": "p(("}, None),
    ({"since": "yesterday"}, "since"),
    ({"since": float("nan")}, "since"),
    ({"since": 5, "until": 4}, "before since"),
    ({"max_queue": 0}, "max_queue"),
    ({"callback": 3}, "callable"),
    ({"id": ""}, "id"),
])
def test_bad_arguments_are_refused_with_a_clear_error(kb, kwargs, message):
    with pytest.raises(SLRError) as info:
        kb.subscribe("p(X)^T", **kwargs)
    if message is None:
        assert isinstance(info.value, SLRSyntaxError) and info.value.filename == "<where>"
    else:
        assert message in str(info.value)


# -- since: history, then live, with no gap and no duplicate ---------------------------------------

def test_since_now_skips_stored_events_and_late_live_ones(kb, clock, history_read):
    kb.add_many(["p(old)^1", "p(future)^20"])
    clock.set(10)
    sub = kb.subscribe("p(X)^T")                      # since="now" = 10
    kb.add_many(["p(late)^9", "p(live)^11"])
    assert xs(take(sub, 2)) == ["future", "live"]


def test_since_a_time_replays_history_then_goes_live(kb, history_read):
    kb.add_many([f"p({i})^{i}" for i in range(10)])
    sub = kb.subscribe("p(X)^T", since=4)
    kb.add_many(["p(10)^10", "p(3)^3.5", "p(11)^11"])
    assert xs(take(sub, 8)) == [4, 5, 6, 7, 8, 9, 10, 11]


def test_history_longer_than_the_queue_is_read_at_the_consumers_pace(kb, history_read):
    kb.add_many([("p", [i], float(i), float(i)) for i in range(3000)])
    sub = kb.subscribe("p(X)^T", since=0, max_queue=50)
    got = []
    end = time.monotonic() + DEADLINE
    while len(got) < 3000:
        got.append(sub.get(timeout=max(end - time.monotonic(), 0.001))["X"])
        assert sub.queued <= 50
    assert got == list(range(3000)) and sub.overflows == 0


@pytest.mark.parametrize("since", [float("-inf"), 0])
def test_no_gap_and_no_duplicate_at_the_seam_with_a_concurrent_writer(tmp_path, since,
                                                                     history_read):
    """A thread adds 1..N in order while the subscription is made in the middle: the answers
    are exactly 1..N once each, in order (history, then live)."""
    n = 3000
    with _open(tmp_path / "seam.db", synchronous="OFF") as kb:
        started = threading.Event()

        def writer():
            for i in range(1, n + 1):
                kb.add_event("p", [i], float(i))
                if i == n // 3:
                    started.set()

        thread = threading.Thread(target=writer)
        thread.start()
        assert started.wait(DEADLINE)
        sub = kb.subscribe("p(X)^T", since=since, max_queue=256)
        got = xs(take(sub, n, timeout=60))
        thread.join(DEADLINE)
        kb.add_event("p", [0], 0.0)    # a sentinel: nothing after n but it
        assert xs(take(sub, 1)) == [0]
        assert got == list(range(1, n + 1))
        assert sub.phase == 1          # it went live


def test_concurrent_writers_and_slow_and_fast_subscribers_all_see_the_store_order(tmp_path):
    """Two writer threads, subscribers with tiny and large queues: each subscriber gets every
    event once, in the order the store assigned (seq), whether it kept up or lagged."""
    with _open(tmp_path / "w.db", synchronous="OFF") as kb:
        subs = [kb.subscribe("p(W, I)^T", since=0, max_queue=q) for q in (1, 3, 7, 10_000)]

        def writer(name):
            for i in range(400):
                if i % 50 == 0:
                    kb.add_many([("p", [name, k], float(k), float(k)) for k in range(i, i + 5)])
                else:
                    kb.add_event("p", [name, i], float(i))

        threads = [threading.Thread(target=writer, args=(w,)) for w in ("a", "b")]
        for t in threads:
            t.start()
        for t in threads:
            t.join(DEADLINE)
        order = [(w, i) for w, i in kb.sql("SELECT arg1, arg2 FROM p ORDER BY seq")[1]]
        for sub in subs:
            assert [(a["W"], a["I"]) for a in take(sub, len(order), timeout=60)] == order


def test_a_reused_arrival_sequence_is_not_replayed_as_history(kb, history_read):
    """Rows deleted below a subscription's position and a new row after them: the history
    (seq <= the top at subscription time) must not take the new row, which is live. (An
    event table's sequence is AUTOINCREMENT: the new row does not reuse a deleted row's
    sequence, which once made it look like history.)"""
    kb.add_many(["p(1)^1", "p(2)^2", "p(3)^3"])
    sub = kb.subscribe("p(X)^T", since=0, max_queue=1)   # p(1) fills its queue
    assert kb._subscriptions.drain(DEADLINE)
    kb.sql("DELETE FROM p WHERE seq >= 2", write=True)
    kb.add("p(new)^4")
    assert kb.sql("SELECT seq FROM p WHERE arg1 = 'new'")[1] == [(4,)]
    assert xs(take(sub, 2)) == [1, "new"]
    kb.add("p(sentinel)^5")
    assert xs(take(sub, 1)) == ["sentinel"]


def test_a_cbuffer_that_prunes_at_once_loses_nothing_for_subscribers(kb):
    kb.load("cBuffer(face(P, _), 1).")
    sub = kb.subscribe("face(P, R)^T", since=0)
    for i in range(50):
        kb.add(f"face(bob, {i})^{i}")
    assert kb.sql("SELECT count(*) FROM face")[1] == [(1,)]
    assert xs(take(sub, 50), "R") == list(range(50))


# -- until ------------------------------------------------------------------------------------------

def test_until_ends_once_the_type_is_complete_by_the_clock(kb, clock):
    kb.load(":- max_delay(p/1, 1).")
    sub = kb.subscribe("p(X)^T", since=0, until=5)
    kb.add_many(["p(a)^1", "p(b)^4", "p(c)^6"])
    assert xs(take(sub, 2)) == ["a", "b"]
    clock.set(5.5)
    kb.add("p(late)^4.8")               # within max_delay: still delivered
    assert xs(take(sub, 1)) == ["late"]
    clock.set(6.01)                     # passed 5 + 1
    assert ends(sub)
    assert sub.closed
    assert kb.sql("SELECT count(*) FROM slr_subscriptions")[1] == [(0,)]


@pytest.mark.parametrize("how", ["mark_complete", "fullyUpdated"])
def test_until_ends_on_a_completeness_mark(kb, how):
    sub = kb.subscribe("p(X)^T", since=0, until=5)
    kb.add("p(a)^2")
    assert xs(take(sub, 1)) == ["a"]
    if how == "mark_complete":
        kb.mark_complete("p/1", 5)
    else:
        kb.add("fullyUpdated(p/1)^5")
    assert ends(sub)


def test_until_in_the_past_delivers_the_history_then_ends(kb, clock):
    kb.add_many(["p(a)^1", "p(b)^2", "p(c)^8"])
    clock.set(10)
    sub = kb.subscribe("p(X)^T", since=0, until=3)
    assert xs(take(sub, 2)) == ["a", "b"]
    assert ends(sub)


def test_until_on_a_type_with_no_events_yet(kb, clock):
    sub = kb.subscribe("nothing(X)^T", since=0, until=2)
    clock.set(3)
    assert ends(sub)


def test_a_callback_subscription_with_until_can_be_waited_for(kb, clock):
    got = []
    sub = kb.subscribe("p(X)^T", since=0, until=2, callback=lambda a: got.append(a["X"]))
    kb.add_many(["p(a)^1", "p(b)^2"])
    clock.set(3)
    assert sub.wait(DEADLINE)
    assert got == ["a", "b"]


# -- slow consumers ------------------------------------------------------------------------------------

def test_a_slow_callback_never_blocks_add_and_loses_nothing(kb):
    release, first, last = threading.Event(), threading.Event(), threading.Event()
    got = []

    def slow(answer):
        first.set()
        assert release.wait(DEADLINE)
        got.append(answer["X"])
        if answer["X"] == 199:
            last.set()

    sub = kb.subscribe("p(X)^T", since=0, callback=slow, max_queue=5)
    kb.add("p(0)^0")
    assert first.wait(DEADLINE)          # the callback is now stuck on the first answer
    for i in range(1, 200):              # every add returns while the consumer is stuck
        kb.add(f"p({i})^{i}")
    assert kb._subscriptions.drain(DEADLINE)
    assert sub.overflows == 1 and sub.lagging and sub.queued == 5
    release.set()
    assert last.wait(DEADLINE)
    sub.close()
    assert got == list(range(200))


def test_a_consumer_too_far_behind_gets_an_overflow_after_its_queued_answers(kb):
    sub = kb.subscribe("p(X)^T", since=0, max_queue=3, max_lag=10)
    for i in range(40):
        kb.add(f"p({i})^{i}")
    got = []
    with pytest.raises(SubscriptionOverflow) as info:
        while True:
            got.append(sub.get(timeout=DEADLINE)["X"])
    assert got == list(range(len(got))) and len(got) >= 3
    assert info.value.behind > 10 and info.value.subscription_id == sub.id
    assert "max_lag 10" in str(info.value)
    assert sub.closed


def test_a_durable_subscription_resumes_after_an_overflow(tmp_path):
    with _open(tmp_path / "o.db") as kb:
        sub = kb.subscribe("p(X)^T", since=0, id="slow", max_queue=2, max_lag=5)
        kb.add_many([("p", [i], float(i), float(i)) for i in range(20)])
        got = []
        with pytest.raises(SubscriptionOverflow, match="resume"):
            while True:
                got.append(sub.get(timeout=DEADLINE)["X"])
        again = kb.subscribe("p(X)^T", since=0, id="slow")
        got += xs(take(again, 20 - len(got)))
        assert got == list(range(20))
        again.close(forget=True)


# -- close, unsubscribe, durability ---------------------------------------------------------------

def test_close_stops_delivery_and_removes_the_registration(kb):
    sub = kb.subscribe("p(X)^T", since=0)
    kb.add("p(1)^1")
    assert xs(take(sub, 1)) == [1]
    sub.close()
    kb.add("p(2)^2")
    assert sub.get(timeout=DEADLINE) is None and list(sub) == []
    assert kb.sql("SELECT count(*) FROM slr_subscriptions")[1] == [(0,)]
    sub.close()                          # idempotent


def test_the_journal_exists_only_while_someone_subscribes(tmp_path):
    path = tmp_path / "j.db"
    with _open(path) as kb:
        kb.add("p(1)^1")
        sub = kb.subscribe("p(X)^T")
        names = {r[0] for r in kb.sql("SELECT name FROM sqlite_master")[1]}
        assert {journal_table("p"), "slr_subt_p"} <= names
        sub.close()
    with _open(path) as kb:
        names = {r[0] for r in kb.sql("SELECT name FROM sqlite_master")[1]}
        assert not {n for n in names if n.startswith(("slr_subj_", "slr_subt_"))}


def test_the_journal_keeps_only_what_subscriptions_still_need(kb):
    fast = kb.subscribe("p(X)^T", since=0)
    slow = kb.subscribe("p(X)^T", since=0, id="slow")
    kb.add_many([("p", [i], float(i), float(i)) for i in range(100)])
    assert xs(take(fast, 100)) == list(range(100))
    assert xs(take(slow, 40)) == list(range(40))
    hub = kb._subscriptions
    hub._last_lease = hub._last_persist = 0.0     # renew claims and write positions now
    assert hub.housekeeping_round(DEADLINE)
    hub.cleanup()
    jids = kb.sql(f"SELECT min(jid), count(*) FROM {journal_table('p')}")[1][0]
    assert jids == (40, 61)   # from the answer the slow one took last (not handled yet) on
    assert xs(take(slow, 60)) == list(range(40, 100))
    slow.close(forget=True)
    fast.close()
    assert "slr_subt_p" not in {r[0] for r in kb.sql("SELECT name FROM sqlite_master")[1]}


def test_a_registration_removed_behind_its_back_ends_the_subscription_loudly(tmp_path):
    """A process that stopped renewing its claim (suspended) loses its registration to
    another process's cleanup; its subscription then ends with an error, not a silent gap."""
    path = tmp_path / "lease.db"
    with _open(path) as kb, _open(path) as other:
        sub = kb.subscribe("p(X)^T", since=0)
        kb.sql("UPDATE slr_subscriptions SET lease_until = 0", write=True)   # as if not renewed for long
        other._subscriptions.cleanup()
        kb._subscriptions._last_lease = kb._subscriptions._last_persist = 0.0
        assert kb._subscriptions.housekeeping_round(DEADLINE)
        with pytest.raises(SLRError, match="removed from the store"):
            sub.get(timeout=DEADLINE)


def test_durable_subscription_resumes_after_a_real_reopen(tmp_path):
    path = tmp_path / "d.db"
    with _open(path) as kb:
        sub = kb.subscribe("e(X)^T", where="X \\= skip", since=0, id="robot-log")
        kb.add_many(["e(0)^0", "e(skip)^1", "e(1)^2", "e(2)^3"])
        assert xs(take(sub, 2)) == [0, 1]   # 1 taken: handled once the kb closes
    with _open(path) as kb:
        kb.add("e(3)^4")
        with pytest.raises(SLRError, match="different|exists with"):
            kb.subscribe("e(X)^T", since=0, id="robot-log")
        sub = kb.subscribe("e(X)^T", where="X \\= skip", since=0, id="robot-log")
        assert xs(take(sub, 2)) == [2, 3]
        with pytest.raises(SLRSubscriptionInUse, match="already open"):   # (may pass: 503)
            kb.subscribe("e(X)^T", where="X \\= skip", id="robot-log")
        sub.close()
        kb.unsubscribe("robot-log")
        with pytest.raises(SLRError, match="no subscription"):
            kb.unsubscribe("robot-log")
        assert kb.sql("SELECT count(*) FROM slr_subscriptions")[1] == [(0,)]


def test_durable_subscription_resumes_in_the_middle_of_its_history(tmp_path):
    path = tmp_path / "h.db"
    with _open(path) as kb:
        kb.add_many([("p", [i], float(i), float(i)) for i in range(100)])
        sub = kb.subscribe("p(X)^T", since=0, id="h", max_queue=10)
        assert xs(take(sub, 30)) == list(range(30))
        kb.add("p(100)^100")
    with _open(path) as kb:
        sub = kb.subscribe("p(X)^T", since=0, id="h")
        assert xs(take(sub, 71)) == list(range(30, 101))
        sub.close(forget=True)


def test_an_answer_taken_but_not_handled_is_delivered_again(tmp_path):
    path = tmp_path / "a.db"
    with _open(path) as kb:
        sub = kb.subscribe("p(X)^T", since=0, id="a")
        kb.add_many(["p(1)^1", "p(2)^2"])
        with pytest.raises(RuntimeError):
            with sub:
                for answer in sub:
                    if answer["X"] == 2:
                        raise RuntimeError("the consumer failed on 2")
    with _open(path) as kb:
        sub = kb.subscribe("p(X)^T", since=0, id="a")
        assert xs(take(sub, 1)) == [2]
        sub.close(forget=True)


def test_a_finished_durable_subscription_stays_finished(tmp_path):
    path = tmp_path / "f.db"
    clock = ManualClock(0)
    with slr_sql.open(path, clock=clock) as kb:
        sub = kb.subscribe("p(X)^T", since=0, until=2, id="f")
        kb.add("p(a)^1")
        kb.mark_complete("p/1", 2)
        assert xs(take(sub, 1)) == ["a"] and ends(sub)
        assert kb.sql("SELECT finished FROM slr_subscriptions WHERE id = 'f'")[1] == [(1,)]
    with slr_sql.open(path, clock=clock) as kb:
        sub = kb.subscribe("p(X)^T", since=0, until=2, id="f")
        assert ends(sub)
        kb.unsubscribe("f")


def test_kb_close_ends_open_subscriptions(tmp_path):
    kb = _open(tmp_path / "c.db")
    sub = kb.subscribe("p(X)^T")
    kb.close()
    assert sub.get(timeout=DEADLINE) is None and sub.closed


def test_events_derived_inside_the_adding_transaction_are_delivered(kb):
    """Complex events are stored in the transaction of the event that completes them and then
    delivered like any event; here an SQL trigger stands in for the event-rule engine."""
    kb.load(":- event relFace/1. :- event face/2.")
    sub = kb.subscribe("relFace(F)^[S, E]", since=0)
    kb.sql("CREATE TRIGGER derive AFTER INSERT ON face WHEN NEW.arg2 > 60 BEGIN "
           "INSERT INTO relFace (arg1, t_start, t_end, arrival) "
           "VALUES (NEW.arg1, NEW.t_start - 1, NEW.t_end, NEW.arrival); END", write=True)
    kb.add_many(["face(bob, 20)^1", "face(antonio, 65)^2"])
    assert take(sub, 1) == [{"F": "antonio", "S": 1.0, "E": 2.0}]


# -- other connections and processes -------------------------------------------------------------

def test_events_added_by_another_connection_are_delivered(tmp_path):
    path = tmp_path / "x.db"
    with _open(path) as kb, _open(path) as other:
        sub = kb.subscribe("p(X)^T", since=0)
        other.add("p(from_other)^1")
        kb.sql("INSERT INTO p (arg1, t_start, t_end, arrival) VALUES ('by_sql', 2, 2, 0)", write=True)
        assert xs(take(sub, 2)) == ["from_other", "by_sql"]


def test_events_added_by_another_process_are_delivered(tmp_path):
    path = str(tmp_path / "p.db")
    with _open(path) as kb:
        kb.add("p(first)^0")
        sub = kb.subscribe("p(X)^T", since=1)
        r = subprocess.run([sys.executable, "-m", "slr_sql", "add", path, "p(a)^1", "p(b)^2"],
                           capture_output=True, text=True, cwd=str(ROOT), env=_env(),
                           timeout=120)
        assert r.returncode == 0, r.stderr
        assert xs(take(sub, 2)) == ["a", "b"]


def test_a_durable_subscription_is_delivered_by_one_process_at_a_time(tmp_path):
    path = str(tmp_path / "o.db")
    with _open(path) as kb:
        kb.add("p(1)^1")
    child, lines = start_cli("subscribe", path, "p(X)^T", "--since", "0", "--id", "shared")
    try:
        assert json.loads(lines.wait_for(1)[0])["X"] == 1
        with _open(path) as kb:
            with pytest.raises(SLRSubscriptionInUse, match="another process"):   # may pass
                kb.subscribe("p(X)^T", since=0, id="shared")
    finally:
        child.send_signal(signal.SIGINT)
        code = child.wait(DEADLINE)
        errors = errors_of(child)
    assert code == 0, errors
    with _open(path) as kb:   # released by the clean exit
        kb.subscribe("p(X)^T", since=0, id="shared").close(forget=True)


def test_a_sigkilled_durable_subscriber_resumes_with_no_gap(tmp_path):
    path = str(tmp_path / "k.db")
    with _open(path) as kb:
        kb.add("e(0)^0")
        child, lines = start_cli("subscribe", path, "e(X)^T", "--since", "0", "--id", "k")
        try:
            for i in range(1, 8):            # lockstep: each event printed before the next
                assert json.loads(lines.wait_for(i)[-1])["X"] == i - 1
                kb.add(f"e({i})^{i}")
            printed = [json.loads(x)["X"] for x in lines.wait_for(8)]
        finally:
            os.kill(child.pid, signal.SIGKILL)
            child.wait(DEADLINE)
            errors_of(child)
        kb.add_many([f"e({i})^{i}" for i in range(8, 12)])
        sub = kb.subscribe("e(X)^T", since=0, id="k")
        first = sub.get(timeout=DEADLINE)["X"]
        resumed = [first] + xs(take(sub, 11 - first))
        sub.close(forget=True)
    assert printed == list(range(8))
    assert first <= len(printed)                         # no gap: at least once
    assert resumed == list(range(first, 12))             # in order, nothing skipped


# -- slr subscribe ------------------------------------------------------------------------------------

@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_cli_prints_json_lines_and_exits_0_on_a_signal(tmp_path, stop):
    path = str(tmp_path / "cli.db")
    with _open(path) as kb:
        kb.add_many(["face(bob, 70)^1", "face(al, 20)^2"])
        child, lines = start_cli("subscribe", path, "face(F, R)^T", "--where", "R > 60",
                                 "--since", "0")
        try:
            assert json.loads(lines.wait_for(1)[0]) == {"F": "bob", "R": 70, "T": 1.0}
            kb.add_event("face", ["carl", 99.5], 3.0)
            kb.add_event("face", [String("dee"), 61], 4.0)
            out = [json.loads(x) for x in lines.wait_for(3)]
            assert out[1:] == [{"F": "carl", "R": 99.5, "T": 3.0},
                               {"F": {"$string": "dee"}, "R": 61, "T": 4.0}]
        finally:
            child.send_signal(stop)
            code = child.wait(DEADLINE)
            errors = errors_of(child)
        assert code == 0, errors
        assert kb.sql("SELECT count(*) FROM slr_subscriptions")[1] == [(0,)]


def test_cli_exits_0_when_until_is_complete_by_another_processes_mark(tmp_path):
    path = str(tmp_path / "until.db")
    t0 = round(time.time())
    with _open(path) as kb:
        kb.load(":- max_delay(p/1, 1000).")
        kb.add(f"p(a)^{t0}")
        child, lines = start_cli("subscribe", path, "p(X)^T", "--since", str(t0 - 1),
                                 "--until", str(t0 + 5))
        try:
            assert json.loads(lines.wait_for(1)[0])["X"] == "a"
            kb.add(f"p(b)^{t0 + 1}")
            assert json.loads(lines.wait_for(2)[1])["X"] == "b"
            kb.mark_complete("p/1", t0 + 5)
            code = child.wait(DEADLINE)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
            errors = errors_of(child)
        assert code == 0, errors


def test_cli_errors_are_words_and_exit_1(tmp_path):
    path = str(tmp_path / "e.db")
    _open(path).close()
    r = subprocess.run([sys.executable, "-m", "slr_sql", "subscribe", path, "p(X)^T",
                        "--where", "X >"], capture_output=True, text=True, cwd=str(ROOT),
                       env=_env(), timeout=120)
    assert r.returncode == 1 and "<where>:1:" in r.stderr and "Traceback" not in r.stderr
    r = subprocess.run([sys.executable, "-m", "slr_sql", "subscribe", str(tmp_path / "no.db"),
                        "p(X)^T"], capture_output=True, text=True, cwd=str(ROOT), env=_env(),
                       timeout=120)
    assert r.returncode == 1 and "no such store" in r.stderr and "Traceback" not in r.stderr


def test_cli_ends_with_the_error_of_a_condition_out_of_its_limit(tmp_path):
    """The subscription ends with an SLRTimeout, the class of a get() that waited 0.2 s for
    nothing, which the command took for one and waited on for ever, saying nothing."""
    path = str(tmp_path / "endless.db")
    with _open(path) as kb:
        kb.add("p(1)^1")
    r = subprocess.run([sys.executable, "-m", "slr_sql", "subscribe", path, "p(X)^T",
                        "--where", "repeat, fail", "--since", "0"], capture_output=True,
                       text=True, cwd=str(ROOT), env=_env(), timeout=120)
    assert r.returncode == 1, r.stderr
    assert "error: the subscription's where condition did not end within its limit" in \
        r.stderr and "Traceback" not in r.stderr
    assert r.stdout == ""


# -- the JSON encoding of answers ----------------------------------------------------------------

terms = st.recursive(
    st.one_of(st.text(min_size=1).map(Atom), st.text().map(String),
              st.integers(min_value=-2**70, max_value=2**70),
              st.floats(allow_nan=False)),
    lambda inner: st.one_of(st.lists(inner, max_size=3).map(make_list),
                            st.tuples(st.sampled_from(["f", "pose", "[x"]),
                                      st.lists(inner, min_size=1, max_size=3))
                            .map(lambda t: Struct(Atom(t[0]), tuple(t[1])))),
    max_leaves=8)


@settings(max_examples=200)
@given(terms)
def test_answer_json_round_trips_through_the_store_encoding(term):
    value = to_python(term)
    obj = json.loads(answer_json({"X": value}))
    back = to_python(decode("[" + json.dumps(obj["X"]) + "]"))
    assert back == [value]
    assert [type(x) for x in back] == [type(value)]
