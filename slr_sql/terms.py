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

import functools
import itertools
import math
import re
import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable

from .errors import SLRTimeout
from .unichars import ESCAPED, ID_CONTINUE, ID_START, SYMBOL

__all__ = [
    "Atom", "String", "Struct", "Var", "NIL", "TRUE", "CONS",
    "deref", "make_list", "list_items", "is_ground", "is_callable", "from_python",
    "to_python", "term_vars", "Span", "Clause", "indicator",
    "format_term", "format_atom", "quoted_text", "undrawn_character", "char_escape", "INFIX_OPS", "PREFIX_OPS", "OPERATORS",
    "MAX_INTEGER_BITS", "int_text", "int_from_text", "factorize_cycles", "BODY_CONTROL",
    "body_problem", "CheckedBodies",
]

# The largest integer slr_sql reads, computes or stores, in bits (2**18 bits: about 78,900
# decimal digits). Python's integers are unbounded, but CPython multiplies, divides and
# converts big ones in quadratic time, within one uninterruptible call: beyond this size one
# operation could outlast a query's timeout. Arithmetic that would go beyond it raises
# resource_error(max_integer_size); a literal beyond it is a syntax error.
MAX_INTEGER_BITS = 1 << 18
# Python's own str(int)/int(str) refuse more than 4,300 decimal digits; pieces below this
# many digits are converted by Python, bigger ones split in halves (divide and conquer).
_PIECE_DIGITS = 3000


@functools.lru_cache(maxsize=64)
def _power_of_ten(k: int) -> int:
    return 10 ** k


def int_text(n: int) -> str:
    """Decimal text of an integer, also beyond Python's 4,300-digit ``str()`` limit.

    >>> len(int_text(10 ** 5000)), int_text(-42)
    (5001, '-42')
    """
    if n.bit_length() <= _PIECE_DIGITS * 3:
        return str(n)
    if n < 0:
        return "-" + int_text(-n)
    half = int(n.bit_length() * 0.30103) // 2  # about half the decimal digits
    high, low = divmod(n, _power_of_ten(half))
    return int_text(high) + int_text(low).rjust(half, "0")


def int_from_text(digits: str, base: int = 10) -> int:
    """The integer written by ``digits`` (digits of ``base``, optionally after ``-``), also
    beyond Python's 4,300-digit ``int()`` limit.

    >>> int_from_text("1" * 5000) % 1000, int_from_text("ff", 16), int_from_text("-7")
    (111, 255, -7)
    """
    # (int() has no limit in a base that is a power of two, and the limit in any other)
    if len(digits) <= _PIECE_DIGITS or base & (base - 1) == 0:
        return int(digits, base)
    if digits[0] == "-":
        return -int_from_text(digits[1:], base)
    half = len(digits) // 2
    scale = _power_of_ten(half) if base == 10 else base ** half
    return (int_from_text(digits[:-half], base) * scale
            + int_from_text(digits[-half:], base))


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


_VAR_AGES = itertools.count(1)


class Var:
    """A logic variable. ``ref`` is ``None`` while unbound; ``name`` is for answers and printing.

    >>> v = Var("X"); v.ref is None
    True
    """

    __slots__ = ("ref", "name", "age")

    def __init__(self, name: str | None = None):
        self.ref = None
        # the standard order of two variables is their age, as SWI-Prolog's (by address):
        # of a query's, the first written is the oldest
        self.age = age = next(_VAR_AGES)
        self.name = f"_G{age}" if name is None else name

    def __repr__(self) -> str:
        return f"Var({self.name!r})" if self.ref is None else _term_repr(self)

    def __str__(self) -> str:
        return self.name if self.ref is None else format_term(self)


class Struct:
    """A compound term ``name(args...)``. ``args`` is a tuple; ``str()`` gives Prolog text.

    >>> str(Struct("f", (Atom("x"), 1)))
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
        return _term_repr(self)

    def __str__(self) -> str:
        return format_term(self)


def _term_repr(t: Any) -> str:
    """repr() of a term, ``Struct('f', (Atom('a'),))`` style, from an explicit stack (a
    term nested 100,000 deep has a repr); a binding met again inside itself (a cyclic
    term) is shown as ``Var('X'=...)``."""
    out: list[str] = []
    todo: list = [t]
    open_vars: set[int] = set()
    while todo:
        x = todo.pop()
        tx = type(x)
        if tx is _ReprText:
            out.append(x.text)
            if x.closes is not None:
                open_vars.discard(x.closes)
        elif tx is Struct:
            out.append(f"Struct({str(x.name)!r}, (")
            todo.append(_ReprText(",))" if len(x.args) == 1 else "))"))
            _push_items(todo, x.args)
        elif tx is Var and x.ref is not None:
            if id(x) in open_vars:
                out.append(f"Var({x.name!r}=...)")
                continue
            open_vars.add(id(x))
            out.append(f"Var({x.name!r}=")
            todo.append(_ReprText(")", id(x)))
            todo.append(x.ref)
        elif tx is list or tx is tuple:
            out.append("[" if tx is list else "(")
            todo.append(_ReprText("]" if tx is list else (",)" if len(x) == 1 else ")")))
            _push_items(todo, x)
        elif tx is int:
            out.append(int_text(x))  # repr() refuses more than 4,300 digits
        else:
            out.append(repr(x))
    return "".join(out)


def _push_items(todo: list, items: Any) -> None:
    for k in range(len(items) - 1, -1, -1):
        todo.append(items[k])
        if k:
            todo.append(_ReprText(", "))


class _ReprText:
    """_term_repr's marker: text to write (and a binding to close) after the items above."""

    __slots__ = ("text", "closes")

    def __init__(self, text: str, closes: int | None = None):
        self.text = text
        self.closes = closes


NIL = Atom("[]")
TRUE = Atom("true")
CONS = Atom(".")


def indicator(term: Any) -> tuple[str, int]:
    """Name and arity of a callable term.

    >>> "%s/%d" % indicator(Struct("location", (Atom("cup1"), Atom("table")))), indicator(Atom("halt"))
    ('location/2', ('halt', 0))
    """
    if type(term) is Struct:
        return term.name, len(term.args)
    return str(term), 0


# Nodes a term walk (printing, converting, copying, comparing) visits between two looks at
# the clock when it has a deadline: a cheap counter, a clock read a few times a millisecond.
NODES_BETWEEN_CLOCK_CHECKS = 4096


