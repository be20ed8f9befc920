"""The service's JSON encoding of terms: exact and reversible (no server needed)."""
from __future__ import annotations

import json
import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slr_sql import Atom, SLRCancelled, SLREvaluationError, SLRSyntaxError, SLRTimeout, String, Struct, Var
from slr_sql.service.encoding import (MAX_DEPTH, TermError, decode_answers, decode_args,
                                      decode_plain, decode_term, dumps, encode_answers,
                                      encode_args, encode_plain, encode_term, loads)
from slr_sql.service.errors import ServiceError, error_body, error_from_body

from service_helpers import same


text = st.text(max_size=8)
atoms = text.map(Atom)
strings = text.map(String)
integers = st.integers(min_value=-(2 ** 64), max_value=2 ** 64) | st.integers(-(10 ** 80), 10 ** 80)
floats = st.floats(allow_nan=True, allow_infinity=True)
variables = st.sampled_from(["X", "Y", "_G7", "Long_name"]).map(Var)
leaves = atoms | strings | integers | floats | variables
terms = st.recursive(
    leaves,
    lambda children: st.lists(children, max_size=4)
    | st.builds(Struct, text, st.lists(children, min_size=0, max_size=3).map(tuple)),
    max_leaves=25)


@given(terms)
def test_every_term_survives_encode_json_decode(term):
    wire = dumps(encode_term(term))
    assert b"NaN" not in wire and b"Infinity" not in wire  # strict JSON only
    back = decode_term(loads(wire))
    assert same(term, back), (term, wire, back)


def plain_strings(t):
    """A term as kb.query returns it: strings as plain str."""
    if type(t) is String:
        return str(t)
    if type(t) is list:
        return [plain_strings(x) for x in t]
    if type(t) is Struct:
        return Struct(t.name, tuple(plain_strings(x) for x in t.args))
    return t


@given(st.dictionaries(st.sampled_from(["X", "Y", "Z", "Answer"]), terms, max_size=4))
def test_answers_survive_with_strings_as_str(answer):
    answer = {k: plain_strings(v) for k, v in answer.items()}
    back = decode_answers(loads(dumps(encode_answers([answer]))))
    assert len(back) == 1 and set(back[0]) == set(answer)
    names: dict = {}
    assert all(same(answer[k], back[0][k], names) for k in answer)


@given(st.dictionaries(st.sampled_from(["O", "T", "L"]), terms, max_size=3))
def test_args_survive(args):
    back = decode_args(loads(dumps(encode_args(args))))
    names: dict = {}
    assert set(back) == set(args) and all(same(args[k], back[k], names) for k in args)


@pytest.mark.parametrize("value, wire", [
    (Atom("cup1"), '"cup1"'),
    (Atom("[]"), '"[]"'),
    ([], "[]"),
    (String("hi"), '{"$string":"hi"}'),
    (42, "42"),
    (2 ** 70, '{"$int":"1180591620717411303424"}'),
    (1.0, "1.0"),
    (-0.0, "-0.0"),
    (1e22, ("1e22", "1e+22")),   # the exponent's spelling depends on orjson's version
    (math.inf, '{"$float":"inf"}'),
    (-math.inf, '{"$float":"-inf"}'),
    (math.nan, '{"$float":"nan"}'),
    ([0.4, Atom("a")], '[0.4,"a"]'),
    (Struct("f", (Atom("a"), 1)), '{"f":["a",1]}'),
    (Struct("$string", (1,)), '{"$string":[1]}'),
    (Struct(".", (Atom("a"), Var("T"))), '{".":["a",{"$var":"T"}]}'),
    (Var("X"), '{"$var":"X"}'),
])
def test_documented_forms(value, wire):
    spellings = wire if isinstance(wire, tuple) else (wire,)
    assert dumps(encode_term(value)).decode() in spellings
    for text in spellings:
        assert same(decode_term(json.loads(text)), value)


@given(st.floats(allow_nan=False, allow_infinity=False))
def test_a_float_is_written_as_a_float_that_reads_back_exactly(value):
    # orjson spells exponents its own way (1e22, 0.00001); the text must still say "float"
    # (a . or an exponent, so 1.0 never becomes the integer 1) and read back to the same bits
    text = dumps(encode_term(value)).decode()
    assert "." in text or "e" in text
    assert math.copysign(1, json.loads(text)) == math.copysign(1, value)
    assert json.loads(text) == value == loads(text)
    assert loads(repr(value)) == value          # Python's spelling (1e+22) is read the same


def test_plain_str_is_an_atom_in_requests_and_a_string_in_answers():
    assert encode_term("cup1") == "cup1"
    assert encode_answers([{"S": "text"}]) == [{"S": {"$string": "text"}}]
    assert decode_answers([{"S": {"$string": "text"}}])[0]["S"].__class__ is str
    assert decode_term({"$string": "text"}).__class__ is String


