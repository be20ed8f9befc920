"""Loaded programs: clauses compiled into templates that are cheap to rename apart.

A clause is compiled once: its variables become numbered :class:`Slot` s and every compound
that contains a variable becomes a :class:`Template`; ground subterms are shared as they are.
Resolving against a clause then needs no copy of the head at all (slots are filled straight
from the goal's arguments) and one copy of the body goals.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .terms import Atom, Clause, Struct, Var, deref

__all__ = ["Slot", "Template", "CompiledClause", "Predicate", "Program", "compile_clause",
           "split_event_atom", "event_key", "Declarations", "BufferDecl"]


class Slot:
    """The i-th variable of a compiled clause."""

    __slots__ = ("index", "name")

    def __init__(self, index: int, name: str):
        self.index = index
        self.name = name

    def __repr__(self) -> str:
        return f"Slot({self.index}, {self.name!r})"


class Template:
    """A compound term of a compiled clause that contains at least one Slot.

    ``spine`` marks a list cell whose tail is again a template, built iteratively.
    ``nest`` is how deep :func:`build` would recurse on it; deeper templates (a term nested
    thousands of levels) are built from an explicit stack instead.
    """

    __slots__ = ("name", "args", "spine", "nest")

    def __init__(self, name: str, args: tuple):
        self.name = name
        self.args = args
        self.spine = name == "." and len(args) == 2 and type(args[1]) is Template
        nest = 0
        for a in args:
            if type(a) is Template and a.nest > nest:
                nest = a.nest
        if self.spine:  # build walks list spines in a loop: the tail adds no depth
            head = args[0]
            self.nest = max(args[1].nest, head.nest + 1 if type(head) is Template else 1)
        else:
            self.nest = nest + 1

    def __repr__(self) -> str:
        return f"Template({self.name!r}, {self.args!r})"


# Templates nested deeper than this are built (and matched, in the engine) iteratively: well
# below Python's recursion limit, which the caller's own frames share.
MAX_RECURSIVE_NEST = 200


def build(t: Any, frame: list) -> Any:
    """Instantiate a compiled term with the variables of ``frame`` (fresh Vars on demand).

    >>> from slr_sql.terms import Var
    >>> X = Var("X"); c = compile_clause((Struct("f", (X, X, 1)),), Atom("true"))
    >>> frame = [None] * c.nslots; t = build(c.head[0], frame)
    >>> t, t.args[0] is t.args[1] is frame[0]
    (Struct('f', (Var('X'), Var('X'), 1)), True)
    """
    tt = type(t)
    if tt is Slot:
        v = frame[t.index]
        if v is None:
            v = frame[t.index] = Var(t.name)
        return v
    if tt is not Template:
        return t
    if t.nest > MAX_RECURSIVE_NEST:
        return _build_deep(t, frame)
    if t.spine:
        # long list templates: walk the spine iteratively
        heads = []
        while type(t) is Template and t.name == "." and len(t.args) == 2:
            heads.append(build(t.args[0], frame))
            t = t.args[1]
        out = build(t, frame)
        for h in reversed(heads):
            out = Struct(".", (h, out))
        return out
    # the common case inlined: arguments that are slots or constants need no call
    out = []
    for a in t.args:
        ta = type(a)
        if ta is Slot:
            v = frame[a.index]
            if v is None:
                v = frame[a.index] = Var(a.name)
            out.append(v)
        elif ta is Template:
            out.append(build(a, frame))
        else:
            out.append(a)
    return Struct(t.name, tuple(out))


def _build_deep(t: Template, frame: list) -> Any:
    """build() for a deeply nested template, from an explicit stack."""
    done: list = []
    todo: list = [t]
    while todo:
        x = todo.pop()
        tx = type(x)
        if tx is Template:
            todo.append((x.name, len(x.args)))  # assemble once the arguments are built
            todo.extend(reversed(x.args))
        elif tx is tuple:
            name, k = x
            args = tuple(done[len(done) - k:])
            del done[len(done) - k:]
            done.append(Struct(name, args))
        elif tx is Slot:
            v = frame[x.index]
            if v is None:
                v = frame[x.index] = Var(x.name)
            done.append(v)
        else:
            done.append(x)
    return done[0]


@dataclass(slots=True)
class CompiledClause:
    head: tuple  # compiled head arguments (for temporal rules: data args + (start, end))
    body: tuple  # compiled body goals, top-level conjunction flattened
    nslots: int
    source: Clause | None = None
    index_key: Any = None  # first-argument key, None when the first argument is a variable


def _compile(t: Any, slots: dict) -> Any:
    """A clause term with its variables replaced by Slots (numbered in order of first
    appearance, depth-first left to right) and every compound holding one by a Template.

    Iterative (an explicit stack, not recursion): clause terms nested 100,000 deep and
    million-element list facts compile.
    """
    t = deref(t)
    tt = type(t)
    if tt is Var:
        s = slots.get(id(t))
        if s is None:
            s = slots[id(t)] = Slot(len(slots), t.name)
        return s
    if tt is not Struct:
        return t
    done: list = []
    todo: list = [t]
    while todo:
        x = todo.pop()
        tx = type(x)
        if tx is _Assemble:
            original = x.struct
            k = len(original.args)
            args = tuple(done[len(done) - k:])
            del done[len(done) - k:]
            if any(type(a) is Slot or type(a) is Template for a in args):
                done.append(Template(original.name, args))
            elif all(a is b for a, b in zip(args, original.args)):
                done.append(original)
            else:
                done.append(Struct(original.name, args))
            continue
        while tx is Var and x.ref is not None:
            x = x.ref
            tx = type(x)
        if tx is Var:
            s = slots.get(id(x))
            if s is None:
                s = slots[id(x)] = Slot(len(slots), x.name)
            done.append(s)
        elif tx is Struct:
            todo.append(_Assemble(x))
            todo.extend(reversed(x.args))
        else:
            done.append(x)
    return done[0]


class _Assemble:
    """_compile's marker: the arguments of ``struct`` are compiled, build its template."""

    __slots__ = ("struct",)

    def __init__(self, struct: Struct):
        self.struct = struct


