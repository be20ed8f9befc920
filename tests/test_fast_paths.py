"""The ingest fast paths give exactly what the general paths give: the flat-list encoder the
same text as the general JSON encoder, the store's column-at-a-time insert the same rows and
the same rejections as the event-by-event insert, kb.add_many's pass-through the same as its
preparing loop."""
from __future__ import annotations

import math

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import slr_sql
from slr_sql.encoding import Unencodable, _json, encode
from slr_sql.store import EventStore
from slr_sql.terms import Atom, String, Struct, make_list

ELEMENTS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2 ** 70), max_value=2 ** 70),
    st.sampled_from([Atom("cup1"), Atom("[]"), Atom("[x"), Atom("é"), Atom("\ud800"), Atom("")]),
    st.text(max_size=3).map(Atom),
    st.text(max_size=3).map(String),
    st.booleans(),
    st.just(make_list([1.0])),
)


def general(term):
    """What the general encoder (no fast path) gives: text, or the Unencodable reason."""
    try:
        text = _json(term, 0)
    except Unencodable as exc:
        return ("refused", exc.reason)
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return ("refused", "surrogate")
    return text


def fast(term):
    try:
        return encode(term)
    except Unencodable as exc:
        return ("refused", "surrogate" if "surrogate" in exc.reason else exc.reason)


@given(st.lists(ELEMENTS, max_size=6))
@example([0.5, 1, Atom("cup1")])
@example([-0.0, 1e22, 5e-324, 2 ** 63 - 1, -(2 ** 63)])
@example([2 ** 63, math.inf, -math.inf])
@example([math.nan])
def test_flat_lists_encode_as_the_general_encoder_does(items):
    for term in (make_list(items), list(items), tuple(items)):
        assert fast(term) == general(term)


@given(st.lists(ELEMENTS, min_size=1, max_size=4), ELEMENTS)
def test_partial_lists_take_the_general_path(items, tail):
    term = make_list(items, tail if not isinstance(tail, bool) else Atom("t"))
    assert fast(term) == general(term)


EVENT_ARGS = st.lists(st.one_of(ELEMENTS, st.lists(ELEMENTS, max_size=3).map(make_list)),
                      min_size=2, max_size=2).map(tuple)
TIMES = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=32),
                  st.integers(-3, 3))


