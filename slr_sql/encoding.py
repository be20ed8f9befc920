"""How SLR terms are stored in SQLite columns (pure Python; no SQLite import here).

Every data argument of an event is one column value. The encoding is chosen so that the
common values are plain SQL values a user can read and filter on, and so that
``decode(encode(t))`` gives back exactly ``t`` for every ground term.

Column values (top level)
-------------------------

======================  ==========================  ==================================
term                    stored as                   example
======================  ==========================  ==================================
atom                    TEXT, the atom's text       ``cup1``
integer (64-bit)        INTEGER                     ``42``
integer (larger)        TEXT, JSON                  ``{"$int":"123456789012345678901"}``
float                   REAL                        ``0.5``
string                  TEXT, a JSON string         ``"hello world"``
proper list             TEXT, a JSON array          ``[0.4,0.1,0.9]``  ``["a","b"]``
the empty list ``[]``   TEXT, an empty JSON array   ``[]``
compound ``f(a,1)``     TEXT, a single-key object   ``{"f":["a",1]}``
atom starting with      TEXT, JSON                  ``{"$atom":"[x"}``
``[`` ``{`` or ``"``
======================  ==========================  ==================================

So a TEXT value that does not start with ``[``, ``{`` or ``"`` is always an atom, verbatim;
anything starting with one of those three characters is JSON. Inside SQL,
``WHERE arg1 = 'cup1'`` finds the atom ``cup1`` and ``WHERE arg1 = 3`` the integer 3 (and,
SQL being SQL, the float 3.0).

Inside JSON (list elements, compound arguments)
-----------------------------------------------

* atom -> JSON string (``"a"``); the empty list ``[]`` -> ``[]``
* string -> ``{"$string":"text"}``
* integer -> JSON number without a fraction (``7``); beyond 64 bits ``{"$int":"digits"}``
* float -> JSON number that always has a ``.`` or an exponent (``7.0``, ``1e+22``), so it decodes
  as a float again; +inf/-inf -> ``1e999`` / ``-1e999`` (valid JSON that both Python and
  SQLite's JSON functions read as infinity)
* proper list -> JSON array; compound ``f(X1..Xn)`` -> ``{"f":[X1..Xn]}`` (also for names such
  as ``'$string'``: the reserved ``$string``/``$atom``/``$int`` keys always have a JSON
  *string* value, a compound always an *array*, so they never clash)
* a partial list ``[a|b]`` (tail not ``[]``) is the compound ``'.'(a, b)``: ``{".":["a","b"]}``

JSON is written compactly (no spaces) and keeps non-ASCII characters as they are, so SQLite's
``json_extract(arg2, '$[0]')`` works on lists. What has no stored form makes :func:`encode`
raise :class:`Unencodable`: unbound variables, NaN, text with a lone surrogate (not valid
Unicode, so SQLite's UTF-8 cannot hold it), integers with more decimal digits than Python
converts (``sys.get_int_max_str_digits()``, 4300 by default), and terms nested more than
400 deep.

>>> from slr_sql.terms import Atom, String, Struct, make_list
>>> encode(make_list([Atom("x"), 1, 2.0])), encode(Struct("f", (Atom("a"), String("s"))))
('["x",1,2.0]', '{"f":["a",{"$string":"s"}]}')
>>> decode('{"f":["a",{"$string":"s"}]}') == Struct("f", (Atom("a"), String("s")))
True
"""
from __future__ import annotations

import json
import math
import re
import sys
from operator import itemgetter
from operator import le as _le
from json.encoder import encode_basestring as _quote  # C-accelerated; keeps non-ASCII
from typing import Any

from .terms import CONS, NIL, Atom, String, Struct, Var, make_list

__all__ = ["encode", "encode_column", "decode", "encode_json", "Unencodable", "INT64_MIN",
           "INT64_MAX"]

INT64_MIN = -(2 ** 63)
INT64_MAX = 2 ** 63 - 1

# First characters that mark a TEXT column value as JSON rather than a bare atom.
_JSON_STARTS = frozenset('[{"')


