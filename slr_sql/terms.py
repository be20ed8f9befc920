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
import re
from dataclasses import dataclass
from typing import Any, Iterable

__all__ = [
    "Atom", "String", "Struct", "Var", "NIL", "TRUE", "CONS",
    "deref", "make_list", "list_items", "is_ground", "is_callable", "from_python",
    "to_python", "term_vars", "Span", "Clause", "indicator",
    "format_term", "format_atom", "INFIX_OPS", "PREFIX_OPS", "OPERATORS",
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

    Atoms stay :class:`Atom`, strings become ``str``, proper lists become ``list`` (the
    empty list ``[]`` too), compounds :class:`Struct` with converted args, unbound variables
    stay :class:`Var`.

    >>> to_python(make_list([Atom("a"), String("s")])), to_python(NIL)
    ([Atom('a'), 's'], [])
    """
    t = deref(t)
    tt = type(t)
    if tt is Atom:
        return [] if t == "[]" else t
    if tt is int or tt is float:
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
    (1060, "yfx", ("where",)),        # event-rule operators (ETALIS priorities)
    (1055, "xfy", ("within",)),
    (1053, "yfx", ("or",)),
    (1050, "xfy", ("->", "*->")),
    (1045, "yfx", ("par",)),
    (1040, "yfx", ("and",)),
    (1031, "yfx", ("cnot",)),
    (1025, "yfx", ("seq", "equals", "meets", "during", "starts", "finishes")),
    (1000, "xfy", (",",)),
    (990, "xfx", (":=",)),
    (900, "fy", ("\\+",)),
    (700, "xfx", ("=", "\\=", "==", "\\==", "@<", "@>", "@=<", "@>=", "=..", "is", "=:=",
                  "=\\=", "<", ">", "=<", ">=", ">:<", ":<", "as")),
    (600, "xfy", (":",)),
    (500, "yfx", ("+", "-", "/\\", "\\/", "xor")),
    (400, "yfx", ("*", "/", "//", "mod", "rem", "<<", ">>", "div", "rdiv")),
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
_LETTER_ATOM = re.compile(r"[^\W\d_A-Z]\w*\Z")
_SYMBOL_ATOM = re.compile(r"[#$&*+\-./:<=>?@^~\\]+\Z")
_SOLO = frozenset(("[]", "{}", "!", ";"))
# As SWI-Prolog's writeq: letter escapes where they exist, other control characters
# (C0, DEL, C1) as `\xHH\`.
_ESCAPES = {"\\": "\\\\", "\n": "\\n", "\t": "\\t", "\r": "\\r", "\a": "\\a", "\b": "\\b",
            "\f": "\\f", "\v": "\\v"}
_NEEDS_ESCAPE = re.compile(r"[\\'\"\x00-\x1f\x7f-\x9f]")
_ARG_PRIORITY = 999  # arguments and list elements, as writeq prints them


def format_atom(name: str, quoted: bool = True) -> str:
    """The text of an atom, quoted only when it would not read back as the same atom.

    >>> format_atom("cup1"), format_atom("hello world"), format_atom("=.."), format_atom("A")
    ('cup1', "'hello world'", '=..', "'A'")
    """
    if not quoted or name in _SOLO:
        return name
    if _LETTER_ATOM.match(name):
        # A non-ASCII capital would read as a variable in SWI; quote it to be portable.
        if name[0] < "\x80" or name[0].islower():
            return name
    elif _SYMBOL_ATOM.match(name) and not name.startswith("/*") and name != ".":
        return name
    return "'" + _escape(name, "'") + "'"


def _escape(text: str, quote: str) -> str:
    if not _NEEDS_ESCAPE.search(text):
        return text
    out = []
    for ch in text:
        if ch == quote:
            out.append("\\" + quote)
        elif ch in _ESCAPES:
            out.append(_ESCAPES[ch])
        elif ch < " " or "\x7f" <= ch <= "\x9f":
            out.append(f"\\x{ord(ch):X}\\")
        else:
            out.append(ch)
    return "".join(out)


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


class _Writer:
    """Accumulates tokens, inserting a space where two tokens would otherwise glue."""

    __slots__ = ("out", "last", "quoted")

    def __init__(self, quoted: bool):
        self.out: list[str] = []
        self.last = ""  # last character written
        self.quoted = quoted

    def put(self, s: str) -> None:
        if not s:
            return
        a, b = self.last, s[0]
        if a and ((a in _SYMBOL_CHARS and b in _SYMBOL_CHARS)
                  or ((a.isalnum() or a == "_") and (b.isalnum() or b == "_"))
                  or (a == "," and b == "|")):
            self.out.append(" ")
        self.out.append(s)
        self.last = s[-1]

    def space(self) -> None:
        self.out.append(" ")
        self.last = " "

    # -- terms ---------------------------------------------------------------------
    def term(self, t: Any, prec: int, operand: bool = False) -> None:
        """Write t at priority ≤ prec; ``operand``: t is the operand of an operator."""
        while type(t) is Var and t.ref is not None:
            t = t.ref
        tt = type(t)
        if tt is Atom:
            if operand and _is_op_atom(t):
                # An operator atom as the operand of an operator: `(-)=a`, `- (-)`.
                self.put("(")
                self.put(format_atom(t, self.quoted))
                self.put(")")
            else:
                self.put(format_atom(t, self.quoted))
        elif tt is Struct:
            self.struct(t, prec)
        elif tt is Var:
            self.put(t.name)
        elif tt is String or isinstance(t, str):
            if self.quoted:
                self.put('"' + _escape(t, '"') + '"')
            else:
                self.put(str(t))
        elif tt is int:
            self.put(str(t))
        elif tt is float:
            self.put(_format_float(t))
        elif tt is bool:
            self.put("true" if t else "false")
        elif tt is list:
            # a list inside a value returned to Python (to_python): Prolog's list text
            self.term(make_list(t), prec, operand)
        else:
            self.put(str(t))

    def struct(self, t: Struct, prec: int) -> None:
        name, args = t.name, t.args
        n = len(args)
        if n == 2 and name == ".":
            self.list(t)
            return
        if n == 1 and name == "{}":
            self.put("{")
            self.term(args[0], 1200)
            self.put("}")
            return
        if n == 2 and name in INFIX_OPS:
            p, lp, rp = INFIX_OPS[name]
            open_ = p > prec
            if open_:
                self.put("(")
            self.term(args[0], lp, True)
            if name == "," or name == "|":
                self.put(name)
            elif name[0].isalpha():
                self.space()
                self.put(format_atom(name, self.quoted))
                self.space()
            else:
                self.put(format_atom(name, self.quoted))
            self.term(args[1], rp, True)
            if open_:
                self.put(")")
            return
        if n == 1 and name in PREFIX_OPS and name not in ("|", ","):
            p, ap = PREFIX_OPS[name]
            open_ = p > prec
            if open_:
                self.put("(")
            self.put(format_atom(name, self.quoted))
            arg = args[0]
            while type(arg) is Var and arg.ref is not None:
                arg = arg.ref
            mark = len(self.out)
            self.term(arg, ap, True)
            first = self.out[mark][0] if mark < len(self.out) else ""
            # `- (a,b)` is -((a,b)) but `-(a,b)` is -(a,b); `- 1` is -(1) but `-1` is -1.
            if first != " " and (
                    first == "(" or (name == "-" and first.isdigit()) or name[0].isalpha()):
                self.out.insert(mark, " ")
            if open_:
                self.put(")")
            return
        # canonical form: name(arg, ...)
        self.put(format_atom(name, self.quoted))
        self.out.append("(")
        self.last = "("
        for i, a in enumerate(args):
            if i:
                self.put(",")
            self.term(a, _ARG_PRIORITY)
        self.put(")")

    def list(self, t: Any) -> None:
        # Iterative over the tail: a million-element list must not recurse.
        self.put("[")
        self.term(t.args[0], _ARG_PRIORITY)
        t = t.args[1]
        while True:
            while type(t) is Var and t.ref is not None:
                t = t.ref
            if type(t) is Struct and t.name == "." and len(t.args) == 2:
                self.put(",")
                self.term(t.args[0], _ARG_PRIORITY)
                t = t.args[1]
            elif type(t) is Atom and t == "[]":
                break
            else:
                self.put("|")
                self.term(t, _ARG_PRIORITY)
                break
        self.put("]")


def format_term(t: Any, quoted: bool = True, priority: int = 1200) -> str:
    """Prolog text of a term, like SWI-Prolog's ``writeq`` (``quoted=False``: like ``write``).

    >>> from slr_sql.terms import make_list
    >>> format_term(Struct(":-", (Atom("a"), Struct(",", (Atom("b"), Atom("c"))))))
    'a:-b,c'
    >>> format_term(Struct("*", (Struct("+", (1, 2)), 3))), format_term(Struct("-", (1,)))
    ('(1+2)*3', '- 1')
    >>> format_term(make_list([Atom("hello world"), String("s"), 1.0], Var("T")))
    "['hello world',\\"s\\",1.0|T]"
    """
    w = _Writer(quoted)
    w.term(t, priority)
    return "".join(w.out)
