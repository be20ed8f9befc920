"""Static analysis of SLR programs: the predicate dependency graph, goal sets, recursion.

Used by synchronized queries (:mod:`slr_sql.sync`: which event types must be complete before
a query may be answered) and by the SQL compiler (which predicates are recursive).

Nodes of the graph are :class:`Node` tuples:

* ``Node("pred", name, arity)`` — an ordinary predicate (user program or the Prolog-defined
  library, :func:`slr_sql.builtins.library_program`);
* ``Node("event", name, n)`` — an *event goal* ``p(A1..An)^T``: the stored events of type
  p/n followed by the temporal rules whose head is ``p(..)^T``.

An edge A → B means a clause of A may call B. Besides the edges, each node lists the event
types whose *stored* events its clauses read directly: an event goal reads its own type, and
``prev(E^Z, ..)`` / ``next(E^Z, ..)`` read E's type — and only the stored events: prev and next
never call rules, so they add no edge.

Calls the analysis cannot resolve — ``call(G)`` or a goal that is a variable, ``prev(E, T)``
with E unbound — make the node *unknown*: anything may be called. Meta-predicates are
resolved at their call sites: a predicate whose clause calls ``call(G, X..)`` with ``G`` one
of its head arguments is a meta-predicate in that argument (inferred, to a fixpoint, for the
library's ``maplist``, ``include``, ``foldl``, ``once``, ... and for user predicates alike), so
``maplist(seen_at, Ts)`` depends on ``seen_at/1`` and is not unknown.

>>> from slr_sql.parser import parse_program
>>> from slr_sql.program import Program
>>> p = Program()
>>> for c in parse_program("color(O,C)^T :- prev(obj(O,_,C)^Z, T).  ok(O) :- color(O, red)^1."):
...     p.add_clause(c)
>>> sorted(goal_set(p, "ok(X)"))       # color/2 may also have stored events
[('color', 2), ('obj', 3)]
>>> sorted(goal_set(p, "prev(color(cup, C)^Z, 2)"))   # prev reads stored events only
[('color', 2)]
"""
from __future__ import annotations

import weakref
from typing import Any, Iterable, NamedTuple

from .program import Program, Slot, Template, split_event_atom, event_key
from .terms import Atom, Struct, Var, deref

__all__ = ["Node", "GoalSet", "Analysis", "analyze", "goal_refs", "goal_set",
           "dependency_graph", "reachable", "sccs", "recursive_predicates"]


class Node(NamedTuple):
    """A node of the dependency graph: ``kind`` is ``"pred"`` or ``"event"``.

    >>> str(Node("pred", "ok", 1)), str(Node("event", "seg", 2))
    ('ok/1', 'seg/2^')
    """

    kind: str
    name: str
    arity: int

    def __str__(self) -> str:
        return f"{self.name}/{self.arity}" + ("^" if self.kind == "event" else "")


class GoalSet(frozenset):
    """A set of event types ``(name, n)``. ``unknown`` is True when the goal may call something
    the analysis cannot see (``call/N`` on a variable, ...): the set is then every event type
    known to the program (plus ``known_types``) and ``reasons`` says why.

    >>> g = GoalSet({("seg", 2)}); g.unknown, sorted(g)
    (False, [('seg', 2)])
    """

    unknown: bool = False
    reasons: tuple = ()

    def __new__(cls, items: Iterable = (), unknown: bool = False, reasons: Iterable = ()):
        self = super().__new__(cls, items)
        self.unknown = unknown
        self.reasons = tuple(reasons)
        return self

    def __repr__(self) -> str:
        inner = ", ".join(f"{n}/{a}" for n, a in sorted(self))
        return f"GoalSet({{{inner}}}{', unknown' if self.unknown else ''})"