# Tokens of a term an error message shows (the error term itself keeps it whole).
MESSAGE_TOKENS = 4096


def check_deadline(deadline: float | None) -> None:
    """Raise :class:`SLRTimeout` when ``deadline`` (a ``time.monotonic()`` value) has passed:
    the long walks over terms call it every few thousand nodes, so that a query's
    ``timeout=`` holds inside one huge or cyclic term too.

    >>> check_deadline(None); check_deadline(time.monotonic() + 60)
    """
    if deadline is not None and time.monotonic() > deadline:
        raise SLRTimeout("query timed out inside a term walk (a huge or deeply shared term)")


def deref(t: Any) -> Any:
    """Follow variable bindings to the representative term (iterative).

    >>> X, Y = Var("X"), Var("Y"); X.ref = Y; Y.ref = Atom("cup1")
    >>> deref(X), deref(Var("Z"))
    (Atom('cup1'), Var('Z'))
    """
    while type(t) is Var:
        r = t.ref
        if r is None:
            return t
        t = r
    return t


def term_equal(a: Any, b: Any) -> bool:
    """Structural identity (``==``) after dereferencing: iterative (no recursion limit on
    deep or long terms), and finite on cyclic terms (compared as rational trees).

    >>> X = Var("X"); X.ref = 1
    >>> term_equal(Struct("f", (X,)), Struct("f", (1,))), term_equal(Var("A"), Var("B"))
    (True, False)
    """
    stack = [(a, b)]
    seen = None  # pairs of compounds reached through a binding, already being compared
    while stack:
        x, y = stack.pop()
        via = False
        while type(x) is Var and x.ref is not None:
            x = x.ref
            via = True
        while type(y) is Var and y.ref is not None:
            y = y.ref
            via = True
        if x is y:
            continue
        tx = type(x)
        if tx is not type(y):
            return False
        if tx is Struct:
            if x.name != y.name or len(x.args) != len(y.args):
                return False
            if via:
                # a cycle always passes through a binding: comparing the same pair again
                # adds nothing (the pair is equal if everything else is)
                key = (id(x), id(y))
                if seen is None:
                    seen = set()
                elif key in seen:
                    continue
                seen.add(key)
            stack.extend(zip(x.args, y.args))
        elif tx is Var:
            return False
        elif tx is float:
            if not same_float(x, y):
                return False
        elif x != y:
            return False
    return True


def same_float(x: float, y: float) -> bool:
    """Whether two floats are one term, as SWI-Prolog has it: equal and of one sign (``-0.0``
    is not ``0.0``, though Python's ``==`` says they are equal and hashes them alike), or both
    NaN. Arithmetic comparison (``=:=``) stays numeric.

    >>> same_float(-0.0, 0.0), same_float(0.0, 0.0), same_float(float("nan"), float("nan"))
    (False, True, True)
    """
    if x == y:
        return bool(x) or math.copysign(1.0, x) == math.copysign(1.0, y)
    return x != x and y != y


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
    """Split a (possibly partial) list into its dereferenced items and its dereferenced tail.

    A cyclic list (``L = [a|L]``) stops at the cell where the cycle is found (Brent's
    method: constant extra work per cell): its "tail" is then a list cell, so callers that
    want a proper list see a type error instead of looping forever.

    >>> items, tail = list_items(make_list([1, 2], Var("T"))); items, tail
    ([1, 2], Var('T'))
    """
    items = []
    t = deref(t)
    mark = t
    power = steps = 1
    while type(t) is Struct and t.name == "." and len(t.args) == 2:
        items.append(t.args[0])
        t = deref(t.args[1])
        if t is mark:
            return items, t
        if steps == power:
            mark = t
            power *= 2
            steps = 0
        steps += 1
    return items, t


def is_ground(t: Any) -> bool:
    """True when the term has no unbound variable (finite on cyclic terms).

    >>> is_ground(Struct("f", (Atom("a"), 1))), is_ground(Struct("f", (Var("X"),)))
    (True, False)
    """
    stack = [t]
    seen = None  # compounds reached through a binding and already walked (cycles)
    budget = NODES_BETWEEN_CLOCK_CHECKS
    while stack:
        x = stack.pop()
        via = False
        while type(x) is Var:
            if x.ref is None:
                return False
            x = x.ref
            via = True
        if type(x) is Struct:
            budget -= 1
            # past a few thousand nodes every compound is remembered: a term that shares
            # subterms directly (one resolve() made) is walked once per distinct subterm
            if via or budget < 0:
                if seen is None:
                    seen = set()
                elif id(x) in seen:
                    continue
                seen.add(id(x))
            stack.extend(x.args)
    return True


def is_callable(t: Any) -> bool:
    """True for an atom or a compound term (after dereferencing), what ``call/1`` accepts.

    >>> is_callable(Atom("true")), is_callable(Struct("f", (1,))), is_callable(1), is_callable(Var("G"))
    (True, True, False, False)
    """
    t = deref(t)
    return type(t) is Struct or type(t) is Atom


def term_vars(t: Any, deadline: float | None = None) -> list[Var]:
    """Unbound variables of a term, depth-first left to right, each once (finite on cyclic
    terms; a walk of a huge term looks at ``deadline`` every few thousand compounds).

    >>> x, y = Var("X"), Var("Y")
    >>> [v.name for v in term_vars(Struct("f", (y, Struct("g", (x, y)), 1)))]
    ['Y', 'X']
    """
    seen: set[int] = set()
    out: list[Var] = []
    stack = [t]
    budget = NODES_BETWEEN_CLOCK_CHECKS
    while stack:
        x = stack.pop()
        via = False
        while type(x) is Var and x.ref is not None:
            x = x.ref
            via = True
        tx = type(x)
        if tx is Var:
            if id(x) not in seen:
                seen.add(id(x))
                out.append(x)
        elif tx is Struct:
            budget -= 1
            if via or budget < 0:   # (as in is_ground: shared subterms walked once)
                if id(x) in seen:
                    continue
                seen.add(id(x))
                if budget % NODES_BETWEEN_CLOCK_CHECKS == 0:
                    check_deadline(deadline)
            stack.extend(reversed(x.args))
    return out


