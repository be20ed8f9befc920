"""Event-history management: tBuffer / cBuffer declarations, runtime history
policies, conflict detection, persistence, counters, and a model-based property test.

No sleeps: every test drives time with a ManualClock.
"""
from __future__ import annotations

import sqlite3
from collections import Counter

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql import ManualClock, SLRError, String, Struct
from slr_sql.encoding import encode
from slr_sql.engine import copy_term, unify
from slr_sql.parser import parse_term
from slr_sql.terms import format_term
from slr_sql.terms import deref, from_python

PAPER_BUFFERS = """
tBuffer(face(P), 60s).
tBuffer(tf(S, D, TF), 300s).
cBuffer(inView(face(P, _)), 1).
cBuffer(inView(obj(O, _)), 1).
"""


def kb_at(t: float = 0.0, path=None):
    return slr_sql.open(path, clock=ManualClock(t))


@pytest.fixture
def open_kb(backend):
    """``open_kb(t)``: the test's store (a SQLite file, or a fresh PostgreSQL database) with a
    ManualClock at ``t``; the same place each time (a reopen), closed after the test."""
    opened = []

    def open_at(t: float = 0.0):
        kb = slr_sql.open(backend, clock=ManualClock(t))
        opened.append(kb)
        return kb
    yield open_at
    for kb in opened:
        kb.close()


def add_buffers(kb, buffers) -> None:
    """Install ``(kind, pattern text, amount)`` buffers through ``kb.add_buffer``."""
    for kind, text, amount in buffers:
        if kind == "tBuffer":
            kb.add_buffer(text, keep_seconds=amount)
        elif kind == "cBuffer":
            kb.add_buffer(text, keep_last=amount)
        else:
            kb.add_buffer(text, keep_between=tuple(amount))


def buffer_triggers(kb) -> set:
    return {name for name in kb.store.triggers() if name.startswith("slr_buf_")}


def rows(kb, table: str) -> list[tuple]:
    return kb.sql(f'SELECT * FROM "{table}" ORDER BY t_end, t_start, seq')[1]


def txt(value) -> str:
    return format_term(from_python(value))


def by_pattern(kb) -> dict:
    return {b.pattern: b for b in kb.buffers()}


# ----------------------------------------------------------------------------- paper

def test_paper_tbuffer_face_60s(open_kb):
    kb = open_kb(0)
    kb.load(PAPER_BUFFERS, "paper.slr")
    kb.add_many(["face(bob)^1", "face(ann)^30", "face(carl)^59"])
    kb.clock.set(61.5)  # bob ended at 1: 1 < 61.5 - 60, expired; ann and carl stay
    assert [a["P"] for a in kb.query("face(P)^T")] == ["ann", "carl"]
    kb.clock.set(90)  # 90 - 60 = 30: ann (end 30) is still kept (end >= now - D)
    assert [a["P"] for a in kb.query("face(P)^T")] == ["ann", "carl"]
    kb.clock.advance(0.5)
    assert [a["P"] for a in kb.query("face(P)^T")] == ["carl"]
    # a late event, already older than its buffer keeps on arrival, is dropped and counted
    kb.add("face(dave)^10")
    assert [a["P"] for a in kb.query("face(P)^T")] == ["carl"]
    info = by_pattern(kb)["face(P)"]
    assert (info.pruned, info.dropped) == (2, 1)


def test_paper_tbuffer_tf_300s(open_kb):
    kb = open_kb(0)
    kb.load(PAPER_BUFFERS, "paper.slr")
    for t in range(0, 1000, 10):
        kb.clock.set(float(t))
        kb.add_event("tf", ["base", "cam", [t, 0.0, 1.0]], float(t))
    # at now = 990 the events with end >= 690 are kept: 690, 700, ..., 990
    ends = [r[-2] for r in rows(kb, "tf")]
    assert ends == [float(t) for t in range(690, 1000, 10)]
    assert by_pattern(kb)["tf(S,D,TF)"].pruned == 69
    assert kb.query("prev(tf(base, cam, X)^T, 995)") == [{"X": [990, 0.0, 1.0], "T": 990.0}]


