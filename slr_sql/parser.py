"""SLR text -> terms.  The only module that uses the LALR parser of ``grammar/slr.lark``.

Two stages, both run inside one LALR parse:

1. ``grammar/slr.lark`` recognises tokens and bracket structure and hands each bracketed
   region to this module as a flat *sequence* of operands and names.
2. :class:`_Resolver` turns a sequence into a term with Prolog's operator-precedence rules
   and the operator table of :mod:`slr_sql.terms` (SWI-Prolog 9 defaults).  It decides
   whether a name is a prefix operator, an infix operator or an atom, and whether ``-``
   before a number makes a negative literal (only when written directly against it:
   ``-1`` is an integer, ``- 1`` the compound ``-(1)``, as SWI-Prolog 9 reads them).

The parser (the module lark's standalone tool generates from the grammar,
``grammar/slr_parser.py``) is built once per process (``_parser()``) with the transformer inlined,
so terms are built while parsing and no parse tree is materialised.  Per-parse state (the
variable table of the current clause, the source text) is thread-local, so several threads
may parse at once.
"""
from __future__ import annotations

import gc
import math
import re
import threading
import unicodedata
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .grammar.slr_parser import Lark

from .errors import SLRError, SLRSyntaxError
from .lockorder import ordered_lock
from .terms import INFIX_OPS, PREFIX_OPS
from .terms import CONS, NIL, TRUE, Atom, Clause, Span, String, Struct, Var, make_list
from .terms import MAX_INTEGER_BITS, int_from_text

__all__ = ["parse_program", "parse_term", "parse_first_term", "parse_event_fast", "token_spans",
           "full_stop_end", "parse_indicator"]

_GRAMMAR_PATH = Path(__file__).with_name("grammar") / "slr.lark"

# Item kinds of an operand/operator sequence.
_TERM, _NAME, _NUM, _FUNC = 0, 1, 2, 3
# Duration units (SLR): value in seconds.
_UNITS = {"ms": 0.001, "s": 1, "min": 60, "h": 3600}
_ESC = {"n": "\n", "t": "\t", "r": "\r", "a": "\a", "b": "\b", "f": "\f", "v": "\v",
        "e": "\x1b", "s": " ", "0": "\0", "\\": "\\", "'": "'", '"': '"', "`": "`"}
_GOAL_OPS = frozenset((":-", "?-", ",", ";", "|", "->", "*->", "\\+"))
# Control constructs whose arguments are goals (where `|` means `;`).
_CONTROL = frozenset((",", ";", "|", "->", "*->", "\\+"))

_state = threading.local()


class _NotLoaded(Exception):
    """Stands for lark's classes below until :func:`_parser` imports the parser's module:
    nothing is one, nothing raises it."""


# Bound to the parser module's classes by _load_parser (before the first parse). The module
# is imported then, not with this one: ~12 ms (its tables) that the processes which parse
# nothing -- most `slr` commands on a store without rules -- no longer pay.
Token: Any = _NotLoaded
UnexpectedInput: Any = _NotLoaded
UnexpectedCharacters: Any = _NotLoaded
UnexpectedToken: Any = _NotLoaded


class _Fail(Exception):
    """A syntax error found while building terms; converted to SLRSyntaxError at the top."""

    def __init__(self, message: str, pos: int):
        super().__init__(message)
        self.message = message
        self.pos = pos


# ---------------------------------------------------------------------------- tokens
def _quoted_text(tok: str, pos: int) -> str:
    """The text of a quoted atom or string token; ``pos`` is the token's offset in the source.

    Plain runs are copied in one slice each (a 10 MB atom is not walked character by
    character); doubled quotes and escapes are decoded, and an error points at its escape.
    """
    q = tok[0]
    body = tok[1:-1]
    if "\\" not in body:
        return body.replace(q + q, q) if q in body else body
    out = []
    qq = q + q
    i, n = 0, len(body)
    while i < n:
        j = body.find("\\", i)
        if j < 0:
            j = n
        if j > i:
            chunk = body[i:j]
            out.append(chunk.replace(qq, q) if q in chunk else chunk)
        if j == n:
            break
        ch, i = _escape_at(body, j, pos + 1)
        out.append(ch)
    return "".join(out)


_HEX_DIGITS = frozenset("0123456789abcdefABCDEF")
_OCT_DIGITS = frozenset("01234567")


def _escape_at(body: str, j: int, base: int) -> tuple[str, int]:
    """Decode the escape sequence starting with the backslash at ``body[j]``: (text, end).

    ``base`` is the source offset of ``body[0]``, for the error position. As SWI-Prolog,
    ``\\xHH..\\`` and ``\\OOO..\\`` must name a Unicode character: at most 0x10FFFF and not a
    surrogate (D800-DFFF, which no UTF-8 text can hold).
    """
    n = len(body)
    c = body[j + 1]  # the lexer only ends a token after a complete escape
    if c == "\n":  # `\` newline: line continuation, and SWI skips the layout that follows
        k = j + 2     # on that line too (deprecated there, for \c, but still read so)
        while k < n and body[k] in _LAYOUT_CHARS and body[k] != "\n":
            k += 1
        return "", k
    if c == "x" or c in _OCT_DIGITS:
        digits = _HEX_DIGITS if c == "x" else _OCT_DIGITS
        start = j + 2 if c == "x" else j + 1
        k = start
        while k < n and body[k] in digits:
            k += 1
        if k == start:
            raise _Fail("\\x escape without hexadecimal digits", base + j)
        end = k + 1 if k < n and body[k] == "\\" else k
        text = body[start:k].lstrip("0") or "0"
        code = int(text, 16 if c == "x" else 8) if len(text) <= 8 else -1
        return _code_char(code, body[j:end], base + j), end
    if c == "u" or c == "U":      # \uXXXX, \UXXXXXXXX: exactly 4 or 8 hexadecimal digits
        end = j + (6 if c == "u" else 10)
        digits = body[j + 2:end]
        if len(digits) != end - j - 2 or not _HEX_DIGITS.issuperset(digits):
            raise _Fail(f"illegal \\{c} escape (\\{c} takes {end - j - 2} hexadecimal digits)",
                        base + j)
        return _code_char(int(digits, 16), body[j:end], base + j), end
    if c == "c":                  # \c: skip the layout that follows
        k = j + 2
        while k < n and body[k] in _LAYOUT_CHARS:
            k += 1
        return "", k
    if c in _ESC:
        return _ESC[c], j + 2
    raise _Fail(f"undefined escape sequence '\\{c}'", base + j)


