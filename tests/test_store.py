"""The SQLite event store: encoding, persistence, validation, lookups and their query plans."""
from __future__ import annotations

import math
import sqlite3
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slr_sql.encoding import decode, encode, encode_json
from slr_sql.errors import EventRejected
from slr_sql.store import EventBatch, EventStore, migration_scripts, split_sql_script
from slr_sql.terms import NIL, Atom, String, Struct, Var, make_list


class StepClock:
    """A clock the tests move by hand."""

    def __init__(self, now: float = 100.0):
        self.value = now

    def now(self) -> float:
        return self.value


@pytest.fixture
def mem_store():
    store = EventStore(None, StepClock())
    yield store
    store.close()


@pytest.fixture
def file_store(tmp_path):
    store = EventStore(tmp_path / "robot.db", StepClock())
    yield store
    store.close()


@pytest.fixture(params=["memory", "file"])
def store(request, tmp_path):
    path = None if request.param == "memory" else tmp_path / "robot.db"
    store = EventStore(path, StepClock())
    yield store
    store.close()


def same_term(a, b) -> bool:
    """Identical terms, including the Python types (Atom vs String, int vs float)."""
    if type(a) is not type(b):
        return False
    if type(a) is Struct:
        return (a.name == b.name and len(a.args) == len(b.args)
                and all(same_term(x, y) for x, y in zip(a.args, b.args)))
    if type(a) is float:
        return a == b and math.copysign(1, a) == math.copysign(1, b) or (a != a and b != b)
    return a == b


# ---------------------------------------------------------------- terms for hypothesis

TRICKY_TEXTS = ["[x", "{", '"q"', "$string", "$atom", "$int", "'", "''", "[]", "{}", "",
                "; DROP TABLE seg; --", "a\"b", "back\\slash", "new\nline", "nul\x00byte",
                "héllo", "日本", "😀", " lead", "1", "1.5", "null", "true"]

texts = st.one_of(st.sampled_from(TRICKY_TEXTS), st.text(max_size=12))
atoms = texts.map(Atom)
strings = texts.map(String)
ints = st.one_of(st.integers(-2 ** 63, 2 ** 63 - 1), st.integers(), st.sampled_from(
    [0, -1, 2 ** 63 - 1, -2 ** 63, 2 ** 63, -2 ** 63 - 1, 10 ** 30]))
floats = st.one_of(st.floats(allow_nan=False), st.sampled_from(
    [0.0, -0.0, 1.0, 1e22, 1e-300, 5e-324, math.inf, -math.inf, 0.1]))
scalars = st.one_of(atoms, strings, ints, floats)


def extend(children):
    lists = st.lists(children, max_size=5).map(make_list)
    partial = st.tuples(st.lists(children, min_size=1, max_size=3), st.one_of(atoms, ints)).map(
        lambda pair: make_list(pair[0], pair[1]))
    compounds = st.tuples(texts, st.lists(children, min_size=1, max_size=4)).map(
        lambda pair: Struct(pair[0], pair[1]))
    return st.one_of(lists, partial, compounds)


terms = st.recursive(scalars, extend, max_leaves=20)


# 300 examples (600 took 6 s, all of it drawing the terms): the encoding is also round-tripped
# by test_terms_survive_the_database, tests/test_messages.py and tests/test_subscriptions.py
@settings(max_examples=300, deadline=None)
@given(terms)
def test_encode_decode_are_inverse(term):
    value = encode(term)
    assert type(value) in (str, int, float)
    assert same_term(decode(value), term)


@settings(max_examples=100, deadline=None)
@given(st.lists(terms, min_size=1, max_size=3))
def test_terms_survive_the_database(tmp_path_factory, args):
    path = tmp_path_factory.mktemp("rt") / "rt.db"
    with EventStore(path, StepClock()) as store:
        store.add_event("v", args, 1.0, 2.0)
    with EventStore(path, StepClock()) as store:
        ((stored, start, end, seq),) = list(store.scan("v", len(args), {}))
    assert (start, end, seq) == (1.0, 2.0, 1)
    assert all(same_term(a, b) for a, b in zip(stored, args))