def first_arg_key(t: Any) -> Any:
    """Key for first-argument indexing, or None for a variable.

    >>> first_arg_key(Atom("cup1")), first_arg_key(Struct("p", (1, 2))), first_arg_key(Slot(0, "X"))
    ((<class 'slr_sql.terms.Atom'>, Atom('cup1')), (<class 'slr_sql.terms.Struct'>, Atom('p'), 2), None)
    """
    tt = type(t)
    if tt is Slot or tt is Var:
        return None
    if tt is Struct or tt is Template:
        return (Struct, t.name, len(t.args))
    return (tt, t)


def flatten_conjunction(body: Any) -> list:
    """The goals of a conjunction ``(A, B, C)`` as a list, left to right (nested conjunctions
    flattened).

    >>> [str(g) for g in flatten_conjunction(Struct(",", (Atom("a"), Struct(",", (Atom("b"), Atom("c"))))))]
    ['a', 'b', 'c']
    """
    goals = []
    stack = [body]
    while stack:
        g = deref(stack.pop())
        if type(g) is Struct and g.name == "," and len(g.args) == 2:
            stack.append(g.args[1])
            stack.append(g.args[0])
        else:
            goals.append(g)
    return goals


def compile_clause(head_args: tuple, body: Any, source: Clause | None = None) -> CompiledClause:
    """Compile a clause given its head arguments and body.

    >>> from slr_sql.terms import Var, Atom
    >>> X = Var("X"); c = compile_clause((X,), Struct("q", (X,)))
    >>> c.nslots, c.head
    (1, (Slot(0, 'X'),))
    """
    slots: dict = {}
    head = tuple(_compile(a, slots) for a in head_args)
    goals = [_compile(g, slots) for g in flatten_conjunction(body)]
    goals = tuple(g for g in goals if not (type(g) is Atom and g == "true"))
    key = first_arg_key(head[0]) if head else None
    return CompiledClause(head, goals, len(slots), source, key)


def split_event_atom(t: Any) -> tuple[Any, Any, Any] | None:
    """``p(..)^T`` -> (p(..), T, T); ``p(..)^[S,E]`` -> (p(..), S, E); else None.

    >>> from slr_sql.terms import Var, make_list
    >>> S, E = Var("S"), Var("E"); p = Struct("seen", (Atom("cup1"),))
    >>> split_event_atom(Struct("^", (p, S)))
    (Struct('seen', (Atom('cup1'),)), Var('S'), Var('S'))
    >>> split_event_atom(Struct("^", (p, make_list([S, E])))), split_event_atom(p)
    ((Struct('seen', (Atom('cup1'),)), Var('S'), Var('E')), None)
    """
    t = deref(t)
    if type(t) is not Struct or t.name != "^" or len(t.args) != 2:
        return None
    atom = deref(t.args[0])
    if type(atom) is not Struct and type(atom) is not Atom:
        return None
    stamp = deref(t.args[1])
    if type(stamp) is Struct and stamp.name == "." and len(stamp.args) == 2:
        tail = deref(stamp.args[1])
        if type(tail) is Struct and tail.name == "." and len(tail.args) == 2 \
                and deref(tail.args[1]) == "[]" and type(deref(tail.args[1])) is Atom:
            return atom, stamp.args[0], tail.args[0]
    return atom, stamp, stamp


def event_key(atom: Any) -> tuple[str, int]:
    """The event type of an event atom, as (name, arity).

    >>> event_key(Struct("location", (Atom("cup1"), Atom("table")))), event_key(Atom("tick"))
    (('location', 2), ('tick', 0))
    """
    if type(atom) is Struct:
        return str(atom.name), len(atom.args)
    return str(atom), 0