def _code_char(code: int, escape: str, pos: int) -> str:
    """The character of an escape's code, which must name a Unicode character."""
    if not 0 <= code <= 0x10FFFF or 0xD800 <= code <= 0xDFFF:
        raise _Fail(f"illegal character code {escape} (not a Unicode character)", pos)
    return chr(code)


def _int_value(text: str, pos: int) -> int:
    if text.startswith("0'"):
        c = text[2:]
        if c == "''":
            return 39
        if c[0] != "\\":
            return ord(c)
        ch, _ = _escape_at(c, 0, pos + 2)
        if len(ch) != 1:  # `0'\` followed by a newline
            raise _Fail("incomplete character code 0'", pos)
        return ord(ch)
    if "_" in text or " " in text:
        text = _GROUP_GAP.sub("", text)     # digit groups: 1_000_000, 1 000 000
    if "'" in text:                         # R'digits: radix R, 2..36
        radix, _, digits = text.partition("'")
        base = int(radix)
        if any(int(d, 36) >= base for d in digits):
            raise _Fail(f"illegal number {text} (a digit beyond radix {base})", pos)
        return _checked_int(digits, base, len(digits) * base.bit_length(), pos)
    if text[:2] in ("0x", "0o", "0b"):
        base = {"x": 16, "o": 8, "b": 2}[text[1]]
        digits = text[2:]
        return _checked_int(digits, base, len(digits) * (base.bit_length() - 1), pos)
    if not text.isascii():
        _one_script(text, pos)
    return _checked_int(text, 10, int(len(text) * 3.33), pos)


def _one_script(number: str, pos: int) -> None:
    """Refuse a number whose digits are of two scripts (``1٣``): SWI-Prolog reads digits of
    any script, one script a number, where Python's int() and float() mix them."""
    zeros = {ord(c) - unicodedata.decimal(c) for c in number if c.isdecimal()}
    if len(zeros) > 1:
        raise _Fail("illegal number (its digits are of two scripts)", pos)


def _checked_int(digits: str, base: int, approx_bits: int, pos: int) -> int:
    """An integer literal, refused beyond MAX_INTEGER_BITS (checked on the length first,
    so that a megabyte of digits is not converted only to be refused)."""
    if approx_bits > MAX_INTEGER_BITS + 8:
        raise _Fail(f"integer too large (more than {MAX_INTEGER_BITS} bits)", pos)
    value = int_from_text(digits, base)
    if value.bit_length() > MAX_INTEGER_BITS:
        raise _Fail(f"integer too large (more than {MAX_INTEGER_BITS} bits)", pos)
    return value


def _float_value(text: str, pos: int) -> float:
    if text.endswith("Inf"):
        return float("inf")
    if text.endswith("NaN"):
        # SWI-Prolog writes NaN as 1.5NaN and reads a mantissa strictly between 1 and 2
        if not 1.0 < float(text[:-3]) < 2.0:
            raise _Fail(f"illegal NaN {text} (a NaN is written 1.5NaN)", pos)
        return float("nan")
    if not text.isascii():
        _one_script(text, pos)
    value = float(text)
    if value == _INF:  # 1.0e400: as SWI-Prolog (float_overflow=error), not infinity
        raise _Fail("float overflow (the number is beyond the largest float)", pos)
    return value


_INF = float("inf")


def _duration_value(text: str, pos: int) -> int | float:
    i = len(text)
    while not text[i - 1].isdigit():
        i -= 1
    num, unit = text[:i], text[i:]
    if not num.isascii():
        _one_script(num, pos)
    scale = _UNITS[unit]
    if "." not in num and type(scale) is int:
        return _checked_int(num, 10, int(len(num) * 3.33), pos) * scale
    value = float(num) * scale
    if value == _INF:
        raise _Fail("float overflow (the number is beyond the largest float)", pos)
    return value


# Layout as SWI-Prolog reads it (and slr.lark's _LAYOUT): whitespace except U+001C..U+001F and
# U+0085, which SWI refuses as illegal characters and Python's `\s`, str.isspace and float() take
_L = r"[^\S\x1c-\x1f\x85]"
_LAYOUT_CHARS = "\t\n\v\f\r \xa0\u1680\u2000\u2001\u2002\u2003\u2004\u2005\u2006\u2007\u2008" \
    "\u2009\u200a\u2028\u2029\u202f\u205f\u3000"     # the same characters

# what separates digit groups in an integer (slr.lark's _GROUP_GAP, or one space)
_GROUP_GAP = re.compile(rf"_(?:/\*[\s\S]*?\*/|%[^\n]*|{_L})*| ")

_NUMBER = re.compile(rf"{_L}*-?[0-9]+(?:\.[0-9]+)?(?:[eE][0-9]+)?{_L}*\Z")


def _numlist_value(text: str, pos: int) -> Any:
    """The list term of a NUMLIST token such as ``[0.4, 0.1, -0.9]``."""
    parts = text[1:-1].split(",")
    nums = []
    append = nums.append
    for part in parts:
        try:
            if "." in part or "e" in part or "E" in part:
                # float() also takes `1.`, `.5` and `1.e5`, which Prolog does not
                if not _NUMBER.match(part):
                    raise ValueError(part)
                value = float(part)
                if value == _INF:
                    raise _Fail("float overflow (the number is beyond the largest float)",
                                pos + text.find(part.strip(), 1))
                append(value)
            elif len(part) < 100:
                append(int(part))
            else:  # the position is only looked up for a long integer (rare)
                append(_checked_int(part.strip(), 10, int(len(part) * 3.33),
                                    pos + text.find(part.strip(), 1)))
        except ValueError:
            offset = text.find(part.strip(), 1) if part.strip() else text.find(",,")
            raise _Fail("malformed number in list", pos + max(offset, 0)) from None
    out = NIL
    for num in reversed(nums):
        out = Struct(CONS, (num, out))
    return out


def _functor_name(tok: str, pos: int) -> str:
    name = tok[:-1]
    if name[0] == "'":
        return _quoted_text(name, pos)
    if _capital(name):        # a variable before `(`, as `Foo(a)`
        raise _Fail("operator expected", pos + len(name))
    return name


def _capital(name: str) -> bool:
    """A name that SWI-Prolog reads as a variable though the grammar's VAR (``[A-Z_]``)
    does not: one that begins with a non-ASCII capital letter (``Émile``, ``Ωx``, ``Ⅻ``;
    str.isupper: SWI's uppercase, which leaves a titlecase ``ǅ`` to the atoms)."""
    return name[0] > "\x7f" and name[0].isupper()


