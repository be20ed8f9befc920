"""A row with a NULL argument is no event (no term is stored as NULL). slr_sql's own door
for hand-written SQL (`kb.sql(..., write=True)`, `slr sql --write`) refuses a statement
that would leave one, and changes nothing; a row written so by another SQLite client is
met by a goal that reads it with NotAnEvent, naming the type, the row's seq, the column and
the fix, the same words whichever path met it (compiled SQL, the interpreter, prev/next, a
lazy `solutions`, the command line); goals that do not meet it answer as before, on both
paths alike."""
from __future__ import annotations

import sqlite3

import pytest

import slr_sql
from slr_sql import Atom, ManualClock, NotAnEvent

from test_cli import slr
from test_cli_errors import fails_in_words

RULES = """
r(X) :- p(X)^_.
s(X, T) :- p(X)^T.
u(X) :- p(X)^_, atom(X).
"""


def null_by_another_client(db, statement: str) -> None:
    """A write slr_sql does not see: plain sqlite3 (docs/schema.md: unsupported)."""
    with sqlite3.connect(db) as conn:
        conn.execute(statement)
    conn.close()


@pytest.fixture
def kb(tmp_path):
    db = tmp_path / "k.db"
    with slr_sql.open(db, clock=ManualClock(10)) as kb:
        for event in ("p(a)^1", "p(b)^2", "p(c)^3", "q(x, 1)^1"):
            kb.add(event)
    null_by_another_client(db, "UPDATE p SET arg1 = NULL WHERE seq = 2")
    kb = slr_sql.open(db, clock=ManualClock(10))
    kb.load(RULES)
    yield kb
    kb.close()


def expect_not_an_event(kb, goal: str, where: str = "query") -> str:
    with pytest.raises(NotAnEvent) as caught:
        kb.query(goal)
    message = str(caught.value)
    assert message.startswith(f"{where}: p/1: the stored row of seq 2 is not an event: its "
                              f"arg1 is NULL"), message
    assert 'DELETE FROM "p" WHERE arg1 IS NULL' in message
    assert "ValueError" not in message
    return message


@pytest.mark.parametrize("goal", [
    "p(X)^T", "r(X)", "s(X, T)", "u(X)", "findall(X, p(X)^_, L)", "p(X)^_, X == b",
    "prev(p(X)^T, 2.5)", "next(p(X)^T, [1.5, 5])", "q(A, B)^_, p(X)^_",
])
def test_a_goal_that_reads_the_row_says_which_row_on_both_paths(kb, goal):
    said = []
    for compiled in (True, False):
        kb.sql_enabled = compiled
        said.append(expect_not_an_event(kb, goal))
    assert said[0] == said[1]


@pytest.mark.parametrize("goal, answers", [
    ("p(b)^T", []),
    ("p(a)^T", [{"T": 1.0}]),
    ("prev(p(a)^T, 2.5)", [{"T": 1.0}]),
    ("prev(p(X)^T, 3.5)", [{"X": Atom("c"), "T": 3.0}]),
    ("q(X, Y)^T", [{"X": Atom("x"), "Y": 1, "T": 1.0}]),
])
def test_a_goal_that_does_not_meet_the_row_answers_alike_on_both_paths(kb, goal, answers):
    for compiled in (True, False):
        kb.sql_enabled = compiled
        assert kb.query(goal) == answers


def test_solutions_say_it_as_query_does(kb):
    kb.sql_enabled = False
    with pytest.raises(NotAnEvent, match=r"^solutions: p/1: the stored row of seq 2"):
        list(kb.solutions("p(X)^T"))


def test_the_row_deleted_the_goal_answers(kb):
    expect_not_an_event(kb, "p(X)^T")
    kb.sql('DELETE FROM "p" WHERE arg1 IS NULL', write=True)
    assert [a["X"] for a in kb.query("p(X)^T")] == [Atom("a"), Atom("c")]


def test_a_row_fixed_through_the_door_answers(kb):
    # a row that is no event already does not hold up writes that leave no new one
    kb.sql("INSERT INTO p (arg1, t_start, t_end, arrival) VALUES ('d', 4, 4, 10)", write=True)
    kb.sql("UPDATE p SET arg1 = 'b' WHERE seq = 2", write=True)
    assert [a["X"] for a in kb.query("p(X)^T")] == [Atom(x) for x in "abcd"]