def from_python(value: Any) -> Any:
    """Convert a Python value given by a caller into a term.

    ``str`` -> atom, :class:`String` -> string, ``int``/``float``, ``list``/``tuple`` -> list,
    :class:`Struct` (its args converted too). Terms already in engine form pass through.
    Iterative: a list nested 100,000 deep converts; a list that contains itself is a
    ``TypeError``, like any other value that is not a term.

    >>> str(from_python(["cup1", 1, 2.5]))
    '[cup1,1,2.5]'
    """
    leaf = _python_leaf(value)
    if leaf is not _NOT_LEAF:
        return leaf
    done: list = []        # converted values, in order
    todo: list = [value]   # values to convert; _Build markers to assemble containers
    on_path: set[int] = set()
    while todo:
        v = todo.pop()
        if type(v) is _Build:
            k = len(v.items)
            args = done[len(done) - k:]
            del done[len(done) - k:]
            on_path.discard(v.key)
            done.append(make_list(args) if v.name is None else Struct(v.name, tuple(args)))
            continue
        leaf = _python_leaf(v)
        if leaf is not _NOT_LEAF:
            done.append(leaf)
            continue
        items = v.args if type(v) is Struct else v
        if id(v) in on_path:
            raise TypeError("cannot convert a list that contains itself to an SLR term")
        on_path.add(id(v))
        todo.append(_Build(v.name if type(v) is Struct else None, items, id(v)))
        todo.extend(reversed(items))
    return done[0]


class _Build:
    """from_python's marker: assemble the last ``len(items)`` converted values."""

    __slots__ = ("name", "items", "key")

    def __init__(self, name: Any, items: Any, key: int):
        self.name = name
        self.items = items
        self.key = key


_NOT_LEAF = object()


def _python_leaf(value: Any) -> Any:
    """The term of a Python value that is not a container, else _NOT_LEAF."""
    tv = type(value)
    if tv is Atom or tv is String or tv is int or tv is float or tv is Var:
        return value
    if tv is str:
        return Atom(value)
    if tv is bool:
        return Atom("true" if value else "false")
    if tv is Struct or isinstance(value, (list, tuple)):
        return _NOT_LEAF
    if isinstance(value, String):
        return String(value)
    if isinstance(value, str):
        return Atom(value)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return float(value)
    raise TypeError(f"cannot convert {value!r} ({tv.__name__}) to an SLR term")


class _CyclicTerm(Exception):
    """Raised inside to_python/format_term when a term turns out to be cyclic."""


def to_python(t: Any, deadline: float | None = None,
              variables: Callable[[Var], Var] | None = None) -> Any:
    """Convert a term into the value handed to callers.

    Atoms stay :class:`Atom`, strings become ``str``, proper lists become ``list`` (the
    empty list ``[]`` too), compounds :class:`Struct` with converted args, unbound variables
    stay :class:`Var`, or become ``variables(var)`` where that is given (an answer names
    its variables so: :func:`slr_sql.answers.answer_bindings`). Iterative (a term nested
    100,000 deep converts). A cyclic term
    (``X = f(X)``) comes back as SWI-Prolog prints it: ``@(Template, [S_1 = Value, ...])``
    with the variables ``S_1``... standing for the repeated subterms (see
    :func:`factorize_cycles`). ``deadline`` (``time.monotonic()``) stops the conversion of
    a huge term (one with shared subterms is exponential as a tree) with SLRTimeout.

    >>> to_python(make_list([Atom("a"), String("s")])), to_python(NIL)
    ([Atom('a'), 's'], [])
    >>> to_python(Struct("f", (Var("Y"), 1)), variables=lambda v: Var("Z"))
    Struct('f', (Var('Z'), 1))
    """
    tt = type(t)
    if tt is Atom:
        return [] if t == "[]" else t
    if tt is int or tt is float:
        return t
    try:
        return _to_python(t, deadline, variables)
    except _CyclicTerm:
        factored = factorize_cycles(t, deadline)
        if variables is not None and factored is not t:
            variables = _labels_kept(factored, variables)
        return _to_python(factored, deadline, variables)


def _labels_kept(factored: Struct, variables: Callable[[Var], Var]) -> Callable[[Var], Var]:
    """``variables`` for the ``@(Template, [S_1 = Value, ...])`` of a cyclic term: the labels
    ``S_1``, ... stand for subterms, not for variables of the term, and keep their names."""
    labels = _cycle_labels(factored)
    return lambda v: v if id(v) in labels else variables(v)


def _cycle_labels(factored: Struct) -> set[int]:
    """``id()`` of the labels ``S_1``, ... of a cyclic term's ``@(Template, [S_1 = Value,
    ...])`` (:func:`factorize_cycles`)."""
    return {id(deref(pair.args[0])) for pair in list_items(factored.args[1])[0]}


def _to_python(t: Any, deadline: float | None,
               variables: Callable[[Var], Var] | None = None) -> Any:
    done: list = []
    # work items: a term to convert, or a tuple (k, name, gray ids) that assembles the last k
    # converted values into a list (name None), a partial list (name CONS) or a compound
    todo: list = [t]
    gray: set[int] = set()  # compounds reached through a binding, being converted
    clock = NODES_BETWEEN_CLOCK_CHECKS
    while todo:
        clock -= 1
        if not clock:
            clock = NODES_BETWEEN_CLOCK_CHECKS
            check_deadline(deadline)
        x = todo.pop()
        if type(x) is tuple:
            k, name, keys = x
            if k:
                vals = done[len(done) - k:]
                del done[len(done) - k:]
            else:
                vals = []
            if name is None:
                done.append(vals)
            elif name is CONS:  # a partial list: vals are the items then the tail
                out = vals[-1]
                for v in reversed(vals[:-1]):
                    out = Struct(CONS, (v, out))
                done.append(out)
            else:
                done.append(Struct(name, tuple(vals)))
            gray.difference_update(keys)
            continue
        via = False
        while type(x) is Var and x.ref is not None:
            x = x.ref
            via = True
        tx = type(x)
        if tx is not Struct:
            if tx is Var and variables is not None:
                done.append(variables(x))
                continue
            done.append(str(x) if tx is String else [] if tx is Atom and x == "[]" else x)
            continue
        keys: list[int] = []
        if via:
            if id(x) in gray:
                raise _CyclicTerm
            gray.add(id(x))
            keys.append(id(x))
        if x.name == "." and len(x.args) == 2:
            items = []
            cell = x
            while True:
                items.append(cell.args[0])
                nxt = cell.args[1]
                via = False
                while type(nxt) is Var and nxt.ref is not None:
                    nxt = nxt.ref
                    via = True
                if type(nxt) is not Struct or nxt.name != "." or len(nxt.args) != 2:
                    break
                if via:
                    if id(nxt) in gray:
                        raise _CyclicTerm
                    gray.add(id(nxt))
                    keys.append(id(nxt))
                cell = nxt
            if type(nxt) is Atom and nxt == "[]":
                todo.append((len(items), None, keys))
            else:
                todo.append((len(items) + 1, CONS, keys))
                todo.append(nxt)
            todo.extend(reversed(items))
        else:
            todo.append((len(x.args), x.name, keys))
            todo.extend(reversed(x.args))
    return done[0]


