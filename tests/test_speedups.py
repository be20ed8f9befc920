"""The optional C loops of the column encoder (csrc/_slr_sql_speedups.c) give exactly the
texts of the Python path and of the general encoder, decline whatever they do not know, and
are built wherever a C compiler is."""
from __future__ import annotations

import contextlib
import enum
import math
import signal
import random
import shutil

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from slr_sql import encoding
from slr_sql.encoding import Unencodable, encode, encode_column
from slr_sql.terms import CONS, NIL, Atom, String, Struct, Var, make_list

speedups = encoding._speedups


def test_the_accelerator_is_built_where_a_c_compiler_is():
    import os

    import sysconfig
    from pathlib import Path

    can_build = (shutil.which("cc") or shutil.which("gcc")) and \
        (Path(sysconfig.get_paths()["include"]) / "Python.h").exists()
    if os.environ.get("SLR_SQL_NO_SPEEDUPS"):
        assert speedups is None
    elif can_build:
        # setup.py builds it (optional=True keeps a compiler error from failing the install;
        # this test is where such an error shows)
        assert speedups is not None, "csrc/_slr_sql_speedups.c was not built"
    else:
        assert encoding._speedups is None or speedups.LOOPS_VERSION == encoding._LOOPS_VERSION


@contextlib.contextmanager
def encoder(path: str):
    """The column encoder with the C loops ("c") or without them ("python")."""
    saved = encoding._speedups
    encoding._speedups = speedups if path == "c" else None
    try:
        yield
    finally:
        encoding._speedups = saved


PATHS = ["python", "c"] if speedups is not None else ["python"]


def expected_texts(values):
    try:
        return [encode(v) for v in values]
    except Unencodable:
        return "refused"


def column_texts(values, path):
    with encoder(path):
        try:
            return encode_column(list(values))
        except Unencodable:
            return "refused"


# Every magnitude where repr and orjson part (exponents, 0.0000, 1e16), the integer limits
# of orjson (53 bits) and of the stored form (64 bits), and values that are not numbers.
NUMBERS = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False),
    st.floats(min_value=-1e-3, max_value=1e-3),
    st.floats(min_value=1e15, max_value=1e17),
    st.integers(-(2 ** 54), 2 ** 54),
    st.sampled_from([2 ** 53, 2 ** 53 + 1, 2 ** 63 - 1, 2 ** 63, -(2 ** 63), 1e-4, 1e-5,
                     10.00001, -0.0, 5e-324, 1e22, 1.7976931348623157e308, 100.0]),
)
ODD = st.sampled_from([math.inf, -math.inf, math.nan, True, Atom("cup1"), Atom("[]"),
                       make_list([1.0]), [2.0]])
ROW = st.lists(st.one_of(NUMBERS, NUMBERS, NUMBERS, ODD), max_size=5)


@pytest.mark.parametrize("path", PATHS)
@given(rows=st.lists(ROW, max_size=6))
@example(rows=[[1e-05, 0.5], [], [1e16, 2 ** 53 + 1]])
@example(rows=[[[1.0, 2.0]], [[1.0], [2.0]], [[]]])
def test_a_column_of_python_lists_encodes_as_each_value_does(path, rows):
    assert column_texts(rows, path) == expected_texts(rows)


@pytest.mark.parametrize("path", PATHS)
@given(rows=st.lists(ROW, min_size=1, max_size=6))
@example(rows=[[1e-05, 0.5], [], [10.00001]])
@example(rows=[[], [], [1.0]])
@example(rows=[[2 ** 60], [1.0]])
def test_a_column_of_prolog_lists_encodes_as_each_value_does(path, rows):
    values = [make_list(row) for row in rows]
    assert column_texts(values, path) == expected_texts(values)


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("odd", [
    make_list([1.0], Atom("tail")),                 # a partial list
    make_list([1.0], Var("T")),                     # an unbound tail
    Struct(".", (1.0,)),                            # a '.' of one argument
    Struct(".", (1.0, Struct("f", (NIL,)))),        # another compound in the spine
    Struct("pose", ([1.0, 2.0], [0.0, 0.0, 0.0, 1.0])),
])
def test_a_column_with_one_value_that_is_not_a_list_of_numbers(path, odd):
    values = [make_list([0.5, 1.5]), odd, make_list([2.5])]
    assert column_texts(values, path) == expected_texts(values)


class Half(enum.Enum):
    VALUE = 0.5


