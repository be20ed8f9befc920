"""Compile non-recursive SLR goals to one SQL statement (SPEC §3 "Execution").

The compiler is an *abstract interpreter*: it walks the goal depth-first exactly like the
top-down interpreter does, but instead of values it binds variables to :class:`Col` objects,
SQL expressions that stand for the value one row of the statement will hold. Every path
through the goal tree (every alternative of a ``;``, every clause of a called rule) becomes
one *branch*: a flat ``SELECT`` with its ``FROM`` aliases, ``WHERE`` conditions and ordering
keys. The branches are glued with ``UNION ALL`` and ordered by their keys, which reproduces
the interpreter's depth-first order of solutions:

* an event goal contributes its store-order columns ``t_end, t_start, seq``;
* prev contributes ``t_start, seq`` (its ties), next ``t_end, seq``; a fact table ``ord``;
* a disjunction, a called rule or an if-then-else contributes the index of the alternative
  taken (a constant) *before* the keys of the goals inside it.

Two solutions of different branches share the goals (and so the key columns) up to the first
alternative where they part, and there their alternative indexes decide; keys are padded
with NULL to a common width.

Values in SQL are always in the store's *top-level encoding* (slr_sql.encoding): atoms TEXT,
integers INTEGER, floats REAL, everything else JSON TEXT. Unification of two values is
``a = b AND typeof(a) = typeof(b)`` (SQLite's ``1 = 1.0`` must not unify), simplified when
the kinds are known (time columns are REAL, counts INTEGER). Arithmetic goes through
application-defined functions that call :func:`slr_sql.arith.evaluate` (Prolog's integer and
float rules, errors included) except ``+``/``-``/``*`` on floats, which SQLite computes with
the same IEEE doubles. A function that meets something the interpreter would reject (a type
error, an integer overflow, a non-ground result) raises, and the query is re-run by the
interpreter, which raises the proper error or answers.

Whatever the compiler does not handle exactly raises :class:`Fallback` with the reason.
Handlers are named ``<kind>_sql``.
"""
from __future__ import annotations

import itertools
import math
from typing import Any, Callable

from ..encoding import INT64_MAX, INT64_MIN, Unencodable, encode, encode_json
from ..program import build, event_key, split_event_atom
from ..terms import NIL, Atom, String, Struct, Var, deref, list_items
from .guards import NUM_ARG, guards, unused_checks
from .model import (CYCLIC, NUMERIC, SITES, Col, ColRef, Fallback, Part, Site, State, _fmt,
                    _has_float, _occurs, _shown, _site_ids, has_col, has_var, quote_ident,
                    resolve, term_free_vars)

__all__ = ["Fallback", "Col", "Compiler", "Part", "SITES", "quote_ident"]


# det builtins that only test (never bind): free variables passed to them stay free
NO_BIND = frozenset([
    ("\\=", 2), ("==", 2), ("\\==", 2), ("@<", 2), ("@>", 2), ("@=<", 2), ("@>=", 2),
    ("var", 1), ("nonvar", 1), ("atom", 1), ("number", 1), ("integer", 1), ("float", 1),
    ("atomic", 1), ("compound", 1), ("callable", 1), ("is_list", 1), ("string", 1),
    ("ground", 1),
])


# det builtins with effects outside the answer: never called from SQL
EFFECTS = frozenset([
    ("write", 1), ("print", 1), ("writeq", 1), ("write_canonical", 1), ("writeln", 1),
    ("nl", 0), ("tab", 1), ("format", 1), ("format", 2), ("format", 3), ("halt", 0),
])


COMPARISONS = {"<": "<", ">": ">", "=<": "<=", ">=": ">=", "=:=": "=", "=\\=": "<>"}


CONTROL_FALLBACK = {
    ("!", 0): "cut (!)",
    ("*->", 2): "soft-cut (*->)",
    ("catch", 3): "catch/3",
    ("throw", 1): "throw/1",
    ("findall", 4): "findall/4 (difference list)",
    ("bagof", 3): "bagof/3 (free-variable grouping)",
    ("setof", 3): "setof/3 (free-variable grouping)",
}


