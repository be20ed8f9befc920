"""Bad input to the library: every event that cannot be stored is an EventRejected with its
reason (never a raw Python or sqlite3 exception), and nothing else in its batch is lost."""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import slr_sql
from slr_sql import EventRejected, SLRError
from slr_sql.store import EventStore
from slr_sql.terms import Atom, String, Struct

@pytest.fixture
def kb():
    """A fresh in-memory store with a ManualClock: the events here are stamped 1.0, 2.0 (on a
    wall clock they would be "decades late", a LearnedDelayWarning); nothing here waits on
    the store's time."""
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as k:
        yield k


def stored(kb, name: str, arity: int) -> list:
    """The argument tuples of the stored events name/arity, in store order."""
    return [args for args, *_ in kb.store.scan(name, arity)]


# ---------------------------------------------------------------- arguments that cannot be stored

SURROGATE = "\ud800"

BAD_ARGUMENTS = [
    pytest.param([10 ** 5000], "too large", id="integer of 5001 digits"),
    pytest.param([-(10 ** 5000)], "too large", id="negative integer of 5001 digits"),
    pytest.param([[1, 10 ** 5000]], "too large", id="huge integer inside a list"),
    pytest.param([Struct("f", (10 ** 5000,))], "too large", id="huge integer inside a compound"),
    pytest.param(["a" + SURROGATE], "surrogate", id="lone surrogate in an atom"),
    pytest.param([String("x\udc00y")], "surrogate", id="lone surrogate in a string"),
    pytest.param([["ok", "b" + SURROGATE]], "surrogate", id="lone surrogate in a list"),
    pytest.param([Struct("f" + SURROGATE, (1,))], "surrogate", id="lone surrogate in a functor"),
    pytest.param([Atom("[" + SURROGATE)], "surrogate", id="lone surrogate in a JSON-escaped atom"),
]


@pytest.mark.parametrize("args, reason", BAD_ARGUMENTS)
def test_unstorable_arguments_are_rejected_and_the_rest_of_the_batch_is_kept(kb, args, reason):
    with pytest.raises(EventRejected, match=reason) as raised:
        kb.add_event("p", args, 1.0)
    assert str(raised.value).startswith("p(")
    errors = kb.add_many([("p", [0], 0.0, 0.0), ("p", args, 1.0, 1.0), ("p", [2], 2.0, 2.0)])
    assert [e.index for e in errors] == [1] and reason in str(errors[0])
    assert stored(kb, "p", 1) == [(0,), (2,)]


def test_a_lone_surrogate_in_the_event_name_is_rejected(kb):
    errors = kb.add_many([("p" + SURROGATE, [1], 1.0, 1.0), ("p", [1], 1.0, 1.0)])
    assert [e.index for e in errors] == [0] and "surrogate" in str(errors[0])
    assert stored(kb, "p", 1) == [(1,)]


def test_a_lone_surrogate_written_as_an_escape_in_event_text_is_rejected(kb):
    # the parser refuses the escape where it stands (a syntax error with its column)
    with pytest.raises(slr_sql.SLRSyntaxError, match="not a Unicode character"):
        kb.add("p('\\xD800\\')^1")
    assert kb.query("p(X)^T") == []


TEXT_WITH_SURROGATES = st.lists(st.one_of(st.characters(), st.integers(0xD800, 0xDFFF).map(chr)),
                                max_size=8).map("".join)


@given(TEXT_WITH_SURROGATES)
def test_any_text_is_stored_exactly_or_rejected_for_its_surrogates(text):
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        has_surrogate = any(0xD800 <= ord(c) <= 0xDFFF for c in text)
        for value in (Atom(text), String(text), [Atom(text)], Struct("f", (String(text),))):
            try:
                kb.add_event("p", [value], 1.0)
            except EventRejected as exc:
                assert has_surrogate, exc
                continue
            assert not has_surrogate
        if not has_surrogate:
            values = [args[0] for args in stored(kb, "p", 1)]
            assert values == [Atom(text), String(text), slr_sql.terms.make_list([Atom(text)]),
                              Struct("f", (String(text),))]


def test_the_largest_integers_that_fit_are_stored_exactly(kb):
    big = 10 ** 4000 + 7
    kb.add_event("p", [big, [-big]], 1.0)
    assert kb.query("p(X, Y)^_") == [{"X": big, "Y": [-big]}]


