"""Programs across reopen on both backends: facts become tables with inspection views, a later
load replaces them (PostgreSQL refuses to drop a table a view reads: the views are moved
aside and back), and a bad program changes nothing."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import SLRError


def test_a_load_after_reopen_replaces_the_fact_tables_under_their_views(backend):
    with slr_sql.open(backend) as kb:
        kb.load("ok(1). ok(2).", name="a")
    with slr_sql.open(backend) as kb:
        kb.load("ok2(3).", name="b")
        assert [a["X"] for a in kb.query("ok(X)")] == [1, 2]
        assert [a["X"] for a in kb.query("ok2(X)")] == [3]
        _, rows = kb.sql("SELECT count(*) FROM ok")
        assert rows[0][0] == 2
        _, rows = kb.sql("SELECT count(*) FROM ok2")
        assert rows[0][0] == 1


@pytest.mark.parametrize("bad", ["bad( :- .", ":- no_such_directive(x).", "atom(x) :- true."])
def test_a_bad_program_after_reopen_changes_nothing(backend, bad):
    with slr_sql.open(backend) as kb:
        kb.load("ok(1).")
    with slr_sql.open(backend) as kb:
        with pytest.raises(SLRError):
            kb.load("ok2(1).\n" + bad)
        assert kb.query("ok(X)") == [{"X": 1}]
        kb.load("ok2(2).")
        assert kb.query("ok2(X)") == [{"X": 2}]


def test_text_with_u0000_is_a_value_on_both_backends_and_a_name_only_on_sqlite(backend):
    """PostgreSQL text cannot hold U+0000: an argument holding it is stored escaped (the same
    answers as SQLite), an event *name* holding it is that event's rejection in words there,
    and the batch's other events are stored."""
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p('a\\0\\b')^1")
        kb.load("q('x\\0\\y'). r(X) :- q(X).")
        assert kb.query("p(X)^_") == [{"X": "a\x00b"}]
        assert kb.query("p('a\\0\\b')^T") == [{"T": 1.0}]
        assert kb.query("r(X)") == [{"X": "x\x00y"}]
        rejected = kb.add_many(["'n\\0\\'(1)^2", "p(ok)^3"])
        if backend.startswith("postgresql"):
            [why] = rejected
            assert "cannot hold the character U+0000" in str(why)
            assert kb.query("'n\\0\\'(X)^_") == []
        else:
            assert rejected == [] and kb.query("'n\\0\\'(X)^_") == [{"X": 1}]
        assert [a["X"] for a in kb.query("p(X)^_")] == ["a\x00b", "ok"]


def test_sql_takes_question_mark_and_named_parameters_on_both_backends(backend):
    """``kb.sql``'s placeholders are the API's (``?`` with a sequence, ``:name`` with a
    mapping) on either backend; a mapping is never taken for the sequence of its keys."""
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add_many(["p(a)^1", "p(b)^2", "p(c)^3"])
        _, rows = kb.sql("SELECT arg1 FROM p WHERE t_end >= ? ORDER BY t_end", [2.0])
        assert rows == [("b",), ("c",)]
        _, rows = kb.sql("SELECT arg1 FROM p WHERE t_end = :t AND arg1 = :a", {"t": 3.0, "a": "c"})
        assert rows == [("c",)]
        _, rows = kb.sql("SELECT count(*) FROM p WHERE arg1 LIKE '%'")   # a % as written
        assert rows[0][0] == 3
        # a ? or :name inside a comment is no parameter (PostgreSQL took the comment's for
        # one: "the query has 2 placeholders but 1 parameters were passed")
        _, rows = kb.sql("SELECT arg1 /* after ?, 50% :t */ FROM p WHERE t_end > ? "
                         "ORDER BY t_end", [2.0])
        assert rows == [("c",)]
        _, rows = kb.sql("SELECT arg1 FROM p /* :t? */ WHERE t_end = :t", {"t": 1.0})
        assert rows == [("a",)]


def test_sql_parameters_are_not_read_inside_postgresql_strings_and_comments(postgres_url):
    """PostgreSQL's own kinds of text hold a ? or :name that is no parameter: a dollar-quoted
    string, an escape string whose quote is escaped by a backslash, a nested comment."""
    with slr_sql.open(postgres_url) as kb:
        _, rows = kb.sql("SELECT $$?:a$$, $tag$ ? $x$ $tag$, E'it\\'s ?:a', ? "
                         "/* a /* nested ? */ comment ? */", [1])
        assert rows == [("?:a", " ? $x$ ", "it's ?:a", 1)]
        _, rows = kb.sql("SELECT E'\\\\', :a, e'%'", {"a": 2})
        assert rows == [("\\", 2, "%")]


