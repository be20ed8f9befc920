"""A where goal that cannot be asked at the moment (a defined predicate's service is down, the
store is busy or full: SLRUnavailable) does not reject its candidate: rejecting it would
derive the next candidate in its place, a decision the moment's trouble made. The round fails
instead, and the decision is made again: an add that decides is refused as a whole (retryable,
nothing stored) and derives the right event when retried; a clock move raises the error and
leaves the decision pending for the next move. An error that is the goal's own answer (a type
error) still rejects the candidate, as before (docs/events.md, "where")."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRError, SLRUnavailable

PROGRAM = (":- consumption(recent).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n"
           "c(X) <- a(X) seq b(Y) where ok(X).\n")


class MapService:
    """A defined predicate ``ok/1`` asking a service that is down for key 2 until it is up."""

    def __init__(self) -> None:
        self.up = False
        self.asked: list = []

    def ok(self, x: object) -> bool:
        self.asked.append(x)
        if not self.up and x == 2:
            raise SLRUnavailable("the map service is down")
        return True


def _open(backend: str, now: float, service: MapService):
    kb = slr_sql.open(backend, clock=ManualClock(now))
    kb.define("ok", 1, service.ok)
    kb.load(PROGRAM)
    return kb


def _c(kb) -> list:
    return [(a["X"], a["S"], a["E"]) for a in kb.query("c(X)^[S, E]")]


def test_an_add_that_decides_is_refused_and_retried_it_derives_the_best_candidate(backend):
    service = MapService()
    with _open(backend, 10.0, service) as kb:   # the clock is past: decided at the add
        kb.add_many(["a(1)^1", "a(2)^2"])
        with pytest.raises(SLRUnavailable, match="map service is down"):
            kb.add("b(9)^3")
        assert kb.query("b(X)^T") == [] and _c(kb) == []   # nothing of the add is stored
        assert kb.event_rules()[0]["errors"] == 0
        service.up = True
        kb.add("b(9)^3")
        # a(2) is the most recent a before b: c(1) would be the moment's trouble's answer
        assert _c(kb) == [(2, 2.0, 3.0)]


def test_a_clock_move_raises_and_the_next_one_decides(backend):
    service = MapService()
    with _open(backend, 0.0, service) as kb:
        kb.add_many(["a(1)^1", "a(2)^2", "b(9)^3"])   # b waits for a/1 complete up to 3
        with pytest.raises(SLRUnavailable, match="map service is down"):
            kb.clock.set(5.0)
        assert _c(kb) == [] and kb.event_rules()[0]["pending"] == 1
        service.up = True
        kb.clock.set(6.0)
        assert _c(kb) == [(2, 2.0, 3.0)] and kb.event_rules()[0]["pending"] == 0


def test_an_error_that_is_the_goals_answer_still_rejects_the_candidate(tmp_path):
    def ok(x: object) -> bool:
        if x == 2:
            raise SLRError("type_error(integer, two)")
        return True

    with slr_sql.open(str(tmp_path / "r.db"), clock=ManualClock(10.0)) as kb:
        kb.define("ok", 1, ok)
        kb.load(PROGRAM)
        kb.add_many(["a(1)^1", "a(2)^2", "b(9)^3"])
        assert _c(kb) == [(1, 1.0, 3.0)]
        rule = kb.event_rules()[0]
        assert rule["errors"] == 1 and "type_error" in rule["last_error"]