# ---------------------------------------------------------------- too many arguments

def test_an_event_with_2000_arguments_is_rejected_not_a_raw_sqlite_error(kb):
    with pytest.raises(EventRejected, match="too many arguments"):
        kb.add_event("wide", list(range(2000)), 1.0)
    with pytest.raises(EventRejected, match="too many arguments"):
        kb.add("wide(" + ",".join(["1"] * 2000) + ")^1")
    errors = kb.add_many([("wide", list(range(2000)), 1.0, 1.0), ("wide", [1], 1.0, 1.0)])
    assert [e.index for e in errors] == [0] and "too many arguments" in str(errors[0])
    assert stored(kb, "wide", 1) == [(1,)]


def test_the_widest_event_that_fits_is_stored_and_read_back(kb):
    widest = kb.store.max_event_arity
    kb.add_event("wide", list(range(widest)), 1.0)
    assert stored(kb, "wide", widest) == [tuple(range(widest))]
    with pytest.raises(EventRejected, match="too many arguments"):
        kb.add_event("wide", list(range(widest + 1)), 1.0)


def test_the_widest_event_type_that_fits_can_be_declared(kb):
    widest = kb.store.max_event_arity
    kb.load(f":- event wide/{widest}.")
    with pytest.raises(SLRError, match="too many arguments"):
        kb.load(f":- event wider/{widest + 1}.")
    assert kb.store.declared_types() == {("wide", widest)}


def test_declaring_an_event_type_with_too_many_arguments_is_an_error(kb):
    with pytest.raises(SLRError, match="too many arguments"):
        kb.load(":- event wide/5000.")
    kb.load(":- event wide/3.")  # the failed load changed nothing
    assert kb.store.declared_types() == {("wide", 3)}


@pytest.mark.parametrize("name, arity", [(5, 1), (None, 2), ("p", -1), ("p", "2"),
                                         ("p", 1.0)])
def test_the_store_refuses_a_type_that_is_no_name_and_arity(name, arity):
    store = EventStore(None)
    with pytest.raises(ValueError, match="bad event type"):
        store.declare_type(name, arity)
    assert store.declared_types() == set()


# ---------------------------------------------------------------- the argument list itself

@pytest.mark.parametrize("args, shown", [
    pytest.param(None, "None", id="None"),
    pytest.param("abc", "'abc'", id="a str (not split into characters)"),
    pytest.param(5, "5", id="an int"),
    pytest.param({"a": 1}, "{'a': 1}", id="a dict"),
    pytest.param(Atom("abc"), "abc", id="an Atom"),
])
def test_arguments_must_be_a_list_or_tuple(kb, args, shown):
    with pytest.raises(EventRejected, match="arguments must be a list or tuple") as raised:
        kb.add_event("p", args, 1.0)
    assert shown in str(raised.value)
    errors = kb.add_many([("p", args, 1.0, 1.0), ("p", ["ok"], 1.0, 1.0)])
    assert [e.index for e in errors] == [0]
    assert "arguments must be a list or tuple" in str(errors[0])
    errors = kb.store.add_events([("p", args, 1.0, 1.0)])
    assert len(errors) == 1 and "arguments must be a list or tuple" in str(errors[0])
    assert kb.query("findall(X, p(X)^_, L)") == [{"L": [Atom("ok")]}]
    assert kb.store.table_for("p", 3) is None


def test_a_list_of_arguments_is_still_accepted(kb):
    kb.add_event("p", ["a", [1, 2]], 1.0)
    kb.store.add_events([("p", ["b", [3]], 2.0, 2.0)])
    assert kb.query("p(X, Y)^_") == [{"X": "a", "Y": [1, 2]}, {"X": "b", "Y": [3]}]


# ---------------------------------------------------------------- times

