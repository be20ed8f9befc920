"""Event rules as data: ``Head <- Pattern`` read into alternatives of event atoms, temporal
relations, windows, negations and goals, with the static checks of a load (docs/events.md).

An event rule's pattern is a tree of the operators of the event-processing library (ETALIS):
``seq and par or equals meets during starts finishes`` between sub-patterns, ``cnot`` (no
event of a kind inside the sub-pattern's interval), ``within D`` (the interval lasts at most
D seconds) and ``where G`` (the goal G holds). ``or`` is expanded first: a rule is the union
of its :class:`Alternative` s, each free of ``or``. An alternative lists its positive event
atoms (:class:`Leaf`, numbered left to right: the *positions*), the relation each binary
operator imposes between the intervals of its operands, the windows, the negations and the
goals, and the interval of the complex event -- all as small expression trees over the
positions' start and end times, which :mod:`slr_sql.cep.sqlgen` turns into SQL.

>>> from slr_sql.parser import parse_program
>>> rule = compile_rule(parse_program("c(X) <- (a(X) or b(X)) seq d(X).")[0])
>>> [[leaf.name for leaf in alt.leaves] for alt in rule.alternatives]
[['a', 'd'], ['b', 'd']]
>>> rule.alternatives[0].relations
[('seq', (('s', 0), ('e', 0)), (('s', 1), ('e', 1)))]
"""
from __future__ import annotations

import hashlib
import re
from dataclasses import dataclass, field
from typing import Any

from ..clocks import parse_duration
from ..errors import SLRError, SLRSyntaxError
from ..program import flatten_conjunction
from ..terms import Atom, Clause, String, Struct, Var, deref, format_term, is_ground, term_vars

__all__ = ["POLICIES", "BINARY", "IGNORED_FACTS", "MAX_PATTERN_EVENTS", "MAX_ALTERNATIVES",
           "MAX_PATTERN_DEPTH", "Leaf", "Alternative", "EventRule", "pattern_size",
           "check_size",
           "compile_rule", "is_event_rule", "is_ignored_fact", "consumption_directive",
           "order_rules", "rule_error"]

POLICIES = ("unrestricted", "recent", "chronological")

# binary operators between two sub-patterns (``or`` is expanded before these are read)
BINARY = ("seq", "and", "par", "equals", "meets", "during", "starts", "finishes")
_PATTERN_OPS = frozenset(BINARY + ("or", "cnot", "within", "where"))
# ETALIS's parser also reads each operator capitalized and in capitals ('SEQ', 'Where'):
# the same operator (rules written either way are one rule)
SYNONYMS = {variant: op for op in BINARY + ("or", "cnot", "where")
            for variant in (op.capitalize(), op.upper())}

# The largest pattern a rule may have (docs/events.md, "Limits"), refused at load beyond.
# Each alternative is decided by joins of the tables of its event atoms, one alias per
# atom, where a decision also joins its pending row: SQLite joins at most 64 tables, and the
# statements of recent and chronological rules grow with the square of the atoms (each
# partner a sub-query over the partners after it). 32 atoms -- a 30-part sequence with
# its negations -- keeps every statement well inside both engines' limits.
MAX_PATTERN_EVENTS = 32
# ``or`` multiplies: ``(a or b) seq (c or d) seq ..`` is one alternative per combination,
# each with its own statements
MAX_ALTERNATIVES = 64
# operators nested in one pattern (``((a within 1) within 1) ..`` nests without atoms): the
# readings of a pattern walk it recursively
MAX_PATTERN_DEPTH = 128

# ETALIS program facts that only steer ETALIS itself (what it prints, which events it takes
# from outside): accepted so that ETALIS rule files load unchanged, and ignored.
IGNORED_FACTS = frozenset({("print_trigger", 1), ("external_trigger", 1)})

# Names that read as goals, not events: a pattern operand written like this is a mistake.
_GOAL_NAMES = frozenset({",", ";", "->", "*->", "\\+", "|", ":-", "<-", "=", "\\=", "==",
                         "\\==", "<", ">", "=<", ">=", "=:=", "=\\=", "is", "!", "true",
                         "fail", "false", "call", "findall", "prev", "next"})


# ------------------------------------------------------------------------ the data

@dataclass
class Leaf:
    """One event atom of a pattern: ``name(args)``, optionally stamped ``^T`` (a point
    event: start = end = T) or ``^[S, E]``. ``args`` are variables or ground terms
    (a compound argument with variables is moved into the goals as ``V = f(..)``);
    ``start``/``end`` are a variable, a number or None (no stamp)."""

    name: str
    arity: int
    args: tuple
    start: Any = None
    end: Any = None
    point: bool = False
    text: str = ""

    @property
    def key(self) -> tuple[str, int]:
        return (self.name, self.arity)


