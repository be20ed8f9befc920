"""Event rules of many parts (docs/events.md, "Limits"): a pattern of the most event atoms
a rule may have is decided on both backends as the naive reference of
tests/test_cep_differential.py decides it, and a larger one is refused at load with the
rule, its line and the maximum, the program in force left as it was.

Before, a 30-part ``seq`` under ``recent`` loaded and then refused every add that decided
it (SQLite's "Expression tree is too large": an equality of the shared variable between
every two positions), a 30-part ``and`` spent seconds in SQLite's planner per position,
beyond 64 parts SQLite refused the join, and from ~990 parts the load failed in the
recursive walks of the rule's reader. A 30-part ``and`` under ``recent`` took 3.5-15 s for
its first decisions: each partner's sub-query asked for rows of every partner after it
(an EXISTS over up to 28 tables, ~0.1 s of SQLite's planner per statement), where the
partners of an ``and`` constrain only the terminator's row, not each other.
"""
from __future__ import annotations

import os
import random
import subprocess
import sys

import pytest
import test_cep_differential as cepdiff
from hypothesis import HealthCheck, given, settings, strategies as st
from strategy_helpers import integers, sampled

import slr_sql
from slr_sql import ManualClock, SLRSyntaxError
from slr_sql.cep.rules import MAX_ALTERNATIVES, MAX_PATTERN_DEPTH, MAX_PATTERN_EVENTS

N = MAX_PATTERN_EVENTS


@pytest.fixture
def kb():
    """A knowledge base in memory whose clock is the events' times."""
    with slr_sql.open(None, clock=ManualClock(0)) as k:
        yield k


def _chain(op: str, leaves: list) -> tuple:
    """The left-nested tree ``l0 op l1 op ..`` of the reference's rules."""
    tree = leaves[0]
    for leaf in leaves[1:]:
        tree = (op, tree, leaf)
    return tree


def _stream(seed: int) -> list:
    """One event of each type p0..p<N-1> with X = 0, in time order, and a few more: a
    second p0 and a second last part (two initiators, two terminators), a p<N/2> out of
    order (it fits an ``and``, not a ``seq``), a p3 of another X (no partner has it)."""
    events = [(f"p{i}", (0,), float(i + 1), float(i + 1)) for i in range(N)]
    events += [("p0", (0,), 0.5, 0.5), (f"p{N - 1}", (0,), N + 4.0, N + 5.0),
               (f"p{N // 2}", (0,), 2.0, 2.0), ("p3", (1,), 3.5, 3.5)]
    random.Random(seed).shuffle(events)   # (any arrival order: the same complex events)
    return events


