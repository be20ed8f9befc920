"""Event goals and prev/next.

An event goal ``p(X)^T`` is a row of the table of p/1 (its store order ``t_end, t_start,
seq`` among the ordering keys) or, when p/1 has rules, also each of their clauses. prev
(next) is a row of the same table whose end (start) time is the latest (earliest) one a
subquery on the same pattern finds.

Mixed into :class:`slr_sql.sqlcompile.Compiler` (uses ``self.solve``, ``self.unify``,
``self.alias``, ``self.time_sql``, ``self.clauses_sql``, ``self.record_mode``; reads
``self.ctx``, ``self.program``, ``self.has_at``; records ``self.missing``, ``self.time_sites``,
``self.start_ordered``, ``self.read_types``).
"""
from __future__ import annotations

import re

from ..program import event_key, split_event_atom
from ..store.dialect import short_text
from ..store.sqltext import joined_balanced
from ..terms import Atom, Struct, Var, deref, list_items, make_list
from .model import NUMERIC, Col, Fallback, State

# what a plain equality of an event's first argument may compare it with, for its key's
# equality (a named parameter, or another table's column)
_PLAIN_OPERAND = re.compile(r"(?::\w+|\w+\.arg\d+)\Z")
# an argument from Python (planner.compile_goal names them :a<slot>)
_ARG_PARAM = re.compile(r":a\d+\Z")


def _check_point_stamp(s, e) -> None:
    """``E^T`` with T a findall list known only at run time: SQL would compare the list
    with a time, the interpreter splits it into an interval, so the interpreter answers."""
    s = deref(s)
    if s is deref(e) and type(s) is Col and s.kind not in NUMERIC and s.kind != "any":
        raise Fallback("an event's time that is a list at run time (an interval [S, E])")


def _stamp_may_be_interval(s, e) -> bool:
    """``E^T`` with T a value known only at run time (a stored column, a parameter, a part
    of either): T may be a list ``[S, E]`` there, which makes the goal an interval goal
    (the interpreter splits the stamp when it reaches the goal)."""
    s = deref(s)
    return s is deref(e) and type(s) is Col and s.kind == "any"


