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
message ``'p/msg/T'``   TEXT, an object of fields   ``{"$type":"p/msg/T","x":1.0}``
``(x:1.0)``
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
* a *message term* -- a compound whose name holds a ``/`` and whose every argument is
  ``Key: Value`` with distinct atom keys not starting with ``$`` (how ROS messages reach
  SLR: ``'geometry_msgs/msg/Point'(x: 1.0, y: 2.0, z: 0.5)``) -- is the object
  ``{"$type":"geometry_msgs/msg/Point","x":1.0,"y":2.0,"z":0.5}`` (at the top level too),
  so that ``json_extract(arg1, '$.pose.position.x')`` reads a field by name

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
import json.scanner
import math
import os
import re
import sys
from itertools import chain
from operator import itemgetter
from operator import le as _le
from json.encoder import encode_basestring as _quote  # C-accelerated; keeps non-ASCII
from typing import Any, Callable

import orjson

from .terms import CONS, NIL, Atom, String, Struct, Var, make_list, to_python

# The optional C loops of the column encoder (csrc/, built by setup.py when a compiler is
# there): the same texts as the Python code below, which stays the reference and the
# fallback. SLR_SQL_NO_SPEEDUPS=1 turns them off (to measure or test the Python path).
_LOOPS_VERSION = 2  # the version of csrc/_slr_sql_speedups.c this module is written for
if os.environ.get("SLR_SQL_NO_SPEEDUPS"):
    _speedups = None
else:
    try:
        import _slr_sql_speedups as _speedups
    except ImportError:
        _speedups = None
    if getattr(_speedups, "LOOPS_VERSION", None) != _LOOPS_VERSION:
        _speedups = None  # a build older (or newer) than this source: not used
# Two of its loops walk a batch of events rather than terms: the shape checks of a bulk add
# (store/events.py's column path, kb.add_many's form of the batch) in one pass. None
# without the C loops or with a build from before them: the Python checks then decide,
# with the same outcome.
event_columns_loop: Callable[[list], tuple | None] | None = \
    getattr(_speedups, "event_columns", None)
event_form_loop: Callable[[list], str | None] | None = getattr(_speedups, "event_form", None)
# And one writes a stored event row's JSON message (slr_sql/viz/channels.py, an export's and
# the live view's per-row cost); None without it: the Python method writes the same bytes.
event_message_loop: Callable[[tuple, tuple, dict, Callable[[Any], str]], bytes] | None = \
    getattr(_speedups, "event_message", None)
# Not an encoding loop: a function SQLite calls wrapped so that what a signal handler raises
# in it is kept for the store (store/connection.py, register_functions); None without it:
# the store wraps the functions of one argument in Python.
signal_safe_loop: Callable[[Callable[..., Any], list], Callable[..., Any]] | None = \
    getattr(_speedups, "signal_safe", None)

__all__ = ["encode", "encode_column", "decode", "decode_answer", "encode_json", "Unencodable",
           "NullArgument",
           "INT64_MIN", "INT64_MAX", "field_pairs", "column_json", "decode_json", "load_json",
           "orjson_reads_exactly", "JSON_STARTS"]

INT64_MIN = -(2 ** 63)
INT64_MAX = 2 ** 63 - 1

# First characters that mark a TEXT column value as JSON rather than a bare atom.
JSON_STARTS = _JSON_STARTS = frozenset('[{"')


class NullArgument(ValueError):
    """A stored argument that is SQL NULL: no term has that stored form (the store never
    writes one; a row written by hand may hold one). A ValueError, as other column values
    that are no stored term; the facade turns it into :class:`~slr_sql.errors.NotAnEvent`
    naming the row."""


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
        text = _struct_json(term) if tt is Struct else _python_list_json(term)
        if text is None:
            _check_size(term)
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
    try:
        shown = repr(term)
    except ValueError:  # an integer inside with more digits than Python prints
        shown = "(holding an integer too long to print)"
    if len(shown) > 80:
        shown = shown[:80] + "..."
    raise Unencodable(f"{type(term).__name__} value {shown} is not a term")


