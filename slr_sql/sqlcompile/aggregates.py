"""findall/3 and aggregate_all/3: a scalar subquery over the branches of the goal, ordered
as the interpreter finds its solutions, whose value is the list (JSON text), the count, or an
``slr_`` aggregate.

Mixed into :class:`slr_sql.sqlcompile.Compiler` (uses ``self.solve``, ``self.unify``,
``self.sub_parts``, ``self.json_sql``, ``self.num_sql``, ``self.udf``, ``self.record_mode``).
"""
from __future__ import annotations

from typing import Any

from ..terms import NIL, Atom, Struct, deref
from .model import (Col, Fallback, Part, format_for_message, key_columns, resolve,
                    shown_in_message)


class AggregateGoals:
    """Handlers of findall/3 and aggregate_all/3."""

    def findall_sql(self, g, args, ctx, nxt, st, emit):
        self.record_mode(g)
        template, goal, out = args
        self.check_called_body(goal)
        parts = self.sub_parts(goal, ctx, st, lambda s: [self.json_sql(resolve(template))])
        if not parts:
            value: Any = NIL
        else:
            value = Col(self.list_sql(parts), "text")
        m = st.mark()
        if type(value) is Col and self.dialect.may_raise(value.sql):
            st.checks.append(value.sql)
            st.raised(value.sql, len(st.conds), False)
        if self.unify(out, value, st):
            self.solve(nxt, st, emit)
        st.restore(m)

    def union(self, parts: list[Part]) -> tuple[str, list[str]]:
        """The branches as one UNION ALL (``v0``, keys ``k0..``) and its ordering keys."""
        width = max(len(p.keys) for p in parts)
        selects = []
        for p, keys in zip(parts, key_columns(parts, self.dialect)):
            cols = [f"{x} AS v{i}" for i, x in enumerate(p.proj)] + keys
            selects.append(p.select(cols))
        return " UNION ALL ".join(selects), [f"k{i}" for i in range(width)]

    def ordered_union(self, parts: list[Part], ncols: int) -> str:
        union, keys = self.union(parts)
        return union + (" ORDER BY " + ", ".join(keys) if keys else "")

    def list_sql(self, parts: list[Part]) -> str:
        return self.dialect.list_of(*self.union(parts))

    def aggregate_sql(self, g, args, ctx, nxt, st, emit):
        self.record_mode(g)
        spec = deref(args[0])
        goal, out = args[1], args[2]
        self.check_called_body(goal)
        if type(spec) is Atom and spec == "count":
            kind, templ = "count", None
        elif type(spec) is Struct and len(spec.args) == 1 and spec.name in (
                "count", "sum", "max", "min", "bag", "set"):
            kind, templ = str(spec.name), spec.args[0]
        else:
            raise Fallback(f"aggregate_all/3 with the spec {format_for_message(shown_in_message(spec))}")
        if kind in ("max", "min"):
            t0 = deref(templ)
            if type(t0) is Struct and t0.name == "-" and len(t0.args) == 2:
                raise Fallback("aggregate_all max/min with a witness (X-W)")
        if kind == "count":
            parts = self.sub_parts(goal, ctx, st, lambda s: ["1"])
            value: Any = 0 if not parts else Col(
                "(SELECT count(*) FROM (" + " UNION ALL ".join(p.select(["1"]) for p in parts)
                + ")" + self.dialect.subquery_alias + ")", "int")
        elif kind in ("bag", "set"):
            parts = self.sub_parts(goal, ctx, st, lambda s: [self.json_sql(resolve(templ))])
            if not parts:
                value = NIL
            elif kind == "bag":
                value = Col(self.list_sql(parts), "text")
            else:
                value = Col(self.udf(f"coalesce("
                                     f"{self.dialect.aggregate('slr_setof', self.ordered_union(parts, 1))}"
                                     f", '[]')"), "text")
        else:
            parts = self.sub_parts(goal, ctx, st, lambda s: [self.num_sql(resolve(templ))])
            fn = {"sum": "slr_sum", "max": "slr_max", "min": "slr_min"}[kind]
            if not parts:
                if kind == "sum":
                    value = 0
                else:
                    return  # max/min of nothing fails
            else:
                sql = self.dialect.aggregate(fn, self.ordered_union(parts, 1))
                if kind == "sum":
                    # a Python aggregate over no rows gives NULL; the sum of nothing is 0
                    sql = f"coalesce({sql}, 0)"
                value = Col(self.udf(sql), "num")
        m = st.mark()
        if type(value) is Col and kind in ("max", "min"):
            st.conds.append(f"{value.sql} IS NOT NULL")
        elif type(value) is Col and self.dialect.may_raise(value.sql):
            st.checks.append(value.sql)
            st.raised(value.sql, len(st.conds), False)
        if self.unify(out, value, st):
            self.solve(nxt, st, emit)
        st.restore(m)
