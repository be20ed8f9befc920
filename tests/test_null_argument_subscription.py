"""A subscription that meets a stored row with a NULL argument (a row another client wrote:
no event, docs/schema.md) ends with NotAnEvent naming the row, after the answers before it,
as a goal that reads the row refuses it. The delivery thread failed on it instead: it
logged a traceback and tried again on every pass, and every subscription of the type waited
for ever, without a word, for the answers after it and before it alike."""
from __future__ import annotations

import logging
import sqlite3

import pytest

import slr_sql
from slr_sql import Atom, ManualClock, NotAnEvent

WORDS = (r"^subscribe: p/1: the stored row of seq 2 is not an event: its arg1 is NULL, which "
         r"is no term \(written by hand, by another client of the database\); fix or delete "
         r"it \(DELETE FROM \"p\" WHERE arg1 IS NULL\)$")


def by_another_client(db, statement: str) -> None:
    with sqlite3.connect(db) as conn:
        conn.execute(statement)
    conn.close()


def test_a_stored_row_met_in_the_history_ends_the_subscription_in_words(tmp_path, caplog):
    db = tmp_path / "k.db"
    with slr_sql.open(db, clock=ManualClock(10)) as kb:
        kb.add_many(["p(a)^1", "p(b)^2", "p(c)^3"])
    by_another_client(db, "UPDATE p SET arg1 = NULL WHERE seq = 2")
    with caplog.at_level(logging.WARNING, logger="slr_sql"), \
            slr_sql.open(db, clock=ManualClock(10)) as kb, \
            kb.subscribe("p(X)^T", since=0) as sub:
        assert sub.get(timeout=30)["X"] == Atom("a")
        with pytest.raises(NotAnEvent, match=WORDS):
            sub.get(timeout=30)
    assert not [r for r in caplog.records if r.exc_info], caplog.text


def test_a_row_another_client_adds_ends_a_live_subscription_in_words(tmp_path, caplog):
    db = tmp_path / "k.db"
    with caplog.at_level(logging.WARNING, logger="slr_sql"), \
            slr_sql.open(db, clock=ManualClock(10)) as kb, \
            kb.subscribe("p(X)^T") as sub:
        kb.add("p(a)^11")                  # (a live subscription: from the clock's time on)
        assert sub.get(timeout=30)["X"] == Atom("a")
        by_another_client(db, "INSERT INTO p (arg1, t_start, t_end, arrival) "
                              "VALUES (NULL, 12, 12, 10)")
        kb.add("p(c)^13")
        with pytest.raises(NotAnEvent, match=WORDS):
            sub.get(timeout=30)
    assert not [r for r in caplog.records if r.exc_info], caplog.text