class EventGoals:
    """Handlers of event goals (``^``), prev/2 and next/2,3."""

    finite_checks: dict[str, str]

    def origin_sql(self, args, ctx, nxt, st, emit):
        """origin(R, Goal): Goal's rows restricted to robot R (rows of unnamed events have
        none); with R unbound, R is the row's robot and the robots come in name order (the
        robot column leads Goal's ordering keys)."""
        r = deref(args[0])
        if not (type(r) in (Var, Atom) or (type(r) is Col and r.sql.endswith(".robot"))):
            raise Fallback("origin/2 of a robot that is not an atom (an error at run time)")
        g = deref(args[1])
        if type(g) is Struct and g.name == "^" and len(g.args) == 2:
            ev = split_event_atom(g)
            if ev is None:
                raise Fallback("origin/2 of something that is not an event goal")
            atom = deref(ev[0])
            if type(atom) in (Struct, Atom):
                rules = self.program.temporal.get(event_key(atom))
                if rules is not None and rules.clauses:
                    raise Fallback("origin/2 of an event defined by rules")
            return self.event_sql(ev, ctx, nxt, st, emit, origin=r)
        if type(g) is Struct and (g.name, len(g.args)) in (("prev", 2), ("next", 2),
                                                            ("next", 3)):
            return (self.prev_sql if g.name == "prev" else self.next_sql)(
                g.args, ctx, nxt, st, emit, origin=r)
        raise Fallback("origin/2 of a goal that is not an event goal, prev or next "
                       "(an error at run time)")

    def robot_rows(self, alias: str, st: State, origin) -> bool:
        """Restrict ``alias`` to the query's robot and to ``origin`` (a robot term, None:
        any); an unbound origin is bound to the row's robot, which then must be a name."""
        terms = self.robot_terms if origin is None else self.robot_terms + [origin]
        for t in terms:
            if type(deref(t)) is Var:
                st.conds.append(f"{alias}.robot IS NOT NULL")
            if not self.unify(t, Col(f"{alias}.robot"), st):
                return False
        return True

    def caret_sql(self, g, args, ctx, nxt, st, emit):
        ev = split_event_atom(g)
        if ev is None:
            return self.solve((args[1], ctx, nxt), st, emit)
        self.record_mode(g)
        return self.event_sql(ev, ctx, nxt, st, emit)

    def row_unify(self, pattern: tuple, alias: str, n: int, st: State) -> bool:
        """Match an event pattern (data arguments + (start, end)) with a row of ``alias``:
        the data by unification, the stored times by value (``^5`` finds 5.0)."""
        for i, p in enumerate(pattern[:n]):
            since = len(st.conds)
            if not self.unify(p, Col(f"{alias}.arg{i + 1}"), st):
                return False
            if i == 0:
                self.key_conditions(f"{alias}.arg1", st, since)
        return (self.match_time(pattern[n], Col(f"{alias}.t_start", "float"), st)
                and self.match_time(pattern[n + 1], Col(f"{alias}.t_end", "float"), st))

    def key_conditions(self, column: str, st: State, since: int) -> None:
        """An event's first argument is read through the dialect's key indexes (on
        PostgreSQL partial ones: short texts as they are, long ones by slr_key): each plain
        equality of ``column`` with a parameter or another column among the conditions
        from ``since`` on is written as the dialect's ``key_equal`` -- the same rows, with
        the predicate of the index that holds them. A constant's form follows its length;
        an argument from Python gets the short text's form, and ``key_forms`` the long
        one's, which ``SqlPlan`` runs instead for a long text (one form each: the planner
        then keeps a plan for each). Nothing on SQLite, whose index holds the text."""
        dialect = self.dialect
        if dialect.key(column) == column:
            return
        conds = st.conds
        for i in range(since, len(conds)):
            left, equals, right = conds[i].partition(" = ")
            other = right if left == column else left if right == column else None
            if not equals or other is None or not _PLAIN_OPERAND.match(other):
                continue
            if _ARG_PARAM.match(other):
                conds[i] = dialect.key_equal(column, other, other)
                form = (other[1:], conds[i], dialect.key_equal(column, other, "NULL"))
                if form not in self.key_forms:
                    self.key_forms.append(form)
            elif other[1:] in self.params:
                short = short_text(self.params[other[1:]]) is not None
                conds[i] = dialect.key_equal(column, other, other if short else "NULL")
            else:
                conds[i] = dialect.key_equal(column, other)

    def event_table(self, name: str, n: int) -> str | None:
        table = self.ctx.event_table(name, n)
        if table is None:
            self.missing.add((name, n))
        else:
            self.read_types.add((name, n))
        return table

    def each_stamp(self, ev, st, run) -> None:
        """Run ``run(ev)`` for the stamps an event goal's time may be: as it is, and, when
        it is a value known only at run time, also as the interval ``[S, E]`` it may hold
        there. The two branches exclude each other (a number never is a list), and the
        branch key keeps Prolog's order either way."""
        atom, s, e = ev
        if not _stamp_may_be_interval(s, e):
            run(ev)
            return
        m = st.mark()
        st.keys.append("0")    # T a number: a point goal (the time match checks the type)
        run(ev)
        st.restore(m)
        m = st.mark()
        st.keys.append("1")    # T = [S, E]: an interval goal
        start, end = Var(), Var()
        if self.unify(s, make_list([start, end]), st):
            run((atom, start, end))
        st.restore(m)

    def event_sql(self, ev, ctx, nxt, st, emit, origin=None):
        self.each_stamp(ev, st, lambda ev: self._event_rows(ev, ctx, nxt, st, emit, origin))

    def _event_rows(self, ev, ctx, nxt, st, emit, origin=None):
        atom, s, e = ev
        _check_point_stamp(s, e)
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
            by_robot = origin is not None and type(deref(origin)) is Var
            if self.row_unify(args + (s, e), alias, n, st) \
                    and self.robot_rows(alias, st, origin):
                if self.has_at:
                    st.conds.append(f"{alias}.t_end <= :at")
                if by_robot:
                    st.keys.append(f"{alias}.robot")
                st.keys.extend([f"{alias}.t_end", f"{alias}.t_start", f"{alias}.seq"])
                self.solve(nxt, st, emit)
            st.restore(m)
        if has_rules:
            self.clauses_sql(rules, ("event", name, n), args + (s, e), ctx, nxt, st, emit,
                             offset=1)

    def _robot_sandbox(self, pattern, table, n, st, origin):
        """The alias of prev/next's row and its subquery's sandbox, restricted to the robot
        origin, or, when origin is unbound (it becomes the robot of the row found), to that
        row's robot."""
        if origin is not None and type(deref(origin)) is Var:
            p = self.alias("p")
            return p, self._sandbox(pattern, table, n, st, Col(f"{p}.robot"))
        sb = self._sandbox(pattern, table, n, st, origin)
        return (None, None) if sb is None else (self.alias("p"), sb)

    def _prev_next_event(self, t):
        ev = split_event_atom(t)
        if ev is None:
            raise Fallback("prev/next of something that is not an event atom (error at run time)")
        return ev

    def _prev_next_pattern(self, ev):
        atom, s, e = ev
        _check_point_stamp(s, e)
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

    def _sandbox(self, pattern, table, n, st, origin=None):
        """Conditions of the pattern on a fresh alias, bindings undone; None: never matches."""
        q = self.alias("q")
        m = st.mark()
        st.nested += 1   # these conditions go into a subquery on q, not into the branch
        try:
            ok = self.row_unify(pattern, q, n, st) and self.robot_rows(q, st, origin)
        finally:
            st.nested -= 1
        conds = list(st.conds[m[1]:])
        st.restore(m)
        return (q, conds) if ok else None

    def prev_sql(self, args, ctx, nxt, st, emit, origin=None):
        self.each_stamp(self._prev_next_event(args[0]), st,
                        lambda ev: self._prev(ev, args, nxt, st, emit, origin))

    def _prev(self, ev, args, nxt, st, emit, origin):
        name, n, pattern = self._prev_next_pattern(ev)
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
            self._prev_rows(name, n, pattern, lo, hi, nxt, st, emit, origin)
        finally:
            st.restore(m0)

    def _time_checks(self, st, *times) -> None:
        """Prolog evaluates a prev/next time before it looks at the history (an error even
        when no event matches): one computed through an slr_ function is tested here."""
        for t in times:
            if t is None:
                continue
            checked = self.finite_checks.get(t)
            if checked is not None:
                st.conds.append(f"({checked}) IS NOT NULL")
            elif self.dialect.may_raise(t):
                st.conds.append(f"({t}) IS NOT NULL")

    def _prev_rows(self, name, n, pattern, lo, hi, nxt, st, emit, origin=None):
        table = self.event_table(name, n)
        if table is None:
            return
        p, sb = self._robot_sandbox(pattern, table, n, st, origin)
        if sb is None:
            return
        q, qconds = sb
        qconds.append(f"{q}.t_end <= {hi}")
        if lo is not None:
            qconds.append(f"{q}.t_start >= {lo}")
        sub = (f"(SELECT {q}.t_end FROM {table} AS {q} WHERE {joined_balanced(qconds, 'AND')} "
               f"ORDER BY {q}.t_end DESC LIMIT 1)")
        m = st.mark()
        by_robot = origin is not None and type(deref(origin)) is Var
        st.froms.append((table, p, "seq"))
        if self.row_unify(pattern, p, n, st) and self.robot_rows(p, st, origin):
            st.conds.append(f"{p}.t_end = {sub}")
            if lo is not None:
                st.conds.append(f"{p}.t_start >= {lo}")
            st.keys.extend(([f"{p}.robot"] if by_robot else []) + [f"{p}.t_start", f"{p}.seq"])
            self.solve(nxt, st, emit)
        st.restore(m)

    def next_sql(self, args, ctx, nxt, st, emit, origin=None):
        self.each_stamp(self._prev_next_event(args[0]), st,
                        lambda ev: self._next(ev, args, nxt, st, emit, origin))

    def _next(self, ev, args, nxt, st, emit, origin):
        name, n, pattern = self._prev_next_pattern(ev)
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
            self._next_rows(name, n, pattern, lo, hi, nxt, st, emit, origin)
        finally:
            st.restore(m0)

    def _next_rows(self, name, n, pattern, lo, hi, nxt, st, emit, origin=None):
        table = self.event_table(name, n)
        if table is None:
            return
        p, sb = self._robot_sandbox(pattern, table, n, st, origin)
        if sb is None:
            return
        q, qconds = sb
        qconds.append(f"{q}.t_start >= {lo}")
        qconds.append(f"{q}.t_start <= {hi}")
        qconds.append(f"{q}.t_end <= {hi}")
        sub = (f"(SELECT {q}.t_start FROM {table} AS {q} WHERE {joined_balanced(qconds, 'AND')} "
               f"ORDER BY {q}.t_start LIMIT 1)")
        self.start_ordered.add((name, n))
        m = st.mark()
        by_robot = origin is not None and type(deref(origin)) is Var
        st.froms.append((table, p, "seq"))
        if self.row_unify(pattern, p, n, st) and self.robot_rows(p, st, origin):
            st.conds.append(f"{p}.t_start = {sub}")
            st.conds.append(f"{p}.t_end <= {hi}")
            st.keys.extend(([f"{p}.robot"] if by_robot else []) + [f"{p}.t_end", f"{p}.seq"])
            self.solve(nxt, st, emit)
        st.restore(m)