def test_encoding_is_readable():
    assert encode(Atom("cup1")) == "cup1"
    assert encode(42) == 42 and encode(0.5) == 0.5
    assert encode(String("hi there")) == '"hi there"'
    assert encode(make_list([0.4, 0.1, 0.9])) == "[0.4,0.1,0.9]"
    assert encode(make_list([1.0, 2])) == "[1.0,2]"  # floats keep their '.', ints do not
    assert encode(NIL) == "[]"
    assert encode(Struct("pose", (make_list([1.0, 2.0]), Atom("w")))) == '{"pose":[[1.0,2.0],"w"]}'
    assert encode(make_list([String("s"), Atom("a")])) == '[{"$string":"s"},"a"]'
    assert encode(Atom("[x")) == '{"$atom":"[x"}'
    assert encode(2 ** 64) == '{"$int":"18446744073709551616"}'
    assert encode_json(math.inf) == "1e999"
    assert encode(Struct("$string", (Atom("x"),))) == '{"$string":["x"]}'
    assert same_term(decode('{"$string":["x"]}'), Struct("$string", (Atom("x"),)))


def test_plain_python_values_are_encoded_as_terms():
    assert encode("cup1") == "cup1"
    assert encode([1, "a"]) == '[1,"a"]'
    assert same_term(decode(encode(["a", [1.5]])), make_list([Atom("a"), make_list([1.5])]))


def test_bound_variables_are_followed_and_unbound_ones_rejected():
    bound = Var("X")
    bound.ref = Atom("a")
    assert encode(make_list([bound])) == '["a"]'
    with pytest.raises(ValueError, match="Y is unbound"):
        encode(make_list([Var("Y")]))
    with pytest.raises(ValueError, match="partial list"):
        encode(make_list([1], Var("T")))
    with pytest.raises(ValueError, match="NaN"):
        encode(make_list([math.nan]))


# ---------------------------------------------------------------- persistence

def rows_of(store, name, arity):
    return [(tuple(args), s, e, q) for args, s, e, q in store.scan(name, arity, {})]


def test_every_value_kind_round_trips(store):
    values = [Atom("cup1"), String("a string"), 7, -2 ** 63, 2 ** 80, 0.25, -0.0, math.inf,
              NIL, make_list([0.4, 0.1, 0.9]), make_list([Atom("a"), make_list([1, 2])]),
              Struct("pose", (make_list([1.0, 2.0, 3.0]), make_list([0.0, 0.0, 0.0, 1.0]))),
              make_list([1], Atom("tail")), Atom("[x"), Atom("'"), String('"q"')]
    store.add_events([("v", (value,), float(i), float(i)) for i, value in enumerate(values)])
    stored = [args[0] for args, *_ in store.scan("v", 1, {})]
    assert len(stored) == len(values)
    for got, want in zip(stored, values):
        assert same_term(got, want), (got, want)


def test_close_and_reopen_gives_identical_rows(tmp_path):
    path = tmp_path / "robot.db"
    clock = StepClock(50.0)
    with EventStore(path, clock) as store:
        store.add_events([("seg", (Atom(f"o{i}"), make_list([i, i / 2])), i, i + 0.5)
                          for i in range(100)])
        store.add_event("obj", ("cup1", "cup", "red"), 2.0, 2.0)
        store.append_program("color(O,C)^T :- prev(obj(O,_,C)^Z, T).", "color.slr")
        store.meta_set("delay/seg/2", 0.25)
        before = rows_of(store, "seg", 2), rows_of(store, "obj", 3)
        types = store.event_types()
    with EventStore(path, clock) as store:
        assert (rows_of(store, "seg", 2), rows_of(store, "obj", 3)) == before
        assert store.event_types() == types
        assert store.program_sources() == [("color(O,C)^T :- prev(obj(O,_,C)^Z, T).",
                                            "color.slr")]
        assert store.meta_get("delay/seg/2") == 0.25