# -------------------------------------------------------------------------- resolver
class _Resolver:
    """Operator-precedence parsing of one sequence (ISO 6.3.4, with SWI's leniencies).

    Items are tuples ``(kind, value, token[, arg_priorities])``.  SWI-Prolog accepts terms
    up to priority 1200 as arguments (``f(a:-b)``), so every sequence is parsed at 1200.
    """

    __slots__ = ("items", "i", "n")

    def __init__(self, items: list):
        self.items = items
        self.i = 0
        self.n = len(items)

    def run(self) -> tuple[Any, int]:
        term, prec = self.parse(1200)
        if self.i < self.n:
            kind, value, tok = self.items[self.i][:3]
            if kind == _NAME and value in INFIX_OPS:
                raise _Fail(f"operator priority clash at '{value}'", tok.start_pos)
            raise self.operator_expected(tok)
        return term, prec

    def operator_expected(self, tok: Token) -> _Fail:
        text = _state.text
        pos = tok.start_pos
        if pos and text[pos - 1].isdigit() and _RATIONAL_TAIL.match(text, pos):
            # SWI-Prolog 9 reads 1r3 as a rational number; slr_sql has no rationals
            return _Fail("rational numbers such as 1r3 are not supported (1/3 is the float "
                         "0.333...)", pos)
        line_start = text.rfind("\n", 0, tok.start_pos) + 1
        if not text[line_start:tok.start_pos].strip() and line_start > self.items[0][2].start_pos:
            # The operand starts a line: most likely the previous clause lacks its '.'.
            return _Fail("operator expected (missing '.' at the end of the previous line?)",
                         tok.start_pos)
        return _Fail("operator expected", tok.start_pos)

    def parse(self, maxp: int) -> tuple[Any, int]:
        """The term of priority ≤ maxp starting at ``self.i``, and its priority.

        A Pratt parser written as a loop: an operator waiting for its (right) operand is
        pushed on ``pending`` instead of recursing, so ``- - ... - a``, ``a^a^...^a`` or a
        body of 100,000 goals is read in constant Python stack.
        """
        items = self.items
        n = self.n
        # (prefix name or None, left operand of an infix operator, operator, priority,
        #  the maxp to resume with once the operand is read)
        pending: list[tuple] = []
        while True:
            # -- a primary term at maxp (an operand, a prefix operator, an atom) ----------
            i = self.i
            if i >= n:
                tok = items[i - 1][2]
                op = items[i - 1][1]
                what = "a goal" if op in _GOAL_OPS else "a term"
                raise _Fail(f"{{unexpected}} (expected {what} after '{op}')", -tok.end_pos - 1)
            item = items[i]
            self.i = i + 1
            if item[0] != _NAME:
                left, lp = item[1], 0
            else:
                name, tok = item[1], item[2]
                left = None
                if i + 1 < n:
                    nxt = items[i + 1]
                    nk = nxt[0]
                    pre = PREFIX_OPS.get(name)
                    # `-1`: a minus written directly against a number is a negative literal.
                    if name == "-" and nk == _NUM and nxt[2].start_pos == tok.end_pos:
                        self.i = i + 2
                        left, lp = -nxt[1], 0
                    # A prefix operator followed by an infix operator is an atom: `- = a`;
                    # unless that operator ends the sequence and fits as the prefix
                    # operator's operand, as SWI reads `(- ^)`, `[\+ is]` (not `(- =)`).
                    elif pre is not None and not (
                            nk == _NAME and nxt[1] in INFIX_OPS and nxt[1] not in PREFIX_OPS
                            and (i + 2 < n or INFIX_OPS[nxt[1]][0] > pre[1])):
                        p, ap = pre
                        if p > maxp:
                            raise _Fail(f"operator priority clash at '{name}'", tok.start_pos)
                        pending.append((name, None, None, p, maxp))
                        maxp = ap
                        continue  # read the operand
                if left is None:
                    if name == "," or name == "|":
                        raise _Fail(f"unexpected '{name}' (expected a term)", tok.start_pos)
                    # An operator as an atom (`f(-)`, `X = (+)`, `- (-)`): lenient like SWI.
                    left, lp = Atom(name), 0
            # -- infix operators that fit at maxp; a finished operand completes its operator
            while True:
                if self.i < n:
                    item = items[self.i]
                    kind = item[0]
                    if kind == _FUNC:
                        # `a-(b,c)` lexes as the functor `-(` but, in infix position, it is
                        # the operator `-` followed by a parenthesised term.
                        op = item[1].name
                        if op not in INFIX_OPS:
                            raise self.operator_expected(item[2])
                        p, lmax, rmax = INFIX_OPS[op]
                        if p <= maxp and lp <= lmax:
                            self.i += 1
                            # The bracketed group is only the first operand of the right-hand
                            # side: `p:-(a;b),c` is p :- ((a;b), c).
                            pending.append((None, left, op, p, maxp))
                            left, lp, maxp = _group_of(item), 0, rmax
                            continue
                    else:
                        if kind != _NAME:
                            raise self.operator_expected(item[2])
                        spec = INFIX_OPS.get(item[1])
                        if spec is None:
                            raise self.operator_expected(item[2])
                        p, lmax, rmax = spec
                        if p <= maxp and lp <= lmax:
                            self.i += 1
                            pending.append((None, left, item[1], p, maxp))
                            maxp = rmax
                            break  # read the right operand
                # nothing more fits at this priority: `left` completes the newest operator
                if not pending:
                    return left, lp
                prefix, left0, op, p, maxp = pending.pop()
                left = Struct(prefix, (left,)) if prefix is not None else Struct(op, (left0, left))
                lp = p

    @staticmethod
    def group(args: list) -> Any:
        """The term of a bracket ``(a, b)`` met in infix position (``x-(a, b)``); see
        _group_of."""
        if len(args) == 1:
            return args[0][0]
        if max(a[1] for a in args) <= 999:
            group = args[-1][0]
            for a in reversed(args[:-1]):
                group = Struct(",", (a[0], group))
            return group
        # An argument above 999 (`=(a, b;c)`): re-read the whole bracket as one sequence
        # in which the commas are operators.
        joined = list(args[0][2])
        for a in args[1:]:
            first = a[2][0][2]
            joined.append((_NAME, ",", Token.new_borrow_pos("COMMA", ",", first)))
            joined.extend(a[2])
        return _Resolver(joined).run()[0]


