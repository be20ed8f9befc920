"""Unification and term copying: the primitives shared by the interpreter, the builtins,
buffers and the SQL planner (they sit below all of them, so none has to import another).

>>> X = Var("X"); trail = []; unify(Struct("f", (X,)), Struct("f", (1,)), trail), X.ref
(True, 1)
"""
from __future__ import annotations

from math import copysign
from typing import Any

from .terms import (CONS, NODES_BETWEEN_CLOCK_CHECKS, Atom, String, Struct, Var, check_deadline,
                    deref, is_ground)

__all__ = ["unify", "undo", "copy_term", "resolve", "unify_tuple", "bound_args", "match_time",
           "unify_event_row"]


# Compound pairs one unify() call walks before it starts remembering pairs: small terms
# (nearly every unification) pay nothing for it, and two cyclic terms (X = f(X,X) and
# Y = f(Y,Y)) or two copies of a term with shared subterms (a DAG, exponential as a tree)
# unify after a few thousand pairs, in time linear in their distinct subterm pairs.
_PAIRS_BEFORE_CYCLE_CHECK = 2048
# Remembering pairs, unify() looks at the clock this often (pairs) when given a deadline.
_PAIRS_BETWEEN_CLOCK_CHECKS = 16384


def unify(a: Any, b: Any, trail: list, deadline: float | None = None) -> bool:
    """Unify two terms, recording bindings on ``trail``. No occurs check (as in Prolog).

    Cyclic terms (rational trees) unify in finite time, as in SWI-Prolog. ``deadline`` (a
    ``time.monotonic()`` value) stops a unification of huge terms with :class:`SLRTimeout`.

    >>> X = Var("X"); tr = []; unify(Struct("f", (X,)), Struct("f", (1,)), tr), X.ref
    (True, 1)
    """
    stack = None
    budget = _PAIRS_BEFORE_CYCLE_CHECK
    while True:
        while type(a) is Var:
            r = a.ref
            if r is None:
                break
            a = r
        while type(b) is Var:
            r = b.ref
            if r is None:
                break
            b = r
        if a is not b:
            ta = type(a)
            tb = type(b)
            if ta is Var:
                a.ref = b
                trail.append(a)
            elif tb is Var:
                b.ref = a
                trail.append(b)
            elif ta is Struct:
                if tb is not Struct or a.name != b.name:
                    return False
                aa = a.args
                ba = b.args
                n = len(aa)
                if n != len(ba):
                    return False
                budget -= 1
                if not budget:
                    return _unify_remembering(a, b, stack if stack is not None else [],
                                              trail, deadline)
                if stack is None:
                    stack = []
                if n == 2:
                    stack.append((aa[0], ba[0]))
                    a = aa[1]
                    b = ba[1]
                    continue
                stack.extend(zip(aa, ba))
            elif ta is not tb or a != b:
                if ta is float and tb is float and a != a and b != b:
                    pass
                else:
                    return False
            elif ta is float and not a and copysign(1.0, a) != copysign(1.0, b):
                return False  # -0.0 and 0.0 are equal numbers but two terms (SWI-Prolog)
        if not stack:
            return True
        a, b = stack.pop()


def _unify_remembering(a: Any, b: Any, stack: list, trail: list,
                       deadline: float | None) -> bool:
    """unify() after its first compound pairs: each pair of compounds reached through a
    variable binding is unified once (a cycle always passes through a binding), so cyclic
    terms (rational trees) unify in finite time, as in SWI-Prolog, and shared subterms once."""
    seen: set[tuple[int, int]] = set()
    clock = _PAIRS_BETWEEN_CLOCK_CHECKS
    while True:
        via = False
        while type(a) is Var:
            r = a.ref
            if r is None:
                break
            a = r
            via = True
        while type(b) is Var:
            r = b.ref
            if r is None:
                break
            b = r
            via = True
        if a is not b:
            ta = type(a)
            tb = type(b)
            if ta is Var:
                a.ref = b
                trail.append(a)
            elif tb is Var:
                b.ref = a
                trail.append(b)
            elif ta is Struct:
                if tb is not Struct or a.name != b.name:
                    return False
                aa = a.args
                ba = b.args
                n = len(aa)
                if n != len(ba):
                    return False
                clock -= 1
                if not clock:
                    clock = _PAIRS_BETWEEN_CLOCK_CHECKS
                    check_deadline(deadline)
                if via:
                    key = (id(a), id(b))
                    if key in seen:  # unified already, or being unified further down
                        a = None
                        b = None
                        if not stack:
                            return True
                        a, b = stack.pop()
                        continue
                    seen.add(key)
                if n == 2:
                    stack.append((aa[0], ba[0]))
                    a = aa[1]
                    b = ba[1]
                    continue
                stack.extend(zip(aa, ba))
            elif ta is not tb or a != b:
                if not (ta is float and tb is float and a != a and b != b):
                    return False
            elif ta is float and not a and copysign(1.0, a) != copysign(1.0, b):
                return False
        if not stack:
            return True
        a, b = stack.pop()