def test_paper_cbuffers_findall_last_seen_per_person_and_object(open_kb):
    kb = open_kb(0)
    kb.load(PAPER_BUFFERS, "paper.slr")
    kb.add_many([
        "inView(face(neda, kitchen))^1", "inView(obj(cup1, table))^2",
        "inView(face(mehdi, hall))^3", "inView(face(neda, hall))^4",
        "inView(obj(cup1, sink))^5", "inView(obj(book, shelf))^6",
        "inView(face(mehdi, office))^7",
        "inView(face(neda, garden))^3.5",  # late: neda was seen later (at 4): dropped
    ])
    answers = kb.query("findAll(Item, inView(Item)^[T1, T2], List)")
    assert len(answers) == 1
    assert [str(item) for item in answers[0]["List"]] == [
        "face(neda,hall)", "obj(cup1,sink)", "obj(book,shelf)", "face(mehdi,office)"]
    info = by_pattern(kb)
    assert info["inView(face(P,_))"].pruned == 2 and info["inView(face(P,_))"].dropped == 1
    assert info["inView(obj(O,_))"].pruned == 1


@pytest.mark.parametrize("pattern, expected", [
    # the last recognition of each distinct person
    ("face(P, _)", [("bob", "hall"), ("ann", "hall")]),
    # only the recognition of the last person
    ("face(_, _)", [("ann", "hall")]),
    # the last recognition of each distinct person in each distinct location
    ("face(P, L)", [("bob", "kitchen"), ("bob", "hall"), ("ann", "kitchen"), ("ann", "hall")]),
])
def test_paper_cbuffer_key_variants(pattern, expected, open_kb):
    kb = open_kb(0)
    kb.load(f"cBuffer(inView({pattern}), 1).", "keys.slr")
    kb.add_many(["inView(face(bob, kitchen))^1", "inView(face(ann, kitchen))^2",
                 "inView(face(bob, kitchen))^3", "inView(face(ann, kitchen))^4",
                 "inView(face(bob, hall))^5", "inView(face(ann, hall))^6"])
    got = [(a["P"], a["L"]) for a in kb.query("inView(face(P, L))^T")]
    assert sorted(got) == sorted(expected)
    # store order of what is left: by end time
    assert got == [pl for pl in [("bob", "kitchen"), ("ann", "kitchen"), ("bob", "hall"),
                                 ("ann", "hall")] if pl in expected]


def test_cbuffer_ties_keep_store_order(open_kb):
    kb = open_kb(0)
    kb.load("cBuffer(p(X, _), 2).")
    # same end: the start time breaks the tie, then arrival
    kb.add_many(["p(a, 1)^[1, 5]", "p(a, 2)^[3, 5]", "p(a, 3)^[2, 5]", "p(a, 4)^[3, 5]"])
    assert [a["V"] for a in kb.query("p(a, V)^[S, E]")] == [2, 4]
    # a full tie (same start and end): the later arrival is the more recent one
    kb.add_many(["q(a, 1)^5", "q(a, 2)^5"])
    kb.load("cBuffer(q(X, _), 1).")
    kb.add_many(["q(a, 3)^5", "q(a, 4)^5", "q(b, 5)^4", "q(b, 6)^4"])
    assert [a["V"] for a in kb.query("q(K, V)^T")] == [6, 4]


# ----------------------------------------------------------------------------- conflicts

def test_conflicting_buffers_name_both_clauses_and_do_not_load(open_kb):
    kb = open_kb(0)
    kb.load("keep(me).", "base.slr")
    program = "ok(1).\ntBuffer(face(P), 60).\nfoo(2).\ncBuffer(face(bob), 1).\n"
    with pytest.raises(SLRError) as err:
        kb.load(program, "robot.slr")
    message = str(err.value)
    assert "robot.slr:2" in message and "robot.slr:4" in message
    assert "tBuffer(face(P), 60)" in message and "cBuffer(face(bob), 1)" in message
    assert kb.buffers() == []
    assert kb.query("keep(X)") == [{"X": "me"}]
    assert [src for src, _ in kb.store.program_sources()] == ["keep(me)."]
    assert buffer_triggers(kb) == set()


