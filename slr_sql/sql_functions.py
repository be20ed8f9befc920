"""The Python functions SQL statements call, listed once: :data:`SQL_FUNCTIONS`.

The query compiler (:mod:`slr_sql.sqlcompile`, through the store's dialect printers) and the
event rules' SQL (:mod:`slr_sql.cep.sqlgen`) print calls of these functions; the facade hands
the list to its store (``store.install_functions``) as it opens it, and the SQLite backend
registers every entry on each connection it opens. Nothing else registers a function
(``tests/test_sql_functions.py`` scans for it). On PostgreSQL each entry is either a
function a migration installs under the same name and number of arguments, or marked
interpreter only: the dialect then refuses to print it and the goal runs in the
interpreter (docs/architecture.md).

* ``slr_j``: a stored value's form inside JSON (list elements, compound arguments);
* ``slr_num``: a stored value as a number in arithmetic (raises on anything else);
* ``slr_key``: what an index over a text users choose holds of it on PostgreSQL (the text
  under 64 characters, else its SHA-256), so that values of any length are keys;
* ``slr_ar1``, ``slr_ar2``: Prolog's arithmetic functions (big integers refused, as the
  interpreter refuses them in a 64-bit column);
* ``slr_det``: a det builtin or ``kb.define`` predicate at a call site of the compiler;
* ``slr_cep_cmp``, ``slr_cep_arith``: an event rule's comparison as Prolog evaluates it;
* ``slr_sign_bit``: whether a float's sign bit is set (on SQLite, whose ``=`` takes -0.0
  for 0.0);
* aggregates ``slr_sum``, ``slr_max``, ``slr_min``, ``slr_setof``.

>>> [name for name, arity in SQL_FUNCTIONS.names()][:3]
['slr_j', 'slr_num', 'slr_key']
>>> from slr_sql.store import EventStore
>>> store = EventStore(None); store.install_functions(SQL_FUNCTIONS)
>>> store.sql("SELECT slr_ar2('+', 1, 2), slr_cep_cmp('<', 1, 2)")[1]
[(3, 1)]
"""
from __future__ import annotations

import hashlib

from functools import lru_cache
from math import copysign
from json.encoder import encode_basestring as _quote  # C-accelerated; keeps non-ASCII
from typing import Any

from .arith import apply_binary
from .builtins import BuiltinMachine, call_python_pred, sorted_unique
from .encoding import INT64_MAX, INT64_MIN, decode, encode, encode_json
from .sqlcompile import SITES, ColRef, resolve
from .store.functions import Native, SqlAggregate, SqlFunction, SqlFunctions
from .terms import Struct, Var, deref, list_items, make_list

__all__ = ["SQL_FUNCTIONS"]


def statement_deadline(store: Any) -> float | None:
    """The deadline of the compiled statement running on ``store`` now (None: no store).

    >>> from slr_sql.store import EventStore
    >>> statement_deadline(None), statement_deadline(EventStore(None))  # no statement running
    (None, None)
    """
    return None if store is None else store.statement_deadline


def _key(v):
    """What a PostgreSQL index over a text users choose holds of it (``slr_key``,
    pg_0013): the text when shorter than 64 characters, else the SHA-256 of its UTF-8."""
    if v is None:
        return None
    v = str(v)
    return v if len(v) < 64 else hashlib.sha256(v.encode("utf-8", "surrogatepass")).hexdigest()


def _num(v):
    if type(v) is int or type(v) is float:
        return v
    raise TypeError(f"not a number: {v!r}")


def _checked(r):
    if type(r) is int and not INT64_MIN <= r <= INT64_MAX:
        raise OverflowError("integer beyond 64 bits")
    return r


def _ar2(op, a, b):
    from .arith import evaluate

    return _checked(evaluate(Struct(op, (_num(a), _num(b)))))


def _ar1(op, a):
    from .arith import evaluate

    return _checked(evaluate(Struct(op, (_num(a),))))


def _j(v):
    """slr_j: a column value's inner-JSON form, ``encode_json(decode(v))``. A stored list or
    compound is already in that form (JSON inside and out); an atom is quoted; an integer
    column is 64-bit. The rest (strings, floats, ``{"$atom":..}``) goes the long way."""
    tv = type(v)
    if tv is str:
        c = v[:1]
        if c == "[" or (c == "{" and not v.startswith('{"$atom":"')):
            return v
        if c and c != "{" and c != '"':
            return _quote(v)
    elif tv is int:
        return str(v)
    return encode_json(decode(v))


def _inst(t, values, varmap):
    t = deref(t) if type(t) is Var else t
    tt = type(t)
    if tt is ColRef:
        return values[t.i]
    if tt is Var:
        v = varmap.get(id(t))
        if v is None:
            v = varmap[id(t)] = Var(t.name)
        return v
    if tt is Struct:
        return Struct(t.name, tuple(_inst(a, values, varmap) for a in t.args))
    return t


def _det(sid, i, *inputs):
    site = SITES[sid]
    # repr for floats: -0.0 == 0.0, but atom_length/term_to_atom tell them apart
    key = tuple((float, repr(x)) if type(x) is float else (type(x), x) for x in inputs)
    last = site.last
    if last is not None and last[0] == key:
        result = last[1]
    else:
        values = [decode(x) for x in inputs]
        varmap: dict = {}
        for v in site.outs:
            varmap[id(v)] = Var(v.name)
        args = tuple(_inst(a, values, varmap) for a in site.args)
        m = BuiltinMachine(site.engine)
        # the timeout= of the statement calling it holds inside a long builtin too
        m.deadline = statement_deadline(site.engine.events)
        if site.python:
            ok = call_python_pred(m, site.fn, args)
        else:
            ok = site.fn(m, args)
        if not ok:
            result = None
        else:
            result = [encode(resolve(varmap[id(v)])) for v in site.outs]  # raises if unbound
        site.last = (key, result)
    if result is None:
        return None
    return 1 if i < 0 else result[i]


