"""The JSON encoding of SLR terms on the wire (server and client, both directions).

One value of an answer, of ``args``, or of an event argument is one JSON value:

=============================  ===================================  =========================
term (Python value)            JSON                                 example
=============================  ===================================  =========================
atom (``Atom``; ``str`` in     a JSON string                        ``"cup1"``, ``"[]"``
arguments)
string (``String``; ``str``    ``{"$string": text}``                ``{"$string":"hi"}``
in answers)
integer, 64-bit                a JSON integer (no fraction)         ``42``
integer beyond 64 bits         ``{"$int": "digits"}``               ``{"$int":"-123..."}``
float, finite                  a JSON number that always has a      ``2.0``, ``1e22``,
                               ``.`` or an exponent                 ``-0.0``
float +inf / -inf / NaN        ``{"$float": "inf" | "-inf" |        ``{"$float":"nan"}``
                               "nan"}``
proper list                    a JSON array                         ``[0.4,0.1,0.9]``, ``[]``
compound ``f(a, 1)``           an object with one key, the name,    ``{"f":["a",1]}``
(``Struct``)                   whose value is the argument array
partial list ``[a|T]``         the compound ``'.'(a, T)``           ``{".":["a",{"$var":"T"}]}``
unbound variable (``Var``)     ``{"$var": name}``                   ``{"$var":"X"}``
=============================  ===================================  =========================

Rules that make the encoding exact and reversible:

* A compound's value is always an *array*; the reserved keys ``$string``, ``$int``,
  ``$float``, ``$var`` (and ``$atom``, read only) always have a *string* value, so a
  compound named ``'$string'`` (``{"$string":[..]}``) never clashes with a string.
* Floats keep their type: Python writes ``1.0`` (never ``1``), so ``1`` and ``1.0`` — which
  SLR keeps apart (``1 \\= 1.0``) — stay apart. A client whose JSON library cannot write
  ``1.0`` may send ``{"$float": 1}``. Non-finite floats never appear as JSON numbers (JSON has
  none); ``NaN``/``Infinity`` literals are refused on input, ``1e999`` is read as +inf.
* The variables of one decoded value (one answer, one ``args`` object, one error term) that
  carry the same name are the same :class:`~slr_sql.Var`, so ``X = Y`` comes back shared.
* Reading also accepts ``{"$atom": text}`` and ``{"$int": "digits"}`` for any integer, the
  forms the store's column encoding writes, so a value copied from ``slr sql`` output can be
  sent back. ``true``, ``false`` and ``null`` are not terms (write the atom as ``"true"``).
* Python ``str`` means an atom in what a client sends (as in ``kb.add_event``) and a string in
  answers (as ``kb.query`` returns strings); :class:`~slr_sql.Atom` and :class:`~slr_sql.String`
  always mean themselves. Decoding gives ``Atom`` and ``String`` (``str`` in answers).
* Nesting deeper than :data:`MAX_DEPTH` levels is refused (:class:`TermError`) both ways.

>>> from slr_sql import Atom, String, Struct, Var
>>> encode_term(Struct("f", (Atom("a"), String("s"), [1, 2.0], float("inf"))))
{'f': ['a', {'$string': 's'}, [1, 2.0], {'$float': 'inf'}]}
>>> decode_term({'f': ['a', {'$string': 's'}, [1, 2.0], {'$float': 'inf'}]})
Struct('f', (Atom('a'), String('s'), [1, 2.0], inf))
"""
from __future__ import annotations

import json
import math
import re
from decimal import Decimal
from typing import Any

import orjson

from slr_sql import Atom, SLRError, String, Struct, Var
from slr_sql.terms import MAX_INTEGER_BITS, int_from_text, int_text

__all__ = ["TermError", "encode_term", "decode_term", "encode_arguments", "decode_arguments",
           "encode_answers", "decode_answers",
           "encode_args", "decode_args", "encode_plain", "decode_plain", "dumps", "loads",
           "MAX_DEPTH"]

MAX_DEPTH = 400          # nesting levels of a term (lists and compounds) that may travel
INT64_MIN, INT64_MAX = -(2 ** 63), 2 ** 63 - 1
_SPECIAL_FLOATS = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}
_INTEGER = re.compile(r"-?[0-9]+\Z")


class TermError(SLRError):
    """A JSON value that is not a term in the wire encoding, or a Python value that cannot be
    sent (``where`` says which part: ``args.O[2]``)."""

    def __init__(self, message: str, where: str = ""):
        self.where = where
        if len(where) > 60:  # a deep path: its start and its end say enough
            where = f"{where[:30]}...{where[-20:]}"
        super().__init__(f"{where}: {message}" if where else message)