def undo(trail: list, mark: int) -> None:
    """Unbind every variable bound since the trail had ``mark`` entries.

    >>> X = Var("X"); trail = []; mark = len(trail)
    >>> unify(X, 1, trail), X.ref
    (True, 1)
    >>> undo(trail, mark); X.ref is None
    True
    """
    while len(trail) > mark:
        trail.pop().ref = None


# Nodes copy_term() copies as a tree before it starts copying each shared compound once:
# a term with shared subterms (X1 = f(X0,X0), X2 = f(X1,X1), ...) is exponential as a tree.
_NODES_BEFORE_SHARING = 8192


def copy_term(t: Any, mapping: dict | None = None, deadline: float | None = None) -> Any:
    """Copy a term with fresh variables (bindings resolved).

    Iterative (terms nested 100,000 deep copy), and finite on cyclic terms: their copy is
    cyclic too, through fresh bound variables; a large term's shared subterms are copied
    once (the copy shares them too). ``mapping`` (id of a variable -> its copy) keeps the
    renaming consistent across calls; ``deadline`` (``time.monotonic()``) stops the copy of
    a huge term with :class:`SLRTimeout`.

    >>> X = Var("X"); c = copy_term(Struct("f", (X, X))); c.args[0] is c.args[1] is not X
    True
    """
    if mapping is None:
        mapping = {}
    t = deref(t)
    tt = type(t)
    if tt is Var:
        v = mapping.get(id(t))
        if v is None:
            v = mapping[id(t)] = Var()
        return v
    if tt is not Struct:
        return t
    try:
        return _copy(t, mapping, None, deadline)
    except _CyclicTerm:
        return _copy(t, mapping, {}, deadline)


class _CyclicTerm(Exception):
    pass


class _Copied:
    """_copy's marker: the arguments of ``struct`` are copied, assemble the copy."""

    __slots__ = ("struct", "key", "placeholder")

    def __init__(self, struct: Struct, key: int | None, placeholder: Var | None):
        self.struct = struct
        self.key = key
        self.placeholder = placeholder


def _copy(t: Any, mapping: dict, shared: dict | None, deadline: float | None) -> Any:
    """copy_term's walk. ``shared`` None: raise _CyclicTerm on a cycle or after
    _NODES_BEFORE_SHARING nodes; a dict: each compound reached through a binding is copied
    once, and a later (or inner) occurrence refers to the copy through a fresh variable
    bound to it."""
    done: list = []
    todo: list = [t]
    gray: set[int] = set()  # compounds reached through a binding, being copied
    nodes = 0
    while todo:
        nodes += 1
        if not nodes % NODES_BETWEEN_CLOCK_CHECKS:
            check_deadline(deadline)
            if shared is None and nodes >= _NODES_BEFORE_SHARING:
                # for the mapping: variables met so far get the same copies the second time
                raise _CyclicTerm
        x = todo.pop()
        tx = type(x)
        if tx is _SpineCopied:
            k = x.n + 1
            values = done[len(done) - k:]
            del done[len(done) - k:]
            out = values[-1]
            for head in reversed(values[:-1]):
                out = Struct(CONS, (head, out))
            done.append(out)
            continue
        if tx is _Copied:
            k = len(x.struct.args)
            args = tuple(done[len(done) - k:])
            del done[len(done) - k:]
            out = Struct(x.struct.name, args)
            if x.placeholder is not None:
                x.placeholder.ref = out
            elif x.key is not None:
                gray.discard(x.key)
            done.append(out)
            continue
        via = False
        while type(x) is Var and x.ref is not None:
            x = x.ref
            via = True
        tx = type(x)
        if tx is Var:
            v = mapping.get(id(x))
            if v is None:
                v = mapping[id(x)] = Var()
            done.append(v)
        elif tx is Struct:
            args = x.args
            if len(args) == 2 and x.name == "." and not via:
                # a list spine: copy the cells of a long list without a marker each
                cells = [x]
                tail = args[1]
                while type(tail) is Struct and tail.name == "." and len(tail.args) == 2:
                    cells.append(tail)
                    tail = tail.args[1]
                if len(cells) > 1:
                    todo.append(_SpineCopied(len(cells)))
                    todo.append(tail)
                    todo.extend(c.args[0] for c in reversed(cells))
                    continue
            key = placeholder = None
            if via:
                key = id(x)
                if shared is not None:
                    known = shared.get(key)
                    if known is not None:
                        done.append(known)
                        continue
                    placeholder = shared[key] = Var()
                elif key in gray:
                    raise _CyclicTerm
                else:
                    gray.add(key)
            todo.append(_Copied(x, key, placeholder))
            todo.extend(reversed(args))
        else:
            done.append(x)
    return done[0]