@dataclass
class Predicate:
    name: str
    arity: int
    clauses: list = field(default_factory=list)
    _index: dict | None = None
    _var_only: list | None = None

    def add(self, clause: CompiledClause) -> None:
        self.clauses.append(clause)
        self._index = None

    def candidates(self, first_arg: Any) -> list:
        """Clauses whose first head argument may unify with ``first_arg`` (dereferenced)."""
        if first_arg is None:
            return self.clauses
        tt = type(first_arg)
        if tt is Var:
            return self.clauses
        if self._index is None:
            self._build_index()
        key = (Struct, first_arg.name, len(first_arg.args)) if tt is Struct else (tt, first_arg)
        try:
            return self._index.get(key, self._var_only)
        except TypeError:
            return self.clauses

    def _build_index(self) -> None:
        keys = []
        for c in self.clauses:
            if c.index_key is not None and c.index_key not in keys:
                keys.append(c.index_key)
        index = {}
        for k in keys:
            index[k] = [c for c in self.clauses if c.index_key is None or c.index_key == k]
        self._var_only = [c for c in self.clauses if c.index_key is None]
        self._index = index


class Program:
    """The clauses of a knowledge base, keyed by name/arity; temporal rules keyed separately.

    ``preds[(name, arity)]`` holds ordinary predicates; ``temporal[(name, n)]`` the rules whose
    head is an event atom ``p(A1..An)^T`` (compiled with head args A1..An, Start, End).
    """

    def __init__(self) -> None:
        self.preds: dict[tuple[str, int], Predicate] = {}
        self.temporal: dict[tuple[str, int], Predicate] = {}
        self.dynamic: set[tuple[str, int]] = set()
        self.clauses: list[Clause] = []
        # analysis.analyze's result for this program, kept here so that it goes with the
        # program (an analysis refers to its program: a cache keyed weakly by the program
        # kept both alive for as long as the process)
        self.analysis_cache: Any = None

    def copy(self) -> "Program":
        p = Program()
        p.preds = {k: Predicate(v.name, v.arity, list(v.clauses)) for k, v in self.preds.items()}
        p.temporal = {k: Predicate(v.name, v.arity, list(v.clauses)) for k, v in self.temporal.items()}
        p.dynamic = set(self.dynamic)
        p.clauses = list(self.clauses)
        return p

    def add_clause(self, clause: Clause) -> None:
        # (a program is built text by text, and a rule's where goal may have it analysed
        # half-built: what was analysed then no longer describes it)
        self.analysis_cache = None
        head = deref(clause.head)
        ev = split_event_atom(head)
        if ev is not None:
            atom, s, e = ev
            name, n = event_key(atom)
            args = tuple(atom.args) if type(atom) is Struct else ()
            pred = self.temporal.get((name, n))
            if pred is None:
                pred = self.temporal[(name, n)] = Predicate(name, n)
            pred.add(compile_clause(args + (s, e), clause.body, clause))
        else:
            if type(head) is Struct:
                name, args = str(head.name), head.args
            else:
                name, args = str(head), ()
            key = (name, len(args))
            pred = self.preds.get(key)
            if pred is None:
                pred = self.preds[key] = Predicate(name, len(args))
            pred.add(compile_clause(tuple(args), clause.body, clause))
        self.clauses.append(clause)


@dataclass
class BufferDecl:
    """A buffer declared by a program (``:- tBuffer(Pattern, Seconds)``, ``cBuffer``) or
    added at run time (``kb.add_buffer``)."""

    kind: str              # "tBuffer" | "cBuffer"
    pattern: Any           # the event pattern term
    amount: float | int    # seconds (tBuffer) or count (cBuffer)
    clause: Clause | None  # where it was declared (None for runtime buffers)


@dataclass
class Declarations:
    """What the program declares beyond clauses (docs/language.md, "Declarations")."""

    event_types: set = field(default_factory=set)         # {(name, arity)}
    max_delay: dict = field(default_factory=dict)         # (name, arity) -> seconds | "learn"
    in_order: set = field(default_factory=set)            # {(name, arity)}
    buffers: list = field(default_factory=list)           # [BufferDecl]
    event_rules: list = field(default_factory=list)       # [cep.EventRule], dependency order
    # program name -> {(name, arity) | None: policy}: a program's consumption directives,
    # which govern its own event rules only
    consumption: dict = field(default_factory=dict)
    # [cep.EventRule] as read, every program's in load order (event_rules is made from
    # them: policies resolved, the same rule under the same policy kept once)
    read_rules: list = field(default_factory=list)

    def copy(self) -> "Declarations":
        return Declarations(set(self.event_types), dict(self.max_delay), set(self.in_order),
                            list(self.buffers), list(self.event_rules),
                            {name: dict(policies) for name, policies in self.consumption.items()},
                            list(self.read_rules))