def test_variables_of_one_answer_are_shared():
    (answer,) = decode_answers([{"X": {"$var": "Y"}, "Y": {"$var": "Y"}}])
    assert answer["X"] is answer["Y"]


def test_inputs_the_store_encoding_writes_are_read_too():
    assert decode_term({"$atom": "[x"}) == Atom("[x") and type(decode_term({"$atom": "[x"})) is Atom
    assert decode_term({"$int": "5"}) == 5
    assert decode_term({"$float": 1}) == 1.0 and type(decode_term({"$float": 1})) is float
    assert decode_term(loads(b"1e999")) == math.inf


@pytest.mark.parametrize("obj, words", [
    (None, "null is not a term"),
    (True, "true is not a term"),
    ({}, "exactly one key"),
    ({"a": 1, "b": 2}, "exactly one key"),
    ({"$int": "1.5"}, "decimal digits"),
    ({"$float": "infinity"}, "$float must be"),
    ({"$nope": "x"}, "unknown tag"),
    ({"f": [1, {"$string": 3}]}, "f[1]"),
])
def test_bad_terms_say_what_and_where(obj, words):
    with pytest.raises(TermError, match=words.replace("[", r"\[").replace("$", r"\$")):
        decode_term(obj)


def test_depth_is_bounded_both_ways():
    deep: list = []
    for _ in range(MAX_DEPTH + 5):
        deep = [deep]
    with pytest.raises(TermError, match="deeper"):
        encode_term(deep)
    with pytest.raises(TermError, match="deeper"):
        decode_term(deep)
    with pytest.raises(ValueError, match="nested too deeply"):
        loads(b"[" * 100_000 + b"]" * 100_000)


@pytest.mark.parametrize("data", [b'{"a": NaN}', b'[Infinity]', b'["\\ud800"]', b"\xff"])
def test_loads_is_strict(data):
    with pytest.raises(ValueError):
        loads(data)


def test_unsendable_python_values_are_slr_errors():
    with pytest.raises(TermError, match="cannot send"):
        encode_term(object())


def test_plain_values_round_trip():
    value = {"now": -math.inf, "rows": [[1, "a", None, b"\x00\xff", 0.5]]}
    assert decode_plain(loads(dumps(encode_plain(value)))) == value


@pytest.mark.parametrize("exc, status", [
    (SLRSyntaxError("operator expected", line=2, column=6, source_line="a(1) b.",
                    filename="robot.slr"), 400),
    (SLREvaluationError(Struct("error", (Struct("type_error", (Atom("integer"), Atom("a"))),
                                         Var("_"))), "type_error(integer,a)"), 400),
    (SLRTimeout("the query ran out of its 1 s"), 408),
    (ServiceError("no such buffer #3", kind="NotFound"), 404),
    (ServiceError("too large", kind="PayloadTooLarge"), 413),
])
def test_errors_come_back_as_the_same_class_and_text(exc, status):
    body = loads(dumps(error_body(exc)))
    assert body["error"]["status"] == status
    back = error_from_body(body, status)
    assert type(back) is type(exc) and str(back) == str(exc)
    if isinstance(exc, SLRSyntaxError):
        assert (back.line, back.column, back.filename) == (2, 6, "robot.slr")
    if isinstance(exc, SLREvaluationError):
        assert same(back.term, exc.term)


def test_a_server_side_cancel_travels_with_the_servers_reason():
    cancelled = SLRCancelled("postgresql://x: the server cancelled the statement (canceling "
                             "statement due to user request); it may be retried")
    cancelled.reason = "canceling statement due to user request"
    body = loads(dumps(error_body(cancelled)))
    assert body["error"]["status"] == 503
    back = error_from_body(body, 503)
    assert type(back) is SLRCancelled and str(back) == str(cancelled)
    assert back.reason == "canceling statement due to user request"


@settings(max_examples=30)
@given(st.text(max_size=20))
def test_any_message_text_travels(message):
    back = error_from_body(loads(dumps(error_body(SLRTimeout(message)))), 408)
    assert str(back) == message


def as_terms(value):
    """Plain JSON read the way the knowledge base reads Python values: str is an atom."""
    if type(value) is str:
        return Atom(value)
    if type(value) is list:
        return [as_terms(v) for v in value]
    assert type(value) in (int, float), value
    return value


@given(st.lists(terms, max_size=4), st.lists(st.text(max_size=5), max_size=3))
def test_the_server_skips_decoding_only_when_arguments_are_plain_json(args, texts):
    """add_many's shortcut (arguments used as parsed) is taken only when it means the same
    terms as decoding them."""
    from slr_sql.service.app import _plain_arguments

    events = [{"name": "p", "args": encode_term(args), "start": 1.0}] + texts
    body = dumps({"events": events, "atomic": False})
    parsed = loads(body)["events"]
    if _plain_arguments(body, parsed):
        assert same(as_terms(parsed[0]["args"]), decode_term(parsed[0]["args"]))