def factorize_cycles(t: Any, deadline: float | None = None) -> Any:
    """An acyclic term for a possibly cyclic one, as SWI-Prolog writes cyclic terms:
    ``@(Template, [S_1 = Value_1, ...])`` where each ``S_k`` stands for a subterm that
    contains itself. An acyclic term is returned as it is.

    >>> X = Var("X"); X.ref = Struct("f", (X,)); format_term(factorize_cycles(X))
    '@(S_1,[S_1=f(S_1)])'
    """
    targets = _cycle_targets(t, deadline)
    if not targets:
        return t
    labels: dict[int, Var] = {}
    order: list = []
    memo: dict[int, Any] = {}

    def copy(root: Any) -> Any:
        """``root`` with every cycle target replaced by its label (iterative)."""
        done: list = []
        todo: list = [root]
        clock = NODES_BETWEEN_CLOCK_CHECKS
        while todo:
            clock -= 1
            if not clock:
                clock = NODES_BETWEEN_CLOCK_CHECKS
                check_deadline(deadline)
            x = todo.pop()
            if type(x) is _Build:
                k = len(x.items)
                args = tuple(done[len(done) - k:])
                del done[len(done) - k:]
                out = Struct(x.name, args)
                memo[x.key] = out
                done.append(out)
                continue
            x = deref(x)
            if type(x) is not Struct:
                done.append(x)
                continue
            key = id(x)
            if key in targets:
                label = labels.get(key)
                if label is None:
                    label = labels[key] = Var(f"S_{len(labels) + 1}")
                    order.append(x)
                done.append(label)
            elif key in memo:
                done.append(memo[key])
            else:
                todo.append(_Build(x.name, x.args, key))
                todo.extend(reversed(x.args))
        return done[0]

    template = copy(t)
    definitions = []
    k = 0
    while k < len(order):  # copying a definition may find further targets
        target = order[k]
        k += 1
        value = Struct(target.name, tuple(copy(a) for a in target.args))
        definitions.append(Struct("=", (labels[id(target)], value)))
    return Struct("@", (template, make_list(definitions)))


def _cycle_targets(t: Any, deadline: float | None) -> dict[int, Any]:
    """The compounds that contain themselves: the ends of the back edges of a depth-first
    walk (every cycle has one)."""
    targets: dict[int, Any] = {}
    gray: set[int] = set()
    black: set[int] = set()
    todo: list = [(t, False)]
    clock = NODES_BETWEEN_CLOCK_CHECKS
    while todo:
        clock -= 1
        if not clock:
            clock = NODES_BETWEEN_CLOCK_CHECKS
            check_deadline(deadline)
        x, leaving = todo.pop()
        if leaving:
            gray.discard(id(x))
            black.add(id(x))
            continue
        x = deref(x)
        if type(x) is not Struct:
            continue
        key = id(x)
        if key in gray:
            targets.setdefault(key, x)
            continue
        if key in black:
            continue
        gray.add(key)
        todo.append((x, True))
        todo.extend((a, False) for a in reversed(x.args))
    return targets


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


# ---------------------------------------------------------------------------------------
# Prolog text of terms.
#
# Term -> text, the way SWI-Prolog's ``writeq/1`` prints it (modulo a few spaces).
#
# The output is the contract of the parser's round trip: for every term ``t``,
# ``parse_term(format_term(t))`` gives ``t`` back (up to variable identity).  That is why the
# printer is careful about the three places where Prolog text is ambiguous:
#
# * operators: minimal parentheses from the priority table below, and an operator *atom*
#   that is an operand of an operator is bracketed, ``(-)=a``;
# * the minus sign: ``-1`` is the integer, ``- 1`` is the compound ``-(1)`` (as SWI 9 reads it);
# * token gluing: two symbol-char tokens or two alphanumeric tokens that would run together
#   are separated by a space (``1- -1``, ``a= \\+b``, ``X is Y``).
#
# The operator table lives here (not in parser.py) so that printing never imports lark.
# ---------------------------------------------------------------------------------------

# (priority, type, names): SWI-Prolog 9 defaults plus SLR's `event` declaration operator and
# the event-rule operators of ETALIS (`<-`, `where`, `within`, `or`, `par`, `and`, `cnot`, `seq`, ...).
OPERATORS: tuple[tuple[int, str, tuple[str, ...]], ...] = (
    (1200, "xfx", (":-", "-->")),
    (1200, "fx", (":-", "?-")),
    # event rules (the event-processing library, as ETALIS declares them): Head <- Pattern
    (1200, "xfy", ("<-",)),
    (1150, "fx", ("dynamic", "discontiguous", "initialization", "module_transparent",
                  "multifile", "public", "table", "event")),
    (1105, "xfy", ("|",)),
    (1100, "xfy", (";",)),
    # event-rule operators (ETALIS priorities), each also in ETALIS's synonyms 'Seq', 'SEQ'
    # (capitalized: quoted in a file, as ETALIS's examples write them)
    (1060, "yfx", ("where", "Where", "WHERE")),
    (1055, "xfy", ("within",)),
    (1053, "yfx", ("or", "Or", "OR")),
    (1050, "xfy", ("->", "*->")),
    (1045, "yfx", ("par", "Par", "PAR")),
    (1040, "yfx", ("and", "And", "AND")),
    (1031, "yfx", ("cnot", "Cnot", "CNOT")),
    (1025, "yfx", ("seq", "Seq", "SEQ", "equals", "Equals", "EQUALS", "meets", "Meets", "MEETS",
                   "during", "During", "DURING", "starts", "Starts", "STARTS", "finishes",
                   "Finishes", "FINISHES")),
    (1000, "xfy", (",",)),
    (900, "fy", ("\\+",)),
    (800, "xfx", (":=",)),
    (700, "xfx", ("=", "\\=", "==", "\\==", "@<", "@>", "@=<", "@>=", "=..", "is", "=:=",
                  "=\\=", "<", ">", "=<", ">=", ">:<", ":<", "as", "=@=", "\\=@=")),
    (600, "xfy", (":",)),
    (500, "yfx", ("+", "-", "/\\", "\\/")),
    (400, "yfx", ("*", "/", "//", "mod", "rem", "<<", ">>", "div", "rdiv", "xor")),
    (200, "xfx", ("**",)),
    (200, "xfy", ("^",)),
    (200, "fy", ("-", "+", "\\")),
)