# Control constructs and collecting builtins: which arguments are goals (index, extra args).
_GOAL_ARGS: dict[tuple[str, int], tuple[int, ...]] = {
    (",", 2): (0, 1), (";", 2): (0, 1), ("->", 2): (0, 1), ("*->", 2): (0, 1),
    ("\\+", 1): (0,), ("not", 1): (0,), ("call", 1): (0,),
    ("findall", 3): (1,), ("findall", 4): (1,), ("findAll", 3): (1,), ("forall", 2): (0, 1),
    ("aggregate_all", 3): (1,), ("bagof", 3): (1,), ("setof", 3): (1,), ("catch", 3): (0, 2),
    ("$with_output_to", 2): (1,),   # (the library's with_output_to/2)
}
_PREV_NEXT = {("prev", 2), ("next", 2), ("next", 3)}
# tf_lookup/4,5 read the stored transforms (slr_sql.frames), like prev/next
_TF_LOOKUP = {("tf_lookup", 4), ("tf_lookup", 5)}
_TF_TYPES = (("tf", 3), ("tf_static", 3))


class _Refs:
    """What one goal (or clause body) refers to."""

    __slots__ = ("nodes", "stored", "var_calls", "reasons")

    def __init__(self) -> None:
        self.nodes: set[Node] = set()          # predicates / event goals it may call
        self.stored: set[tuple[str, int]] = set()  # event types whose stored events it reads
        self.var_calls: list[tuple[Any, int]] = []  # (variable, extra args) called as goals
        self.reasons: list[str] = []           # unresolvable calls other than variables


def _as_term(t: Any) -> Any:
    """Compiled clause terms (Slot/Template) -> plain terms (a Var per Slot, shared)."""
    memo: dict[int, Var] = {}

    def conv(x: Any) -> Any:
        tx = type(x)
        if tx is Slot:
            v = memo.get(x.index)
            if v is None:
                v = memo[x.index] = Var(x.name)
            return v
        if tx is Template:
            return Struct(x.name, tuple(conv(a) for a in x.args))
        return x
    return conv(t)


def goal_refs(goal: Any, program: Program | None = None, library: Program | None = None,
              meta: dict | None = None, visited: set | None = None) -> _Refs:
    """The nodes, stored event types and variable calls of one goal term (not transitive).

    ``meta`` maps predicate keys to their meta-arguments ``{(index, extra_args)}`` (see
    :func:`analyze`); ``program``/``library`` tell user predicates from builtins. Every
    ``(name, arity)`` the goal calls is added to ``visited`` when given.

    >>> from slr_sql.parser import parse_term
    >>> r = goal_refs(parse_term("(seg(O,P)^T, \\\\+ prev(obj(O,_)^Z, T))")[0])
    >>> sorted(map(str, r.nodes)), sorted(r.stored)
    (['seg/2^'], [('obj', 2), ('seg', 2)])
    """
    refs = _Refs()
    meta = meta or {}
    preds = program.preds if program is not None else {}
    lib = library.preds if library is not None else {}
    stack: list[tuple[Any, int]] = [(goal, 0)]
    while stack:
        g, extra = stack.pop()
        g = deref(g)
        tg = type(g)
        if tg is Var or tg is Slot:
            refs.var_calls.append((g, extra))
            continue
        if tg is Template:
            g = _as_term(g)
            tg = Struct
        if tg is Atom:
            name, args = str(g), ()
        elif tg is Struct:
            name, args = str(g.name), tuple(g.args)
        else:
            continue  # a number or string as a goal: a type error at run time, calls nothing
        if extra:
            args = args + tuple(Var() for _ in range(extra))
        key = (name, len(args))
        if visited is not None:
            visited.add(key)
        if key == ("^", 2):
            ev = split_event_atom(Struct("^", args))
            if ev is None:          # V^Goal (bagof/setof or plain): the goal is called
                stack.append((args[1], 0))
                continue
            etype = event_key(deref(ev[0]))
            refs.nodes.add(Node("event", *etype))
            refs.stored.add(etype)
            continue
        if key in _PREV_NEXT:
            ev = split_event_atom(args[0])
            if ev is None:
                refs.reasons.append(f"{name}/{len(args)} on an event that is not known "
                                    f"before the call")
            else:
                refs.stored.add(event_key(deref(ev[0])))
            continue
        if key in _TF_LOOKUP:
            refs.stored.update(_TF_TYPES)
            continue
        if name == "call" and len(args) > 1:
            stack.append((args[0], len(args) - 1))
            continue
        goal_args = _GOAL_ARGS.get(key)
        if goal_args is not None:
            for i in goal_args:
                stack.append((args[i], 0))
            continue
        if key in preds or key in lib:
            refs.nodes.add(Node("pred", *key))
            for i, k in meta.get(key, ()):
                stack.append((args[i], k))
        # anything else: a builtin, a Python predicate or an undefined predicate: no calls
    return refs


