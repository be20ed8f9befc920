"""A ``recent`` rule keeps an add's terminators, none complete yet, as one pending span.

A live stream's batch arrives before the clock passes it: every new terminator must wait.
They are kept as one row of ``slr_cep_pending`` of kind ``span`` (first and last seq and
their count), not one row each; the clock's move decides them with one statement, and a
move that completes only the earlier ones keeps the later ones as terminators of their own.
The answers are the reference evaluator's whatever the batches and clock moves, on SQLite
and PostgreSQL, and a span is a pending decision another process (or the next open after a
crash) decides like any other. A span covers only rows its add stored: a row another client
commits later with a seq drawn while the add ran is never decided with it.
"""
from __future__ import annotations

import itertools
import json
import sqlite3
import subprocess
import sys
from contextlib import suppress

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock
from slr_sql.store.schema import migrate, migration_scripts

from test_cep_differential import (_event_text, _typed, _vars, ab_points, patterns, reference,
                                   rule_text, rules, streams, two_type_rules)

SEQ2 = (":- consumption(recent).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n"
        "c(X) <- a(X) seq b(X).\n")
BATCH = [f"{'a' if i % 2 == 0 else 'b'}({(i // 2) % 3})^{i + 1}" for i in range(10)]
# c(K) for each b(K)^t: the newest a(K) before it (every b follows its own a)
EXPECTED = sorted(((i // 2) % 3, float(i), float(i + 1)) for i in range(1, 10, 2))


def _ending_before(t: float) -> list:
    return [c for c in EXPECTED if c[2] < t]


def _pending(kb) -> list:
    """(kind, rowids) of the store's pending rows, in id order."""
    return [(kind, json.loads(rowids)) for kind, rowids in
            kb.sql("SELECT kind, rowids FROM slr_cep_pending ORDER BY id")[1]]


def _c(kb) -> list:
    return sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]"))


def _decided_as_the_reference(kb, clock) -> None:
    """Once the clock passed every event, nothing is pending and r/1 holds exactly what
    the reference evaluator derives from FIRST + LIVE (the foreign row is no terminator)."""
    clock.set(100.0)
    assert _pending(kb) == []
    got = sorted(((tuple(args), s, e) for args, s, e, _ in kb.store.scan("r", 1)), key=repr)
    expected = reference(SEQ2_RULE, FIRST + LIVE)
    assert _typed(got) == _typed([(tuple(h), s, e) for h, s, e in expected])


def _pending_count(kb) -> int:
    counts = [info["pending"] for info in kb.event_rules()]
    # (an int on both backends: PostgreSQL's sum of a span's counts is a numeric, which the
    # service's JSON would have sent as a string)
    assert all(type(count) is int for count in counts), counts
    return sum(counts)


@pytest.fixture(params=["sqlite", "postgres"])
def where(request, tmp_path):
    if request.param == "sqlite":
        return str(tmp_path / "spans.db")
    return request.getfixturevalue("postgres_url")


def test_a_live_batch_keeps_its_terminators_as_one_span(where):
    clock = ManualClock(0.0)
    with slr_sql.open(where, clock=clock) as kb:
        kb.load(SEQ2)
        kb.add_many(BATCH)
        assert _pending(kb) == [("span", [1, 5, 5])]   # b's seqs 1..5, five terminators
        assert _pending_count(kb) == 5
        clock.set(100.0)
        assert _pending(kb) == []
        assert _c(kb) == EXPECTED


def test_a_span_decided_in_part_keeps_the_rest_as_terminators(where):
    clock = ManualClock(0.0)
    with slr_sql.open(where, clock=clock) as kb:
        kb.load(SEQ2)
        kb.add_many(BATCH)
        clock.set(6.5)   # b^2, b^4, b^6 complete (their a's before them); b^8, b^10 not
        assert _c(kb) == _ending_before(6.5)
        assert _pending(kb) == [("term", [4]), ("term", [5])]
        assert _pending_count(kb) == 2
        kb.add_many(["a(1)^11", "b(1)^12"])   # a later batch: a span of its own
        assert _pending(kb) == [("term", [4]), ("term", [5]), ("span", [6, 6, 1])]
        clock.set(100.0)
        assert _pending(kb) == []
        assert _c(kb) == sorted(EXPECTED + [(1, 11.0, 12.0)])


def test_an_add_with_a_complete_terminator_keeps_the_others_one_by_one(where):
    """A late batch: some terminators complete at once (decided in the add), the others
    kept one by one (a span would hold decided rows)."""
    clock = ManualClock(4.5)
    with slr_sql.open(where, clock=clock) as kb:
        kb.load(SEQ2)
        kb.add_many(["a(0)^1", "b(0)^2", "a(1)^3", "b(1)^4", "a(2)^5", "b(2)^6"])
        assert _c(kb) == [(0, 1.0, 2.0), (1, 3.0, 4.0)]
        assert _pending(kb) == [("term", [3])]
        clock.set(10.0)
        assert _c(kb) == [(0, 1.0, 2.0), (1, 3.0, 4.0), (2, 5.0, 6.0)]


def test_another_process_decides_a_span_a_killed_process_left(tmp_path):
    """The process that stored the span dies before its clock moves; the next store opened
    on the file, with a clock past the span, decides it."""
    path = str(tmp_path / "left.db")
    script = ("import os, sys, slr_sql\n"
              "kb = slr_sql.open(sys.argv[1], clock=slr_sql.ManualClock(0.0))\n"
              f"kb.load({SEQ2!r})\n"
              f"kb.add_many({BATCH!r})\n"
              "os._exit(0)\n")   # (no close: as a crash leaves it)
    subprocess.run([sys.executable, "-c", script, path], check=True, timeout=60)
    clock = ManualClock(0.0)
    with slr_sql.open(path, clock=clock) as kb:
        kb.load(SEQ2)
        assert _pending(kb) == [("span", [1, 5, 5])]
        clock.set(100.0)
        assert _pending(kb) == []
        assert _c(kb) == EXPECTED


def test_a_version_11_store_keeps_its_pending_rows(tmp_path):
    """Migration 12 makes ``slr_cep_pending`` again (SQLite cannot change a CHECK in place):
    the rows pending before are kept as they were, and kind ``span`` is admitted."""
    path = str(tmp_path / "v11.db")
    conn = sqlite3.connect(path, isolation_level=None)
    migrate(conn, path, [s for s in migration_scripts() if s[0] <= 11])
    row = ("k", 0, "term", 1, "[7]", 1.0, 2.0, "a", 1, 3.0, "why", 0.5)
    conn.execute("INSERT INTO slr_cep_pending (rule, alt, kind, pos, rowids, t_start, t_end, "
                 "wait_type, wait_arity, wait_time, wait_reason, created_at) "
                 "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)", row)
    with pytest.raises(sqlite3.IntegrityError):
        conn.execute("INSERT INTO slr_cep_pending (rule, alt, kind, rowids, t_start, t_end) "
                     "VALUES ('k', 0, 'span', '[1, 2, 2]', 1.0, 2.0)")
    conn.close()
    with slr_sql.open(path) as kb:
        assert kb.store.schema_version() == migration_scripts()[-1][0]
    conn = sqlite3.connect(path, isolation_level=None)
    assert conn.execute("SELECT rule, alt, kind, pos, rowids, t_start, t_end, wait_type, "
                        "wait_arity, wait_time, wait_reason, created_at "
                        "FROM slr_cep_pending").fetchall() == [row]
    conn.execute("INSERT INTO slr_cep_pending (rule, alt, kind, rowids, t_start, t_end) "
                 "VALUES ('k', 0, 'span', '[1, 2, 2]', 1.0, 2.0)")
    with pytest.raises(sqlite3.IntegrityError):
        conn.execute("INSERT INTO slr_cep_pending (rule, alt, kind, rowids, t_start, t_end) "
                     "VALUES ('k', 0, 'other', '[1]', 1.0, 2.0)")
    assert [r[1] for r in conn.execute("PRAGMA index_list(slr_cep_pending)")] == \
        ["slr_cep_pending_by_rule"]
    conn.close()


def test_a_version_11_store_with_a_view_of_its_pending_rows_is_upgraded(tmp_path):
    """A view of ``slr_cep_pending`` (one of the user's) names the table migration 12 drops
    and makes again: the upgrade keeps it, reading the new table."""
    path = str(tmp_path / "v11view.db")
    conn = sqlite3.connect(path, isolation_level=None)
    migrate(conn, path, [s for s in migration_scripts() if s[0] <= 11])
    conn.execute("INSERT INTO slr_cep_pending (rule, alt, kind, pos, rowids, t_start, t_end) "
                 "VALUES ('k', 0, 'term', 1, '[7]', 1.0, 2.0)")
    conn.execute("CREATE VIEW waiting AS SELECT rule, kind, rowids FROM slr_cep_pending")
    conn.close()
    with slr_sql.open(path) as kb:
        assert kb.store.schema_version() == migration_scripts()[-1][0]
        assert kb.sql("SELECT * FROM waiting")[1] == [("k", "term", "[7]")]
        kb.sql("INSERT INTO slr_cep_pending (rule, alt, kind, rowids, t_start, t_end) "
               "VALUES ('k', 0, 'span', '[1, 2, 2]', 1.0, 2.0)", write=True)
        assert sorted(kb.sql("SELECT kind FROM waiting")[1]) == [("span",), ("term",)]


def run_with_clock_moves(rule, events, order, cuts, moves, where=None):
    """Add ``events`` in ``order``, in batches cut at ``cuts``; after each batch the clock
    moves to the time ``moves`` picks among the batch's ends (less a half) and just before
    the earliest end still to come -- never past an event that has not arrived (max_delay
    0) -- and at the end past everything."""
    sequence = [events[i] for i in order]
    clock = ManualClock(0.0)
    with slr_sql.open(where, clock=clock) as kb:
        delays = "".join(f":- max_delay({name}/{arity}, 0).\n"
                         for name, arity in (("a", 1), ("b", 1), ("c", 1), ("d", 2)))
        kb.load(f":- consumption({rule['policy']}).\n{delays}" + rule_text(rule))
        start = 0
        for cut in sorted(set(cuts)) + [len(sequence)]:
            if start < cut <= len(sequence):
                batch, start = sequence[start:cut], cut
                assert kb.add_many([_event_text(ev) for ev in batch]) == []
                bound = min((ev[3] for ev in sequence[start:]), default=100.0) - 0.25
                times = sorted({ev[3] - 0.5 for ev in batch} | {bound})
                times = [t for t in times if clock.now() <= t <= bound]
                if times:
                    clock.set(moves(times))
        clock.set(100.0)
        arity = len(rule["head"])
        rows = kb.store.scan("r", arity) if kb.store.table_for("r", arity) else []
        return sorted(((tuple(args), s, e) for args, s, e, _ in rows), key=repr)


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.one_of(two_type_rules().map(lambda rule: dict(rule, policy="recent")),
                 rules().filter(lambda rule: rule["policy"] == "recent")),
       st.one_of(ab_points(), streams()), st.data())
def test_clock_moves_between_batches_give_the_reference(rule, events, data):
    """Spans decided whole, in part, or not at all by each clock move, in any arrival
    order: the complex events are the reference evaluator's."""
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    cuts = data.draw(st.lists(st.integers(0, len(events)), max_size=4), label="batches")
    expected = reference(rule, events)
    got = run_with_clock_moves(rule, events, order, cuts,
                               lambda times: data.draw(st.sampled_from(times), label="clock"))
    assert _typed(got) == _typed([(tuple(h), s, e) for h, s, e in expected]), rule_text(rule)


_SCHEMAS = itertools.count()


@pytest.fixture(scope="module")
def database(postgres_server):
    """One database for the module's PostgreSQL examples, a schema each."""
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


@settings(max_examples=15, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.one_of(two_type_rules().map(lambda rule: dict(rule, policy="recent")),
                 rules().filter(lambda rule: rule["policy"] == "recent")),
       st.one_of(ab_points(), streams()), st.data())
def test_clock_moves_between_batches_on_postgres_give_the_reference(database, rule, events,
                                                                   data):
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    cuts = data.draw(st.lists(st.integers(0, len(events)), max_size=4), label="batches")
    schema = database + ("&" if "?" in database else "?") + f"schema=s{next(_SCHEMAS)}"
    got = run_with_clock_moves(rule, events, order, cuts,
                               lambda times: data.draw(st.sampled_from(times), label="clock"),
                               where=schema)
    expected = reference(rule, events)
    assert _typed(got) == _typed([(tuple(h), s, e) for h, s, e in expected]), rule_text(rule)


@st.composite
def recent_rules_with_or(draw):
    """recent rules of several alternatives (``or``), each with its own terminators (the
    reference evaluator's recent takes no ``or``)."""
    pattern = draw(patterns(allow_or=True))
    if pattern[0] != "or":
        pattern = ("or", pattern, draw(patterns(depth=1, allow_or=True)))
    bound = sorted(_vars(pattern))
    where = []
    if bound and draw(st.booleans()):
        where.append((draw(st.sampled_from(["<", ">", "=<", ">="])),
                      draw(st.sampled_from(bound)), draw(st.sampled_from(bound + [0, 1]))))
    return {"pattern": pattern, "head": [v for v in bound if draw(st.booleans())],
            "where": where, "cnot": None, "within": draw(st.sampled_from([None, 2])),
            "policy": "recent"}


def _all_at_once(rule, events) -> list:
    """The complex events of ``events`` added in one batch in end order, the clock past
    them all (every terminator decided in the add: no span)."""
    with slr_sql.open(None, clock=ManualClock(100.0)) as kb:
        delays = "".join(f":- max_delay({name}/{arity}, 0).\n"
                         for name, arity in (("a", 1), ("b", 1), ("c", 1), ("d", 2)))
        kb.load(f":- consumption(recent).\n{delays}" + rule_text(rule))
        assert kb.add_many([_event_text(ev) for ev in
                            sorted(events, key=lambda ev: (ev[3], ev[2]))]) == []
        arity = len(rule["head"])
        rows = kb.store.scan("r", arity) if kb.store.table_for("r", arity) else []
        return sorted(((tuple(args), s, e) for args, s, e, _ in rows), key=repr)


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(recent_rules_with_or(), streams(), st.data())
def test_spans_of_several_alternatives_give_what_one_batch_gives(rule, events, data):
    """Each alternative keeps spans of its own terminators; decided whole, in part or not
    at all by the clock moves between batches in any arrival order, they derive what the
    events added at once, in order, with the clock past them derive."""
    order = data.draw(st.permutations(range(len(events))), label="arrival order")
    cuts = data.draw(st.lists(st.integers(0, len(events)), max_size=4), label="batches")
    got = run_with_clock_moves(rule, events, order, cuts,
                               lambda times: data.draw(st.sampled_from(times), label="clock"))
    assert _typed(got) == _typed(_all_at_once(rule, events)), rule_text(rule)


def test_explain_shows_how_a_span_is_decided(tmp_path):
    with slr_sql.open(str(tmp_path / "x.db"), clock=ManualClock(0.0)) as kb:
        kb.load(SEQ2)
        kb.add_many(BATCH)
        text = kb.explain("c(X)")
    assert "SQL deciding the spans of position 1 kept in slr_cep_pending" in text
    # (the span's terminators are read by their seq range, not one by one)
    assert "SEARCH e1 USING INTEGER PRIMARY KEY (rowid>? AND rowid<?)" in text


def test_a_span_whose_rule_needs_python_now_decides_every_terminator(where):
    """The program changes what the rule's where goal calls (stored facts, pushed into the
    SQL, become a rule): the rule's text and key stay, its alternative needs the Python
    side now, and the spans it kept are decided one terminator at a time -- every one of
    them, those not complete yet kept as terminators of their own."""
    rule = SEQ2.replace("b(X).", "b(X) where ok(X).")
    clock = ManualClock(0.0)
    with slr_sql.open(where, clock=clock) as kb:
        kb.load(rule + "ok(0). ok(1). ok(2).\n")
        kb.add_many(BATCH)
        assert _pending(kb) == [("span", [1, 5, 5])]
        kb.load(rule + "ok(X) :- X >= 0, X < 3.\n")
        clock.set(6.5)
        assert _c(kb) == _ending_before(6.5)
        assert sorted(_pending(kb)) == [("term", [4]), ("term", [5])]
        assert _pending_count(kb) == 2
        clock.set(100.0)
        assert _pending(kb) == []
        assert _c(kb) == EXPECTED


SEQ2_RULE = {"pattern": ("seq", ("leaf", "a", ["X"]), ("leaf", "b", ["X"])), "head": ["X"],
             "where": [], "cnot": None, "within": None, "policy": "recent"}
FIRST = [("a", (2,), 0.5, 0.5), ("b", (2,), 0.75, 0.75)]
LIVE = [("a" if i % 2 == 0 else "b", ((i // 2) % 3,), float(i + 1), float(i + 1))
        for i in range(10)]


class ForeignClient:
    """Another client of the store's database, writing its tables directly (no write group,
    no rule run): sqlite3 on the file, psycopg on the server."""

    def __init__(self, where: str) -> None:
        self.postgres = where.startswith("postgresql")
        if self.postgres:
            import psycopg
            self.conn = psycopg.connect(where, autocommit=True)
            self.conn.execute("SET search_path = slr")   # (the store's schema)
        else:
            self.conn = sqlite3.connect(where, isolation_level=None, timeout=30)

    def run(self, sql: str, params: tuple = ()) -> list:
        cur = self.conn.execute(sql.replace("?", "%s") if self.postgres else sql, params)
        return cur.fetchall() if cur.description else []

    def draw_a_seq_before(self, t_end: float) -> None:
        """The b row ending at ``t_end`` gets its seq after another one drawn first -- what
        an insert of another client running at that moment does: the add's seqs are then
        not one run, and the one drawn is free for a row committed later."""
        if self.postgres:
            self.run("CREATE FUNCTION draw_a_seq() RETURNS trigger LANGUAGE plpgsql AS $$ "
                     "BEGIN PERFORM nextval(pg_get_serial_sequence('b', 'seq')); "
                     "RETURN NEW; END $$")
            self.run("CREATE TRIGGER draw_a_seq BEFORE INSERT ON b FOR EACH ROW WHEN "
                     f"(NEW.t_end = {t_end!r}) EXECUTE FUNCTION draw_a_seq()")
        else:   # (AUTOINCREMENT hands a seq out once: a row put in and taken out draws it)
            self.run(f"CREATE TRIGGER draw_a_seq BEFORE INSERT ON b WHEN NEW.t_end = {t_end!r} "
                     "BEGIN INSERT INTO b (arg1, t_start, t_end, arrival) "
                     "VALUES (NULL, -1.0, -1.0, 0.0); DELETE FROM b WHERE t_end = -1.0; END")

    def close(self) -> None:
        self.conn.close()


def test_a_row_another_client_commits_inside_a_live_batchs_seqs_is_no_terminator(where):
    """A row of the terminator's type that another client commits after the add, with a seq
    drawn while the add ran (so inside the range of the add's seqs), is no new row of any
    add: it is never decided as a terminator, so the complex events are the reference
    evaluator's over the events added -- a span covers only the rows its add stored."""
    clock = ManualClock(0.0)
    with slr_sql.open(where, clock=clock) as kb:
        kb.load(":- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n:- consumption(recent).\n"
                + rule_text(SEQ2_RULE))
        kb.add_many([_event_text(ev) for ev in FIRST])   # (makes the types' tables)
        clock.set(1.0)
        other = ForeignClient(where)
        try:
            other.draw_a_seq_before(6.0)
            assert kb.add_many([_event_text(ev) for ev in LIVE]) == []
            seqs = [seq for (seq,) in other.run("SELECT seq FROM b ORDER BY seq")]
            gap = [s for s in range(seqs[0], seqs[-1]) if s not in seqs]
            assert len(gap) == 1 and seqs[1] < gap[0] < seqs[-1], seqs
            # (the add's terminators, their seqs not one run, are kept one by one)
            assert _pending(kb) == [("term", [seq]) for seq in seqs[1:]]
            # b(1) at 5.5: the newest a(1) before it is a(1)^3 -- were it decided
            other.run("INSERT INTO b (seq, arg1, t_start, t_end, arrival) "
                      "VALUES (?, 1, 5.5, 5.5, 1.0)", (gap[0],))
        finally:
            other.close()
        _decided_as_the_reference(kb, clock)


def test_a_row_another_session_inserts_while_a_live_batch_goes_in_is_no_terminator(
        postgres_url):
    """The race itself, on PostgreSQL: another session inserts a row of the terminator's
    type while the add's insert is half way (the add is held there by a trigger waiting for
    a lock the test holds), so its seq falls between the add's, and it commits only after
    the add. The add's terminators are kept one by one, and the other session's row is
    never decided: the complex events are the reference evaluator's over the events
    added."""
    import threading
    import time

    import psycopg

    clock = ManualClock(0.0)
    with slr_sql.open(postgres_url, clock=clock) as kb:
        kb.load(":- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n:- consumption(recent).\n"
                + rule_text(SEQ2_RULE))
        kb.add_many([_event_text(ev) for ev in FIRST])
        clock.set(1.0)
        with psycopg.connect(postgres_url, autocommit=True) as other, \
                psycopg.connect(postgres_url, autocommit=True) as watcher:
            other.execute("SET search_path = slr")
            other.execute("CREATE FUNCTION wait_for_the_test() RETURNS trigger "
                          "LANGUAGE plpgsql AS $$ BEGIN PERFORM pg_advisory_xact_lock_shared("
                          "7707); RETURN NEW; END $$")
            other.execute("CREATE TRIGGER wait_for_the_test BEFORE INSERT ON b FOR EACH ROW "
                          "WHEN (NEW.t_end = 6.0) EXECUTE FUNCTION wait_for_the_test()")
            other.execute("SELECT pg_advisory_lock(7707)")
            failed: list[BaseException] = []

            def add() -> None:
                try:
                    kb.add_many([_event_text(ev) for ev in LIVE])
                except BaseException as exc:   # (asserted below)
                    failed.append(exc)
            adding = threading.Thread(target=add)
            adding.start()
            try:
                deadline = time.monotonic() + 30
                while not watcher.execute(
                        "SELECT count(*) FROM pg_locks WHERE locktype = 'advisory' "
                        "AND objid = 7707 AND NOT granted").fetchone()[0]:
                    assert time.monotonic() < deadline, "the add never reached the trigger"
                    assert adding.is_alive(), failed
                    time.sleep(0.005)
                other.execute("BEGIN")
                other.execute("INSERT INTO b (arg1, t_start, t_end, arrival) "
                              "VALUES (1, 5.5, 5.5, 1.0)")   # its seq: drawn now
                other.execute("SELECT pg_advisory_unlock(7707)")
                adding.join(30)
                assert not adding.is_alive() and not failed, failed
                other.execute("COMMIT")   # after the add's commit
            finally:
                with suppress(psycopg.Error):
                    other.execute("ROLLBACK")
                other.execute("SELECT pg_advisory_unlock_all()")
                adding.join(30)
            seqs = [seq for (seq,) in other.execute("SELECT seq FROM b WHERE t_end <> 5.5 "
                                                    "ORDER BY seq").fetchall()]
            (foreign,) = other.execute("SELECT seq FROM b WHERE t_end = 5.5").fetchone()
            assert seqs[1] < foreign < seqs[-1], (seqs, foreign)
            assert _pending(kb) == [("term", [seq]) for seq in seqs[1:]]
        _decided_as_the_reference(kb, clock)
