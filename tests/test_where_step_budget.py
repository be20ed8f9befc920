"""A where goal's limit is a budget of work, never of time (docs/events.md, "Limits of a
where goal"): the interpreter runs it under a budget of inference steps, a compiled SQL
statement under a budget of SQLite instructions, and a statement that runs out of its limit
leaves the decision to the interpreter's budget. So the same events and program derive the
same complex events on an idle machine and on one a thousand times slower, on SQLite and on
PostgreSQL.

The machine's speed is played by the interpreter's clock (:class:`MachineSpeed`, the
interpreter's ManualClock): each look at it finds a fixed time passed. Budgets are made small
here (the module's constants, read at each evaluation) so that the goals stay cheap.
"""
from __future__ import annotations

import time

import pytest

import slr_sql
from slr_sql import ManualClock, engine
from slr_sql.cep import where
from slr_sql.errors import SLRTimeout
from slr_sql.store import EventStore
from slr_sql.store.connection import INSTRUCTIONS_PER_CHECK

PROGRAM = (":- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n:- max_delay(c/1, 0).\n"
           "spin(0) :- !.\nspin(N) :- N1 is N - 1, spin(N1).\n")
# a goal that compiles to SQL on both backends; counting 3000 events takes the interpreter
# more than 2048 steps
COUNT = "q(X, N) <- a(X) seq b(_) where aggregate_all(count, (c(Y)^[_, _], Y >= 0), N).\n"
C_EVENTS = 3000


class MachineSpeed:
    """The interpreter's wall clock (``time.monotonic``) on a machine where every look at it
    finds ``seconds_per_look`` passed (the interpreter looks once per 2048 steps, ~1-5 ms of
    work here: 2 s a look is a machine a thousand times slower). It starts a day ahead of
    the real clock, so the real time the test takes never reaches a deadline it set."""

    def __init__(self, seconds_per_look: float):
        self.now = time.monotonic() + 86400.0
        self.seconds_per_look = seconds_per_look

    def monotonic(self) -> float:
        self.now += self.seconds_per_look
        return self.now


def _rule(kb) -> dict:
    (rule,) = kb.event_rules()
    return rule


@pytest.mark.parametrize("seconds_per_look, backstop", [
    (0.0, None), (2.0, None), (100.0, 1e9)], ids=["idle", "1000x-slower", "no-backstop"])
def test_a_goal_over_the_step_budget_is_rejected_whatever_the_machine_speed(
        backend, monkeypatch, seconds_per_look, backstop):
    monkeypatch.setattr(where, "WHERE_MAX_STEPS", 40_960)
    if backstop is not None:
        monkeypatch.setattr(where, "WHERE_BACKSTOP", backstop)
    monkeypatch.setattr(engine, "time", MachineSpeed(seconds_per_look))
    with slr_sql.open(backend, clock=ManualClock(100.0)) as kb:
        kb.load(":- consumption(recent).\n" + PROGRAM
                + "r(X) <- a(X) seq b(_) where spin(X).\n")
        # the most recent a spins past the budget: rejected, the next one is derived in
        # its place -- on the slow machine as on the idle one (its 40 s of looks stay
        # inside the wall-clock backstop; a 5-second limit would reject both)
        kb.add_many(["a(3000)^1", "a(50000)^2", "b(0)^3"])
        assert [(a["X"], a["S"], a["E"]) for a in kb.query("r(X)^[S, E]")] == [(3000, 1.0, 3.0)]
        rule = _rule(kb)
        assert rule["errors"] == 1
        assert rule["last_error"] == "step limit of 40960 inference steps exceeded"


def test_the_wall_clock_backstop_rejects_like_the_budget_and_never_fails_the_add(tmp_path,
                                                                            monkeypatch):
    # a machine so slow (100 s a look) that the 60 s backstop comes before the budget: the
    # one machine-dependent limit rejects its candidates, as the budget does; it does not
    # refuse the add as a condition that may pass would (that would hold every later
    # decision back behind a goal that may never end)
    monkeypatch.setattr(engine, "time", MachineSpeed(100.0))
    with slr_sql.open(str(tmp_path / "r.db"), clock=ManualClock(100.0)) as kb:
        kb.load(PROGRAM + "r(X) <- a(X) seq b(_) where spin(X).\n")
        kb.add_many(["a(3000)^1", "a(5)^2", "b(0)^3"])
        assert [a["X"] for a in kb.query("r(X)^[_, _]")] == [5]   # under 2048 steps: no look
        rule = _rule(kb)
        assert rule["errors"] == 1 and rule["last_error"].startswith("query timed out after 60.0 s")
        assert len(kb.query("b(X)^_")) == 1


def test_a_builtin_looping_inside_one_step_meets_the_backstop_when_called_directly(
        tmp_path, monkeypatch):
    # numlist/3 builds its list inside one step, so no step budget sees it; a where goal
    # of deterministic builtins is called directly, without the interpreter, and still has
    # the backstop (here already past, as a long enough loop finds it on any machine)
    monkeypatch.setattr(where, "WHERE_BACKSTOP", -1.0)
    with slr_sql.open(str(tmp_path / "r.db"), clock=ManualClock(100.0)) as kb:
        kb.load("c(X) <- a(X) where numlist(1, X, _).\n")
        kb.add_many(["a(5)^1", "a(100000)^2"])
        assert [a["X"] for a in kb.query("c(X)^_")] == [5]   # too short a loop to look
        rule = _rule(kb)
        assert rule["errors"] == 1 and "timed out" in rule["last_error"]


