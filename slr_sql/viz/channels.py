"""The channels of a store, shared by the live Foxglove view and MCAP export.

An event row as stored (:meth:`slr_sql.store.EventStore.raw_rows`) becomes one JSON message
without decoding its terms: each argument is written as it appears inside a stored list or
compound (:func:`slr_sql.encoding.column_json`) -- numbers as numbers, atoms as strings,
lists as arrays, compounds as ``{"name": [args]}``, message terms as objects of their
fields, strings as ``{"$string": text}`` -- so that a message reads naturally in Foxglove's
panels (``/seg/2.arg2[0]`` is a number to plot) *and* gives the exact term back
(:func:`event_from_message`), which is how ``slr ros import`` reads an export.

>>> ch = event_channel("seg", 2)
>>> ch.topic, ch.schema_name
('/seg/2', 'slr.seg/2')
>>> ch.message(("cup1", "[0.4,0.1]", 1.5, 2.0, 2.5, 7))
b'{"arg1":"cup1","arg2":[0.4,0.1],"start":1.5,"end":2.0,"arrival":2.5}'
>>> event_from_message(ch.name, ch.arity, b'{"arg1":"cup1","arg2":[0.4,0.1],"start":1.5,"end":2.0,"arrival":2.5}')
('seg', (Atom('cup1'), Struct('.', (0.4, Struct('.', (0.1, Atom('[]')))))), 1.5, 2.0)
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any

from .. import encoding
from ..encoding import column_json, decode, decode_json
from ..errors import SLRError
from ..terms import Atom, format_term

__all__ = ["EventChannel", "event_channel", "event_from_message", "TRANSFORMS_SCHEMA",
           "TRANSFORMS_SCHEMA_NAME", "MARKS_TOPIC", "MARKS_SCHEMA", "transform_message",
           "mark_message", "time_ns", "TF_TOPICS", "METADATA_EVENT", "METADATA_ARITY",
           "JSON_SCHEMA_ENCODING", "channel_type"]

METADATA_EVENT = "slr_event"       # channel metadata: the event name
METADATA_ARITY = "slr_arity"       # channel metadata: its arity (a decimal string)
JSON_SCHEMA_ENCODING = "jsonschema"
TRANSFORMS_SCHEMA_NAME = "foxglove.FrameTransforms"
TF_TOPICS = {("tf", 3): "/tf", ("tf_static", 3): "/tf_static"}
MARKS_TOPIC = "/slr/completeness"

_JSON_STARTS = frozenset('[{"')
# the JSON text of atoms seen (frame and object names repeat): bounded in number and in
# length, shared, only grows with distinct names; a str key is the stored column value
# (atoms are stored as themselves)
_TEXTS: dict[str, str] = {}
_TEXTS_MAX = 65_536      # atoms kept
_TEXT_MAX = 256          # characters of an atom kept: names repeat, long texts seldom do
_INF, _NEG_INF = math.inf, -math.inf
_float_repr = float.__repr__
_int_str = int.__repr__

_VEC = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
TRANSFORMS_SCHEMA: dict = {
    "title": TRANSFORMS_SCHEMA_NAME,
    "description": "An array of FrameTransform messages",
    "type": "object",
    "properties": {"transforms": {"type": "array", "items": {
        "title": "foxglove.FrameTransform", "type": "object",
        "properties": {
            "timestamp": {"type": "object", "title": "time", "properties": {
                "sec": {"type": "integer", "minimum": 0},
                "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": _VEC,
            "rotation": {"type": "object",
                         "properties": {k: {"type": "number"} for k in "xyzw"}}}}}}}

MARKS_SCHEMA: dict = {
    "title": "slr.completeness",
    "description": "A completeness mark: the history of `type` is complete up to `until`",
    "type": "object",
    "properties": {"type": {"type": "string"}, "until": {"type": "number"},
                   "source": {"type": "string"}}}


def time_ns(t: float) -> int:
    """Seconds as the unsigned nanoseconds of MCAP and Foxglove (negative times clamp to 0,
    times past 2**64 ns, the year 2554, to the last: an event may end at any finite time).

    >>> time_ns(1.5), time_ns(-3.0), time_ns(1e300) == 2 ** 64 - 1
    (1500000000, 0, True)
    """
    if not t > 0.0:
        return 0
    if not t < _LAST_SECOND:   # (t * 1e9 may be infinite: no int)
        return 2 ** 64 - 1
    return min(int(round(t * 1e9)), 2 ** 64 - 1)


_LAST_SECOND = 2 ** 64 / 1e9


def _kind_schema(value: Any) -> dict:
    """The JSON schema of one stored column value (from a sample row)."""
    if type(value) is int or type(value) is float:
        return {"type": "number"}
    if type(value) is str:
        c = value[:1]
        if c == "[":
            return {"type": "array"}
        if c == "{":
            return {"type": "object"} if not value.startswith('{"$atom"') else {"type": "string"}
        if c == '"':
            return {"type": "object", "description": "a string, as {\"$string\": text}"}
        return {"type": "string"}
    return {}


@dataclass
class EventChannel:
    """The channel of one event type name/arity."""

    name: str
    arity: int
    topic: str
    schema: dict
    metadata: dict = field(default_factory=dict)
    _keys: list | None = field(default=None, repr=False, compare=False)
    _key_tuple: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def schema_name(self) -> str:
        return f"slr.{self.name}/{self.arity}"

    def message(self, row: tuple) -> bytes:
        """The JSON message of a stored row ``(arg1..argN, start, end, arrival, seq)``:
        written by the C loop when it is built (the same bytes, see
        :meth:`python_message`), one call per row."""
        loop = encoding.event_message_loop
        if loop is not None and type(row) is tuple:
            keys = self._key_tuple
            if keys is None:
                keys = self._key_tuple = tuple(
                    ('{"arg1":' if i == 0 else f',"arg{i + 1}":') for i in range(self.arity))
            return loop(row, keys, _TEXTS, _argument_text)
        return self.python_message(row)

    def python_message(self, row: tuple) -> bytes:
        """:meth:`message` in Python (the reference of the C loop, and its fallback).

        >>> event_channel("p", 1).python_message(("cup1", 1.5, 2.0, 2.5, 7))
        b'{"arg1":"cup1","start":1.5,"end":2.0,"arrival":2.5}'
        """
        n = self.arity
        keys = self._keys
        if keys is None:
            keys = self._keys = [('{"arg1":' if i == 0 else f',"arg{i + 1}":') for i in range(n)]
        parts = []
        texts = _TEXTS
        for i in range(n):
            parts.append(keys[i])
            value = row[i]
            tv = type(value)
            if tv is str:
                if value and value[0] in "[{":
                    if not value.startswith('{"$atom":'):
                        parts.append(value)   # a list or compound: JSON already
                        continue
                text = texts.get(value)   # atoms repeat (names, frames): each once
                if text is None:
                    text = column_json(value)
                    if len(texts) < _TEXTS_MAX and len(value) <= _TEXT_MAX:
                        texts[value] = text
                parts.append(text)
            elif tv is float and _NEG_INF < value < _INF:
                parts.append(_float_repr(value))
            elif tv is int:
                parts.append(_int_str(value))
            else:
                parts.append(column_json(value))
        parts.append(('{"start":' if not n else ',"start":') + _float_repr(float(row[n]))
                     + ',"end":' + _float_repr(float(row[n + 1])) + ',"arrival":'
                     + _float_repr(float(row[n + 2])) + "}")
        return "".join(parts).encode()


def _argument_text(value: Any) -> str:
    """The text of an argument the C loop of :meth:`EventChannel.message` leaves to Python
    (a str :data:`_TEXTS` does not hold, a number that is no finite float or int, anything
    else), as the Python method writes it: an atom's text kept when short."""
    text = column_json(value)
    if type(value) is str and len(_TEXTS) < _TEXTS_MAX and len(value) <= _TEXT_MAX:
        _TEXTS[value] = text
    return text