# An interval endpoint expression: ("s", i) / ("e", i) the start / end of position i,
# ("min", a, b) / ("max", a, b).
Expr = tuple
Interval = tuple  # (start Expr, end Expr)


@dataclass
class Alternative:
    """One ``or``-free reading of a rule's pattern."""

    leaves: list[Leaf] = field(default_factory=list)
    relations: list[tuple[str, Interval, Interval]] = field(default_factory=list)
    windows: list[tuple[Interval, float, tuple]] = field(default_factory=list)  # + positions
    negations: list[tuple[Interval, Leaf]] = field(default_factory=list)
    goals: list[Any] = field(default_factory=list)
    interval: Interval = (("s", 0), ("e", 0))
    terminators: frozenset = frozenset()   # positions that can end a match (docs/events.md)
    # positions whose event ends strictly before every match's end: those in the left
    # operand of a ``seq`` (the rest may end at the terminator's end, tied with it)
    ends_before: frozenset = frozenset()

    def tied_positions(self) -> frozenset:
        """The positions whose event may end at the same time as the match's terminator
        and be another event than it: not in :attr:`ends_before`, and some other position
        can terminate. A decision for a terminator ending at z must see every event of
        their types ending at z, not only those ending before z (docs/events.md, "in_order
        and ties").

        >>> from slr_sql.parser import parse_program
        >>> def tied(text):
        ...     alt = compile_rule(parse_program(text)[0]).alternatives[0]
        ...     return sorted(alt.tied_positions())
        >>> tied("c(X) <- a(X) seq b(X)."), tied("c(X) <- a(X) and b(X).")
        ([], [0, 1])
        >>> tied("c(X) <- (a(X) and b(X)) seq e(X)."), tied("c(X) <- a(X) seq (b(X) par e(X)).")
        ([], [1, 2])
        >>> tied("c(X) <- (a(X) seq b(X)) and (e(X) seq f(X)).")
        [1, 3]
        """
        return frozenset(p for p in range(len(self.leaves))
                         if p not in self.ends_before and self.terminators - {p})

    def leaf_vars(self) -> set[int]:
        """ids of the variables a positive event atom binds (arguments and stamps)."""
        out: set[int] = set()
        for leaf in self.leaves:
            for t in leaf.args + (leaf.start, leaf.end):
                if t is not None:
                    out.update(id(v) for v in term_vars(t))
        return out


@dataclass
class EventRule:
    """A compiled event rule; ``policy`` is filled in by :func:`order_rules` (a directive
    may come after the rule) from the consumption directives of ``program``, the named
    program whose text holds the rule (a directive governs its own program's rules only)."""

    clause: Clause
    head: Any
    name: str
    arity: int
    pattern: Any
    alternatives: list[Alternative]
    text: str
    key: str = ""
    policy: str = "unrestricted"
    program: str = ""

    @property
    def head_key(self) -> tuple[str, int]:
        return (self.name, self.arity)

    @property
    def source(self) -> str:
        span = self.clause.span
        return f"{span.filename}:{span.line}" if span is not None else "<rule>"

    @property
    def line(self) -> int:
        return self.clause.span.line if self.clause.span is not None else 0

    def decision_inputs(self, n: int) -> dict[tuple[str, int], bool]:
        """The event types a ``recent`` or ``chronological`` decision for a terminator of
        alternative ``n`` waits for, each with whether it must be complete *through* the
        terminator's end z (an event of it ending at z may still change the decision) or
        only *before* z (every event ending before z is in): through for the types of
        :meth:`Alternative.tied_positions`, and under ``chronological`` for the terminators
        of every alternative (one ending at z may come first in occurrence order and take
        the events this one would use); before for the rest and the negated types (a
        negated event lies strictly inside).

        >>> from slr_sql.parser import parse_program
        >>> rule = compile_rule(parse_program("c(X) <- a(X) seq (b(X) and e(X)).")[0])
        >>> rule.decision_inputs(0)
        {('a', 1): False, ('b', 1): True, ('e', 1): True}
        >>> rule = compile_rule(parse_program("c <- a seq b.")[0])
        >>> rule.decision_inputs(0)
        {('a', 0): False, ('b', 0): False}
        >>> rule.policy = "chronological"
        >>> rule.decision_inputs(0)
        {('a', 0): False, ('b', 0): True}
        """
        alt = self.alternatives[n]
        tied = alt.tied_positions()
        out: dict[tuple[str, int], bool] = {}
        for p, leaf in enumerate(alt.leaves):
            out[leaf.key] = out.get(leaf.key, False) or p in tied
        for _, leaf in alt.negations:
            out.setdefault(leaf.key, False)
        if self.policy == "chronological":
            for other in self.alternatives:
                for t in other.terminators:
                    out[other.leaves[t].key] = True
        return out

    def closing_types(self) -> set[tuple[str, int]]:
        """The event types of positions that may end where a match ends (all but those in
        a ``seq``'s left part): a complex event of the rule ending at z may still come
        while one of them is not complete through z; the others need only be complete
        before z (docs/events.md, "in_order and ties").

        >>> from slr_sql.parser import parse_program
        >>> sorted(compile_rule(parse_program("c(X) <- a(X) seq b(X).")[0]).closing_types())
        [('b', 1)]
        """
        return {leaf.key for alt in self.alternatives for p, leaf in enumerate(alt.leaves)
                if p not in alt.ends_before}

    def input_types(self) -> list[tuple[str, int]]:
        """Every event type the rule's patterns read (positive atoms, then negated ones)."""
        out: list[tuple[str, int]] = []
        for alt in self.alternatives:
            for leaf in alt.leaves + [neg for _, neg in alt.negations]:
                if leaf.key not in out:
                    out.append(leaf.key)
        return out


