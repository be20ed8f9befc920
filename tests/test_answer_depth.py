"""The shell cuts long answers where SWI-Prolog's top level cuts them (its
``answer_write_options``, ``max_depth(10)``): by depth, not by a fixed list length. A list
shows fewer elements the deeper it is, a compound nested more than 10 deep prints ``...``,
strings are printed whole. Compared with swipl itself: ``write_term(T, [max_depth(10),
quoted(true)])`` for generated terms, and its top level given the same piped goals."""
from __future__ import annotations

import re
import shutil
import subprocess
import tempfile

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slr_sql.answers import value_text
from slr_sql.cli import abbreviated
from slr_sql.terms import Atom, Struct

from test_cli import slr

SWIPL = shutil.which("swipl")


def swipl_lines(program: str, goal: str) -> list[str]:
    assert SWIPL, "SWI-Prolog is the reference: install swi-prolog (.ci/run does)"
    with tempfile.NamedTemporaryFile("w", suffix=".pl", encoding="utf-8") as file:
        file.write(program)
        file.flush()
        done = subprocess.run([SWIPL, "-q", "-g", goal, "-t", "halt", file.name],
                              capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    return done.stdout.splitlines()


def partial_list(items: list, tail):
    for item in reversed(items):
        tail = Struct(".", (item, tail))
    return tail


leaves = st.one_of(st.integers(-3, 30), st.sampled_from([Atom("a"), Atom("[]"), Atom("A b"),
                                                         "s", "", 1.5]))
terms = st.recursive(
    leaves,
    lambda inner: st.one_of(
        st.lists(inner, max_size=14),
        st.builds(partial_list, st.lists(inner, min_size=1, max_size=12),
                  st.one_of(st.just(Atom("t")), inner.filter(lambda t: not isinstance(t, list)))),
        st.builds(lambda name, args: Struct(name, tuple(args)), st.sampled_from(["f", "g"]),
                  st.lists(inner, min_size=1, max_size=3)),
        st.builds(lambda a: Struct("{}", (a,)), inner),
        st.builds(lambda a, b: Struct("-", (a, b)), inner, inner),
        st.builds(lambda a: Struct("-", (a,)), inner)),
    max_leaves=60)


def nested(depth: int, inner):
    for name in reversed("fghijklmnopqrstu"[:depth]):
        inner = Struct(name, (inner,))
    return inner


# the edges, by hand: a term at depth 10 and 11, a list whose first element is too deep, a
# partial list's tail, a list of exactly 9 and 10 elements at the top
EDGES = [nested(d, inner) for d in (8, 9, 10, 11) for inner in
         ([1, 2], [], Atom("p"), 1.5, "s", partial_list([Atom("a")], Atom("b")),
          Struct("{}", (Atom("a"),)), Struct("-", (Atom("a"), Atom("b"))))]
EDGES += [list(range(1, 10)), list(range(1, 11)), partial_list(list(range(1, 9)), Atom("t")),
          partial_list(list(range(1, 10)), Atom("t")), [list(range(1, 21))] * 2,
          [Atom("a"), [Atom("b"), [Atom("c"), [Atom("d"), [Atom("e"), [Atom("f")]]]]]],
          "x" * 300, [["y" * 250]]]
# a symbolic operator parted from its left operand by a space is parted from its right one
# too: `- ... - 0` (the cut, a symbol-char atom, on its left), `@ - 0`, `a- -1`
EDGES += [[0, 0, [], 0, 0, 0, 0, Struct("-", (Struct("-", (0,)), 0))],
          Struct("-", (Atom("@"), 0)), Struct("<", (Atom("#"), "s")),
          Struct("-", (Atom("a"), -1)), Struct("-", (Atom("-"), 1))]


def compare_with_swipl(values: list) -> None:
    program = "".join(f"t({value_text(v)}).\n" for v in values)
    theirs = swipl_lines(program, "forall(t(T), (write_term(T, [max_depth(10), "
                                  "quoted(true)]), nl))")
    assert [value_text(abbreviated(v)) for v in values] == theirs


def test_the_edges_are_cut_as_swipl_cuts_them():
    compare_with_swipl(EDGES)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(terms, min_size=20, max_size=20))
def test_any_term_is_cut_as_swipl_cuts_it(values):
    compare_with_swipl(values)


GOALS = [
    "numlist(1, 20, L), X = [L, L, [L]].",
    "numlist(1, 30, L), X = f(L).",
    "X = f(g(h(i(j(k(l(m(n(o(p(q(r)))))))))))).",
    "length(L, 300), maplist(=(0'a), L), string_codes(S, L).",
    "numlist(1, 12, L), length(T, 3), append(L, T, P).",
]


def test_the_shells_answers_are_cut_as_swipls_top_level_cuts_them(tmp_path):
    """The same goals piped to both top levels; swipl's layout (a binding a line, a space
    after each comma) put as the shell's before comparing."""
    store = tmp_path / "depth.db"
    assert slr("add", store, "x(1)^1").returncode == 0
    text = "\n".join(GOALS) + "\n"
    ours = slr("shell", store, stdin=text)
    assert ours.returncode == 0 and ours.stderr == "", ours.stderr
    assert SWIPL
    theirs = subprocess.run([SWIPL, "-q"], input=text, capture_output=True, text=True,
                            timeout=60)
    assert theirs.returncode == 0, theirs.stderr

    def layout(answer: str) -> str:
        answer = re.sub(r",\s+", ",", answer.strip()).rstrip(".").strip()
        return re.sub(r"\b_[A-Z]?\d+\b", "_", answer)   # (swipl's fresh variables: _123)

    expected = [layout(a) for a in theirs.stdout.split("\n\n") if a.strip()]
    assert [layout(a) for a in ours.stdout.splitlines()] == expected
    assert len(expected) == len(GOALS)


@pytest.mark.parametrize("value, text", [
    (list(range(1, 31)), "[1,2,3,4,5,6,7,8,9|...]"),
    (Struct("f", (list(range(1, 31)),)), "f([1,2,3,4,5,6,7,8|...])"),
    (nested(11, Atom("x")), "f(g(h(i(j(k(l(m(n(o(...))))))))))"),
    ("z" * 500, '"' + "z" * 500 + '"'),
    (nested(8, Struct("-", (Struct("-", (0,)), 0))), "f(g(h(i(j(k(l(m(- ... - 0))))))))"),
])
def test_examples(value, text):
    assert value_text(abbreviated(value)) == text