class Unencodable(ValueError):
    """A term that has no stored form: it contains an unbound variable, a NaN, or a
    Python value that is not a term. ``reason`` is a short phrase for error messages."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


_SURROGATE = re.compile("[\ud800-\udfff]")


def _check_text(text: str) -> str:
    """``text`` itself, or :class:`Unencodable` if it holds a lone surrogate. ASCII text (the
    common case) is recognised in constant time, without a scan."""
    if not text.isascii():
        found = _SURROGATE.search(text)
        if found is not None:
            raise Unencodable(f"text with a lone surrogate ({found.group()!a}) is not valid "
                              "Unicode")
    return text


def _big_int_json(value: int) -> str:
    """``{"$int":"digits"}`` for an integer beyond 64 bits; :class:`Unencodable` when it has
    more digits than Python converts to text."""
    try:
        digits = str(value)
    except ValueError:  # beyond sys.get_int_max_str_digits()
        raise Unencodable(f"integer too large to be stored (about "
                          f"{int(value.bit_length() * 0.30103) + 1} digits; at most "
                          f"{sys.get_int_max_str_digits()})") from None
    return '{"$int":"' + digits + '"}'


def encode(term: Any) -> Any:
    """Encode a ground term as one SQLite column value (``str``, ``int`` or ``float``).

    Plain Python values are accepted the way :func:`slr_sql.terms.from_python` reads them
    (``str`` -> atom, ``list`` -> list, ``bool`` -> ``true``/``false``).

    >>> encode(Atom("cup1")), encode(3), encode(String("hi")), encode(Atom("[x"))
    ('cup1', 3, '"hi"', '{"$atom":"[x"}')
    """
    tt = type(term)
    if tt is Atom:
        if not term.isascii():
            _check_text(term)
        if term and term[0] in _JSON_STARTS:
            if term == "[]":
                return "[]"
            return '{"$atom":' + _quote(term) + "}"
        return str(term)
    if tt is float:
        if term != term:
            raise Unencodable("NaN cannot be stored")
        return term
    if tt is int:
        if INT64_MIN <= term <= INT64_MAX:
            return term
        return _big_int_json(term)
    if tt is Struct or tt is list or tt is tuple:
        # the fast path: a flat list of numbers or of plain atoms (robot vectors, names)
        if tt is Struct:
            text = _cons_list_json(term) if term.name == "." else None
        else:
            text = _flat_list_json(term)
        if text is None:
            text = _json(term, 0)
        return text if text.isascii() else _check_text(text)
    if tt is String:
        return _quote(_check_text(term))
    if tt is Var:
        return encode(_deref_or_raise(term))
    if tt is str:
        return encode(Atom(term))
    if tt is bool:
        return "true" if term else "false"
    if isinstance(term, str):  # other str subclasses: String/Atom subclasses first
        return encode(String(term) if isinstance(term, String) else Atom(term))
    if isinstance(term, int):
        return encode(int(term))
    if isinstance(term, float):
        return encode(float(term))
    raise Unencodable(f"{type(term).__name__} value {term!r} is not a term")


def _cons_list_json(cell: Struct) -> str | None:
    """The JSON array of a proper list of ``'.'/2`` cells whose elements are each a finite
    float, a 64-bit integer or a plain atom (not ``[]``); None for anything else (another
    element, a partial list, a variable in the spine), which the general encoder handles.
    One walk, no call per element but the number's own text (``repr`` of a float is most of
    the cost of a vector); the text is exactly the general encoder's. (The element tests
    are those of :func:`_flat_list_json`, for Python lists.)

    >>> from slr_sql.terms import make_list
    >>> _cons_list_json(make_list([0.5, 1, Atom("cup1")])), _cons_list_json(make_list([[]]))
    ('[0.5,1,"cup1"]', None)
    """
    parts: list = []
    add = parts.append
    try:
        while True:
            name = cell.name
            if name is not CONS and name != ".":
                return None
            head, cell = cell.args  # ValueError: a '.' with other than two arguments
            kind = type(head)
            if kind is float:
                if not _NEG_INF < head < _INF:
                    return None  # inf (1e999) and NaN (refused) take the general path
                add(_float_repr(head))
            elif kind is int and INT64_MIN <= head <= INT64_MAX:
                add(_int_str(head))
            elif (kind is Atom or kind is str) and head != "[]":
                add(_quote(head))
            else:
                return None
            if type(cell) is not Struct:
                if type(cell) is Atom and cell == "[]":
                    return "[" + ",".join(parts) + "]"
                return None  # a partial list [a|b], or a variable tail
    except ValueError:
        return None


def _flat_list_json(items: list | tuple) -> str | None:
    """The JSON array of a Python list or tuple whose elements are each a finite float, a
    64-bit integer or a plain atom (not ``[]``); None as soon as one is anything else, for
    the general encoder. (The element tests are those of :func:`_cons_list_json`.)

    >>> _flat_list_json([0.5, 1, Atom("cup1")]), _flat_list_json([1.0, math.inf])
    ('[0.5,1,"cup1"]', None)
    """
    parts: list = []
    add = parts.append
    for item in items:
        kind = type(item)
        if kind is float:
            if not _NEG_INF < item < _INF:
                return None  # inf (1e999) and NaN (refused) take the general path
            add(_float_repr(item))
        elif kind is int and INT64_MIN <= item <= INT64_MAX:
            add(_int_str(item))
        elif (kind is Atom or kind is str) and item != "[]":
            add(_quote(item))
        else:
            return None
    return "[" + ",".join(parts) + "]"


def encode_column(values: list) -> list:
    """:func:`encode` of every value of a column (the same argument of many events).
    A column of one kind is checked whole: plain ASCII atoms are their own text, 64-bit
    integers and floats other than NaN are themselves, flat lists of numbers and atoms go
    straight to their encoder; any other column is encoded value by value. Raises
    :class:`Unencodable` as :func:`encode` does.

    >>> encode_column([Atom("cup1"), Atom("cup2")]), encode_column([1.5, 2.0]), encode_column([Atom("[x")])
    (['cup1', 'cup2'], [1.5, 2.0], ['{"$atom":"[x"}'])
    """
    kinds = set(map(type, values))
    if len(kinds) == 1:
        (kind,) = kinds
        if kind is Atom or kind is str:
            try:
                if all(map(str.isascii, values)) \
                        and _JSON_STARTS.isdisjoint(map(_first_char, values)):
                    return list(map(str, values))
            except IndexError:  # an empty atom: encoded one by one
                pass
        elif kind is float:
            if all(map(_le, values, values)):  # False only at a NaN
                return values
        elif kind is int:
            if INT64_MIN <= min(values) and max(values) <= INT64_MAX:
                return values
        elif kind is Struct or kind is list:  # vectors: the fast path, no dispatch
            texts = list(map(_cons_list_json if kind is Struct else _flat_list_json, values))
            if None not in texts and all(map(str.isascii, texts)):
                return texts
    return list(map(encode, values))


def encode_json(term: Any) -> str:
    """The JSON text of a term as it appears *inside* a stored list or compound.

    >>> encode_json(Atom("a")), encode_json(String("a")), encode_json(1.0)
    ('"a"', '{"$string":"a"}', '1.0')
    """
    text = _json(term, 0)
    return text if text.isascii() else _check_text(text)


def _deref_or_raise(var: Var) -> Any:
    t = var
    while type(t) is Var:
        if t.ref is None:
            raise Unencodable(f"{t.name} is unbound")
        t = t.ref
    return t


_INF = math.inf
_NEG_INF = -math.inf
_first_char = itemgetter(0)
_float_repr = float.__repr__
_int_str = int.__repr__
_MAX_DEPTH = 400  # nesting of compounds/lists; deeper terms are rejected, not crashed on


def _json(t: Any, depth: int) -> str:
    tt = type(t)
    if tt is Var:
        t = _deref_or_raise(t)
        tt = type(t)
    if tt is Atom:
        return "[]" if t == "[]" else _quote(t)
    if tt is int:
        if INT64_MIN <= t <= INT64_MAX:
            return str(t)
        return _big_int_json(t)
    if tt is float:
        if t != t:
            raise Unencodable("NaN cannot be stored")
        if t == math.inf:
            return "1e999"
        if t == -math.inf:
            return "-1e999"
        return repr(t)  # repr always has '.' or an exponent: decodes as float
    if tt is String:
        return '{"$string":' + _quote(t) + "}"
    if depth > _MAX_DEPTH:
        raise Unencodable("term is nested too deeply to be stored")
    if tt is Struct:
        args = t.args
        if t.name == "." and len(args) == 2:
            # Walk the cons cells iteratively: long lists must not recurse.
            items = []
            add = items.append
            cell = t
            while True:
                head, tail = cell.args
                # Inline the common element kinds (numbers, atoms): vectors of floats are
                # the bulk of robot data, and a call per element costs more than the element.
                th = type(head)
                if th is float and _NEG_INF < head < _INF:
                    add(_float_repr(head))
                elif th is Atom and head != "[]":
                    add(_quote(head))
                elif th is int and INT64_MIN <= head <= INT64_MAX:
                    add(_int_str(head))
                else:
                    add(_json(head, depth + 1))
                while type(tail) is Var:
                    if tail.ref is None:
                        raise Unencodable(f"{tail.name} is unbound (partial list)")
                    tail = tail.ref
                if type(tail) is Struct and tail.name == "." and len(tail.args) == 2:
                    cell = tail
                    continue
                if type(tail) is Atom and tail == "[]":
                    return "[" + ",".join(items) + "]"
                # An improper list [a|b]: store it as the compound '.'(a, b), rebuilt from
                # the innermost cell outwards so the encoding stays a plain compound.
                break
            return _improper_list_json(t, depth)
        return ("{" + _quote(t.name) + ":["
                + ",".join([_json(a, depth + 1) for a in args]) + "]}")
    if tt is list or tt is tuple:
        # Python lists (add_many tuples, imported ROS messages) get the same inlined element
        # kinds as cons lists above: a vector of floats costs a repr per element, no call.
        items = []
        add = items.append
        for head in t:
            th = type(head)
            if th is float and _NEG_INF < head < _INF:
                add(_float_repr(head))
            elif th is int and INT64_MIN <= head <= INT64_MAX:
                add(_int_str(head))
            else:
                add(_json(head, depth + 1))
        return "[" + ",".join(items) + "]"
    if tt is str:
        return "[]" if t == "[]" else _quote(t)
    if tt is bool:
        return '"true"' if t else '"false"'
    if isinstance(t, String):
        return _json(String(str(t)), depth)
    if isinstance(t, str):
        return _json(Atom(t), depth)
    if isinstance(t, int):
        return _json(int(t), depth)
    if isinstance(t, float):
        return _json(float(t), depth)
    raise Unencodable(f"{type(t).__name__} value {t!r} is not a term")


def _improper_list_json(t: Struct, depth: int) -> str:
    cells = []
    while type(t) is Struct and t.name == "." and len(t.args) == 2:
        cells.append(t.args[0])
        t = t.args[1]
        while type(t) is Var:
            t = _deref_or_raise(t)
    out = _json(t, depth + 1)
    for head in reversed(cells):
        out = '{".":[' + _json(head, depth + 1) + "," + out + "]}"
    return out


def decode(value: Any) -> Any:
    """Turn a stored column value back into the term :func:`encode` was given.

    >>> decode("cup1"), decode(3), decode('"hi"'), decode('{"$atom":"[x"}')
    (Atom('cup1'), 3, String('hi'), Atom('[x'))
    """
    tv = type(value)
    if tv is str:
        if value and value[0] in _JSON_STARTS:
            return _decode_top_json(value)
        return Atom(value)
    if tv is int or tv is float:
        return value
    if value is None:
        raise ValueError("NULL is not a stored term")
    if tv is bytes:
        return decode(value.decode("utf-8"))
    raise ValueError(f"cannot decode column value {value!r}")


def _decode_top_json(text: str) -> Any:
    data = json.loads(text)
    if type(data) is str:  # a top-level JSON string is an SLR string
        return String(data)
    return _from_json(data)


def _from_json(data: Any) -> Any:
    td = type(data)
    if td is str:
        return NIL if data == "[]" else Atom(data)
    if td is int or td is float:
        return data
    if td is list:
        return make_list([_from_json(x) for x in data])
    if td is dict and len(data) == 1:
        ((key, val),) = data.items()
        if type(val) is list:
            return Struct(Atom(key), tuple([_from_json(x) for x in val]))
        if type(val) is str:
            if key == "$string":
                return String(val)
            if key == "$atom":
                return NIL if val == "[]" else Atom(val)
            if key == "$int":
                return int(val)
    raise ValueError(f"not a stored term encoding: {data!r}")