def test_tables_are_readable_with_plain_sqlite(tmp_path):
    path = tmp_path / "robot.db"
    with EventStore(path, StepClock(9.0)) as store:
        store.add_event("seg", ("cup1", [0.4, 0.1, 0.9]), 2.0, 2.0)
        store.add_event("obj", ("cup1", String("red cup"), 3), 1, 2)
    conn = sqlite3.connect(path)
    cursor = conn.execute("SELECT * FROM seg")
    assert [d[0] for d in cursor.description] == ["seq", "arg1", "arg2", "t_start", "t_end",
                                                  "arrival", "robot"]
    assert cursor.fetchall() == [(1, "cup1", "[0.4,0.1,0.9]", 2.0, 2.0, 9.0, None)]
    assert conn.execute("SELECT arg1, arg2, arg3, t_start, t_end FROM obj").fetchall() == [
        ("cup1", '"red cup"', 3, 1.0, 2.0)]
    assert conn.execute("SELECT json_extract(arg2, '$[2]') FROM seg").fetchone() == (0.9,)
    assert conn.execute("SELECT name, arity, table_name, declared FROM slr_event_types "
                        "ORDER BY name").fetchall() == [("obj", 3, "obj", 0), ("seg", 2, "seg", 0)]
    conn.close()


def test_file_pragmas(file_store):
    assert file_store.sql("PRAGMA journal_mode")[1] == [("wal",)]
    assert file_store.sql("PRAGMA synchronous")[1] == [(2,)]  # FULL
    assert file_store.sql("PRAGMA auto_vacuum")[1] == [(2,)]  # INCREMENTAL
    assert file_store.sql("PRAGMA foreign_keys")[1] == [(1,)]


def test_migrations_are_applied_once_and_recorded(tmp_path):
    path = tmp_path / "robot.db"
    latest = migration_scripts()[-1][0]
    with EventStore(path, StepClock()) as store:
        assert store.schema_version() == latest
        store.append_program("p.", None)
    with EventStore(path, StepClock()) as store:  # reopening must not re-run 0001 (it would fail)
        assert store.schema_version() == latest
        assert store.program_sources() == [("p.", None)]
    conn = sqlite3.connect(path)
    assert conn.execute("PRAGMA user_version").fetchone() == (latest,)
    conn.execute(f"PRAGMA user_version = {latest + 1}")
    conn.close()
    with pytest.raises(Exception, match="newer"):
        EventStore(path, StepClock())


def test_split_sql_script_keeps_trigger_bodies_whole():
    script = """
    -- comment; with a semicolon
    CREATE TABLE a(x TEXT DEFAULT ';');
    CREATE TRIGGER t AFTER INSERT ON a BEGIN DELETE FROM a WHERE x = 'y;'; SELECT 1; END;
    INSERT INTO a VALUES ('z')
    """
    statements = split_sql_script(script)
    assert len(statements) == 3
    assert statements[1].startswith("CREATE TRIGGER") and statements[1].endswith("END;")
    store = EventStore(None)
    store.executescript(script)
    assert store.execute("SELECT x FROM a") == [("z",)]


# ---------------------------------------------------------------- validation

@pytest.mark.parametrize("event, message", [
    (("seg", (Var("X"), 1), 2.0, 2.0), "^2.0: event arguments must be ground (X is unbound)"),
    (("seg", (Atom("a"), make_list([1.0, math.nan])), 2.0, 2.0), "must not contain NaN"),
    (("seg", (Atom("a"), 1), math.nan, 2.0), "event times must be finite"),
    (("seg", (Atom("a"), 1), 1.0, math.inf), "event times must be finite"),
    (("seg", (Atom("a"), 1), 3.0, 2.0), "^[3.0,2.0]: start time 3.0 is after end time 2.0"),
    (("seg", (Atom("a"), 1), "now", 2.0), "event times must be numbers"),
    (("seg", (Atom("a"), make_list([1], Var("T"))), 2.0, 2.0), "must be ground"),
    ((42, (1,), 1.0, 1.0), "event name must be an atom"),
    ((["seg"], (1,), 1.0, 1.0), "event name must be an atom"),
])
def test_invalid_events_are_rejected_with_a_message(store, event, message):
    with pytest.raises(EventRejected) as raised:
        store.add_event(*event)
    assert message in str(raised.value)
    if event[0] == "seg":  # the message starts with the event, as SLR text
        assert str(raised.value).startswith("seg(")
    errors = store.add_events([event])
    assert len(errors) == 1 and message in str(errors[0])
    assert errors[0].index == 0 and errors[0].event == event
    assert store.count("seg", 2) == 0