class Vector(list):
    pass


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("values", [
    [[Half.VALUE, 1.0], [2.0]],              # orjson writes an Enum member as its value
    [[1.0, Half.VALUE]],
    [[Vector([1.0, 2.0])], [[3.0]]],         # and a list subclass as an array
    [Vector([1.0]), [2.0]],
    [[1.0, 2.0], (3.0, Half.VALUE)],
    [make_list([Half.VALUE, 1.0]), make_list([2.0])],
    [Struct("pose", ([0.5, Half.VALUE], [1.0])), Struct("pose", ([0.5], [1.0]))],
    [Struct("pose", (Vector([0.5]), [1.0]))],
])
def test_values_orjson_writes_but_the_encoder_refuses_are_refused_on_every_path(path, values):
    assert column_texts(values, path) == expected_texts(values) == "refused"


@pytest.mark.parametrize("path", PATHS)
def test_a_column_given_as_a_tuple_encodes_as_a_list_does(path):
    values = (make_list([1.0, 2.0]), make_list([3.0]))
    with encoder(path):
        assert encode_column(values) == encode_column(list(values)) == ["[1.0,2.0]", "[3.0]"]
        assert encode_column(([1.0], [2.5])) == ["[1.0]", "[2.5]"]


@pytest.mark.parametrize("path", PATHS)
@pytest.mark.parametrize("vectors", ["python", "prolog"])
def test_a_long_column_of_random_vectors_with_the_rows_orjson_spells_otherwise(path, vectors):
    rng = random.Random(5)
    rows = [[rng.random() ** rng.choice((1, 8)), rng.uniform(-1e6, 1e6),
             rng.choice((1e-5, 0.25, 3, 1e16, 123.0))] for _ in range(30_000)]
    values = rows if vectors == "python" else [make_list(row) for row in rows]
    got = column_texts(values, path)
    assert got == expected_texts(values)
    assert sum("e" in text for text in got) > 1_000  # the rows written again by Python


class Cell(Struct):
    """A subclass of Struct: the C walk reads the slots of Struct itself only."""

    __slots__ = ()


class Borrower:
    __slots__ = ()
    name = Struct.name
    args = Struct.args


needs_c = pytest.mark.skipif(speedups is None, reason="the accelerator is not built")


@needs_c
def test_cons_numbers_collects_every_element_and_each_length():
    values = [make_list([1.0, 2]), NIL, make_list([3.5])]
    flat, lengths = speedups.cons_numbers(values, Struct, Atom, CONS, NIL)
    assert (flat, lengths) == ([1.0, 2, 3.5], [2, 0, 1])
    assert speedups.cons_numbers([], Struct, Atom, CONS, NIL) == ([], [])


@needs_c
@pytest.mark.parametrize("value", [
    make_list([Atom("a")]), make_list([True]), make_list([make_list([1.0])]),
    make_list([1.0], Atom("t")), make_list([1.0], Var("T")), Cell(".", (1.0, NIL)),
    Struct(".", (1.0, 2.0, NIL)), Atom("[]x"), 1.0,
])
def test_cons_numbers_declines_anything_but_proper_lists_of_numbers(value):
    assert speedups.cons_numbers([make_list([1.0]), value], Struct, Atom, CONS, NIL) is None


@needs_c
def test_the_empty_list_may_be_any_atom_spelled_brackets():
    values = [make_list([1.0], Atom("[]"))]
    assert speedups.cons_numbers(values, Struct, Atom, CONS, NIL) == ([1.0], [1])


@needs_c
@pytest.mark.parametrize("data, count, rows", [
    (b"[[1.0,2],[],[3]]", 3, ["[1.0,2]", "[]", "[3]"]),
    (b"[]", 0, []),
    (b"[[[1],[2]],[3]]", 2, ["[[1],[2]]", "[3]"]),
    (b"[[1e-05],[0.5],[10.00001],[1e+16]]", 4, [None, "[0.5]", None, None]),
])
def test_split_rows_cuts_the_rows_and_leaves_out_those_repr_may_spell_otherwise(data, count,
                                                                                rows):
    assert speedups.split_rows(data, count) == rows


@needs_c
@pytest.mark.parametrize("data, count", [
    (b"[[1],[2]]", 3), (b"[[1],[2]]", 1), (b"[[1],[2],]", 2), (b"[[1],null]", 2),
    (b'[["a"]]', 1), (b"[[1]", 1), (b"[1,2]", 2), (b"[[1]][[2]]", 2), (b"", 0), (b"[[1]x]", 1),
    (b"[[1],[2]", 2), (b"[{}]", 1), (b"[]", 2 ** 40),
])
def test_split_rows_declines_text_that_is_not_count_arrays_of_numbers(data, count):
    assert speedups.split_rows(data, count) is None


@needs_c
@pytest.mark.parametrize("data, lengths, rows", [
    (b"[1.0,2,3]", [2, 0, 1], ["[1.0,2]", "[]", "[3]"]),
    (b"[]", [0, 0], ["[]", "[]"]),
    (b"[1,2]", [0, 2], ["[]", "[1,2]"]),
    (b"[0.00001,5,1e16]", [1, 1, 1], [None, "[5]", None]),
])
def test_split_flat_cuts_the_numbers_into_rows(data, lengths, rows):
    assert speedups.split_flat(data, lengths) == rows


