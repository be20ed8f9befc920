"""One interface for local and remote (slr_sql.KnowledgeBaseAPI): every public method of the
local KnowledgeBase is in the protocol, and the local knowledge base and `slr_sql.connect`'s
client have it with the same parameters, defaults and return types; then every method runs
on both -- a local knowledge base and a real `slr serve` process -- and gives the same
values."""
from __future__ import annotations

import asyncio
import inspect
import math
import re
import threading
import time
import typing
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
from service_helpers import ServiceProcess, same

import slr_sql
from slr_sql import Atom, KnowledgeBaseAPI, PendingQueryAPI, ProgramInfo, SubscriptionAPI
from slr_sql.service.client import RemoteKnowledgeBase
from slr_sql.service.errors import ServiceError


def _public_methods(cls: type) -> set[str]:
    return {name for name, value in inspect.getmembers(cls)
            if not name.startswith("_") and callable(value)} | {"__enter__", "__exit__"}


PROTOCOL_METHODS = {name for name in dir(KnowledgeBaseAPI)
                    if callable(getattr(KnowledgeBaseAPI, name, None))
                    and (not name.startswith("_") or name in ("__enter__", "__exit__"))}


def test_every_public_method_of_the_local_knowledge_base_is_in_the_protocol():
    assert _public_methods(slr_sql.KnowledgeBase) == PROTOCOL_METHODS
    assert PROTOCOL_METHODS <= _public_methods(RemoteKnowledgeBase)


def _params(fn) -> list[tuple]:
    sig = inspect.signature(fn)
    return [(p.name, p.kind, p.default) for p in sig.parameters.values()]


def _return(cls: type, name: str):
    return typing.get_type_hints(getattr(cls, name))["return"]


@pytest.mark.parametrize("name", sorted(PROTOCOL_METHODS))
def test_same_parameters_defaults_and_return_types(name):
    want = _params(getattr(KnowledgeBaseAPI, name))
    assert _params(getattr(slr_sql.KnowledgeBase, name)) == want
    assert _params(getattr(RemoteKnowledgeBase, name)) == want
    if name in ("__enter__",):         # each returns itself
        return
    expected = _return(KnowledgeBaseAPI, name)
    assert _return(slr_sql.KnowledgeBase, name) == expected
    assert _return(RemoteKnowledgeBase, name) == expected
    assert inspect.iscoroutinefunction(getattr(slr_sql.KnowledgeBase, name)) == \
        inspect.iscoroutinefunction(getattr(RemoteKnowledgeBase, name)) == \
        inspect.iscoroutinefunction(getattr(KnowledgeBaseAPI, name))


# -- every method, run on both ----------------------------------------------------------------

# The served store's clock is the server's wall clock, so the local one keeps a wall clock too
# (the same answers to synchronized queries); the events are stamped 1.0 to 9.0, so every type
# declares its delay (none), or its first event would be "decades late" (a LearnedDelayWarning).
PROGRAM = """\
:- max_delay(seen/1, 0).
:- max_delay(obj/3, 0). :- max_delay(a/1, 0). :- max_delay(b/1, 0).
:- max_delay(c/1, 0). :- max_delay(sub/1, 0).
color(O, C)^T :- prev(obj(O, _, C)^_Z, T).
loop :- loop.
c(X) <- a(X) seq b(X).
"""


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    """A local knowledge base and a served one, each on a file of its own."""
    base = tmp_path_factory.mktemp("parity")
    with ServiceProcess(base / "served.db", "--max-query-time", "2") as server:
        local = slr_sql.open(base / "local.db")
        remote = slr_sql.connect(server.url)
        yield local, remote
        remote.close()
        local.close()


def _outcome(fn, kb):
    try:
        return "value", fn(kb)
    except slr_sql.SLRError as exc:
        return "error", type(exc).__name__


def _same(a, b) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and type(a) is type(b):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, ProgramInfo) and isinstance(b, ProgramInfo):  # loaded at other times
        return (a.name, a.source, a.texts, a.filenames) == (b.name, b.source, b.texts,
                                                            b.filenames)
    if type(a).__name__ == "BufferInfo":
        return type(a) is type(b) and a == b
    return same(a, b)


def both(pair, fn, check=None):
    """Run ``fn`` on the local and the remote knowledge base: the same value (or the same
    SLRError class); ``check`` sees each value."""
    local, remote = pair
    a, b = _outcome(fn, local), _outcome(fn, remote)
    assert a[0] == b[0], (a, b)
    if a[0] == "value":
        if check is not None:
            check(a[1])
            check(b[1])
        else:
            assert _same(a[1], b[1]), (a[1], b[1])
    else:
        assert a == b
    return a[1], b[1]