def test_malformed_events_are_rejected(store):
    with pytest.raises(EventRejected, match="must be a list or tuple, not int 5"):
        store.add_event("seg", 5, 1.0, 1.0)
    errors = store.add_events([("seg", 5, 1.0, 1.0), ("seg", (1,)), ("p", (1,), 1, 1)])
    assert [e.index for e in errors] == [0, 1]
    assert "must be a list or tuple" in str(errors[0])
    assert "is not a (name, args, start, end) tuple" in str(errors[1])
    assert store.count("p", 1) == 1


def test_one_bad_event_does_not_lose_the_batch(store):
    events = [("p", (1,), 1.0, 1.0), ("p", (Var("X"),), 2.0, 2.0), ("p", (3,), 3.0, 3.0),
              ("q", (), 4.0, 4.0)]
    errors = store.add_events(events)
    assert [e.index for e in errors] == [1]
    assert [args for args, *_ in store.scan("p", 1)] == [(1,), (3,)]
    assert store.count("q", 0) == 1


def test_atomic_batch_stores_nothing(store):
    events = [("p", (1,), 1.0, 1.0), ("newtype", (2,), 2.0, 2.0), ("p", (3,), 3.0, 2.0)]
    with pytest.raises(EventRejected, match="after end time"):
        store.add_events(events, atomic=True)
    assert store.count("p", 1) == 0
    assert store.table_for("newtype", 1) is None  # the table made inside was rolled back too
    assert store.add_events([("newtype", (2,), 2.0, 2.0)]) == []
    assert store.count("newtype", 1) == 1


def test_integer_times_are_stored_as_floats(store):
    store.add_event("p", (1,), 1, 2)
    ((args, start, end, _),) = list(store.scan("p", 1))
    assert (start, end) == (1.0, 2.0) and type(start) is float


def test_declared_arity_is_enforced(store):
    store.declare_type("obj", 3)
    with pytest.raises(EventRejected, match="obj/3 is declared, obj/2 is not"):
        store.add_event("obj", ("a", "b"), 1, 1)
    store.add_event("obj", ("a", "b", "c"), 1, 1)
    store.add_event("other", ("a",), 1, 1)  # undeclared names are free
    store.add_event("other", ("a", "b"), 1, 1)
    assert store.declared_types() == {("obj", 3)}


def test_sql_metacharacters_are_stored_verbatim(store):
    nasty = ["'; DROP TABLE p; --", 'Robert"); DROP TABLE p;--', "a'b\"c", "%_*?", "\\", "`x`"]
    store.add_events([("p", (Atom(text), String(text)), 1.0, 1.0) for text in nasty])
    stored = [args for args, *_ in store.scan("p", 2)]
    assert [(str(a), str(s)) for a, s in stored] == [(t, t) for t in nasty]
    assert all(type(a) is Atom and type(s) is String for a, s in stored)
    for text in nasty:
        assert [args[0] for args, *_ in store.scan("p", 2, {0: Atom(text)})] == [text]
        assert [args[1] for args, *_ in store.scan("p", 2, {1: String(text)})] == [text]


def test_event_names_become_safe_unique_table_names(store):
    for name, arity in [("seg", 2), ("seg", 3), ("my event", 1), ("select", 0), ("slr_meta", 1),
                        ("Seg", 2), ('we"ird', 1), ("9lives", 1), ("", 0)]:
        store.add_event(name, tuple(range(arity)), 1.0, 1.0)
    tables = store.event_types()
    assert tables[("seg", 2)] == "seg"
    assert tables[("seg", 3)] == "seg__3"
    assert tables[("my event", 1)] == "ev_my_event"
    assert tables[("select", 0)] == "ev_select"
    assert tables[("slr_meta", 1)] == "ev_slr_meta"
    assert tables[("Seg", 2)] == "Seg__2"  # SQL names are case-insensitive: seg is taken
    assert len(set(tables.values())) == len(tables)
    for (name, arity), table in tables.items():
        assert store.count(name, arity) == 1
        assert store.sql(f'SELECT count(*) FROM "{table}"')[1] == [(1,)]