class Analysis:
    """The dependency graph of a program (with the library), computed once per Program.

    ``edges[node]`` — the nodes its clauses may call; ``stored[node]`` — the event types whose
    stored events its clauses read; ``unknown[node]`` — reasons it may call anything;
    ``meta[(name, arity)]`` — meta-arguments ``{(index, extra_args)}`` of predicates.
    """

    def __init__(self, program: Program, library: Program | None = None):
        if library is None:
            from .builtins import library_program
            library = library_program()
        self.program = program        # (held weakly: see the property)
        self.library = library
        self.meta: dict[tuple[str, int], set[tuple[int, int]]] = {}
        self.edges: dict[Node, set[Node]] = {}
        self.stored: dict[Node, set[tuple[str, int]]] = {}
        self.unknown: dict[Node, list[str]] = {}
        self._build()

    @property
    def program(self) -> Program:
        """The program analysed. The program keeps its analysis (``analysis_cache``), so the
        analysis refers to it weakly: a replaced program is freed by reference counting,
        not left to the cyclic collector (which `slr serve` runs rarely)."""
        program = self._program()
        if program is None:
            raise ReferenceError("the analysed program is gone")
        return program

    @program.setter
    def program(self, program: Program) -> None:
        self._program = weakref.ref(program)

    def _clauses(self, prog: Program) -> list[tuple[Node, tuple, Any]]:
        """(node, head args, body) for every clause of ``prog``."""
        out = []
        for key, pred in prog.preds.items():
            node = Node("pred", *key)
            out.extend((node, *self._head_body(c)) for c in pred.clauses)
        for key, pred in prog.temporal.items():
            node = Node("event", *key)
            out.extend((node, *self._head_body(c)) for c in pred.clauses)
        return out

    @staticmethod
    def _head_body(c: Any) -> tuple[tuple, Any]:
        src = c.source
        if src is not None and src.head is not None:
            head = deref(src.head)
            ev = split_event_atom(head)
            if ev is not None:
                atom = deref(ev[0])
                args = tuple(atom.args) if type(atom) is Struct else ()
                return args + (ev[1], ev[2]), src.body
            return (tuple(head.args) if type(head) is Struct else ()), src.body
        return tuple(_as_term(a) for a in c.head), [_as_term(g) for g in c.body]

    def _body_refs(self, body: Any, visited: set | None = None) -> _Refs:
        if isinstance(body, list):
            goal: Any = Atom("true")
            for g in reversed(body):
                goal = g if goal == "true" else Struct(",", (g, goal))
            body = goal
        return goal_refs(body, self.program, self.library, self.meta, visited)

    def _build(self) -> None:
        # The library is the same for every program: its part of the graph is computed once
        # and copied, unless the program defines a predicate the library calls (then a
        # library clause's calls, and the meta-arguments they follow, depend on the program).
        part = _library_part(self.library) if self.program is not self.library else None
        if part is not None and part.visited.isdisjoint(self.program.preds):
            self.meta = {k: set(v) for k, v in part.meta.items()}
            self.edges = {k: set(v) for k, v in part.edges.items()}
            self.stored = {k: set(v) for k, v in part.stored.items()}
            self.unknown = {k: list(v) for k, v in part.unknown.items()}
            self._add_clauses(self._clauses(self.program))
        else:
            self._add_clauses(self._clauses(self.library) + self._clauses(self.program))
        for key in self.program.temporal:
            self.stored.setdefault(Node("event", *key), set()).add(key)

    def _add_clauses(self, clauses: list[tuple[Node, tuple, Any]],
                     visited: set | None = None) -> None:
        # meta-arguments, to a fixpoint: call(G, ..) with G a head argument
        changed = True
        while changed:
            changed = False
            for node, head, body in clauses:
                if node.kind != "pred":
                    continue
                refs = self._body_refs(body, visited)
                for var, extra in refs.var_calls:
                    for i, h in enumerate(head):
                        if deref(h) is var:
                            spec = self.meta.setdefault((node.name, node.arity), set())
                            if (i, extra) not in spec:
                                spec.add((i, extra))
                                changed = True
        for node, head, body in clauses:
            refs = self._body_refs(body, visited)
            self.edges.setdefault(node, set()).update(refs.nodes)
            stored = self.stored.setdefault(node, set())
            stored.update(refs.stored)
            if node.kind == "event":
                stored.add((node.name, node.arity))
            reasons = list(refs.reasons)
            head_vars = {id(deref(h)) for h in head}
            for var, _extra in refs.var_calls:
                if id(var) not in head_vars or node.kind != "pred":
                    reasons.append(f"{node} calls the variable goal {var}")
            if reasons:
                self.unknown.setdefault(node, []).extend(reasons)

    def event_types(self) -> set[tuple[str, int]]:
        """Every event type the program mentions (event goals, prev/next, temporal heads)."""
        out: set[tuple[str, int]] = set()
        for types in self.stored.values():
            out.update(types)
        return out


