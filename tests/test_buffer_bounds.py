"""Buffer bounds out of range (counts, durations, window times) are refused in words and
change nothing; a store in which an older slr_sql accepted one keeps taking events of that
type, and is never called damaged (docs/buffers.md, "Bounds")."""
from __future__ import annotations

import math
import sqlite3

import pytest

import slr_sql
from slr_sql import SLRError
from slr_sql.buffers import MAX_KEEP_LAST

from service_helpers import HTTP, ServiceProcess


@pytest.fixture
def kb(tmp_path):
    kb = slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(100.0))
    kb.add("p(a)^1")
    yield kb
    kb.close()


@pytest.fixture
def kb_on_both(backend):
    """The store of :func:`kb` on SQLite and on PostgreSQL (the bounds are written into each
    engine's trigger text)."""
    kb = slr_sql.open(backend, clock=slr_sql.ManualClock(100.0))
    kb.add("p(a)^1")
    yield kb
    kb.close()


def nothing_changed(kb) -> None:
    assert kb.buffers() == []
    kb.add_many([f"p(x{i})^{i + 2}" for i in range(5)])
    assert kb.sql("SELECT count(*) FROM p")[1] == [(6,)]


@pytest.mark.parametrize("options, words", [
    ({"keep_last": 10 ** 30}, "keep_last is out of range: at most 9007199254740992 events per "
                              "key, not an integer of 31 digits"),
    ({"keep_last": MAX_KEEP_LAST + 1}, "keep_last is out of range"),
    ({"keep_last": 10 ** 5000}, "keep_last is out of range"),
    ({"keep_last": -1}, "keep_last must be a non-negative integer, not -1"),
    ({"keep_last": 2.5}, "keep_last must be a non-negative integer, not 2.5"),
    ({"keep_last": True}, "keep_last must be a non-negative integer, not True"),
    ({"keep_seconds": 10 ** 400}, "keep_seconds is out of range: an integer of 401 digits"),
    ({"keep_seconds": -0.5}, "keep_seconds must be a non-negative number"),
    ({"keep_seconds": math.nan}, "keep_seconds must be a non-negative number"),
    ({"keep_between": (10 ** 400, 10 ** 401)}, "keep_between's T1 is out of range"),
    ({"keep_between": (0, 10 ** 400)}, "keep_between's T2 is out of range"),
    ({"keep_between": (0, math.nan)}, "keep_between's T2 must be a number, not nan"),
    ({"keep_between": (0, "soon")}, "keep_between's T2 must be a number, not 'soon'"),
    ({"keep_between": (5, 1)}, "T1 must not be after T2"),
    ({"keep_between": (1, 2, 3)}, "keep_between must be a pair of times"),
])
def test_out_of_range_runtime_bounds_are_refused_and_change_nothing(kb, options, words):
    with pytest.raises(SLRError) as caught:
        kb.add_buffer("p(_)", **options)
    assert words in str(caught.value)
    assert "Error:" not in str(caught.value)  # no Python exception name
    nothing_changed(kb)


@pytest.mark.parametrize("declaration, words", [
    ("cBuffer(p(_), 100000000000000000000000000000).", "cBuffer: the count is out of range"),
    ("cBuffer(p(_), -1).", "the count must be a non-negative integer"),
    ("tBuffer(p(_), " + "9" * 400 + ").", "tBuffer: the duration is out of range"),
])
def test_out_of_range_program_bounds_are_refused_and_change_nothing(kb, declaration, words):
    kb.load("q(1).")
    with pytest.raises(SLRError, match=words):
        kb.load(declaration)
    assert [a["X"] for a in kb.query("q(X)")] == [1]
    nothing_changed(kb)


@pytest.mark.parametrize("options", [{"keep_last": MAX_KEEP_LAST}, {"keep_last": 0},
                                     {"keep_seconds": math.inf}, {"keep_seconds": 1e308},
                                     {"keep_between": (-math.inf, math.inf)}])
def test_the_widest_bounds_still_work(kb_on_both, options):
    kb = kb_on_both
    kb.add_buffer("p(_)", **options)
    kb.add_many([f"p(x{i})^{i + 2}" for i in range(3)])
    expected = 0 if options.get("keep_last") == 0 else 4
    assert kb.sql("SELECT count(*) FROM p")[1] == [(expected,)]