# ---------------------------------------------------------------- order and lookups

def test_store_order_is_end_then_start_then_arrival(store):
    store.add_events([("p", ("late",), 5.0, 5.0), ("p", ("wide",), 1.0, 3.0),
                      ("p", ("first",), 2.0, 3.0), ("p", ("second",), 2.0, 3.0),
                      ("p", ("early",), 0.0, 0.0)])
    store.add_event("p", ("third",), 2.0, 3.0)
    assert [str(args[0]) for args, *_ in store.scan("p", 1)] == [
        "early", "wide", "first", "second", "third", "late"]
    assert [str(args[0]) for args, *_ in store.scan("p", 1, end_le=3.0)] == [
        "early", "wide", "first", "second", "third"]
    assert [str(a[0]) for a, *_ in store.rows_at_end("p", 1, {}, 3.0)] == [
        "wide", "first", "second", "third"]
    assert [str(a[0]) for a, *_ in store.rows_at_end("p", 1, {}, 3.0, start_ge=1.5)] == [
        "first", "second", "third"]
    assert list(store.rows_at_end("p", 1, {}, 3.0, end_le=2.0)) == []
    assert [str(a[0]) for a, *_ in store.rows_at_start("p", 1, {}, 2.0, 10.0)] == [
        "first", "second", "third"]


def test_prev_and_next_candidates(store):
    store.add_events([("obj", (Atom(o), Atom(c)), t, t) for o, c, t in [
        ("cup1", "red", 1.0), ("cup2", "blue", 2.0), ("cup1", "green", 3.0),
        ("cup2", "red", 4.0)]])
    store.add_event("obj", ("cup1", "long"), 0.5, 3.5)
    prev = [(str(a[1]), e) for a, s, e, q in store.prev_candidates("obj", 2, {}, 3.5)]
    assert prev == [("long", 3.5), ("green", 3.0), ("blue", 2.0), ("red", 1.0)]
    assert [str(a[1]) for a, *_ in store.prev_candidates("obj", 2, {0: Atom("cup2")}, 3.9)] == [
        "blue"]
    assert [str(a[1]) for a, *_ in store.prev_candidates("obj", 2, {}, 10, start_ge=1.5)] == [
        "red", "green", "blue"]
    assert [str(a[1]) for a, *_ in store.next_candidates("obj", 2, {}, 1.5, math.inf)] == [
        "blue", "green", "red"]
    assert [str(a[1]) for a, *_ in store.next_candidates("obj", 2, {}, 0.0, 3.5)] == [
        "long", "red", "blue", "green"]
    assert [str(a[1]) for a, *_ in store.next_candidates("obj", 2, {1: Atom("red")}, 2, 5)] == [
        "red"]
    assert list(store.prev_candidates("nothing", 1, {}, 5.0)) == []
    assert store.max_end("obj", 2) == 4.0 and store.max_end("nothing", 1) is None


def test_bound_arguments_use_sql_equality(store):
    store.add_events([("p", (1, Atom("x")), 1, 1), ("p", (1.0, Atom("y")), 2, 2),
                      ("p", (Atom("1"), Atom("z")), 3, 3), ("p", (String("1"), Atom("w")), 4, 4)])
    # SQL equality: 1 = 1.0, but neither equals the atom '1' or the string "1";
    # the caller unifies the candidates and drops 1.0 when it asked for 1.
    assert [str(a[1]) for a, *_ in store.scan("p", 2, {0: 1})] == ["x", "y"]
    assert [str(a[1]) for a, *_ in store.scan("p", 2, {0: Atom("1")})] == ["z"]
    assert [str(a[1]) for a, *_ in store.scan("p", 2, {0: String("1")})] == ["w"]
    assert [str(a[1]) for a, *_ in store.scan("p", 2, {0: Var("X")})] == ["x", "y", "z", "w"]


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from("abc"), st.integers(0, 6), st.integers(0, 3)),
                max_size=25),
       st.integers(0, 10), st.integers(0, 10), st.sampled_from([None, "a", "b"]))