def test_every_method_gives_the_same_values_local_and_remote(pair, tmp_path):
    ran: set[str] = set()

    def run(name, fn, check=None):
        ran.add(name)
        return both(pair, fn, check)

    for kb in pair:
        assert isinstance(kb, KnowledgeBaseAPI)
    run("load", lambda kb: kb.load(PROGRAM))
    run("load", lambda kb: kb.load("tea(1).", name="tea"))
    run("load", lambda kb: kb.load("tea(2).", name="tea", replace=True))
    program_file = tmp_path / "more.slr"
    program_file.write_text("more(1).\n", encoding="utf-8")
    run("load_file", lambda kb: kb.load_file(program_file, name="more"))
    run("programs", lambda kb: kb.programs(),
        check=lambda v: (isinstance(v, dict) and list(v) == ["main", "tea", "more"]
                         and all(isinstance(i, ProgramInfo) for i in v.values())) or
        pytest.fail(repr(v)))
    run("programs", lambda kb: {n: (i.source, i.texts) for n, i in kb.programs().items()})
    run("unload", lambda kb: kb.unload("more"))
    run("unload", lambda kb: kb.unload("nosuch"))           # the same SLRError
    local, remote = pair
    local.define("double", 2, lambda x, y: (x, 2 * x))    # remote: below
    ran.add("define")
    run("event_rules", lambda kb: [(r["head"], r["policy"]) for r in kb.event_rules()])
    run("add", lambda kb: kb.add("obj(cup1, cup, red)^2.0"))
    run("add", lambda kb: kb.add("seen(X)^2"))                # rejected alike
    run("add_event", lambda kb: kb.add_event("obj", ["cup1", "cup", "green"], start=9.0))
    run("add_many", lambda kb: [(e.index, type(e).__name__) for e in kb.add_many(
        ["a(1)^1", "b(1)^3", "bad(X)^1", ("seen", ["x"], 5.0, 5.0)])])
    run("query", lambda kb: kb.query("color(cup1, C)^12.5"))
    run("query", lambda kb: kb.query("color(O, C)^T", args={"O": "cup1", "T": 5.0}))
    run("query", lambda kb: kb.query("c(X)^[S, E]"))
    run("query", lambda kb: kb.query("loop", timeout=0.2))    # SLRTimeout alike
    run("query", lambda kb: kb.query("loop", max_steps=1000))
    run("query", lambda kb: kb.query("between(1, 10, X)", limit=3))
    run("query", lambda kb: kb.query("findall(W, seen(W)^_, L)", at=9.0, wait=True,
                                     timeout=5))
    run("solutions", lambda kb: list(kb.solutions("color(cup1, C)^12.5")))
    run("goal_warnings", lambda kb: kb.goal_warnings("colour(cup1, C)^12.5"))
    run("explain", lambda kb: kb.explain("color(cup1, C)^5").splitlines()[0])
    run("mark_complete", lambda kb: kb.mark_complete("obj/3", 20.0))
    run("complete_until", lambda kb: kb.complete_until("obj/3") >= 20.0)

    def submitted(kb):
        p = kb.submit("findall(C, obj(_, _, C)^_, L)", at=15.0, id="q1")
        assert isinstance(p, PendingQueryAPI)
        return p.result(timeout=10)
    run("submit", submitted)

    def waiting(kb):
        p = kb.submit("findall(W, w(W)^_, L)", at=1e12, id="far")
        try:
            listed = [q.id for q in kb.pending()]
            with pytest.raises(slr_sql.SLRTimeout) as info:
                p.result(timeout=0.2)
            assert "w/1" in str(info.value) and "still waiting" in str(info.value)
            waits = [(w.type, w.time, w.reason) for w in p.waiting_for]
            return listed, waits
        finally:
            p.cancel()
    (listed, waits), _ = run("pending", waiting)
    assert listed == ["far"] and waits and waits[0][:2] == ("w/1", 1e12)
    ran.add("pending")
    run("ask", lambda kb: asyncio.run(kb.ask("findall(C, obj(_, _, C)^_, L)", at=15.0)))
    run("add_buffer", lambda kb: kb.add_buffer("seen(_)", keep_last=1))
    run("buffers", lambda kb: [(b.pattern, b.kind, b.amount) for b in kb.buffers()])
    run("remove_buffer", lambda kb: kb.remove_buffer(kb.buffers()[0].id))
    run("sql", lambda kb: kb.sql("SELECT arg1, arg3, t_end FROM obj ORDER BY t_end"))
    run("sql", lambda kb: kb.sql("SELECT ? + 1", [41], timeout=5))
    local.sql("CREATE TABLE IF NOT EXISTS scratch (x)", write=True)
    with pytest.raises(ServiceError) as refused:          # the service runs read-only SQL
        remote.sql("CREATE TABLE scratch (x)", write=True)
    assert "read-only" in str(refused.value)
    run("plot", lambda kb: [t.get_text() for t in kb.plot(["obj/3"], start=0, end=10)
                            .axes[0].get_yticklabels()])

    def subscribed(kb):
        got, done = [], threading.Event()
        with kb.subscribe("sub(X)^T", where="X > 1", since=0, id="durable-one") as pulled:
            assert isinstance(pulled, SubscriptionAPI)
            sub = kb.subscribe("sub(X)^T", since=0,
                               callback=lambda a: (got.append(a), len(got) == 2 and done.set()))
            kb.add_many(["sub(1)^1", "sub(2)^2"])
            first = pulled.get(timeout=10)
            assert done.wait(10)
            sub.close()
        return first, got
    run("subscribe", subscribed)
    run("unsubscribe", lambda kb: kb.unsubscribe("durable-one"))
    with pytest.raises(ServiceError) as info:              # Python runs where the store is
        remote.define("triple", 2, lambda x, y: (x, 3 * x))
    assert "server" in str(info.value)
    assert local.query("double(21, Y)") == [{"Y": 42}]
    assert remote.query("tea(X)") == local.query("tea(X)") == [{"X": 2}]
    assert remote.event_rules()[0]["head"] == local.event_rules()[0]["head"] == "c/1"
    assert isinstance(remote.query("obj(O, _, _)^2")[0]["O"], Atom)
    ran |= {"close", "__enter__", "__exit__"}     # the fixture and the with blocks
    with slr_sql.connect(remote.url) as other:
        assert other.query("true") == [{}]
    assert ran == PROTOCOL_METHODS, PROTOCOL_METHODS - ran