# ----------------------------------------------------------------------- transformer
class _Callbacks:
    """Inline LALR callbacks: build terms while parsing (no parse tree is materialised);
    lark's ``Transformer`` is added as a base by :func:`_load_parser`.

    ``fitems``/``aitems``/``litems`` collect one sequence item per step (tokens become
    items here); the enclosing rule resolves the sequence with :class:`_Resolver`.
    """

    def fitems(self, c: list) -> list:
        if len(c) == 1:
            return [_item(c[0])]
        seq = c[0]
        seq.append(_item(c[1]))
        return seq

    aitems = litems = fitems

    def args(self, c: list) -> list:
        # (term, priority, items): the items are kept for _Resolver.infix, which may have
        # to re-read `a-(b, c;d)` as the operator `-` and one bracketed term.
        if len(c) == 1:
            items = c[0]
            return [_resolve(items)[:2] + (items,)]
        out = c[0]
        items = c[1]
        out.append(_resolve(items)[:2] + (items,))
        return out

    def elems(self, c: list) -> list:
        if len(c) == 1:
            return [_resolve(c[0])]
        out = c[0]
        out.append(_resolve(c[1]))
        return out

    def compound(self, c: list) -> tuple:
        tok = c[0]
        args = c[1]
        name = _functor_name(tok.value, tok.start_pos)
        if name == "[|]" and len(args) == 2:
            name = CONS  # SWI-Prolog 7's name of the list cell: '[|]'(H, T) is [H|T]
        item = (_FUNC, Struct(name, tuple([a[0] for a in args])), tok, args)
        if len(args) > 1 and max(a[1] for a in args) > 999:
            # The rare bracket that, in infix position, must be re-read as one sequence:
            # read it now, while inner brackets already have theirs, so that nesting
            # `a-(b:-c, a-(b:-c, ...))` does not recurse. An error is kept, and raised
            # only if the bracket does stand in infix position.
            try:
                group = _Resolver.group(args)
            except _Fail as fail:
                group = fail
            item += (group,)
        return item

    def paren(self, c: list) -> tuple:
        return (_TERM, _resolve(c[1])[0], c[0])

    def list(self, c: list) -> tuple:
        elems = c[1]
        tail = _resolve(c[3])[0] if len(c) == 4 else NIL
        # Built back to front in a loop: a million-element list must not recurse.
        for k in range(len(elems) - 1, -1, -1):
            tail = Struct(CONS, (elems[k][0], tail))
        return (_TERM, tail, c[0])

    def nil(self, c: list) -> tuple:
        return (_TERM, NIL, c[0])

    def curly(self, c: list) -> tuple:
        return (_TERM, Struct("{}", (_resolve(c[1])[0],)), c[0])

    def curly_empty(self, c: list) -> tuple:
        return (_TERM, Atom("{}"), c[0])

    def clause(self, c: list) -> Clause:
        st = _state
        term, _, first = _resolve(c[0])
        end = c[1]
        varnames = _ordered_vars(st.varmap)
        st.varmap = {}
        span = Span(st.filename, first.line, first.column, end.end_line, end.end_column)
        text = st.text[first.start_pos:end.end_pos]
        if type(term) is Struct and term.name in (":-", "?-") and len(term.args) == 1:
            return Clause(None, _bar_to_semicolon(term.args[0]), span, varnames, text)
        if type(term) is Struct and term.name == ":-" and len(term.args) == 2:
            head, body = term.args
            body = _bar_to_semicolon(body)
        else:
            head, body = term, TRUE
        if type(head) is Var:
            raise _Fail("variable as clause head", first.start_pos)
        if type(head) is not Atom and type(head) is not Struct:
            raise _Fail(f"clause head must be an atom or compound term, not {head!r}",
                        first.start_pos)
        return Clause(head, body, span, varnames, text)

    def program(self, c: list) -> list:
        if not c:
            return []
        out = c[0]
        out.append(c[1])
        return out

    def query(self, c: list) -> tuple[Any, dict[str, Var]]:
        # Returned exactly as read (no `|` -> `;` rewrite): parse_term is also the reader
        # for data, and format_term/parse_term must round-trip.
        return _resolve(c[0])[0], dict(_ordered_vars(_state.varmap))


def _group_of(item: tuple) -> Any:
    """The term of a _FUNC item's bracket in infix position (``x-(a, b)``)."""
    if len(item) > 4:  # read when the compound was built
        group = item[4]
        if type(group) is _Fail:
            raise group
        return group
    return _Resolver.group(item[3])


def _item(c: Any) -> tuple:
    """One sequence item ``(kind, value, token)`` from a token or a bracketed term."""
    if type(c) is not Token:
        return c
    t = c.type
    if t == "NAME" and _capital(c.value):
        t = "VAR"
    if t == "NAME" or t == "SYM" or t == "COMMA" or t == "BAR":
        return (_NAME, c.value, c)
    if t == "VAR":
        name = c.value
        if name == "_":
            return (_TERM, Var("_"), c)
        # Inner brackets reduce before the tokens around them, so variables are met out
        # of textual order: remember each one's first position.
        varmap = _state.varmap
        entry = varmap.get(name)
        if entry is None:
            entry = varmap[name] = [Var(name), c.start_pos]
        elif c.start_pos < entry[1]:
            entry[1] = c.start_pos
        return (_TERM, entry[0], c)
    if t == "FLOAT":
        return (_NUM, _float_value(c.value, c.start_pos), c)
    if t == "INT":
        return (_NUM, _int_value(c.value, c.start_pos), c)
    if t == "NUMLIST":
        return (_TERM, _numlist_value(c.value, c.start_pos), c)
    if t == "QNAME":
        text = _quoted_text(c.value, c.start_pos)
        # A quoted comma or bar is an ordinary atom, never the operator.
        return ((_TERM if text in (",", "|") else _NAME), Atom(text), c)
    if t == "STRING":
        return (_TERM, String(_quoted_text(c.value, c.start_pos)), c)
    if t == "DURATION":
        return (_NUM, _duration_value(c.value, c.start_pos), c)
    raise _Fail(f"unexpected token {c.value!r}", c.start_pos)  # pragma: no cover


def _resolve(items: list) -> tuple[Any, int, Token]:
    """Term, priority and first token of a sequence."""
    first = items[0]
    if len(items) == 1 and first[0] != _NAME:
        return first[1], 0, first[2]  # fast path: a single operand
    term, prec = _Resolver(items).run()
    return term, prec, first[2]