def test_lookups_agree_with_brute_force(events, t1, t2, key):
    store = EventStore(None, StepClock())
    store.add_events([("p", (Atom(k),), float(s), float(s + d)) for k, s, d in events])
    rows = [((Atom(k),), float(s), float(s + d), i + 1) for i, (k, s, d) in enumerate(events)]
    if key is not None:
        rows = [r for r in rows if r[0][0] == key]
    bound = {} if key is None else {0: Atom(key)}
    in_order = sorted(rows, key=lambda r: (r[2], r[1], r[3]))
    assert list(store.scan("p", 1, bound)) == in_order
    assert list(store.scan("p", 1, bound, end_le=t1)) == [r for r in in_order if r[2] <= t1]
    assert list(store.prev_candidates("p", 1, bound, t1)) == [
        r for r in reversed(in_order) if r[2] <= t1]
    assert list(store.prev_candidates("p", 1, bound, t2, start_ge=t1)) == [
        r for r in reversed(in_order) if r[2] <= t2 and r[1] >= t1]
    by_start = sorted(rows, key=lambda r: (r[1], r[2], r[3]))
    assert list(store.next_candidates("p", 1, bound, t1, t2)) == [
        r for r in by_start if r[1] >= t1 and r[2] <= t2]
    assert list(store.rows_at_end("p", 1, bound, t1)) == [r for r in in_order if r[2] == t1]
    assert list(store.rows_at_start("p", 1, bound, t1, t2)) == [
        r for r in in_order if r[1] == t1 and r[2] <= t2]
    store.close()


@pytest.mark.parametrize("kind, bound, options", [
    ("scan", {}, {}), ("scan", {}, {"end_le": True}), ("scan", {0: Atom("a")}, {"end_le": True}),
    ("scan", {1: 1}, {}), ("scan", {0: Atom("a"), 1: 1}, {"end_le": True}),
    ("prev", {}, {}), ("prev", {0: Atom("a")}, {}), ("prev", {1: 1}, {"start_ge": True}),
    ("prev", {0: Atom("a")}, {"start_ge": True}),
    ("at_end", {}, {}), ("at_end", {0: Atom("a")}, {"start_ge": True, "end_le": True}),
    ("next", {}, {}), ("next", {0: Atom("a")}, {}), ("next", {1: 1}, {}),
    ("at_start", {}, {}), ("at_start", {0: Atom("a")}, {}),
])
def test_lookups_stream_from_an_index(file_store, kind, bound, options):
    file_store.add_events([("p", (Atom(f"o{i % 7}"), i), i, i + 1) for i in range(500)])
    file_store.execute("ANALYZE")  # statistics must not talk the planner into a sort
    sql = file_store.lookup_sql(kind, "p", 2, bound, **options)
    plan = " | ".join(file_store.query_plan(sql))
    assert "TEMP B-TREE" not in plan, plan
    assert "USING INDEX" in plan, plan
    if 0 in bound:
        assert "arg1=?" in plan, plan


# ---------------------------------------------------------------- program, meta, raw SQL

def test_program_and_meta(store):
    assert store.program_sources() == []
    store.append_program("a(1).", "a.slr")
    store.append_program("b(2).", None)
    assert store.program_sources() == [("a(1).", "a.slr"), ("b(2).", None)]
    store.replace_program([("c(3).", "c.slr")])
    assert store.program_sources() == [("c(3).", "c.slr")]
    assert store.meta_get("missing", "dflt") == "dflt"
    store.meta_set("delay/seg/2", {"max": 0.5, "learn": True})
    store.meta_set("delay/seg/2", {"max": 0.75, "learn": True})
    assert store.meta_get("delay/seg/2") == {"max": 0.75, "learn": True}
    assert store.meta_items("delay/") == {"delay/seg/2": {"max": 0.75, "learn": True}}
    store.meta_delete("delay/seg/2")
    assert store.meta_get("delay/seg/2") is None