def test_conflict_across_loads_and_with_runtime_buffers(open_kb):
    kb = open_kb(0)
    kb.load("cBuffer(inView(face(P, _)), 1).", "a.slr")
    with pytest.raises(SLRError, match=r"a\.slr:1.*b\.slr:2"):
        kb.load("x.\ncBuffer(inView(face(_, _)), 1).", "b.slr")
    # non-unifiable patterns are fine: different functor, arity or constant
    kb.load("cBuffer(inView(obj(O, _)), 1).\ntBuffer(inView(face(P)), 5).", "c.slr")
    with pytest.raises(SLRError, match="a.slr:1"):
        kb.add_buffer("inView(face(ann, L))", keep_last=3)
    bid = kb.add_buffer("seen(X)", keep_seconds=10)
    with pytest.raises(SLRError, match=f"runtime buffer #{bid}"):
        kb.load("tBuffer(seen(bob), 1).", "d.slr")
    # repeated variables: p(X, X) and p(a, b) do not unify
    kb.load("cBuffer(p(X, X), 1).\ncBuffer(p(a, b), 1).", "e.slr")
    assert len(kb.buffers()) == 6


# ----------------------------------------------------------------------------- runtime policies

def test_runtime_policies_keep_last_seconds_between(open_kb):
    kb = open_kb(0)
    last = kb.add_buffer("pos(O, _)", keep_last=2)
    recent = kb.add_buffer("speech(_)", keep_seconds=5)
    window = kb.add_buffer("door(_)", keep_between=(10, 20))
    for t in range(30):
        kb.clock.set(float(t))
        kb.add_many([("pos", ["cup", t], float(t), float(t)), ("pos", ["box", t], t, t),
                     ("speech", [String(f"w{t}")], float(t), float(t)),
                     ("door", ["open"], float(t), float(t) + 0.5)])
    assert [(a["O"], a["X"]) for a in kb.query("pos(O, X)^T")] == [
        ("cup", 28), ("box", 28), ("cup", 29), ("box", 29)]
    assert [a["W"] for a in kb.query("speech(W)^T")] == ["w24", "w25", "w26", "w27", "w28", "w29"]
    assert [a["T1"] for a in kb.query("door(_)^[T1, T2]")] == [float(t) for t in range(10, 20)]
    infos = {b.id: b for b in kb.buffers()}
    assert infos[last].kind == "cBuffer" and infos[last].amount == 2 and infos[last].pruned == 56
    assert infos[recent].kind == "tBuffer" and infos[recent].pruned == 24
    assert infos[window].kind == "window" and infos[window].keep_between == (10.0, 20.0)
    assert infos[window].dropped == 20
    kb.remove_buffer(recent)
    assert recent not in {b.id for b in kb.buffers()}
    kb.clock.set(100)
    kb.add("speech(\"late\")^1")  # no buffer any more: kept
    assert len(kb.query("speech(W)^T")) == 7
    with pytest.raises(SLRError):
        kb.remove_buffer(recent)


def test_runtime_policy_arguments_are_checked():
    kb = kb_at(0)
    with pytest.raises(SLRError, match="exactly one"):
        kb.add_buffer("p(X)")
    with pytest.raises(SLRError, match="exactly one"):
        kb.add_buffer("p(X)", keep_last=1, keep_seconds=2)
    with pytest.raises(SLRError, match="keep_last"):
        kb.add_buffer("p(X)", keep_last=-1)
    with pytest.raises(SLRError, match="T1"):
        kb.add_buffer("p(X)", keep_between=(5, 1))
    kb.load("tBuffer(q(X), 1).", "q.slr")
    with pytest.raises(SLRError, match="q.slr:1"):
        kb.remove_buffer(kb.buffers()[0].id)
    assert kb.add_buffer("r(_)", keep_seconds="2min") > 0
    assert [b.amount for b in kb.buffers() if b.pattern == "r(_)"] == [120.0]


def test_adding_a_buffer_prunes_the_history_already_stored(open_kb):
    kb = open_kb(0)
    kb.add_many([f"p(a, {i})^{i}" for i in range(10)] + [f"p(b, {i})^{i}" for i in range(5)])
    kb.clock.set(20)
    kb.add_buffer("p(K, _)", keep_last=3)
    assert [(a["K"], a["V"]) for a in kb.query("p(K, V)^T")] == [
        ("b", 2), ("b", 3), ("b", 4), ("a", 7), ("a", 8), ("a", 9)]
    kb.load("tBuffer(q(_), 10).")
    kb.add_many([f"q({i})^{i}" for i in range(20)])  # arrive at now = 20: 0..9 are late
    assert [a["V"] for a in kb.query("q(V)^T")] == list(range(10, 20))
    assert by_pattern(kb)["q(_)"].dropped == 10


# ----------------------------------------------------------------------------- patterns

