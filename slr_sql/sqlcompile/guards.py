"""Guards: statements run before the compiled one so that a goal that may raise does so on
exactly the rows Prolog reaches it with, whatever order SQLite evaluates conditions in.

The compiler records every such goal while it walks (:meth:`State.raised`); :func:`guards`
turns the records into statements, :func:`unused_checks` forces the evaluation of values the
statement would otherwise never compute.
"""
from __future__ import annotations

import re
from typing import Any

from ..store.dialect import SQLITE
from .model import Part


# slr_num(:aN): a value bound from Python (kb.query args) used as a number
NUM_ARG = re.compile(r"slr_num\(:(a\d+)\)")
# a value bound from Python matched with a stored time (Unification.match_time): an integer
# beyond 64 bits is bound as JSON text, which SQL cannot compare by value
TIME_ARG = re.compile(r"typeof\(:(a\d+)\) IN \('integer', 'real'\)")


def guards(raising: list, branches: list, dialect: Any = SQLITE) -> list[str]:
    """Statements that evaluate, over exactly the rows Prolog reaches it with, every goal
    that may raise and that a branch's later goals could filter first.

    Prolog runs the goals of a branch left to right, so ``X is A / 0`` raises on every row
    that reached it, even when a later ``A > 100`` would have rejected the row; SQLite
    applies conditions in its own order (an index on ``arg1`` serves ``A > 100`` first) and
    computes a value only where it is used. A guard ``SELECT count(expr) FROM <the tables
    before the goal> WHERE <the conditions before it>`` runs before the statement: an error
    there hands the query to the interpreter, which raises it. A goal that is the last of
    every branch it is in needs none (the statement evaluates it on every row that reaches
    it); one in a branch that failed at compile time (``X is A / 0, fail``) always does.
    ``branches``: (froms, conds) of every branch, before the forced checks; the goals of a
    findall or ``\\+`` subquery are checked over the rows of the goals before it joined with
    the subquery's own (for ``\\+``, which stops at its first solution, a superset: an
    error there only costs the interpreter's run).

    >>> froms = [("ev_p", "t0", None)]
    >>> raising = [("slr_div(t0.arg1, 0)", froms, ["t0.robot = 1"], False, False)]
    >>> guards(raising, [(froms, ["t0.robot = 1", "t0.arg1 > 100"], [0])])
    ['SELECT count(slr_div(t0.arg1, 0)) FROM ev_p AS t0 WHERE t0.robot = 1']
    >>> guards(raising, [(froms, ["t0.robot = 1"], [0])])  # the branch's last goal: none
    []
    """
    out = []
    for i, (expr, froms, conds, is_cond, first) in enumerate(raising):
        if dialect.raising_calls(expr) == len(NUM_ARG.findall(expr)):
            # only slr_num(:aN), a number bound from Python: it raises for every row or for
            # none, and SqlPlan.run leaves a non-number argument to the interpreter
            continue
        nf, nc = len(froms), len(conds)
        after = nc + (1 if is_cond else 0)
        needed = True
        if first:
            # in \+ or an if-then-else condition SQLite stops at the first row it finds, in
            # its own order, not Prolog's: guard every row (a superset of Prolog's)
            branches_in = []
        else:
            branches_in = [(f, c) for f, c, live in branches if i in live]
        for pfroms, pconds in branches_in:
            if _filtered_first(pfroms, nf, pconds[after:], _call_key(expr)):
                needed = True
                break
            needed = False
        if needed:
            sql = Part(froms, conds, []).select([f"count({expr})"])
            if sql not in out:
                out.append(sql)
    return out


_DET_CHECK = re.compile(r"slr_det\((\d+), -1")


def _call_key(expr: str) -> str:
    """The text whose presence in a later condition means evaluating it evaluates ``expr``
    first (SQLite computes a function's arguments before the call): a builtin's call site,
    or the arithmetic of an ``is``."""
    m = _DET_CHECK.match(expr)
    if m:
        return f"slr_det({m.group(1)}, "
    if expr.startswith("(") and expr.endswith(") IS NOT NULL"):
        return expr[1:-len(") IS NOT NULL")]
    return expr


def _filtered_first(froms: list, nf: int, later: list, key: str) -> bool:
    """Can the goals after a raising one reject a row before SQLite evaluates it?

    Yes when any table or condition follows it, unless that condition computes the raising
    goal itself (``key``: SQLite computes a function's arguments before the call). A later
    table's condition is not safe either: the tables join in goal order (CROSS JOIN), but
    SQLite carries constraints over join equalities (``S = T, S > 3`` also filters ``T``
    in the earlier table's loop), and a condition that names no table may be tested in
    any loop."""
    return len(froms) > nf or any(key not in c for c in later)


def unused_checks(checks: list, used: list) -> list[str]:
    """Conditions forcing the evaluation of the ``checks`` no used SQL text contains.

    >>> unused_checks(["slr_div(t0.arg1, 0)", "t0.arg2"], ["t0.arg2 > 3"])
    ['(slr_div(t0.arg1, 0)) IS NOT NULL']
    """
    return [f"({c}) IS NOT NULL" for c in checks if not any(c in u for u in used)]