@pytest.mark.parametrize("text, reason", [
    pytest.param('foo(1)^"1"', "must be a number", id="a string time (not its character code)"),
    pytest.param('foo(1)^[1, "2"]', "must be a number", id="a string end time"),
    pytest.param("foo(1)^[[1], 2]", "must be a number", id="a list start time"),
    pytest.param("foo(1)^(2**2000)", "finite", id="a time too large for a float"),
    pytest.param("foo(1)^" + "9" * 400, "finite", id="an integer time too large for a float"),
])
def test_event_times_must_be_numbers(kb, text, reason):
    with pytest.raises(EventRejected, match=reason):
        kb.add(text)
    errors = kb.add_many(["foo(0)^0", text, "foo(2)^2"])
    assert [e.index for e in errors] == [1]
    assert kb.query("findall(X-T, foo(X)^T, L)") == [{"L": [Struct("-", (0, 0.0)),
                                                           Struct("-", (2, 2.0))]}]


class _NoRepr:
    def __repr__(self):
        raise RuntimeError("repr failed")


@pytest.mark.parametrize("args", [(1, 2), [1, 2]], ids=["tuple", "list"])
def test_a_rejected_event_is_named_with_its_arguments(kb, args):
    """The message starts with the event as written (a list of arguments too), and a time
    whose repr fails is described by its type, not by the failure."""
    with pytest.raises(EventRejected) as raised:
        kb.add_event("p", args, float("nan"))
    assert str(raised.value).startswith("p(1,2)^[nan,nan]: event times must be finite")
    for errors in (kb.add_many([("p", args, float("nan"), float("nan"))]),
                   kb.store.add_events([("p", args, float("nan"), float("nan"))])):
        assert [str(e) for e in errors] == [
            "p(1,2)^[nan,nan]: event times must be finite (not inf or NaN)"]
    with pytest.raises(EventRejected) as raised:
        kb.add_event("p", args, _NoRepr())
    assert str(raised.value) == "p(1,2)^a _NoRepr: event times must be numbers (got a _NoRepr)"
    assert kb.query("findall(X, p(X, _)^_, L)") == [{"L": []}]


NAN, INF = float("nan"), float("inf")


@pytest.mark.parametrize("event, message", [
    pytest.param(("p", [NAN], 1.0, 2.0), "p(nan)^[1.0,2.0]: event arguments must not contain NaN",
                 id="NaN argument"),
    pytest.param(("p", [[1, NAN]], 2.0, 2.0), "p([1,nan])^2.0: event arguments must not contain NaN",
                 id="NaN in a list"),
    pytest.param("p(f(1.5NaN))^2", "p(f(nan))^2.0: event arguments must not contain NaN",
                 id="NaN written in SLR"),
    pytest.param(("p", [INF, -INF], 3.0, 2.0), "p(inf,-inf)^[3.0,2.0]: start time 3.0 is after "
                 "end time 2.0", id="infinite arguments beside a bad time"),
    pytest.param(("p", [NAN], NAN, 2.0), "p(nan)^[nan,2.0]: event times must be finite "
                 "(not inf or NaN)", id="NaN argument and time"),
])
def test_a_rejection_writes_nan_and_infinity_as_its_times_are_written(kb, event, message):
    """A rejection writes a NaN or infinite argument as it writes a time (``nan``, ``inf``),
    not in SWI-Prolog's syntax of its answers (``1.5NaN``, ``1.0Inf``), which reads as a
    number with a typo."""
    assert [str(e) for e in kb.add_many([event])] == [message]
    if type(event) is tuple:
        assert [str(e) for e in kb.store.add_events([event])] == [message]
    assert kb.query("findall(X, p(X)^_, L)") == [{"L": []}]


@pytest.mark.parametrize("name, written", [("ok", "ok"), ("My Event", "'My Event'"),
                                           ("it's", "'it\\'s'")])
def test_a_rejected_event_without_arguments_is_named_as_an_atom(kb, name, written):
    with pytest.raises(EventRejected) as raised:
        kb.add_event(name, [], float("inf"))
    assert str(raised.value) == f"{written}^inf: event times must be finite (not inf or NaN)"


def test_arithmetic_times_are_still_evaluated(kb):
    kb.add("foo(1)^(2 + 0.5)")
    kb.add("foo(2)^[1, 2*2]")
    assert kb.query("foo(X)^[S, E]") == [{"X": 1, "S": 2.5, "E": 2.5},
                                         {"X": 2, "S": 1.0, "E": 4.0}]