class _SpineCopied:
    """_copy's marker: the heads and the tail of an n-cell list are copied."""

    __slots__ = ("n",)

    def __init__(self, n: int):
        self.n = n


def resolve(t: Any) -> Any:
    """The term with all bound variables replaced by their values (unbound ones kept).

    Iterative; a cyclic term has no such form and is returned as it is.

    >>> X = Var("X"); X.ref = 1; resolve(Struct("f", (X,))).args
    (1,)
    """
    t = deref(t)
    if type(t) is not Struct:
        return t
    try:
        return _copy_keeping_vars(t)
    except _CyclicTerm:
        return t


def _copy_keeping_vars(t: Any) -> Any:
    done: list = []
    todo: list = [t]
    gray: set[int] = set()
    # compounds reached through a binding, resolved: met again (a shared subterm), the
    # resolved term is shared too, so that X1 = f(X0, X0), X2 = f(X1, X1)... stays linear
    resolved: dict[int, Struct] = {}
    while todo:
        x = todo.pop()
        if type(x) is _Copied:
            k = len(x.struct.args)
            args = tuple(done[len(done) - k:])
            del done[len(done) - k:]
            out = Struct(x.struct.name, args)
            if x.key is not None:
                gray.discard(x.key)
                resolved[x.key] = out
            done.append(out)
            continue
        via = False
        while type(x) is Var and x.ref is not None:
            x = x.ref
            via = True
        if type(x) is Struct:
            key = None
            if via:
                key = id(x)
                known = resolved.get(key)
                if known is not None:
                    done.append(known)
                    continue
                if key in gray:
                    raise _CyclicTerm
                gray.add(key)
            todo.append(_Copied(x, key, None))
            todo.extend(reversed(x.args))
        else:
            done.append(x)
    return done[0]


def unify_tuple(xs: tuple, ys: tuple, trail: list) -> bool:
    """Unify two argument tuples position by position (of the same length), recording bindings
    on ``trail``; False at the first mismatch (the caller undoes the trail).

    >>> X = Var("X"); trail = []
    >>> unify_tuple((X, 2), (1, 2), trail), X.ref, unify_tuple((1,), (2,), trail)
    (True, 1, False)
    """
    for x, y in zip(xs, ys):
        if not unify(x, y, trail):
            return False
    return True


def match_time(t: Any, stored: float, trail: list) -> bool:
    """Match a goal's time term with a stored event time (a float) *by value*: an unbound
    variable is bound to the stored float, a number matches when it is numerically equal
    (``5`` matches ``5.0``), anything else fails. Stored times only; data arguments and
    clause heads unify as Prolog terms (``1 \\= 1.0``).

    >>> T = Var("T"); tr = []; match_time(5, 5.0, tr), match_time(T, 5.0, tr), T.ref
    (True, True, 5.0)
    """
    while type(t) is Var:
        r = t.ref
        if r is None:
            t.ref = stored
            trail.append(t)
            return True
        t = r
    tt = type(t)
    # exact comparison (Python compares an int with a float exactly); NaN equals nothing
    return (tt is float or tt is int) and t == stored


def unify_event_row(args: tuple, start_term: Any, end_term: Any, values, start: float,
                    end: float, trail: list) -> bool:
    """Match an event pattern (data arguments, start and end terms) with a stored row:
    the data by unification, then the times by value (:func:`match_time`).

    >>> T = Var("T"); unify_event_row((Atom("x"),), T, T, (Atom("x"),), 5.0, 5.0, []), T.ref
    (True, 5.0)
    """
    for x, y in zip(args, values):
        if not unify(x, y, trail):
            return False
    return match_time(start_term, start, trail) and match_time(end_term, end, trail)


def bound_args(args: tuple) -> dict:
    """Argument positions whose value is atomic or ground, to push into SQL.

    >>> from slr_sql.terms import Atom
    >>> bound_args((Atom("cup1"), Var("L"), Struct("p", (1, 2)), Struct("p", (Var("X"), 2))))
    {0: Atom('cup1'), 2: Struct('p', (1, 2))}
    """
    bound = {}
    for i, a in enumerate(args):
        a = deref(a)
        ta = type(a)
        if ta is Atom or ta is int or ta is String or (ta is float and a == a):
            bound[i] = a
        elif ta is Struct:
            if is_ground(a):
                bound[i] = resolve(a)
    return bound