@pytest.mark.parametrize("backend_kind", ["sqlite", "postgres"])
@pytest.mark.parametrize("statement", [
    "UPDATE p SET arg1 = NULL WHERE seq = 2",
    "INSERT INTO p (arg1, t_start, t_end, arrival) VALUES (NULL, 4, 4, 10)",
    "INSERT INTO q (arg1, arg2, t_start, t_end, arrival) SELECT arg1, NULL, 5, 5, 10 FROM p",
    "with x(v) as (select null) update p set arg1 = (select v from x)",
])
def test_the_door_refuses_a_write_that_would_leave_no_event_and_changes_nothing(
        backend_kind, statement, request, tmp_path):
    where = (request.getfixturevalue("postgres_url") if backend_kind == "postgres"
             else str(tmp_path / "k.db"))
    with slr_sql.open(where, clock=ManualClock(10)) as kb:
        for event in ("p(a)^1", "p(b)^2", "q(x, 1)^1"):
            kb.add(event)
        rows = {t: kb.sql(f"SELECT * FROM {t} ORDER BY seq")[1] for t in ("p", "q")}
        with pytest.raises(NotAnEvent, match=r"^sql: the statement would leave a row that is "
                                             r"no event: arg\d of [pq]/\d's row of seq \d+"):
            kb.sql(statement, write=True)
        assert {t: kb.sql(f"SELECT * FROM {t} ORDER BY seq")[1] for t in ("p", "q")} == rows
        assert [a["X"] for a in kb.query("p(X)^_")] == [Atom("a"), Atom("b")]
        # the door's own work is a transaction of the store: it goes on as before
        kb.add("p(c)^3")
        assert len(kb.query("p(X)^_")) == 3


def test_the_command_line_refuses_the_write_and_says_a_foreign_one_in_words(tmp_path):
    db = str(tmp_path / "robot.db")
    assert slr("add", db, "p(a)^1", "p(b)^2").returncode == 0
    fails_in_words(slr("sql", db, "UPDATE p SET arg1 = NULL WHERE seq = 2", "--write"),
                   "error: sql: the statement would leave a row that is no event: arg1 of "
                   "p/1's row of seq 2 would be NULL")
    null_by_another_client(db, "UPDATE p SET arg1 = NULL WHERE seq = 2")
    fails_in_words(slr("query", db, "p(X)^T"),
                   "p/1: the stored row of seq 2 is not an event: its arg1 is NULL")


def test_postgresql_says_it_in_the_same_words(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(10)) as kb:
        for event in ("p(a)^1", "p(b)^2", "p(c)^3"):
            kb.add(event)
        kb.store.execute("UPDATE p SET arg1 = NULL WHERE seq = 2")   # (below the door)
        for compiled in (True, False):
            kb.sql_enabled = compiled
            expect_not_an_event(kb, "p(X)^T")
            assert kb.query("p(a)^T") == [{"T": 1.0}]


def test_the_service_says_it_as_a_bad_request_and_stays_up(tmp_path):
    from service_helpers import ServiceProcess

    db = tmp_path / "served.db"
    with slr_sql.open(db, clock=ManualClock(10)) as kb:
        for event in ("p(a)^1", "p(b)^2"):
            kb.add(event)
    null_by_another_client(db, "UPDATE p SET arg1 = NULL WHERE seq = 2")
    with ServiceProcess(db) as server, slr_sql.connect(server.url) as remote:
        with pytest.raises(NotAnEvent, match=r"^query: p/1: the stored row of seq 2 is not an "
                                             r"event: its arg1 is NULL"):
            remote.query("p(X)^T")
        assert remote.query("p(a)^T") == [{"T": 1.0}]
    assert "Traceback" not in server.log.read_text()


def test_the_door_refuses_a_postgresql_merge_too(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(10)) as kb:
        kb.add("p(a)^1")
        with pytest.raises(NotAnEvent, match=r"^sql: the statement would leave a row"):
            kb.sql("MERGE INTO p USING (SELECT 1 AS one) AS s ON false WHEN NOT MATCHED THEN "
                   "INSERT (arg1, t_start, t_end, arrival) VALUES (NULL, 4, 4, 10)", write=True)
        assert kb.sql("SELECT count(*) FROM p")[1] == [(1,)]


