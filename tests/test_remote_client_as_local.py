"""The remote client (slr_sql.connect) against a BackgroundServer answers a call as a local
knowledge base answers the same call: the same values, the same errors in the same words.
Each test makes its two stores, a local one and a served one, on the same ManualClock time."""
from __future__ import annotations

import contextlib

import pytest

import slr_sql
from slr_sql.service.background import BackgroundServer


@contextlib.contextmanager
def local_and_remote():
    """A local knowledge base, and a client of another one served from a thread (both
    memory stores on a ManualClock at 10)."""
    with slr_sql.open(clock=slr_sql.ManualClock(10)) as local, \
            slr_sql.open(clock=slr_sql.ManualClock(10)) as served, \
            BackgroundServer(served) as server, slr_sql.connect(server.url) as remote:
        yield local, remote


def test_sql_params_by_name_are_the_values_of_the_names_not_the_names():
    # a mapping of :name placeholders once went as list(mapping): its keys were the values
    with local_and_remote() as (local, remote):
        for kb in (local, remote):
            kb.add_many(["p(a)^1", "p(b)^4"])
        for call in (lambda kb: kb.sql("SELECT :x + 1 AS y", {"x": 41}),
                     lambda kb: kb.sql("SELECT arg1 FROM p WHERE t_end < :t", {"t": 3})):
            assert call(remote) == call(local)
        assert remote.sql("SELECT :x + 1 AS y", {"x": 41}) == (["y"], [(42,)])
        assert remote.sql("SELECT ? * 2 AS y", (21,)) == (["y"], [(42,)])


def test_a_sql_param_by_name_that_is_no_sql_value_is_refused_by_name():
    with local_and_remote() as (_local, remote):
        # (refused by the client, which cannot send it, before anything is sent)
        with pytest.raises(slr_sql.SLRError, match=r"sql: parameter 'x' = \[1, 2\] cannot be "
                                                    r"sent to slr serve"):
            remote.sql("SELECT :x", {"x": [1, 2]})


def test_a_synchronized_query_not_answered_in_time_says_so_in_the_local_words():
    # the server's sentence was once put inside the client's own ("was not answered within
    # 0.2 s: synchronized query 'far' (...) was not answerable: ..."): it said it twice
    with local_and_remote() as (local, remote):
        messages = []
        for kb in (local, remote):
            pending = kb.submit("r(X)^T", at=60, id="far")
            with pytest.raises(slr_sql.SLRTimeout) as info:
                pending.result(timeout=0.2)
            pending.cancel()
            messages.append(str(info.value))
        assert messages[1] == messages[0]
        assert messages[0].startswith("synchronized query 'far' (r(X)^T at 60) was not "
                                      "answerable within 0.2 s: r/1 (goal set) would require "
                                      "its history up to 60, but it is complete only up to 10")
        assert messages[0].count("synchronized query") == 1


def test_a_query_out_of_time_says_the_timeout_it_was_given():
    # the server took the moment of taking a free query slot off the timeout: the error
    # said "after 0.19998527899879265 s" for timeout=0.2
    with local_and_remote() as (local, remote):
        for kb in (local, remote):
            with pytest.raises(slr_sql.SLRTimeout,
                               match=r"^query timed out after 0\.2 s \(\d+ inference steps\)$"):
                kb.query("between(1, inf, X), fail", timeout=0.2)


def test_add_many_rejects_what_is_no_event_in_the_local_words_and_names_each_rejected_event():
    # the client had its own words for an item that is neither text nor a 4-tuple, and its
    # rejections had no .event (the caller's item, which a local knowledge base sets)
    with local_and_remote() as (local, remote):
        batch = ["q(1)^1", ("p",), 5, "p(1)^[2,1]", ("p", [1], 2.0, 1.0)]
        seen = [[(e.index, str(e), e.event) for e in kb.add_many(batch)] for kb in (local, remote)]
        assert seen[1] == seen[0]
        assert seen[0][0] == (1, "event #1 is neither SLR text nor a (name, args, start, end) "
                                 "tuple: ('p',)", ("p",))
        assert [event for _index, _text, event in seen[0]] == batch[1:]
        for kb in (local, remote):
            with pytest.raises(slr_sql.EventRejected, match=r"^event #0 is neither SLR text"):
                kb.add_many([5], atomic=True)


def test_a_closed_client_leaves_no_long_poll_behind_and_the_server_stops_at_once(caplog):
    # a client closed while its synchronized query was waiting left that query's long-poll
    # open on the server for up to max_poll: a server stopping meanwhile waited its whole
    # grace, then cancelled the poll and logged "Exception in ASGI application" with a
    # traceback
    import threading
    import time

    with slr_sql.open(clock=slr_sql.ManualClock(10)) as served:
        server = BackgroundServer(served, stop_grace=5.0).start()
        try:
            remote = slr_sql.connect(server.url)
            waiting = remote.submit("p(X)^T", at=20)
            # the poll is in flight once the server holds a request task for it
            state = server._server.server_state
            deadline = time.monotonic() + 10
            while not state.tasks and time.monotonic() < deadline:
                threading.Event().wait(0.01)
            assert state.tasks, "the client's long-poll never reached the server"
            remote.close()
            with pytest.raises(slr_sql.SLRError, match="closed"):
                waiting.result(timeout=5)
            started = time.monotonic()
        finally:
            server.stop()
        assert time.monotonic() - started < 2.0
    assert not [r for r in caplog.records if r.levelname == "ERROR"], caplog.text


@pytest.mark.parametrize("ending", ["until", "close"])
def test_a_subscription_says_it_is_closed_as_a_local_one_does(ending):
    with local_and_remote() as (local, remote):
        states = []
        for kb in (local, remote):
            sub = kb.subscribe("p(X)^T", since=0, until=12)
            kb.add("p(1)^11")
            before = sub.closed
            if ending == "until":
                kb.mark_complete("p/1", 12)
                taken = [sub.get(timeout=10), sub.get(timeout=10)]
            else:
                sub.close()
                taken = []
            states.append((before, [a and a["X"] for a in taken], sub.closed))
        assert states[0] == states[1]
        assert states[0][0] is False and states[0][2] is True
