"""Builtins in SQL: arithmetic (SQLite's own for float ``+ - *``, application-defined
``slr_`` functions for the rest), comparisons, ``=``, ``is``, and every other deterministic
builtin or ``kb.define`` predicate as a call of ``slr_det`` on a :class:`Site`.

Mixed into :class:`slr_sql.sqlcompile.Compiler` (uses ``self.solve``, ``self.unify``,
``self.const``, ``self.udf``, ``self.record_mode``, ``self.ctx``, ``self.sites``).
"""
from __future__ import annotations

import math
import operator
from typing import Any

from ..encoding import INT64_MAX, INT64_MIN
from ..terms import Atom, Struct, Var, deref, list_items
from .model import (NUMERIC, SITES, Col, ColRef, Fallback, Site, format_for_message, shown_in_message, next_site_id,
                    has_col, has_var, resolve, term_free_vars)


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
    # the same to a stream alias (the library's write(user_error, X), ...)
    ("$write_to", 2), ("$print_to", 2), ("$writeq_to", 2), ("$write_canonical_to", 2),
    ("$writeln_to", 2), ("$nl_to", 1), ("$tab_to", 2), ("$print_message", 2),
])


# det builtins that read the store themselves (and wait in a synchronized query, through
# the machine's hooks): never called from inside a statement
STORE_READERS = frozenset([("tf_lookup", 4), ("tf_lookup", 5)])


COMPARISONS = {"<": "<", ">": ">", "=<": "<=", ">=": ">=", "=:=": "=", "=\\=": "<>"}
# two constant operands: decided at compile time by Python's comparison of the numbers, as
# the interpreter's builtins do (without importing them: the engine is not below the compiler)
CONSTANT_COMPARISONS = {"<": operator.lt, ">": operator.gt, "=<": operator.le,
                        ">=": operator.ge, "=:=": operator.eq, "=\\=": operator.ne}