# The door does not read the statement's text: the store says which tables a statement
# wrote (SQLite's authorizer while it compiles the statement and its triggers; PostgreSQL's
# row counters of the transaction), so a write by a trigger, by a function, or through a
# name spelled another way is checked like a plain one.
TRIGGER = {
    "sqlite": ["CREATE TABLE notes (x)",
               "CREATE TRIGGER notes_p AFTER INSERT ON notes BEGIN "
               "INSERT INTO p (arg1, t_start, t_end, arrival) VALUES (NULL, 4, 4, 10); END"],
    "postgres": ["CREATE TABLE notes (x int)",
                 "CREATE FUNCTION notes_p() RETURNS trigger LANGUAGE plpgsql AS $$ BEGIN "
                 "INSERT INTO p (arg1, t_start, t_end, arrival) VALUES (NULL, 4, 4, 10); "
                 "RETURN NULL; END $$",
                 "CREATE TRIGGER notes_p AFTER INSERT ON notes FOR EACH ROW "
                 "EXECUTE FUNCTION notes_p()"],
}
SPELLED_OTHERWISE = {
    "sqlite": ['UPDATE "main"."P" SET arg1 = NULL WHERE seq = 2',
               "UPDATE [p] SET arg1 = NULL WHERE seq = 2"],
    "postgres": ['UPDATE U&"\\0070" SET arg1 = NULL WHERE seq = 2',
                 'UPDATE U&"!0070" UESCAPE \'!\' SET arg1 = NULL WHERE seq = 2'],
}


def opened_with_p(backend_kind, request, tmp_path):
    where = (request.getfixturevalue("postgres_url") if backend_kind == "postgres"
             else str(tmp_path / "k.db"))
    kb = slr_sql.open(where, clock=ManualClock(10))
    for event in ("p(a)^1", "p(b)^2"):
        kb.add(event)
    return kb


def refused_unchanged(kb, statement: str, seq: int) -> None:
    rows = kb.sql("SELECT * FROM p ORDER BY seq")[1]
    with pytest.raises(NotAnEvent, match=rf"^sql: the statement would leave a row that is no "
                                         rf"event: arg1 of p/1's row of seq {seq} would be NULL"):
        kb.sql(statement, write=True)
    assert kb.sql("SELECT * FROM p ORDER BY seq")[1] == rows
    assert [a["X"] for a in kb.query("p(X)^_")] == [Atom("a"), Atom("b")]


@pytest.mark.parametrize("backend_kind", ["sqlite", "postgres"])
def test_the_door_refuses_a_null_a_trigger_would_write(backend_kind, request, tmp_path):
    with opened_with_p(backend_kind, request, tmp_path) as kb:
        for statement in TRIGGER[backend_kind]:
            kb.sql(statement, write=True)
        # the statement names no event table; its trigger writes one
        refused_unchanged(kb, "INSERT INTO notes VALUES (1)", 3)
        assert kb.sql("SELECT count(*) FROM notes")[1] == [(0,)]
        # also when the statement ran before (SQLite keeps it compiled)
        refused_unchanged(kb, "INSERT INTO notes VALUES (1)", 3 if backend_kind == "sqlite"
                          else 4)   # (a PostgreSQL sequence does not go back)


@pytest.mark.parametrize("backend_kind", ["sqlite", "postgres"])
def test_the_door_refuses_a_null_through_a_table_name_spelled_otherwise(
        backend_kind, request, tmp_path):
    with opened_with_p(backend_kind, request, tmp_path) as kb:
        for statement in SPELLED_OTHERWISE[backend_kind]:
            refused_unchanged(kb, statement, 2)


def test_the_door_refuses_a_null_written_through_another_name_of_the_store_file(tmp_path):
    """``ATTACH`` of the store's own file names its tables again (``o.p``): a write through
    that name is one of the store's, checked as such -- it changes nothing (it waits for
    the check's own transaction, which holds the file's write lock) instead of running
    unchecked and leaving a NULL argument."""
    db = tmp_path / "k.db"
    with slr_sql.open(db, clock=ManualClock(10), busy_timeout=0.2) as kb:
        for event in ("p(a)^1", "p(b)^2"):
            kb.add(event)
        kb.sql(f"ATTACH DATABASE '{db}' AS o", write=True)
        with pytest.raises(slr_sql.SLRError):
            kb.sql("UPDATE o.p SET arg1 = NULL WHERE seq = 2", write=True)
        kb.sql("DETACH DATABASE o", write=True)
        assert kb.sql("SELECT arg1 FROM p ORDER BY seq")[1] == [("a",), ("b",)]
        assert [a["X"] for a in kb.query("p(X)^_")] == [Atom("a"), Atom("b")]