# the same condition, met locally and through `slr serve`: the same error class (each was
# another class, or no error at all, on one side)
SAME_CONDITION = {
    # an unknown buffer id: ServiceError (NotFound) remotely, a plain SLRError locally
    "unknown buffer": (lambda kb: kb.remove_buffer(10 ** 6), "BufferNotFound"),
    # remotely int("1") was sent (a buffer removed by another id's text), int("x") a ValueError
    "buffer id given as text": (lambda kb: kb.remove_buffer("x"), "SLRError"),
    "buffer id that is a bool": (lambda kb: kb.remove_buffer(True), "SLRError"),
    # remotely the name's str() was stored: an event 5/1 (or None/1) that a local store refuses
    "event name that is no atom": (lambda kb: kb.add_event(5, [1], start=1.0), "EventRejected"),
    "event name in a batch that is no atom": (
        lambda kb: [(e.index, type(e).__name__) for e in kb.add_many([(None, [1], 1.0, 1.0)])],
        [(0, "EventRejected")]),
    # locally the boundary's "add_many: TypeError: ...", remotely a bare TypeError
    "no events to go through": (lambda kb: kb.add_many(5), "SLRError"),
    # ServiceError (BadRequest, RequestTimeout) remotely, SLRError and SLRTimeout locally
    "sql naming no table": (lambda kb: kb.sql("SELECT * FROM nosuch"), "SLRError"),
    "sql running out of its timeout": (lambda kb: kb.sql(
        "WITH RECURSIVE c(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM c) SELECT count(*) "
        "FROM c", timeout=0.2), "SLRTimeout"),
}


@pytest.mark.parametrize("condition", sorted(SAME_CONDITION))
def test_the_same_condition_is_the_same_error_class_local_and_remote(pair, condition):
    call, expected = SAME_CONDITION[condition]
    local, remote = both(pair, call)
    assert local == expected
    if condition == "event name in a batch that is no atom":
        assert pair[1].sql("SELECT name FROM slr_event_types WHERE name IN ('None', '5')")[1] \
            == []


def test_an_unknown_buffer_is_a_404_named_after_its_condition(pair):
    import httpx

    from slr_sql.service.errors import error_status

    _local, remote = pair
    response = httpx.delete(f"{remote.url}/buffers/987654")
    assert response.status_code == 404
    assert response.json()["error"]["kind"] == "BufferNotFound"
    assert error_status(slr_sql.BufferNotFound("no active buffer #1")) == 404
    assert "BufferNotFound" in slr_sql.__all__ and issubclass(slr_sql.BufferNotFound,
                                                             slr_sql.SLRError)


def _error(fn, kb):
    """(class name, message) of the SLRError ``fn(kb)`` raises; ("value", ...) otherwise."""
    try:
        return "value", repr(fn(kb))
    except slr_sql.SLRError as exc:
        return type(exc).__name__, str(exc)