# ------------------------------------------------------------------------ errors

def rule_error(clause: Clause | None, message: str, near: Any = None,
               in_head: bool = False) -> SLRSyntaxError:
    """An SLRSyntaxError at the rule's clause, at the text of ``near`` when it can be found
    in the clause (in the head with ``in_head``, else in the pattern; the clause's start
    when it cannot be found).

    >>> from slr_sql.parser import parse_program
    >>> e = rule_error(parse_program("c(X) <- a(X) seq 5.")[0], "not an event", 5)
    >>> (e.line, e.column)
    (1, 18)
    """
    if clause is None or clause.span is None:
        return SLRSyntaxError(message)
    span = clause.span
    text = clause.text or ""
    arrow = text.find("<-")
    offset = 0
    if near is not None:
        printed = near if isinstance(near, str) else format_term(near)
        # the printed term with any layout between its characters: `X>1` finds `X > 1`
        regex = r"\s*".join(re.escape(c) for c in printed if not c.isspace())
        if in_head or arrow < 0:
            found = re.compile(regex).search(text, 0, arrow if arrow >= 0 else len(text))
        else:
            found = re.compile(regex).search(text, arrow + 2)
        if found is not None and regex:
            offset = found.start()
    before = text[:offset]
    line = span.line + before.count("\n")
    if "\n" in before:
        column = offset - before.rfind("\n")
    else:
        column = span.column + offset
    lines = text.split("\n")
    source_line = lines[before.count("\n")] if lines else ""
    if "\n" not in before and span.column > 1:
        source_line = " " * (span.column - 1) + source_line
    return SLRSyntaxError(message, line, column, source_line, span.filename)


# ------------------------------------------------------------------------ reading

def is_event_rule(head: Any) -> bool:
    """Is this clause head an event rule ``H <- P``?

    >>> from slr_sql.parser import parse_term
    >>> is_event_rule(parse_term("c(X) <- a(X) seq b(X)")[0]), is_event_rule(Atom("c"))
    (True, False)
    """
    head = deref(head)
    return type(head) is Struct and head.name == "<-" and len(head.args) == 2


def is_ignored_fact(head: Any) -> bool:
    """``print_trigger(_)`` and the other ETALIS-only facts (see :data:`IGNORED_FACTS`).

    >>> from slr_sql.parser import parse_term
    >>> is_ignored_fact(parse_term("print_trigger(a/1)")[0])
    True
    """
    head = deref(head)
    return type(head) is Struct and (str(head.name), len(head.args)) in IGNORED_FACTS


def consumption_directive(goal: Any) -> tuple[tuple[str, int] | None, str] | None:
    """``consumption(P)`` -> (None, P); ``consumption(H/N, P)`` -> ((H, N), P); None if the
    directive is not a consumption directive. Raises SLRError on a bad one.

    >>> from slr_sql.parser import parse_term
    >>> consumption_directive(parse_term("consumption(relFace/1, recent)")[0])
    (('relFace', 1), 'recent')
    """
    goal = deref(goal)
    if type(goal) is not Struct or goal.name != "consumption" or len(goal.args) not in (1, 2):
        return None
    policy = deref(goal.args[-1])
    if type(policy) is not Atom or str(policy) not in POLICIES:
        raise SLRError(f"consumption: the policy must be one of {', '.join(POLICIES)}, not "
                       f"{format_term(policy)}")
    if len(goal.args) == 1:
        return None, str(policy)
    ind = deref(goal.args[0])
    if type(ind) is Struct and ind.name == "/" and len(ind.args) == 2:
        name, n = deref(ind.args[0]), deref(ind.args[1])
        if type(name) is Atom and type(n) is int and n >= 0:
            return (str(name), n), str(policy)
    raise SLRError(f"consumption: expected Head/N, not {format_term(ind)}")


