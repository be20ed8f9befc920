"""Time traps a newcomer falls into, made visible where they happen: events stamped at small
times (2.0, 5.0) on a store whose clock is the wall clock arrive ~1.8e9 s "late". The delay a
type may learn is capped (max_learned_delay, default 3600 s), a LearnedDelayWarning says what
happened and the fix, and synchronized queries do not wait for decades."""
from __future__ import annotations

import warnings

import pytest

import slr_sql
from slr_sql.sync import DEFAULT_MAX_LEARNED_DELAY, LearnedDelayWarning


def _add_recorded(kb) -> list[warnings.WarningMessage]:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        kb.add("seen(a)^2.0")
        kb.add("seen(b)^5.0")
        kb.add_many(["seen(c)^6.0", "pos(r1, 1)^7.0"])
    return [w for w in caught if issubclass(w.category, LearnedDelayWarning)]


def test_small_times_on_a_wall_clock_warn_once_per_type_and_the_delay_is_capped(tmp_path):
    with slr_sql.open(tmp_path / "robot.db") as kb:
        caught = _add_recorded(kb)
        assert [str(w.message).split(":")[0] for w in caught] == ["seen/1", "pos/2"]
        text = str(caught[0].message)
        for words in ("WallClock", "ManualClock", "StreamClock", "max_delay(seen/1, D)",
                      "max_learned_delay", "capped at 3600 s", 'subscribe(since="now")'):
            assert words in text, text
        assert float(text.split(" arrived ")[1].split(" s ")[0]) > 1e9   # the delay, said
        assert DEFAULT_MAX_LEARNED_DELAY == 3600.0
        # complete up to now - 3600 s: a synchronized query on these times answers at once
        assert kb.complete_until("seen/1") > 1e9
        pending = kb.submit("findall(W, seen(W)^_, L)", at=5.0)
        assert pending.result(timeout=10) == [{"L": ["a", "b"]}]
    with slr_sql.open(tmp_path / "robot.db") as kb:   # the stored delay is the capped one
        assert 1e9 < kb.complete_until("seen/1")


@pytest.mark.parametrize("cap, horizon_after", [(10.0, 1e9), (None, None)])
def test_the_cap_is_configurable(cap, horizon_after):
    with slr_sql.open(max_learned_delay=cap) as kb:
        caught = _add_recorded(kb)
        if cap is None:     # no cap: the delay learned is the whole gap, and nothing is said
            assert caught == []
            assert kb.complete_until("seen/1") < 10
        else:
            assert "capped at 10 s" in str(caught[0].message)
            assert kb.complete_until("seen/1") > horizon_after


@pytest.mark.parametrize("bad", [-1, "1h", float("nan"), True])
def test_a_bad_cap_is_refused_in_words(bad):
    with pytest.raises(slr_sql.SLRError, match="max_learned_delay"):
        slr_sql.open(max_learned_delay=bad)


def test_a_clock_that_matches_the_events_says_nothing():
    clock = slr_sql.ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        clock.set(10.0)
        assert _add_recorded(kb) == []
    with slr_sql.open(clock=slr_sql.StreamClock()) as kb:
        assert _add_recorded(kb) == []


def test_a_declared_delay_is_not_capped_and_not_warned_about():
    with slr_sql.open() as kb:
        kb.load(":- max_delay(seen/1, 5e9).")
        caught = _add_recorded(kb)
        assert [str(w.message).split(":")[0] for w in caught] == ["pos/2"]
        assert kb.complete_until("seen/1") < 0


def test_a_complex_event_type_is_not_warned_about_only_the_types_its_rules_read():
    """A rule's complex events are as late as the events that complete them, which are
    warned of; the warning for the complex type advised a delay it has no use for (its
    completeness follows from its rule's types)."""
    with slr_sql.open() as kb:
        kb.load("seen_twice(X) <- seen(X) seq seen(X).")
        caught = _add_recorded(kb)
        with warnings.catch_warnings(record=True) as later:
            warnings.simplefilter("always")
            kb.add("seen(a)^8.0")                # its first complex event
        assert kb.query("seen_twice(a)^[S, E]") == [{"S": 2.0, "E": 8.0}]
        assert [str(w.message).split(":")[0] for w in caught] == ["seen/1", "pos/2"]
        assert [w for w in later if issubclass(w.category, LearnedDelayWarning)] == []


def test_a_wait_for_a_synchronized_answer_that_runs_out_says_what_it_waits_for():
    clock = slr_sql.ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.add("seen(a)^0")
        pending = kb.submit("findall(W, seen(W)^_, L)", at=50.0, id="q7")
        with pytest.raises(slr_sql.SLRTimeout) as info:
            pending.result(timeout=0.05)
        assert isinstance(info.value, TimeoutError)        # what a Future's wait raises
        message = str(info.value)
        assert "q7" in message and "seen/1" in message and "still waiting" in message
        assert [(w.type, w.time) for w in pending.waiting_for] == [("seen/1", 50.0)]
        kb.mark_complete("seen/1", 50.0)
        assert pending.result(timeout=10) == [{"L": ["a"]}]


def test_subscribe_since_now_on_a_type_stamped_long_before_now_warns():
    with slr_sql.open() as kb:
        _add_recorded(kb)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            kb.subscribe("seen(W)^T").close()                 # since="now": would miss them
            kb.subscribe("seen(W)^T", since=0).close()        # history first: fine
            kb.subscribe("never(W)^T").close()                # nothing stored: nothing said
        said = [str(w.message) for w in caught if issubclass(w.category, LearnedDelayWarning)]
        assert len(said) == 1 and said[0].startswith('subscribe(since="now") on seen/1'), said
        assert "since=0" in said[0] and "StreamClock" in said[0]
    clock = slr_sql.ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:                    # times in the clock's base
        clock.set(10.0)
        _add_recorded(kb)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            kb.subscribe("seen(W)^T").close()
        assert not [w for w in caught if issubclass(w.category, LearnedDelayWarning)]