@pytest.mark.parametrize("text, reason", [
    pytest.param("fullyUpdated(seg/2)^[5,3]", "after end time", id="mark with start after end"),
    pytest.param('fullyUpdated(seg/2)^"5"', "must be a number", id="mark with a string time"),
])
def test_bad_completeness_marks_are_rejected(text, reason):
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        with pytest.raises(EventRejected, match=reason):
            kb.add(text)
        assert kb.complete_until("seg/2") < 3.0
        errors = kb.add_many(["seg(a, 1)^1", text, "seg(b, 2)^2"])
        assert [e.index for e in errors] == [1]
        assert kb.complete_until("seg/2") < 3.0
        assert len(stored(kb, "seg", 2)) == 2


# ---------------------------------------------------------------- add_many's .index

def test_rejection_index_counts_the_lines_rejected_before_storing():
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        events = ["p(1)^1", "p(1^1", "p(2)^[3,2]", ("p", None, 1.0, 1.0), "p(4)^4",
                  "fullyUpdated(p/1)^[9,8]", ("p", [5], 5.0, 5.0), "p(X)^6", "p(7)^7"]
        errors = kb.add_many(events)
        assert [e.index for e in errors] == [1, 2, 3, 5, 7]
        for error in errors:
            assert error.event is events[error.index]
        assert kb.query("findall(X, p(X)^_, L)") == [{"L": [1, 4, 5, 7]}]


def test_atomic_add_many_with_a_bad_line_stores_nothing(kb):
    with pytest.raises(SLRError):
        kb.add_many(["p(1)^1", ("p", "abc", 2.0, 2.0)], atomic=True)
    with pytest.raises(SLRError):
        kb.add_many(["p(1)^1", "p(1^1"], atomic=True)
    assert kb.query("p(X)^_") == []


def test_malformed_batch_entries_are_rejected_with_their_index(kb):
    errors = kb.add_many([("p", [1], 1.0), None, 17, ("p", [1], 1.0, 1.0)])
    assert [e.index for e in errors] == [0, 1, 2]
    assert all(isinstance(e, EventRejected) for e in errors)
    assert stored(kb, "p", 1) == [(1,)]


# ---------------------------------------------------------------- query limit

@pytest.mark.parametrize("goal", [
    "p(X)^_",                     # compiled SQL
    "p(X)^_, X > 0",              # compiled SQL with a condition
    "prev(p(X)^Z, 10)",           # the single-prev fast path
    "between(1, 5, X)",           # the interpreter
    "p(X)^_, !",                  # the interpreter (cut)
])
def test_limit_zero_returns_no_answer(kb, goal):
    kb.add_many(["p(1)^1", "p(2)^2"])
    assert kb.query(goal, limit=0) == []
    assert len(kb.query(goal, limit=1)) == 1


@pytest.mark.parametrize("limit", [-1, 1.5, "2", True])
def test_a_limit_that_is_not_a_count_is_an_error(kb, limit):
    with pytest.raises(SLRError, match="limit"):
        kb.query("p(X)^_", limit=limit)


def test_the_store_rejects_a_str_argument_list_directly():
    store = EventStore(None)
    with pytest.raises(EventRejected, match="list or tuple"):
        store.add_event("p", "abc", 1.0, 1.0)
    assert store.table_for("p", 3) is None


def test_a_declared_arity_holds_after_reopen_and_in_another_connection(tmp_path):
    """``:- event p/2.`` makes p(1) a wrong-arity mistake: also for the same file opened
    again, and for a knowledge base that was already open when p/2 was declared."""
    path = tmp_path / "robot.db"
    clock = slr_sql.ManualClock(0.0)
    with slr_sql.open(path, clock=clock) as early, slr_sql.open(path, clock=clock) as kb:
        kb.load(":- event p/2.")
        with pytest.raises(EventRejected, match="wrong number of arguments"):
            early.add("p(1)^1")
    with slr_sql.open(path, clock=clock) as again:
        with pytest.raises(EventRejected, match="wrong number of arguments"):
            again.add("p(1)^1")
        again.add("p(1, 2)^1")
        assert again.query("p(X, Y)^T") == [{"X": 1, "Y": 2, "T": 1.0}]


# ---------------------------------------------------------------- arguments refused at the call
# (what only a local knowledge base has; tests/test_api_parity.py sweeps the methods both have)

NOT_A_FUNCTION = [5, "print", None, [print]]


@pytest.mark.parametrize("listeners", ["add_listeners", "load_listeners", "reload_listeners",
                                       "progress_listeners"])