# -- encoding ----------------------------------------------------------------------------------

def encode_term(value: Any, *, plain_str: str = "atom", _where: str = "") -> Any:
    """A term (Python value) as a JSON-ready value. ``plain_str`` says what a plain ``str``
    is: ``"atom"`` (what callers send, as in ``kb.add_event``) or ``"string"`` (answers).

    >>> encode_term(["cup1", 1, 0.5, -0.0]), encode_term("hi", plain_str="string")
    (['cup1', 1, 0.5, -0.0], {'$string': 'hi'})
    """
    try:
        return _encode_fast(value, plain_str == "atom", 0)
    except _Unusual:
        return _encode(value, plain_str, _where, 0)


class _Unusual(Exception):
    """The fast paths met a value they leave to the complete ones (which also say where)."""


def _encode_fast(value: Any, str_is_atom: bool, depth: int) -> Any:
    """The common values only, with no bookkeeping: ingest spends its time here."""
    tv = type(value)
    if tv is float:
        if value - value == 0.0:     # finite: inf - inf and nan - nan are nan
            return value
        raise _Unusual
    if tv is Atom:
        return value                 # json writes a str subclass as a string
    if tv is int:
        if INT64_MIN <= value <= INT64_MAX:
            return value
        raise _Unusual
    if tv is str:
        return value if str_is_atom else {"$string": value}
    if depth >= MAX_DEPTH:
        raise _Unusual
    if tv is list or tv is tuple:
        return [_encode_fast(v, str_is_atom, depth + 1) for v in value]
    if tv is Struct:
        return {str(value.name): [_encode_fast(v, str_is_atom, depth + 1) for v in value.args]}
    if tv is String:
        return {"$string": str(value)}
    raise _Unusual


def _encode(value: Any, plain_str: str, where: str, depth: int) -> Any:
    """Every value, keeping the path of each part (``args.O[2]``) for error messages."""
    tv = type(value)
    if tv is Atom:
        return str(value)
    if tv is str:
        return value if plain_str == "atom" else {"$string": value}
    if tv is String:
        return {"$string": str(value)}
    if tv is int:
        if INT64_MIN <= value <= INT64_MAX:
            return value
        return {"$int": int_text(value)}   # (str() refuses more than 4,300 digits)
    if tv is float:
        if math.isfinite(value):
            return value
        return {"$float": "nan" if value != value else ("inf" if value > 0 else "-inf")}
    if depth >= MAX_DEPTH:
        raise TermError(f"term nested deeper than {MAX_DEPTH} levels", where)
    if tv is list or tv is tuple:
        return [_encode(v, plain_str, f"{where}[{i}]", depth + 1) for i, v in enumerate(value)]
    if tv is Struct:
        name = str(value.name)
        return {name: [_encode(v, plain_str, f"{where}.{name}[{i}]", depth + 1)
                       for i, v in enumerate(value.args)]}
    if tv is Var:
        if value.ref is not None:   # a bound variable stands for its value
            return _encode(value.ref, plain_str, where, depth + 1)
        return {"$var": value.name}
    if tv is bool:
        return "true" if value else "false"
    # subclasses of the basic types (a str subclass other than Atom/String, an IntEnum, ...)
    if isinstance(value, String):
        return {"$string": str(value)}
    if isinstance(value, Atom):
        return str(value)
    if isinstance(value, str):
        return _encode(str(value), plain_str, where, depth)
    if isinstance(value, int):
        return _encode(int(value), plain_str, where, depth)
    if isinstance(value, float):
        return _encode(float(value), plain_str, where, depth)
    raise TermError(f"cannot send {value!r} ({tv.__name__}) as an SLR term", where)


def encode_arguments(args: list, where: str = "args") -> list:
    """The arguments of an event (a list of terms; ``str`` is an atom) -> JSON-ready.

    >>> encode_arguments(["cup1", [0.4, 0.1]])
    ['cup1', [0.4, 0.1]]
    """
    try:
        return _encode_fast(args, True, -1)
    except _Unusual:
        return [_encode(a, "atom", f"{where}[{i}]", 0) for i, a in enumerate(args)]