# The C fast path for numbers. orjson writes a float as its shortest round-trip text (Ryu),
# the same digits as Python's repr (checked on millions of values in tests/test_fast_paths.py)
# about ten times faster; it may spell the exponent forms differently (0.00001 for 1e-05;
# 1e16 for 1e+16 before orjson 3.10 or so) and writes NaN and infinities as null. So its
# text is used only when it holds nothing but digits, signs, points, commas and brackets,
# and no "0.0000" (where repr would switch to an exponent); anything else (an atom, a big
# integer, 1e16, inf, a value orjson refuses) takes the Python path, which gives the stored
# text by definition. Only floats and ints of exactly those types are given to it: orjson
# also writes an Enum member (as its value) and list subclasses, which encode() refuses.
_dumps = orjson.dumps
_STRICT_INTEGER = orjson.OPT_STRICT_INTEGER  # integers beyond 53 bits are refused, not written
_NUMBER_BYTES = b"0123456789-.,[]"
_SMALL = b"0.0000"
_SMALL_TEXT = _SMALL.decode()
_NUMBER_KINDS = frozenset((float, int))


def _is_repr_text(data: bytes) -> bool:
    """True when orjson's ``data`` (numbers in arrays) is the text repr would give."""
    return not data.translate(None, _NUMBER_BYTES) and _SMALL not in data


def _numbers_json(items: Any) -> str | None:
    """The JSON array of a Python list or tuple holding only finite floats and integers of at
    most 53 bits, written in C; None for anything else, and for values whose text orjson
    spells differently from Python, so the caller takes its own path.

    >>> _numbers_json([0.5, 1, -2.25]), _numbers_json([1e16]), _numbers_json([0.5, "a"])
    ('[0.5,1,-2.25]', None, None)
    """
    # exact types: orjson also writes an Enum member (as its value) and list subclasses,
    # which the general encoder refuses
    if not _NUMBER_KINDS.issuperset(map(type, items)):
        return None
    try:
        data = _dumps(items, option=_STRICT_INTEGER)
    except TypeError:  # orjson.JSONEncodeError: an object it does not know, a big integer
        return None
    return data.decode() if _is_repr_text(data) else None


def _cons_list_json(cell: Struct) -> str | None:
    """The JSON array of a proper list of ``'.'/2`` cells whose elements are each a finite
    float, a 64-bit integer or a plain atom (not ``[]``); None for anything else (another
    element, a partial list, a variable in the spine), which the general encoder handles.
    One walk; a list of numbers is then written in C (:func:`_numbers_json`), any other
    with no call per element but the number's own text. The text is exactly the general
    encoder's. (The element tests are those of :func:`_flat_list_json`, for Python lists.)

    >>> from slr_sql.terms import make_list
    >>> _cons_list_json(make_list([0.5, 1, Atom("cup1")])), _cons_list_json(make_list([[]]))
    ('[0.5,1,"cup1"]', None)
    """
    heads = _cons_heads(cell)
    if heads is None:
        return None  # a partial list [a|b], a variable tail, another compound in the spine
    if _NUMBER_KINDS.issuperset(map(type, heads)):
        text = _numbers_json(heads)
        if text is not None:
            return text
    return _flat_list_json(heads)


def _cons_heads(cell: Struct) -> list | None:
    """The elements of a proper list of ``'.'/2`` cells, or None for anything else.

    >>> from slr_sql.terms import make_list
    >>> _cons_heads(make_list([1, 2.5])), _cons_heads(make_list([1], Atom("t")))
    ([1, 2.5], None)
    """
    heads: list = []
    add = heads.append
    try:
        while type(cell) is Struct:
            if cell.name is not CONS and cell.name != ".":
                return None
            head, cell = cell.args  # ValueError: a '.' with other than two arguments
            add(head)
    except ValueError:
        return None
    if cell is NIL or (type(cell) is Atom and cell == "[]"):
        return heads
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