@pytest.mark.parametrize("value", NOT_A_FUNCTION, ids=repr)
def test_a_listener_that_is_no_function_is_refused_as_it_is_added(kb, listeners, value):
    """kb.add_listeners took 5; the next add stored its events, then failed in its last
    stage ("add: TypeError: 'int' object is not callable"), after the commit. Each way into
    a listener list refuses it, and the knowledge base goes on as before."""
    target = getattr(kb, listeners)
    before = list(target)
    for add in (target.append, lambda v: target.insert(0, v), lambda v: target.extend([v]),
                lambda v: target.__iadd__([v]), lambda v: target.__setitem__(slice(0, 0), [v])):
        with pytest.raises(SLRError, match=f"kb.{listeners}: a listener must be callable"):
            add(value)
    if target:
        with pytest.raises(SLRError, match="must be callable"):
            target[0] = value
    assert list(target) == before
    heard = []
    kb.add_listeners.append(heard.append)
    kb.load("p(X)^T :- q(X)^T.")
    kb.add("q(1)^1")
    assert len(heard) == 1 and kb.query("p(X)^T") == [{"X": 1, "T": 1.0}]


@pytest.mark.parametrize("call, words", [
    (lambda: slr_sql.ManualClock("0"), "ManualClock: t must be a number of seconds, not '0'"),
    (lambda: slr_sql.ManualClock(float("nan")), "ManualClock: t must be a number of seconds, "
                                                "not nan"),
    (lambda: slr_sql.ManualClock(0).set("5"), "ManualClock.set: t must be a number of "
                                              "seconds, not '5'"),
    (lambda: slr_sql.ManualClock(0).set(float("nan")), "not nan"),
    (lambda: slr_sql.ManualClock(0).advance(None), "ManualClock.advance: dt must be a number "
                                                   "of seconds, not None"),
    (lambda: slr_sql.ManualClock(0).advance(-1), "dt must be a number of seconds >= 0, not -1"),
    (lambda: slr_sql.ManualClock(0).subscribe(5), "Clock.subscribe: fn must be callable"),
    (lambda: slr_sql.StreamClock().subscribe(None), "Clock.subscribe: fn must be callable"),
], ids=["ManualClock text", "ManualClock nan", "set text", "set nan", "advance None",
        "advance negative", "subscribe 5", "subscribe None"])
def test_a_clock_refuses_what_is_no_time_or_no_function(call, words):
    """ManualClock("0") was a ValueError and set("5") a TypeError; set(nan) made a clock that
    every later set compared false with; a listener that is no function was taken and made
    the next set fail (in every waiting query's release)."""
    with pytest.raises(SLRError) as refused:
        call()
    assert words in str(refused.value)


def test_a_clock_and_a_wait_take_any_real_number_of_seconds(kb):
    """A time read from a NumPy array (np.int64, np.float32) or a Fraction is a number of
    seconds to a clock and to a wait's timeout, as it always was: the check of the times
    took only int and float, and refused them."""
    clock = slr_sql.ManualClock(np.int64(2))
    clock.set(np.float32(3.5))
    clock.advance(Fraction(1, 2))
    clock.set(np.int64(5))
    assert clock.now() == 5.0 and type(clock.now()) is float
    assert slr_sql.ManualClock(Fraction(3, 4)).now() == 0.75
    with kb.subscribe("p(X)^T") as sub:
        kb.add("p(1)^1")
        assert sub.get(timeout=np.int64(5))["X"] == 1
        with pytest.raises(slr_sql.SLRTimeout):
            sub.get(timeout=np.float32(0))
    with pytest.raises(SLRError, match="ManualClock.set: t must be a number of seconds"):
        slr_sql.ManualClock(0).set(np.bool_(True))


def test_a_subscription_wait_refuses_a_timeout_that_is_no_seconds(kb):
    """wait(timeout="x") was a TypeError (adding it to the monotonic clock)."""
    with kb.subscribe("p(X)^T", callback=lambda answer: None) as sub:
        for timeout, words in (("x", "not 'x'"), (float("nan"), ">= 0, not nan"),
                               (-1, ">= 0, not -1")):
            with pytest.raises(SLRError, match="wait: timeout must be a number of seconds"):
                sub.wait(timeout=timeout)
            with pytest.raises(SLRError, match=words):
                sub.wait(timeout=timeout)
        assert sub.wait(timeout=0) is False