def encode_answers(answers: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Answers as ``kb.query`` returns them (strings as ``str``) -> JSON-ready answers.

    >>> encode_answers([{"X": "text", "Y": Atom("a")}]) == [{"X": {"$string": "text"}, "Y": "a"}]
    True
    """
    return [{name: encode_term(value, plain_str="string", _where=name)
             for name, value in answer.items()} for answer in answers]


def encode_args(args: dict[str, Any] | None) -> dict[str, Any] | None:
    """``args`` of a query (``str`` is an atom, as for ``kb.query``) -> JSON-ready.

    >>> encode_args({"O": "cup1", "L": [0.4, 0.1], "S": String("hi")})
    {'O': 'cup1', 'L': [0.4, 0.1], 'S': {'$string': 'hi'}}
    """
    if args is None:
        return None
    if not isinstance(args, dict):
        raise TermError("args must be a dict of variable name -> value")
    return {str(name): encode_term(value, _where=f"args.{name}") for name, value in args.items()}


# -- decoding ----------------------------------------------------------------------------------

def decode_term(obj: Any, *, strings: type = String, variables: dict | None = None,
                _where: str = "") -> Any:
    """A JSON value in the wire encoding -> the term as a Python value. ``strings`` is the
    type strings decode to (``String``, or ``str`` for answers); ``variables`` maps names to
    the :class:`Var` objects already made for this value (shared across one answer).

    >>> decode_term({"g": [{"$var": "X"}, {"$var": "X"}]})
    Struct('g', (Var('X'), Var('X')))
    """
    if variables is None:
        variables = {}
    try:
        return _decode_fast(obj, strings, variables, 0)
    except (_Unusual, TermError):
        return _decode(obj, strings, variables, _where, 0)


def decode_arguments(objs: list, where: str = "args") -> list:
    """The JSON arguments of an event -> terms (their variables shared).

    >>> decode_arguments(["cup1", {"$string": "s"}])
    [Atom('cup1'), String('s')]
    """
    variables: dict = {}
    try:
        return _decode_fast(objs, String, variables, -1)
    except (_Unusual, TermError):
        return [_decode(o, String, variables, f"{where}[{i}]", 0) for i, o in enumerate(objs)]


def _decode_fast(obj: Any, strings: type, variables: dict, depth: int) -> Any:
    """Well-formed values, with no bookkeeping; anything wrong goes to :func:`_decode`."""
    to = type(obj)
    if to is str:
        return Atom(obj)
    if to is float or to is int:
        return obj
    if depth >= MAX_DEPTH:
        raise _Unusual
    if to is list:
        return [_decode_fast(v, strings, variables, depth + 1) for v in obj]
    if to is dict and len(obj) == 1:
        for key, value in obj.items():
            if type(value) is list:
                return Struct(key, [_decode_fast(v, strings, variables, depth + 1)
                                    for v in value])
            return _decode_special(key, value, strings, variables, "")
    raise _Unusual


def _decode(obj: Any, strings: type, variables: dict, where: str, depth: int) -> Any:
    """Every value, keeping the path of each part for error messages."""
    to = type(obj)
    if to is str:
        return Atom(obj)
    if to is int or to is float:
        return obj
    if depth >= MAX_DEPTH:
        raise TermError(f"term nested deeper than {MAX_DEPTH} levels", where)
    if to is list:
        return [_decode(v, strings, variables, f"{where}[{i}]", depth + 1)
                for i, v in enumerate(obj)]
    if to is dict:
        if len(obj) != 1:
            raise TermError("an object must have exactly one key: a compound {\"name\": [args]} "
                            "or one of $string, $int, $float, $var, $atom", where)
        (key, value), = obj.items()
        if type(value) is list:
            return Struct(key, [_decode(v, strings, variables, f"{where}.{key}[{i}]", depth + 1)
                                for i, v in enumerate(value)])
        return _decode_special(key, value, strings, variables, where)
    if obj is None or to is bool:
        raise TermError(f"{json.dumps(obj)} is not a term (an atom is a JSON string: "
                        f"\"{json.dumps(obj)}\")", where)
    raise TermError(f"{obj!r} is not a term", where)


def _decode_special(key: str, value: Any, strings: type, variables: dict | None,
                    where: str) -> Any:
    if key == "$float":
        if type(value) is str and value in _SPECIAL_FLOATS:
            return _SPECIAL_FLOATS[value]
        if type(value) in (int, float):
            try:
                return float(value)
            except OverflowError:
                raise TermError("$float: number out of range", where) from None
        raise TermError('$float must be a number or one of "inf", "-inf", "nan"', where)
    if type(value) is not str:
        raise TermError(f"{key} needs a string value, or a compound an array of arguments", where)
    if key == "$string":
        return strings(value)
    if key == "$atom":
        return Atom(value)
    if key == "$int":
        if not _INTEGER.match(value):
            raise TermError(f"$int must be decimal digits, not {value!r}", where)
        # (the length first: converting a megabyte of digits would hold the request)
        number = (int_from_text(value) if len(value) <= MAX_INTEGER_BITS * 0.302 + 2
                  else None)
        if number is None or number.bit_length() > MAX_INTEGER_BITS:
            raise TermError(f"$int: integer too large (more than {MAX_INTEGER_BITS} bits)",
                            where)
        return number
    if key == "$var":
        if variables is None:
            return Var(value)
        var = variables.get(value)
        if var is None:
            var = variables[value] = Var(value)
        return var
    raise TermError(f"unknown tag {key!r} (a compound's value must be an array)", where)


def decode_answers(objs: Any) -> list[dict[str, Any]]:
    """JSON answers -> the list ``kb.query`` would return (strings as ``str``).

    >>> decode_answers([{"X": {"$string": "text"}, "Y": "a"}])
    [{'X': 'text', 'Y': Atom('a')}]
    """
    if type(objs) is not list:
        raise TermError("answers must be a list")
    out = []
    for answer in objs:
        if type(answer) is not dict:
            raise TermError("an answer must be an object")
        variables: dict = {}
        out.append({name: decode_term(value, strings=str, variables=variables, _where=name)
                    for name, value in answer.items()})
    return out


def decode_args(obj: Any) -> dict[str, Any] | None:
    """The ``args`` object of a request -> ``{name: term}`` (strings as ``String``).

    >>> decode_args({"O": "cup1", "S": {"$string": "hi"}, "F": {"f": [1, {"$var": "X"}]}})
    {'O': Atom('cup1'), 'S': String('hi'), 'F': Struct('f', (1, Var('X')))}
    """
    if obj is None:
        return None
    if type(obj) is not dict:
        raise TermError("args must be an object of variable name -> term")
    variables: dict = {}
    return {name: decode_term(value, variables=variables, _where=f"args.{name}")
            for name, value in obj.items()}


# -- plain JSON values (stats, SQL rows, buffer descriptions) ----------------------------------

def encode_plain(value: Any) -> Any:
    """Numbers, text, None, bytes, lists/tuples/dicts of them -> JSON-ready; non-finite
    floats as ``{"$float": ...}``, bytes as ``{"$bytes": hex}`` (SQL blobs).

    >>> encode_plain({"now": float("-inf"), "rows": [(1, "a", None, b"\\x01")]})
    {'now': {'$float': '-inf'}, 'rows': [[1, 'a', None, {'$bytes': '01'}]]}
    >>> from decimal import Decimal
    >>> encode_plain([Decimal("190"), Decimal("10.50"), Decimal("NaN")])
    [190, 10.5, {'$float': 'nan'}]
    """
    tv = type(value)
    if value is None or tv is bool or tv is int or tv is str:
        return value
    if tv is float:
        return value if math.isfinite(value) else encode_term(value)
    if isinstance(value, (bytes, bytearray, memoryview)):
        return {"$bytes": bytes(value).hex()}
    if isinstance(value, dict):
        return {str(k): encode_plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode_plain(v) for v in value]
    if isinstance(value, str):    # str/int/float subclasses (Atom, IntEnum, ...)
        return str(value)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return encode_plain(float(value))
    if isinstance(value, Decimal):
        # a PostgreSQL NUMERIC (sum or avg of an integer column in /sql): the number, as
        # SQLite gives its sum (an integer when written without fractional digits); it
        # travelled as its text ("190"), a string where the same statement on a store file
        # or on the database directly gives a number
        if value.is_finite() and value.as_tuple().exponent >= 0:   # type: ignore[operator]
            return int(value)
        return encode_plain(float(value))
    return str(value)


def decode_plain(obj: Any) -> Any:
    r"""The inverse of :func:`encode_plain` (tuples come back as lists).

    >>> obj = encode_plain({"a": (1, float("inf")), "b": b"\x00\x01"}); obj
    {'a': [1, {'$float': 'inf'}], 'b': {'$bytes': '0001'}}
    >>> decode_plain(obj)
    {'a': [1, inf], 'b': b'\x00\x01'}
    """
    if type(obj) is list:
        return [decode_plain(v) for v in obj]
    if type(obj) is dict:
        if len(obj) == 1:
            (key, value), = obj.items()
            if key == "$float" and value in _SPECIAL_FLOATS:
                return _SPECIAL_FLOATS[value]
            if key == "$bytes" and type(value) is str:
                try:
                    return bytes.fromhex(value)
                except ValueError:
                    pass
        return {k: decode_plain(v) for k, v in obj.items()}
    return obj


# -- bytes <-> JSON ----------------------------------------------------------------------------

_SURROGATE_ESCAPE = re.compile(rb"\\u[dD][89a-fA-F]")


def _refuse_constant(name: str) -> Any:
    raise ValueError(f"{name} is not JSON (a non-finite float is {{\"$float\": \"inf\"}})")


def dumps(obj: Any) -> bytes:
    """Compact UTF-8 JSON; never writes NaN/Infinity (they are tagged by the encoders).

    orjson writes it (in C); its text differs from Python's ``json`` only in how an
    exponent is spelled (``1e16``, ``1e-5`` written ``0.00001``; the same shortest
    round-trip digits, read back as the same float). What orjson does not write the Python
    way goes through ``json``: output holding ``null`` (orjson writes a stray NaN as
    ``null``; ``json`` refuses it), integers beyond 64 bits, lone surrogates, and values
    orjson does not know.

    >>> dumps({"a": [1, 2.0, "é"]})
    b'{"a":[1,2.0,"\\xc3\\xa9"]}'
    """
    try:
        data = orjson.dumps(obj)
    except TypeError:       # orjson.JSONEncodeError is a TypeError
        pass
    else:
        if b"null" not in data:
            return data
    return json.dumps(obj, ensure_ascii=False, allow_nan=False,
                      separators=(",", ":")).encode("utf-8", "surrogatepass")


# What orjson reads differently from Python's json is found on the bytes, in C: one
# translate keeps the brackets and the points, writes every digit as 0 and everything else
# as a space; an integer literal (after a space or a bracket, not a point) beyond 64 bits,
# which orjson reads as a float and json keeps exact, has 19 digits or more.
_SKELETON = bytes(b if b in b"[]{}." else 48 if 48 <= b <= 57 else 32 for b in range(256))
_LONG_INTEGERS = (b" " + b"0" * 19, b"[" + b"0" * 19)
_FAST_DEPTH = 32


def _orjson_reads_it(raw: bytes) -> bool:
    """True when orjson reads ``raw`` as Python's json does: no integer of 19 digits (one
    beyond 64 bits, which orjson turns into a float: json keeps it exact) and brackets
    nested at most :data:`_FAST_DEPTH` levels (orjson reads any depth; a body nested too
    deeply must be refused). The nesting is measured by removing the innermost pairs
    level by level; a bracket inside a string can only make this say False (then Python's
    json reads it: slower, same result)."""
    if raw.count(b"[") + raw.count(b"{") <= _FAST_DEPTH and len(raw) < 19:
        return True
    skeleton = b" " + raw.translate(_SKELETON)
    if _LONG_INTEGERS[0] in skeleton or _LONG_INTEGERS[1] in skeleton:
        return False
    brackets = skeleton.translate(None, b" 0.")
    for _ in range(_FAST_DEPTH):
        shorter = brackets.replace(b"[]", b"").replace(b"{}", b"")
        if not shorter:
            return True
        if len(shorter) == len(brackets):
            return False
        brackets = shorter
    return False


def loads(data: bytes | str) -> Any:
    """Strict JSON: UTF-8, no NaN/Infinity literals, and no lone surrogates (``"\\ud800"``,
    which no store can keep). Raises ValueError with a short reason.

    orjson reads it (in C) when it reads it as Python's ``json`` would
    (:func:`_orjson_reads_it`); a body it refuses (``1e999``, which is +inf here, a lone
    surrogate, bad JSON: the reason comes from Python's ``json``) is read by Python's
    ``json``.

    >>> loads(b'{"a": 1e999}')
    {'a': inf}
    """
    if isinstance(data, (bytes, bytearray)):
        data = bytes(data)
        raw = data
    else:
        raw = data.encode("utf-8", "surrogatepass")
    if _orjson_reads_it(raw):
        try:
            return orjson.loads(raw)
        except orjson.JSONDecodeError:
            pass            # the reason (or the reading orjson does not give) comes below
    text = data.decode("utf-8") if isinstance(data, bytes) else data
    check = _SURROGATE_ESCAPE.search(raw) is not None
    try:
        obj = json.loads(text, parse_constant=_refuse_constant)
    except RecursionError:
        raise ValueError("JSON nested too deeply") from None
    if check:
        _check_unicode(obj)
    return obj


def _check_unicode(obj: Any) -> None:
    stack = [obj]
    while stack:
        x = stack.pop()
        if type(x) is str:
            try:
                x.encode("utf-8")
            except UnicodeEncodeError:
                raise ValueError("a JSON string holds a lone surrogate (\\ud800-\\udfff), "
                                 "which is not a Unicode character") from None
        elif type(x) is list:
            stack.extend(x)
        elif type(x) is dict:
            stack.extend(x.keys())
            stack.extend(x.values())