def _sign_bit(v):
    """slr_sign_bit: 1 for a float whose sign bit is set (-0.0 among them), else 0; SQL's
    ``=`` takes -0.0 for 0.0 and no SQLite built-in shows a zero's sign."""
    return 1 if type(v) is float and copysign(1.0, v) < 0.0 else 0


class _Sum:
    def __init__(self):
        self.v = 0

    def step(self, x):
        self.v = apply_binary("+", self.v, _num(x))

    def finalize(self):
        return _checked(self.v)


class _Max:
    # Prolog's max/2 (max(1, 1.0) is 1.0 in either order), folded as aggregate_all does,
    # from max(X, X) for the first X (max(inf, inf) is float_overflow)
    name = "max"

    def __init__(self):
        self.v = None

    def step(self, x):
        x = _num(x)
        self.v = apply_binary(self.name, x if self.v is None else self.v, x)

    def finalize(self):
        return self.v


class _Min(_Max):
    name = "min"


class _Setof:
    def __init__(self):
        self.items = []

    def step(self, x):
        self.items.append(x)

    def finalize(self):
        items, _ = list_items(decode("[" + ",".join(self.items) + "]"))
        return encode(make_list(sorted_unique(items)))


def _compare(op: str, a: Any, b: Any, decoded: bool = False) -> int:
    """``slr_cep_cmp(op, a, b)``: the comparison ``A op B`` of two stored values as Prolog
    evaluates it (big integers, arithmetic atoms such as ``pi``, expressions); an error is
    false."""
    try:
        if not decoded:
            a, b = decode(a), decode(b)
    except Exception:  # (not a stored value: no match)
        return 0
    return int(compare_terms(op, a, b))


def compare_terms(op: str, a: Any, b: Any) -> bool:
    """The arithmetic comparison ``A op B`` (``<``, ``=:=``, ...) of two ground terms as
    Prolog evaluates it, an error (a type error, an overflow) being false: how an event
    rule's statement decides a comparison of its ``where`` goal (``slr_cep_cmp``,
    ``slr_cep_arith``), and the Python side on a server that calls no Python from SQL.

    >>> from slr_sql.terms import Atom, Struct
    >>> compare_terms("<", Struct("+", (1, 2)), 4), compare_terms("<", Atom("a"), 4)
    (True, False)
    """
    from .arith import evaluate

    try:
        x, y = evaluate(a), evaluate(b)
        if op == "<":
            return x < y
        if op == ">":
            return x > y
        if op == "=<":
            return x <= y
        if op == ">=":
            return x >= y
        if op == "=:=":
            return x == y
        return x != y
    except Exception:  # a type error in Prolog: the candidate does not match
        return False


@lru_cache(maxsize=256)
def _arith_goal(text: str) -> tuple[Any, dict]:
    from .parser import parse_term

    return parse_term(text, "<event rule>")


def _compare_expressions(text: str, *values: Any) -> int:
    """``slr_cep_arith(goal, v0, v1, ...)``: the comparison ``goal`` (its variables named
    ``V0``, ``V1``, ... for the stored values given) as Prolog evaluates it; an error is
    false. The fallback of a pushed comparison whose operands SQL cannot compute exactly."""
    try:
        goal, _ = _arith_goal(text)
        bound = [decode(v) for v in values]

        def put(t: Any) -> Any:
            t = deref(t)
            if type(t) is Var:
                return bound[int(t.name[1:])]
            if type(t) is Struct:
                return Struct(t.name, tuple(put(a) for a in t.args))
            return t

        return _compare(goal.name, put(goal.args[0]), put(goal.args[1]), decoded=True)
    except Exception:  # a type error in Prolog: the candidate does not match
        return 0


SQL_FUNCTIONS = SqlFunctions(
    functions=(
        SqlFunction("slr_j", 1, _j, Native.MIGRATION),
        SqlFunction("slr_num", 1, _num, Native.MIGRATION),
        SqlFunction("slr_key", 1, _key, Native.MIGRATION),
        SqlFunction("slr_ar1", 2, _ar1, Native.INTERPRETER_ONLY),
        SqlFunction("slr_ar2", 3, _ar2, Native.INTERPRETER_ONLY),
        SqlFunction("slr_det", -1, _det, Native.INTERPRETER_ONLY),
        SqlFunction("slr_cep_cmp", 3, _compare, Native.INTERPRETER_ONLY),
        SqlFunction("slr_cep_arith", -1, _compare_expressions, Native.INTERPRETER_ONLY),
        # (PostgreSQL's typed texts tell -0.0 from 0.0: its printers never call it)
        SqlFunction("slr_sign_bit", 1, _sign_bit, Native.INTERPRETER_ONLY),
    ),
    aggregates=(
        SqlAggregate("slr_sum", 1, _Sum, Native.INTERPRETER_ONLY),
        SqlAggregate("slr_max", 1, _Max, Native.INTERPRETER_ONLY),
        SqlAggregate("slr_min", 1, _Min, Native.INTERPRETER_ONLY),
        SqlAggregate("slr_setof", 1, _Setof, Native.INTERPRETER_ONLY),
    ))
"""Every Python function a statement may call, and every aggregate (see the module)."""