def test_nested_constants_keys_and_shapes(open_kb):
    kb = open_kb(0)
    kb.load("""
        cBuffer(obs(f(a, K), "str", [1, _]), 1).
        cBuffer(obs(g(X), _, _), 2).
    """)
    kb.add_many([
        'obs(f(a, 1), "str", [1, x])^1', 'obs(f(a, 1), "str", [1, y])^2',   # key K=1
        'obs(f(a, 1.0), "str", [1, z])^3',                                   # K=1.0 differs
        'obs(g(1), "str", [1, x])^4', 'obs(g(1), a, b)^5',                   # second buffer
        'obs(g(1), c, d)^6',
        'obs(f(a, 1), str, [1, q])^7',                                       # atom, not string
        'obs(f(a, 1), str, [1, q])^8',
        'obs(f(a, 1), "str", [1, 2, 3])^9',                                  # list too long
        'obs(f(a, 1), "str", [1, 2, 3])^10',
        'obs(f(a, 2), "str", [1, 2])^11',                                    # key K=2
    ])
    got = [(txt(a["X"]), txt(a["Y"]), txt(a["Z"]), a["T"]) for a in kb.query("obs(X, Y, Z)^T")]
    assert got == [("f(a,1)", "str", "[1,y]", 2.0), ("f(a,1.0)", "str", "[1,z]", 3.0),
                   ("g(1)", "a", "b", 5.0), ("g(1)", "c", "d", 6.0),
                   ("f(a,1)", "str", "[1,q]", 7.0), ("f(a,1)", "str", "[1,q]", 8.0),
                   ("f(a,1)", "str", "[1,2,3]", 9.0), ("f(a,1)", "str", "[1,2,3]", 10.0),
                   ("f(a,2)", "str", "[1,2]", 11.0)]


def test_buffer_declared_before_its_type_exists_and_quoted_constants(open_kb):
    kb = open_kb(0)
    kb.load("cBuffer(say('it''s', X), 1).")
    assert kb.store.table_for("say", 2) is None
    kb.add_many(["say('it''s', a)^1", "say('it''s', a)^2", "say(other, a)^3",
                 "say(other, a)^4"])
    assert [(a["W"], a["T"]) for a in kb.query("say(W, _)^T")] == [
        ("it's", 2.0), ("other", 3.0), ("other", 4.0)]


def test_the_two_float_zeros_are_one_count_buffer_key_on_both_backends(open_kb):
    # SQLite's triggers compare keys with SQL's `=`, which takes one zero for the other and
    # shows no sign; PostgreSQL's compared the column texts ('0.0', '-0.0') and kept one
    # event of each. Both backends keep one for both now (docs/buffers.md): as a whole
    # argument, inside a compound or a list, a constant of the pattern, a repeated
    # variable, and a buffer applied to the rows already stored.
    kb = open_kb(0)
    kb.load("cBuffer(p(K, _), 1). cBuffer(q(f(K), _), 1). cBuffer(s(0.0, _), 1). "
            "cBuffer(t(X, X, _), 1). cBuffer(u([K], _), 1).")
    kb.add_many(["p(0.0, a)^1", "p(-0.0, b)^2", "q(f(-0.0), a)^1", "q(f(0.0), b)^2",
                 "s(-0.0, a)^1", "s(-0.0, b)^2", "t(0.0, -0.0, a)^1", "t(0.0, 0.0, b)^2",
                 "u([0.0], a)^1", "u([-0.0], b)^2", "r(0.0, a)^1", "r(-0.0, b)^2",
                 "w(f(0.0), a)^1", "w(f(-0.0), b)^2", "p(1.0, c)^3", "p(0, d)^4"])
    kb.add_buffer("r(K, _)", keep_last=1)
    kb.add_buffer("w(f(K), _)", keep_last=1)
    kept = {name: [(format_term(from_python(a["K"])), str(a["V"])) for a in
                   kb.query(f"{name}(K, V)^_" if name != "t" else "t(K, _, V)^_")]
            for name in "pqstuwr"}
    assert kept == {"p": [("-0.0", "b"), ("1.0", "c"), ("0", "d")], "q": [("f(0.0)", "b")],
                    "s": [("-0.0", "b")], "t": [("0.0", "b")], "u": [("[-0.0]", "b")],
                    "w": [("f(-0.0)", "b")], "r": [("-0.0", "b")]}
    # the zeros' own values are kept: a zero's key finds the other, never a non-zero
    kb.add_many(["p(0.0, e)^5", "p(1.0, f)^6"])
    assert [(format_term(from_python(a["K"])), str(a["V"])) for a in kb.query("p(K, V)^_")] \
        == [("0", "d"), ("0.0", "e"), ("1.0", "f")]