def _flatten_and(goal: Any) -> list:
    return [_bar_to_semicolon(g) for g in flatten_conjunction(goal)]


def _bar_to_semicolon(goal: Any) -> Any:
    """``(a | b)`` in a goal is ``(a ; b)``, as in a clause body."""
    goal = deref(goal)
    if type(goal) is not Struct or goal.name not in (",", ";", "|", "->", "*->", "\\+"):
        return goal
    args = tuple(_bar_to_semicolon(a) for a in goal.args)
    name = ";" if goal.name == "|" and len(args) == 2 else goal.name
    return Struct(name, args)


def _alternatives(pattern: Any, clause: Clause) -> list[Any]:
    """The ``or``-free readings of a pattern (``a or b`` -> [a, b]; operators distribute)."""
    p = deref(pattern)
    if type(p) is Struct and len(p.args) == 2 and p.name in _PATTERN_OPS:
        if p.name == "or":
            return _alternatives(p.args[0], clause) + _alternatives(p.args[1], clause)
        if p.name in ("within", "where"):
            return [Struct(p.name, (left, p.args[1]))
                    for left in _alternatives(p.args[0], clause)]
        if p.name == "cnot":
            return [Struct("cnot", (left, p.args[1]))
                    for left in _alternatives(p.args[0], clause)]
        return [Struct(p.name, (left, right))
                for left in _alternatives(p.args[0], clause)
                for right in _alternatives(p.args[1], clause)]
    return [p]


