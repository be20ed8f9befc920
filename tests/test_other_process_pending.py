"""Decisions another process left pending (it stored them, then stopped) are made here when
only this process's clock moves, or an in-order event of this process completes them: on
SQLite the rules read their pending summaries again when ``PRAGMA data_version`` says that
another connection committed (a check without I/O when nothing changed)."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import slr_sql
from slr_sql import ManualClock

REPO = Path(__file__).resolve().parent.parent

RULE = ":- consumption(recent).\n:- max_delay(b/1, 0).\n" \
       "c(X) <- a(X) seq b(X).\n"
BY_DELAY = ":- max_delay(a/1, 5).\n" + RULE        # a/1 complete to now - 5
IN_ORDER = ":- in_order(a/1).\n" + RULE             # a/1 complete to its latest end


def _add_in_another_process(path: Path, events: list[str]) -> None:
    """Another process opens the store (the program is the stored one), adds ``events``
    with its clock at 0, and exits."""
    code = ("import sys, slr_sql\n"
            "kb = slr_sql.open(sys.argv[1], clock=slr_sql.ManualClock(0.0))\n"
            "assert kb.add_many(sys.argv[2:]) == []\n"
            "assert kb.event_rules()[0]['pending'] == 1, kb.event_rules()\n"
            "kb.close()\n")
    done = subprocess.run([sys.executable, "-c", code, str(path), *events],
                          env=dict(os.environ, PYTHONPATH=str(REPO)),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


def _c(kb) -> list:
    return [(a["X"], a["S"], a["E"]) for a in kb.query("c(X)^[S, E]")]


def test_a_clock_move_decides_what_another_process_left_pending(tmp_path):
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
        kb.clock.advance(1)                   # (its rules have looked: nothing pending)
        _add_in_another_process(path, ["a(1)^1", "b(1)^2"])
        assert _c(kb) == []                   # (its clock at 1: a/1 complete to -4)
        kb.clock.set(8.0)                     # a/1 complete to 3: the decision can be made
        assert _c(kb) == [(1, 1.0, 2.0)]
        assert kb.event_rules()[0]["pending"] == 0


def test_an_in_order_event_decides_what_another_process_left_pending(tmp_path):
    path = tmp_path / "robot.db"
    # (the clock here is at 10: b/1 is complete to 10; what a/1 needs is its event at 3)
    with slr_sql.open(path, clock=ManualClock(10.0)) as kb:
        kb.load(IN_ORDER)
        assert kb.add_many(["a(0)^0.5"]) == []
        _add_in_another_process(path, ["a(1)^1", "b(1)^2"])
        assert _c(kb) == []
        assert kb.add_many(["a(9)^3"]) == []  # a/1 complete before 3
        assert _c(kb) == [(1, 1.0, 2.0)]


def test_a_process_alone_reads_its_summaries_no_more_often(tmp_path):
    # nothing committed by another connection: a clock move reads no summary (the rules'
    # statements, counted by SQLite's own trace of this connection)
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.load(BY_DELAY)
        kb.add_many(["a(1)^1", "b(1)^2"])
        kb.clock.advance(1)
        statements: list[str] = []
        kb.store._db.conn.set_trace_callback(statements.append)
        try:
            for _ in range(5):
                kb.clock.advance(0.1)
        finally:
            kb.store._db.conn.set_trace_callback(None)
        assert not [s for s in statements if "slr_cep_pending WHERE rule" in s]
