"""Printed answers (``slr query``, ``slr shell``, ``slr run``) write a binding's value as
SWI-Prolog's top level writes it: as the right operand of ``=`` (``X = (a,b)``, which reads
back as the binding, where ``X = a,b`` read as a conjunction), a list's elements as
arguments (``[(a:-b)]``, not ``[a:-b]``, a syntax error), atoms quoted as writeq quotes them
(``','``), an atom that is an operator in brackets (``X = (table)``), floats as SWI-Prolog writes them (``1.0e+22``, ``1.0e-5``, ``1.0Inf``,
``1.5NaN``). Compared with swipl: ``write_term(T, [quoted(true), priority(699)])`` for
generated terms, and its top level given the same piped goals."""
from __future__ import annotations

import math
import re
import shutil
import subprocess
import tempfile

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from slr_sql.answers import answer_text, binding_text
from slr_sql.terms import INFIX_OPS, PREFIX_OPS, Atom, Struct

from test_answer_depth import partial_list
from test_cli import slr

SWIPL = shutil.which("swipl")


def swipl_written(values: list) -> list[str]:
    """swipl's ``write_term(T, [quoted(true), priority(699)])`` of each value, read from
    the text :func:`binding_text` wrote (so a text swipl reads otherwise fails here)."""
    assert SWIPL, "SWI-Prolog is the reference: install swi-prolog (.ci/run does)"
    program = "".join(f"t({binding_text(v)}).\n" for v in values)
    with tempfile.NamedTemporaryFile("w", suffix=".pl", encoding="utf-8") as file:
        file.write(program)
        file.flush()
        done = subprocess.run(
            [SWIPL, "-q", "-g", "forall(t(T), (write_term(T, [quoted(true), priority(699)]), "
             "nl))", "-t", "halt", file.name], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    return done.stdout.splitlines()


OPERATORS_2 = [",", ";", "->", ":-", "=", "+", "-", "*", "^", ":", "=.."]   # (no `is`: as below)
# (no operator named by letters: swipl's writeq glues one to what follows,
# `dynamic-1` for dynamic(-1), which reads back as -(dynamic, 1), and `[]is 0`; ours keeps
# the spaces)
OPERATORS_1 = ["-", "\\+", "+", ":-"]
leaves = st.one_of(
    st.integers(-3, 30),
    st.sampled_from([Atom("a"), Atom("[]"), Atom("A b"), Atom("-"), Atom(","), Atom("table"),
                     Atom(";"), Atom("{}"), "s", "", 1.5, -0.0, 1e22, 1e-5, 1.5e-7, 1e15,
                     0.1, math.inf, -math.inf, math.nan]))
terms = st.recursive(
    leaves,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.builds(partial_list, st.lists(inner, min_size=1, max_size=3), st.just(Atom("t"))),
        st.builds(lambda name, args: Struct(name, tuple(args)), st.sampled_from(["f", "g"]),
                  st.lists(inner, min_size=1, max_size=3)),
        st.builds(lambda a: Struct("{}", (a,)), inner),
        st.builds(lambda op, a, b: Struct(op, (a, b)), st.sampled_from(OPERATORS_2), inner,
                  inner),
        st.builds(lambda op, a: Struct(op, (a,)), st.sampled_from(OPERATORS_1), inner)),
    max_leaves=25)


def top_level(values: list, written: list[str]) -> list[str]:
    """swipl's top level brackets an operator atom a binding holds (``X = (-)``), which its
    write_term at priority 699 writes bare."""
    return [f"({text})" if type(v) is Atom and (v in INFIX_OPS or v in PREFIX_OPS) else text
            for v, text in zip(values, written)]


def test_the_cases_that_did_not_read_back_are_written_as_swipl_writes_them():
    cases = [Struct(",", (Atom("a"), Atom("b"))), [Struct(":-", (Atom("a"), Atom("b")))],
             Struct(";", (Struct("->", (Atom("a"), Atom("b"))), Atom("c"))), Atom(","),
             1e22, 1e-5, 1e15, math.inf, -math.inf, math.nan]
    ours = [binding_text(v) for v in cases]
    assert ours == ["(a,b)", "[(a:-b)]", "(a->b;c)", "(',')", "1.0e+22", "1.0e-5", "1.0e+15",
                    "1.0Inf", "-1.0Inf", "1.5NaN"]
    assert ours == top_level(cases, swipl_written(cases))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(terms, min_size=20, max_size=20))
def test_any_binding_is_written_as_swipl_writes_it(values):
    assert [binding_text(v) for v in values] == top_level(values, swipl_written(values))


GOALS = [
    "X = (a, b).",
    "X = (a :- b, c).",
    "X = (a -> b ; c).",
    "X = [(a :- b)], Y = f((a, b)).",
    "X = 1.0e22, Y = 1.0e-5, Z = 1.0e15.",
    "X is inf, Y is -inf, Z is nan.",
    "X = ',', Y = [','].",
    "X = (table), Y = (mod), Z = (-), W = [table], V = f(dynamic).",
    "X = - (1), Y = 1 - -1, Z = -(-(a)).",
]


def layout(answer: str) -> str:
    """An answer as one line: swipl writes a binding a line and a space after each comma."""
    return re.sub(r",\s+", ",", answer.strip()).rstrip(".").strip()


def test_the_shell_and_slr_query_print_as_swipls_top_level(tmp_path):
    store = tmp_path / "text.db"
    assert slr("add", store, "x(1)^1").returncode == 0
    text = "\n".join(GOALS) + "\n"
    assert SWIPL
    theirs = subprocess.run([SWIPL, "-q"], input=text, capture_output=True, text=True,
                            timeout=60)
    assert theirs.returncode == 0, theirs.stderr
    expected = [layout(a) for a in theirs.stdout.split("\n\n") if a.strip()]
    assert len(expected) == len(GOALS)
    shell = slr("shell", store, stdin=text)
    assert shell.returncode == 0 and shell.stderr == "", shell.stderr
    assert [layout(a) for a in shell.stdout.splitlines()] == expected
    for goal, answer in zip(GOALS, expected):
        query = slr("query", store, goal.rstrip("."))
        assert query.returncode == 0, query.stderr
        assert layout(query.stdout) == answer


def test_an_operator_atom_a_binding_holds_is_in_brackets_as_swipl_writes_it():
    """Written bare, `X = table, Y = 1` was a syntax error (a prefix operator above 999 before
    a comma): swipl's top level brackets every operator atom a binding holds, not one inside
    a term."""
    assert answer_text({"L": Atom("table"), "X": Atom("-"), "Y": Atom("|"), "Z": Atom("mod"),
                        "W": [Atom("table")], "V": Struct("f", (Atom("dynamic"),))}) == \
        "L = (table), X = (-), Y = ('|'), Z = (mod), W = [table], V = f(dynamic)"