class _Reader:
    """Builds one :class:`Alternative` from an ``or``-free pattern tree."""

    def __init__(self, clause: Clause):
        self.clause = clause
        self.alt = Alternative()
        self.unify_goals: list = []   # V = f(..) for compound arguments with variables
        # each where goal: the counts (leaves, goals, unify goals) before its part, after
        # its part, after its goals, and the variables its part binds
        self.where_scopes: list = []

    def error(self, message: str, near: Any = None) -> SLRSyntaxError:
        return rule_error(self.clause, message, near)

    def read(self, pattern: Any) -> Alternative:
        interval, terms = self.node(pattern)
        self.alt.interval = interval
        self.alt.terminators = frozenset(terms)
        # (the last first: a scope's goals lie before those of every scope read after it)
        for scope in reversed(self.where_scopes):
            self.scope_where(*scope)
        self.alt.goals = self.unify_goals + self.alt.goals
        return self.alt

    def node(self, p: Any) -> tuple[Interval, set]:
        p = deref(p)
        if type(p) is Struct and len(p.args) == 2 and p.name in _PATTERN_OPS:
            op = str(p.name)
            if op == "within":
                first = len(self.alt.leaves)
                interval, terms = self.node(p.args[0])
                d = deref(p.args[1])
                try:
                    seconds = float(parse_duration(d))
                except SLRError:
                    raise self.error(f"within: the window must be a non-negative number of "
                                     f"seconds (or a duration such as 5s), not "
                                     f"{format_term(d)}", d) from None
                self.alt.windows.append((interval, seconds,
                                         tuple(range(first, len(self.alt.leaves)))))
                return interval, terms
            if op == "where":
                marks = (len(self.alt.leaves), len(self.alt.goals), len(self.unify_goals))
                interval, terms = self.node(p.args[0])
                goal = deref(p.args[1])
                if type(goal) not in (Atom, Struct):
                    raise self.error(f"where: the condition must be a goal, not "
                                     f"{format_term(goal)}", goal)
                after = (len(self.alt.leaves), len(self.alt.goals), len(self.unify_goals))
                own = self.bound_since(*marks)
                self.alt.goals.extend(_flatten_and(goal))
                self.where_scopes.append((marks, after, len(self.alt.goals), own))
                return interval, terms
            if op == "cnot":
                marks = (len(self.alt.leaves), len(self.alt.goals), len(self.unify_goals))
                interval, terms = self.node(p.args[0])
                own = self.bound_since(*marks)
                for negated in self.negated(p.args[1]):
                    self.alt.negations.append((interval, _scoped(negated, own)))
                return interval, terms
            if op == "or":  # pragma: no cover - expanded before
                raise self.error("internal: or not expanded", p)
            first = len(self.alt.leaves)
            left, lterms = self.node(p.args[0])
            if op == "seq":
                # the left part ends before the right one starts, so before every end of
                # the operators above (each ends at or after the end of its operands);
                # every other operator lets its operands end where it ends
                self.alt.ends_before |= frozenset(range(first, len(self.alt.leaves)))
            right, rterms = self.node(p.args[1])
            (s1, e1), (s2, e2) = left, right
            self.alt.relations.append((op, left, right))
            if op == "seq" or op == "meets":
                return (s1, e2), rterms
            if op in ("and", "par"):
                return (("min", s1, s2), ("max", e1, e2)), lterms | rterms
            if op == "equals":
                if _uniform(p.args[0]) and _uniform(p.args[1]):
                    # every event of the part has the same interval: the rightmost ends it
                    return (s1, e1), {max(lterms | rterms)}
                return (s1, e1), lterms | rterms
            if op == "during":
                return (s2, e2), lterms | rterms
            if op == "starts":
                return (s1, ("max", e1, e2)), lterms | rterms
            if op == "finishes":
                return (("min", s1, s2), e1), lterms | rterms
            raise self.error(f"unknown event operator {op}", p)  # pragma: no cover
        leaf = self.leaf(p, negated=False)
        pos = len(self.alt.leaves)
        self.alt.leaves.append(leaf)
        return (("s", pos), ("e", pos)), {pos}

    def scope_where(self, before: tuple, after: tuple, end: int, own: set[int]) -> None:
        """Run a where goal with the bindings of its part only (SPEC §6, scope): in
        ``(a(X) where X < Y) seq b(Y)`` the goal sees no Y (an instantiation error, as
        Prolog raises it), and in ``(a(X) where \\+ c(Y)^_) seq b(Y)`` any c blocks. A
        variable the part does not bind but other parts of the pattern (or other where
        goals) use is renamed apart in the goal, and unified with its namesake after it:
        what the goal binds still reaches the rest, as when the goal runs first."""
        outside: set[int] = set()
        for leaf in self.alt.leaves[:before[0]] + self.alt.leaves[after[0]:]:
            for t in leaf.args + (leaf.start, leaf.end):
                if t is not None:
                    outside.update(id(v) for v in term_vars(t))
        for goal in (self.alt.goals[:before[1]] + self.alt.goals[end:]
                     + self.unify_goals[:before[2]] + self.unify_goals[after[2]:]):
            outside.update(id(v) for v in term_vars(goal))
        goals = self.alt.goals[after[1]:end]
        renamed: dict[int, tuple[Var, Var]] = {}
        for goal in goals:
            for v in term_vars(goal):
                if id(v) in outside and id(v) not in own and id(v) not in renamed:
                    renamed[id(v)] = (v, Var(f"_{v.name}{len(renamed)}"))
        if not renamed:
            return

        def rename(t: Any) -> Any:
            t = deref(t)
            if type(t) is Var:
                pair = renamed.get(id(t))
                return t if pair is None else pair[1]
            if type(t) is Struct:
                return Struct(t.name, tuple(rename(a) for a in t.args))
            return t

        self.alt.goals[after[1]:end] = ([rename(g) for g in goals]
                                        + [Struct("=", (new, old))
                                           for old, new in renamed.values()])

    def bound_since(self, leaves: int, goals: int, unify_goals: int) -> set[int]:
        """ids of the variables the part read since these counts binds: its event atoms
        and its own where goals (the scope of a cnot over that part, SPEC §6)."""
        own: set[int] = set()
        for leaf in self.alt.leaves[leaves:]:
            for t in leaf.args + (leaf.start, leaf.end):
                if t is not None:
                    own.update(id(v) for v in term_vars(t))
        for goal in self.alt.goals[goals:] + self.unify_goals[unify_goals:]:
            own.update(id(v) for v in term_vars(goal))
        return own

    def negated(self, p: Any) -> list[Leaf]:
        p = deref(p)
        if type(p) is Struct and p.name == "or" and len(p.args) == 2:
            return self.negated(p.args[0]) + self.negated(p.args[1])
        if type(p) is Struct and p.name in _PATTERN_OPS and len(p.args) == 2:
            raise self.error(f"cnot: the negated part must be an event atom (or atoms joined "
                             f"by or), not the pattern {format_term(p)}; define it as its own "
                             f"event rule and negate that", p)
        return [self.leaf(p, negated=True)]

    def leaf(self, p: Any, negated: bool) -> Leaf:
        p = deref(p)
        start = end = None
        point = False
        atom = p
        if type(p) is Struct and p.name == "^" and len(p.args) == 2:
            atom = deref(p.args[0])
            stamp = deref(p.args[1])
            if type(stamp) is Struct and stamp.name == "." and len(stamp.args) == 2 \
                    and type(deref(stamp.args[1])) is Struct \
                    and deref(stamp.args[1]).name == "." \
                    and deref(deref(stamp.args[1]).args[1]) == "[]":
                start = self.time(deref(stamp.args[0]), p)
                end = self.time(deref(deref(stamp.args[1]).args[0]), p)
            else:
                start = end = self.time(stamp, p)
                point = True
        what = "the negated part of cnot" if negated else "an operand of an event operator"
        if type(atom) is Var:
            raise self.error(f"{what} must be an event atom, not the variable {atom.name}",
                             atom)
        if type(atom) not in (Atom, Struct) or type(atom) is String:
            raise self.error(f"{what} must be an event atom such as p(X) or p(X)^T, not "
                             f"{format_term(atom)}", atom)
        name = str(atom.name) if type(atom) is Struct else str(atom)
        args = tuple(atom.args) if type(atom) is Struct else ()
        if name in (".", "[]", "{}"):
            raise self.error(f"{what} must be an event atom such as p(X) or p(X)^T, not "
                             f"{format_term(atom)}", atom)
        if name in _GOAL_NAMES or name in _PATTERN_OPS or name == "^":
            raise self.error(f"{what} must be an event atom, not the goal "
                             f"{format_term(atom)} (conditions go after where)", atom)
        if name == "fullyUpdated":
            raise self.error("fullyUpdated(..) is a completeness mark, not an event a "
                             "pattern can match", atom)
        out = []
        for a in args:
            a = deref(a)
            if type(a) is Struct and not is_ground(a):
                if negated:
                    raise self.error("cnot: the negated event's arguments must be variables "
                                     "or ground terms", a)
                v = Var(f"_Arg{len(self.unify_goals)}")
                self.unify_goals.append(Struct("=", (v, a)))
                out.append(v)
            else:
                out.append(a)
        return Leaf(name, len(args), tuple(out), start, end, point, format_term(p))

    def time(self, t: Any, near: Any) -> Any:
        t = deref(t)
        if type(t) is Var:
            return t
        if type(t) in (int, float) and t == t and abs(t) != float("inf"):
            return float(t)
        raise self.error(f"an event time must be a variable or a number, not "
                         f"{format_term(t)}", near)


