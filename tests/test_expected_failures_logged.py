"""Failures that any client can bring about (the store busy past ``busy_timeout``, closed,
full) are logged as one line, without a traceback: a delivery pass or a housekeeping round
of the subscription hub that meets a busy store, a WebSocket subscription whose closing
fails. A bug (an exception that is no SLRError) keeps its traceback, at ERROR.

The busy store is real: another connection holds the SQLite file's write lock while the
hub must write (a housekeeping round; a pass journaling a type whose trigger is missing)."""
from __future__ import annotations

import asyncio
import logging
import sqlite3

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRBusy
from slr_sql.service.app import Limits, _Service
from slr_sql.subscriptions.registry import TRIGGER_PREFIX
from store_holders import meta_held

DEADLINE = 30.0


def _records(caplog, text: str) -> list[logging.LogRecord]:
    return [r for r in caplog.records if text in r.getMessage()]


def _one_line(caplog, record: logging.LogRecord) -> None:
    assert record.levelno == logging.WARNING
    assert record.exc_info is None, caplog.text
    assert "Traceback" not in caplog.text
    assert "\n" not in caplog.handler.format(record)


def test_a_housekeeping_round_meeting_a_busy_store_is_one_line(tmp_path, caplog):
    path = str(tmp_path / "s.db")
    with slr_sql.open(path, clock=ManualClock(0.0), busy_timeout=0.2) as kb, \
            caplog.at_level(logging.WARNING, logger="slr_sql"):
        hub = kb._subscriptions
        sub = kb.subscribe("p(X)^T", since=0, id="log")
        kb.add_many(["p(1)^1", "p(2)^2"])
        assert [sub.get(timeout=DEADLINE)["X"] for _ in range(2)] == [1, 2]
        with meta_held(path):
            hub._last_persist = 0.0       # the position is due now
            assert hub.housekeeping_round(DEADLINE)
        [record] = _records(caplog, "housekeeping failed")
        assert "SLRBusy" in record.getMessage() and "retrying" in record.getMessage()
        _one_line(caplog, record)
        hub._last_persist = 0.0
        assert hub.housekeeping_round(DEADLINE)   # the store is free again: written
        assert {r["id"]: r["live_pos"] for r in hub.subscriptions()}["log"] == 1   # p(1): handled
        sub.close()


def test_a_delivery_pass_meeting_a_busy_store_is_one_line(tmp_path, caplog):
    """The pass must journal a type whose trigger is missing (a program without this module
    dropped it) while another connection holds the file: SLRBusy, one line; once the file is
    free the next pass journals it and delivers."""
    path = str(tmp_path / "s.db")
    with slr_sql.open(path, clock=ManualClock(0.0), busy_timeout=0.2) as kb, \
            slr_sql.open(path, clock=ManualClock(0.0)) as other, \
            caplog.at_level(logging.WARNING, logger="slr_sql"):
        hub = kb._subscriptions
        hub.poll_interval = 3600.0        # a pass runs when asked for, not on a timer
        sub = kb.subscribe("q(X)^T", since=0)
        assert hub.drain(DEADLINE)        # no table yet: nothing journaled
        other.add("q(1)^1")               # the table, journaled for the subscription
        table = other.store.table_for("q", 1)
        raw = sqlite3.connect(path, isolation_level=None)
        try:
            raw.execute(f'DROP TRIGGER "{TRIGGER_PREFIX}{table}"')
        finally:
            raw.close()
        with meta_held(path):
            assert hub.drain(DEADLINE)
        [record] = _records(caplog, "delivery pass failed")
        assert "SLRBusy" in record.getMessage()
        _one_line(caplog, record)
        assert hub.drain(DEADLINE)        # journaled again now: every event reaches it
        other.add("q(2)^2")
        assert hub.drain(DEADLINE)
        assert [sub.get(timeout=DEADLINE)["X"] for _ in range(2)] == [1, 2]
        sub.close()


def test_a_bug_in_a_delivery_pass_or_housekeeping_keeps_its_traceback(tmp_path, caplog,
                                                                      monkeypatch):
    def bug(*args):
        raise KeyError("a bug")

    with slr_sql.open(str(tmp_path / "s.db"), clock=ManualClock(0.0)) as kb, \
            caplog.at_level(logging.WARNING, logger="slr_sql"):
        hub = kb._subscriptions
        sub = kb.subscribe("p(X)^T", since=0)
        monkeypatch.setattr(hub, "_serve_type", bug)
        monkeypatch.setattr(hub, "_housekeeping", bug)
        assert hub.drain(DEADLINE)
        assert hub.housekeeping_round(DEADLINE)
        monkeypatch.undo()
        for what in ("delivery pass failed", "housekeeping failed"):
            [record] = _records(caplog, what)
            assert record.levelno == logging.ERROR
            assert record.exc_info is not None and record.exc_info[0] is KeyError
        assert "Traceback" in caplog.text
        sub.close()


class _Unclosable:
    """A subscription whose closing fails with ``error`` (the service only calls close)."""

    def __init__(self, error: BaseException):
        self.error = error

    def close(self) -> None:
        raise self.error


def test_closing_a_websocket_subscription_that_fails_is_one_line_unless_a_bug(caplog):
    with slr_sql.open() as kb, caplog.at_level(logging.WARNING, logger="slr_sql"):
        service = _Service(kb, None, Limits())
        asyncio.run(service._close_subscription(_Unclosable(SLRBusy("the store is busy"))))
        [record] = _records(caplog, "closing a subscription failed")
        assert "SLRBusy: the store is busy" in record.getMessage()
        _one_line(caplog, record)
        caplog.clear()
        asyncio.run(service._close_subscription(_Unclosable(KeyError("a bug"))))
        [record] = _records(caplog, "closing a subscription failed")
        assert record.levelno == logging.ERROR and record.exc_info is not None