@given(st.lists(st.tuples(EVENT_ARGS, TIMES, TIMES), max_size=8))
def test_the_column_insert_stores_and_rejects_as_event_by_event_does(specs):
    events = [("p", args, start, end) for args, start, end in specs]
    # interleaving a second type whose times are integers (not the column paths' floats):
    # the event-by-event path
    mixed = [e for event in events for e in (event, ("marker", (), 0, 0))]
    uniform, each = EventStore(None), EventStore(None)
    errors_uniform = uniform.add_events(events)
    errors_each = each.add_events(mixed)
    assert [(e.index, str(e)) for e in errors_uniform] == \
        [(e.index // 2, str(e)) for e in errors_each]
    rows = [[row[:3] for row in store.scan("p", 2)] for store in (uniform, each)]
    assert repr(rows[0]) == repr(rows[1])  # repr: 1 and 1.0, 0.0 and -0.0 differ
    assert uniform.count("marker", 0) == 0


def test_a_batch_bigger_than_a_chunk_keeps_its_order_and_its_rejections():
    store = EventStore(None)
    events = [("p", (i,), float(i), float(i)) for i in range(45_000)]
    events[30_000] = ("p", (math.nan,), 1.0, 1.0)
    errors = store.add_events(iter(events))  # an iterator: sliced as it is read
    assert [e.index for e in errors] == [30_000]
    values = [args[0] for args, *_ in store.scan("p", 1)]
    assert values == [i for i in range(45_000) if i != 30_000]


BATCH_EVENTS = st.lists(st.tuples(st.sampled_from(["p", "q"]), st.sampled_from([(1,), (1, 2), (math.nan,)]),
                                   TIMES, TIMES), max_size=12)


@given(BATCH_EVENTS, st.booleans())
def test_an_event_batch_gets_the_end_times_of_what_was_stored(specs, one_type):
    from slr_sql.store import EventBatch
    from slr_sql.sync import _end_spans

    events = [("p" if one_type else name, args, start, end) for name, args, start, end in specs]
    store = EventStore(None)
    batch = EventBatch(events)
    errors = store.add_events(batch)
    rejected = {e.index for e in errors}
    stored = [ev for k, ev in enumerate(events) if k not in rejected]
    # the store's spans are those of the stored events (floats: the store's times)
    expected = {key: (float(a), float(b)) for key, (a, b) in _end_spans(stored).items()} \
        if stored else {}
    assert batch.ends == expected


def test_an_event_batch_over_several_chunks_and_a_failed_atomic_add():
    from slr_sql.store import EventBatch

    store = EventStore(None)
    batch = EventBatch(("p", (i,), float(i), float(i) + 0.5) for i in range(45_000))
    assert store.add_events(batch) == [] and batch.ends == {("p", 1): (0.5, 44_999.5)}
    bad = EventBatch([("p", (1,), 1.0, 1.0), ("p", (math.nan,), 2.0, 2.0)])
    with pytest.raises(slr_sql.EventRejected):
        store.add_events(bad, atomic=True)
    assert bad.ends is None  # nothing stored, nothing described
    batch[:] = [("p", (1,), 2.0, 2.0), ("p", (math.nan,), 3.0, 3.0)]  # given again: fails
    with pytest.raises(slr_sql.EventRejected):
        store.add_events(batch, atomic=True)
    assert batch.ends is None  # not the first add's description


@pytest.mark.parametrize("form", ["tuples", "text"])
def test_add_many_learns_the_same_delays_and_horizons_from_tuples_and_text(form):
    # tuples take the pass-through (the store describes the batch), text the preparing loop
    # (the synchronizer walks the stored events): the same learned delay and in-order horizon
    with slr_sql.open(clock=slr_sql.ManualClock(100.0)) as kb:
        kb.load(":- in_order(r/1).")
        spec = [("r", 1, 40.0), ("r", 2, 90.5), ("s", 3, 12.0), ("r", 3, 55.0), ("s", 4, 97.0)]
        if form == "tuples":
            kb.add_many([(name, (x,), t, t) for name, x, t in spec])
        else:
            kb.add_many([f"{name}({x})^{t}" for name, x, t in spec])
        tracker = kb._sync.tracker
        assert tracker.learned[("r", 1)] == 60.0 and tracker.learned[("s", 1)] == 88.0
        assert tracker.latest_end(("r", 1)) == 90.5
        assert kb.complete_until("r/1") >= 90.5


@pytest.mark.parametrize("args", [tuple, list])
def test_add_many_passes_tuples_through_and_maps_rejections_back(args):
    # tuples of (name, args, start, end) skip the preparing loop, whether their arguments are
    # tuples or lists (lists only become tuples: the listeners see tuples either way)
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        events = [("p", args((1,)), 1.0, 1.0), ("p", args((2,)), 3.0, 2.0),
                  ("fullyUpdated", ("p/1",), 5.0, 5.0),
                  ("p", args((Atom("\ud800"),)), 4.0, 4.0), ("p", args((5,)), 5.0, 5.0)]
        heard: list = []
        kb.add_listeners.append(heard.extend)
        prepared: list = []
        preparing = kb._prepare_events
        kb._prepare_events = lambda *a: prepared.append(a) or preparing(*a)  # type: ignore
        errors = kb.add_many(events)
        assert prepared == []
        assert [e.index for e in errors] == [1, 3]
        assert all(e.event is events[e.index] for e in errors)
        assert [(name, a) for name, a, *_ in heard] == [("p", (1,)), ("p", (5,))]  # (a mark
        # is not an event)
        assert kb.query("findall(X, p(X)^_, L)") == [{"L": [1, 5]}]
        assert kb.complete_until("p/1") >= 5.0


COLUMN_VALUES = st.one_of(
    st.lists(st.sampled_from([Atom("a"), Atom(""), Atom("[x"), Atom("{"), Atom('"q'), Atom("é"),
                              Atom("\ud800"), Atom("cup1")]), min_size=1, max_size=5),
    st.lists(st.text(max_size=3), min_size=1, max_size=5),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=1, max_size=5),
    st.lists(st.integers(-(2 ** 65), 2 ** 65), min_size=1, max_size=5),
    st.lists(ELEMENTS, min_size=1, max_size=5),
    st.lists(st.one_of(st.lists(ELEMENTS, max_size=3).map(make_list),
                       st.lists(ELEMENTS, min_size=1, max_size=2).map(
                           lambda items: make_list(items, Atom("tail"))),
                       st.just(Struct("f", (Atom("x"),)))), min_size=1, max_size=4),
    st.lists(st.lists(ELEMENTS, max_size=3), min_size=1, max_size=4),
)


@given(COLUMN_VALUES)
def test_a_column_encodes_as_its_values_do(values):
    from slr_sql.encoding import encode_column

    try:
        expected = [encode(v) for v in values]
    except Unencodable:
        expected = "refused"
    try:
        got = encode_column(list(values))
    except Unencodable:
        got = "refused"
    assert repr(got) == repr(expected)
    assert got == "refused" or [type(v) for v in got] == [type(v) for v in expected]


def test_the_same_bad_tuple_given_twice_is_rejected_at_both_places():
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        bad = ("p", (math.nan,), 1.0, 1.0)
        errors = kb.add_many([bad, ("p", (1,), 1.0, 1.0), bad])
        assert [e.index for e in errors] == [0, 2]
        assert kb.query("findall(X, p(X)^_, L)") == [{"L": [1]}]


# Numbers in every magnitude and at the integer limits of the C path (53 bits) and of the
# stored form (64 bits): where orjson's text is used it must be repr's, everywhere else the
# Python path must take over.
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e-3, max_value=1e-3),
    st.floats(min_value=1e15, max_value=1e17),
    st.integers(-(2 ** 65), 2 ** 65),
    st.sampled_from([2 ** 53, 2 ** 53 + 1, -(2 ** 53) - 1, 2 ** 63 - 1, 2 ** 63, -(2 ** 63),
                     1e-4, 1e-5, 9.999999999999999e-05, 1e16, 9999999999999998.0, 10.00001,
                     -0.0, 5e-324, 1.7976931348623157e308]),
)
VECTORS = st.lists(NUMBERS, max_size=7)


