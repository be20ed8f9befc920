"""The store's parts (catalog, fleet, buffers, lookups, space, tables, events) run their
statements through the connection's ``execute`` (``Database.failure``): a condition of the
file or its disk met by one of them is an SLRError in words, never sqlite3's error, also on
the paths no knowledge base call is around -- the subscription hub's delivery pass and its
housekeeping, which log it as one WARNING line without a traceback.

Every condition is real: the store's page limit (``PRAGMA max_page_count``: SQLITE_FULL at
the statement that needs a new page), a page or the whole file overwritten on disk, another
store's file put in the store's place."""
from __future__ import annotations

import logging

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.errors import SLRStoreFull
from slr_sql.store import EventStore

from hub_helpers import hub_with_one_delivery
from store_conditions import file_condition, slr_failure

DEADLINE = 30.0
NO_LIMIT = 1073741823   # SQLite's default max_page_count

BIG = "x" * 100_000     # a value that needs pages of its own


def _store(path: str) -> EventStore:
    """A store whose parts have something to read: events of p/1 and r/2, a buffer, a
    robot that shipped, a rule's table."""
    store = EventStore(path, robot="r1")
    store.add_events([("p", ("a",), 1.0, 1.0), ("r", ("a", 1), 1.0, 2.0)])
    store.meta_set("k", 1)
    store.append_program("q(1).")
    store.insert_buffer("cBuffer", "program", "p(_)", "p", 1, 3, None, None, "add")
    store.fleet_receive("r2", "p", 1, [(1, "b", 1.0, 1.0, 1.0, None)])
    store.create_rule_tables('"slr_cep_m_x"', 1, 1)
    return store


# The reads of each part, outside a transaction: each says a file no longer a database (or
# no longer the store) itself
READS = {
    "meta_get": lambda s: s.meta_get("k"),
    "meta_items": lambda s: s.meta_items(),
    "versions": lambda s: s.versions(),
    "program_texts": lambda s: s.program_texts(),
    "rule_matches": lambda s: s.rule_matches('"slr_cep_m_x"', 1),
    "buffer_rows": lambda s: s.buffer_rows(),
    "has_active_buffer": lambda s: s.has_active_buffer("tBuffer"),
    "buffer_objects": lambda s: s.buffer_objects(1),
    "robots": lambda s: s.robots(),
    "fleet_counters": lambda s: s.fleet_counters(),
    "fleet_positions": lambda s: s.fleet_positions("r2"),
    "fleet_contacts": lambda s: s.fleet_contacts(),
    "fleet_retired": lambda s: s.fleet_retired(),
    "fleet_read_after": lambda s: s.fleet_read_after("p", 1, 0, 10),
    "fleet_backlog": lambda s: s.fleet_backlog("p", 1, 0),
    "table_rows": lambda s: s.table_rows(),
    "space_stats": lambda s: s.space_stats(),
    "recorded_now": lambda s: s.recorded_now(),
    "table_for_unknown": lambda s: s.table_for("unknown", 1),
    "count": lambda s: s.count("p", 1),
    "max_end": lambda s: s.max_end("p", 1),
    "max_seq": lambda s: s.max_seq("p", 1),
    "raw_rows": lambda s: s.raw_rows("p", 1, after_seq=0),
    "raw_page": lambda s: s.raw_page("p", 1, rows=5, max_bytes=100, after_seq=0),
    "latest_rows": lambda s: s.latest_rows("p", 1, (0,), ["a"], 5.0, False),
    "bracket": lambda s: s.bracket("r", 2, {0: "a"}, 1.5),
    "bracket_zero": lambda s: s.bracket("r", 2, {0: "a", 1: 0.0}, 1.5),
    "distinct_pairs": lambda s: s.distinct_pairs("r", 2),
    "null_arguments": lambda s: s.null_arguments(),
    "scan": lambda s: list(s.scan("p", 1, {})),
}


@pytest.mark.parametrize("afterwards", ["damaged", "replaced"])
@pytest.mark.parametrize("read", READS.values(), ids=READS.keys())
def test_each_read_of_the_stores_parts_says_the_files_condition(tmp_path, read, afterwards):
    """The file's bytes turned to garbage under the open store (its cached pages dropped):
    a damaged file; once another store took its place at the path as well, SLRStoreGone."""
    path = str(tmp_path / "s.db")
    _store(path).close()
    store = EventStore(path)
    try:
        file_condition(path, store, read, afterwards, _store)
    finally:
        store.close()