@pytest.mark.parametrize("forever", [None, float("inf"), 1e300])
def test_a_wait_of_inf_or_beyond_a_thread_s_limit_waits_for_the_answer(kb, forever):
    """result(timeout=inf) was an OverflowError ("timestamp out of range for platform
    time_t"), as was any timeout beyond threading.TIMEOUT_MAX: they wait for ever, as None
    does."""
    import threading

    pending = kb.submit("findall(X, p(X)^_, L)", at=5)
    with kb.subscribe("p(X)^T", since=0) as sub:
        threading.Timer(0.05, lambda: (kb.add("p(1)^1"), kb.mark_complete("p/1", 5))).start()
        assert pending.result(timeout=forever) == [{"L": [1]}]
        assert pending.exception(timeout=forever) is None
        assert sub.get(timeout=forever) == {"X": 1, "T": 1.0}


@pytest.mark.parametrize("options, words", [
    ({"path": 5}, "open: path must be a file's path (a str or a pathlib.Path), a PostgreSQL "
                  "URL or None, not 5"),
    ({"clock": 5}, "open: clock must be a clock"),
    ({"adopt": "yes"}, "open: adopt must be True or False, not 'yes'"),
    ({"synchronous": 5}, "synchronous must be OFF, NORMAL, FULL or EXTRA, not 5"),
    ({"checkpoint": 5}, "checkpoint must be 'auto' or 'background', not 5"),
    ({"cache_mib": "x"}, "cache_mib must be a number of MiB from 0.0625 to 1048576, not 'x'"),
    ({"cache_mib": float("nan")}, "cache_mib must be a number of MiB"),
], ids=["path 5", "clock 5", "adopt text", "synchronous 5", "checkpoint 5", "cache_mib text",
        "cache_mib nan"])
def test_open_refuses_options_of_the_wrong_kind_in_words_and_creates_nothing(tmp_path, options,
                                                                             words):
    """path=5 and synchronous=5 were "open: TypeError: ..." and "open: AttributeError: ...",
    cache_mib and checkpoint "open: ValueError: ..." (the boundary's words for a Python
    error); clock=5 and adopt="yes" were taken (clock=5 failed at the first call that asked
    the time)."""
    with pytest.raises(SLRError) as refused:
        slr_sql.open(**({"path": tmp_path / "robot.db"} | options))
    said = str(refused.value)
    assert words in said and "Error:" not in said, said
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("options, words", [
    ({"synchronous": "FAST"}, "synchronous must be OFF, NORMAL, FULL or EXTRA, not 'FAST'"),
    ({"checkpoint": "sometimes"}, "checkpoint must be 'auto' or 'background', not 'sometimes'"),
    ({"cache_mib": 0}, "cache_mib must be a number of MiB from 0.0625 to 1048576, not 0"),
    ({"cache_mib": float("nan")}, "cache_mib must be a number of MiB"),
], ids=["synchronous FAST", "checkpoint sometimes", "cache_mib 0", "cache_mib nan"])
def test_the_sqlite_tuning_options_are_checked_alike_on_both_backends(backend, options, words):
    """synchronous, checkpoint and cache_mib tune an SQLite file; a PostgreSQL store took any
    value unchecked (the same open refused on one engine, taken on the other). Checked alike
    now, before anything is made; a good value opens on both (then unused on PostgreSQL,
    docs/postgres.md)."""
    with pytest.raises(SLRError) as refused:
        slr_sql.open(backend, **options)
    assert words in str(refused.value), refused.value
    with slr_sql.open(backend, slr_sql.ManualClock(10.0), synchronous="normal",
                      checkpoint="background", cache_mib=16) as kb:
        kb.add("p(1)^1")
        assert kb.query("p(X)^T") == [{"X": 1, "T": 1.0}]


def test_connect_refuses_a_token_that_is_no_text_without_showing_it():
    """connect(url, token=5) was a raw TypeError ('int' object is not iterable)."""
    with pytest.raises(SLRError) as refused:
        slr_sql.connect("http://127.0.0.1:9", token=12345)
    assert str(refused.value) == "connect: token must be text (a str), not of type int"
