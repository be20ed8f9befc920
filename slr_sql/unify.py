"""Unification and term copying: the primitives shared by the interpreter, the builtins,
buffers and the SQL planner (they sit below all of them, so none has to import another).

>>> X = Var("X"); trail = []; unify(Struct("f", (X,)), Struct("f", (1,)), trail), X.ref
(True, 1)
"""
from __future__ import annotations

from typing import Any

from .terms import Atom, String, Struct, Var, deref, is_ground, list_items, make_list

__all__ = ["unify", "undo", "copy_term", "resolve", "unify_tuple", "bound_args", "match_time",
           "unify_event_row"]


def unify(a: Any, b: Any, trail: list) -> bool:
    """Unify two terms, recording bindings on ``trail``. No occurs check (as in Prolog).

    >>> X = Var("X"); tr = []; unify(Struct("f", (X,)), Struct("f", (1,)), tr), X.ref
    (True, 1)
    """
    stack = None
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
        if not stack:
            return True
        a, b = stack.pop()


def undo(trail: list, mark: int) -> None:
    """Unbind every variable bound since the trail had ``mark`` entries."""
    while len(trail) > mark:
        trail.pop().ref = None


def copy_term(t: Any, mapping: dict | None = None) -> Any:
    """Copy a term with fresh variables (bindings resolved). Iterative over list spines."""
    if mapping is None:
        mapping = {}
    t = deref(t)
    tt = type(t)
    if tt is Var:
        v = mapping.get(id(t))
        if v is None:
            v = mapping[id(t)] = Var()
        return v
    if tt is Struct:
        if t.name == "." and len(t.args) == 2:
            heads = []
            cur = t
            while type(cur) is Struct and cur.name == "." and len(cur.args) == 2:
                heads.append(copy_term(cur.args[0], mapping))
                cur = deref(cur.args[1])
            out = copy_term(cur, mapping)
            for h in reversed(heads):
                out = Struct(".", (h, out))
            return out
        return Struct(t.name, tuple([copy_term(a, mapping) for a in t.args]))
    return t


def resolve(t: Any) -> Any:
    """The term with all bound variables replaced by their values (unbound ones kept)."""
    t = deref(t)
    if type(t) is Struct:
        if t.name == "." and len(t.args) == 2:
            items, tail = list_items(t)
            return make_list([resolve(x) for x in items], resolve(tail))
        return Struct(t.name, tuple([resolve(a) for a in t.args]))
    return t


def unify_tuple(xs: tuple, ys: tuple, trail: list) -> bool:
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
    """Argument positions whose value is atomic or ground, to push into SQL."""
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
