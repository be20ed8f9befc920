"""The facade's edge: whatever a caller passes, a failure is an SLRError in words (never a
raw Python or SQLite exception), and the knowledge base keeps working afterwards."""
from __future__ import annotations

import os

import pytest

import slr_sql

SURROGATE = "\ud800"


def _raises_define(kb, error):
    def boom(x):
        raise error
    kb.define("boom", 1, boom)
    return kb.query("boom(1)")


def _define_returning(kb, value):
    kb.define("odd", 1, lambda x: {"X": value})
    return kb.query("odd(X)")


CASES = {
    "goal None": lambda kb: kb.query(None),
    "goal bytes": lambda kb: kb.query(b"true"),
    "explain None": lambda kb: kb.explain(None),
    "submit None": lambda kb: kb.submit(None),
    "timeout text": lambda kb: kb.query("true", timeout="a"),
    "timeout NaN": lambda kb: kb.query("true", timeout=float("nan")),
    "timeout negative": lambda kb: kb.query("true", timeout=-1),
    "at text": lambda kb: kb.query("p(X)^T", at="x"),
    "at huge integer": lambda kb: kb.query("p(X)^T", at=10 ** 5000),
    "args object": lambda kb: kb.query("p(T)^T", args={"T": object()}),
    "program name surrogate": lambda kb: kb.load("z(1).", name=SURROGATE),
    "mark_complete surrogate": lambda kb: kb.mark_complete(SURROGATE + "/1", 1),
    "mark_complete text time": lambda kb: kb.mark_complete("p/1", "x"),
    "define raising ZeroDivisionError": lambda kb: _raises_define(kb, ZeroDivisionError("x")),
    "define returning object": lambda kb: _define_returning(kb, object()),
    "manual clock backwards": lambda kb: kb.clock.set(-1.0),
}


@pytest.mark.parametrize("case", list(CASES), ids=list(CASES))
def test_bad_calls_are_slr_errors_and_the_kb_keeps_working(case):
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        with pytest.raises(slr_sql.SLRError) as info:
            CASES[case](kb)
        assert type(info.value).__module__.startswith("slr_sql")
        assert str(info.value)
        kb.add("p(a)^1")
        assert kb.query("p(X)^T") == [{"X": "a", "T": 1.0}]


@pytest.mark.parametrize("path", [5, "a\0b.db"], ids=["int", "NUL"])
def test_open_with_a_bad_path_is_an_slr_error(path):
    with pytest.raises(slr_sql.SLRError):
        slr_sql.open(path)


def test_a_damaged_store_is_reported_with_its_path(tmp_path):
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many([f"seen(o{i})^{i}" for i in range(2000)])
    size = os.path.getsize(path)
    assert size > 5 * 4096
    with open(path, "r+b") as f:  # pages 2-4: the catalog and the first tables
        f.seek(4096)
        f.write(os.urandom(3 * 4096))
    with pytest.raises(slr_sql.SLRError, match=str(path)):
        with slr_sql.open(path) as kb:
            kb.query("findall(X, seen(X)^_, L)")