def test_the_door_refuses_a_null_a_postgresql_function_writes(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(10)) as kb:
        kb.add("p(a)^1")
        kb.sql("CREATE FUNCTION spoil() RETURNS int LANGUAGE sql AS "
               "$$ UPDATE p SET arg1 = NULL RETURNING 1 $$", write=True)
        with pytest.raises(NotAnEvent, match=r"^sql: the statement would leave a row"):
            kb.sql("SELECT spoil()", write=True)
        assert kb.query("p(X)^_") == [{"X": Atom("a")}]


def test_the_door_refuses_a_null_a_deferred_postgresql_trigger_writes(postgres_url):
    """A constraint trigger deferred to the commit writes after the statement: it runs
    before the door reads what the statement wrote, so its NULL is refused too."""
    with slr_sql.open(postgres_url, clock=ManualClock(10)) as kb:
        for event in ("p(a)^1", "p(b)^2"):
            kb.add(event)
        kb.sql("CREATE TABLE notes (n int)", write=True)
        kb.sql("CREATE FUNCTION spoil() RETURNS trigger LANGUAGE plpgsql AS "
               "$$ BEGIN UPDATE p SET arg1 = NULL WHERE seq = 2; RETURN NULL; END $$",
               write=True)
        kb.sql("CREATE CONSTRAINT TRIGGER spoiler AFTER INSERT ON notes DEFERRABLE "
               "INITIALLY DEFERRED FOR EACH ROW EXECUTE FUNCTION spoil()", write=True)
        refused_unchanged(kb, "INSERT INTO notes VALUES (1)", 2)
        assert kb.sql("SELECT count(*) FROM notes")[1] == [(0,)]


@pytest.mark.parametrize("backend_kind", ["sqlite", "postgres"])
def test_a_write_beside_rows_that_were_no_events_already_goes_through_once(
        backend_kind, request, tmp_path):
    with opened_with_p(backend_kind, request, tmp_path) as kb:
        kb.store.execute("UPDATE p SET arg1 = NULL WHERE seq = 2")   # (below the door)
        # the table it writes holds a row that is no event: the run is taken back, the
        # rows there before read, and it runs again; its effect is there once
        kb.sql("INSERT INTO p (arg1, t_start, t_end, arrival) VALUES ('d', 4, 4, 10)",
               write=True)
        assert kb.sql("SELECT count(*) FROM p WHERE arg1 = 'd'")[1] == [(1,)]
        kb.sql("UPDATE p SET t_end = t_end WHERE seq = 2", write=True)   # (stays as it was)
        with pytest.raises(NotAnEvent, match=r"^sql: the statement would leave a row that "
                                             r"is no event: arg1 of p/1's row of seq 1 "):
            kb.sql("UPDATE p SET arg1 = NULL WHERE seq = 1", write=True)
        assert kb.sql("SELECT arg1 FROM p WHERE seq = 1")[1] == [("a",)]


def test_without_the_servers_row_counters_every_table_counts_as_written(postgres_url):
    # (track_counts = off: pg_stat_xact_user_tables stays still, so the door reads them all)
    with slr_sql.open(postgres_url, clock=ManualClock(10)) as kb:
        for event in ("p(a)^1", "p(b)^2"):
            kb.add(event)
        for statement in TRIGGER["postgres"]:
            kb.sql(statement, write=True)
        kb.store.execute("SET track_counts = off")
        refused_unchanged(kb, "INSERT INTO notes VALUES (1)", 3)
        kb.sql("INSERT INTO notes SELECT 2 WHERE false", write=True)   # (writes no NULL)


def test_a_sqlite_statement_that_writes_no_event_table_runs_outside_a_transaction(tmp_path):
    # SQLite tells what a statement writes by compiling it (EXPLAIN): one that writes no
    # event table runs as given, so one that cannot run in a transaction still runs
    with slr_sql.open(tmp_path / "k.db", clock=ManualClock(10)) as kb:
        kb.add("p(a)^1")
        assert kb.sql("VACUUM", write=True) == ([], [])
        assert kb.sql("PRAGMA wal_checkpoint(TRUNCATE)", write=True)[1] == [(0, 0, 0)]
        assert kb.query("p(X)^_") == [{"X": Atom("a")}]