def event_channel(name: str, arity: int, sample: tuple | None = None) -> EventChannel:
    """The channel of name/arity; ``sample`` (a stored row) gives the arguments' kinds.

    >>> ch = event_channel("seg", 2, ("cup1", "[0.4,0.1]"))
    >>> ch.topic, ch.schema["title"], ch.schema["properties"]["arg2"], ch.metadata
    ('/seg/2', 'slr.seg/2', {'type': 'array'}, {'slr_event': 'seg', 'slr_arity': '2'})
    """
    props: dict = {}
    for i in range(arity):
        props[f"arg{i + 1}"] = _kind_schema(sample[i]) if sample is not None else {}
    for key, text in (("start", "start time (s)"), ("end", "end time (s): the log time"),
                      ("arrival", "when the store received it (s): the publish time")):
        props[key] = {"type": "number", "description": text}
    schema = {"title": f"slr.{name}/{arity}", "type": "object", "properties": props,
              "required": list(props)}
    return EventChannel(name, arity, f"/{name}/{arity}", schema,
                        {METADATA_EVENT: name, METADATA_ARITY: str(arity)})


def channel_type(path: Any, topic: str, metadata: dict) -> tuple[str, int] | None:
    """The event type ``(name, arity)`` a channel of the MCAP file ``path`` names in its
    metadata (:data:`METADATA_EVENT`, :data:`METADATA_ARITY`, as :func:`event_channel`
    writes them), None for a channel of no event; an :class:`SLRError` naming the channel
    when its arity is no count of arguments (a file written elsewhere).

    >>> channel_type("a.mcap", "/seg/2", {"slr_event": "seg", "slr_arity": "2"})
    ('seg', 2)
    >>> channel_type("a.mcap", "/p", {"slr_event": "p", "slr_arity": "-3"})
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: cannot read a.mcap: channel /p: its slr_arity '-3' is no count of arguments
    """
    if METADATA_EVENT not in metadata:
        return None
    text = metadata.get(METADATA_ARITY)
    # (an arity is at most a few thousand: a text of 5,000 digits is no arity either)
    if not (isinstance(text, str) and text.isascii() and text.isdigit() and len(text) <= 9):
        shown = "missing" if text is None else repr(text if len(text) <= 40
                                                    else text[:40] + "...")
        raise SLRError(f"cannot read {path}: channel {topic}: its {METADATA_ARITY} {shown} is "
                       "no count of arguments")
    return str(metadata[METADATA_EVENT]), int(text)