def _scoped(leaf: Leaf, own: set[int]) -> Leaf:
    """The negated event atom with every variable its part does not bind renamed apart:
    in ``((a seq b) cnot x(X)) and y(X)`` the x(X) blocks for any X (a seq b binds no X),
    whatever y(X) binds later. A variable repeated in the atom stays one variable."""
    fresh: dict[int, Var] = {}

    def rename(t: Any) -> Any:
        t = deref(t)
        if type(t) is Var and id(t) not in own:
            v = fresh.get(id(t))
            if v is None:
                v = fresh[id(t)] = Var(f"_Free{len(fresh)}")
            return v
        return t

    if all(id(v) in own for t in leaf.args + (leaf.start, leaf.end) if t is not None
           for v in term_vars(t)):
        return leaf
    return Leaf(leaf.name, leaf.arity, tuple(rename(a) for a in leaf.args),
                None if leaf.start is None else rename(leaf.start),
                None if leaf.end is None else rename(leaf.end), leaf.point, leaf.text)


def _uniform(p: Any) -> bool:
    """Do all event atoms of this (or-free) part have the same interval? (an atom, or
    ``equals`` of such parts, possibly under within/where/cnot)."""
    p = deref(p)
    if type(p) is Struct and len(p.args) == 2 and p.name in _PATTERN_OPS:
        if p.name == "equals":
            return _uniform(p.args[0]) and _uniform(p.args[1])
        if p.name in ("within", "where", "cnot"):
            return _uniform(p.args[0])
        return False
    return True


def _canonical(term: Any) -> str:
    """The rule's text with its variables renamed in order of appearance (the rule's key)."""
    mapping: dict[int, Var] = {}

    def walk(t: Any) -> Any:
        t = deref(t)
        if type(t) is Var:
            v = mapping.get(id(t))
            if v is None:
                v = mapping[id(t)] = Var(f"V{len(mapping)}")
            return v
        if type(t) is Struct:
            return Struct(t.name, tuple(walk(a) for a in t.args))
        return t

    return format_term(walk(term))