class Compiler:
    """Compiles goals for one knowledge base (``ctx`` gives the program, store, builtins).

    ``ctx`` needs: ``program``, ``library``, ``det``, ``nondet``, ``python_preds``,
    ``event_table(name, n)`` -> quoted table or None, ``fact_table(name, n)`` -> quoted table
    or None, ``engine``.
    """

    MAX_BRANCHES = 512

    def __init__(self, ctx: Any, has_at: bool, literal: bool = False):
        self.ctx = ctx
        self.program = ctx.program
        self.has_at = has_at
        self.literal = literal        # views: constants as literals, no parameters
        self.params: dict[str, Any] = {}
        self._const: dict[tuple, str] = {}
        self._alias = itertools.count()
        self.missing: set = set()     # event types without a table when compiled
        self.sites: list[Site] = []
        self.uses_udf = False
        self.modes: list[str] = []
        self._modes_seen: set = set()
        self.branches = 0
        # ((name, n), upper time SQL) of every prev/next: a synchronized query may run the
        # statement once each history is complete up to its time (slr_sql.sync)
        self.time_sites: list[tuple[tuple[str, int], str]] = []

    # ------------------------------------------------------------------ helpers
    def alias(self, prefix: str = "t") -> str:
        return f"{prefix}{next(self._alias)}"

    def const(self, value: Any) -> str:
        """A bound parameter (or, for views, a literal) holding an SQL value."""
        key = (type(value), value)
        if type(value) is float and value != value:
            raise Fallback("NaN constant")
        name = self._const.get(key)
        if name is not None:
            return name
        if self.literal:
            from ..store import sql_literal

            name = sql_literal(value)
        else:
            name = f":c{len(self._const)}"
            self.params[name[1:]] = value
        self._const[key] = name
        return name

    def udf(self, sql: str) -> str:
        self.uses_udf = True
        return sql

    def record_mode(self, goal: Any) -> None:
        if len(self.modes) >= 60:
            return
        g = deref(goal)
        try:
            text = _mode_text(g)
        except Exception:
            return
        if text not in self._modes_seen:
            self._modes_seen.add(text)
            self.modes.append(text)

    # ------------------------------------------------------------------ driver
    def compile(self, goal: Any, emit: Callable[[State], None]) -> None:
        st = self.state = State()
        self.solve((goal, (), None), st, emit)

    def solve(self, cont, st: State, emit) -> None:
        if cont is None:
            self.branches += 1
            if self.branches > self.MAX_BRANCHES:
                raise Fallback(f"more than {self.MAX_BRANCHES} alternative paths")
            emit(st)
            return
        goal, ctx, nxt = cont
        self.goal_sql(goal, ctx, nxt, st, emit)

    def sub_parts(self, goal: Any, ctx: tuple, st: State,
                  project: Callable[[State], list] | None = None,
                  first: bool = False) -> list[Part]:
        """The branches of ``goal`` as a subquery of the current state (bindings undone)."""
        parts: list[Part] = []
        m = st.mark()

        def emit(s: State) -> None:
            # a subquery's branch is a path of its own goals only: the goals before it go
            # on with the goal after the subquery (which may never be reached)
            s.branches.append((list(s.froms), list(s.conds), frozenset(s.live[m[5]:])))
            proj = project(s) if project is not None else None
            conds = list(s.conds[m[1]:])
            keys = list(s.keys[m[2]:])
            conds += unused_checks(s.checks[m[4]:], conds + keys + (proj or []))
            parts.append(Part(list(s.froms[m[0]:]), conds, keys, proj))

        st.first += first
        try:
            self.solve((goal, ctx, None), st, emit)
        finally:
            st.first -= first
        st.restore(m)
        return parts

    # ------------------------------------------------------------------ dispatch
    def goal_sql(self, goal, ctx, nxt, st, emit) -> None:
        g = deref(goal)
        tg = type(g)
        if tg is Var:
            raise Fallback("a goal that is an unbound variable (call/N on an unknown goal)")
        if tg is Col:
            raise Fallback("a goal only known at run time (call/N on an unknown goal)")
        if tg is _Marker:
            return self.marker_sql(g, ctx, nxt, st, emit)
        if tg is Struct:
            name, args = str(g.name), g.args
        elif tg is Atom:
            name, args = str(g), ()
        else:
            raise Fallback(f"{_fmt(g)} is not callable (type error at run time)")
        key = (name, len(args))
        ctl = CONTROL_SQL.get(key)
        if ctl is not None:
            return ctl(self, g, args, ctx, nxt, st, emit)
        if key in CONTROL_FALLBACK:
            raise Fallback(CONTROL_FALLBACK[key])
        pred = self.program.preds.get(key)
        if pred is not None:
            return self.call_sql(pred, ("pred", name, len(args)), args, ctx, nxt, st, emit)
        lib = self.ctx.library.preds.get(key)
        if lib is not None:
            return self.library_sql(key, args, ctx, nxt, st, emit)
        if key in self.ctx.det:
            return self.builtin_sql(key, args, ctx, nxt, st, emit)
        if key in (("prev", 2), ("next", 2), ("next", 3)):
            self.record_mode(g)
            return (self.prev_sql if name == "prev" else self.next_sql)(args, ctx, nxt, st, emit)
        if key in self.ctx.nondet:
            raise Fallback(f"the builtin {name}/{len(args)} has no SQL form")
        fn = self.ctx.python_preds.get(key)
        if fn is not None:
            return self.det_sql(key, fn, True, args, nxt, st, emit)
        if key in self.program.dynamic or key in self.program.temporal:
            return  # fails
        raise Fallback(f"unknown predicate {name}/{len(args)} (existence error at run time)")

    # ------------------------------------------------------------------ unification
    def unify(self, a: Any, b: Any, st: State) -> bool:
        """Unify at compile time; conditions on run-time values go to ``st.conds``.
        False: fails whatever the rows hold."""
        stack = [(a, b)]
        trail = st.trail
        while stack:
            a, b = stack.pop()
            a = deref(a)
            b = deref(b)
            if a is b:
                continue
            ta, tb = type(a), type(b)
            if ta is Var:
                if tb is Struct and _occurs(a, b):
                    raise Fallback(CYCLIC)
                a.ref = b
                trail.append(a)
            elif tb is Var:
                if ta is Struct and _occurs(b, a):
                    raise Fallback(CYCLIC)
                b.ref = a
                trail.append(b)
            elif ta is Col or tb is Col:
                if ta is not Col:
                    a, b = b, a
                cond = self.eq_sql(a, b, st)
                if cond is False:
                    return False
                if cond is not True:
                    st.conds.append(cond)
            elif ta is Struct:
                if tb is not Struct or a.name != b.name or len(a.args) != len(b.args):
                    return False
                stack.extend(zip(a.args, b.args))
            elif ta is not tb or a != b:
                if ta is float and tb is float and a != a and b != b:
                    continue
                return False
        return True

    def eq_sql(self, col: Col, other: Any, st: State | None = None):
        """SQL for "the value of ``col`` unifies with ``other``" (True/False when static).

        A compound term or list with unbound variables is matched part by part
        (:meth:`match_sql`): its conditions go to ``st.conds`` and its variables are bound
        on ``st.trail`` to the elements of the stored value (then the result is True/False).
        """
        k = col.kind
        to = type(other)
        if to is Col:
            k2 = other.kind
            a, b = col.sql, other.sql
            if k == k2 and k in ("float", "int", "text"):
                return f"{a} = {b}"
            if {k, k2} == {"float", "int"} or ("text" in (k, k2) and (k in NUMERIC or k2 in NUMERIC)):
                return False
            return f"({a} = {b} AND typeof({a}) = typeof({b}))"
        if to is Atom or to is String:
            if k in NUMERIC:
                return False
            return f"{col.sql} = {self.const(encode(other))}"
        if to is int:
            if INT64_MIN <= other <= INT64_MAX:
                if k == "float" or k == "text":
                    return False
                if k == "int":
                    return f"{col.sql} = {self.const(other)}"
                return f"({col.sql} = {self.const(other)} AND typeof({col.sql}) = 'integer')"
            if k in NUMERIC:
                return False
            return f"{col.sql} = {self.const(encode(other))}"
        if to is float:
            if other != other:
                raise Fallback("NaN in a goal")
            if k == "int" or k == "text":
                return False
            if k == "float":
                return f"{col.sql} = {self.const(other)}"
            return f"({col.sql} = {self.const(other)} AND typeof({col.sql}) = 'real')"
        if to is Struct:
            if has_col(other) and not has_var(other):
                if k in NUMERIC:
                    return False
                return f"{col.sql} = {self.json_sql(other, top=True)}"
            if has_var(other):
                if st is None:
                    raise Fallback(f"matching a stored value against the compound term "
                                   f"{_fmt(_shown(other))} with unknown parts")
                if k in NUMERIC:
                    return False
                return self.match_sql(col, other, st)
            if k in NUMERIC:
                return False
            try:
                return f"{col.sql} = {self.const(encode(other))}"
            except Unencodable as exc:
                raise Fallback(f"constant cannot be encoded: {exc.reason}")
        raise Fallback(f"cannot compare a stored value with {other!r}")

    # ------------------------------------------------------------------ compound patterns
    # A stored list or compound is JSON text (slr_sql.encoding); a pattern such as [X,Y|T]
    # or f(A, b) becomes conditions on its shape plus one Col per variable, whose SQL gives
    # the element in the top-level column encoding. Paths are ("c", text) when constant
    # (bound as a parameter) or ("x", sql) when they depend on the row (partial lists).
    # Every JSON function reads a *guarded* text: the column value when it starts with
    # "[" or "{" (then it is the encoder's JSON), else NULL (bare atoms such as cup1 are not
    # JSON, and SQLite would raise on them whatever order it evaluates the conditions in).

    MAX_PATTERN_DEPTH = 402  # the encoder stores nothing nested deeper than 400

    def match_sql(self, col: Col, pat: Struct, st: State) -> bool:
        """Unify the value of ``col`` with the compound/list ``pat`` that has unbound
        variables (Prolog unification, part by part). False: fails statically."""
        if col.src is not None:
            text, path = col.src
        else:
            if col.kind == "text":  # findall/aggregate lists: always JSON arrays
                if not (pat.name == "." and len(pat.args) == 2):
                    return False
                text = col.sql
            else:
                text = (f"(CASE WHEN substr({col.sql}, 1, 1) IN ('[', '{{') "
                        f"THEN {col.sql} END)")
            path = ("c", "$")
        return self._match_at(text, path, pat, st, 0)

    def _path_sql(self, path: tuple) -> str:
        return self.const(path[1]) if path[0] == "c" else path[1]

    def _sub_path(self, path: tuple, suffix: str) -> tuple:
        if path[0] == "c":
            return ("c", path[1] + suffix)
        return ("x", f"({path[1]} || {self.const(suffix)})")

    def _elem_col(self, text: str, path: tuple) -> Col:
        """The element at ``path`` of the JSON ``text``, in the top-level encoding: an atom
        inside JSON is a JSON string (TEXT, or {"$atom":..} when it starts with [ { or "),
        {"$string":s} is the string s (a JSON string at the top level); numbers come out as
        INTEGER/REAL, lists and compounds ({"$int":..} too) as the same compact JSON text
        (SQLite copies the tokens of the encoder's text)."""
        p = self._path_sql(path)
        ps = self._path_sql(self._sub_path(path, '."$string"'))
        val = f"json_extract({text}, {p})"
        sql = (f"(CASE json_type({text}, {p}) "
               f"WHEN 'text' THEN (CASE WHEN substr({val}, 1, 1) IN ('[', '{{', '\"') "
               f"THEN '{{\"$atom\":' || ({text} -> {p}) || '}}' ELSE {val} END) "
               f"WHEN 'object' THEN (CASE WHEN json_type({text}, {ps}) = 'text' "
               f"THEN {text} -> {ps} ELSE {text} -> {p} END) "
               f"ELSE {val} END)")
        return Col(sql, "any", (text, path))

    def _match_at(self, text: str, path: tuple, pat: Struct, st: State, depth: int) -> bool:
        if depth > self.MAX_PATTERN_DEPTH:
            return False  # deeper than any stored value
        p = self._path_sql(path)
        subs: list = []
        if pat.name == "." and len(pat.args) == 2:
            items, tail = list_items(pat)
            n = len(items)
            if type(tail) is Atom and tail == "[]":
                # a proper list pattern: a JSON array of exactly n elements
                st.conds.append(f"json_array_length({text}, {p}) = {n}")
                subs = [(self._sub_path(path, f"[{i}]"), x) for i, x in enumerate(items)]
            else:
                # [X1..Xn|T]: a stored proper list (JSON array) of n or more elements, T the
                # rest; or a stored partial list, which is a chain of '.'/2 compounds
                # {".":[H, T]} (the encoder's canonical form: an array is never a tail).
                is_arr = f"json_type({text}, {p}) = 'array'"
                cells = [path]
                for _ in range(n):
                    cells.append(self._sub_path(cells[-1], '."."[1]'))
                dot = '."."'
                chain = " AND ".join(
                    f"json_array_length({text}, {self._path_sql(self._sub_path(c, dot))}) = 2"
                    for c in cells[:n])
                st.conds.append(f"(CASE WHEN {is_arr} THEN json_array_length({text}, {p}) >= {n} "
                                f"ELSE ({chain}) END)")
                for i, x in enumerate(items):
                    in_arr = self._path_sql(self._sub_path(path, f"[{i}]"))
                    in_chain = self._path_sql(self._sub_path(cells[i], '."."[0]'))
                    subs.append((("x", f"(CASE WHEN {is_arr} THEN {in_arr} ELSE {in_chain} END)"),
                                 x))
                removes = ", ".join(self.const(f"$[{i}]") for i in reversed(range(n)))
                rest = self._elem_col(text, cells[n]).sql
                tail_col = Col(f"(CASE WHEN {is_arr} THEN json_remove(json_extract({text}, {p}), "
                               f"{removes}) ELSE {rest} END)")
                subs.append((None, tail))
        else:
            name = str(pat.name)
            if '"' in name or "\\" in name or any(ord(ch) < 0x20 for ch in name):
                raise Fallback(f"matching a stored value against a compound named {name!r} "
                               f"(the name has characters a JSON path cannot hold)")
            key = '."' + name + '"'
            st.conds.append(f"json_array_length({text}, "
                            f"{self._path_sql(self._sub_path(path, key))}) = {len(pat.args)}")
            subs = [(self._sub_path(path, f"{key}[{i}]"), a) for i, a in enumerate(pat.args)]
        for sub, arg in subs:
            if sub is None:
                if not self.unify(arg, tail_col, st):
                    return False
            elif not self._match_elem(text, sub, arg, st, depth + 1):
                return False
        return True

    def _match_elem(self, text: str, path: tuple, arg: Any, st: State, depth: int) -> bool:
        """Unify the element at ``path`` with the pattern argument ``arg``."""
        a = deref(arg)
        ta = type(a)
        if ta is Struct and (has_var(a) or has_col(a) or _has_float(a)):
            return self._match_at(text, path, a, st, depth)
        if ta is Var or ta is Col:
            return self.unify(a, self._elem_col(text, path), st)
        p = self._path_sql(path)
        if ta is float:
            if a != a:
                raise Fallback("NaN in a goal")
            st.conds.append(f"(json_extract({text}, {p}) = {self.const(a)} "
                            f"AND json_type({text}, {p}) = 'real')")
            return True
        # a ground term without floats: its inner JSON text is canonical (one text per term)
        try:
            enc = encode_json(a)
        except Unencodable as exc:
            raise Fallback(f"constant cannot be encoded: {exc.reason}")
        st.conds.append(f"({text} -> {p}) = {self.const(enc)}")
        return True

    # ------------------------------------------------------------------ values
    def value_sql(self, t: Any) -> str:
        """SQL for a bound term's encoded value (a Col, or a ground constant)."""
        t = deref(t)
        if type(t) is Col:
            return t.sql
        if has_var(t):
            raise Fallback(f"{_fmt(_shown(t))} is not ground")
        if has_col(t):
            return self.json_sql(t, top=True)
        try:
            return self.const(encode(t))
        except Unencodable as exc:
            raise Fallback(f"constant cannot be encoded: {exc.reason}")

    def json_sql(self, t: Any, top: bool = False) -> str:
        """SQL text expression of the encoding of a term built from Cols and constants:
        its inner-JSON form (``top``: the top-level column form, only for compounds/lists)."""
        t = deref(t)
        tt = type(t)
        if tt is Col:
            if t.src is not None:  # an element of stored JSON: its text there is canonical
                return f"({t.src[0]} -> {self._path_sql(t.src[1])})"
            return self.udf(f"slr_j({t.sql})")
        if tt is Var:
            raise Fallback(f"a template with the unbound variable {t.name} (findall of "
                           f"non-ground terms)")
        if not has_col(t):
            try:
                return self.const(encode_json(t))
            except Unencodable as exc:
                raise Fallback(f"constant cannot be encoded: {exc.reason}")
        if tt is Struct:
            if t.name == "." and len(t.args) == 2:
                items, tail = list_items(t)
                if not (type(tail) is Atom and tail == "[]"):
                    raise Fallback("a partial list in a template")
                inner = " || ',' || ".join(self.json_sql(x) for x in items)
                return f"('[' || {inner} || ']')"
            inner = " || ',' || ".join(self.json_sql(x) for x in t.args)
            name = self.const(encode_json(Atom(t.name)))
            return "('{' || " + name + " || ':[' || " + inner + " || ']}')"
        raise Fallback(f"cannot encode {t!r}")

    # ------------------------------------------------------------------ arithmetic
    def arith_sql(self, t: Any):
        """(sql, kind) of an arithmetic expression, or ('const', value) when constant."""
        t = deref(t)
        tt = type(t)
        if tt is int or tt is float:
            return None, t
        if tt is Var:
            raise Fallback(f"the unbound variable {t.name} in arithmetic (instantiation error)")
        if tt is Col:
            if t.kind in NUMERIC:
                return t.sql, t.kind
            if t.kind == "text":
                raise Fallback("arithmetic on a list value")
            return self.udf(f"slr_num({t.sql})"), "num"
        if not has_col(t):
            if has_var(t):
                raise Fallback(f"unbound variable in the arithmetic expression {_fmt(_shown(t))}")
            from ..arith import evaluate

            if tt is Atom and t in ("random", "cputime", "realtime"):
                raise Fallback(f"the non-deterministic function {t}")
            if tt is Struct and any(deref(a) in ("random", "cputime", "realtime")
                                    for a in _atoms(t)):
                raise Fallback("a non-deterministic arithmetic function")
            try:
                return None, evaluate(t)
            except Exception as exc:
                raise Fallback(f"arithmetic error: {exc}")
        if tt is Struct and len(t.args) in (1, 2):
            from ..arith import BINARY, UNARY

            op = str(t.name)
            subs = [self.arith_sql(a) for a in t.args]
            if len(subs) == 2 and op in BINARY:
                (sa, va), (sb, vb) = subs
                if op in ("+", "-", "*") and _floatish(sa, va) and _floatish(sb, vb) \
                        and (_is_float(sa, va) or _is_float(sb, vb)):
                    xa = sa if sa is not None else self.const(float(va))
                    xb = sb if sb is not None else self.const(float(vb))
                    return f"({xa} {op} {xb})", "float"
                xa = sa if sa is not None else self.const(va)
                xb = sb if sb is not None else self.const(vb)
                return self.udf(f"slr_ar2({self.const(op)}, {xa}, {xb})"), "num"
            if len(subs) == 1 and op in UNARY:
                (sa, va), = subs
                xa = sa if sa is not None else self.const(va)
                return self.udf(f"slr_ar1({self.const(op)}, {xa})"), "num"
        raise Fallback(f"arithmetic expression {_fmt(_shown(t))} has no SQL form")

    def num_sql(self, t: Any) -> str:
        sql, v = self.arith_sql(t)
        if sql is None:
            if type(v) is float and v != v:
                raise Fallback("NaN in arithmetic")
            return self.const(v)
        return sql

    def time_sql(self, t: Any) -> str:
        """A time argument of prev/next: float(evaluate(t))."""
        sql, v = self.arith_sql(t)
        if sql is None:
            try:
                f = float(v)
            except OverflowError:
                raise Fallback("time out of range")
            if f != f:
                raise Fallback("NaN time")
            return self.const(f)
        return sql

    # ------------------------------------------------------------------ control
    def conj_sql(self, g, args, ctx, nxt, st, emit):
        self.solve((args[0], ctx, (args[1], ctx, nxt)), st, emit)

    def true_sql(self, g, args, ctx, nxt, st, emit):
        self.solve(nxt, st, emit)

    def fail_sql(self, g, args, ctx, nxt, st, emit):
        return

    def disj_sql(self, g, args, ctx, nxt, st, emit):
        left = deref(args[0])
        if type(left) is Struct and len(left.args) == 2 and left.name == "->":
            return self.ite_sql(left.args[0], left.args[1], args[1], ctx, nxt, st, emit)
        if type(left) is Struct and len(left.args) == 2 and left.name == "*->":
            raise Fallback("soft-cut (*->)")
        alts = [args[0]]
        right = deref(args[1])
        # flatten a right-nested chain a ; b ; c (but not an if-then-else inside it)
        while type(right) is Struct and right.name == ";" and len(right.args) == 2:
            inner_left = deref(right.args[0])
            if type(inner_left) is Struct and inner_left.name in ("->", "*->") \
                    and len(inner_left.args) == 2:
                break
            alts.append(right.args[0])
            right = deref(right.args[1])
        alts.append(right)
        for i, alt in enumerate(alts):
            m = st.mark()
            st.keys.append(str(i))
            self.solve((alt, ctx, nxt), st, emit)
            st.restore(m)

    def ifthen_sql(self, g, args, ctx, nxt, st, emit):
        self.ite_sql(args[0], args[1], Atom("fail"), ctx, nxt, st, emit)

    def ite_sql(self, cond, then, other, ctx, nxt, st, emit):
        """``( C -> T ; E )``: T after C's first solution, else E when C has none."""
        parts = self.sub_parts(cond, ctx, st, first=True)
        if len(parts) > 1 and any(p.froms for p in parts):
            raise Fallback("if-then-else whose condition has several alternatives over "
                           "stored data (first solution of a union)")
        count = [0]
        m0 = st.mark()
        info = {"m": m0, "parts": parts, "count": count, "ctx": ctx, "cond": cond}
        if parts:
            st.keys.append("0")
            marker = _Marker(info)
            self.solve((cond, ctx, (marker, ctx, (then, ctx, nxt))), st, emit)
            st.restore(m0)
        # else: no solution of C
        m = st.mark()
        st.keys.append("1")
        ok = True
        for p in parts:
            if not p.froms and not p.conds:
                ok = False  # C always succeeds
                break
        if ok:
            if parts:
                st.conds.append(self.not_exists(parts))
            self.solve((other, ctx, nxt), st, emit)
        st.restore(m)

    def marker_sql(self, marker: "_Marker", ctx, nxt, st, emit):
        info = marker.info
        m0 = info["m"]
        parts = info["parts"]
        i = info["count"][0]
        info["count"][0] += 1
        # C yields one solution: its own ordering keys go (the branch key "0" stays)
        saved_keys = st.keys[m0[2] + 1:]
        del st.keys[m0[2] + 1:]
        m = st.mark()
        froms = st.froms[m0[0]:]
        if froms:
            # C's first solution in C's order: the ids of its rows are those of the first row
            trail = st.trail[m0[3]:]
            saved = [(v, v.ref) for v in trail]
            for v in reversed(trail):
                v.ref = None
            try:
                sub = self.sub_parts(info["cond"], info["ctx"], State())
            finally:
                for v, ref in saved:
                    v.ref = ref
            if len(sub) != 1 or len(sub[0].froms) != len(froms):
                raise Fallback("if-then-else condition compiled unevenly")
            p = sub[0]
            ids = ", ".join(f"{a}.{idc}" for _, a, idc in froms)
            sub_ids = ", ".join(f"{a}.{idc}" for _, a, idc in p.froms)
            order = (" ORDER BY " + ", ".join(p.keys)) if p.keys else ""
            sql = p.select([sub_ids]) + order + " LIMIT 1"
            st.conds.append(f"{ids} = ({sql})" if len(froms) == 1 else f"({ids}) = ({sql})")
        else:
            for p in parts[:i]:
                st.conds.append(self.not_exists([p]))
        self.solve(nxt, st, emit)
        st.restore(m)
        st.keys.extend(saved_keys)

    def not_exists(self, parts: list[Part]) -> str:
        return "NOT " + self.exists(parts)

    def exists(self, parts: list[Part]) -> str:
        return "EXISTS (" + " UNION ALL ".join(p.select(["1"]) for p in parts) + ")"

    def neg_sql(self, g, args, ctx, nxt, st, emit):
        self.record_mode(g)
        parts = self.sub_parts(args[0], ctx, st, first=True)
        for p in parts:
            if not p.froms and not p.conds:
                return  # the goal always succeeds: \+ fails
        m = st.mark()
        if parts:
            st.conds.append(self.not_exists(parts))
        self.solve(nxt, st, emit)
        st.restore(m)

    def call_n_sql(self, g, args, ctx, nxt, st, emit):
        goal = deref(args[0])
        if type(goal) in (Var, Col):
            raise Fallback("call/N on an unknown goal")
        if len(args) > 1:
            if type(goal) is Atom:
                goal = Struct(goal, tuple(args[1:]))
            elif type(goal) is Struct:
                goal = Struct(goal.name, goal.args + tuple(args[1:]))
            else:
                raise Fallback("call/N on a non-callable term (type error)")
        self.solve((goal, ctx, nxt), st, emit)

    def caret_sql(self, g, args, ctx, nxt, st, emit):
        ev = split_event_atom(g)
        if ev is None:
            return self.solve((args[1], ctx, nxt), st, emit)
        self.record_mode(g)
        return self.event_sql(ev, ctx, nxt, st, emit)

    def forall_sql(self, g, args, ctx, nxt, st, emit):
        rewritten = Struct("\\+", (Struct(",", (args[0], Struct("\\+", (args[1],)))),))
        self.solve((rewritten, ctx, nxt), st, emit)

    # ------------------------------------------------------------------ events
    def row_unify(self, pattern: tuple, alias: str, n: int, st: State) -> bool:
        cols = [Col(f"{alias}.arg{i + 1}") for i in range(n)]
        cols += [Col(f"{alias}.t_start", "float"), Col(f"{alias}.t_end", "float")]
        for p, c in zip(pattern, cols):
            if not self.unify(p, c, st):
                return False
        return True

    def event_table(self, name: str, n: int) -> str | None:
        table = self.ctx.event_table(name, n)
        if table is None:
            self.missing.add((name, n))
        return table

    def event_sql(self, ev, ctx, nxt, st, emit):
        atom, s, e = ev
        atom = deref(atom)
        if type(atom) not in (Struct, Atom):
            raise Fallback("an event goal whose name is not known")
        name, n = event_key(atom)
        args = tuple(atom.args) if type(atom) is Struct else ()
        rules = self.program.temporal.get((name, n))
        has_rules = rules is not None and bool(rules.clauses)
        table = self.event_table(name, n)
        if table is not None:
            m = st.mark()
            if has_rules:
                st.keys.append("0")
            alias = self.alias()
            st.froms.append((table, alias, "seq"))
            if self.row_unify(args + (s, e), alias, n, st):
                if self.has_at:
                    st.conds.append(f"{alias}.t_end <= :at")
                st.keys.extend([f"{alias}.t_end", f"{alias}.t_start", f"{alias}.seq"])
                self.solve(nxt, st, emit)
            st.restore(m)
        if has_rules:
            self.clauses_sql(rules, ("event", name, n), args + (s, e), ctx, nxt, st, emit,
                             offset=1)

    def _prev_next_pattern(self, t):
        ev = split_event_atom(t)
        if ev is None:
            raise Fallback("prev/next of something that is not an event atom (error at run time)")
        atom, s, e = ev
        atom = deref(atom)
        if type(atom) not in (Struct, Atom):
            raise Fallback("prev/next of an event with an unknown name")
        name, n = event_key(atom)
        args = tuple(atom.args) if type(atom) is Struct else ()
        return name, n, args + (s, e)

    def _interval(self, t):
        t = deref(t)
        if type(t) is Struct and t.name == "." and len(t.args) == 2:
            items, tail = list_items(t)
            if len(items) == 2 and type(tail) is Atom and tail == "[]":
                return self.time_sql(items[0]), self.time_sql(items[1])
            raise Fallback("a malformed interval (type error at run time)")
        return None

    def _sandbox(self, pattern, table, n, st):
        """Conditions of the pattern on a fresh alias, bindings undone; None: never matches."""
        q = self.alias("q")
        m = st.mark()
        st.nested += 1   # these conditions go into a subquery on q, not into the branch
        try:
            ok = self.row_unify(pattern, q, n, st)
        finally:
            st.nested -= 1
        conds = list(st.conds[m[1]:])
        st.restore(m)
        return (q, conds) if ok else None

    def prev_sql(self, args, ctx, nxt, st, emit):
        name, n, pattern = self._prev_next_pattern(args[0])
        iv = self._interval(args[1])
        if iv is None:
            if type(deref(args[1])) is Var:
                raise Fallback("prev/2 with an unbound time (instantiation error)")
            lo, hi = None, self.time_sql(args[1])
        else:
            lo, hi = iv
        self.time_sites.append(((name, n), hi))
        m0 = st.mark()
        self._time_checks(st, lo, hi)
        try:
            self._prev_rows(name, n, pattern, lo, hi, nxt, st, emit)
        finally:
            st.restore(m0)

    def _time_checks(self, st, *times) -> None:
        """Prolog evaluates a prev/next time before it looks at the history (an error even
        when no event matches): one computed through an slr_ function is tested here."""
        for t in times:
            if t is not None and "slr_" in t:
                st.conds.append(f"({t}) IS NOT NULL")

    def _prev_rows(self, name, n, pattern, lo, hi, nxt, st, emit):
        table = self.event_table(name, n)
        if table is None:
            return
        sb = self._sandbox(pattern, table, n, st)
        if sb is None:
            return
        q, qconds = sb
        qconds.append(f"{q}.t_end <= {hi}")
        if lo is not None:
            qconds.append(f"{q}.t_start >= {lo}")
        sub = (f"(SELECT {q}.t_end FROM {table} AS {q} WHERE {' AND '.join(qconds)} "
               f"ORDER BY {q}.t_end DESC LIMIT 1)")
        m = st.mark()
        p = self.alias("p")
        st.froms.append((table, p, "seq"))
        if self.row_unify(pattern, p, n, st):
            st.conds.append(f"{p}.t_end = {sub}")
            if lo is not None:
                st.conds.append(f"{p}.t_start >= {lo}")
            st.keys.extend([f"{p}.t_start", f"{p}.seq"])
            self.solve(nxt, st, emit)
        st.restore(m)

    def next_sql(self, args, ctx, nxt, st, emit):
        name, n, pattern = self._prev_next_pattern(args[0])
        if len(args) == 2:
            iv = self._interval(args[1])
            if iv is None:
                raise Fallback("next/2 without an interval (error at run time)")
            lo, hi = iv
        else:
            lo, hi = self.time_sql(args[1]), self.time_sql(args[2])
        self.time_sites.append(((name, n), hi))
        m0 = st.mark()
        self._time_checks(st, lo, hi)
        try:
            self._next_rows(name, n, pattern, lo, hi, nxt, st, emit)
        finally:
            st.restore(m0)

    def _next_rows(self, name, n, pattern, lo, hi, nxt, st, emit):
        table = self.event_table(name, n)
        if table is None:
            return
        sb = self._sandbox(pattern, table, n, st)
        if sb is None:
            return
        q, qconds = sb
        qconds.append(f"{q}.t_start >= {lo}")
        qconds.append(f"{q}.t_start <= {hi}")
        qconds.append(f"{q}.t_end <= {hi}")
        sub = (f"(SELECT {q}.t_start FROM {table} AS {q} WHERE {' AND '.join(qconds)} "
               f"ORDER BY {q}.t_start LIMIT 1)")
        m = st.mark()
        p = self.alias("p")
        st.froms.append((table, p, "seq"))
        if self.row_unify(pattern, p, n, st):
            st.conds.append(f"{p}.t_start = {sub}")
            st.conds.append(f"{p}.t_end <= {hi}")
            st.keys.extend([f"{p}.t_end", f"{p}.seq"])
            self.solve(nxt, st, emit)
        st.restore(m)

    # ------------------------------------------------------------------ rules and facts
    def call_sql(self, pred, node, args, ctx, nxt, st, emit):
        self.record_mode(Struct(node[1], args) if args else Atom(node[1]))
        table = self.ctx.fact_table(node[1], node[2]) if len(pred.clauses) > 4 else None
        if table is not None:
            return self.facts_sql(table, node, args, ctx, nxt, st, emit)
        self.clauses_sql(pred, node, args, ctx, nxt, st, emit, offset=0)

    def clauses_sql(self, pred, node, args, ctx, nxt, st, emit, offset: int):
        if node in ctx:
            raise Fallback(f"recursion: {node[1]}/{node[2]} calls itself"
                           + (f" (through {', '.join(f'{c[1]}/{c[2]}' for c in ctx[ctx.index(node) + 1:])})"
                              if ctx.index(node) + 1 < len(ctx) else ""))
        inner = ctx + (node,)
        for i, clause in enumerate(pred.clauses):
            m = st.mark()
            st.keys.append(str(i + offset))
            frame = [None] * clause.nslots
            ok = True
            for h, a in zip(clause.head, args):
                if not self.unify(build(h, frame), a, st):
                    ok = False
                    break
            if ok:
                cont = nxt
                for g in reversed(clause.body):
                    cont = (build(g, frame), inner, cont)
                self.solve(cont, st, emit)
            st.restore(m)

    def facts_sql(self, table, node, args, ctx, nxt, st, emit):
        m = st.mark()
        alias = self.alias("f")
        st.froms.append((table, alias, "ord"))
        ok = True
        for i, a in enumerate(args):
            if not self.unify(a, Col(f"{alias}.arg{i + 1}"), st):
                ok = False
                break
        if ok:
            st.keys.append(f"{alias}.ord")
            self.solve(nxt, st, emit)
        st.restore(m)

    def library_sql(self, key, args, ctx, nxt, st, emit):
        name = key[0]
        if key == ("member", 2):
            items, tail = list_items(args[1])
            if type(tail) is Atom and tail == "[]" and not any(type(deref(x)) is Col
                                                                 for x in [args[1]]):
                alts = [Struct("=", (args[0], x)) for x in items]
                for i, alt in enumerate(alts):
                    m = st.mark()
                    st.keys.append(str(i))
                    self.solve((alt, ctx, nxt), st, emit)
                    st.restore(m)
                return
            raise Fallback("member/2 over a list only known at run time")
        if key == ("once", 1):
            return self.ite_sql(args[0], Atom("true"), Atom("fail"), ctx, nxt, st, emit)
        if key == ("ignore", 1):
            return self.ite_sql(args[0], Atom("true"), Atom("true"), ctx, nxt, st, emit)
        raise Fallback(f"the library predicate {name}/{key[1]} (recursive or with cut) "
                       f"has no SQL form")

    # ------------------------------------------------------------------ builtins
    def builtin_sql(self, key, args, ctx, nxt, st, emit):
        name = key[0]
        if key == ("=", 2):
            m = st.mark()
            if self.unify(args[0], args[1], st):
                self.solve(nxt, st, emit)
            st.restore(m)
            return
        if name in COMPARISONS and len(args) == 2:
            a_sql, a_v = self.arith_sql(args[0])
            b_sql, b_v = self.arith_sql(args[1])
            if a_sql is None and b_sql is None:
                from ..builtins import DET

                if DET[key](None, (a_v, b_v)):
                    self.solve(nxt, st, emit)
                return
            xa = a_sql if a_sql is not None else self.num_sql(a_v)
            xb = b_sql if b_sql is not None else self.num_sql(b_v)
            m = st.mark()
            st.conds.append(f"{xa} {COMPARISONS[name]} {xb}")
            self.solve(nxt, st, emit)
            st.restore(m)
            return
        if key == ("is", 2):
            sql, v = self.arith_sql(args[1])
            m = st.mark()
            value = v if sql is None else Col(sql, v)
            if sql is not None and "slr_" in sql:
                # evaluated where the goal stands (its loop level), as Prolog does, even when
                # the value is used only later or not at all
                st.conds.append(f"({sql}) IS NOT NULL")
            if self.unify(args[0], value, st):
                self.solve(nxt, st, emit)
            st.restore(m)
            return
        if key in EFFECTS:
            raise Fallback(f"{name}/{key[1]} has effects (output) and runs in the interpreter")
        self.det_sql(key, self.ctx.det[key], False, args, nxt, st, emit)

    def det_sql(self, key, fn, python, args, nxt, st, emit):
        """A deterministic builtin or ``kb.define`` predicate as the function ``slr_det``."""
        self.record_mode(Struct(key[0], args) if args else Atom(key[0]))
        resolved = [resolve(a) for a in args]
        cols: list[Col] = []
        index: dict[str, int] = {}

        def subst(t):
            t = deref(t)
            if type(t) is Col:
                i = index.get(t.sql)
                if i is None:
                    i = index[t.sql] = len(cols)
                    cols.append(t)
                return ColRef(i)
            if type(t) is Struct:
                return Struct(t.name, tuple(subst(a) for a in t.args))
            return t

        templ = tuple(subst(a) for a in resolved)
        outs = [] if key in NO_BIND else term_free_vars(Struct("t", tuple(resolved)))
        if python and not cols and len(outs) == len(term_free_vars(Struct("t", tuple(resolved)))) \
                and outs and all(type(deref(a)) is Var for a in args):
            raise Fallback(f"the Python predicate {key[0]}/{key[1]} called with every argument "
                           f"unbound (a non-functional mode)")
        site = Site(fn, python, templ, len(cols), outs, self.ctx.engine)
        sid = next(_site_ids)
        SITES[sid] = site
        self.sites.append(site)
        inputs = "".join(f", {c.sql}" for c in cols)
        m = st.mark()
        st.conds.append(self.udf(f"slr_det({sid}, -1{inputs}) IS NOT NULL"))
        ok = True
        for i, v in enumerate(outs):
            if not self.unify(v, Col(self.udf(f"slr_det({sid}, {i}{inputs})")), st):
                ok = False
                break
        if ok:
            self.solve(nxt, st, emit)
        st.restore(m)

    # ------------------------------------------------------------------ collecting
    def findall_sql(self, g, args, ctx, nxt, st, emit):
        self.record_mode(g)
        template, goal, out = args
        parts = self.sub_parts(goal, ctx, st, lambda s: [self.json_sql(resolve(template))])
        if not parts:
            value: Any = NIL
        else:
            value = Col(self.list_sql(parts), "text")
        m = st.mark()
        if type(value) is Col and "slr_" in value.sql:
            st.checks.append(value.sql)
            st.raised(value.sql, len(st.conds), False)
        if self.unify(out, value, st):
            self.solve(nxt, st, emit)
        st.restore(m)

    def ordered_union(self, parts: list[Part], ncols: int) -> str:
        width = max(len(p.keys) for p in parts)
        selects = []
        for p in parts:
            cols = [f"{x} AS v{i}" for i, x in enumerate(p.proj)]
            cols += [f"{k} AS k{i}" for i, k in enumerate(p.keys)]
            cols += [f"NULL AS k{i}" for i in range(len(p.keys), width)]
            selects.append(p.select(cols))
        sql = " UNION ALL ".join(selects)
        if width:
            sql += " ORDER BY " + ", ".join(f"k{i}" for i in range(width))
        return sql

    def list_sql(self, parts: list[Part]) -> str:
        return (f"(SELECT '[' || coalesce(group_concat(v0, ','), '') || ']' FROM "
                f"({self.ordered_union(parts, 1)}))")

    def aggregate_sql(self, g, args, ctx, nxt, st, emit):
        self.record_mode(g)
        spec = deref(args[0])
        goal, out = args[1], args[2]
        if type(spec) is Atom and spec == "count":
            kind, templ = "count", None
        elif type(spec) is Struct and len(spec.args) == 1 and spec.name in (
                "count", "sum", "max", "min", "bag", "set"):
            kind, templ = str(spec.name), spec.args[0]
        else:
            raise Fallback(f"aggregate_all/3 with the spec {_fmt(_shown(spec))}")
        if kind in ("max", "min"):
            t0 = deref(templ)
            if type(t0) is Struct and t0.name == "-" and len(t0.args) == 2:
                raise Fallback("aggregate_all max/min with a witness (X-W)")
        if kind == "count":
            parts = self.sub_parts(goal, ctx, st, lambda s: ["1"])
            value: Any = 0 if not parts else Col(
                "(SELECT count(*) FROM (" + " UNION ALL ".join(p.select(["1"]) for p in parts)
                + "))", "int")
        elif kind in ("bag", "set"):
            parts = self.sub_parts(goal, ctx, st, lambda s: [self.json_sql(resolve(templ))])
            if not parts:
                value = NIL
            elif kind == "bag":
                value = Col(self.list_sql(parts), "text")
            else:
                value = Col(self.udf(f"coalesce((SELECT slr_setof(v0) FROM "
                                     f"({self.ordered_union(parts, 1)})), '[]')"), "text")
        else:
            parts = self.sub_parts(goal, ctx, st, lambda s: [self.num_sql(resolve(templ))])
            fn = {"sum": "slr_sum", "max": "slr_max", "min": "slr_min"}[kind]
            if not parts:
                if kind == "sum":
                    value = 0
                else:
                    return  # max/min of nothing fails
            else:
                sql = f"(SELECT {fn}(v0) FROM ({self.ordered_union(parts, 1)}))"
                if kind == "sum":
                    # a Python aggregate over no rows gives NULL; the sum of nothing is 0
                    sql = f"coalesce({sql}, 0)"
                value = Col(self.udf(sql), "num")
        m = st.mark()
        if type(value) is Col and kind in ("max", "min"):
            st.conds.append(f"{value.sql} IS NOT NULL")
        elif type(value) is Col and "slr_" in value.sql:
            st.checks.append(value.sql)
            st.raised(value.sql, len(st.conds), False)
        if self.unify(out, value, st):
            self.solve(nxt, st, emit)
        st.restore(m)


