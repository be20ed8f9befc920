"""The event pipeline (slr_sql/pipeline.py, docs/architecture.md): an add, a mark and a
moving clock go through fixed stages -- marks, store and rule rounds, completeness,
decisions until nothing changes, buffers, wake -- and no stage re-enters the pipeline."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

import slr_sql
from slr_sql import ManualClock, StreamClock
from slr_sql.errors import EventRejected
from slr_sql.pipeline import STAGES

RULE = ":- max_delay(c/0, 1).\nn <- (a seq b) cnot c.\n"


class Heard:
    """An add listener: each batch's event names, the stage the pipeline was in, and how
    deeply the listener was entered (a re-entered pipeline calls it inside itself)."""

    def __init__(self, kb, on_call=None):
        self.kb = kb
        self.batches: list[list[str]] = []
        self.stages: list[str | None] = []
        self.depth = 0
        self.max_depth = 0
        self.on_call = on_call

    def __call__(self, batch):
        self.depth += 1
        self.max_depth = max(self.max_depth, self.depth)
        try:
            self.batches.append([event[0] for event in batch])
            self.stages.append(self.kb._pipeline.stage())
            if self.on_call is not None:
                self.on_call(self)
        finally:
            self.depth -= 1


@pytest.fixture
def clock():
    return ManualClock(0.0)


@pytest.fixture
def kb(clock):
    with slr_sql.open(clock=clock) as k:
        yield k


def test_an_add_runs_the_stages_in_order_and_hands_on_its_batch_first(kb):
    kb.load(RULE)
    heard = Heard(kb)
    kb.add_listeners.append(heard)
    waiting = kb.submit("findall(x, n^[_, _], L)", at=5)   # a query on the complex type
    # the marks complete c/0 (and a/0, b/0 for the query) up to 10: the pending decision
    # is made in this same add
    assert kb.add_many(["a^1", "b^5", "fullyUpdated(c/0)^10", "fullyUpdated(a/0)^10",
                        "fullyUpdated(b/0)^10"]) == []
    assert heard.batches == [["a", "b"], ["n"]]     # the add's events, then the decision's
    assert heard.stages == ["wake", "wake"]
    assert heard.max_depth == 1
    assert waiting.result(timeout=10) == [{"L": ["x"]}]  # re-checked after the decisions
    assert kb._pipeline.stage() is None


def test_a_request_for_decisions_from_the_last_stage_joins_the_run(kb, clock):
    kb.load(RULE)

    def move_clock(heard):
        if len(heard.batches) == 1:
            clock.set(20.0)     # completes c/0 (max_delay 1) while stage 6 runs

    heard = Heard(kb, move_clock)
    kb.add_listeners.append(heard)
    kb.add_many(["a^1", "b^5"])
    # the decision was made before the add returned, by the same run, not by a second
    # pipeline inside the listener
    assert heard.batches == [["a", "b"], ["n"]]
    assert heard.max_depth == 1
    assert kb.query("n^[S, E]") == [{"S": 1.0, "E": 5.0}]


def test_a_listener_adding_events_runs_a_pipeline_of_its_own(kb, clock):
    kb.load(RULE)
    after: list = []

    def add_more(heard):
        if heard.batches == [["a", "b"]]:
            kb.add("z^6")                   # the outer run goes on after this add
            after.append(kb._pipeline.stage())
            clock.set(20.0)                 # ... and still takes requests for decisions

    heard = Heard(kb, add_more)
    kb.add_listeners.append(heard)
    kb.add_many(["a^1", "b^5"])
    assert heard.batches == [["a", "b"], ["z"], ["n"]]
    assert after == ["wake"]
    assert kb._pipeline.stage() is None


def test_a_stream_clock_moved_by_the_add_decides_in_the_same_add():
    with slr_sql.open(clock=StreamClock()) as kb:
        kb.load(RULE + ":- in_order(z/0).\n")
        heard = Heard(kb)
        kb.add_listeners.append(heard)
        kb.add_many(["a^1", "b^5"])
        assert kb.query("n^[S, E]") == []           # c/0 complete only up to 4
        kb.add("z^100")      # the clock moves to 100 while the completeness stage runs
        assert kb.query("n^[S, E]") == [{"S": 1.0, "E": 5.0}]
        assert heard.batches == [["a", "b"], ["z"], ["n"]]
        assert heard.max_depth == 1


def test_mark_complete_runs_the_stages_after_completeness(kb):
    kb.load(RULE)
    kb.add_many(["a^1", "b^5"])
    heard = Heard(kb)
    kb.add_listeners.append(heard)
    kb.mark_complete("c/0", 10)
    assert heard.batches == [["n"]]
    assert heard.stages == ["wake"]


def test_a_rejected_atomic_add_stops_before_completeness(kb):
    kb.load(RULE)
    heard = Heard(kb)
    kb.add_listeners.append(heard)
    with pytest.raises(EventRejected):
        kb.add_many(["a^1", "b^[5, 4]", "fullyUpdated(c/0)^10"], atomic=True)
    assert heard.batches == []
    assert kb.complete_until("c/0") < 10           # the mark was not applied either
    errors = kb.add_many(["b^[5, 4]"])             # not atomic: the listeners hear the add
    assert len(errors) == 1 and heard.batches == [[]]


def test_the_stages_are_drawn_in_the_architecture_document():
    text = (Path(__file__).resolve().parent.parent / "docs" / "architecture.md").read_text()
    section = text[text.index("## The path of an event"):text.index("## The path of a query")]
    drawn = re.findall(r"^\s*(\d)\. \*\*([a-z ]+)\*\*", section, flags=re.M)
    assert [name for _, name in drawn] == list(STAGES)
    assert [int(n) for n, _ in drawn] == list(range(1, len(STAGES) + 1))