@pytest.mark.parametrize("text", ["50%", "a?b", ":name", "$slr$", "x\\y", "é ✓", "1", "[x"])
def test_constants_that_mean_something_to_sql_are_only_constants(open_kb, text):
    kb = open_kb(0)
    escaped = text.replace("\\", "\\\\")
    atom, string = f"'{escaped}'", f'"{escaped}"'
    kb.add_many([f"say({atom}, f({atom}))^1", f"say({atom}, f({atom}))^2",
                 "say(other, f(other))^3", "say(other, f(other))^4"])
    kb.add_buffer(f"say({atom}, f({atom}))", keep_last=1)   # applied to the stored rows
    kb.load(f"cBuffer(said(_, f(_), {string}), 1).")        # a string inside JSON
    kb.add_many([f"say({atom}, f({atom}))^5", f"said(x, f(x), {string})^6",
                 f"said(y, f(y), {string})^7", f"said(z, f(z), {atom})^8"])
    assert [(a["T"], a["W"] == text) for a in kb.query("say(W, _)^T")] == [
        (3.0, False), (4.0, False), (5.0, True)]
    assert [a["T"] for a in kb.query("said(_, _, _)^T")] == [7.0, 8.0]


def test_pattern_with_time_stamp_and_repeated_variables(open_kb):
    kb = open_kb(0)
    kb.load("cBuffer(pair(X, X)^T, 1).")
    kb.add_many(["pair(a, a)^1", "pair(a, a)^2", "pair(a, b)^3", "pair(a, b)^4",
                 "pair(1, 1.0)^5", "pair(1, 1.0)^6"])
    assert [(str(a["X"]), str(a["Y"])) for a in kb.query("pair(X, Y)^T")] == [
        ("a", "a"), ("a", "b"), ("a", "b"), ("1", "1.0"), ("1", "1.0")]


def test_unsupported_patterns_are_errors_naming_the_clause(open_kb):
    kb = open_kb(0)
    with pytest.raises(SLRError, match="bad.slr:2"):
        kb.load("ok.\ncBuffer(p([H|T]), 1).", "bad.slr")
    with pytest.raises(SLRError):
        kb.load("tBuffer(p(X)^3, 1).", "bad2.slr")
    assert kb.buffers() == []


# ----------------------------------------------------------------------------- persistence

def insert_as_another_tool(where: str, statements: list[str]) -> None:
    """Rows written by another program through the database's own driver (no slr_sql)."""
    if where.startswith("postgresql://"):
        import psycopg

        with psycopg.connect(where, autocommit=True) as conn:
            conn.execute("SET search_path = slr")
            for sql in statements:
                conn.execute(sql)
        return
    con = sqlite3.connect(where)
    for sql in statements:
        con.execute(sql)
    con.commit()
    con.close()


def test_buffers_survive_reopen_and_apply_to_external_sql_inserts(backend):
    kb = kb_at(0, backend)
    kb.load(PAPER_BUFFERS, "paper.slr")
    keep = kb.add_buffer("pos(O, _)", keep_last=1)
    kb.add_many(["face(bob)^1", "pos(cup, 1)^1", "pos(cup, 2)^2"])
    kb.close()

    kb = kb_at(50, backend)
    assert sorted(b.pattern for b in kb.buffers()) == [
        "face(P)", "inView(face(P,_))", "inView(obj(O,_))", "pos(O,_)", "tf(S,D,TF)"]
    assert {b.id: b.pruned for b in kb.buffers()}[keep] == 1
    kb.add_many(["pos(cup, 3)^3", "inView(face(ann, a))^1", "inView(face(ann, b))^2"])
    assert [a["X"] for a in kb.query("pos(cup, X)^T")] == [3]
    assert [a["L"] for a in kb.query("inView(face(ann, L))^T")] == ["b"]
    kb.clock.set(100)  # face(bob)^1 expires
    assert kb.query("face(P)^T") == []
    kb.close()

    # another tool writing rows through SQL: the triggers still keep the buffers
    insert_as_another_tool(backend, [
        "INSERT INTO pos (arg1, arg2, t_start, t_end, arrival) VALUES ('cup', 4, 4.0, 4.0, 100.0)",
        "INSERT INTO face (arg1, t_start, t_end, arrival) VALUES ('eve', 5.0, 5.0, 100.0)",
        # a compound-looking text that is not JSON: matches no pattern, raises nothing
        "INSERT INTO \"inView\" (arg1, t_start, t_end, arrival) VALUES ('{face', 6.0, 6.0, 100.0)"])
    kb = kb_at(100, backend)
    assert [a["X"] for a in kb.query("pos(cup, X)^T")] == [4]
    assert kb.query("face(P)^T") == []  # 5 < 100 - 60: dropped on insert
    assert by_pattern(kb)["face(P)"].dropped == 1
    assert kb.store.count("inView", 1) == 2
    kb.close()