# The writes of each part that need a new page, in their transactions
WRITES = {
    "meta_set": lambda s: s.meta_set("big", BIG),
    "append_program": lambda s: s.append_program(f"q('{BIG}')."),
    "replace_named_program": lambda s: s.replace_named_program("main", f"q('{BIG}')."),
    "replace_program": lambda s: s.replace_program([(f"q('{BIG}').", None)]),
    "replace_fact_tables": lambda s: s.replace_fact_tables({("c", 1): [("x",)]}),
    "create_rule_tables": lambda s: s.create_rule_tables('"slr_cep_m_y"', 1, 1),
    "create_journal": lambda s: s.create_journal("p", 1, "slr_subj_p", "slr_subt_p"),
    "declare_type": lambda s: s.declare_type("new", 2),
    "add_events": lambda s: s.add_events([("p", (BIG,), 5.0, 5.0)]),
    "fleet_receive": lambda s: s.fleet_receive("r2", "p", 1, [(2, BIG, 2.0, 2.0, 2.0, None)]),
}


@pytest.mark.parametrize("write", WRITES.values(), ids=WRITES.keys())
def test_each_write_of_the_stores_parts_at_its_size_limit_is_store_full(tmp_path, write):
    path = str(tmp_path / "s.db")
    store = _store(path)
    try:
        assert store.execute("PRAGMA freelist_count") == [(0,)]   # (no page to reuse)
        store.execute(f"PRAGMA max_page_count = {store.execute('PRAGMA page_count')[0][0]}")
        exc = slr_failure(lambda: write(store))
        assert isinstance(exc, SLRStoreFull)
        assert str(exc).startswith(f"{path}: the disk is full (or the store reached its size "
                                   f"limit")
        store.execute(f"PRAGMA max_page_count = {NO_LIMIT}")
        write(store)   # (nothing of the refused call stayed in the way)
    finally:
        store.close()


def _one_line(caplog: pytest.LogCaptureFixture, what: str) -> logging.LogRecord:
    """The one log record of ``what``: a WARNING without a traceback, and nothing worse."""
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR], caplog.text
    [record] = [r for r in caplog.records if what in r.getMessage()]
    assert record.levelno == logging.WARNING and record.exc_info is None, caplog.text
    assert "Traceback" not in caplog.text
    return record


def test_the_hubs_pass_journaling_a_table_at_the_size_limit_logs_one_line(tmp_path, caplog):
    """Another connection (another process's store, which has no hub) stores the first
    q/1 event: its table has no journal, so the hub's delivery pass makes one, on the
    store's connection -- at the store's size limit, SLRStoreFull: one WARNING line. Once
    there is room, the next pass makes it and q events are delivered."""
    path = str(tmp_path / "s.db")
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb, \
            caplog.at_level(logging.WARNING, logger="slr_sql"):
        hub = kb._subscriptions
        hub.poll_interval = 3600.0        # a pass runs when asked for, not on a timer
        sub = kb.subscribe("q(X)^T", since=0)
        assert hub.drain(DEADLINE)
        other = EventStore(path)
        try:
            other.add_event("q", ("a",), 1.0, 1.0)
        finally:
            other.close()
        store = kb.store
        assert store.execute("PRAGMA freelist_count") == [(0,)]
        store.execute(f"PRAGMA max_page_count = {store.execute('PRAGMA page_count')[0][0]}")
        assert hub.drain(DEADLINE)
        record = _one_line(caplog, "delivery pass failed")
        assert f"SLRStoreFull: {path}: the disk is full" in record.getMessage()
        assert "slr_subt_q" not in store.triggers("q")
        store.execute(f"PRAGMA max_page_count = {NO_LIMIT}")
        assert hub.drain(DEADLINE)
        assert "slr_subt_q" in store.triggers("q")
        kb.add("q(b)^2")
        assert sub.get(timeout=DEADLINE)["X"] == "b"
        sub.close()


def test_the_hubs_housekeeping_dropping_a_damaged_journal_logs_one_line(tmp_path, caplog):
    """A journal no subscription wants any more (another process's, unsubscribed) is dropped
    by the housekeeping's cleanup, on the store's connection: its pages overwritten on disk,
    the drop meets a damaged file -- one WARNING line."""
    path = str(tmp_path / "s.db")
    with hub_with_one_delivery(path, caplog) as (kb, hub, sub):
        hub.persist_interval = hub.cleanup_interval = 3600.0   # rounds only when asked
        store = kb.store
        kb.add("q(a)^1")
        store.create_journal("q", 1, "slr_subj_q", "slr_subt_q")
        kb.add("q(b)^2")
        assert hub.drain(DEADLINE)
        store.execute("PRAGMA wal_checkpoint(TRUNCATE)")   # every page in the file
        [(root,)] = store.execute("SELECT rootpage FROM sqlite_master WHERE name = ?",
                                  ("slr_subj_q",))
        [(size,)] = store.execute("PRAGMA page_size")
        with open(path, "r+b") as f:
            f.seek((root - 1) * size)
            f.write(b"\xff" * size)
        store.execute("PRAGMA shrink_memory")   # the next read of the page reads the file
        hub._last_cleanup = 0.0                  # a cleanup is due
        assert hub.housekeeping_round(DEADLINE)
        record = _one_line(caplog, "housekeeping failed")
        assert f"SLRError: {path}: the file is damaged (database disk image is malformed)" \
            in record.getMessage()
        assert "slr_subj_q" in store.table_names()   # the drop rolled back