@needs_c
@pytest.mark.parametrize("data, lengths", [
    (b"[1,2,3]", [2]), (b"[1,2]", [3]), (b"[1,,2]", [3]), (b"[1,2,]", [3]),
    (b"[1,null]", [2]), (b"[[1]]", [1]), (b"[1", [1]), (b"", []),
])
def test_split_flat_declines_lengths_that_do_not_fit_the_text(data, lengths):
    assert speedups.split_flat(data, lengths) is None


@needs_c
@pytest.mark.parametrize("call", [
    lambda: speedups.split_rows("[[1]]", 1),
    lambda: speedups.split_rows(b"[[1]]"),
    lambda: speedups.split_flat(b"[1]", (1,)),
    lambda: speedups.split_flat(b"[1]", ["1"]),
    lambda: speedups.cons_numbers((), Struct, Atom, CONS, NIL),
    lambda: speedups.cons_numbers([], Atom, Atom, CONS, NIL),  # Atom has no slots
    # a type that borrows Struct's slot descriptors: their offsets are not its own
    lambda: speedups.cons_numbers([Borrower()], Borrower, Atom, CONS, NIL),
    lambda: speedups.split_flat(b"[1]", [-1]),
    lambda: speedups.split_rows(b"[[1]]", -1),
    lambda: speedups.number_rows(([1.0],)),
])
def test_misuse_is_a_python_error_not_a_crash(call):
    with pytest.raises((TypeError, ValueError, AttributeError)):
        call()


@needs_c
@pytest.mark.parametrize("values, expected", [
    ([[1.0, 2], (3.5,), []], True),
    ([], True),
    ([[1.0, True]], False),
    ([[Half.VALUE]], False),
    ([Vector([1.0])], False),
    ([[[1.0]]], False),
    ([make_list([1.0])], False),
])
def test_number_rows_accepts_lists_and_tuples_of_exact_floats_and_ints(values, expected):
    assert speedups.number_rows(values) is expected


@needs_c
def test_a_cyclic_list_made_by_hand_lets_a_signal_stop_the_walk():
    cell = Struct(".", (1.0, NIL))
    cell.args = (1.0, cell)  # a cycle: no proper list ever ends

    class Stopped(Exception):
        pass

    def stop(signum, frame):
        raise Stopped

    previous = signal.signal(signal.SIGALRM, stop)
    try:
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        with pytest.raises(Stopped):
            speedups.cons_numbers([cell], Struct, Atom, CONS, NIL)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


# -- the loops over a batch of events (store/events.py's column path, kb.add_many's form) --

def test_the_built_accelerator_has_the_event_loops():
    # a build from before them still encodes, but every bulk add would check its events in
    # Python: rebuild (python setup.py build_ext --inplace)
    if speedups is not None:
        assert encoding.event_columns_loop is speedups.event_columns
        assert encoding.event_form_loop is speedups.event_form
        assert encoding.event_message_loop is speedups.event_message


_TIMES = st.one_of(st.floats(-1e3, 1e3), st.sampled_from([-0.0, 0.0, math.inf, -math.inf,
                                                          math.nan]), st.integers(-3, 3))
_ARGS = st.lists(st.one_of(st.integers(-3, 3), st.text(max_size=2)), max_size=3)
_EXACT_EVENT = st.tuples(st.sampled_from(["p", "q"]),
                         st.one_of(_ARGS, _ARGS.map(tuple)), _TIMES, _TIMES)


def _python_split(chunk):
    from slr_sql.store.events import _split_columns

    try:
        if set(map(len, chunk)) != {4} or len(set(map(lambda e: e[0], chunk))) != 1:
            return None
        return _split_columns(chunk)
    except (TypeError, IndexError, KeyError):
        return None


@needs_c
@given(st.lists(_EXACT_EVENT, min_size=1, max_size=8))
@example([("p", (1,), -0.0, 0.0), ("p", [2], -1.0, -0.0)])
@example([("p", (), 1.0, 1.0), ("p", (), 0.5, math.inf)])
def test_event_columns_splits_exactly_the_chunks_the_python_checks_accept(chunk):
    # events of exact types: the C loop declines a chunk exactly when the Python checks
    # refuse it, and splits the others into the same columns (-0.0 times given as 0.0)
    split = speedups.event_columns(chunk)
    assert repr(split) == repr(_python_split(chunk))


class Name(str):
    pass


