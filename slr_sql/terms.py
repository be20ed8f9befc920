"""Prolog terms as used everywhere in slr_sql.

The representation is chosen so that the interpreter's hot loop stays cheap and so that
answers can be handed to Python callers without copying:

* atom       -> :class:`Atom` (a ``str`` subclass; ``Atom("cup1") == "cup1"``)
* string     -> :class:`String` inside the engine; returned to callers as a plain ``str``
* integer    -> ``int``;  float -> ``float``  (``1`` and ``1.0`` do not unify, as in Prolog)
* compound   -> :class:`Struct` (``name``: str, ``args``: tuple)
* list       -> cons cells ``Struct('.', (Head, Tail))`` ending in the atom ``[]``
* variable   -> :class:`Var`, bound by setting ``ref`` (undone through the engine's trail)

Terms are immutable except for ``Var.ref``; clause bodies and heads are shared, never
mutated, and renamed apart before use.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable

__all__ = [
    "Atom", "String", "Struct", "Var", "NIL", "TRUE", "CONS",
    "deref", "make_list", "list_items", "is_ground", "is_callable", "from_python",
    "to_python", "term_vars", "Span", "Clause", "indicator",
]


class Atom(str):
    """A Prolog atom. Equal to the ``str`` with the same text, so ``Atom('a') == 'a'``.

    >>> Atom("cup1") == "cup1", repr(Atom("cup1"))
    (True, "Atom('cup1')")
    """

    __slots__ = ()

    def __repr__(self) -> str:
        return f"Atom({str.__repr__(self)})"


class String(str):
    """A Prolog string ("text" in double quotes). Callers get it back as a plain ``str``.

    >>> String("a string") == "a string"
    True
    """

    __slots__ = ()

    def __repr__(self) -> str:
        return f"String({str.__repr__(self)})"


class Var:
    """A logic variable. ``ref`` is ``None`` while unbound; ``name`` is for answers and printing.

    >>> v = Var("X"); v.ref is None
    True
    """

    __slots__ = ("ref", "name")
    _counter = 0

    def __init__(self, name: str | None = None):
        self.ref = None
        if name is None:
            Var._counter += 1
            name = f"_G{Var._counter}"
        self.name = name

    def __repr__(self) -> str:
        return f"Var({self.name!r})" if self.ref is None else f"Var({self.name!r}={self.ref!r})"

    def __str__(self) -> str:
        return self.name if self.ref is None else str(self.ref)


class Struct:
    """A compound term ``name(args...)``. ``args`` is a tuple; ``str()`` gives Prolog text.

    >>> str(Struct("f", ("x", 1)))
    'f(x,1)'
    """

    __slots__ = ("name", "args")

    def __init__(self, name: str, args: Iterable[Any]):
        self.name = name if type(name) is Atom else Atom(name)
        self.args = args if type(args) is tuple else tuple(args)

    @property
    def arity(self) -> int:
        return len(self.args)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Struct):
            return NotImplemented
        return term_equal(self, other)

    def __hash__(self) -> int:
        return hash((self.name, len(self.args)))

    def __repr__(self) -> str:
        return f"Struct({str(self.name)!r}, {self.args!r})"

    def __str__(self) -> str:
        from .printer import format_term

        return format_term(self)


NIL = Atom("[]")
TRUE = Atom("true")
CONS = Atom(".")


def indicator(term: Any) -> tuple[str, int]:
    """Name and arity of a callable term."""
    if type(term) is Struct:
        return term.name, len(term.args)
    return str(term), 0


def deref(t: Any) -> Any:
    """Follow variable bindings to the representative term (iterative)."""
    while type(t) is Var:
        r = t.ref
        if r is None:
            return t
        t = r
    return t


def term_equal(a: Any, b: Any) -> bool:
    """Structural identity (``==``) after dereferencing; no recursion limit on long lists."""
    stack = [(a, b)]
    while stack:
        x, y = stack.pop()
        x = deref(x)
        y = deref(y)
        if x is y:
            continue
        tx = type(x)
        if tx is not type(y):
            return False
        if tx is Struct:
            if x.name != y.name or len(x.args) != len(y.args):
                return False
            stack.extend(zip(x.args, y.args))
        elif tx is Var:
            return False
        elif tx is float:
            if not (x == y or (math.isnan(x) and math.isnan(y))):
                return False
        elif x != y:
            return False
    return True


def make_list(items: Iterable[Any], tail: Any = NIL) -> Any:
    """Build a Prolog list from Python items.

    >>> str(make_list([1, 2]))
    '[1,2]'
    """
    items = list(items)
    out = tail
    for x in reversed(items):
        out = Struct(CONS, (x, out))
    return out


def list_items(t: Any) -> tuple[list, Any]:
    """Split a (possibly partial) list into its dereferenced items and its dereferenced tail."""
    items = []
    t = deref(t)
    while type(t) is Struct and t.name == "." and len(t.args) == 2:
        items.append(t.args[0])
        t = deref(t.args[1])
    return items, t


def is_ground(t: Any) -> bool:
    stack = [t]
    while stack:
        x = deref(stack.pop())
        tx = type(x)
        if tx is Var:
            return False
        if tx is Struct:
            stack.extend(x.args)
    return True


def is_callable(t: Any) -> bool:
    t = deref(t)
    return type(t) is Struct or type(t) is Atom


def term_vars(t: Any) -> list[Var]:
    """Unbound variables of a term, depth-first left to right, each once."""
    seen: set[int] = set()
    out: list[Var] = []
    stack = [t]
    while stack:
        x = deref(stack.pop())
        tx = type(x)
        if tx is Var:
            if id(x) not in seen:
                seen.add(id(x))
                out.append(x)
        elif tx is Struct:
            stack.extend(reversed(x.args))
    return out


def from_python(value: Any) -> Any:
    """Convert a Python value given by a caller into a term.

    ``str`` -> atom, :class:`String` -> string, ``int``/``float``, ``list``/``tuple`` -> list,
    :class:`Struct` (its args converted too). Terms already in engine form pass through.

    >>> str(from_python(["cup1", 1, 2.5]))
    '[cup1,1,2.5]'
    """
    tv = type(value)
    if tv is Atom or tv is String or tv is int or tv is float or tv is Var:
        return value
    if tv is str:
        return Atom(value)
    if tv is bool:
        return Atom("true" if value else "false")
    if isinstance(value, (list, tuple)):
        return make_list([from_python(v) for v in value])
    if tv is Struct:
        return Struct(value.name, tuple(from_python(a) for a in value.args))
    if isinstance(value, String):
        return String(value)
    if isinstance(value, str):
        return Atom(value)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value)
    raise TypeError(f"cannot convert {value!r} ({tv.__name__}) to an SLR term")


def to_python(t: Any) -> Any:
    """Convert a term into the value handed to callers (SPEC §4).

    Atoms stay :class:`Atom`, strings become ``str``, proper lists become ``list``, compounds
    :class:`Struct` with converted args, unbound variables stay :class:`Var`.

    >>> to_python(make_list([Atom("a"), String("s")]))
    [Atom('a'), 's']
    """
    t = deref(t)
    tt = type(t)
    if tt is Atom or tt is int or tt is float:
        return t
    if tt is String:
        return str(t)
    if tt is Var:
        return t
    if tt is Struct:
        if t.name == "." and len(t.args) == 2:
            items, tail = list_items(t)
            if tail == NIL and type(tail) is Atom:
                return [to_python(x) for x in items]
            # a partial list: rebuild the spine in a loop, not by recursing on each tail
            out = to_python(tail)
            for x in reversed(items):
                out = Struct(CONS, (to_python(x), out))
            return out
        return Struct(t.name, tuple(to_python(a) for a in t.args))
    return t


@dataclass(frozen=True, slots=True)
class Span:
    """Where a clause or term came from, for error messages."""

    filename: str
    line: int
    column: int
    end_line: int = 0
    end_column: int = 0


@dataclass(frozen=True, slots=True)
class Clause:
    """One program clause. ``head`` is None for a directive ``:- body``; ``body`` is TRUE for facts.

    ``varnames`` maps each named variable of the clause to its :class:`Var`.
    """

    head: Any
    body: Any
    span: Span | None = None
    varnames: tuple = ()
    text: str = ""