def event_from_message(name: str, arity: int, data: bytes | str) -> tuple:
    """The event ``(name, args, start, end)`` of a message :meth:`EventChannel.message` wrote.

    >>> from slr_sql.terms import format_term
    >>> name, args, start, end = event_from_message("seg", 2, b'{"arg1":"cup1","arg2":[0.4,0.1],"start":1.5,"end":2.0,"arrival":2.5}')
    >>> name, [format_term(a) for a in args], start, end
    ('seg', ['cup1', '[0.4,0.1]'], 1.5, 2.0)
    """
    obj = json.loads(data)
    if type(obj) is not dict:
        raise ValueError("it is no JSON object")
    keys = [f"arg{i + 1}" for i in range(arity)]
    missing = [key for key in (*keys, "start", "end") if key not in obj]
    if missing:
        raise ValueError(f"it has no {', '.join(missing[:3])}")
    args = tuple(decode_json(obj[key]) for key in keys)
    return (name, args, _seconds(obj, "start"), _seconds(obj, "end"))


def _seconds(obj: dict, key: str) -> float:
    """A message's ``start`` or ``end``: a JSON number, nothing that merely converts to one
    (``true`` or ``"1.5"`` would be stored as a time the export never had)."""
    value = obj[key]
    if type(value) is float:
        return value
    if type(value) is int:
        try:
            return float(value)
        except OverflowError:
            raise ValueError(f"its {key} time is an integer beyond any float") from None
    shown = json.dumps(value)
    raise ValueError(f"its {key} time {shown if len(shown) <= 40 else shown[:40] + '...'} "
                     "is no number")


def _frame(value: Any) -> str:
    term = decode(value)
    return str(term) if type(term) is Atom else format_term(term)