@needs_c
@pytest.mark.parametrize("chunk", [
    [["p", (1,), 1.0, 1.0]],                                 # an event that is a list
    [("p", (1,), 1.0, 1.0), ["p", (2,), 2.0, 2.0]],
    [(Name("p"), (1,), 1.0, 1.0)],                           # a str subclass as the name
    [("p", (1,), 1.0, 1.0), (Name("p"), (2,), 2.0, 2.0)],
    [("p", Vector([1]), 1.0, 1.0)],                          # a list subclass as arguments
    [("p", (1,), 1.0, 1.0, "extra")],
    [(1, (1,), 1.0, 1.0)],                                   # not a name at all
    [("p", 1, 1.0, 1.0)],
    [("p", (1,), 1.0, 1.0), ("p", (1, 2), 2.0, 2.0)],        # two arities
    [("p", (1,), 1.0, 1.0), ("q", (1,), 2.0, 2.0)],          # two names
    [("p", (1,), 1.0, 2.0), ("p", (1,), 2.0, 1.0)],          # start after end
])
def test_event_columns_declines_what_it_does_not_know_and_the_python_checks_decide(chunk):
    assert speedups.event_columns(chunk) is None
    assert speedups.event_columns(tuple(chunk)) is None   # (only a list is walked)


@needs_c
def test_event_columns_gives_the_columns_of_a_bulk_chunk():
    chunk = [("seg", (Atom(f"o{i}"), make_list([i, 0.5])), float(i), float(i) + 1)
             for i in range(1000)]
    name, arity, columns, starts, ends = speedups.event_columns(chunk)
    assert (name, arity) == ("seg", 2)
    assert columns == [[e[1][0] for e in chunk], [e[1][1] for e in chunk]]
    assert starts == [e[2] for e in chunk] and ends == [e[3] for e in chunk]
    assert speedups.event_columns([]) is None


_ANY_EVENT = st.one_of(_EXACT_EVENT, _EXACT_EVENT.map(list),
                       st.tuples(st.just("p"), st.sampled_from([1, None, Vector([1])]),
                                 _TIMES, _TIMES),
                       st.tuples(st.just("p"), _ARGS), st.just("p(1)^1"))


@needs_c
@given(st.lists(_ANY_EVENT, max_size=6))
@example([("p", (1,), 1.0, 1.0), ("p", [1], 1.0, 1.0)])
@example([("p", (1,), 1.0, 1.0), ["p", (1,), 1.0, 1.0]])
def test_event_form_answers_as_the_column_checks_do(events):
    from slr_sql.kb import _event_form_by_columns

    assert speedups.event_form(events) == _event_form_by_columns(events)


# -- the JSON message of a stored event row (slr_sql/viz/channels.py) --

class _Text(str):
    """A str of a subclass: no exact str to the loop (column_json decides, uncached)."""


_TERMS = st.recursive(
    st.one_of(st.text(max_size=4).map(Atom), st.text(max_size=4).map(String),
              st.integers(-2 ** 70, 2 ** 70), st.floats(allow_nan=False),
              st.sampled_from([Atom("{x"), Atom('{"$atom":"a"}'), Atom("[]"), Atom("")])),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.tuples(st.sampled_from(["f", "{"]),
                                      st.lists(inner, min_size=1, max_size=2))
                            .map(lambda t: Struct(t[0], tuple(t[1])))),
    max_leaves=6)
_STORED = st.one_of(_TERMS.map(encode), st.sampled_from(
    [None, b"\x00", True, math.inf, -math.inf, math.nan, "\ud800", "{\"$atom\":\"\ud800\"}",
     _Text("cup"), 10 ** 5000, "", "{", "[", '{"$atom":']))
_ROW_TIMES = st.one_of(st.floats(), st.integers(-10, 10), st.sampled_from(["1.5", None, "x"]))


def _outcome(function, *args):
    try:
        return function(*args)
    except Exception as exc:  # noqa: BLE001 - compared, not handled
        return type(exc)


@needs_c
@given(st.integers(0, 3).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(_STORED, min_size=n, max_size=n), st.lists(_ROW_TIMES, min_size=3,
                                                                    max_size=3))))
@example((1, [encode(Atom("cup1"))], [1.5, 2, 2.5]))
@example((2, ['{"$atom":"[x]"}', _Text("[1]")], [0.0, -0.0, 1e300]))
def test_event_message_writes_the_bytes_of_the_python_message(case):
    from slr_sql.viz import channels

    n, args, times = case
    row = (*args, *times, 7)
    channel = channels.event_channel("p", n)
    assert encoding.event_message_loop is speedups.event_message
    for _ in range(2):   # (the second time, atoms come from the cache)
        assert _outcome(channel.message, row) == _outcome(channel.python_message, row)


@needs_c
def test_event_message_keeps_short_atoms_as_the_python_message_does():
    from slr_sql.viz import channels

    channel = channels.event_channel("p", 2)
    short, long = "c" + "x" * 20, "d" * (channels._TEXT_MAX + 1)
    channel.message((short, long, 1.0, 2.0, 3.0, 1))
    assert channels._TEXTS[short] == '"' + short + '"' and long not in channels._TEXTS
