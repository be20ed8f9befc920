"""One item of an ``add_many`` too large for Python to convert or print (an integer of 5,000
digits as a name, a time, an argument, the arguments themselves, inside a malformed item)
is that item's EventRejected, in words; the good events of the batch are stored."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import EventRejected, SLRError

HUGE = 10 ** 5000
DIGITS = "9" * 5000


@pytest.fixture
def kb():
    # a ManualClock: events stamped 2.0 on a wall clock would be "decades late" (a
    # LearnedDelayWarning); nothing here waits on the store's time
    kb = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    yield kb
    kb.close()


@pytest.mark.parametrize("item, words", [
    (("k", [HUGE], 2.0, 2.0), "integer too large to be stored"),
    (("k", [[1, HUGE]], 2.0, 2.0), "integer too large to be stored"),
    ((HUGE, [1], 2.0, 2.0), "event name must be an atom, not an integer of about 5001 digits"),
    (("k", [1], HUGE, HUGE), "event times must be finite"),
    (("k", [1], 1.0, HUGE), "event times must be finite"),
    (("k", [1], -HUGE, 1.0), "event times must be finite"),
    (("k", HUGE, 2.0, 2.0), "event arguments must be a list or tuple, not an integer of about "
                            "5001 digits"),
    ((HUGE, [1]), "is neither SLR text nor a (name, args, start, end) tuple: a tuple holding "
                  "an integer too long to print"),
    ([HUGE, HUGE, HUGE, HUGE, HUGE], "neither SLR text nor"),
    ((HUGE, HUGE, HUGE, HUGE), "event arguments must be a list or tuple"),
    (f"k({DIGITS})^2", "an integer too long (5000 digits): at most 4300 digits are read"),
    (f"k(a)^{DIGITS}", "event times must be finite"),
    (f"k(f({DIGITS}, x))^2", "an integer too long"),
])
@pytest.mark.parametrize("tuples_only", [False, True])
def test_an_oversized_item_is_rejected_and_the_good_events_are_stored(kb, item, words,
                                                                      tuples_only):
    good = [("k", ["a"], 1.0, 1.0), ("k", ["b"], 3.0, 3.0)] if tuples_only else \
        ["k(a)^1", ("k", ["b"], 3.0, 3.0)]
    rejected = kb.add_many([good[0], item, good[1]])
    assert len(rejected) == 1, rejected
    (error,) = rejected
    assert isinstance(error, EventRejected)
    assert words in str(error), str(error)
    assert "sys.set_int_max_str_digits" not in str(error)
    assert len(str(error)) < 600, str(error)   # (the event's text was repeated whole: 5 KB)
    assert error.index == 1 and error.event is item
    assert [a["X"] for a in kb.query("k(X)^T")] == ["a", "b"]


@pytest.mark.parametrize("item", [("k", [HUGE], 2.0, 2.0), (HUGE, [1], 2.0, 2.0),
                                  ("k", HUGE, 2.0, 2.0), (HUGE, [1])])
def test_atomic_add_many_raises_the_rejection_in_words_and_stores_nothing(kb, item):
    with pytest.raises(EventRejected) as caught:
        kb.add_many([("k", ["a"], 1.0, 1.0), item], atomic=True)
    assert "Error:" not in str(caught.value)
    assert kb.query("k(X)^T") == []


@pytest.mark.parametrize("call, words", [
    (lambda kb: kb.add_event(HUGE, [1], 1.0), "event name must be an atom"),
    (lambda kb: kb.add_event("k", [HUGE], 1.0), "integer too large to be stored"),
    (lambda kb: kb.add_event("k", HUGE, 1.0), "event arguments must be a list or tuple"),
    (lambda kb: kb.add_event("k", [1], HUGE), "event times must be finite"),
    (lambda kb: kb.add(("k", [1], 1.0, 1.0)), "add takes one event written in SLR syntax"),
    (lambda kb: kb.add(HUGE), "add takes one event written in SLR syntax (a str), not a int"),
    (lambda kb: kb.add(f"k({DIGITS})^1"), "5000 digits"),
])
def test_single_adds_of_oversized_values_say_what_is_wrong(kb, call, words):
    with pytest.raises(SLRError) as caught:
        call(kb)
    assert words in str(caught.value), str(caught.value)
    assert "ValueError" not in str(caught.value) and "TypeError" not in str(caught.value)
    kb.add("k(ok)^1")
    assert [a["X"] for a in kb.query("k(X)^T")] == ["ok"]


@pytest.mark.parametrize("name", [{"a": 1}, ["x"], {1, 2}])
def test_an_unhashable_name_next_to_event_rules_is_that_items_rejection(kb, name):
    """(Found by tests/test_api_fuzz.py: with an event rule loaded, the batch failed whole.)"""
    kb.load("c(X) <- p(X) seq q(X, _).")
    rejected = kb.add_many([("p", ["a"], 1.0, 1.0), (name, (1,), 1.5, 1.5),
                            ("q", ["a", 1], 2.0, 2.0)])
    assert [e.index for e in rejected] == [1]
    assert "event name must be an atom" in str(rejected[0])
    assert [a["X"] for a in kb.query("c(X)^[S, E]")] == ["a"]