def test_program_buffers_are_not_duplicated_on_reopen(backend):
    with kb_at(0, backend) as kb:
        kb.load("tBuffer(face(P), 60).", "f.slr")
        first = [(b.id, b.pattern) for b in kb.buffers()]
        triggers = buffer_triggers(kb)
    with kb_at(0, backend) as kb:
        assert [(b.id, b.pattern) for b in kb.buffers()] == first
        kb.load("cBuffer(obj(O), 1).", "g.slr")
        kb.add("obj(cup)^1")   # the table and the buffer's triggers on it
        triggers_after = buffer_triggers(kb)
    with kb_at(0, backend) as kb:
        assert [b.pattern for b in kb.buffers()] == ["face(P)", "obj(O)"]
        assert buffer_triggers(kb) == triggers_after > triggers
        extra = kb.add_buffer("obj2(_)", keep_last=2)
        kb.add("obj2(cup)^1")
        assert len(buffer_triggers(kb)) == len(triggers_after) + 2
        kb.remove_buffer(extra)   # its triggers go with it
        assert buffer_triggers(kb) == triggers_after


# ----------------------------------------------------------------------------- stats and space

def test_stats_command_prints_counters_and_file_size(tmp_path):
    from click.testing import CliRunner

    from slr_sql.cli import main

    path = tmp_path / "s.db"
    with kb_at(0, path) as kb:
        kb.load("tBuffer(face(P), 10).\ncBuffer(obj(O, _), 1).", "s.slr")
        kb.add_many(["face(a)^1", "obj(cup, 1)^1", "obj(cup, 2)^2"])
        kb.clock.set(30)
        kb.add("face(b)^2")
    result = CliRunner().invoke(main, ["stats", str(path)])
    assert result.exit_code == 0, result.output
    out = result.output
    assert "file" in out and "bytes" in out
    assert "tBuffer face(P)" in out and "cBuffer obj(O,_)" in out
    assert "s.slr:1" in out
    face_line = next(line for line in out.splitlines() if "face(P)" in line)
    assert "pruned 1" in face_line and "dropped 1" in face_line


def test_file_stops_growing_under_a_stream(tmp_path):
    path = tmp_path / "stream.db"
    kb = slr_sql.open(path, clock=ManualClock(0), synchronous="NORMAL")
    kb.load("tBuffer(tf(_, _, _), 10).")
    sizes = []
    t = 0.0
    for batch in range(60):
        events = []
        for _ in range(1000):
            t += 0.01
            events.append(("tf", ["map", "base", [t, 1.0, 2.0, 0.0, 0.0, 0.0, 1.0]], t, t))
        kb.clock.set(t)
        kb.add_many(events)
        sizes.append(kb.store.space_stats()["file_bytes"]
                     + kb.store.space_stats()["wal_bytes"])
    assert kb.store.count("tf", 3) <= 1000 * 10 / 10 + 1000
    assert max(sizes[40:]) <= max(sizes[15:25]) * 1.1
    kb.close()


def test_an_add_that_freed_little_reads_one_pragma_for_the_space(tmp_path):
    # the space stage after every add: the free list's length decides alone while it is
    # short (the page count is read only when there may be pages to give back)
    kb = slr_sql.open(tmp_path / "s.db", clock=ManualClock(0))
    kb.add("p(1)^1")
    seen: list[str] = []
    kb.store._db.conn.set_trace_callback(seen.append)
    try:
        kb.add("p(2)^2")
    finally:
        kb.store._db.conn.set_trace_callback(None)
    assert "PRAGMA freelist_count" in seen and "PRAGMA page_count" not in seen
    kb.close()