def _python_list_json(items: list | tuple) -> str | None:
    """:func:`_flat_list_json`, with a list of numbers written in C first."""
    if items and type(items[0]) in _NUMBER_KINDS:
        text = _numbers_json(items)
        if text is not None:
            return text
    return _flat_list_json(items)


# The key orjson writes for a functor name, when it is the general encoder's (_quote), with
# the name as a plain str (orjson takes no str subclass as a key); names are few, so each is
# checked once.
_KEYS: dict[str, tuple[bytes, str] | None] = {}


def _compound_key(name: str) -> tuple[bytes, str] | None:
    try:
        return _KEYS[name]
    except KeyError:
        pass
    plain = str.__str__(name)
    key: tuple[bytes, str] | None = None
    if plain.isascii():
        try:
            prefix = _dumps({plain: 0})[:-2]
        except TypeError:
            prefix = b""
        if prefix.decode() == "{" + _quote(plain) + ":":
            key = (prefix, plain)
    if len(_KEYS) < 10_000:
        _KEYS[name] = key
    return key


def _numbers_compound_json(term: Struct) -> str | None:
    """The JSON object of a compound whose arguments are numbers or Python lists of numbers
    (a decoded ROS pose: ``pose([X,Y,Z],[QX,QY,QZ,QW])``), written in C; None otherwise.

    >>> _numbers_compound_json(Struct("pose", ([0.5, 1.0, 2.0], [0.0, 0.0, 0.0, 1.0])))
    '{"pose":[[0.5,1.0,2.0],[0.0,0.0,0.0,1.0]]}'
    """
    args = term.args
    if not args:
        return None
    for arg in args:  # exact types only (see _numbers_json)
        kind = type(arg)
        if (kind is list or kind is tuple) and _NUMBER_KINDS.issuperset(map(type, arg)):
            continue
        if kind is not float and kind is not int:
            return None
    key = _compound_key(term.name)
    if key is None:
        return None
    try:
        data = _dumps({key[1]: args}, option=_STRICT_INTEGER)
    except TypeError:
        return None
    return data.decode() if _is_repr_text(data[len(key[0]):-1]) else None



def _struct_json(term: Struct) -> str | None:
    """The fast text of a list or a compound of numbers, or None (see the two above)."""
    if term.name == ".":
        return _cons_list_json(term)
    return _numbers_compound_json(term)


# e and +: the exponents orjson writes (1e16 before 3.10 or so, 1e+16 after, 5e-324)
_COLUMN_BYTES = _NUMBER_BYTES + b"e+"
_SEQUENCE_KINDS = frozenset((list, tuple))


def _numbers_column_json(values: list) -> list | None:
    """:func:`_python_list_json` of every list of a column (flat lists of numbers): the whole
    column written by one orjson call and split into its rows, the text checked at C speed,
    and only the rows holding a value whose text orjson spells differently (``1e-05`` in a
    random stream, ``1e16``) written again by the Python path. None when a row needs the
    general encoder (a nested list, an atom, inf, a big integer).

    >>> _numbers_column_json([[0.5, 1], [], [1e-05, 2.0]])
    ['[0.5,1]', '[]', '[1e-05,2.0]']
    """
    # exact types only (see _numbers_json); the C loop checks a column in ~10 ns a number
    if _speedups is not None:
        if not _speedups.number_rows(values):
            return None
    elif not (_SEQUENCE_KINDS.issuperset(map(type, values))
              and _NUMBER_KINDS.issuperset(map(type, chain.from_iterable(values)))):
        return None
    try:
        data = _dumps(values, option=_STRICT_INTEGER)
    except TypeError:
        return None
    if _speedups is not None:
        texts = _speedups.split_rows(data, len(values))
        if texts is not None and None in texts:
            return _rows_redone(texts, values, _python_list_json)
        return texts
    if data.translate(None, _COLUMN_BYTES):
        return None  # null: inf or NaN (the rows are flat lists of numbers: checked above)
    rows = data[1:-1].decode().replace("],[", "]\n[")
    texts = rows.split("\n") if values else []
    for needle in (_SMALL_TEXT, "e"):
        at = rows.find(needle)
        row, counted = 0, 0
        while at >= 0:
            row += rows.count("\n", counted, at)  # rows before this one
            counted = at
            text = _flat_list_json(values[row])
            if text is None:
                return None
            texts[row] = text
            end = rows.find("\n", at)
            at = rows.find(needle, end) if end >= 0 else -1
    return texts