# an argument a local knowledge base refuses: the same class and the same words through
# `slr serve` (the client runs the local check before sending: each was a ServiceError
# (BadRequest) of the server's words, a TermError, a raw Python error, or no error at all,
# on one side)
SAME_WORDS = {
    "limit that is text": (lambda kb: kb.query("true", limit="x"), "SLRError",
                           "limit must be a count (an integer >= 0), not 'x'"),
    "limit that is a float": (lambda kb: kb.query("true", limit=1.0), "SLRError",
                              "limit must be a count (an integer >= 0), not 1.0"),
    "negative timeout": (lambda kb: kb.query("true", timeout=-1), "SLRError",
                         "timeout must be a number of seconds >= 0, not -1"),
    "timeout that is text": (lambda kb: kb.query("true", timeout="x"), "SLRError",
                             "timeout must be a number of seconds, not 'x'"),
    "at that is a bool": (lambda kb: kb.query("true", at=True), "SLRError",
                          "at must be a number of seconds, not True"),
    "robot that is no name": (lambda kb: kb.query("true", robot=5), "SLRError",
                              "a robot's name is a non-empty text, not 5"),
    "args value that is no term": (lambda kb: kb.query("X = Y", args={"Y": {1}}), "SLRError",
                                   "args['Y'] = {1} is not a term"),
    "args value None": (lambda kb: kb.query("X = Y", args={"Y": None}), "SLRError",
                        "args['Y'] = None is not a term"),
    "args that is no dict": (lambda kb: kb.query("X = 1", args=[1]), "SLRError",
                             "args must be a dict of variable name -> value, not [1]"),
    "goal that is no text": (lambda kb: kb.query(5), "SLRError",
                             "a goal is SLR text (a str), not int 5"),
    "explain of a goal that is no text": (lambda kb: kb.explain(5), "SLRError",
                                          "a goal is SLR text (a str), not int 5"),
    "warnings of a goal that is no text": (lambda kb: kb.goal_warnings(None), "SLRError",
                                           "a goal is SLR text (a str), not NoneType None"),
    "solutions with a negative timeout": (lambda kb: list(kb.solutions("true", timeout=-1)),
                                          "SLRError",
                                          "timeout must be a number of seconds >= 0, not -1"),
    # locally the boundary's "submit: ValueError: could not convert string to float: 'x'"
    "submit at a time that is text": (lambda kb: kb.submit("true", at="x"), "SLRError",
                                      "at must be a number of seconds, not 'x'"),
    "submit with a negative timeout": (lambda kb: kb.submit("true", at=0, timeout=-1),
                                       "SLRError",
                                       "timeout must be a number of seconds >= 0, not -1"),
    "unload of a name that is no text": (lambda kb: kb.unload(5), "SLRError",
                                         "a program name is a non-empty string, not 5"),
    "load under a name that is no text": (lambda kb: kb.load("p(1).", name=5), "SLRError",
                                          "a program name is a non-empty string, not 5"),
    "load of text that is no str": (lambda kb: kb.load(b"p(1)."), "SLRError",
                                    "load takes program text (a str), not a bytes"),
    "load with a filename that is no str": (lambda kb: kb.load("p(1).", 5), "SLRError",
                                            "load: filename is the text shown in messages"),
    "load_file of a path that is no path": (lambda kb: kb.load_file(5), "SLRError",
                                            "load_file takes a file's path (a str or a "
                                            "pathlib.Path), not 5"),
    "load_file of a missing file": (lambda kb: kb.load_file("/no/such/dir/rules.slr"),
                                    "SLRError",
                                    "/no/such/dir/rules.slr: No such file or directory"),
    "add of no text": (lambda kb: kb.add(("p", [1], 1.0, 1.0)), "SLRError",
                       "add takes one event written in SLR syntax (a str), not a tuple"),
    "add_event arguments that are no list": (lambda kb: kb.add_event("p", 5, 1.0),
                                             "EventRejected",
                                             "event arguments must be a list or tuple, not "
                                             "int 5"),
    # remotely list("ab") was sent: an event p(a, b) that a local store refuses
    "add_event arguments that are a str": (lambda kb: kb.add_event("p", "ab", 1.0),
                                           "EventRejected",
                                           "event arguments must be a list or tuple, not "
                                           "str 'ab'"),
    "mark_complete at a time that is text": (lambda kb: kb.mark_complete("p/1", "x"),
                                             "SLRError",
                                             "mark_complete: t must be a number of seconds, "
                                             "not 'x'"),
    "mark_complete of a type that is no text": (lambda kb: kb.mark_complete(5, 1.0),
                                                "SLRError",
                                                "mark_complete: the event type is text such as"),
    "complete_until of a type that is no text": (lambda kb: kb.complete_until(None),
                                                 "SLRError",
                                                 "complete_until: the event type is text such "
                                                 "as"),
    "keep_last that is text": (lambda kb: kb.add_buffer("p(_)", keep_last="x"), "SLRError",
                               "keep_last must be a non-negative integer, not 'x'"),
    "keep_last that is a bool": (lambda kb: kb.add_buffer("p(_)", keep_last=True),
                                 "SLRError",
                                 "keep_last must be a non-negative integer, not True"),
    "negative keep_seconds": (lambda kb: kb.add_buffer("p(_)", keep_seconds=-1), "SLRError",
                              "keep_seconds must be a non-negative number of seconds, not -1"),
    "keep_between that is no pair": (lambda kb: kb.add_buffer("p(_)", keep_between=5),
                                     "SLRError",
                                     "keep_between must be a pair of times (T1, T2)"),
    "sql statement that is no text": (lambda kb: kb.sql(5), "SLRError",
                                      "sql: the statement is text (a str), not a int"),
    # locally "sql: a parameter cannot be bound: unsupported operand type(s) ..."
    "sql timeout that is text": (lambda kb: kb.sql("SELECT 1", timeout="x"), "SLRError",
                                 "sql: timeout must be a number of seconds, not 'x'"),
    "subscribe with max_queue 0": (lambda kb: kb.subscribe("p(X)^T", max_queue=0),
                                   "SLRError",
                                   "subscribe: max_queue must be a positive integer, not 0"),
    "subscribe with max_lag 0": (lambda kb: kb.subscribe("p(X)^T", max_lag=0), "SLRError",
                                 "subscribe: max_lag must be a positive integer or None, "
                                 "not 0"),
    "subscribe since a time that is text": (lambda kb: kb.subscribe("p(X)^T", since="x"),
                                            "SLRError",
                                            "subscribe: since must be a number of seconds, "
                                            "not 'x'"),
    # since and until had a check of their own, in other words ("must be a number, not NaN")
    "subscribe since NaN": (lambda kb: kb.subscribe("p(X)^T", since=math.nan), "SLRError",
                            "subscribe: since must be a number of seconds, not nan"),
    "subscribe until NaN": (lambda kb: kb.subscribe("p(X)^T", until=math.nan), "SLRError",
                            "subscribe: until must be a number of seconds, not nan"),
    "subscribe until beyond a float": (lambda kb: kb.subscribe("p(X)^T", until=10 ** 400),
                                       "SLRError", "subscribe: until is out of range (an "
                                       "integer of 1329 bits)"),
    # the flag was taken by its truth: ack="no" acknowledged
    "close with ack that is text": (
        lambda kb: _on_subscription(kb, lambda s: s.close(ack="no")), "SLRError",
        "close: ack must be True or False, not 'no'"),
    # (was "not 1.5NaN", SWI-Prolog's spelling, for a Python caller's nan)
    "add_buffer of a pattern that is NaN": (lambda kb: kb.add_buffer(math.nan, keep_last=1),
                                            "SLRError", "a buffer pattern must be an event "
                                            "term, not nan"),
    "subscribe where no goal": (lambda kb: kb.subscribe("p(X)^T", where=5), "SLRError",
                                "subscribe: where must be a goal as text, not 5"),
    "subscribe to a pattern that is no text": (lambda kb: kb.subscribe(5), "SLRError",
                                               "subscribe: the pattern must be text"),
    # locally max_steps="x" was taken (and ignored until the step count was compared)
    "max_steps that is text": (lambda kb: kb.query("true", max_steps="x"), "SLRError",
                               "max_steps must be a count (an integer >= 0), not 'x'"),
    "negative max_steps": (lambda kb: kb.query("true", max_steps=-1), "SLRError",
                           "max_steps must be a count (an integer >= 0), not -1"),
    # remotely the key's str() was sent: args names '5'
    "args naming no variable": (lambda kb: kb.query("X = 1", args={5: 1}), "SLRError",
                                "args names 5, which is not a variable of the goal 'X = 1'"),
    "add_event at a time that is text": (lambda kb: kb.add_event("p", [1], "x"),
                                         "EventRejected",
                                         "p(1)^'x': event times must be numbers (got 'x')"),
    "add_event ending at a time that is text": (lambda kb: kb.add_event("p", [1], 1.0, "x"),
                                                "EventRejected",
                                                "p(1)^[1.0,'x']: event times must be numbers"),
    "add_event of an argument that is no term": (lambda kb: kb.add_event("p", [None], 1.0),
                                                 "EventRejected",
                                                 "p(None)^1.0: event argument cannot be "
                                                 "stored"),
    "add_many of a tuple at a time that is text": (
        lambda kb: [(e.index, type(e).__name__, str(e))
                    for e in kb.add_many([("p", [1], "x", 1.0)])],
        "value", "event times must be numbers (got 'x')"),
    # remotely "the query parameter "type" (p/N) is required"
    "complete_until of an empty type": (lambda kb: kb.complete_until(""), "SLRError",
                                        "expected an event type p/N or p, not "),
    # remotely a path no route matched: ServiceError (NotFound), "no such endpoint"
    "remove_buffer of a negative id": (lambda kb: kb.remove_buffer(-1), "BufferNotFound",
                                       "no active buffer #-1"),
    "add_buffer of a pattern that is no term": (lambda kb: kb.add_buffer(5, keep_last=1),
                                                "SLRError",
                                                "a buffer pattern must be an event term, "
                                                "not 5"),
    # remotely raw Python errors, no SLRError
    "sql parameters that are no sequence": (lambda kb: kb.sql("SELECT ?", 5), "SLRError",
                                            "sql: a parameter cannot be bound: 'int' object is "
                                            "not iterable"),
    # (was "plot: TypeError: 'int' object is not iterable")
    "plot of types that are no list": (lambda kb: kb.plot(5), "SLRError",
                                       "plot: types must be a text or a list of texts, not 5"),
    "unsubscribe of an id that is no text": (lambda kb: kb.unsubscribe(5), "SLRError",
                                             "no subscription with id 5"),
    # each a raw TypeError on both sides (a str compared with or added to a number)
    "result timeout that is text": (lambda kb: _on_waiting(kb, lambda p: p.result(timeout="x")),
                                    "SLRError",
                                    "result: timeout must be a number of seconds, not 'x'"),
    "exception timeout that is text": (
        lambda kb: _on_waiting(kb, lambda p: p.exception(timeout="x")), "SLRError",
        "exception: timeout must be a number of seconds, not 'x'"),
    "get timeout that is text": (lambda kb: _on_subscription(kb, lambda s: s.get(timeout="x")),
                                 "SLRError", "get: timeout must be a number of seconds, not 'x'"),
    # a local subscription's get(timeout=nan) waited for ever; remotely at once, "within nan s"
    "get timeout NaN": (lambda kb: _on_subscription(kb, lambda s: s.get(timeout=math.nan)),
                        "SLRError", "get: timeout must be a number of seconds >= 0, not nan"),
    # an SLRTimeout "within -1 s" on both sides
    "result with a negative timeout": (
        lambda kb: _on_waiting(kb, lambda p: p.result(timeout=-1)), "SLRError",
        "result: timeout must be a number of seconds >= 0, not -1"),
    # each taken, then failing on a thread of its own where it was only logged
    "submit with a callback that is no function": (
        lambda kb: kb.submit("true", at=0, callback=5), "SLRError",
        "callback must be callable (a function), not 5"),
    "add_done_callback of no function": (
        lambda kb: _on_waiting(kb, lambda p: p.add_done_callback("print")), "SLRError",
        "add_done_callback: fn must be callable (a function), not 'print'"),
    # remotely define was refused whatever its arguments, locally they were taken as given
    "define of a function that is no function": (lambda kb: kb.define("p", 1, 5), "SLRError",
                                                 "define: fn must be callable (a function), "
                                                 "not 5"),
    "define of an arity that is text": (lambda kb: kb.define("p", "1", abs), "SLRError",
                                        "define: arity must be a count (an integer >= 0), "
                                        "not '1'"),
    # flags were taken by their truth: "no" replaced, atomic="no" was atomic
    "load with replace that is text": (lambda kb: kb.load("p(1).", replace="no"), "SLRError",
                                       "load: replace must be True or False, not 'no'"),
    "add_many with atomic that is text": (lambda kb: kb.add_many([], atomic="no"), "SLRError",
                                          "add_many: atomic must be True or False, not 'no'"),
    "query with wait that is text": (lambda kb: kb.query("true", wait="no"), "SLRError",
                                     "wait must be True or False, not 'no'"),
    "sql with write that is a number": (lambda kb: kb.sql("SELECT 1", write=1), "SLRError",
                                        "sql: write must be True or False, not 1"),
    # locally str(5) became the id; a list was "submit: TypeError: unhashable type: 'list'"
    "submit with an id that is no text": (lambda kb: kb.submit("true", at=0, id=5), "SLRError",
                                          "id must be a non-empty string (or None: one is "
                                          "made), not 5"),
    # locally "query: TypeError: unhashable type: 'list'"
    "goal that is a list, with args": (lambda kb: kb.query(["p(X)"], args={"X": 1}),
                                       "SLRError", "a goal is SLR text (a str), not list"),
    "goal that is a list": (lambda kb: kb.query(["p(X)"]), "SLRError",
                            "a goal is SLR text (a str), not list"),
    "unsubscribe of an id that is a list": (lambda kb: kb.unsubscribe([1]), "SLRError",
                                            "no subscription with id [1]"),
    # "a duration must be a non-negative number of seconds, not x": which argument?
    "keep_seconds that is no duration": (lambda kb: kb.add_buffer("p(_)", keep_seconds="x"),
                                         "SLRError", "keep_seconds must be a non-negative "
                                         "number of seconds or a duration"),
}