def _ordered_vars(varmap: dict) -> tuple:
    if len(varmap) < 2:
        return tuple((k, e[0]) for k, e in varmap.items())
    return tuple((k, e[0]) for k, e in sorted(varmap.items(), key=lambda kv: kv[1][1]))


def _bar_to_semicolon(goal: Any) -> Any:
    """SWI reads `(a | b)` as '|'(a, b) but runs it as `;` in a body: do that here.

    Rebuilds the control constructs bottom-up with an explicit stack (a body may hold
    100,000 goals); subterms without a `|` are kept as they are.
    """
    if type(goal) is not Struct or goal.name not in _CONTROL:
        return goal
    done: list = []                    # rebuilt terms, in order
    todo: list = [(goal, False)]       # (term, its arguments are rebuilt and on `done`)
    while todo:
        t, ready = todo.pop()
        if not ready:
            if type(t) is Struct and t.name in _CONTROL:
                todo.append((t, True))
                todo.extend((a, False) for a in reversed(t.args))
            else:
                done.append(t)
            continue
        k = len(t.args)
        args = tuple(done[-k:])
        del done[-k:]
        name = ";" if t.name == "|" and k == 2 else t.name
        if name == t.name and all(a is b for a, b in zip(args, t.args)):
            done.append(t)
        else:
            done.append(Struct(name, args))
    return done[0]


# ------------------------------------------------------------------------ entry points
_LARK: Lark | None = None
_LOCK = ordered_lock("parser")


def parse_first_term(text: str) -> tuple[Any, dict[str, Var]]:
    """Parse the first term of ``text``, up to the '.' that ends it, and ignore what follows,
    as SWI-Prolog's term_to_atom/2 and term_string/2 read a text; without such a '.' the
    whole text is the term (:func:`parse_term`).

    >>> str(parse_first_term("f(X). g(")[0]), str(parse_first_term("'a. b'")[0])
    ('f(X)', 'a. b')
    """
    try:
        for token in _parser().lex(text):
            if token.type == "END":
                return _parse(text[:token.end_pos], "<query>", "query")
    except UnexpectedInput:
        pass  # a text that does not lex up to an end: parse_term says where it is wrong
    return _parse(text, "<query>", "query")


def full_stop_end(text: str) -> int | None:
    """Where the clause or goal typed so far in ``text`` ends (the offset after its full
    stop, so a comment after the stop is left out), or None while the reader would read on:
    no full stop yet, a '.' inside a comment, or a quote still open (a quoted atom or
    string may span lines). Any other text that does not lex (a character no token holds,
    a bad escape in closed quotes) ends at its last character if that is a '.' (not
    ``..``), so that its syntax error is shown rather than waited on.

    >>> full_stop_end("X = 1. % the answer"), full_stop_end("X = 1 % not the end.")
    (6, None)
    >>> full_stop_end("X = 'a. b"), full_stop_end('X = "a.'), full_stop_end("X =.. [f")
    (None, None, None)
    >>> full_stop_end("X = 'a." + chr(10) + "b'."), full_stop_end("X = a" + chr(0) + ".")
    (11, 7)
    """
    try:
        tokens = list(_parser().lex(text))
    except UnexpectedInput as exc:
        at = getattr(exc, "pos_in_stream", None)
        if at is not None and text[at:at + 1] in ("'", '"', "`") \
                and text[at] not in text[at + 1:]:
            return None   # the quote opened there is not closed yet
        stripped = text.rstrip()
        return len(stripped) if stripped.endswith(".") and not stripped.endswith("..") else None
    if tokens and tokens[-1].type == "END":
        return tokens[-1].end_pos
    return None


def token_spans(text: str) -> list[tuple[int, int]]:
    """The ``(start, end)`` offsets of the tokens the reader makes of ``text`` (layout and
    comments are no tokens): how number_codes/2 and the like tell a number's text from one
    with a comment after it.

    >>> token_spans("12"), token_spans("1/**/")
    ([(0, 2)], [(0, 1)])
    """
    return [(token.start_pos, token.end_pos) for token in _parser().lex(text)]


def _parser() -> Lark:
    global _LARK
    if _LARK is None:
        with _LOCK:
            if _LARK is None:
                # lexer="basic", not "contextual": the grammar is flat, so nearly every
                # state accepts every terminal and a contextual lexer cannot disambiguate
                # anything (measured: same speed); but it would lex a clause-ending `.`
                # inside an unclosed bracket as the symbol atom `.` (END is not acceptable
                # there), moving the error to the end of the file.
                # (generated with: -s program -s query -l basic, no placeholders)
                _LARK = _load_parser()
    return _LARK


def _load_parser() -> Lark:
    global Token, UnexpectedInput, UnexpectedCharacters, UnexpectedToken
    # The LALR parser is a module generated from grammar/slr.lark by lark's standalone tool
    # (grammar/__init__.py says how): it needs no `lark` at run time, so it works whichever
    # `lark` an environment has -- lark-parser 0.12 (which ROS 2's rosidl parser installs
    # into the same `lark/` directory) or none.
    from .grammar import slr_parser

    Token, UnexpectedInput = slr_parser.Token, slr_parser.UnexpectedInput
    UnexpectedCharacters, UnexpectedToken = (slr_parser.UnexpectedCharacters,
                                             slr_parser.UnexpectedToken)

    class _Builder(_Callbacks, slr_parser.Transformer):
        pass

    return slr_parser.Lark_StandAlone(transformer=_Builder())


# Typical mistakes, matched against the parser state of the error by lark's
# UnexpectedInput.match_examples.  Bracket mismatches are diagnosed separately (by
# _bracket_problem, which can also say where the unclosed bracket was opened).
_EXAMPLES: dict[str, list[str]] = {
    "missing '.' at the end of the clause": [
        "a", "a(1)", "a :- b", "a :- b, c", "a :- X", "a :- 1", "a :- \"s\"", "a :- [b]",
        "a :- 1.5", "a :- 'b'", "a :- {b}", "a :- (b)", "a :- - "],
    "expected an argument": ["a(", "a(b,", "a(,", "a(b,)", "a()", "a(b, )", "a(b,,c)"],
    "expected a list element": ["a([b,", "a([,", "a([b,]", "a([b|", "a([b|]", "a([b|c|d]",
                                "a([b|c,d]", "a([,b])"],
    "expected a term": ["(", "a :- (", "a :- (,", "a :- ()", "{", "a :- {,", ",", ", a.",
                        "a :- (|", "a :- {}}"],
}

