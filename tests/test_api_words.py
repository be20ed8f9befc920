"""Bad arguments to the public API are refused in the caller's terms: an SLRError naming the
argument and what is wrong with it, never the boundary's last resort "method: ValueError:
..." that wraps an internal error (the cases of the finding, and their neighbours)."""
from __future__ import annotations

import re
from fractions import Fraction

import numpy as np
import pytest

import slr_sql
from slr_sql import EventRejected, SLRError

HUGE = 10 ** 5000
WRAPPED = re.compile(r"^\w+: [A-Z]\w*(?:Error|Exception): ")


@pytest.fixture
def kb():
    kb = slr_sql.open(clock=slr_sql.ManualClock(10.0))
    kb.add("p(a)^1")
    yield kb
    kb.close()


CASES = [
    (lambda kb: kb.load("q(1).", name="\ud800"),
     "the program name '\\ud800' cannot be stored: text with a lone surrogate"),
    (lambda kb: kb.load("q(1).", name=""), "a program name is a non-empty string"),
    (lambda kb: kb.load("q(1).", filename=HUGE), "load: filename is the text shown in messages"),
    (lambda kb: kb.load("q(1).", filename="\udc80"), "load: filename is the text shown"),
    (lambda kb: kb.load(b"q(1)."), "load takes program text (a str), not a bytes"),
    (lambda kb: kb.subscribe("p(X)^T", since=10 ** 400),
     "subscribe: since is out of range (an integer of 1329 bits)"),
    (lambda kb: kb.subscribe("p(X)^T", until=-10 ** 400), "subscribe: until is out of range"),
    # any numbers.Real is a number of seconds (a Fraction beyond a float is out of range,
    # not "an AttributeError"); numpy's bool is no number, as Python's is not
    (lambda kb: kb.query("p(X)^T", at=Fraction(10 ** 400, 7)), "at is out of range (an "
                                                               "integer of 1326 bits)"),
    (lambda kb: kb.query("p(X)^T", timeout=np.True_), "timeout must be a number of seconds, "
                                                      "not np.True_"),
    (lambda kb: kb.subscribe("p(X)^T", since={"a": HUGE}),
     "subscribe: since must be a number of seconds, not a dict holding an integer too long"),
    (lambda kb: kb.subscribe("p(X)^T", where=HUGE),
     "subscribe: where must be a goal as text, not an integer of about 5001 digits"),
    # (flags were taken by their truth: forget="no" forgot)
    (lambda kb: kb.subscribe("p(X)^T", id="kept").close(forget="no"),
     "close: forget must be True or False, not 'no'"),
    (lambda kb: kb.subscribe("p(X)^T").close(join=1), "close: join must be True or False, "
                                                      "not 1"),
    (lambda kb: kb.subscribe("p(X)^T").close(ack=None), "close: ack must be True or False, "
                                                        "not None"),
    (lambda kb: kb.mark_complete("p/1", "x"), "mark_complete: t must be a number of seconds, "
                                              "not 'x'"),
    (lambda kb: kb.mark_complete("p/1", 10 ** 400), "mark_complete: t is out of range"),
    (lambda kb: kb.mark_complete("p/1", True), "mark_complete: t must be a number of seconds"),
    (lambda kb: kb.mark_complete(5, 1.0), "mark_complete: the event type is text such as"),
    (lambda kb: kb.mark_complete("p\ud800", 1.0), "mark_complete: the event type 'p\\ud800' "
                                                  "cannot be stored"),
    (lambda kb: kb.complete_until("p/" + "9" * 5000), "complete_until: the arity of"),
    (lambda kb: kb.complete_until((None, "\ud800")), "complete_until: the event type is text"),
    (lambda kb: kb.query("p(X)^T", args={"X": {"a": 1}}),
     "args['X'] = {'a': 1} is not a term: cannot convert {'a': 1} (dict) to an SLR term"),
    (lambda kb: kb.query("p(X)^T", args={"X": [1, {2}]}), "args['X'] = [1, {2}] is not a term"),
    (lambda kb: kb.query("p(X)^T", args={HUGE: 1}), "args names an integer of about 5001 digits"),
    (lambda kb: kb.query("p(X)^T", limit=-HUGE), "limit must be a count (an integer >= 0), not "
                                                "an integer of about 5001 digits"),
    (lambda kb: kb.query("p(X)^T", at={"t": HUGE}), "at must be a number of seconds"),
    (lambda kb: kb.query(HUGE), "a goal is SLR text (a str), not int an integer of about"),
    (lambda kb: kb.sql("SELECT '\ud800'"), "sql: the statement or a parameter is not valid "
                                            "Unicode (a lone surrogate"),
    (lambda kb: kb.sql("SELECT ?", ["\ud800"]), "not valid Unicode"),
    (lambda kb: kb.sql("SELECT ?", [2 ** 64]), "sql: a parameter cannot be bound"),
    (lambda kb: kb.sql("SELECT ?", [[1]]), "sql: Error binding parameter 1: type 'list' is not "
                                           "supported"),
    (lambda kb: kb.sql(b"SELECT 1"), "sql: the statement is text (a str), not a bytes"),
    (lambda kb: kb.remove_buffer(-HUGE), "no active buffer #an integer of about 5001 digits"),
    (lambda kb: kb.remove_buffer("1"), "remove_buffer: a buffer id is an integer"),
    (lambda kb: kb.add_buffer("p(" + "9" * 5000 + ")", keep_last=1),
     "buffer pattern constant cannot be stored: integer too large"),
    (lambda kb: kb.add_event([], [], []), "add_event: event name must be an atom (a str)"),
    (lambda kb: kb.add_many([("p", [{"a": -HUGE}], 0, 0)], atomic=True),
     "dict value (holding an integer too long to print) is not a term"),
]