@given(VECTORS)
@example([1e-05, 0.0001, 1e16, 1e15, 2 ** 53 + 1, 2 ** 63, True])
def test_vectors_of_numbers_encode_as_the_general_encoder_does(items):
    for term in (items, tuple(items), make_list(items)):
        assert fast(term) == general(term)


@given(st.lists(VECTORS, min_size=1, max_size=3), st.sampled_from(["pose", "p_2", "é", "a\nb", "[]"]))
def test_compounds_of_number_lists_encode_as_the_general_encoder_does(lists, name):
    term = Struct(name, tuple(lists))
    assert fast(term) == general(term)
    assert fast(Struct(Atom(name), (lists[0], 1.5, 2))) == general(Struct(name, (lists[0], 1.5, 2)))


@given(st.lists(VECTORS, min_size=1, max_size=5))
def test_a_column_of_vectors_encodes_as_the_general_encoder_does(rows):
    from slr_sql.encoding import encode_column

    expected = [general(row) for row in rows]
    try:
        got = encode_column([list(row) for row in rows])
    except Unencodable as exc:
        assert any(isinstance(e, tuple) for e in expected), exc
    else:
        assert got == expected


@given(st.lists(st.tuples(st.sampled_from(["pose", "pose", "p_2", "é", "a\nb", "[]"]),
                          st.lists(st.one_of(VECTORS, NUMBERS), min_size=1, max_size=3)),
                min_size=1, max_size=5))