# name -> (priority, max left priority, max right priority)
INFIX_OPS: dict[str, tuple[int, int, int]] = {}
# name -> (priority, max argument priority)
PREFIX_OPS: dict[str, tuple[int, int]] = {}
for _p, _type, _names in OPERATORS:
    for _n in _names:
        if _type == "xfx":
            INFIX_OPS[_n] = (_p, _p - 1, _p - 1)
        elif _type == "xfy":
            INFIX_OPS[_n] = (_p, _p - 1, _p)
        elif _type == "yfx":
            INFIX_OPS[_n] = (_p, _p, _p - 1)
        elif _type == "fy":
            PREFIX_OPS[_n] = (_p, _p)
        else:  # fx
            PREFIX_OPS[_n] = (_p, _p - 1)

_SYMBOL_CHARS = frozenset("#$&*+-./:<=>?@^~\\")


def _char_class(ascii_part: str, chars: str) -> str:
    """A regex matching one character of ``ascii_part`` or of unichars' class ``chars``,
    its astral ranges behind a look-ahead: a class with astral ranges makes the regex engine
    try each of them on every character it refuses."""
    bmp, astral = [], []
    k = 0
    while k < len(chars):
        a = b = chars[k]
        if chars[k + 1:k + 2] == "-":
            b = chars[k + 2]
            k += 2
        k += 1
        if a <= "\uffff":
            bmp.append(a + "-" + min(b, "\uffff"))
        if b > "\uffff":
            astral.append(max(a, "\U00010000") + "-" + b)
    return f"(?:[{ascii_part}{''.join(bmp)}]|(?=[\U00010000-\U0010ffff])[{''.join(astral)}])"


# As SWI-Prolog's writeq (slr_sql/unichars.py): an atom is written unquoted when it is a name
# (that does not begin with a capital), a run of symbol characters, or a solo character. The
# regexes of unichars' classes take ~25 ms to compile: ASCII text, all most processes ever
# write, is matched by small ones, and the large ones are compiled by the first text they serve.
_ASCII_LETTER_ATOM = re.compile(r"[a-z][a-zA-Z0-9_]*\Z")
_ASCII_SYMBOL_ATOM = re.compile(r"[#$&*+\-./:<=>?@^~\\]+\Z")
_ASCII_NEEDS_ESCAPE = re.compile("[\\\\'\"\x00-\x1f\x7f]")


@functools.cache
def _unicode_pattern(name: str) -> re.Pattern[str]:
    """The regex ``name`` of the writer's Unicode classes, compiled once, when first needed."""
    if name == "letter atom":
        return re.compile(_char_class("a-z", ID_START) + _char_class("a-zA-Z0-9_", ID_CONTINUE)
                          + r"*\Z")
    if name == "symbol atom":
        return re.compile(_char_class(r"#$&*+\-./:<=>?@^~\\", SYMBOL) + r"+\Z")
    if name == "symbol char":
        return re.compile(_char_class("", SYMBOL))
    if name == "escaped":
        return re.compile(_char_class("\x00-\x1f\x7f", ESCAPED))
    assert name == "needs escape", name
    return re.compile("[\\\\'\"]|" + _unicode_pattern("escaped").pattern)


# (SWI writes these solo characters of Latin-1 unquoted and quotes the other SOLO ones)
_SOLO = frozenset(("[]", "{}", "!", ";", "\xad", "\xb2", "\xb3", "\xb9", "\xbc", "\xbd", "\xbe"))
# As SWI-Prolog's writeq: letter escapes where they exist, other control, format, separator,
# private-use and unassigned characters as `\xHH\`.
_ESCAPES = {"\\": "\\\\", "\n": "\\n", "\t": "\\t", "\r": "\\r", "\a": "\\a", "\b": "\\b",
            "\f": "\\f", "\v": "\\v"}
_ARG_PRIORITY = 999  # arguments and list elements, as writeq prints them


def format_atom(name: str, quoted: bool = True, escapes: bool = True) -> str:
    """The text of an atom, quoted only when it would not read back as the same atom.
    ``escapes=False``: inside the quotes only a quote (doubled) and a backslash (``\\``)
    are escaped, every other character is itself, a newline too (SWI-Prolog's
    term_to_atom/2; the reader takes a raw newline inside quotes, as SWI-Prolog's does).

    >>> format_atom("cup1"), format_atom("hello world"), format_atom("=.."), format_atom("A")
    ('cup1', "'hello world'", '=..', "'A'")
    >>> print(format_atom("it's"), format_atom("it's", escapes=False))
    'it\\'s' 'it''s'
    """
    if not quoted or name in _SOLO:
        return name
    ascii = name.isascii()
    if _ASCII_LETTER_ATOM.match(name) if ascii else _unicode_pattern("letter atom").match(name):
        if ascii or not name[0].isupper():     # (a non-ASCII capital begins a variable)
            return name
    elif (_ASCII_SYMBOL_ATOM.match(name) if ascii else _unicode_pattern("symbol atom").match(name)) \
            and not name.startswith("/*") and name != ".":
        return name
    return "'" + _escape(name, "'", escapes) + "'"


def quoted_text(text: str, quote: str = "'") -> str:
    r"""``text`` between ``quote`` characters as ``writeq`` writes a quoted atom (``'``) or
    string (``"``): the quote and the backslash escaped, and each character a terminal does
    not draw as itself (:func:`undrawn_character`) as its escape.

    >>> print(quoted_text("it's\x1b[2J"), quoted_text('say "hi"\n', '"'))
    'it\'s\x1B\[2J' "say \"hi\"\n"
    """
    return quote + _escape(text, quote) + quote


def undrawn_character() -> re.Pattern[str]:
    r"""The regex of one character ``writeq`` escapes because a terminal does not draw it as
    itself: C0 and C1 controls, DEL, format characters (bidi overrides, zero-width ones),
    line and paragraph separators, private-use and unassigned code points.

    >>> [bool(undrawn_character().match(c)) for c in "\x1b\r\x9b\u202e\u2028aé"]
    [True, True, True, True, True, False, False]
    """
    return _unicode_pattern("escaped")