def _on_waiting(kb, call):
    """``call`` on a synchronized query that waits (no mark reaches its time), then
    cancelled."""
    pending = kb.submit("findall(W, w(W)^_, L)", at=1e12)
    try:
        return call(pending)
    finally:
        pending.cancel()


def _on_subscription(kb, call):
    """``call`` on a subscription to a type nobody adds, then closed."""
    with kb.subscribe("nobody(X)^T") as sub:
        return call(sub)


# what a local knowledge base takes, taken remotely too (the server refused it)
SAME_VALUE = {
    # (stamped now: the stores' clocks are wall clocks)
    "an event named ''": lambda kb: kb.add_event("", [1], time.time()),
    "a bool as an SQL parameter": lambda kb: kb.sql("SELECT ? + 1", [True]),
    # any numbers.Real is a number of seconds, as mark_complete's time always was (numpy's
    # numbers were refused by at=, timeout=, since=; remotely by mark_complete too)
    "numpy numbers as at and timeout": lambda kb: kb.query("X = 1", at=np.int64(5),
                                                           timeout=np.int64(10)),
    "a Fraction as at and a numpy timeout for solutions": lambda kb: list(kb.solutions(
        "X = 1", at=Fraction(1, 2), timeout=np.float32(10))),
    "numpy numbers for submit and result": lambda kb: kb.submit(
        "X = 1", at=np.float32(0), timeout=np.float32(10)).result(timeout=np.float32(10)),
    "a numpy time for mark_complete": lambda kb: kb.mark_complete("numpy/1", np.int64(5)),
    "a numpy timeout for sql": lambda kb: kb.sql("SELECT 1 AS one", timeout=np.int64(5)),
    "numpy since and a Fraction until": lambda kb: kb.subscribe(
        "nobody(X)^T", since=np.int64(0), until=Fraction(1, 2)).close(),
}