_OPENERS = {"LPAR": ")", "FUNCT": ")", "LSQB": "]", "LBRACE": "}"}
_CLOSERS = {"RPAR": ")", "RSQB": "]", "RBRACE": "}"}
_BRACKET_NAMES = {")": "parenthesis", "]": "bracket", "}": "brace"}


def _line_col(text: str, pos: int) -> tuple[int, int, str]:
    line_start = text.rfind("\n", 0, pos) + 1
    line_end = text.find("\n", pos)
    if line_end < 0:
        line_end = len(text)
    # the source line as shown under the message: printable (no CR, no lone surrogate)
    shown = _SURROGATE.sub("\ufffd", text[line_start:line_end].rstrip("\r"))
    return text.count("\n", 0, pos) + 1, pos - line_start + 1, shown


def _describe(text: str, pos: int) -> str:
    """``unexpected <what is at pos>`` for a message."""
    if pos >= len(text):
        return "unexpected end of text"
    word = text[pos:pos + 16].split()
    if not word:
        return "unexpected end of text"
    w = word[0]
    for stop in ("(", ")", "[", "]", "{", "}", ",", "|"):
        k = w.find(stop)
        if k == 0:
            w = stop
            break
        if k > 0:
            w = w[:k]
    if w.startswith("."):
        w = "."
    return f"unexpected {w!r}"


def _next_token_pos(text: str, pos: int) -> int:
    """First character at or after pos that is not layout or a comment."""
    n = len(text)
    while pos < n:
        ch = text[pos]
        if ch in _LAYOUT_CHARS:
            pos += 1
        elif ch == "%":
            nl = text.find("\n", pos)
            pos = n if nl < 0 else nl + 1
        elif text.startswith("/*", pos):
            end = text.find("*/", pos + 2)
            pos = n if end < 0 else end + 2
        else:
            break
    return pos


def _syntax_error(text: str, filename: str, message: str, pos: int) -> SLRSyntaxError:
    if pos < 0:  # "after the token ending at -pos-1": report at the next token, naming it
        pos = _next_token_pos(text, -pos - 1)
        message = message.replace("{unexpected}", _describe(text, pos))
    line, col, src = _line_col(text, min(pos, len(text)))
    return SLRSyntaxError(message, line, col, src, filename)


def _bracket_problem(text: str, err_pos: int, err_type: str) -> str | None:
    """Explain an error caused by unbalanced brackets, or None if brackets are fine."""
    stack: list[Token] = []
    try:
        for tok in _parser().lex(text):
            if tok.start_pos >= err_pos:
                break
            if tok.type in _OPENERS:
                stack.append(tok)
            elif tok.type in _CLOSERS and stack:
                stack.pop()
            elif tok.type == "END":
                stack.clear()
    except UnexpectedInput:
        pass
    closer = _CLOSERS.get(err_type)
    if closer is not None:
        if not stack:
            return f"unexpected '{closer}' (no matching opening bracket)"
        want = _OPENERS[stack[-1].type]
        if want != closer:
            o = stack[-1]
            return (f"unexpected '{closer}' (the '{o.value[-1]}' at line {o.line}, column "
                    f"{o.column + len(o.value) - 1} is closed by '{want}')")
        return None
    if stack and err_type in ("$END", "END"):
        o = stack[-1]
        want = _OPENERS[o.type]
        return (f"unbalanced {_BRACKET_NAMES[want]}: missing '{want}' for the "
                f"'{o.value[-1]}' at line {o.line}, column {o.column + len(o.value) - 1}")
    return None


def _expected_text(expected: set[str]) -> str:
    if {"NAME", "VAR"} <= expected:
        return "expected a term"
    if "END" in expected:
        return "expected an operator or '.'"
    if expected == {"$END"}:     # a query (one term) goes on after its final '.'
        return "expected the end of the text after '.'"
    names = [_CLOSERS.get(x, x.lower()) for x in sorted(expected)]
    return "expected " + " or ".join(f"'{n}'" if len(n) == 1 else n for n in names)


_RATIONAL_TAIL = re.compile(r"r[0-9]")


def _lark_error(e: UnexpectedInput, text: str, filename: str, start: str) -> SLRSyntaxError:
    if isinstance(e, UnexpectedCharacters):
        pos = e.pos_in_stream
        ch = text[pos]
        if ch == "'" and text[pos - 1:pos] == "0" and (pos < 2 or not text[pos - 2].isalnum()):
            msg = "incomplete character code 0'"
        elif ch == "'":
            msg = "unterminated quoted atom"
        elif ch == '"':
            msg = "unterminated string"
        elif ch == "`":
            msg = "back-quoted text is not supported"
        else:
            msg = f"unexpected character {ch!r}"
        return _syntax_error(text, filename, msg, pos)
    at_end = not isinstance(e, UnexpectedToken) or e.token.type == "$END"
    pos = len(text.rstrip()) if at_end else e.token.start_pos
    err_type = "$END" if at_end else e.token.type
    what = "unexpected end of text" if at_end else _describe(text, pos)
    problem = _bracket_problem(text, pos, err_type)
    if problem is not None:
        return _syntax_error(text, filename, problem if problem.startswith("unexpected")
                             else f"{what} ({problem})", pos)
    label = None
    if isinstance(e, UnexpectedToken):
        try:
            label = e.match_examples(_example_parse, _EXAMPLES, use_accepts=True)
        except Exception:  # pragma: no cover - a broken example must not hide the error
            label = None
        if label is None:
            # match_examples also compares the parser's stack depth, so an example only
            # matches at the same bracket nesting; retry on the LALR state alone.
            table = _example_table()
            pos_ = e.state.position if e.state is not None else None
            label = table.get((pos_, e.token.type)) or table.get((pos_, None))
    if label is None:
        label = _expected_text(set(getattr(e, "expected", ()) or ()))
    if at_end and label.startswith("missing '.'"):
        # `X is 1 +.` reads `+.` as one symbol atom: say so.
        tail = text.rstrip()
        k = len(tail)
        while k > 0 and tail[k - 1] in "#$&*+-./:<=>?@^~\\":
            k -= 1
        if tail.endswith(".") and k < len(tail) - 1:
            label += f" ('{tail[k:]}' reads as one symbol atom: put a space before '.')"
    return _syntax_error(text, filename, f"{what} ({label})", pos)


_TABLE: dict | None = None