def char_escape(ch: str) -> str:
    r"""``writeq``'s escape of one character it escapes: a letter escape where there is one
    (``\n``, ``\r``), else ``\xHH\``.

    >>> print(char_escape("\r"), char_escape("\x1b"), char_escape("\u202e"))
    \r \x1B\ \x202E\
    """
    return _ESCAPES.get(ch) or f"\\x{ord(ch):X}\\"


def _escape(text: str, quote: str, escapes: bool = True) -> str:
    if not escapes:
        return text.replace("\\", "\\\\").replace(quote, quote + quote)
    ascii = text.isascii()
    if not (_ASCII_NEEDS_ESCAPE if ascii else _unicode_pattern("needs escape")).search(text):
        return text
    out = []
    for ch in text:
        if ch == quote:
            out.append("\\" + quote)
        elif ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ch < " " or ch == "\x7f" or (not ascii and _unicode_pattern("escaped").match(ch)):
            out.append(char_escape(ch))
        else:
            out.append(ch)
    return "".join(out)


def _format_float_in_message(x: float) -> str:
    """A float as a message writes it: NaN and the infinities as the message writes its
    times (``nan``, ``inf``, ``-inf``), since SWI's ``1.5NaN`` reads as a number with a typo."""
    if math.isnan(x) or math.isinf(x):
        return repr(x)
    return _format_float(x)


def _format_float(x: float) -> str:
    """Shortest round-tripping digits, laid out as SWI does (``1.0e+15``, ``0.0001``)."""
    if math.isnan(x):
        return "1.5NaN"
    if math.isinf(x):
        return "1.0Inf" if x > 0 else "-1.0Inf"
    r = repr(x)
    sign = ""
    if r[0] == "-":
        sign, r = "-", r[1:]
    mantissa, _, exp = r.partition("e")
    whole, _, frac = mantissa.partition(".")
    digits = (whole + frac).lstrip("0")
    if not digits:
        return sign + "0.0"
    # decimal exponent of the first significant digit
    e = (int(exp) if exp else 0) + len(whole) - 1 - (len(whole + frac) - len((whole + frac).lstrip("0")))
    digits = digits.rstrip("0") or "0"
    if -4 <= e < 15:
        if e >= 0:
            ip = digits[: e + 1].ljust(e + 1, "0")
            fp = digits[e + 1:] or "0"
        else:
            ip, fp = "0", "0" * (-e - 1) + digits
        return f"{sign}{ip}.{fp}"
    return f"{sign}{digits[0]}.{digits[1:] or '0'}e{'+' if e >= 0 else '-'}{abs(e)}"


def _is_op_atom(t: Any) -> bool:
    return type(t) is Atom and (t in INFIX_OPS or t in PREFIX_OPS)


class _Op:
    """The tag of a _Writer work item that is an action, not a term to write."""

    __slots__ = ("name",)

    def __init__(self, name: str):
        self.name = name


# Work items of _Writer.write, besides (term, priority, operand) triples.
_PUT, _SPACE, _PREFIX_END, _LIST_REST, _UNGRAY, _INFIX = (
    _Op("put"), _Op("space"), _Op("prefix end"), _Op("list rest"), _Op("ungray"),
    _Op("infix operator"))


_VARIABLE_NAME = re.compile(r"[A-Z_][A-Za-z0-9_]*\Z")