@pytest.mark.parametrize("call, words", CASES, ids=[str(i) for i in range(len(CASES))])
def test_bad_arguments_are_refused_in_the_callers_terms(kb, call, words):
    with pytest.raises(SLRError) as caught:
        call(kb)
    message = str(caught.value)
    assert words in message, message
    assert not WRAPPED.match(message), message
    assert "set_int_max_str_digits" not in message
    kb.add("p(b)^2")  # and nothing broke
    assert [a["X"] for a in kb.query("p(X)^T")] == ["a", "b"]


def test_explain_prints_a_5000_digit_parameter_in_full(kb):
    digits = "9" * 5000
    text = kb.explain(f"p(X)^T, X > {digits}")
    assert f":c0 = {digits}" in text


@pytest.mark.parametrize("goal", ["9" * 5000, f"X = {'9' * 5000}", f"X is {'9' * 5000} + 1"])
def test_explain_of_goals_with_5000_digit_numbers_answers(kb, goal):
    assert kb.explain(goal).startswith("goal: ")


def test_an_add_many_rejection_is_still_an_event_rejected(kb):
    (error,) = kb.add_many([("p", [{"a": 1}], 3, 3), "p(c)^4"])
    assert isinstance(error, EventRejected) and error.index == 0
    assert "dict value {'a': 1} is not a term" in str(error)


def test_a_refused_close_flag_closes_nothing(kb):
    sub = kb.subscribe("p(X)^T", since=0, id="kept")
    with pytest.raises(SLRError, match="close: forget must be True or False"):
        sub.close(forget="yes")
    assert not sub.closed and sub.get(timeout=5) == {"X": slr_sql.Atom("a"), "T": 1.0}
    sub.close()
    assert kb.subscribe("p(X)^T", id="kept").position() == sub.position()  # remembered


def test_an_unknown_option_of_open_or_connect_is_refused_in_words():
    """open(bogus=1) was "open: TypeError: KnowledgeBase.__init__() got an unexpected
    keyword argument 'bogus'" (the boundary's last resort), connect(url, bogus=1) a raw
    TypeError."""
    with pytest.raises(SLRError) as refused:
        slr_sql.open(bogus=1)
    assert str(refused.value) == (
        "open has no option 'bogus' (its options: synchronous, busy_timeout, adopt, "
        "checkpoint, cache_mib, robot, max_learned_delay)")
    with pytest.raises(SLRError) as refused:
        slr_sql.connect("http://127.0.0.1:9", bogus=1)   # (refused before connecting)
    assert str(refused.value) == "connect has no option 'bogus' (its options: timeout)"
    slr_sql.open(robot="r1", cache_mib=8).close()       # (the options it has are taken)