def test_transaction_makes_several_calls_atomic(store):
    with pytest.raises(RuntimeError):
        with store.transaction():
            store.append_program("a.", None)
            store.declare_type("seg", 2)
            store.add_event("seg", ("x", 1), 1, 1)
            raise RuntimeError("parse error in the middle of a load")
    assert store.program_sources() == [] and store.event_types() == {}
    assert store.table_for("seg", 2) is None
    with store.transaction():
        store.append_program("a.", None)
        with pytest.raises(EventRejected):
            with store.transaction():  # nested: a savepoint
                store.add_event("seg", ("x", 1), 1, 1)
                store.add_event("seg", (Var("X"), 1), 1, 1)
        store.add_event("seg", ("y", 1), 1, 1)
    assert [args[0] for args, *_ in store.scan("seg", 2)] == ["y"]
    assert store.program_sources() == [("a.", None)]


def test_sql_returns_columns_and_rows(store):
    store.add_event("seg", ("cup1", 1), 1.0, 2.0)
    assert store.sql("SELECT arg1, arg2, t_end FROM seg WHERE arg1 = ?", ["cup1"]) == (
        ["arg1", "arg2", "t_end"], [("cup1", 1, 2.0)])


def test_arrival_comes_from_the_clock(store):
    store.clock.value = 7.5
    store.add_event("p", (1,), 1, 1)
    store.clock.value = 8.5
    store.add_events([("p", (2,), 1, 1), ("p", (3,), 1, 1)])
    assert store.execute('SELECT arrival FROM "p" ORDER BY seq') == [(7.5,), (8.5,), (8.5,)]