class _Marker:
    """Pushed after the condition of an if-then-else (see :meth:`Compiler.marker_sql`)."""

    __slots__ = ("info",)

    def __init__(self, info):
        self.info = info


def _floatish(sql, v) -> bool:
    """An operand SQLite's float arithmetic computes exactly as Python does."""
    if sql is None:
        return (type(v) is float and math.isfinite(v)) or (type(v) is int and abs(v) < 2 ** 53)
    return v == "float"


def _is_float(sql, v) -> bool:
    return v == "float" if sql is not None else type(v) is float


def _atoms(t):
    stack = [t]
    while stack:
        x = deref(stack.pop())
        if type(x) is Struct:
            stack.extend(x.args)
        else:
            yield x


def _mode_text(g: Any) -> str:
    """``obj(-,+,-)^-``: + bound (known when the goal is reached), - free."""
    def m(t):
        t = deref(t)
        if type(t) is Var:
            return "-"
        if type(t) is Col or not has_var(t):
            return "+"
        return "?"
    ev = split_event_atom(g)
    if ev is not None:
        atom, s, e = ev
        atom = deref(atom)
        name, n = event_key(atom)
        args = atom.args if type(atom) is Struct else ()
        stamp = m(s) if deref(s) is deref(e) else f"[{m(s)},{m(e)}]"
        return f"{name}({','.join(m(a) for a in args)})^{stamp}" if args else f"{name}^{stamp}"
    if type(g) is Struct:
        if g.name in ("prev", "next"):
            inner = _mode_text(deref(g.args[0]))
            return f"{g.name}({inner}, {','.join(m(a) for a in g.args[1:])})"
        if g.name in ("findall", "aggregate_all", "\\+"):
            return f"{g.name}/{len(g.args)}"
        return f"{g.name}({','.join(m(a) for a in g.args)})"
    return str(g)


CONTROL_SQL = {
    (",", 2): Compiler.conj_sql,
    ("true", 0): Compiler.true_sql,
    ("fail", 0): Compiler.fail_sql,
    ("false", 0): Compiler.fail_sql,
    (";", 2): Compiler.disj_sql,
    ("->", 2): Compiler.ifthen_sql,
    ("\\+", 1): Compiler.neg_sql,
    ("not", 1): Compiler.neg_sql,
    ("^", 2): Compiler.caret_sql,
    ("forall", 2): Compiler.forall_sql,
    ("findall", 3): Compiler.findall_sql,
    ("findAll", 3): Compiler.findall_sql,
    ("aggregate_all", 3): Compiler.aggregate_sql,
}
for _n in range(1, 9):
    CONTROL_SQL[("call", _n)] = Compiler.call_n_sql