@example([("pose", [[0.5, 1], [0, 0, 0, 1.0]]), ("pose", [[1e-05], [2 ** 63]])])
def test_a_column_of_compounds_encodes_as_the_general_encoder_does(rows):
    # a column of poses is written by one orjson call and cut back into rows; any other
    # column of compounds (other names, bare numbers, big integers, a text repr spells
    # differently) takes the value-by-value path: the same texts either way
    from slr_sql.encoding import encode_column

    values = [Struct(name, tuple(args)) for name, args in rows]
    expected = [general(value) for value in values]
    try:
        got = encode_column(values)
    except Unencodable as exc:
        assert any(isinstance(e, tuple) for e in expected), exc
    else:
        assert got == expected


def test_the_c_float_text_is_repr_on_random_bit_patterns():
    import random
    import struct

    from slr_sql.encoding import _numbers_json

    rng = random.Random(20261122)
    used = 0
    for _ in range(200_000):
        (x,) = struct.unpack("<d", rng.getrandbits(64).to_bytes(8, "little"))
        for value in (x, rng.uniform(-1000, 1000), round(rng.uniform(-10, 10), 3)):
            text = _numbers_json([value])
            if text is not None:
                used += 1
                assert text == "[" + repr(value) + "]"
            elif math.isfinite(value):
                assert "e" in repr(value) or "0.0000" in repr(value), value
    assert used > 400_000  # the C path is taken for nearly every value


MIXED_EVENTS = st.lists(st.tuples(st.sampled_from(["p", "q", "r"]), EVENT_ARGS,
                                  st.floats(-1e6, 1e6), st.floats(0, 10)), max_size=12)


@given(MIXED_EVENTS, st.booleans())
@example([("p", (1, 2), 1.0, 0.0), ("q", (Atom("a"), make_list([1.0])), 0.5, 2.0),
          ("p", (3, 4), 2.0, 1.0)], False)
def test_a_batch_of_interleaved_types_stores_as_event_by_event_does(specs, named):
    # several names in one chunk: each name's events checked and inserted column-wise (one
    # executemany per table) when all are well-formed; the same rows, order, end spans and
    # rejections as the event-by-event path (forced here by one event with integer times)
    from slr_sql.store import EventBatch

    events = [(name, args, start, start + length) for name, args, start, length in specs]
    forced = events + [("marker", (), 0, 0)]
    robot = "r1" if named else None
    column, each = (EventStore(None, slr_sql.ManualClock(5.0), robot=robot) for _ in range(2))
    batches = EventBatch(events), EventBatch(forced)
    errors = [column.add_events(batches[0]), each.add_events(batches[1])]
    assert [(e.index, str(e)) for e in errors[0]] == [(e.index, str(e)) for e in errors[1]]
    for name in ("p", "q", "r"):
        table = column.declare_type(name, 2), each.declare_type(name, 2)
        rows = [store.execute(f'SELECT * FROM "{t}" ORDER BY seq')
                for store, t in zip((column, each), table)]
        assert repr(rows[0]) == repr(rows[1])  # repr: 1 and 1.0, 0.0 and -0.0 differ
    # (as lists: the types in the same order, that of their first event)
    assert list(batches[0].ends.items()) == [(key, span) for key, span in
                                             (batches[1].ends or {}).items()
                                             if key != ("marker", 0)]


def test_interleaved_types_take_the_column_path_and_a_bad_event_the_general_one():
    # the column path is taken for a valid interleaved chunk (one statement per table), and
    # refuses (storing nothing) a chunk with a bad event, which the general path then rejects
    store = EventStore(None)
    writer = store._writer
    arrival = 1.0
    good = [("a", (i,), float(i), float(i)) if i % 2 else ("b", (i, "x"), float(i), float(i))
            for i in range(10)]
    with store._db.transaction():
        assert writer._insert_uniform(good, arrival, None) is True
    assert store.count("a", 1) == 5 and store.count("b", 2) == 5
    bad = good[:3] + [("a", (math.nan,), 1.0, 1.0)] + good[3:]
    with store._db.transaction():
        assert writer._insert_uniform(bad, arrival, None) is False
    assert store.count("a", 1) == 5 and store.count("b", 2) == 5
    errors = store.add_events(bad)
    assert [e.index for e in errors] == [3]
    assert store.count("a", 1) == 10 and store.count("b", 2) == 10


