"""The bindings of an answer are printed in the order SWI-Prolog's top level prints them:
the order in which the variables first appear in the query text (not the order of a
dict, of Python's id(), of the compiled plan's columns). `slr query` and `slr shell` (its
input piped) against a live swipl on goals whose variables all have distinct values (SWI
joins variables of equal values, ``X = Y, Y = 1``: a difference of its own, docs/semantics.md)."""
from __future__ import annotations

import re
import shutil
import subprocess
import sys

import pytest
from service_helpers import slr_env

import slr_sql

GOALS = [
    "Y = 1, X = 2",
    "f(Y, g(X)) = f(1, g(2))",
    "X = [Y|T], Y = 1, T = []",
    "length(L, 2), L = [b, a], nth0(0, L, E)",
    "B = b, atom_length(abc, N), A = a",
    "Z = 3, findall(Q, member(Q, [1, 2]), L)",
    "sort([c, a, b], S), msort([b, a], M), K = k",
    "succ(P, 5), plus(P, R, 10), format(atom(F), '~w', [R])",
]
NAME = r"([A-Z_][A-Za-z0-9_]*) = "


def swi_order(goal: str) -> list[str]:
    if shutil.which("swipl") is None:
        pytest.fail("swipl (SWI-Prolog) is not installed: this test compares with it "
                    "(apt-get install swi-prolog-nox)")
    done = subprocess.run(["swipl", "-q", "-f", "none"], input=f"{goal}.\n", text=True,
                          capture_output=True, timeout=60)
    return re.findall("^" + NAME, done.stdout, re.M)


def our_lines(command: list[str], stdin: str | None = None) -> list[str]:
    done = subprocess.run([sys.executable, "-m", "slr_sql", *command], input=stdin, text=True,
                          capture_output=True, env=slr_env(), timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.splitlines()


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    db = tmp_path_factory.mktemp("order") / "order.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0)):
        pass
    return db


@pytest.mark.parametrize("goal", GOALS)
def test_slr_query_prints_the_bindings_in_swi_prolog_s_order(store, goal):
    expected = swi_order(goal)
    assert len(expected) >= 2, expected
    line, = our_lines(["query", str(store), goal])
    assert re.findall(r"(?:^|, )" + NAME, line) == expected, line


def test_slr_shell_prints_them_in_the_same_order(store):
    lines = our_lines(["shell", str(store)], "".join(f"{goal}.\n" for goal in GOALS))
    answers = [line for line in lines if " = " in line]
    assert [re.findall(r"(?:^|, )" + NAME, line) for line in answers] == \
        [swi_order(goal) for goal in GOALS], lines