def _cons_column_json(values: list) -> list | None:
    """:func:`_cons_list_json` of every value of a column of ``'.'/2`` lists of numbers (parsed
    vectors), or None when one is not such a list. With the C loops, one walk collects every
    element into one flat list, written by one orjson call and cut back into rows; without
    them, the elements of each list are collected (:func:`_cons_heads`) and written as a
    column of Python lists.

    >>> from slr_sql.terms import make_list
    >>> _cons_column_json([make_list([0.5, 1]), make_list([]), make_list([1e-05])])
    ['[0.5,1]', '[]', '[1e-05]']
    """
    if _speedups is None:
        heads = list(map(_cons_heads, values))
        return None if None in heads else _numbers_column_json(heads)
    found = _speedups.cons_numbers(values, Struct, Atom, CONS, NIL)
    if found is None:
        return None
    flat, lengths = found
    try:
        data = _dumps(flat, option=_STRICT_INTEGER)
    except TypeError:  # an integer beyond 53 bits
        return None
    texts = _speedups.split_flat(data, lengths)
    if texts is not None and None in texts:
        return _rows_redone(texts, values, _cons_list_json)
    return texts


def _compound_column_json(values: list) -> list | None:
    """:func:`_numbers_compound_json` of every value of a column of compounds of one name
    whose arguments are lists of numbers (decoded ROS poses), with the C loops: the
    arguments of the whole column written by one orjson call and cut back into rows; None
    when a value is not such a compound, or without the C loops.

    >>> texts = _compound_column_json([Struct("pose", ([0.5, 1], [0, 0, 0, 1.0]))] * 2)
    >>> texts is None or texts == ['{"pose":[[0.5,1],[0,0,0,1.0]]}'] * 2
    True
    """
    if _speedups is None:
        return None
    name = values[0].name
    try:
        if not all(value.name == name and value.args for value in values):
            return None
    except AttributeError:  # (a Struct subclass without the slots)
        return None
    argss = [value.args for value in values]
    if not _speedups.number_rows(list(chain.from_iterable(argss))):
        return None
    key = _compound_key(name)
    if key is None:
        return None
    try:
        data = _dumps(argss, option=_STRICT_INTEGER)
    except TypeError:
        return None
    rows = _speedups.split_rows(data, len(values))
    if rows is None:
        return None
    head = key[0].decode()
    if not head.isascii():  # (the general encoder checks such names)
        return None
    texts = [None if row is None else f"{head}{row}}}" for row in rows]
    if None in texts:
        return _rows_redone(texts, values, _numbers_compound_json)
    return texts


def _rows_redone(texts: list, values: list, row_json: Any) -> list | None:
    """``texts`` with the rows the C splitter left out (None: orjson may spell one of their
    numbers differently from repr) written by ``row_json``, the Python path; None if one of
    them needs the general encoder."""
    row = texts.index(None)  # (few rows: found at C speed, not by a loop over all)
    while True:
        text = row_json(values[row])
        if text is None:
            return None
        texts[row] = text
        try:
            row = texts.index(None, row + 1)
        except ValueError:
            return texts