# ----------------------------------------------------------------------------- model test

ATOMS = ["a", "b"]
VALUES = [slr_sql.Atom("a"), slr_sql.Atom("b"), 1, 2, 1.0, String("s"),
          Struct("f", (slr_sql.Atom("a"),)), Struct("f", (1,)), [slr_sql.Atom("a"), 1]]
ARG_PATTERNS = ["_", "X", "Y", "_Z", "a", "b", "1", "1.0", "\"s\"", "f(X)", "f(_)", "f(a)",
                "[X, _]", "[a, 1]"]


def pattern_strategy():
    return st.tuples(st.sampled_from(ARG_PATTERNS), st.sampled_from(ARG_PATTERNS)).map(
        lambda ab: f"p({ab[0]}, {ab[1]})")


buffer_strategy = st.one_of(
    st.tuples(st.just("tBuffer"), pattern_strategy(), st.sampled_from([0, 1, 2.5, 6])),
    st.tuples(st.just("cBuffer"), pattern_strategy(), st.sampled_from([1, 1, 2, 0, 3])),
    st.tuples(st.just("window"), pattern_strategy(),
              st.tuples(st.integers(0, 10), st.integers(0, 10)).map(sorted)),
)

time_strategy = st.integers(0, 8).map(lambda x: x / 2)  # small: many ties
event_strategy = st.tuples(st.sampled_from(VALUES), st.sampled_from(VALUES), time_strategy,
                           st.sampled_from([0, 0, 0, 0.5, 2]))
op_strategy = st.one_of(
    st.tuples(st.just("add"), st.lists(event_strategy, min_size=1, max_size=8)),
    st.tuples(st.just("tick"), st.sampled_from([0, 0.5, 1, 2.5, 4])),
)


class Model:
    """Brute force: which arrived events each buffer keeps, recomputed from scratch."""

    def __init__(self, buffers):
        self.buffers = []
        for kind, text, amount in buffers:
            term, names = parse_term(text, "<model>")
            named = [v for n, v in names.items() if not n.startswith("_")]
            self.buffers.append((kind, term, named, amount))
        self.events = []  # (seq, args, start, end)
        self.now = 0.0

    def match(self, args):
        event = from_python(Struct("p", tuple(args)))
        for index, (kind, term, named, amount) in enumerate(self.buffers):
            mapping: dict = {}
            copy = copy_term(term, mapping)
            if unify(copy, event, []):
                key = []
                for v in named:
                    value = encode(deref(mapping[id(v)]))
                    key.append((type(value).__name__, value))
                return index, tuple(key)
        return None, None

    def stored(self):
        groups: dict = {}
        keep = []
        for seq, args, start, end in self.events:
            index, key = self.match(args)
            if index is None:
                keep.append((seq, args, start, end))
                continue
            kind, _, _, amount = self.buffers[index]
            if kind == "tBuffer":
                if end >= self.now - amount:
                    keep.append((seq, args, start, end))
            elif kind == "window":
                if amount[0] <= start and end <= amount[1]:
                    keep.append((seq, args, start, end))
            else:
                groups.setdefault((index, key), []).append((seq, args, start, end))
        for (index, _), events in groups.items():
            n = self.buffers[index][3]
            events.sort(key=lambda e: (e[3], e[2], e[0]), reverse=True)
            keep.extend(events[:n])
        return Counter((tuple(_typed(encode(a)) for a in args), start, end)
                       for _, args, start, end in keep)

    def arrived_per_buffer(self):
        counts = Counter()
        for _, args, _, _ in self.events:
            index, _ = self.match(args)
            counts[index] += 1
        return counts


def stored_rows(kb):
    if kb.store.table_for("p", 2) is None:
        return Counter()
    return Counter(((_typed(a1), _typed(a2)), s, e) for a1, a2, s, e in
                   kb.sql("SELECT arg1, arg2, t_start, t_end FROM p")[1])


def _typed(value):
    """A counter key that keeps 1 and 1.0 apart (Python's == merges them; Prolog does not)."""
    return (type(value).__name__, value)