def test_many_threads_add_and_read(file_store):
    def producer(k):
        for i in range(50):
            file_store.add_events([("p", (k, i), float(i), float(i))])
            list(file_store.prev_candidates("p", 2, {0: k}, float(i)))

    threads = [threading.Thread(target=producer, args=(k,)) for k in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert file_store.count("p", 2) == 300
    for k in range(6):
        assert [a[1] for a, *_ in file_store.scan("p", 2, {0: k})] == list(range(50))


def test_unfinished_iterators_do_not_block_writes(file_store):
    file_store.add_events([("p", (i,), i, i) for i in range(100)])
    pending = file_store.scan("p", 1)
    next(pending)  # a statement left open mid-way
    file_store.add_event("p", (1000,), 1000, 1000)
    file_store.meta_set("k", 1)
    pending.close()
    assert file_store.count("p", 1) == 101


def test_closed_store_refuses_work(tmp_path):
    store = EventStore(tmp_path / "x.db")
    store.add_events([("p", (i,), i, i) for i in range(20)])
    pending = store.scan("p", 1)
    next(pending)
    store.close()
    pending.close()  # an iterator left open does not complain after close
    with pytest.raises(Exception, match="closed"):
        store.add_event("p", (1,), 1, 1)


@pytest.mark.parametrize("robot", [None, "r1"])
@pytest.mark.parametrize("path", ["uniform", "each"])
def test_added_rows_carry_the_store_robot_and_the_batch_its_end_times(tmp_path, robot, path):
    # an unnamed store leaves robot to the column's NULL (not bound per row), a named one
    # binds its name; both on the columnar fast path and the event-by-event path, whose rows
    # then differ in width (the batch's end times are read from them)
    store = EventStore(tmp_path / "r.db", robot=robot)
    events = [("seg", ("a", 1), 1.0, 2.0), ("seg", ("b", 2), 0.5, 7.0)]
    if path == "each":  # a second type with integer times: the event-by-event path
        events.append(("other", (3,), 4, 4))
    batch = EventBatch(events)
    assert store.add_events(batch) == []
    table = store.declare_type("seg", 2)
    rows = store.execute(f'SELECT arg1, t_end, robot FROM "{table}" ORDER BY seq')
    assert rows == [(encode(Atom("a")), 2.0, robot), (encode(Atom("b")), 7.0, robot)]
    assert batch.ends[("seg", 2)] == (2.0, 7.0)
    if path == "each":
        assert batch.ends[("other", 1)] == (4.0, 4.0)
    store.close()


@pytest.mark.parametrize("order", [
    ["p(1,2)^1", "p(1)^2", "p(3)^3", "p(4,5)^4"],
    ["p(1)^1", "p(1,2)^2", "p(3,4)^3", "p(5)^4"],
])
def test_one_name_with_two_arities_in_one_batch(tmp_path, order):
    """p/1 and p/2 are two types: a batch that switches between them stores each event in
    its own type's table, in either order."""
    import slr_sql

    with slr_sql.open(tmp_path / "t.db", clock=slr_sql.ManualClock(10.0)) as kb:
        assert kb.add_many(order) == []
        ones = sorted(str(e) for e in order if "," not in e)
        twos = sorted(str(e) for e in order if "," in e)
        assert [f"p({r['X']})^{int(r['T'])}" for r in kb.query("p(X)^T")] == ones
        assert [f"p({r['X']},{r['Y']})^{int(r['T'])}" for r in kb.query("p(X, Y)^T")] == twos


def test_a_lookup_read_across_a_rolled_back_add_loses_no_row(tmp_path):
    """A scan that has handed out its first rows goes on where it was after an atomic add
    on the same store failed and rolled back the table of a new type (SQLite aborts the open
    read when a rollback undoes a schema change)."""
    import slr_sql

    with slr_sql.open(tmp_path / "t.db", clock=slr_sql.ManualClock(1000.0)) as kb:
        assert kb.add_many([f"p({i})^{i}" for i in range(300)]) == []
        rows = kb.store.scan("p", 1)
        first = [next(rows) for _ in range(5)]
        with pytest.raises(EventRejected):
            kb.add_many(["p(1000)^1000", "fresh(1)^1", "p(x)^nan"], atomic=True)
        seen = first + list(rows)
        assert [args[0] for args, *_ in seen] == list(range(300))
        assert kb.query("findall(X, (p(X)^_, X >= 1000), L)") == [{"L": []}]
        assert kb.store.table_for("fresh", 1) is None


def test_rows_into_a_large_table_go_in_one_statement_execution_per_row(file_store):
    store = file_store
    """Once a table holds more than ~65,536 rows an add binds the one-row INSERT per row
    (cheaper per row there than multi-row VALUES), a small table still gets multi-row
    INSERTs; the same rows stored, the same rejections, nothing stored by a refused atomic
    add, on either path."""
    store.add_events([("p", (i,), float(i), float(i)) for i in range(70_000)])
    statements: list[str] = []
    store._db.conn.set_trace_callback(statements.append)
    try:
        clean = store.add_events([("p", ("a",), 1e5, 1e5), ("p", ("b",), 1e5, 1e5)])
        errors = store.add_events([("p", ("c",), 2e5, 2e5), ("p", (Var("X"),), 2e5, 2e5),
                                   ("p", ("d",), 3e5, 3e5)])
        with pytest.raises(EventRejected, match="after end time"):
            store.add_events([("p", ("e",), 4e5, 4e5), ("p", ("f",), 5e5, 4e5)], atomic=True)
        small = store.add_events([("q", (1,), 1.0, 1.0), ("q", (2,), 1.0, 1.0)])
    finally:
        store._db.conn.set_trace_callback(None)
    assert clean == [] and [e.index for e in errors] == [1] and small == []
    into_p = [s for s in statements if s.startswith('INSERT INTO "p"')]
    assert len(into_p) == 4 and not any("),(" in s for s in into_p)
    into_q = [s for s in statements if s.startswith('INSERT INTO "q"')]
    assert len(into_q) == 1 and "),(" in into_q[0]
    assert store.count("p", 1) == 70_004
    assert [args for args, *_ in store.scan("p", 1, end_le=1e6)][-4:] == [
        (Atom("a"),), (Atom("b"),), (Atom("c"),), (Atom("d"),)]
    assert [(args, s) for args, s, *_ in store.scan("q", 1)] == [((1,), 1.0), ((2,), 1.0)]