def encode_column(values: list) -> list:
    """:func:`encode` of every value of a column (the same argument of many events).
    A column of one kind is checked whole: plain ASCII atoms are their own text, 64-bit
    integers and floats other than NaN are themselves, flat lists of numbers and atoms go
    straight to their encoder; any other column is encoded value by value. Raises
    :class:`Unencodable` as :func:`encode` does.

    >>> encode_column([Atom("cup1"), Atom("cup2")]), encode_column([1.5, 2.0]), encode_column([Atom("[x")])
    (['cup1', 'cup2'], [1.5, 2.0], ['{"$atom":"[x"}'])
    """
    if type(values) is not list:
        values = list(values)
    kinds = set(map(type, values))
    if len(kinds) == 1:
        (kind,) = kinds
        if kind is Atom or kind is str:
            # a column of names repeats few atoms: check (and copy to plain str) each once
            distinct = dict.fromkeys(values)
            try:
                if all(map(str.isascii, distinct)) \
                        and _JSON_STARTS.isdisjoint(map(_first_char, distinct)):
                    if len(distinct) * 2 > len(values):
                        return list(map(str, values))
                    texts = {atom: str(atom) for atom in distinct}
                    return list(map(texts.__getitem__, values))
            except IndexError:  # an empty atom: encoded one by one
                pass
        elif kind is float:
            if all(map(_le, values, values)):  # False only at a NaN
                return values
        elif kind is int:
            if INT64_MIN <= min(values) and max(values) <= INT64_MAX:
                return values
        elif kind is list or kind is tuple:  # vectors: the fast path, no dispatch
            texts = _numbers_column_json(values)
            if texts is not None:
                return texts
            return _completed(list(map(_python_list_json, values)), values)
        elif kind is Struct:  # parsed lists, and compounds of numbers (poses)
            if values[0].name == ".":
                texts = _cons_column_json(values)
            else:
                texts = _compound_column_json(values)
            if texts is not None:
                return texts
            return _completed(list(map(_struct_json, values)), values)
    return list(map(encode, values))


def _completed(texts: list, values: list) -> list:
    """``texts`` (a fast path's texts of ``values``, None where it declined) with :func:`encode`
    of the values it declined or whose text is not ASCII (checked for lone surrogates)."""
    if None in texts or not all(map(str.isascii, texts)):
        return [encode(value) if text is None or not text.isascii() else text
                for text, value in zip(texts, values)]
    return texts


def encode_json(term: Any) -> str:
    """The JSON text of a term as it appears *inside* a stored list or compound.

    >>> encode_json(Atom("a")), encode_json(String("a")), encode_json(1.0)
    ('"a"', '{"$string":"a"}', '1.0')
    """
    _check_size(term)
    text = _json(term, 0)
    return text if text.isascii() else _check_text(text)


# Nodes (compounds, list cells, values) a stored term may have, written out as a tree: a
# term that shares subterms (X1 = f(X0, X0), X2 = f(X1, X1), ...) is small in memory but
# exponential as text, and is refused before its text is built.
MAX_STORED_NODES = 10_000_000


def _check_size(term: Any) -> None:
    """Unencodable when ``term`` written out has more than MAX_STORED_NODES nodes; linear
    in its distinct compounds (each shared one is sized once)."""
    sizes: dict[int, int] = {}
    todo: list = [(term, False)]
    done: list = []
    while todo:
        t, leaving = todo.pop()
        if leaving:
            k = len(t.args) if type(t) is Struct else len(t)
            n = 1 + sum(done[len(done) - k:]) if k else 1
            del done[len(done) - k:]
            sizes[id(t)] = n
            if n > MAX_STORED_NODES:
                raise Unencodable(f"term too large to be stored (more than "
                                  f"{MAX_STORED_NODES} nodes written out)")
            done.append(n)
            continue
        while type(t) is Var and t.ref is not None:
            t = t.ref
        tt = type(t)
        if tt is Struct or tt is list or tt is tuple:
            known = sizes.get(id(t))
            if known is not None:
                done.append(known)
                continue
            sizes[id(t)] = MAX_STORED_NODES + 1   # met again inside itself: cyclic
            todo.append((t, True))
            todo.extend((a, False) for a in reversed(t.args if tt is Struct else t))
        else:
            done.append(1)