def _as_older_versions_wrote(path, count: int, source_count: str | None = None) -> None:
    """Give buffer #1 (installed with ``count``) the bound 10^30 the way an older slr_sql
    stored it: the amount as a REAL and its triggers with that number written in."""
    huge = "1000000000000000019884624838656"   # int(1e30), as older versions printed it
    conn = sqlite3.connect(path)
    conn.execute("UPDATE slr_buffers SET amount = 1e30 WHERE id = 1")
    for name, sql in conn.execute("SELECT name, sql FROM sqlite_master WHERE type = 'trigger' "
                                  "AND name LIKE 'slr_buf_1_%'").fetchall():
        conn.execute(f'DROP TRIGGER "{name}"')
        conn.execute(sql.replace(f"LIMIT {count}", f"LIMIT {huge}")
                     .replace(f"OFFSET {count}", f"OFFSET {huge}"))
    if source_count is not None:
        conn.execute("UPDATE slr_program SET source = replace(source, ?, ?)",
                     (f", {count})", f", {source_count})"))
    conn.commit()
    conn.close()


# ManualClock(100.0) as in the fixtures above: events stamped 1, 2 on a wall clock would be
# "decades late" (a LearnedDelayWarning); no test here waits on the store's time.
def test_a_runtime_bound_an_older_version_accepted_does_not_break_the_type(tmp_path):
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=slr_sql.ManualClock(100.0)) as kb:
        kb.add_buffer("p(_)", keep_last=3)
        kb.add("p(a)^1")
    _as_older_versions_wrote(path, 3)
    with slr_sql.open(path, clock=slr_sql.ManualClock(100.0)) as kb:
        kb.add_many([f"p(x{i})^{i + 2}" for i in range(10)])
        kb.add("p(b)^20")
        assert kb.sql("SELECT count(*) FROM p")[1] == [(12,)]
        (info,) = kb.buffers()
        assert info.amount == MAX_KEEP_LAST
    with slr_sql.open(path, clock=slr_sql.ManualClock(100.0)) as kb:  # and after a second reopen
        kb.add("p(c)^21")
        assert kb.sql("SELECT count(*) FROM p")[1] == [(13,)]


def test_a_program_bound_an_older_version_accepted_does_not_break_the_type(tmp_path):
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=slr_sql.ManualClock(100.0)) as kb:
        kb.load("cBuffer(p(_), 3).")
        kb.add("p(a)^1")
    _as_older_versions_wrote(path, 3, source_count="1000000000000000000000000000000")
    with slr_sql.open(path, clock=slr_sql.ManualClock(100.0)) as kb:
        kb.add_many([f"p(x{i})^{i + 2}" for i in range(10)])
        assert kb.sql("SELECT count(*) FROM p")[1] == [(11,)]
        assert [b.amount for b in kb.buffers()] == [MAX_KEEP_LAST]


def test_a_failing_trigger_is_not_called_a_damaged_file(tmp_path):
    """What the finding saw: the old trigger failing every add said "if the file is damaged,
    restore it". A statement failing in a healthy file says what failed, not that."""
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=slr_sql.ManualClock(100.0)) as kb:
        kb.add("p(a)^1")
        conn = sqlite3.connect(path)
        conn.execute("CREATE TRIGGER bad BEFORE INSERT ON p BEGIN "
                     "SELECT * FROM p LIMIT 1e30; END")
        conn.commit()
        conn.close()
        with pytest.raises(SLRError) as caught:
            kb.add("p(b)^2")
        assert "datatype mismatch" in str(caught.value)
        assert "damaged" not in str(caught.value)


def test_post_buffers_refuses_out_of_range_bounds_with_400(tmp_path):
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(100.0)) as kb:
        kb.add("p(a)^1")
    with ServiceProcess(db) as server:
        for body, words in (({"pattern": "p(_)", "keep_last": 10 ** 30}, "keep_last is out of range"),
                            ({"pattern": "p(_)", "keep_between": [0, 10 ** 400]},
                             "out of range")):
            r = HTTP.post(server.url + "/buffers", json=body, timeout=30)
            assert r.status_code == 400, r.text
            assert words in r.json()["error"]["message"], r.text
        assert HTTP.get(server.url + "/buffers", timeout=30).json()["buffers"] == []
        r = HTTP.post(server.url + "/add", json={"event": "p(b)^2"}, timeout=30)
        assert r.status_code == 200, r.text


def test_a_conflict_with_a_wide_buffer_names_both_readably(kb):
    # the widest duration was written as an integer of 309 digits, the buffer being added
    # as 'runtime buffer #None'
    kb.add_buffer("p(_)", keep_seconds=1e308)
    with pytest.raises(SLRError) as refused:
        kb.add_buffer("p(X)", keep_last=1)
    assert str(refused.value).startswith(
        "conflicting buffers: keep_seconds(p(_), 1e+308) at runtime buffer #1 (kb.add_buffer) "
        "and keep_last(p(X), 1) at a new runtime buffer (kb.add_buffer) have unifiable patterns")
    assert [str(b) for b in kb.buffers()] == [
        "#1 tBuffer p(_): keep while end >= now - 1e+308s (runtime, kb.add_buffer; pruned 0, "
        "dropped 0)"]