class BuiltinGoals:
    """Arithmetic expressions, comparisons, ``=``, ``is`` and deterministic builtins."""

    dialect: Any
    finite_checks: dict[str, str]

    # ------------------------------------------------------------------ arithmetic
    def arith_sql(self, t: Any):
        """(sql, kind) of an arithmetic expression, or ('const', value) when constant."""
        sql, v, native = self._arith(t)
        return (self._finite(sql) if native else sql), v

    def _finite(self, sql: str) -> str:
        """SQL's own float arithmetic checked as Prolog checks it (float_overflow)."""
        return self.dialect.finite_float(sql)

    def _arith(self, t: Any):
        """(sql, kind, native): native when ``sql`` is SQL's own float ``+ - *``, whose
        overflow the caller checks once for the whole native part (an infinity or NaN stays
        one through + - *, and only an overflow makes one of finite operands)."""
        t = deref(t)
        tt = type(t)
        if tt is int or tt is float:
            return None, t, False
        if tt is Var:
            raise Fallback(f"the unbound variable {t.name} in arithmetic (instantiation error)")
        if tt is Col:
            if t.kind in NUMERIC:
                return t.sql, t.kind, False
            if t.kind == "text":
                raise Fallback("arithmetic on a list value")
            return self.udf(self.dialect.prolog_number(t.sql)), "num", False
        if not has_col(t):
            if has_var(t):
                raise Fallback(f"unbound variable in the arithmetic expression {format_for_message(shown_in_message(t))}")
            from ..arith import evaluate

            if tt is Atom and t in ("random_float", "cputime"):
                raise Fallback(f"the non-deterministic function {t}")
            if tt is Struct and _nondeterministic(t):
                raise Fallback("a non-deterministic arithmetic function")
            try:
                return None, evaluate(t), False
            except Exception as exc:
                raise Fallback(f"arithmetic error: {exc}")
        if tt is Struct and _nondeterministic(t):
            raise Fallback("a non-deterministic arithmetic function")
        if tt is Struct and len(t.args) in (1, 2):
            from ..arith import BINARY, UNARY

            op = str(t.name)
            subs = [self._arith(a) for a in t.args]
            if len(subs) == 2 and op in BINARY:
                (sa, va, na), (sb, vb, nb) = subs
                if op in ("+", "-", "*") and _floatish(sa, va) and _floatish(sb, vb) \
                        and (_is_float(sa, va) or _is_float(sb, vb)):
                    xa = sa if sa is not None else self.const(float(va))
                    xb = sb if sb is not None else self.const(float(vb))
                    return f"({xa} {op} {xb})", "float", True
                xa = self._operand(sa, va, na)
                xb = self._operand(sb, vb, nb)
                return self.udf(self.dialect.arith2(self.const(op), xa, xb)), "num", False
            if len(subs) == 1 and op in UNARY:
                (sa, va, na), = subs
                xa = self._operand(sa, va, na)
                return self.udf(self.dialect.arith1(self.const(op), xa)), "num", False
        raise Fallback(f"arithmetic expression {format_for_message(shown_in_message(t))} has no SQL form")

    def _operand(self, sql, v, native: bool) -> str:
        if sql is None:
            return self.const(v)
        return self._finite(sql) if native else sql

    def num_sql(self, t: Any) -> str:
        sql, v = self.arith_sql(t)
        if sql is None:
            if type(v) is float and v != v:
                raise Fallback("NaN in arithmetic")
            return self.const(v)
        return sql

    def time_sql(self, t: Any) -> str:
        """A time argument of prev/next: float(evaluate(t)). SQL's own float arithmetic is
        left unchecked here (it is used inside the history's subqueries): its overflow check
        is ``self.finite_checks[sql]``, which the goal tests where it stands."""
        sql, v, native = self._arith(t)
        if native:
            self.finite_checks[sql] = self._finite(sql)
            return sql
        if sql is None:
            try:
                f = float(v)
            except OverflowError:
                raise Fallback("time out of range")
            if f != f:
                raise Fallback("NaN time")
            return self.const(f)
        if v != "float":
            # float(N) as the interpreter takes it: 2**53 + 3 is the time 2.0**53 + 4, and
            # SQL would compare the integer with the stored times exactly
            return f"CAST({sql} AS {self.dialect.real})"
        return sql

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
                if CONSTANT_COMPARISONS[name](a_v, b_v):
                    self.solve(nxt, st, emit)
                return
            xa = a_sql if a_sql is not None else self.num_sql(a_v)
            xb = b_sql if b_sql is not None else self.num_sql(b_v)
            m = st.mark()
            st.conds.append(self.dialect.comparison(COMPARISONS[name], xa, _kind(a_sql, a_v),
                                                    xb, _kind(b_sql, b_v)))
            self.solve(nxt, st, emit)
            st.restore(m)
            return
        if key == ("is", 2):
            sql, v, native = self._arith(args[1])
            if native:
                sql = self._finite(sql)
            m = st.mark()
            value = v if sql is None else Col(sql, v)
            if sql is not None and (native or self.dialect.may_raise(sql)):
                # evaluated where the goal stands (its loop level), as Prolog does, even when
                # the value is used only later or not at all
                st.conds.append(f"({sql}) IS NOT NULL")
            if self.unify(args[0], value, st):
                self.solve(nxt, st, emit)
            st.restore(m)
            return
        if key in EFFECTS:
            raise Fallback(f"{name}/{key[1]} has effects (output) and runs in the interpreter")
        if key in STORE_READERS:
            raise Fallback(f"{name}/{key[1]} reads the stored transforms (and waits for them "
                           f"in a synchronized query): it runs in the interpreter")
        self.det_sql(key, self.ctx.det[key], False, args, nxt, st, emit)

    def reverse_sql(self, args, nxt, st, emit):
        """reverse/2 of a list whose end is known when the goal is reached (a proper list,
        a stored value, no list at all) as the deterministic ``$reverse_list``; of a partial
        list, which enumerates one length after another, in the interpreter."""
        _, tail = list_items(resolve(args[0]))
        if type(tail) is Var:
            raise Fallback("reverse/2 of a partial list enumerates lists of each length: "
                           "it runs in the interpreter")
        self.det_sql(("reverse", 2), self.ctx.det[("$reverse_list", 2)], False, args, nxt,
                     st, emit)

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
        inputs = "".join(f", {c.sql}" for c in cols)
        self.dialect.det_call(0, -1, inputs)   # an engine without Python functions refuses
        site = Site(fn, python, templ, len(cols), outs, self.ctx.engine)
        sid = next_site_id()
        SITES[sid] = site
        self.sites.append(site)
        m = st.mark()
        st.conds.append(self.udf(f"{self.dialect.det_call(sid, -1, inputs)} IS NOT NULL"))
        ok = True
        for i, v in enumerate(outs):
            if not self.unify(v, Col(self.udf(self.dialect.det_call(sid, i, inputs))), st):
                ok = False
                break
        if ok:
            self.solve(nxt, st, emit)
        st.restore(m)


def _kind(sql, v) -> str:
    """The kind of a comparison's operand (:meth:`arith_sql`'s pair) for the dialect."""
    if sql is not None:
        return v
    if type(v) is float:
        return "float"
    if -2 ** 53 <= v <= 2 ** 53:
        return "small"
    return "int" if INT64_MIN <= v <= INT64_MAX else "bignum"


def _floatish(sql, v) -> bool:
    """An operand SQLite's float arithmetic computes exactly as Python does."""
    if sql is None:
        return (type(v) is float and math.isfinite(v)) or (type(v) is int and abs(v) < 2 ** 53)
    return v == "float"


def _is_float(sql, v) -> bool:
    return v == "float" if sql is not None else type(v) is float


def _nondeterministic(t) -> bool:
    """An expression with random_float, cputime or random/1 in it: its value differs from
    call to call (never folded at compile time, nor evaluated by SQL, which may evaluate
    an expression more than once)."""
    stack = [t]
    while stack:
        x = deref(stack.pop())
        if type(x) is Struct:
            if x.name == "random" and len(x.args) == 1:
                return True
            stack.extend(x.args)
        elif type(x) is Atom and x in ("random_float", "cputime"):
            return True
    return False