def transform_message(rows: list) -> bytes | None:
    """``foxglove.FrameTransforms`` of stored tf / tf_static rows (``(parent, child, pose,
    start, end, arrival, seq)``); rows whose third argument is not a pose (of finite
    numbers, a quaternion other than zero) are left out (None when none is left).

    >>> transform_message([("map", "base", '{"pose":[[1.0,2.0,3.0],[0.0,0.0,0.0,1.0]]}', 2.5, 2.5, 3.0, 1)])
    b'{"transforms":[{"timestamp":{"sec":2,"nsec":500000000},"parent_frame_id":"map","child_frame_id":"base","translation":{"x":1.0,"y":2.0,"z":3.0},"rotation":{"x":0.0,"y":0.0,"z":0.0,"w":1.0}}]}'
    """
    if len(rows) == 1:
        fast = _one_transform(rows[0])
        if fast is not None:
            return fast
    out = []
    for row in rows:
        try:
            if type(row[2]) is not str:
                continue
            (x, y, z), (qx, qy, qz, qw) = json.loads(row[2])["pose"]
            values = [float(v) for v in (x, y, z, qx, qy, qz, qw)]
        except (TypeError, ValueError, KeyError, AttributeError, OverflowError):
            continue     # (OverflowError: an integer beyond any float)
        if not all(math.isfinite(v) for v in values) or not any(values[3:]):
            continue     # (a zero quaternion is no rotation: tf_lookup refuses it too)
        ns = time_ns(row[4])
        out.append({"timestamp": {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000},
                    "parent_frame_id": _frame(row[0]), "child_frame_id": _frame(row[1]),
                    "translation": dict(zip("xyz", values[:3])),
                    "rotation": dict(zip("xyzw", values[3:]))})
    if not out:
        return None
    return json.dumps({"transforms": out}, separators=(",", ":")).encode()


def _plain_frame(value: Any) -> str | None:
    """The JSON string of a frame stored as a plain atom, else None."""
    if type(value) is not str or value[:1] in _JSON_STARTS:
        return None
    text = _TEXTS.get(value)
    if text is None:
        text = column_json(value)
        if len(_TEXTS) < _TEXTS_MAX and len(value) <= _TEXT_MAX:
            _TEXTS[value] = text
    return text


# a pose as the encoder stores it: two lists of JSON numbers (3 and 4 of them)
_NUMBER = r"(-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?)"
_STORED_POSE = re.compile(r'\{"pose":\[\[' + ",".join([_NUMBER] * 3) + r"\],\["
                          + ",".join([_NUMBER] * 4) + r"\]\]\}")
_NONZERO_DIGITS = frozenset("123456789")


def _one_transform(row: tuple) -> bytes | None:
    """transform_message of one row in its common form (plain frame names, a pose of finite
    JSON numbers), written from the stored text directly (the encoder wrote each number's
    shortest text, at most 24 characters for a float); None for anything else (the general
    path decides: an integer of 400 digits is no float, a text that is no JSON number is
    no pose)."""
    parent, child, pose = _plain_frame(row[0]), _plain_frame(row[1]), row[2]
    if parent is None or child is None or type(pose) is not str:
        return None
    match = _STORED_POSE.fullmatch(pose)
    if match is None or "e999" in pose:
        return None
    x, y, z, qx, qy, qz, qw = numbers = match.groups()
    if max(map(len, numbers)) > 24:
        return None
    if not any(_NONZERO_DIGITS.intersection(v.lower().partition("e")[0]) for v in (qx, qy, qz, qw)):
        return None   # (no non-zero digit: a zero quaternion, perhaps; the general path checks)
    ns = time_ns(row[4])
    return (f'{{"transforms":[{{"timestamp":{{"sec":{ns // 1_000_000_000},"nsec":'
            f'{ns % 1_000_000_000}}},"parent_frame_id":{parent},"child_frame_id":{child},'
            f'"translation":{{"x":{x},"y":{y},"z":{z}}},"rotation":{{"x":{qx},'
            f'"y":{qy},"z":{qz},"w":{qw}}}}}]}}').encode()


def mark_message(type_text: str, until: float, source: str) -> bytes:
    """A completeness mark message.

    >>> mark_message("seg/2", 2.0, "kb.mark_complete")
    b'{"type":"seg/2","until":2.0,"source":"kb.mark_complete"}'
    """
    return json.dumps({"type": type_text, "until": until, "source": source},
                      separators=(",", ":")).encode()