VIEWS_PROGRAM = """
usedFor(cup, tea).  usedFor(mug, coffee).
teaThing(O) :- obj(O, T, _)^_, usedFor(T, tea).
when(O, T) :- obj(O, _, _)^T.
size(O, X) :- obj(O, _, X)^_.
either(O) :- obj(O, cup, _)^_ ; obj(O, mug, _)^_.
notMug(O) :- obj(O, K, _)^_, \\+ K = mug.
sameKind(A, B) :- obj(A, K, _)^T1, obj(B, K, _)^T2, T1 < T2.
near(O) :- obj(O, _, D)^_, D < 2.5.
firstCup(O) :- obj(O, cup, _)^_, !.
double(O, X) :- obj(O, _, D)^_, X is D * 2.
"""


def _views(kb) -> list[str]:
    if kb.store.dialect.name == "sqlite":
        _, rows = kb.sql("SELECT name FROM sqlite_master WHERE type = 'view'")
    else:
        _, rows = kb.sql("SELECT table_name FROM information_schema.views "
                         "WHERE table_schema = current_schema()")
    return sorted(r[0] for r in rows)


def test_derived_predicates_get_the_same_views_on_both_backends(backend):
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0)) as kb:
        for event in ("obj(cup1, cup, 1.5)^1", "obj(mug1, mug, 3)^2", "obj(cup2, cup, [1,2])^3",
                      "obj(mug2, mug, 3.0)^3.5", "obj('a b', cup, f(x))^4"):
            kb.add(event)
        kb.load(VIEWS_PROGRAM)
        # comparisons and arithmetic call slr_sql's functions, a cut does not compile: no
        # view for those, on either engine
        assert _views(kb) == ["either", "notMug", "sameKind", "size", "teaThing", "usedFor",
                              "when"]
        rows = {v: kb.sql(f'SELECT * FROM "{v}"')[1] for v in _views(kb)}
        assert rows["teaThing"] == [("cup1",), ("cup2",), ("a b",)]
        assert rows["either"] == [("cup1",), ("cup2",), ("a b",), ("mug1",), ("mug2",)]
        assert rows["notMug"] == [("cup1",), ("cup2",), ("a b",)]
        assert rows["sameKind"] == [("cup1", "cup2"), ("cup1", "a b"), ("mug1", "mug2"),
                                    ("cup2", "a b")]
        assert rows["when"] == [("cup1", 1.0), ("mug1", 2.0), ("cup2", 3.0), ("mug2", 3.5),
                                ("a b", 4.0)]
        # values in each engine's column encoding (docs/sql.md, docs/postgres.md)
        sizes = [v for _, v in rows["size"]]
        if not backend.startswith("postgresql"):
            assert sizes == [1.5, 3, "[1,2]", 3.0, '{"f":["x"]}']
        else:
            assert sizes == ["1.5", "3", "[1,2]", "3.0", '{"f":["x"]}']
        # the views answer as the queries do
        assert [(a["O"],) for a in kb.query("teaThing(O)")] == rows["teaThing"]
        kb.unload("main")
        assert _views(kb) == []


def test_a_postgres_view_reads_from_a_session_without_the_store_search_path(postgres_url):
    import psycopg

    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(0)) as kb:
        kb.add("obj(cup1, cup, 1.5)^1")
        kb.load(VIEWS_PROGRAM)
    with psycopg.connect(postgres_url) as conn:   # as psql would: search_path "$user", public
        rows = conn.execute('SELECT * FROM slr."teaThing"').fetchall()
    assert rows == [("cup1",)]


MIXED_PROGRAM = """
byRobot(R, X) :- origin(R, seen(X, _)^_) ; X = none.
byRobotOrTime(R, X) :- origin(R, seen(X, _)^_) ; other(X)^_.
stamp(X) :- seen(_, _)^X ; X = a.
"""


def test_a_program_whose_branches_mix_kinds_loads_with_the_views_the_server_can_type(backend):
    """A view's column has one type on PostgreSQL: a robot's name (text) and a time (a
    number) cannot share an order key, nor a time and a data value an argument. Such a
    predicate gets no view there (as one that needs slr_sql's functions); the program
    loads all the same and answers as on SQLite."""
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0), robot="r1") as kb:
        kb.add_many(["seen(a, dock)^1", "seen(3, bay)^2", "other(b)^3"])
        kb.load(MIXED_PROGRAM)
        on_sqlite = not backend.startswith("postgresql")
        assert _views(kb) == (["byRobot", "byRobotOrTime", "stamp"] if on_sqlite
                              else ["byRobot"])
        assert kb.sql('SELECT * FROM "byRobot"')[1] == (
            [("r1", "a"), ("r1", 3), (None, "none")] if on_sqlite
            else [("r1", "a"), ("r1", "3"), (None, "none")])
        assert [a["X"] for a in kb.query("stamp(X)")] == [1.0, 2.0, slr_sql.Atom("a")]
        assert [a["X"] for a in kb.query("byRobotOrTime(_, X)")] == [
            slr_sql.Atom("a"), 3, slr_sql.Atom("b")]