@pytest.mark.parametrize("condition", sorted(SAME_VALUE))
def test_what_a_local_knowledge_base_takes_is_taken_remotely_too(pair, condition):
    local, remote = (_error(SAME_VALUE[condition], kb) for kb in pair)
    assert local == remote and local[0] == "value", (local, remote)


@pytest.mark.parametrize("condition", sorted(SAME_WORDS))
def test_a_refused_argument_is_the_same_error_in_the_same_words_local_and_remote(
        pair, condition):
    call, expected_class, expected_words = SAME_WORDS[condition]
    local, remote = (_error(call, kb) for kb in pair)
    assert local == remote
    assert local[0] == expected_class and expected_words in local[1], local


def test_a_callback_that_is_no_function_is_refused_before_anything_waits(pair, caplog):
    """kb.submit(goal, callback=5) was taken: the query was registered (remotely: submitted
    to the server), and once it was answered the Future only logged "exception calling
    callback" with a TypeError, on a thread of its own. It is refused at the call, on both,
    and nothing waits."""
    for kb in pair:
        with pytest.raises(slr_sql.SLRError, match="callback must be callable"):
            kb.submit("findall(W, w(W)^_, L)", at=1e12, id="never", callback=5)
        assert [p.id for p in kb.pending()] == []
        with pytest.raises(slr_sql.SLRError, match="subscribe: callback must be callable"):
            kb.subscribe("p(X)^T", callback="print")
        pending = kb.submit("true", at=0)
        assert pending.result(timeout=10) == [{}]
        with pytest.raises(slr_sql.SLRError, match="add_done_callback: fn must be callable"):
            pending.add_done_callback(5)    # (done: a Future would call it now)
    assert "exception calling callback" not in caplog.text


# -- every argument of every public method, given a value of the wrong kind -------------------
#
# Each (method, parameter) gets the wrong kinds of value its kind of parameter can meet: text
# where a number is expected, NaN, a negative timeout, a bool where a count or a number is
# expected, None where a value is required, a non-callable where a function is. Every one is
# an SLRError (a subclass at most) naming what is wrong, of the same class locally and
# through `slr serve`, and never the boundary's fallback words for a Python error
# ("query: TypeError: ...").

NAN, INF = math.nan, math.inf
TIME = ["x", NAN, True, [1], b"1"]                  # at=, since=, t, start, end
TIMEOUT = ["x", NAN, True, [1], -1, -INF]           # timeout= (seconds >= 0)
COUNT = ["x", 1.5, True, -1, NAN, None]             # limit=, max_steps=, keep_last=
TEXT = [5, None, True, [1], b"p"]                   # a goal, a program, a pattern, a name
CALLABLE = [5, "print", True, [print]]              # callback=, fn
FLAG = ["no", 1, None, 0.0]                         # replace=, atomic=, wait=, write=
MAPPING = [[1], "X", 5, True]                       # args=
ROBOT = [5, True, "", [1]]
EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "tea.slr"


def _listed(iterator):
    return list(iterator)