def column_json(value: Any) -> str:
    """A stored column value as the JSON of its term *inside* a list or compound (what
    :func:`encode_json` gives for the decoded term), without decoding lists and compounds:
    they are JSON already. Live views and exports write events with it.

    >>> column_json("cup1"), column_json(3), column_json('[0.5,1.0]'), column_json('"hi"')
    ('"cup1"', '3', '[0.5,1.0]', '{"$string":"hi"}')
    """
    tv = type(value)
    if tv is str:
        c = value[:1]
        if c == "[" or (c == "{" and not value.startswith('{"$atom":"')):
            return value
        if c and c != "{" and c != '"':
            return _quote(value)
    elif tv is int:
        return str(value)
    elif tv is float and _NEG_INF < value < _INF:
        return _float_repr(value)
    return encode_json(decode(value))


def decode_json(data: Any) -> Any:
    """The term of a value parsed from the JSON :func:`encode_json` / :func:`column_json`
    wrote (``json.loads`` of it).

    >>> str(decode_json({"pose": [[1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0]]}))
    'pose([1.0,2.0,3.0],[0.0,0.0,0.0,1.0])'
    """
    return term_from_json(data)


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
        if "/" in t.name:
            fields = field_pairs(t)
            if fields is not None:
                return ('{"$type":' + _quote(t.name) + "".join(
                    ["," + _quote(key) + ":" + _json(value, depth + 1) for key, value in fields])
                    + "}")
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


def field_pairs(t: Struct) -> list[tuple[str, Any]] | None:
    """The fields of a message term -- a compound whose every argument is ``Key: Value``
    with distinct atom keys not starting with ``$`` -- as ``[(key, value)]``; else None.
    A message term whose name holds a ``/`` (a ROS message type, ``pkg/msg/Name``) is stored
    as a JSON object ``{"$type": Name, Key: Value, ...}``, so that SQL reads its fields by
    name (``json_extract(arg1, '$.pose.position.x')``).

    >>> field_pairs(Struct("geometry_msgs/msg/Point", (Struct(":", (Atom("x"), 1.0)),)))
    [('x', 1.0)]
    >>> field_pairs(Struct("f", (1,))) is None
    True
    """
    args = t.args
    if not args:
        return None
    out = []
    seen = set()
    for arg in args:
        while type(arg) is Var and arg.ref is not None:
            arg = arg.ref
        if type(arg) is not Struct or arg.name != ":" or len(arg.args) != 2:
            return None
        key, value = arg.args
        while type(key) is Var and key.ref is not None:
            key = key.ref
        if type(key) is not Atom or key.startswith("$") or key in seen:
            return None
        seen.add(key)
        out.append((str(key), value))
    return out


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
        raise NullArgument("NULL is not a stored term")
    if tv is bytes:
        return decode(value.decode("utf-8"))
    raise ValueError(f"cannot decode column value {value!r}")


def decode_answer(value: Any) -> Any:
    """A stored column value as an answer shows it: ``to_python(decode(value))``, without
    building the term first when the value is a list of numbers (a position, a pose's
    vector), the common argument of a robot's events.

    >>> decode_answer("[0.5,1,2.0]"), decode_answer("cup1"), decode_answer('"hi"')
    ([0.5, 1, 2.0], Atom('cup1'), 'hi')
    """
    tv = type(value)
    if tv is str:
        if not value or value[0] not in _JSON_STARTS:
            return Atom(value)
        if value[0] == "[":
            try:
                data = load_json(value)
            except ValueError:
                return to_python(decode(value))   # (not stored JSON: decode says so)
            for x in data:
                tx = type(x)
                if tx is not float and tx is not int:
                    break
            else:
                return data
            return to_python(term_from_json(data))
        return to_python(_decode_top_json(value))
    if tv is int or tv is float:
        return value
    return to_python(decode(value))