def _example_table() -> dict:
    """(LALR state, token type) -> label, from _EXAMPLES; (state, None) for any token."""
    global _TABLE
    if _TABLE is None:
        table: dict = {}
        for label, examples in _EXAMPLES.items():
            for example in examples:
                try:
                    _run(example, "<example>", "program")
                except UnexpectedToken as ex:
                    table.setdefault((ex.state.position, ex.token.type), label)
                    table.setdefault((ex.state.position, None), label)
                except (UnexpectedInput, _Fail):
                    pass
        _TABLE = table
    return _TABLE


def _example_parse(text: str) -> Any:
    try:
        return _run(text, "<example>", "program")
    except _Fail:
        return None


def _run(text: str, filename: str, start: str) -> Any:
    st = _state
    st.varmap = {}
    st.text = text
    st.filename = filename
    return _parser().parse(text, start=start)


# Above this size the cyclic GC is paused while parsing: building a million cons cells
# otherwise triggers repeated full collections that traverse the growing list (3x slower).
_GC_PAUSE_CHARS = 100_000


def _parse(text: str, filename: str, start: str) -> Any:
    if len(text) > _GC_PAUSE_CHARS and gc.isenabled():
        gc.disable()
        try:
            return _parse1(text, filename, start)
        finally:
            gc.enable()
    return _parse1(text, filename, start)


# A lone surrogate (U+D800..U+DFFF) can sit in a Python str but in no UTF-8 text: refused
# here, as SWI-Prolog refuses it, instead of failing later when the program is stored.
_SURROGATE = re.compile("[\ud800-\udfff]")


def _parse1(text: str, filename: str, start: str) -> Any:
    st = _state
    saved = getattr(st, "varmap", None), getattr(st, "text", None), getattr(st, "filename", None)
    try:
        bad = _SURROGATE.search(text)
        if bad is not None:
            raise _Fail(f"illegal character code \\x{ord(bad.group()):X}\\ (a lone surrogate, "
                        "not a Unicode character)", bad.start())
        return _run(text, filename, start)
    except _Fail as f:
        raise _syntax_error(text, filename, f.message, f.pos) from None
    except UnexpectedInput as e:
        err = _lark_error(e, text, filename, start)
        raise err from None
    except RecursionError:  # pragma: no cover - a safety net: the parser itself is iterative
        raise _syntax_error(text, filename, "term nested too deeply", 0) from None
    finally:
        st.varmap, st.text, st.filename = saved


def parse_program(text: str, filename: str = "<string>") -> list[Clause]:
    """Parse program text into clauses, in source order; any syntax error raises.

    >>> [str(c.head) for c in parse_program("p(a).  q(X) :- p(X).")]
    ['p(a)', 'q(X)']
    >>> c = parse_program(":- event seg/2.")[0]; c.head is None, str(c.body)
    (True, 'event seg/2')
    """
    return _parse(text, filename, "program")


def parse_term(text: str, filename: str = "<query>") -> tuple[Any, dict[str, Var]]:
    """Parse one term (a goal or an event); the final '.' is optional.

    Returns the term and its named variables in order of first appearance (``_`` excluded).

    >>> t, vs = parse_term("color(O, C)^12.5"); str(t), list(vs)
    ('color(O,C)^12.5', ['O', 'C'])
    """
    return _parse(text, filename, "query")


def parse_indicator(text: str) -> tuple[str, int | None]:
    r"""An event type or predicate given as text, ``Name/Arity`` or ``Name`` (every arity):
    ``(name, arity)``, arity None when not given.

    A name that begins with a quote is read as Prolog reads a quoted atom (the form
    ``writeq`` and slr_sql's messages print: ``'x/seen'/2``, ``'it''s'/1``, escapes such as
    ``\n``), and the text must then be that atom or that atom ``/`` an arity; anything
    else is an SLRError. A name written without quotes is the text before the last slash
    that digits follow (so ``x/seen/2`` is the type ``'x/seen'`` of two arguments, as
    before quoted names were read), else the whole text.

    >>> parse_indicator("seg/2"), parse_indicator("seg"), parse_indicator("x/seen/2")
    (('seg', 2), ('seg', None), ('x/seen', 2))
    >>> parse_indicator("'x/seen'/2"), parse_indicator("'it''s'"), parse_indicator("'a\\nb'/0")
    (('x/seen', 2), ("it's", None), ('a\nb', 0))
    >>> parse_indicator("'x/seen/2")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: "'x/seen/2" is not an indicator Name/Arity or Name: it does not read as a quoted name, alone or followed by /Arity (unterminated quoted atom)
    """
    if not text.startswith("'"):
        name, slash, arity = text.rpartition("/")
        if slash and name and arity.isascii() and arity.isdigit():
            return name, int(arity)
        return text, None
    from .printable import shown

    def refused(why: str) -> SLRError:
        return SLRError(f"{shown(text)} is not an indicator Name/Arity or Name: {why}")

    try:
        term, _ = _parse(text, "<indicator>", "query")
    except SLRError as exc:
        detail = getattr(exc, "message", None) or str(exc).splitlines()[0]
        raise refused(f"it does not read as a quoted name, alone or followed by /Arity "
                      f"({detail})") from None
    if type(term) is Struct and term.name == "/" and len(term.args) == 2:
        name, arity = term.args
        if type(name) is not Atom:
            raise refused("the part before the last / is not one quoted name")
        if type(arity) is not int or arity < 0:
            raise refused("the arity must be an integer >= 0")
    elif type(term) is Atom:
        name, arity = term, None
    else:
        raise refused("after the quoted name comes /Arity or nothing")
    if not str(name):
        raise refused("the name is empty")
    return str(name), arity


# Events: the common shape of recorded events -- plain atoms, numbers, lists and compounds
# such as seg(cup1,[0.4,0.1,0.9])^12.31 -- is read directly by a regular-expression scanner:
# the full parser costs ~80 us an event, which dominates ingesting a long recording. Anything else (quoted atoms, strings,
# operators, variables, other number syntaxes) falls back to the full parser, so the fast
# path only ever accepts text that the parser reads the same way.
# the tokens both fast readers take: a float needs a dot; an int followed by what would make
# it another number syntax (0'a, 0x1f, 1_000, 1e5, 1.) is none; digits of other scripts go to
# the parser, which refuses a number mixing two (int() and float() take any mix)
_FAST_FLOAT = r"-?[0-9]+\.[0-9]+(?:[eE][+-]?[0-9]+)?"
_FAST_INT = r"-?[0-9]+(?![\d.'xob_eE])"
_FAST_ATOM = r"[a-z][A-Za-z0-9_]*"
_FAST_TOKEN = re.compile(rf"""{_L}*(?:
      (?P<float>{_FAST_FLOAT})
    | (?P<int>{_FAST_INT})
    | (?P<functor>{_FAST_ATOM})\(
    | (?P<atom>{_FAST_ATOM})
    | (?P<punct>[\[\](),^])
    )""", re.VERBOSE)