def test_predicates_whose_names_share_the_first_63_bytes_load_on_both_backends(backend):
    """PostgreSQL cuts identifiers at 63 bytes: the second predicate's view would take the
    first one's name, and the server refuses it. The program loads all the same (that
    predicate has no view there) and answers as on SQLite."""
    first, second = "p" * 70 + "a", "p" * 70 + "b"
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0)) as kb:
        kb.add("seen(a, dock)^1")
        kb.load(f"{first}(X) :- seen(X, _)^_.\n{second}(X) :- seen(X, dock)^_ ; X = z.\n")
        assert [a["X"] for a in kb.query(f"{second}(X)")] == ["a", "z"]
        assert len(_views(kb)) == (2 if not backend.startswith("postgresql") else 1)


def test_a_view_appears_when_another_connection_adds_the_first_event_of_its_type(backend):
    """A derived predicate over an event type with no table yet has no view; the view is
    made when the table is, whichever connection (or process) adds that first event, not
    only the one that loaded the program."""
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0)) as kb:
        kb.load("d(X) :- e(X)^_ ; X = none.\nf(X) :- g(X)^_.")
        assert _views(kb) == ["d"]
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0)) as writer:
        writer.add("e(a)^1")
        assert _views(writer) == ["d"]
        assert writer.sql('SELECT * FROM "d"')[1] == [("a",), ("none",)]
        writer.add("g(b)^2")
        assert _views(writer) == ["d", "f"]


def test_a_statement_the_client_cannot_send_is_refused_not_a_lost_server(postgres_url):
    """psycopg raises OperationalError for more parameters than the protocol carries: that
    is the statement's error (SLRError, not retryable), not an unreachable server (503)."""
    with slr_sql.open(postgres_url) as kb:
        with pytest.raises(SLRError, match="cannot be sent") as info:
            kb.sql("SELECT " + ", ".join(["?"] * 70_000), tuple(range(70_000)))
        assert not isinstance(info.value, slr_sql.errors.SLRUnavailable)
        assert kb.sql("SELECT ?", (1,))[1] == [(1,)]


def test_long_event_names_get_tables_on_both_backends(backend):
    """PostgreSQL cuts names at 63 bytes: an event name of 60 characters gave its table's
    four indexes one name, and two long names sharing a beginning one table. A long name now
    gets a table of its own there (cut, with a digest); SQLite keeps the name as it is. The
    events, an event rule over them and a subscription work alike."""
    long_a, long_b = "perception_" + "x" * 60 + "_a", "perception_" + "x" * 60 + "_b"
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.load(f"both(X) <- {long_a}(X) seq {long_b}(X).")
        sub = kb.subscribe(f"{long_b}(X)^T")
        kb.add_many([f"{long_a}(1)^1", f"{long_b}(1)^2", f"{long_a}(2)^3"])
        assert kb.query(f"{long_a}(X)^T") == [{"X": 1, "T": 1.0}, {"X": 2, "T": 3.0}]
        assert kb.query(f"{long_b}(X)^T") == [{"X": 1, "T": 2.0}]
        assert kb.query("both(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 2.0}]
        assert sub.get(timeout=30) == {"X": 1, "T": 2.0}
        sub.close()
        _, rows = kb.sql("SELECT name, table_name FROM slr_event_types ORDER BY name")
        tables = dict(rows)
        assert len(set(tables.values())) == len(tables)
        if backend.startswith("postgresql"):
            assert all(len(t) <= 30 for t in tables.values())
        else:
            assert tables[long_a] == long_a


def test_long_fact_predicate_names_get_tables_on_both_backends(backend):
    """Two fact predicates whose table names share their first 63 bytes failed to load on
    PostgreSQL (it cuts names): each gets a table of its own, and answers as on SQLite."""
    long_a, long_b = "fact_" + "y" * 60 + "_a", "fact_" + "y" * 60 + "_b"
    with slr_sql.open(backend) as kb:
        kb.load(f"{long_a}(1). {long_a}(2). {long_b}(3).\n"
                f"both(X) :- {long_a}(X) ; {long_b}(X).")
    with slr_sql.open(backend) as kb:       # a reopened store reads its tables back
        assert [a["X"] for a in kb.query(f"{long_a}(X)")] == [1, 2]
        assert [a["X"] for a in kb.query(f"{long_b}(X)")] == [3]
        assert [a["X"] for a in kb.query("both(X)")] == [1, 2, 3]