def pattern_size(pattern: Any) -> tuple[int, int, int]:
    """The size of a pattern, walked without recursion (a pattern of any depth can be
    measured before it is refused): the most event atoms of one alternative (positive and
    negated), the number of alternatives ``or`` makes, and how deep its operators nest.

    >>> from slr_sql.parser import parse_term
    >>> pattern_size(parse_term("(a or b) seq (c cnot d) seq e within 5")[0])
    (4, 2, 4)
    """
    def operator(p: Any) -> str | None:
        p = deref(p)
        if type(p) is Struct and len(p.args) == 2:
            name = SYNONYMS.get(str(p.name), str(p.name))
            if name in _PATTERN_OPS:
                return name
        return None

    sizes: dict[int, tuple[int, int, int]] = {}
    stack: list[tuple[Any, bool]] = [(pattern, False)]
    while stack:
        node, visited = stack.pop()
        node = deref(node)
        op = operator(node)
        if op is None:
            sizes[id(node)] = (1, 1, 0)
            continue
        left, right = deref(node.args[0]), deref(node.args[1])
        # (the negated side of cnot counts its atoms; where and within have no pattern there)
        children = [left] if op in ("within", "where") else [left, right]
        if not visited:
            stack.append((node, True))
            stack.extend((child, False) for child in children)
            continue
        l_atoms, l_alts, l_depth = sizes[id(left)]
        if op in ("within", "where"):
            sizes[id(node)] = (l_atoms, l_alts, l_depth + 1)
            continue
        r_atoms, r_alts, r_depth = sizes[id(right)]
        depth = max(l_depth, r_depth) + 1
        if op == "or":
            sizes[id(node)] = (max(l_atoms, r_atoms), l_alts + r_alts, depth)
        elif op == "cnot":   # its atoms joined by or are all negated in each alternative
            sizes[id(node)] = (l_atoms + r_atoms * r_alts, l_alts, depth)
        else:
            sizes[id(node)] = (l_atoms + r_atoms, l_alts * r_alts, depth)
    return sizes[id(deref(pattern))]


def check_size(clause: Clause) -> None:
    """Refuse the event rule ``clause`` if its pattern is beyond :data:`MAX_PATTERN_EVENTS`,
    :data:`MAX_ALTERNATIVES` or :data:`MAX_PATTERN_DEPTH` (an SLRSyntaxError at the rule),
    before anything walks it.

    >>> from slr_sql.parser import parse_program
    >>> check_size(parse_program("c(X) <- a(X) seq b(X).")[0])
    >>> long = " seq ".join(f"a{i}(X)" for i in range(40))
    >>> check_size(parse_program(f"c(X) <- {long}.")[0])
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRSyntaxError: <string>:1:1: event rule c/1: its pattern has 40 event atoms in one alternative; at most 32 are supported (split it into event rules over each other's complex events)
    ...
    """
    rule = deref(clause.head)
    head, pattern = deref(rule.args[0]), rule.args[1]
    name = (f" {head.name}/{len(head.args)}" if type(head) is Struct
            else f" {head}/0" if type(head) is Atom else "")
    atoms, alternatives, depth = pattern_size(pattern)
    if atoms > MAX_PATTERN_EVENTS:
        raise rule_error(clause, f"event rule{name}: its pattern has {atoms} event atoms in "
                                 f"one alternative; at most {MAX_PATTERN_EVENTS} are supported "
                                 f"(split it into event rules over each other's complex "
                                 f"events)")
    if depth > MAX_PATTERN_DEPTH:
        raise rule_error(clause, f"event rule{name}: its pattern nests operators "
                                 f"{depth} deep; at most {MAX_PATTERN_DEPTH} are supported")
    if alternatives > MAX_ALTERNATIVES:
        raise rule_error(clause, f"event rule{name}: its pattern has {alternatives} "
                                 f"alternatives (each or doubles the parts it joins); at most "
                                 f"{MAX_ALTERNATIVES} are supported")


def compile_rule(clause: Clause, sized: bool = True) -> EventRule:
    """Read the clause ``Head <- Pattern`` into an :class:`EventRule`; raises
    :class:`SLRSyntaxError` (with line and column) for a rule that is not well formed, or
    (with ``sized``) larger than :func:`check_size` admits -- not checked for a rule a
    store holds already, which an earlier version loaded (docs/events.md, "Limits").

    >>> from slr_sql.parser import parse_program
    >>> r = compile_rule(parse_program("r(F) <- face(F, R1) seq face(F, R2) where R2 > R1.")[0])
    >>> r.name, r.arity, len(r.alternatives[0].leaves), r.alternatives[0].goals
    ('r', 1, 2, [Struct('>', (Var('R2'), Var('R1')))])
    """
    if sized:
        check_size(clause)
    rule = deref(clause.head)
    head, pattern = deref(rule.args[0]), _lowercase_operators(rule.args[1])
    rule = Struct(rule.name, (rule.args[0], pattern))
    if type(head) is Struct and head.name == "^" and len(head.args) == 2:
        raise rule_error(clause, "the head of an event rule takes its interval from the "
                                 "pattern: write it without ^", head, in_head=True)
    if type(head) is Var:
        raise rule_error(clause, "the head of an event rule cannot be a variable", head)
    if type(head) not in (Atom, Struct) or type(head) is String:
        raise rule_error(clause, f"the head of an event rule must be an event atom, not "
                                 f"{format_term(head)}", head)
    name = str(head.name) if type(head) is Struct else str(head)
    arity = len(head.args) if type(head) is Struct else 0
    if name == "fullyUpdated" or name in _GOAL_NAMES or name in _PATTERN_OPS:
        raise rule_error(clause, f"{name}/{arity} cannot be the head of an event rule", head,
                         in_head=True)
    if type(pattern) is Var:
        raise rule_error(clause, "the pattern of an event rule cannot be a variable", pattern)
    alternatives = []
    for tree in _alternatives(pattern, clause):
        alt = _Reader(clause).read(tree)
        bound = alt.leaf_vars()
        for goal in alt.goals:
            bound.update(id(v) for v in term_vars(goal))
        for v in term_vars(head):
            if id(v) not in bound:
                where = "" if len(alternatives) == 0 and not _has_or(pattern) else \
                    f" in the alternative {' '.join(leaf.text for leaf in alt.leaves)}"
                raise rule_error(clause, f"unsafe head variable {v.name}: it is bound by no "
                                         f"event of the pattern{where} nor by its where goal",
                                 v, in_head=True)
        alternatives.append(alt)
    text = f"{format_term(head)} <- {format_term(pattern, priority=1199)}"
    key = hashlib.sha1(_canonical(rule).encode("utf-8")).hexdigest()[:12]
    return EventRule(clause, head, name, arity, pattern, alternatives, text, key)


