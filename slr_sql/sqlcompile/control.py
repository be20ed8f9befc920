"""Control constructs: conjunction, disjunction, if-then-else, negation, call/N, forall.

A disjunction and an if-then-else put the index of the alternative taken among the ordering
keys; a negation or a condition becomes ``NOT EXISTS`` over the branches of its goal
(:meth:`Compiler.sub_parts`).

Mixed into :class:`slr_sql.sqlcompile.Compiler` (uses ``self.solve``, ``self.sub_parts``
and ``self.record_mode``).
"""
from __future__ import annotations

from ..terms import Atom, Struct, Var, deref
from .model import Col, Fallback, Part, State


class ControlGoals:
    """Handlers of the control constructs (see ``CONTROL_SQL`` in the compiler)."""

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
            marker = IfThenMarker(info)
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

    def marker_sql(self, marker: "IfThenMarker", ctx, nxt, st, emit):
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
                sub = self.sub_parts(info["cond"], info["ctx"], State(self.dialect.may_raise))
            finally:
                for v, ref in saved:
                    v.ref = ref
            if len(sub) != 1 or len(sub[0].froms) != len(froms):
                raise Fallback("if-then-else condition compiled unevenly")
            p = sub[0]
            ids = ", ".join(f"{a}.{idc}" for _, a, idc in froms)
            sub_ids = ", ".join(f"{a}.{idc}" for _, a, idc in p.froms)
            # a branch's index among the keys is one constant for all of p's rows; as an
            # ORDER BY term SQLite would read it as a column number
            keys = [k for k in p.keys if not k.isdigit()]
            order = (" ORDER BY " + ", ".join(keys)) if keys else ""
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
        self.check_called_body(args[0])
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
        self.check_called_body(goal)
        self.solve((goal, ctx, nxt), st, emit)

    def forall_sql(self, g, args, ctx, nxt, st, emit):
        self.check_called_body(args[0])
        self.check_called_body(args[1])
        rewritten = Struct("\\+", (Struct(",", (args[0], Struct("\\+", (args[1],)))),))
        self.solve((rewritten, ctx, nxt), st, emit)


class IfThenMarker:
    """Pushed after the condition of an if-then-else (see :meth:`Compiler.marker_sql`)."""

    __slots__ = ("info",)

    def __init__(self, info):
        self.info = info