# an integer of 19 digits or more: orjson keeps integers exact only from -2**63 to 2**64 - 1
# and reads a longer one as a float, silently; the json module reads it exactly. The store's
# encoder writes such integers as {"$int": ...}, but text written by another program (plain
# sqlite3, `slr sql --write`) may hold one bare. Fractions do not count: orjson rounds a
# fraction of any length as the json module does, and the store writes fractions of 19
# digits and more (repr(0.00014271126099703728): three zeros, then 17 digits). A first
# plain search of 19 digits in a row keeps the common text on the fastest check; only text
# that has them is searched again for a run that is no fraction (not after a point).
_NINETEEN_DIGITS = re.compile("[0-9]{19}")
_NINETEEN_DIGITS_NOT_A_FRACTION = re.compile(r"(?<![.0-9])[0-9]{19}")
_DECIMAL_INTEGER = re.compile(r"-?[0-9]+\Z")   # the digits of {"$int": ...}


def orjson_reads_exactly(text: str) -> bool:
    """False when ``text`` may hold an integer that orjson would read as a float (one of 19
    digits or more), which only the json module reads exactly.

    >>> orjson_reads_exactly('[1, 0.5]'), orjson_reads_exactly('[18446744073709551617]')
    (True, False)
    >>> orjson_reads_exactly('[0.00014271126099703728]')
    True
    """
    return (_NINETEEN_DIGITS.search(text) is None
            or _NINETEEN_DIGITS_NOT_A_FRACTION.search(text) is None)


def load_json(text: str) -> Any:
    """Stored JSON text parsed: by orjson (~4x faster than the json module), or by the json
    module when orjson refuses it (a lone surrogate escaped, a nesting past its limit,
    1e400) or might read an integer as a float (:func:`orjson_reads_exactly`); anything
    that is not JSON raises ``ValueError``.

    >>> load_json('[0.5, 1, {"$atom": "[x"}]'), load_json('["\\ud800"]')
    ([0.5, 1, {'$atom': '[x'}], ['\ud800'])
    >>> load_json('[-9223372036854775809]')
    [-9223372036854775809]
    """
    if (_NINETEEN_DIGITS.search(text) is None
            or _NINETEEN_DIGITS_NOT_A_FRACTION.search(text) is None):   # (inlined: hot)
        try:
            return orjson.loads(text)
        except orjson.JSONDecodeError:
            pass
    return json.loads(text)


def _decode_top_json(text: str) -> Any:
    data = load_json(text)
    if type(data) is str:  # a top-level JSON string is an SLR string
        return String(data)
    return term_from_json(data)


def term_from_json(data: Any) -> Any:
    """The term of a parsed JSON value in the column encoding (``json.loads`` of a stored
    compound's text): the inverse of :func:`encode_json` after parsing.

    >>> term_from_json({"f": ["a", 1]})
    Struct('f', (Atom('a'), 1))
    """
    td = type(data)
    if td is str:
        return NIL if data == "[]" else Atom(data)
    if td is int or td is float:
        return data
    if td is list:
        return make_list([term_from_json(x) for x in data])
    if td is dict and "$type" in data:
        name = data["$type"]
        if type(name) is str and len(data) > 1:
            return Struct(Atom(name), tuple([
                Struct(":", (Atom(k), term_from_json(v))) for k, v in data.items() if k != "$type"]))
    if td is dict and len(data) == 1:
        ((key, val),) = data.items()
        if type(val) is list:
            return Struct(Atom(key), tuple([term_from_json(x) for x in val]))
        if type(val) is str:
            if key == "$string":
                return String(val)
            if key == "$atom":
                return NIL if val == "[]" else Atom(val)
            if key == "$int":
                if not _DECIMAL_INTEGER.match(val):   # (int() would take "1_000", " 7 ")
                    raise ValueError(f'{{"$int": {json.dumps(val)}}}: $int must be decimal digits')
                return int(val)
    raise ValueError(f"not a stored term encoding: {data!r}")