class _LibraryPart:
    """The library's own part of every program's graph (its clauses analysed with no user
    program), and ``visited``: every (name, arity) its clauses call."""

    __slots__ = ("meta", "edges", "stored", "unknown", "visited")

    def __init__(self, library: Program):
        alone = Analysis.__new__(Analysis)
        empty = Program()      # (alive while analysed: the analysis holds it weakly)
        alone.program, alone.library = empty, library
        alone.meta, alone.edges, alone.stored, alone.unknown = {}, {}, {}, {}
        self.visited: set[tuple[str, int]] = set()
        alone._add_clauses(alone._clauses(library), self.visited)
        self.meta, self.edges = alone.meta, alone.edges
        self.stored, self.unknown = alone.stored, alone.unknown


_LIBRARY_PARTS: "weakref.WeakKeyDictionary[Program, _LibraryPart]" = weakref.WeakKeyDictionary()


def _library_part(library: Program) -> _LibraryPart:
    part = _LIBRARY_PARTS.get(library)
    if part is None:
        part = _LIBRARY_PARTS[library] = _LibraryPart(library)
    return part


def analyze(program: Program, library: Program | None = None) -> Analysis:
    """The (cached) :class:`Analysis` of ``program``. Programs are replaced, not mutated, on
    load (``KnowledgeBase.load`` builds a new Program), so the cache is kept on the object
    (``program.analysis_cache``) and goes with it.

    >>> p = Program(); a = analyze(p); ("maplist", 2) in a.meta, analyze(p) is a
    (True, True)
    """
    if library is not None:
        return Analysis(program, library)
    a = program.analysis_cache
    if a is None:
        a = program.analysis_cache = Analysis(program)
    return a


def dependency_graph(program: Program, library: Program | None = None) -> dict[Node, set[Node]]:
    """Edges of the predicate dependency graph (library included).

    >>> from slr_sql.parser import parse_program
    >>> p = Program(); [p.add_clause(c) for c in parse_program("a :- b, c(1). b. c(_).")] and None
    >>> sorted(map(str, dependency_graph(p)[Node("pred", "a", 0)]))
    ['b/0', 'c/1']
    """
    return analyze(program, library).edges


def reachable(program: Program, start: Iterable[Node], library: Program | None = None
              ) -> set[Node]:
    """Every node reachable from ``start`` (included) through the graph.

    >>> from slr_sql.parser import parse_program
    >>> p = Program(); [p.add_clause(c) for c in parse_program("a :- b. b :- c. c.")] and None
    >>> sorted(map(str, reachable(p, [Node("pred", "b", 0)])))
    ['b/0', 'c/0']
    """
    edges = analyze(program, library).edges
    seen: set[Node] = set()
    stack = list(start)
    while stack:
        n = stack.pop()
        if n in seen:
            continue
        seen.add(n)
        stack.extend(edges.get(n, ()))
    return seen


