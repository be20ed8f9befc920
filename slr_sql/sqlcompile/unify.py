"""Unification at compile time: bindings of variables to :class:`Col` and constants, SQL
conditions where a value is known only when the statement runs, stored lists and compounds
matched part by part through SQLite's JSON functions, and the SQL of a term's encoding.

Mixed into :class:`slr_sql.sqlcompile.Compiler` (uses ``self.const`` and ``self.udf``).
"""
from __future__ import annotations

import math
from typing import Any

from ..encoding import INT64_MAX, INT64_MIN, Unencodable, encode, encode_json
from ..terms import Atom, String, Struct, Var, deref, list_items, same_float
from .model import (CYCLIC, NUMERIC, Col, Fallback, State, format_for_message, has_float, occurs_in, shown_in_message,
                    has_col, has_var)


class Unification:
    """Unification, compound patterns on stored values, and encoded values."""

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
                if tb is Struct and occurs_in(a, b):
                    raise Fallback(CYCLIC)
                a.ref = b
                trail.append(a)
            elif tb is Var:
                if ta is Struct and occurs_in(b, a):
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
            elif ta is float and tb is float:
                if not same_float(a, b):
                    return False
            elif ta is not tb or a != b:
                return False
        return True

    def match_time(self, t: Any, col: Col, st: State) -> bool:
        """Match a goal's time term with a stored time column (REAL) by value, as the
        interpreter does (:func:`slr_sql.unify.match_time`): a variable is bound to the
        column, a number compares numerically, a run-time value must be a number equal to
        it; anything else fails. False: fails whatever the rows hold."""
        t = deref(t)
        tt = type(t)
        if tt is Var:
            return self.unify(t, col, st)
        if tt is int:
            try:
                value = float(t)
            except OverflowError:
                return False
            if value != t:
                return False  # no float equals it (beyond 2**53, not a multiple)
            st.conds.append(f"{col.sql} = {self.const(value)}")
            return True
        if tt is float:
            if t != t:
                return False  # NaN equals no stored time
            st.conds.append(f"{col.sql} = {self.const(t)}")
            return True
        if tt is Col:
            if t.kind in NUMERIC:
                st.conds.append(f"{t.sql} = {col.sql}")
            elif t.kind == "any":
                # a stored value or an argument from Python: a number of equal value
                st.conds.append(self.dialect.time_equal(t.sql, col.sql))
            else:
                return False
            return True
        return False

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
            cond = self.dialect.same_value(a, k, b, k2)
            sign = None if self.literal else self.dialect.same_zero_sign(a, b)
            # (an inspection view, read outside slr_sql's connection, has no slr_sign_bit:
            # its joins take -0.0 for 0.0 as SQL does, docs/sql.md)
            return cond if sign is None else f"({cond} AND {sign})"
        if to is Atom or to is String:
            if k in NUMERIC:
                return False
            return f"{col.sql} = {self.stored(encode(other))}"
        if to is int:
            if INT64_MIN <= other <= INT64_MAX:
                if k == "float" or k == "text":
                    return False
                if k == "int":
                    return f"{col.sql} = {self.const(other)}"
                return self.dialect.typed_equal(col.sql, self.stored(other), "integer")
            if k in NUMERIC:
                return False
            return f"{col.sql} = {self.stored(encode(other))}"
        if to is float:
            if other != other:
                raise Fallback("NaN in a goal")
            if k == "int" or k == "text":
                return False
            if k == "float":
                return f"{col.sql} = {self.const(other)}"
            cond = self.dialect.typed_equal(col.sql, self.stored(other), "real")
            return cond if other else self._with_zero_sign(cond, col.sql, other)
        if to is Struct:
            if has_col(other) and not has_var(other):
                if k in NUMERIC:
                    return False
                return f"{col.sql} = {self.json_sql(other, top=True)}"
            if has_var(other):
                if st is None:
                    raise Fallback(f"matching a stored value against the compound term "
                                   f"{format_for_message(shown_in_message(other))} with unknown parts")
                if k in NUMERIC:
                    return False
                return self.match_sql(col, other, st)
            if k in NUMERIC:
                return False
            try:
                return f"{col.sql} = {self.stored(encode(other))}"
            except Unencodable as exc:
                raise Fallback(f"constant cannot be encoded: {exc.reason}")
        raise Fallback(f"cannot compare a stored value with {other!r}")

    def _with_zero_sign(self, cond: str, value: str, zero: float) -> str:
        """``cond`` (``value`` equals the float ``zero``) and the zero's sign: -0.0 and
        0.0 are two terms, one number to SQL's ``=`` on SQLite."""
        sign = self.dialect.zero_sign(value, math.copysign(1.0, zero) < 0.0)
        # (udf: an inspection view, read outside slr_sql's connection, cannot call it)
        return cond if sign is None else f"({cond} AND {self.udf(sign)})"

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
                text = self.dialect.json_guard(col.sql)
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
        d = self.dialect
        val = d.json_part(text, p)
        sql = (f"(CASE {d.json_kind(text, p)} "
               f"WHEN 'text' THEN (CASE WHEN substr({val}, 1, 1) IN ('[', '{{', '\"') "
               f"THEN '{{\"$atom\":' || ({d.json_text(text, p)}) || '}}' ELSE {val} END) "
               f"WHEN 'object' THEN (CASE WHEN {d.json_kind(text, ps)} = 'text' "
               f"THEN {d.json_text(text, ps)} ELSE {d.json_text(text, p)} END) "
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
                st.conds.append(f"{self.dialect.json_length(text, p)} = {n}")
                subs = [(self._sub_path(path, f"[{i}]"), x) for i, x in enumerate(items)]
            else:
                # [X1..Xn|T]: a stored proper list (JSON array) of n or more elements, T the
                # rest; or a stored partial list, which is a chain of '.'/2 compounds
                # {".":[H, T]} (the encoder's canonical form: an array is never a tail).
                is_arr = f"{self.dialect.json_kind(text, p)} = 'array'"
                cells = [path]
                for _ in range(n):
                    cells.append(self._sub_path(cells[-1], '."."[1]'))
                dot = '."."'
                chain = " AND ".join(
                    f"{self.dialect.json_length(text, self._path_sql(self._sub_path(c, dot)))} = 2"
                    for c in cells[:n])
                st.conds.append(f"(CASE WHEN {is_arr} THEN {self.dialect.json_length(text, p)} >= {n} "
                                f"ELSE ({chain}) END)")
                for i, x in enumerate(items):
                    in_arr = self._path_sql(self._sub_path(path, f"[{i}]"))
                    in_chain = self._path_sql(self._sub_path(cells[i], '."."[0]'))
                    subs.append((("x", f"(CASE WHEN {is_arr} THEN {in_arr} ELSE {in_chain} END)"),
                                 x))
                removes = ", ".join(self.const(f"$[{i}]") for i in reversed(range(n)))
                rest = self._elem_col(text, cells[n]).sql
                tail_col = Col(f"(CASE WHEN {is_arr} THEN {self.dialect.json_drop(text, p, removes)} "
                               f"ELSE {rest} END)")
                subs.append((None, tail))
        else:
            name = str(pat.name)
            if "/" in name:
                raise Fallback(f"matching a stored value against a compound named {name!r} "
                               f"(a message type: message terms are stored as objects of "
                               f"fields, read by the interpreter)")
            if '"' in name or "\\" in name or any(ord(ch) < 0x20 for ch in name):
                raise Fallback(f"matching a stored value against a compound named {name!r} "
                               f"(the name has characters a JSON path cannot hold)")
            key = '."' + name + '"'
            st.conds.append(f"{self.dialect.json_length(text, self._path_sql(self._sub_path(path, key)))}"
                            f" = {len(pat.args)}")
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
        if ta is Struct and (has_var(a) or has_col(a) or has_float(a)):
            return self._match_at(text, path, a, st, depth)
        if ta is Var or ta is Col:
            return self.unify(a, self._elem_col(text, path), st)
        p = self._path_sql(path)
        if ta is float:
            if a != a:
                raise Fallback("NaN in a goal")
            cond = (f"({self.dialect.json_part(text, p)} = {self.const(a)} "
                    f"AND {self.dialect.json_kind(text, p)} = 'real')")
            st.conds.append(cond if a else self._with_zero_sign(
                cond, self.dialect.json_part(text, p), a))
            return True
        # a ground term without floats: its inner JSON text is canonical (one text per term)
        try:
            enc = encode_json(a)
        except Unencodable as exc:
            raise Fallback(f"constant cannot be encoded: {exc.reason}")
        st.conds.append(f"({self.dialect.json_text(text, p)}) = {self.const(enc)}")
        return True

    # ------------------------------------------------------------------ values
    def value_sql(self, t: Any) -> str:
        """SQL for a bound term's encoded value (a Col, or a ground constant)."""
        t = deref(t)
        if type(t) is Col:
            return t.sql
        if has_var(t):
            raise Fallback(f"{format_for_message(shown_in_message(t))} is not ground")
        if has_col(t):
            return self.json_sql(t, top=True)
        try:
            return self.stored(encode(t))
        except Unencodable as exc:
            raise Fallback(f"constant cannot be encoded: {exc.reason}")

    def json_sql(self, t: Any, top: bool = False) -> str:
        """SQL text expression of the encoding of a term built from Cols and constants:
        its inner-JSON form (``top``: the top-level column form, only for compounds/lists)."""
        t = deref(t)
        tt = type(t)
        if tt is Col:
            if t.src is not None:  # an element of stored JSON: its text there is canonical
                return f"({self.dialect.json_text(t.src[0], self._path_sql(t.src[1]))})"
            return self.udf(self.dialect.inner_json(t.sql, t.kind))
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
            if "/" in str(t.name):
                raise Fallback(f"building a compound named {str(t.name)!r} from stored values "
                               f"(a message type: message terms are stored as objects of "
                               f"fields)")
            inner = " || ',' || ".join(self.json_sql(x) for x in t.args)
            name = self.const(encode_json(Atom(t.name)))
            return "('{' || " + name + " || ':[' || " + inner + " || ']}')"
        raise Fallback(f"cannot encode {t!r}")