@pytest.mark.parametrize("op, policy, within", [
    ("and", "unrestricted", None),
    ("and", "recent", None),
    ("seq", "recent", N + 1),
    ("seq", "chronological", None),
])
def test_a_pattern_of_the_most_atoms_equals_the_reference(backend, op, policy, within):
    rule = {"pattern": _chain(op, [("leaf", f"p{i}", ("X",)) for i in range(N)]),
            "head": ["X"], "where": [], "cnot": None, "within": within, "policy": policy}
    events = _stream(len(op) + len(policy))
    expected = cepdiff.reference(rule, events)
    assert expected, "the stream matches the pattern"
    got = cepdiff.run(rule, events, list(range(len(events))), [len(events) // 2], False,
                      False, where=backend)
    assert cepdiff._typed(got) == cepdiff._typed([(tuple(h), s, e) for h, s, e in expected])



OPERATORS = ["seq", "and", "par"] * 3 + ["equals", "meets", "during", "starts", "finishes"]
# a longer hunt: SLR_DIFF_FACTOR=20 runs the random patterns with twenty times their examples
FACTOR = int(os.environ.get("SLR_DIFF_FACTOR", "1"))


def _mixed_pattern(rnd, lo: int, hi: int) -> tuple:
    """A random tree of the binary operators over the types p<lo>..p<hi - 1>, in order;
    an argument is X (shared by every part), free, or a variable of its own part."""
    if hi - lo == 1:
        return ("leaf", f"p{lo}", (rnd.choice(["X", "X", "_", f"V{lo}"]),))
    mid = rnd.randint(lo + 1, hi - 1)
    return (rnd.choice(OPERATORS), _mixed_pattern(rnd, lo, mid), _mixed_pattern(rnd, mid, hi))


def _witness(rnd, tree) -> list:
    """Events [name, start, end] that match ``tree``: each right part is moved in time so
    that the operator's relation to its left part holds (equals and during, which need
    lengths that fit, may still fail: a stream without a match is a case too)."""
    if tree[0] == "leaf":
        s = float(rnd.randint(0, 3))
        return [[tree[1], s, s + rnd.choice([0.0, 0.0, 1.0, 2.0])]]
    left, right = _witness(rnd, tree[1]), _witness(rnd, tree[2])
    s1, e1 = min(x[1] for x in left), max(x[2] for x in left)
    s2, e2 = min(x[1] for x in right), max(x[2] for x in right)
    shift = {"seq": e1 + rnd.choice([1.0, 2.0]) - s2, "meets": e1 - s2, "starts": s1 - s2,
             "finishes": e1 - e2, "equals": s1 - s2, "during": s1 - s2 - rnd.choice([0.0, 1.0]),
             "par": s1 - s2 + rnd.choice([-1.0, 0.0, 1.0]),
             "and": rnd.choice([-2.0, 0.0, 2.0])}[tree[0]]
    for x in right:
        x[1] += shift
        x[2] += shift
    return left + right


def mixed_case(rnd) -> tuple:
    """(rule, events, arrival order): a pattern of 5 to 10 parts of mixed operators, any
    policy, sometimes a window; a stream that matches it (X = 0) and events beside it (other
    values, times moved, ties); a shuffled arrival order."""
    n = rnd.randint(5, 10)
    pattern = _mixed_pattern(rnd, 0, n)
    rule = {"pattern": pattern, "head": sorted(cepdiff._vars(pattern)), "where": [],
            "cnot": None, "within": rnd.choice([None, None, n, 3]),
            "policy": rnd.choice(["unrestricted", "recent", "chronological"])}
    events = [(name, (0,), s, e) for name, s, e in _witness(rnd, pattern)]
    first = min(ev[2] for ev in events)
    events = [(name, args, s - first, e - first) for name, args, s, e in events]
    for _ in range(rnd.randint(1, n)):
        name, _, s, e = rnd.choice(events)
        start = max(0.0, s + rnd.choice([0.0, 0.0, 1.0, -1.0, 2.0]))
        events.append((name, (rnd.choice([0, 0, 1]),), start,
                       start + rnd.choice([0.0, e - s, 1.0])))
    order = list(range(len(events)))
    rnd.shuffle(order)
    return rule, events, order


@settings(max_examples=10 * FACTOR, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.randoms(use_true_random=False))
def test_a_long_pattern_of_mixed_operators_equals_the_reference(rnd):
    rule, events, order = mixed_case(rnd)
    expected = cepdiff.reference(rule, events)
    got = cepdiff.run(rule, events, order, [rnd.randint(0, len(events))], False, False)
    assert cepdiff._typed(got) == cepdiff._typed([(tuple(h), s, e) for h, s, e in expected]), \
        (cepdiff.rule_text(rule), events, order)

def test_a_variable_of_every_part_is_tied_once_per_part_in_a_statement(kb):
    # (each part equal to the first one joined: n - 1 equalities, not n(n-1)/2, which made
    # SQLite's planner slow and its expressions too deep)
    kb.load("c(X) <- " + " and ".join(f"a{i}(X)" for i in range(12)) + ".")
    kb.add_many([f"a{i}(1)^{i}" for i in range(12)])
    shown = kb.explain("c(X)")
    statements = [line for line in shown.splitlines() if line.strip().startswith("WHERE")]
    assert len(statements) == 12
    assert all(line.count("typeof(") == 2 * 11 for line in statements), statements[0]
    assert len(kb.query("c(X)^[S, E]")) == 1


def test_a_recent_and_asks_each_partner_of_its_own_table_only(kb):
    # (the partners of an and sharing the terminator's variable constrain only the
    # terminator's row: each is the newest of its own type, one small sub-query each)
    k = 12
    kb.load(":- consumption(recent).\nc(X) <- " + " and ".join(f"a{i}(X)" for i in range(k))
            + ".")
    kb.add_many([f"a{i}(1)^{i}" for i in range(k)])
    shown = kb.explain("c(X)")
    assert "EXISTS" not in shown
    searches = [line for line in shown.splitlines() if "plan: SEARCH q" in line]
    statements = shown.count("SQL when position") + shown.count("SQL deciding the spans")
    assert statements == 2 * k   # (each position: its new rows, and its spans)
    assert len(searches) == statements * (k - 1)
    kb.clock.set(k + 1.0)
    assert kb.query("c(X)^[S, E]") == [{"X": 1, "S": 0.0, "E": float(k - 1)}]


def _leaf(name, *args):
    return ("leaf", name, args)


# what ties two partners of a recent rule together (their rows are then chosen in one
# sub-query), each with a stream whose newest row of one partner has no fitting row of the
# other: choosing each partner apart found no match, or another one, where the reference
# takes an older row
LINKED = {
    "a variable the terminator lacks": (
        ("and", ("and", _leaf("a", "X"), _leaf("b", "Y")), _leaf("d", "Y", "_")), [], None,
        None, [("a", (1,), 3.0, 6.0), ("d", (1, 1), 0.0, 0.0), ("d", (0, 0), 2.0, 2.0),
               ("b", (1,), 4.0, 4.0)]),
    "rows of one type": (
        ("and", ("and", _leaf("a", "X"), _leaf("b", 1)), _leaf("b", "_")), [], None, None,
        [("a", (1,), 2.0, 2.0), ("b", (1,), 2.0, 2.0), ("b", (0,), 1.0, 2.0),
         ("a", (1,), 3.0, 3.0)]),
    "a where between partners": (
        ("and", ("and", _leaf("a", "X"), _leaf("b", "Y")), _leaf("d", "Z", "_")),
        [("<", "Y", "Z")], None, None,
        [("b", (0,), 4.0, 7.0), ("d", (1, 0), 4.0, 4.0), ("d", (0, 1), 5.0, 5.0),
         ("a", (0,), 5.0, 8.0)]),
    "a par between partners": (
        ("and", _leaf("a", "X"), ("par", _leaf("b", "_"), _leaf("d", "_", "_"))), [], None,
        None, [("d", (0, 1), 5.0, 6.0), ("b", (1,), 0.0, 3.0), ("d", (1, 0), 1.0, 4.0),
               ("a", (0,), 4.0, 7.0)]),
    "a window": (
        ("and", ("and", _leaf("a", "X"), _leaf("b", "_")), _leaf("d", "_", "_")), [], None,
        2, [("b", (0,), 3.0, 3.0), ("b", (1,), 1.0, 4.0), ("a", (0,), 4.0, 5.0),
            ("d", (1, 0), 5.0, 5.0)]),
    "a cnot over partners": (
        ("and", _leaf("a", "X"), ("cnot", ("and", _leaf("b", "_"), _leaf("d", "_", "_")),
                                  _leaf("c", "_"))), [], None, None,
        [("a", (0,), 5.0, 5.0), ("b", (0,), 1.0, 1.0), ("d", (0, 0), 2.0, 2.0),
         ("c", (0,), 3.0, 3.0), ("d", (1, 1), 3.5, 3.5)]),
}


@pytest.mark.parametrize("arrival", ["in order", "reversed"])
@pytest.mark.parametrize("case", list(LINKED))
def test_recent_partners_tied_together_are_chosen_together(backend, case, arrival):
    pattern, where, cnot, within, events = LINKED[case]
    rule = {"pattern": pattern, "head": ["X"], "where": where, "cnot": cnot,
            "within": within, "policy": "recent"}
    expected = cepdiff.reference(rule, events)
    assert expected, "the stream matches the pattern"
    order = list(range(len(events)))
    if arrival == "reversed":   # (in two batches, with the marks each type has earned)
        order.reverse()
    got = cepdiff.run(rule, events, order, [2], arrival == "reversed", False, where=backend)
    assert cepdiff._typed(got) == cepdiff._typed([(tuple(h), s, e) for h, s, e in expected]), \
        cepdiff.rule_text(rule)


@st.composite
def linked_recent_rules(draw):
    """A recent rule of 3-5 atoms over a/1, b/1 and d/2, mostly joined by ``and``: partners
    that share a variable the terminator lacks, rows of one type, a ``where`` between two
    variables, a ``par``, ``seq``, ``within`` or ``cnot`` tie some partners (or all of them)
    together, the others only to the terminator."""
    leaves = []
    for _ in range(draw(integers(3, 5))):
        name = draw(sampled(["a", "b", "d"]))
        leaves.append(("leaf", name, tuple(draw(sampled(["X", "X", "Y", "Z", "_", 1]))
                                           for _ in range(cepdiff.TYPES[name]))))
    tree = leaves[0]
    for leaf in leaves[1:]:
        tree = (draw(sampled(["and", "and", "and", "par", "seq"])), tree, leaf)
    bound = sorted(cepdiff._vars(tree))
    where = []
    if len(bound) > 1 and draw(integers(0, 3)) == 0:
        where.append((draw(sampled(["<", "=<", ">"])), bound[0], bound[-1]))
    cnot = ("c", (draw(sampled(bound + ["_"])),)) if draw(integers(0, 5)) == 0 else None
    return {"pattern": tree, "head": bound[:1], "where": where, "cnot": cnot,
            "within": draw(sampled([None, None, None, 3])), "policy": "recent"}


@st.composite
def linked_streams(draw):
    out = []
    for _ in range(draw(integers(3, 11))):
        name = draw(sampled(["a", "b", "d", "d", "c"]))
        args = tuple(draw(sampled([0, 1, 1.0])) for _ in range(cepdiff.TYPES[name]))
        s = float(draw(integers(0, 6)))
        out.append((name, args, s, s + float(draw(sampled([0, 0, 1])))))
    return out


@settings(max_examples=80, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(linked_recent_rules(), linked_streams(), st.data())
def test_recent_partners_chosen_apart_or_together_equal_the_reference(rule, events, data):
    cepdiff.equals_the_reference(rule, events, data, may_add_one_by_one=True)


def test_a_variable_that_is_a_value_and_a_time_keeps_every_equality(backend):
    # a time equals 5 and 5.0 alike, the values 5 and 5.0 are two terms: a(5) and c(5.0)
    # do not match, whatever b's time says (b's time is the first X its statement joins)
    with slr_sql.open(backend, clock=ManualClock(0)) as kb:
        kb.load("r(X) <- a(X) and b(_)^X and c(X).")
        kb.add_many(["a(5)^1", "c(5.0)^2", "c(5)^3"])
        kb.add("b(x)^5")
        assert kb.query("r(X)^[S, E]") == [{"X": 5, "S": 1.0, "E": 5.0}]


def _refused(kb, text: str) -> SLRSyntaxError:
    with pytest.raises(SLRSyntaxError) as e:
        kb.load(text, "long.slr", name="rules", replace=True)
    return e.value


def test_a_pattern_beyond_the_most_atoms_is_refused_at_load_and_the_program_kept(backend):
    with slr_sql.open(backend, clock=ManualClock(0)) as kb:
        kb.load("c(X) <- a(X) seq b(X).", name="rules")
        for op in ("and", "seq"):
            text = ("ok(X) <- a(X) seq b(X).\n\nlong(X) <- "
                    + f" {op} ".join(f"p{i}(X)" for i in range(N + 1)) + ".")
            error = _refused(kb, text)
            assert f"event rule long/1: its pattern has {N + 1} event atoms" in error.message
            assert f"at most {N}" in error.message
            assert (error.line, error.filename) == (3, "long.slr")
        # negated atoms count too: each is a search of the statement
        error = _refused(kb, "long <- (" + " seq ".join(f"p{i}" for i in range(N - 1))
                         + ") cnot (x or y).")
        assert f"has {N + 1} event atoms" in error.message
        assert [r["head"] for r in kb.event_rules()] == ["c/1"]
        kb.add_many(["a(1)^1", "b(1)^2"])
        assert kb.query("c(X)^[S, E]") == [{"X": 1, "S": 1.0, "E": 2.0}]


def test_a_store_holding_a_longer_rule_from_before_opens_and_can_unload_it(tmp_path):
    # (a store an earlier version loaded such a rule into: written here as that version
    # wrote the program's text, without the check of a load)
    path = tmp_path / "robot.db"
    with slr_sql.open(path, clock=ManualClock(0)) as kb:
        kb.load("c(X) <- a(X) seq b(X).", name="small")
        kb.store.append_program("long(X) <- " + " seq ".join(f"p{i}(X)" for i in range(N + 8))
                                + ".", "long.slr", "long")
    with slr_sql.open(path, clock=ManualClock(0)) as kb:
        assert [r["head"] for r in kb.event_rules()] == ["c/1", "long/1"]
        kb.unload("long")
        assert [r["head"] for r in kb.event_rules()] == ["c/1"]
        # a load of the same text is refused: new text meets the maximum
        with pytest.raises(SLRSyntaxError, match=f"at most {N}"):
            kb.load("long(X) <- " + " seq ".join(f"p{i}(X)" for i in range(N + 8)) + ".")


@pytest.mark.parametrize("parts", [990, 5000])
def test_a_pattern_of_thousands_of_parts_is_refused_not_a_recursion(kb, parts):
    error = _refused(kb, "long(X) <- " + " seq ".join(f"p{i}(X)" for i in range(parts)) + ".")
    assert f"its pattern has {parts} event atoms in one alternative; at most {N}" \
        in error.message
    assert kb.event_rules() == []


def test_operators_nested_too_deep_or_too_many_alternatives_are_refused(kb):
    deep = "a"
    for _ in range(MAX_PATTERN_DEPTH + 1):
        deep = f"({deep} within 1)"
    error = _refused(kb, f"c <- {deep}.")
    assert f"nests operators {MAX_PATTERN_DEPTH + 1} deep; at most {MAX_PATTERN_DEPTH}" \
        in error.message
    # each `or` part of a seq doubles the alternatives: 2^7 of them
    error = _refused(kb, "c <- " + " seq ".join(f"(a{i} or b{i})" for i in range(7)) + ".")
    assert "has 128 alternatives" in error.message
    assert f"at most {MAX_ALTERNATIVES}" in error.message
    kb.load("c <- " + " seq ".join(f"(a{i} or b{i})" for i in range(6)) + ".")
    assert len(kb.event_rules()) == 1


def test_the_command_line_words_a_pattern_of_a_thousand_parts(tmp_path):
    rules = tmp_path / "long.slr"
    rules.write_text("% a long sequence\nlong(X) <- "
                     + " seq ".join(f"p{i}(X)" for i in range(1000)) + ".\n")
    done = subprocess.run([sys.executable, "-m", "slr_sql", "load", str(tmp_path / "r.db"),
                           str(rules)], capture_output=True, text=True, timeout=120)
    assert done.returncode != 0
    assert "Traceback" not in done.stderr
    assert "long.slr:2:" in done.stderr
    assert "event rule long/1: its pattern has 1000 event atoms" in done.stderr