# The flattest events -- atoms and numbers as arguments, or flat lists of them, the shape of
# nearly every recorded event (seg(cup1,[0.4,0.1,0.9])^12.31) -- are checked by one regular
# expression of the same tokens and then split, without the scanner's loop of one match per
# token (~3-6x faster); whatever it does not match goes to the scanner below.
_FLAT_NUMBER = rf"{_FAST_FLOAT}|{_FAST_INT}"
_FLAT_ITEM = rf"(?:{_FLAT_NUMBER}|{_FAST_ATOM})"
_FLAT_ARG = rf"{_L}*(?:{_FLAT_ITEM}|\[{_L}*(?:{_FLAT_ITEM}{_L}*(?:,{_L}*{_FLAT_ITEM}{_L}*)*)?\]){_L}*"
_FLAT_EVENT = re.compile(
    rf"{_L}*({_FAST_ATOM})(?:\(({_FLAT_ARG}(?:,{_FLAT_ARG})*)\))?{_L}*\^{_L}*"
    rf"(?:(?!-)({_FLAT_NUMBER})|\[{_L}*({_FLAT_NUMBER}){_L}*,{_L}*({_FLAT_NUMBER}){_L}*\]){_L}*\Z")
# (the pieces of arguments _FLAT_EVENT matched: an int needs no look-ahead there)
_FLAT_PIECE = re.compile(rf"{_FAST_FLOAT}|-?[0-9]+|{_FAST_ATOM}|\[|\]")


def _flat_event(text: str) -> tuple | None:
    """``parse_event_fast`` for the flattest events (see above), else None."""
    m = _FLAT_EVENT.match(text)
    if m is None:
        return None
    name, inside, at, start, stop = m.groups()
    args: list = []
    if inside is not None:
        items: list | None = None      # the open list's items
        pieces = _FLAT_PIECE.findall(inside) if "[" in inside else inside.split(",")
        for piece in pieces:
            piece = piece.strip()
            first = piece[0]
            if first == "[":
                items = []
                continue
            if first == "]":
                args.append(make_list(items) if items else NIL)
                items = None
                continue
            value = Atom(piece) if "a" <= first <= "z" else \
                float(piece) if "." in piece else int(piece)
            if type(value) is float and math.isinf(value):
                return None        # the parser's "float overflow", not an infinite argument
            (args if items is None else items).append(value)
    if at is not None:
        return (name, tuple(args), float(at), float(at))
    return (name, tuple(args), float(start), float(stop))


class _NotFast(Exception):
    pass


_FAST_MAX_DEPTH = 50


def parse_event_fast(text: str) -> tuple | None:
    """``name(args)^T`` / ``name(args)^[S,E]`` in the simple subset -> ``(name, args, S, E)``
    with float times, or None when the text is outside it (then use :func:`parse_term`).

    >>> parse_event_fast("seg(cup1, [0.5, 1])^12.5")
    ('seg', (Atom('cup1'), Struct('.', (0.5, Struct('.', (1, Atom('[]')))))), 12.5, 12.5)
    >>> parse_event_fast("p('A')^1") is None
    True
    """
    flat = _flat_event(text)
    if flat is not None:
        return flat
    return _scanned_event(text)


def _scanned_event(text: str) -> tuple | None:
    """``parse_event_fast`` by the token scanner: nested terms, the rest of the subset."""
    tokens: list[tuple[str, str]] = []
    pos = 0
    end = len(text)
    while pos < end:
        m = _FAST_TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            if text[pos:].strip(_LAYOUT_CHARS) == "":
                break
            return None
        pos = m.end()
        kind = m.lastgroup
        tokens.append((kind, m.group(kind)))
    i = 0

    def peek() -> tuple[str, str]:
        return tokens[i] if i < len(tokens) else ("eof", "")

    def take(kind: str, value: str | None = None) -> str:
        nonlocal i
        k, v = peek()
        if k != kind or (value is not None and v != value):
            raise _NotFast
        i += 1
        return v

    depth = 0

    def term() -> object:
        nonlocal i, depth
        k, v = peek()
        if k == "float":
            i += 1
            value = float(v)
            if math.isinf(value):
                raise _NotFast    # the parser's "float overflow", not an infinite argument
            return value
        if k == "int":
            i += 1
            return int(v)
        if k == "atom":
            i += 1
            return Atom(v)
        if depth > _FAST_MAX_DEPTH:
            raise _NotFast  # deeper terms are left to the (iterative) parser
        if k == "functor":
            i += 1
            depth += 1
            out = Struct(v, args_until(")"))
            depth -= 1
            if v == "[|]" and len(out.args) == 2:
                out = Struct(CONS, out.args)
            return out
        if k == "punct" and v == "[":
            i += 1
            if peek() == ("punct", "]"):
                i += 1
                return NIL
            depth += 1
            items = args_until("]")
            depth -= 1
            return make_list(items)
        raise _NotFast

    def args_until(close: str) -> list:
        items = [term()]
        while peek() == ("punct", ","):
            take("punct", ",")
            items.append(term())
        take("punct", close)
        return items

    def number() -> float:
        nonlocal i
        k, v = peek()
        if k not in ("int", "float"):
            raise _NotFast
        i += 1
        return float(v)

    try:
        k, name = peek()
        if k == "functor":
            i += 1
            args = args_until(")")
        elif k == "atom":
            i += 1
            args = []
        else:
            return None
        take("punct", "^")
        if peek() == ("punct", "["):
            take("punct", "[")
            start = number()
            take("punct", ",")
            stop = number()
            take("punct", "]")
        else:
            # "^-4" is not a negative time to Prolog: "^-" reads as one symbol atom.
            if peek()[1].startswith("-"):
                return None
            start = stop = number()
        if i != len(tokens):
            return None
    except _NotFast:
        return None
    finally:
        # term and args_until call each other through their closures' cells: a reference
        # cycle of ~20 objects per call that only the cyclic collector would free (in `slr
        # serve` at 1,000 events/s, a young collection of ~20,000 objects every second or two,
        # a pause of every request and subscriber). Emptying the cells breaks it.
        term = args_until = None  # type: ignore[assignment]  # noqa: F841
    return (name, tuple(args), start, stop)