@pytest.mark.parametrize("path", ["columns", "event by event"])
@pytest.mark.parametrize("robot", [None, "r1"])
def test_a_run_of_one_type_goes_in_with_a_few_multi_row_inserts_in_its_order(path, robot):
    # one statement per event costs ~35 % more than multi-row INSERTs of the same rows: 1,000
    # events of one type take at most one statement per power of two in 1,000 (and 1,000 rows
    # keep their order in seq); a bad event sends the chunk down the event-by-event path,
    # whose runs of one type go in the same way
    store = EventStore(None, slr_sql.ManualClock(5.0), robot=robot)
    events = [("p", (i, f"x{i}"), float(i), float(i)) for i in range(1000)]
    if path == "event by event":
        events.insert(500, ("p", (math.nan, "y"), 1.0, 1.0))
    inserts: list[str] = []
    store._db.conn.set_trace_callback(
        lambda sql: inserts.append(sql) if sql.startswith('INSERT INTO "p"') else None)
    try:
        errors = store.add_events(events)
    finally:
        store._db.conn.set_trace_callback(None)
    assert [e.index for e in errors] == ([500] if path == "event by event" else [])
    assert len(inserts) <= (2 * bin(500).count("1") if path == "event by event"
                            else bin(1000).count("1"))
    assert [args for args, *_ in store.scan("p", 2)] == [(i, f"x{i}") for i in range(1000)]
    robots = store._db.conn.execute('SELECT DISTINCT robot FROM "p"').fetchall()
    assert robots == [(robot,)]


@given(st.one_of(VECTORS, st.lists(VECTORS, min_size=1, max_size=3).map(
    lambda lists: Struct("pose", tuple(lists)))))
@example([2 ** 63 - 1, -(2 ** 63), 2 ** 63, 1e16, -0.0])
def test_stored_text_decodes_as_the_json_module_reads_it(value):
    # stored text is read by orjson; the json module, its reference, must agree on every
    # number the encoder writes (integers past 64 bits are written as {"$int": ...})
    import json

    from slr_sql.encoding import decode, term_from_json

    try:
        text = encode(value)
    except Unencodable:
        return
    if isinstance(text, str) and text[:1] in "[{":
        expected = term_from_json(json.loads(text))
        got = decode(text)
        assert repr(got) == repr(expected)
        assert decode(encode(got)) == got


def test_text_orjson_refuses_is_read_by_the_json_module():
    from slr_sql.encoding import decode

    assert decode('["\\ud800x", 1]') == make_list([Atom("\ud800x"), 1])
    assert decode("[1e400]") == make_list([math.inf])


_BEYOND_64_BITS = st.one_of(st.integers(2 ** 64, 2 ** 80), st.integers(-(2 ** 80), -(2 ** 63) - 1))


@given(st.lists(st.one_of(_BEYOND_64_BITS, st.integers(-5, 5), st.floats(-1e3, 1e3)),
                min_size=1, max_size=4))
@example([2 ** 64, -(2 ** 63) - 1, 0.5])
def test_bare_integers_beyond_64_bits_read_as_the_json_module_reads_them(numbers):
    # text written by another program (plain sqlite3, `slr sql --write`) may hold an integer
    # bare where the encoder writes {"$int": ...}; orjson reads one beyond 64 bits as a float
    import json

    from slr_sql.cep.where import plain_value
    from slr_sql.encoding import decode, decode_answer, load_json, term_from_json

    text = json.dumps(numbers)
    assert repr(load_json(text)) == repr(json.loads(text))
    assert repr(decode(text)) == repr(term_from_json(json.loads(text)))
    assert repr(decode_answer(text)) == repr(numbers)
    plain = plain_value(text)
    assert plain is None or repr(plain) == repr(numbers)


def test_an_integer_beyond_64_bits_written_by_sql_answers_exactly():
    with slr_sql.open(None, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("p([1, 2])^1")
        kb.sql('UPDATE "p" SET arg1 = ?', ["[18446744073709551617, 2]"], write=True)
        assert kb.query("p(X)^_") == [{"X": [18446744073709551617, 2]}]
