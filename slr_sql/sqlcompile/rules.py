"""Calls of user predicates: the clauses of a rule as alternatives (each one's index an
ordering key), a predicate of more than four facts as its fact table when it has one, and
the library predicates that have an SQL form (member/2 over a known list, once/1, ignore/1).

Mixed into :class:`slr_sql.sqlcompile.Compiler` (uses ``self.solve``, ``self.unify``,
``self.alias``, ``self.ite_sql``, ``self.record_mode`` and ``self.ctx``).
"""
from __future__ import annotations

from ..program import build
from ..terms import Atom, Struct, deref, list_items
from .model import Col, Fallback


class RuleGoals:
    """Rules, fact tables and library predicates."""

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
        if key in (("once", 1), ("ignore", 1)):
            self.check_called_body(args[0])     # (the library calls it: call/1's check)
        if key == ("once", 1):
            return self.ite_sql(args[0], Atom("true"), Atom("fail"), ctx, nxt, st, emit)
        if key == ("ignore", 1):
            return self.ite_sql(args[0], Atom("true"), Atom("true"), ctx, nxt, st, emit)
        # (recursive, with a cut, or output and text: with_output_to/2, write/2, ...)
        raise Fallback(f"the library predicate {name}/{key[1]} has no SQL form")