def _numbervar_name(arg: Any) -> str | None:
    """The name ``'$VAR'(arg)`` is written as under ``numbervars`` (None: written as a
    compound): an integer within 64 bits N >= 0 is a letter and N // 26 after it (``A``,
    ``Z``, ``A1``), a negative one ``S_`` and -N; an atom spelled as a variable is itself.

    >>> _numbervar_name(0), _numbervar_name(27), _numbervar_name(-3), _numbervar_name(Atom("Foo"))
    ('A', 'B1', 'S_3', 'Foo')
    >>> _numbervar_name(Atom("foo")) is None, _numbervar_name(2 ** 63) is None
    (True, True)
    """
    while type(arg) is Var and arg.ref is not None:
        arg = arg.ref
    if type(arg) is int:
        if not -(1 << 63) <= arg < (1 << 63):
            return None
        if arg < 0:
            return f"S_{-arg}"
        return chr(65 + arg % 26) + (str(arg // 26) if arg >= 26 else "")
    if type(arg) is Atom and _VARIABLE_NAME.match(arg):
        return str(arg)
    return None


class _Writer:
    """Accumulates tokens, inserting a space where two tokens would otherwise glue.

    Terms are written from an explicit stack of work items (no recursion: a term nested
    100,000 deep prints). A compound reached through a variable binding is "gray" while
    it is being written: meeting it again inside itself means the term is cyclic.
    """

    __slots__ = ("out", "last", "quoted", "deadline", "limit", "float_text", "numbervars",
                 "escapes", "var_names", "ignore_ops")

    def __init__(self, quoted: bool, deadline: float | None = None, limit: int | None = None,
                 message: bool = False, numbervars: bool = False, escapes: bool = True,
                 var_names: Callable[["Var"], str] | None = None, ignore_ops: bool = False):
        self.out: list[str] = []
        self.last = ""  # last character written
        self.quoted = quoted
        self.deadline = deadline
        self.limit = limit  # pieces of text after which the writer stops (with "...")
        self.float_text = _format_float_in_message if message else _format_float
        self.numbervars = numbervars
        self.escapes = escapes
        self.var_names = var_names
        self.ignore_ops = ignore_ops

    def put(self, s: str) -> None:
        if not s:
            return
        a, b = self.last, s[0]
        if a and ((a in _SYMBOL_CHARS or (a > "\x7f" and _unicode_pattern("symbol char").match(a)))
                  and (b in _SYMBOL_CHARS
                       or (b > "\x7f" and _unicode_pattern("symbol char").match(b)))
                  or ((a.isalnum() or a == "_") and (b.isalnum() or b == "_"))
                  or (a == "," and b == "|")):
            self.out.append(" ")
        self.out.append(s)
        self.last = s[-1]

    def space(self) -> None:
        self.out.append(" ")
        self.last = " "

    def write(self, t: Any, prec: int) -> None:
        """Write t at priority ≤ prec; raises _CyclicTerm on a cyclic term."""
        todo: list = [(t, prec, False)]
        gray: set[int] = set()
        put = self.put
        clock = NODES_BETWEEN_CLOCK_CHECKS
        while todo:
            clock -= 1
            if not clock:
                clock = NODES_BETWEEN_CLOCK_CHECKS
                check_deadline(self.deadline)
                if self.limit is not None and len(self.out) > self.limit:
                    self.out.append(" ...")
                    return
            item = todo.pop()
            kind = item[0]
            if type(kind) is _Op:
                if kind is _PUT:
                    put(item[1])
                elif kind is _SPACE:
                    self.space()
                elif kind is _INFIX:
                    # a symbolic operator parted from its left operand by a space (it would
                    # glue to it: `# - 1`, `... - 0`) is parted from its right one too, as
                    # SWI-Prolog writes it; `1-2`, `a- -1` stay as they are
                    before = len(self.out)
                    put(item[1])
                    if len(self.out) - before == 2:
                        self.space()
                elif kind is _LIST_REST:
                    self._list_rest(item[1], todo, gray)
                elif kind is _UNGRAY:
                    gray.discard(item[1])
                else:  # _PREFIX_END
                    self._prefix_end(item[1], item[2])
                continue
            t, prec, operand = item
            via = False
            while type(t) is Var and t.ref is not None:
                t = t.ref
                via = True
            if type(t) is Struct:
                if self.numbervars and t.name == "$VAR" and len(t.args) == 1:
                    name = _numbervar_name(t.args[0])
                    if name is not None:
                        put(name)
                        continue
                if via:
                    if id(t) in gray:
                        raise _CyclicTerm
                    gray.add(id(t))
                    todo.append((_UNGRAY, id(t)))
                self._struct(t, prec, todo)
            elif type(t) is list or type(t) is tuple:
                # a list as to_python returns it (inside a returned Struct)
                put("[")
                todo.append((_PUT, "]"))
                for k in range(len(t) - 1, -1, -1):
                    todo.append((t[k], _ARG_PRIORITY, False))
                    if k:
                        todo.append((_PUT, ","))
            else:
                self._atomic(t, operand)

    def _atomic(self, t: Any, operand: bool) -> None:
        tt = type(t)
        if tt is Atom:
            if operand and _is_op_atom(t):
                # An operator atom as the operand of an operator: `(-)=a`, `- (-)`.
                self.put("(")
                self.put(format_atom(t, self.quoted, self.escapes))
                self.put(")")
            else:
                self.put(format_atom(t, self.quoted, self.escapes))
        elif tt is Var:
            self.put(t.name if self.var_names is None else self.var_names(t))
        elif tt is String or isinstance(t, str):
            if self.quoted:
                self.put('"' + _escape(t, '"', self.escapes) + '"')
            else:
                self.put(str(t))
        elif tt is int:
            self.put(int_text(t))
        elif tt is float:
            self.put(self.float_text(t))
        elif tt is bool:
            self.put("true" if t else "false")
        else:   # lists are written by the caller's loop, never here
            self.put(str(t))

    def _struct(self, t: Struct, prec: int, todo: list) -> None:
        """Write the start of a compound now; push the rest (in reverse order) on todo."""
        name, args = t.name, t.args
        n = len(args)
        put = self.put
        if n == 2 and name == ".":
            put("[")
            todo.append((_PUT, "]"))
            todo.append((_LIST_REST, args[1]))
            todo.append((args[0], _ARG_PRIORITY, False))
            return
        if self.ignore_ops:
            pass   # every other compound in its canonical form, name(arg, ...)
        elif n == 1 and name == "{}":
            put("{")
            todo.append((_PUT, "}"))
            todo.append((args[0], 1200, False))
            return
        elif n == 2 and name in INFIX_OPS:
            p, lp, rp = INFIX_OPS[name]
            if p > prec:
                put("(")
                todo.append((_PUT, ")"))
            todo.append((args[1], rp, True))
            if name == "," or name == "|":
                todo.append((_PUT, name))
            elif name[0].isalpha():
                todo.append((_SPACE,))
                todo.append((_PUT, format_atom(name, self.quoted, self.escapes)))
                todo.append((_SPACE,))
            else:
                todo.append((_INFIX, format_atom(name, self.quoted, self.escapes)))
            todo.append((args[0], lp, True))
            return
        elif n == 1 and name in PREFIX_OPS and name not in ("|", ","):
            p, ap = PREFIX_OPS[name]
            open_ = p > prec
            if open_:
                put("(")
                todo.append((_PUT, ")"))
            put(format_atom(name, self.quoted, self.escapes))
            todo.append((_PREFIX_END, len(self.out), name))
            todo.append((args[0], ap, True))
            return
        # canonical form: name(arg, ...)
        put(format_atom(name, self.quoted, self.escapes))
        self.out.append("(")
        self.last = "("
        todo.append((_PUT, ")"))
        for k in range(n - 1, -1, -1):
            todo.append((args[k], _ARG_PRIORITY, False))
            if k:
                todo.append((_PUT, ","))

    def _prefix_end(self, mark: int, name: str) -> None:
        """After a prefix operator's argument (written from ``mark`` on): separate it where
        `- (a,b)` is -((a,b)) but `-(a,b)` is -(a,b), `- 1` is -(1) but `-1` is -1, and
        `- {a}` is -({a}) but `-{a}` a dict to SWI-Prolog (a syntax error)."""
        first = self.out[mark][0] if mark < len(self.out) else ""
        if first != " " and (
                first == "(" or first == "{" or (name == "-" and first.isdigit())
                or name[0].isalpha()):
            self.out.insert(mark, " ")

    def _list_rest(self, t: Any, todo: list, gray: set) -> None:
        """The tail of a list after an element: one more element, `|Tail`, or nothing."""
        via = False
        while type(t) is Var and t.ref is not None:
            t = t.ref
            via = True
        if type(t) is Struct and t.name == "." and len(t.args) == 2:
            if via:
                if id(t) in gray:
                    raise _CyclicTerm
                gray.add(id(t))
                todo.append((_UNGRAY, id(t)))
            self.put(",")
            todo.append((_LIST_REST, t.args[1]))
            todo.append((t.args[0], _ARG_PRIORITY, False))
        elif not (type(t) is Atom and t == "[]"):
            self.put("|")
            todo.append((t, _ARG_PRIORITY, False))


def format_term(t: Any, quoted: bool = True, priority: int = 1200,
                deadline: float | None = None, limit: int | None = None,
                message: bool = False, numbervars: bool = False,
                char_escapes: bool = True, var_names: Callable[[Var], str] | None = None,
                cycle_names: bool = True, ignore_ops: bool = False) -> str:
    """Prolog text of a term, like SWI-Prolog's ``writeq`` (``quoted=False``: like ``write``).

    A cyclic term is written as SWI-Prolog writes it, ``@(Template, [S_1=Value, ...])``
    (see :func:`factorize_cycles`). ``deadline`` (``time.monotonic()``) stops writing a
    huge term with SLRTimeout; ``limit`` (for messages) cuts the text after about that
    many tokens with ``...``; ``message`` writes NaN and the infinities as ``nan``,
    ``inf``, ``-inf`` (as a message writes an event's times), not as SWI's ``1.5NaN``;
    ``numbervars`` writes ``'$VAR'(N)`` as a variable name (``A``..``Z``, ``A1``.., and
    ``S_N`` for a negative N) and ``'$VAR'('Name')`` as ``Name``, as SWI-Prolog's
    ``write``, ``print`` and ``writeq`` do (its option ``numbervars(true)``);
    ``char_escapes=False`` escapes only quotes (doubled) and backslashes inside quoted
    atoms and strings, as SWI-Prolog's ``term_to_atom/2`` writes (:func:`format_atom`);
    ``var_names`` gives the text of an unbound variable (default: its name;
    :func:`prolog_var_name` as Prolog's write/1 writes one), but for the ``S_k`` of a cyclic
    term's factorization unless ``cycle_names`` is false (SWI-Prolog's write/1 and format/2
    write ``S_1``, its term_to_atom/2 a variable's ``_123``); ``ignore_ops`` writes every
    compound but a list in its canonical form, ``name(arg, ...)`` (write_canonical/1).

    >>> from slr_sql.terms import make_list
    >>> format_term(Struct(":-", (Atom("a"), Struct(",", (Atom("b"), Atom("c"))))))
    'a:-b,c'
    >>> format_term(Struct("*", (Struct("+", (1, 2)), 3))), format_term(Struct("-", (1,)))
    ('(1+2)*3', '- 1')
    >>> print(format_term(make_list([Atom("hello world"), String("s"), 1.0], Var("T"))))
    ['hello world',"s",1.0|T]
    >>> format_term(Struct("-", (Struct("$VAR", (27,)),)), numbervars=True)
    '-B1'
    """
    w = _Writer(quoted, deadline, limit, message, numbervars, char_escapes, var_names, ignore_ops)
    try:
        w.write(t, priority)
    except _CyclicTerm:
        factorized = factorize_cycles(t, deadline)
        if var_names is not None and cycle_names:
            labels = _cycle_labels(factorized)
            var_names = (lambda names: lambda v: v.name if id(v) in labels else names(v))(var_names)
        w = _Writer(quoted, deadline, limit, message, numbervars, char_escapes, var_names,
                    ignore_ops)
        w.write(factorized, priority)
    return "".join(w.out)


def prolog_var_name(v: Var) -> str:
    """The text Prolog's write/1, format/2 and term_to_atom/2 give an unbound variable, as
    SWI-Prolog's: ``_`` and a number of its own (``_123``), not the name in the source,
    which a program cannot see (``X = f(Y), term_to_atom(X, A)`` gives ``'f(_123)'``).

    >>> v = Var("X"); prolog_var_name(v) == f"_{v.age}"
    True
    """
    return f"_{v.age}"


# The control constructs whose arguments a called body runs as goals
BODY_CONTROL = frozenset(((",", 2), (";", 2), ("->", 2), ("*->", 2), ("\\+", 1)))


def body_problem(goal: Any, unknown: type | None = None) -> str | None:
    """What keeps ``goal``, a body to call, from running as it is: ``"uncallable"`` when a
    goal inside its control constructs is no callable term (a number, ``[]``: Prolog's
    type_error(callable, Body) before anything runs), ``"unknown"`` when one is of the type
    ``unknown`` (a compiler's value known only at run time), else None; the first met.

    >>> body_problem(Struct(",", (Atom("fail"), 1))), body_problem(Struct(",", (Atom("a"), Var())))
    ('uncallable', None)
    """
    return CheckedBodies(unknown).problem(goal)


class CheckedBodies:
    r""":func:`body_problem` for the bodies one query (or one compilation) calls, walking a
    body inside one already walked only when it must: a large body found without a problem
    and with no variable as a goal in its control constructs cannot gain one (nothing bound
    or undone later changes it), so the bodies inside it -- the goal of each nested ``\+``,
    ``call/1``, ``findall/3`` -- are remembered as checked. ``\+ \+ ... \+ true``
    nested N deep was walked once per level, N²/2 steps; it is walked once. A body with a
    variable as a goal is walked each time (what the variable is bound to may have
    changed). Only the last such body is remembered: the memory is that of one body.

    >>> bodies = CheckedBodies()
    >>> deep = Atom("true")
    >>> for _ in range(20):
    ...     deep = Struct("\\+", (deep,))
    >>> bodies.problem(deep), bodies.problem(deep.args[0].args[0])   # the second not walked
    (None, None)
    >>> bodies.problem(Struct(",", (Atom("fail"), 1)))
    'uncallable'
    """

    # the fewest control constructs of a body remembered: a smaller one is walked again
    # (about as fast as looking it up)
    REMEMBERED = 16

    __slots__ = ("unknown", "_root", "_parts")

    def __init__(self, unknown: type | None = None):
        self.unknown = unknown           # body_problem's: a value known only at run time
        self._root: Any = None           # keeps the remembered ids from being reused
        self._parts: frozenset[int] = frozenset()

    def problem(self, goal: Any) -> str | None:
        """What :func:`body_problem` says of ``goal`` (``unknown`` as given)."""
        t = deref(goal)
        if type(t) is not Struct or (t.name, len(t.args)) not in BODY_CONTROL:
            return None
        if id(t) in self._parts:
            return None
        unknown = self.unknown
        parts = [t]
        closed = True
        stack = list(t.args)
        while stack:
            x = stack.pop()
            tx = type(x)
            if tx is Var:
                closed = False   # (bound now, it may be unbound and bound again)
                x = deref(x)
                tx = type(x)
            if tx is Struct:
                if (x.name, len(x.args)) in BODY_CONTROL:
                    parts.append(x)
                    stack.extend(x.args)
            elif unknown is not None and tx is unknown:
                return "unknown"
            elif tx is not Var and (tx is not Atom or x == "[]"):
                return "uncallable"
        if closed and len(parts) >= self.REMEMBERED:
            self._root = t
            self._parts = frozenset(map(id, parts))
        return None