# "method.parameter": (the call given the bad value, its values, words the message holds)
SWEEP = {
    "load.text": (lambda kb, v: kb.load(v), TEXT, "program text"),
    "load.filename": (lambda kb, v: kb.load("p(1).", v), [5, None, True, [1]], "filename"),
    "load.name": (lambda kb, v: kb.load("p(1).", name=v), TEXT + [""], "program name"),
    "load.replace": (lambda kb, v: kb.load("p(1).", name="swept", replace=v), FLAG,
                     "replace"),
    "load_file.path": (lambda kb, v: kb.load_file(v), [5, None, True, [1]], "path"),
    "load_file.name": (lambda kb, v: kb.load_file(EXAMPLE, name=v), TEXT + [""],
                       "program name"),
    "load_file.replace": (lambda kb, v: kb.load_file(EXAMPLE, name="swept", replace=v), FLAG,
                          "replace"),
    "unload.name": (lambda kb, v: kb.unload(v), TEXT + [""], "program name"),
    "define.name": (lambda kb, v: kb.define(v, 1, abs), [5, None, True, [1]], "name"),
    "define.arity": (lambda kb, v: kb.define("p", v, abs), COUNT, "arity"),
    "define.fn": (lambda kb, v: kb.define("p", 1, v), CALLABLE + [None], "fn"),
    "add.text": (lambda kb, v: kb.add(v), TEXT, "add takes one event"),
    "add_event.name": (lambda kb, v: kb.add_event(v, [1], 1.0), [5, None, True, [1]],
                       "event name"),
    "add_event.args": (lambda kb, v: kb.add_event("p", v, 1.0), [5, None, True, "ab"],
                       "event arguments"),
    "add_event.start": (lambda kb, v: kb.add_event("p", [1], v), TIME + [None], "event times"),
    "add_event.end": (lambda kb, v: kb.add_event("p", [1], 1.0, v), TIME, "event times"),
    "add_many.events": (lambda kb, v: kb.add_many(v), [5, None, True, NAN],
                        "add_many takes an iterable"),
    "add_many.atomic": (lambda kb, v: kb.add_many(["p(1)^1"], atomic=v), FLAG, "atomic"),
    "query.goal": (lambda kb, v: kb.query(v), TEXT, "a goal is SLR text"),
    "query.at": (lambda kb, v: kb.query("true", at=v), TIME, "at must be"),
    "query.args": (lambda kb, v: kb.query("true", args=v), MAPPING, "args must be"),
    "query.timeout": (lambda kb, v: kb.query("true", timeout=v), TIMEOUT, "timeout must be"),
    "query.max_steps": (lambda kb, v: kb.query("true", max_steps=v), COUNT[:-1],
                        "max_steps must be"),
    "query.limit": (lambda kb, v: kb.query("true", limit=v), COUNT[:-1], "limit must be"),
    "query.wait": (lambda kb, v: kb.query("true", wait=v), FLAG, "wait must be"),
    "query.robot": (lambda kb, v: kb.query("true", robot=v), ROBOT, "robot"),
    "solutions.goal": (lambda kb, v: _listed(kb.solutions(v)), TEXT, "a goal is SLR text"),
    "solutions.at": (lambda kb, v: _listed(kb.solutions("true", at=v)), TIME, "at must be"),
    "solutions.args": (lambda kb, v: _listed(kb.solutions("true", args=v)), MAPPING,
                       "args must be"),
    "solutions.timeout": (lambda kb, v: _listed(kb.solutions("true", timeout=v)), TIMEOUT,
                          "timeout must be"),
    "solutions.robot": (lambda kb, v: _listed(kb.solutions("true", robot=v)), ROBOT, "robot"),
    "goal_warnings.goal": (lambda kb, v: kb.goal_warnings(v), TEXT, "a goal is SLR text"),
    "explain.goal": (lambda kb, v: kb.explain(v), TEXT, "a goal is SLR text"),
    "submit.goal": (lambda kb, v: kb.submit(v, at=0), TEXT, "a goal is SLR text"),
    "submit.at": (lambda kb, v: kb.submit("true", at=v), TIME, "at must be"),
    "submit.id": (lambda kb, v: kb.submit("true", at=0, id=v), [5, True, "", [1], NAN],
                  "id must be"),
    "submit.args": (lambda kb, v: kb.submit("true", at=0, args=v), MAPPING, "args must be"),
    "submit.timeout": (lambda kb, v: kb.submit("true", at=0, timeout=v), TIMEOUT,
                       "timeout must be"),
    "submit.callback": (lambda kb, v: kb.submit("true", at=0, callback=v), CALLABLE,
                        "callback must be callable"),
    "submit.robot": (lambda kb, v: kb.submit("true", at=0, robot=v), ROBOT, "robot"),
    "ask.goal": (lambda kb, v: asyncio.run(kb.ask(v, at=0)), TEXT, "a goal is SLR text"),
    "ask.at": (lambda kb, v: asyncio.run(kb.ask("true", at=v)), TIME, "at must be"),
    "ask.id": (lambda kb, v: asyncio.run(kb.ask("true", at=0, id=v)), [5, True, "", [1]],
               "id must be"),
    "ask.args": (lambda kb, v: asyncio.run(kb.ask("true", at=0, args=v)), MAPPING,
                 "args must be"),
    "ask.timeout": (lambda kb, v: asyncio.run(kb.ask("true", at=0, timeout=v)), TIMEOUT,
                    "timeout must be"),
    "ask.robot": (lambda kb, v: asyncio.run(kb.ask("true", at=0, robot=v)), ROBOT, "robot"),
    "mark_complete.event_type": (lambda kb, v: kb.mark_complete(v, 1.0), TEXT + [""],
                                 "event type"),
    "mark_complete.t": (lambda kb, v: kb.mark_complete("swept/1", v), TIME + [None],
                        "t must be"),
    "complete_until.event_type": (lambda kb, v: kb.complete_until(v), TEXT + [""],
                                  "event type"),
    "add_buffer.pattern": (lambda kb, v: kb.add_buffer(v, keep_last=1), [5, None, True, [1]],
                           "pattern"),
    "add_buffer.keep_last": (lambda kb, v: kb.add_buffer("p(_)", keep_last=v), COUNT[:-1],
                             "keep_last"),
    "add_buffer.keep_seconds": (lambda kb, v: kb.add_buffer("p(_)", keep_seconds=v),
                                ["x", NAN, -1, True, [1]], "keep_seconds"),
    "add_buffer.keep_between": (lambda kb, v: kb.add_buffer("p(_)", keep_between=v),
                                [5, "x", (NAN, 1), ("x", 1), (1,), (True, 2)],
                                "keep_between"),
    "remove_buffer.buffer_id": (lambda kb, v: kb.remove_buffer(v),
                                ["x", 1.5, True, None, [1], NAN], "buffer id"),
    "sql.query": (lambda kb, v: kb.sql(v), [5, None, True, [1]], "statement"),
    "sql.params": (lambda kb, v: kb.sql("SELECT 1", v), [5, True, NAN], "parameter"),
    "sql.write": (lambda kb, v: kb.sql("SELECT 1", write=v), FLAG, "write"),
    "sql.timeout": (lambda kb, v: kb.sql("SELECT 1", timeout=v), TIMEOUT, "timeout must be"),
    "plot.types": (lambda kb, v: kb.plot(v), [5, True, NAN], "types"),
    "subscribe.pattern": (lambda kb, v: kb.subscribe(v), TEXT, "pattern"),
    "subscribe.where": (lambda kb, v: kb.subscribe("p(X)^T", where=v), [5, True, [1]],
                        "where"),
    "subscribe.since": (lambda kb, v: kb.subscribe("p(X)^T", since=v), TIME + [None],
                        "since"),
    "subscribe.until": (lambda kb, v: kb.subscribe("p(X)^T", until=v), TIME, "until"),
    "subscribe.id": (lambda kb, v: kb.subscribe("p(X)^T", id=v), [5, True, "", [1]], "id"),
    "subscribe.callback": (lambda kb, v: kb.subscribe("p(X)^T", callback=v), CALLABLE,
                           "callback must be callable"),
    "subscribe.max_queue": (lambda kb, v: kb.subscribe("p(X)^T", max_queue=v),
                            COUNT + [0], "max_queue"),
    "subscribe.max_lag": (lambda kb, v: kb.subscribe("p(X)^T", max_lag=v), COUNT[:-1] + [0],
                          "max_lag"),
    "unsubscribe.id": (lambda kb, v: kb.unsubscribe(v), [5, None, True, [1]],
                       "no subscription"),
    # the PendingQuery of submit (a Future: exception() too) and the Subscription of subscribe
    "PendingQuery.result.timeout": (
        lambda kb, v: _on_waiting(kb, lambda p: p.result(timeout=v)), TIMEOUT,
        "result: timeout must be"),
    "PendingQuery.exception.timeout": (
        lambda kb, v: _on_waiting(kb, lambda p: p.exception(timeout=v)), TIMEOUT,
        "exception: timeout must be"),
    "PendingQuery.add_done_callback.fn": (
        lambda kb, v: _on_waiting(kb, lambda p: p.add_done_callback(v)), CALLABLE + [None],
        "add_done_callback: fn must be callable"),
    "Subscription.get.timeout": (
        lambda kb, v: _on_subscription(kb, lambda s: s.get(timeout=v)), TIMEOUT,
        "get: timeout must be"),
}