def goal_set(program: Program, goal: Any, library: Program | None = None,
             known_types: Iterable[tuple[str, int]] = ()) -> GoalSet:
    """The goal set of ``goal`` (a term or goal text): the event types whose events may be
    read while proving it through the rules (SLR paper, "Goal Set"), including the types read
    by prev/next. When the goal may call something unknown (a variable goal, ``call/N`` on a
    variable), the result is every event type the program mentions plus ``known_types``, with
    ``unknown=True`` and the ``reasons``.

    >>> from slr_sql.parser import parse_program
    >>> p = Program()
    >>> for c in parse_program("cups(L) :- findall(O, (obj(O,cup,_)^_, next(seg(O,_)^_, [1,2])), L)."):
    ...     p.add_clause(c)
    >>> sorted(goal_set(p, "cups(L)"))
    [('obj', 3), ('seg', 2)]
    >>> g = goal_set(p, "call(G)", known_types=[("tf", 3)]); g.unknown, sorted(g)
    (True, [('obj', 3), ('seg', 2), ('tf', 3)])
    """
    if isinstance(goal, str):
        from .parser import parse_term
        goal = parse_term(goal, "<goal>")[0]
    a = analyze(program, library)
    refs = goal_refs(goal, a.program, a.library, a.meta)
    reasons = list(refs.reasons)
    reasons += [f"the goal calls the variable {v}" for v, _ in refs.var_calls]
    types = set(refs.stored)
    for node in reachable(program, refs.nodes, library):
        types.update(a.stored.get(node, ()))
        if node in a.unknown:
            reasons.extend(a.unknown[node])
    if reasons:
        types = a.event_types() | set(known_types) | types
        return GoalSet(types, True, reasons)
    return GoalSet(types)


def sccs(edges: dict[Any, Iterable[Any]],
         roots: Iterable[Any] | None = None) -> list[list[Any]]:
    """Strongly connected components (Tarjan, iterative), callees before callers: of every
    node, or of those reachable from ``roots`` (a node's component holds only nodes it
    reaches, so theirs are the same as in the whole graph's).

    >>> sccs({1: [2], 2: [1, 3], 3: []})
    [[3], [2, 1]]
    >>> sccs({1: [2], 2: [1, 3], 3: [], 4: [4]}, roots=[3, 2])
    [[3], [1, 2]]
    """
    index: dict[Any, int] = {}
    low: dict[Any, int] = {}
    on_stack: set = set()
    stack: list = []
    out: list[list[Any]] = []
    counter = 0
    if roots is not None:
        nodes = list(roots)
    else:
        nodes = list(edges)
        for n in edges.values():
            for m in n:
                if m not in edges:
                    nodes.append(m)
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(edges.get(root, ())))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, it = work[-1]
            advanced = False
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(edges.get(w, ()))))
                    advanced = True
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            if advanced:
                continue
            work.pop()
            if work:
                u = work[-1][0]
                low[u] = min(low[u], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                out.append(comp)
    return out


def recursive_predicates(program: Program, library: Program | None = None,
                         include_library: bool = False) -> set[Node]:
    """Nodes on a cycle of the dependency graph (a component of size > 1 or a self-call).
    Library predicates (``append``, ``member``, ...) are left out unless ``include_library``.

    >>> from slr_sql.parser import parse_program
    >>> p = Program()
    >>> for c in parse_program("anc(X,Y) :- par(X,Y). anc(X,Y) :- par(X,Z), anc(Z,Y). par(a,b)."):
    ...     p.add_clause(c)
    >>> sorted(map(str, recursive_predicates(p)))
    ['anc/2']
    """
    a = analyze(program, library)
    out: set[Node] = set()
    user = None
    if not include_library:
        user = {Node("pred", *k) for k in program.preds} | \
            {Node("event", *k) for k in program.temporal}
    # (the program's nodes only: not the whole library's graph, which every store's open
    # and every load asked about again)
    for comp in sccs(a.edges, user):
        if len(comp) > 1 or comp[0] in a.edges.get(comp[0], ()):
            out.update(comp)
    if user is not None:
        out &= user
    return out