@settings(max_examples=200, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(buffers=st.lists(buffer_strategy, min_size=1, max_size=3),
       ops=st.lists(op_strategy, min_size=1, max_size=12),
       runtime=st.booleans(), before=st.booleans())
def test_stored_events_equal_the_brute_force_model(buffers, ops, runtime, before):
    texts = [text for _, text, _ in buffers]
    terms = [parse_term(t, "<x>")[0] for t in texts]
    for i in range(len(terms)):
        for j in range(i + 1, len(terms)):
            trail: list = []
            assume(not unify(copy_term(terms[i]), copy_term(terms[j]), trail))
    kb = kb_at(0)
    model = Model(buffers)

    def declare():
        if runtime:
            add_buffers(kb, buffers)
        else:
            program = [f"{kind}({text}, {amount})." for kind, text, amount in buffers
                       if kind != "window"]
            kb.load("\n".join(program), "model.slr")
            for kind, text, amount in buffers:
                if kind == "window":
                    kb.add_buffer(text, keep_between=tuple(amount))

    if not before:
        declare()
    seq = 0
    for step, (op, arg) in enumerate(ops):
        if op == "tick":
            kb.clock.advance(arg)
            model.now = kb.clock.now()
        else:
            batch = []
            for a1, a2, end, length in arg:
                start = max(0.0, end - length)
                batch.append(("p", [a1, a2], float(start), float(end)))
                model.events.append((seq, (from_python(a1), from_python(a2)),
                                     float(start), float(end)))
                seq += 1
            assert kb.add_many(batch) == []
        if before and step == 0:
            declare()  # buffers installed over a history already stored
        assert stored_rows(kb) == model.stored(), f"after step {step}: {op} {arg}"
    expected = model.stored()
    assert stored_rows(kb) == expected
    # every event a buffer received was either kept, pruned or dropped on arrival
    arrived = model.arrived_per_buffer()
    infos = sorted(kb.buffers(), key=lambda b: b.id)
    assert len(infos) == len(buffers)
    for index, _ in enumerate(buffers):
        text = parse_term(texts[index], "<x>")[0]
        info = next(b for b in infos if b.pattern == slr_sql.terms.format_term(text))
        kept = sum(1 for (args, _, _), n in expected.items() for _ in range(n)
                   if model.match([_decode(v) for _, v in args])[0] == index)
        assert info.pruned + info.dropped == arrived[index] - kept
    kb.close()


def _decode(value):
    from slr_sql.encoding import decode

    return decode(value)


@pytest.mark.parametrize("how", ["runtime", "declared"])
def test_a_tbuffer_added_after_the_clock_moved_keeps_the_window_of_the_clock_now(backend, how):
    """Without a tBuffer, moving the clock writes nothing (no commit per move); a tBuffer
    added later still starts from the clock's current time, not from the last add's."""
    clock = ManualClock(0.0)
    with slr_sql.open(backend, clock=clock) as kb:
        kb.add_many([("seen", (i,), float(i), float(i)) for i in range(100)])
        clock.set(150.0)
        clock.set(200.0)
        if how == "runtime":
            kb.add_buffer("seen(X)", keep_seconds=10)
        else:
            kb.load("tBuffer(seen(X), 10s).")
        # 200 - 10 = 190: every stored event (ends 0..99) is outside the window
        assert kb.query("aggregate_all(count, seen(_)^_, N)") == [{"N": 0}]
        kb.add_many([("seen", (i,), float(i), float(i)) for i in range(185, 200)])
        assert kb.query("findall(X, seen(X)^_, L)") == [{"L": list(range(190, 200))}]
        clock.set(205.0)
        assert kb.query("findall(X, seen(X)^_, L)") == [{"L": list(range(195, 200))}]


class _UntickedClock(slr_sql.clocks.Clock):
    """A clock that moves without telling its listeners, as a WallClock does."""

    def __init__(self, t: float):
        super().__init__()
        self.t = t

    def now(self) -> float:
        return self.t


def test_prune_now_removes_what_expired_on_a_clock_that_does_not_tick():
    from slr_sql.buffers import prune_now

    clock = _UntickedClock(1.0)
    with slr_sql.open(clock=clock) as kb:
        kb.add_buffer("p(X)^T", keep_seconds=10)
        kb.add_many(["p(1)^1", "p(2)^1"])
        clock.t = 50.0
        assert len(kb.query("p(X)^T")) == 2   # expired, but nothing told the buffers yet
        prune_now(kb)
        assert kb.query("p(X)^T") == []
        kb.add("p(3)^49")
        assert kb.query("p(X)^T") == [{"X": 3, "T": 49.0}]