# parameters the sweep leaves out, and why
NOT_SWEPT = {
    "plot.options": "keyword options of the timeline, checked by plot (tests/test_plot.py)",
    "__exit__.exc": "the context manager protocol: Python passes them",
    "Subscription.__exit__.exc_type": "the context manager protocol: Python passes them",
    "Subscription.__exit__.rest": "the context manager protocol: Python passes them",
}


def _parameters(proto: type, prefix: str) -> set[str]:
    found = set()
    for name in dir(proto):
        fn = getattr(proto, name, None)
        if not callable(fn) or (name.startswith("_") and name not in ("__enter__", "__exit__")):
            continue
        found |= {f"{prefix}{name}.{p}" for p in inspect.signature(fn).parameters if p != "self"}
    return found


def test_the_sweep_covers_every_parameter_of_every_public_method():
    every = (_parameters(KnowledgeBaseAPI, "") | _parameters(PendingQueryAPI, "PendingQuery.")
             | _parameters(SubscriptionAPI, "Subscription.")
             | {"PendingQuery.exception.timeout"})   # (a Future's, not in the protocol)
    assert every - set(SWEEP) - set(NOT_SWEPT) == set()
    assert set(SWEEP) - every == set()


# (a value's repr, short and the same in every run: an id of each case)
def _value_id(value) -> str:
    return {NAN: "nan", INF: "inf", -INF: "-inf"}.get(value, repr(value)) \
        if isinstance(value, float) else repr(value)


SWEPT = [pytest.param(key, value, id=f"{key}={_value_id(value)}")
         for key, (_call, values, _words) in SWEEP.items() for value in values]


@pytest.mark.parametrize("key, value", SWEPT)
def test_a_wrong_kind_of_argument_is_an_slr_error_in_words_local_and_remote(pair, key, value):
    call, _values, words = SWEEP[key]
    local, remote = pair
    outcomes = []
    for kb in (local, remote):
        try:
            got = call(kb, value)
        except slr_sql.SLRError as exc:
            outcomes.append((type(exc).__name__, str(exc)))
            continue
        if hasattr(got, "close"):          # (a subscription made after all)
            got.close()
        outcomes.append(("value", repr(got)))
    (local_class, local_words), (remote_class, remote_words) = outcomes
    assert local_class != "value" and local_class == remote_class, outcomes
    for said in (local_words, remote_words):
        assert words in said, outcomes
        assert not re.search(r"\b(Type|Value|Attribute|Key|Index|Overflow)Error\b", said), \
            outcomes