def test_a_goal_just_under_the_step_budget_derives_and_one_step_over_is_rejected(tmp_path,
                                                                            monkeypatch):
    budget = 10_240
    monkeypatch.setattr(where, "WHERE_MAX_STEPS", budget)
    with slr_sql.open(str(tmp_path / "r.db"), clock=ManualClock(100.0)) as kb:
        kb.load(PROGRAM + "r(X) <- a(X) seq b(_) where spin(X).\n")

        def within(n: int) -> bool:
            try:
                kb.query(f"spin({n})", max_steps=budget)
            except SLRTimeout:
                return False
            return True

        lo, hi = 0, budget   # spin(0) fits; spin(budget) takes more than budget steps
        while hi - lo > 1:
            mid = (lo + hi) // 2
            lo, hi = (mid, hi) if within(mid) else (lo, mid)
        # the largest spin the budget allows, as kb.query(max_steps=) counts them
        kb.add_many([f"a({lo})^1", f"a({lo + 1})^2", "b(0)^3"])
        assert [a["X"] for a in kb.query("r(X)^[_, _]")] == [lo]
        assert _rule(kb)["errors"] == 1


@pytest.mark.parametrize("instructions, max_steps, derived", [
    (None, 2048, True),        # SQL answers within its instructions: the step budget is moot
    (1000, 2048, False),       # out of them: the interpreter decides, and its budget is spent
    (1000, None, True),        # out of them: the interpreter decides within its budget
], ids=["sql-answers", "interpreter-out-of-steps", "interpreter-answers"])
def test_a_statement_out_of_its_sqlite_instructions_leaves_the_decision_to_the_step_budget(
        tmp_path, monkeypatch, instructions, max_steps, derived):
    if instructions is not None:
        monkeypatch.setattr(where, "WHERE_SQL_INSTRUCTIONS", instructions)
    if max_steps is not None:
        monkeypatch.setattr(where, "WHERE_MAX_STEPS", max_steps)
    monkeypatch.setattr(where, "WHERE_BACKSTOP", 1e9)   # no wall clock decides anything
    with slr_sql.open(str(tmp_path / "r.db"), clock=ManualClock(100.0)) as kb:
        kb.load(PROGRAM + COUNT)
        kb.add_many([f"c({i})^{i / 1000}" for i in range(C_EVENTS)])
        kb.add_many(["a(1)^10", "b(0)^12"])
        got = [(a["X"], a["N"]) for a in kb.query("q(X, N)^[_, _]")]
        rule = _rule(kb)
        if derived:
            assert got == [(1, C_EVENTS)] and rule["errors"] == 0
        else:
            assert got == [] and rule["errors"] == 1
            assert rule["last_error"] == "step limit of 2048 inference steps exceeded"


@pytest.mark.parametrize("max_steps, derived", [(None, True), (2048, False)],
                         ids=["within-steps", "out-of-steps"])
def test_a_statement_out_of_its_time_leaves_the_decision_to_the_step_budget(
        backend, monkeypatch, max_steps, derived):
    # the backstop at 0 s: every statement of the where goal is out of its time at once
    # (PostgreSQL's statement_timeout, SQLite's progress handler); the interpreter's own
    # clock stands still, so only its step budget can stop it
    monkeypatch.setattr(where, "WHERE_BACKSTOP", 0.0)
    monkeypatch.setattr(engine, "time", MachineSpeed(0.0))
    if max_steps is not None:
        monkeypatch.setattr(where, "WHERE_MAX_STEPS", max_steps)
    with slr_sql.open(backend, clock=ManualClock(100.0)) as kb:
        kb.load(PROGRAM + COUNT)
        kb.add_many([f"c({i})^{i / 1000}" for i in range(C_EVENTS)])
        kb.add_many(["a(1)^10", "b(0)^12"])
        got = [(a["X"], a["N"]) for a in kb.query("q(X, N)^[_, _]")]
        rule = _rule(kb)
        if derived:   # what SQL answers given the time: a timeout there decides nothing
            assert got == [(1, C_EVENTS)] and rule["errors"] == 0
        else:
            assert got == [] and rule["errors"] == 1
            assert rule["last_error"] == "step limit of 2048 inference steps exceeded"


COUNT_TO = ("WITH RECURSIVE r(n) AS (SELECT 1 UNION ALL SELECT n + 1 FROM r WHERE n < :k) "
            "SELECT count(*) FROM r")


def test_a_statements_instruction_budget_is_a_count_of_work_not_a_time(tmp_path):
    with EventStore(str(tmp_path / "s.db")) as store:

        def fits(k: int) -> bool:
            try:
                assert store.run_compiled(COUNT_TO, {"k": k}, instructions=100_000) == [(k,)]
            except SLRTimeout as exc:
                assert "budget of 100000 SQLite instructions" in str(exc)
                return False
            return True

        def largest_fitting() -> int:
            lo, hi = 1, 1_000_000
            while hi - lo > 1:
                mid = (lo + hi) // 2
                lo, hi = (mid, hi) if fits(mid) else (lo, mid)
            return lo

        edge = largest_fitting()
        assert 1000 < edge < 100_000   # each row takes a few instructions
        # the same statement stops at the same place, to within the handler's interval
        # (SQLite counts a statement's intervals on from where its last run left off)
        per_row = 100_000 / edge
        assert abs(largest_fitting() - edge) * per_row <= INSTRUCTIONS_PER_CHECK
        # no deadline was given: the budget alone stopped it, and it is gone with its
        # statement (one without a budget runs to its end)
        assert store.run_compiled(COUNT_TO, {"k": 10 * edge}) == [(10 * edge,)]