def _lowercase_operators(p: Any) -> Any:
    """The pattern with ETALIS's operator synonyms (``'SEQ'``, ``'Where'``) as the operators
    they stand for; the operands of ``where`` and ``within`` are left as they are."""
    p = deref(p)
    if type(p) is not Struct or len(p.args) != 2:
        return p
    name = SYNONYMS.get(str(p.name), p.name)
    if name not in _PATTERN_OPS:
        return p
    right = p.args[1] if name in ("where", "within") else _lowercase_operators(p.args[1])
    return Struct(Atom(name), (_lowercase_operators(p.args[0]), right))


def _has_or(p: Any) -> bool:
    p = deref(p)
    if type(p) is Struct and p.name in _PATTERN_OPS and len(p.args) == 2:
        return p.name == "or" or _has_or(p.args[0]) or (p.name != "where"
                                                         and _has_or(p.args[1]))
    return False


def order_rules(rules: list[EventRule], consumption: dict | None = None,
                reads: dict | None = None) -> list[EventRule]:
    """Fill in each rule's policy and its key, and return the rules in dependency order.

    The policy is the one its own program sets (``consumption[rule.program]``, which maps
    the head ``(name, n)`` or None, the program's default, to a policy): the head's, else
    the program's default, else unrestricted -- another program's directives never apply.
    A rule comes after every rule whose complex events it reads (its event atoms, negated
    ones, and the event types ``reads[id(rule)]`` its where goal reads). Cyclic definitions
    are an SLRError naming the rules and lines.

    >>> from slr_sql.parser import parse_program
    >>> rs = [compile_rule(c) for c in parse_program("b(X) <- a(X). c(X) <- b(X) seq a(X).")]
    >>> rs[1].program = "other"
    >>> ordered = order_rules(list(reversed(rs)), {"other": {None: "recent"}})
    >>> [(r.name, r.policy) for r in ordered]
    [('b', 'unrestricted'), ('c', 'recent')]
    """
    for rule in rules:
        own = (consumption or {}).get(rule.program) or {}
        rule.policy = own.get(rule.head_key) or own.get(None) or "unrestricted"
        # the pattern as read (ETALIS's synonyms lowercased): 'SEQ' and seq are one rule
        rule.key = hashlib.sha1((_canonical(Struct("<-", (rule.head, rule.pattern)))
                                 + "|" + rule.policy)
                                .encode("utf-8")).hexdigest()[:12]
    by_head: dict[tuple[str, int], list[EventRule]] = {}
    for rule in rules:
        by_head.setdefault(rule.head_key, []).append(rule)
    deps: dict[int, list[EventRule]] = {}
    for i, rule in enumerate(rules):
        needed = list(rule.input_types()) + list((reads or {}).get(id(rule), ()))
        deps[i] = [r for key in needed for r in by_head.get(key, ())]
    order: list[EventRule] = []
    state: dict[int, int] = {}
    index = {id(r): i for i, r in enumerate(rules)}

    def visit(i: int, trail: list[int]) -> None:
        state[i] = 1
        for dep in deps[i]:
            j = index[id(dep)]
            if state.get(j) == 1:
                cycle = trail[trail.index(j):] + [j] if j in trail else [i, j]
                names = " -> ".join(f"{rules[k].name}/{rules[k].arity} ({rules[k].source})"
                                    for k in reversed(cycle))
                raise rule_error(rules[i].clause, f"cyclic event rules: {names}; an event "
                                                  f"rule cannot read, directly or through "
                                                  f"other rules, the events it derives")
            if state.get(j) is None:
                visit(j, trail + [j])
        state[i] = 2
        order.append(rules[i])

    for i in range(len(rules)):
        if state.get(i) is None:
            visit(i, [i])
    return order
