"""slr export DB FILE.mcap: read back with the mcap reader (channels, schemas, log and
publish times, FrameTransforms), and imported by slr ros import into the same events."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from hypothesis import HealthCheck, given, settings, strategies as st
from mcap.reader import make_reader

import slr_sql
from slr_sql import Atom, ManualClock, StreamClock, String, Struct
from slr_sql.ros.bag_import import import_bag
from slr_sql.viz.mcap_export import export_mcap

REPO = Path(__file__).resolve().parent.parent


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, timeout=60, env={**os.environ, "PYTHONPATH": str(REPO)})


def everything(kb) -> dict:
    """Every stored event of every type (but the import log), in store order."""
    out = {}
    for (name, arity) in kb.store.event_types():
        if name == "slr_import":
            continue
        args = ", ".join(f"A{i}" for i in range(arity))
        goal = f"{name}({args})^[S, E]" if arity else f"{name}^[S, E]"
        out[(name, arity)] = [tuple(a.values()) for a in kb.query(goal)]
    return out


def robot_store(path: Path, clock=None):
    kb = slr_sql.open(path, clock=clock or ManualClock(100.0))
    kb.add_many([
        ("seg", ("cup1", [0.4, 0.1, 0.9]), 1.0, 1.0),
        ("seg", ("cup2", [1, 2, 3]), 2.0, 2.0),
        ("said", (String("hello world"), Atom("[x")), 1.5, 1.75),
        ("tf", ("map", "base", Struct("pose", ([1.0, 2.0, 0.0], [0.0, 0.0, 0.6, 0.8]))), 1.25, 1.25),
        ("tf_static", ("base", "cam", Struct("pose", ([0.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]))), 0.0, 0.0),
        ("goal", (Struct("geometry_msgs/msg/Point", (Struct(":", (Atom("x"), 1.0)),
                                                     Struct(":", (Atom("y"), -2)))),), 3.0, 3.0),
        ("ping", (), 2.5, 2.5),
    ])
    kb.mark_complete("seg/2", 2.0)
    return kb


def test_the_mcap_reader_reads_every_channel_time_and_message(tmp_path):
    clock = ManualClock(100.0)
    with robot_store(tmp_path / "r.db", clock) as kb:
        report = export_mcap(kb.store, tmp_path / "out.mcap")
    assert report.messages == 7
    with open(tmp_path / "out.mcap", "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        messages = list(reader.iter_messages(log_time_order=True))
    topics = {c.topic: c for c in summary.channels.values()}
    assert set(topics) == {"/seg/2", "/said/2", "/tf/3", "/tf_static/3", "/goal/1", "/ping/0",
                           "/tf", "/tf_static", "/slr/completeness"}
    seg = topics["/seg/2"]
    assert seg.metadata == {"slr_event": "seg", "slr_arity": "2"}
    assert summary.schemas[seg.schema_id].name == "slr.seg/2"
    assert summary.schemas[topics["/tf"].schema_id].name == "foxglove.FrameTransforms"
    seg_messages = [(m.log_time, m.publish_time, json.loads(m.data)) for _, c, m in messages
                    if c.topic == "/seg/2"]
    assert seg_messages == [
        (1_000_000_000, 100_000_000_000,
         {"arg1": "cup1", "arg2": [0.4, 0.1, 0.9], "start": 1.0, "end": 1.0, "arrival": 100.0}),
        (2_000_000_000, 100_000_000_000,
         {"arg1": "cup2", "arg2": [1, 2, 3], "start": 2.0, "end": 2.0, "arrival": 100.0})]
    # log-time order across types
    times = [m.log_time for _, c, m in messages]
    assert times == sorted(times)
    (_, _, tf), = [(0, c, m) for _, c, m in messages if c.topic == "/tf"]
    (frame,) = json.loads(tf.data)["transforms"]
    assert frame["timestamp"] == {"sec": 1, "nsec": 250_000_000}
    assert (frame["parent_frame_id"], frame["rotation"]["z"]) == ("map", 0.6)
    goal = [json.loads(m.data) for _, c, m in messages if c.topic == "/goal/1"]
    assert goal[0]["arg1"] == {"$type": "geometry_msgs/msg/Point", "x": 1.0, "y": -2}
    mark = [json.loads(m.data) for _, c, m in messages if c.topic == "/slr/completeness"]
    assert mark == [{"type": "seg/2", "until": 2.0, "source": mark[0]["source"]}]


def test_slr_ros_import_of_an_export_gives_back_the_same_events(tmp_path):
    with robot_store(tmp_path / "r.db") as kb:
        before = everything(kb)
    out = slr("export", str(tmp_path / "r.db"), str(tmp_path / "out.mcap"))
    assert out.returncode == 0, out.stderr
    assert "exported 7 events" in out.stdout
    done = slr("ros", "import", str(tmp_path / "out.mcap"), str(tmp_path / "back.db"))
    assert done.returncode == 0, done.stderr
    again = slr("ros", "import", str(tmp_path / "out.mcap"), str(tmp_path / "back.db"))
    assert "imported 0 events" in again.stdout and "7 already imported" in again.stdout
    with slr_sql.open(tmp_path / "back.db") as kb:
        assert everything(kb) == before
        assert kb.complete_until("seg/2") >= 2.0


# A store that imports a bag gets a StreamClock (recorded data: now is the greatest end time
# imported), as `slr ros import` would want it; a wall clock calls each message "decades late".
def test_from_to_and_types_choose_what_is_exported(tmp_path):
    with robot_store(tmp_path / "r.db") as kb:
        kb.add_many([("seg", ("cup3", [0, 0, 0]), 9.0, 9.0), ("seg", ("cup3", [0, 0, 1]), 1, 2)])
    out = slr("export", str(tmp_path / "r.db"), str(tmp_path / "part.mcap"), "seg", "tf/3",
              "--from", "1.5", "--to", "5")
    assert out.returncode == 0, out.stderr
    with slr_sql.open(None, clock=StreamClock()) as kb:
        import_bag(kb, tmp_path / "part.mcap")
        assert everything(kb) == {
            ("seg", 2): [(Atom("cup3"), [0, 0, 1], 1.0, 2.0), (Atom("cup2"), [1, 2, 3], 2.0, 2.0)]}
    bad = slr("export", str(tmp_path / "r.db"), str(tmp_path / "x.mcap"), "nosuch")
    assert bad.returncode == 1 and "no event type nosuch" in bad.stderr
    assert "Traceback" not in bad.stderr


terms = st.recursive(
    st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.integers(-2**63, 2**63 - 1),
              st.sampled_from([Atom("a"), Atom("[]"), Atom("{x"), String("s"), Atom("")])),
    lambda inner: st.one_of(st.lists(inner, max_size=3),
                            st.builds(lambda args: Struct("f", tuple(args)),
                                      st.lists(inner, min_size=1, max_size=3))),
    max_leaves=8)


DECLARED = ":- max_delay(p/1, 1). :- max_delay(q/1, 1). :- max_delay(slr_import/3, 1)."


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(events=st.lists(st.tuples(st.sampled_from(["p", "q"]), terms,
                                 st.floats(-1e6, 1e6, allow_nan=False)), min_size=1, max_size=12))
def test_round_trip_of_random_events(tmp_path_factory, events):
    tmp = tmp_path_factory.mktemp("rt")
    with slr_sql.open(tmp / "a.db", clock=ManualClock(1e7)) as kb:
        kb.load(DECLARED)   # times far from the clock: no delays to learn
        kb.add_many([(name, (term,), t, t) for name, term, t in events])
        before = everything(kb)
        export_mcap(kb.store, tmp / "a.mcap")
    with slr_sql.open(tmp / "b.db", clock=ManualClock(1e7)) as kb:
        kb.load(DECLARED)
        import_bag(kb, tmp / "a.mcap")
        assert everything(kb) == before


def _messages(path: Path) -> list:
    with open(path, "rb") as stream:
        return [(c.topic, m.log_time, json.loads(m.data))
                for _, c, m in make_reader(stream).iter_messages(log_time_order=True)]


def test_an_export_of_a_postgresql_store_is_the_export_of_the_same_sqlite_store(
        tmp_path, postgres_url):
    """docs/ros.md: `slr export` takes a postgresql:// URL too. Its reads had `WHERE 1`, which
    PostgreSQL refuses (a WHERE needs a boolean): every export of a server store failed."""
    with robot_store(tmp_path / "r.db") as kb:
        export_mcap(kb.store, tmp_path / "sqlite.mcap")
    with robot_store(postgres_url) as kb:
        report = export_mcap(kb.store, tmp_path / "postgres.mcap")
    assert report.messages == 7
    assert _messages(tmp_path / "postgres.mcap") == _messages(tmp_path / "sqlite.mcap")
    out = slr("export", postgres_url, str(tmp_path / "cli.mcap"), "seg")
    assert out.returncode == 0, out.stderr
    assert [m for m in _messages(tmp_path / "cli.mcap") if m[0] == "/seg/2"] == \
        [m for m in _messages(tmp_path / "sqlite.mcap") if m[0] == "/seg/2"]


def test_an_export_of_large_events_holds_one_bounded_page_at_a_time(tmp_path, monkeypatch):
    import random
    import string
    import tracemalloc

    from slr_sql.viz import mcap_export
    # a 2 MiB page instead of 32, so that a store of 24 MB shows the bound
    monkeypatch.setattr(mcap_export, "PAGE_BYTES", 2 << 20)
    letters = random.Random(3)
    texts = ["".join(letters.choices(string.ascii_letters, k=1 << 20)) for _ in range(24)]
    with slr_sql.open(tmp_path / "big.db", clock=ManualClock(100.0)) as kb:
        for i, text in enumerate(texts):   # a megabyte each: the type does not fit one page
            kb.add_event("scan", [String(text), i], float(i + 1))
        tracemalloc.start()
        try:
            report = export_mcap(kb.store, tmp_path / "big.mcap")
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
    assert report.per_type == {("scan", 2): 24}
    # a page (two events), the message being written and the writer's chunk; reading every
    # row in one statement held all 24 MB
    assert peak < 12 << 20, peak
    with open(tmp_path / "big.mcap", "rb") as stream:
        sizes = [len(m.data) for _, _, m in make_reader(stream).iter_messages()]
    assert len(sizes) == 24 and min(sizes) > 1 << 20


def test_an_export_of_several_types_read_in_small_pages_merges_them_in_time_order(
        tmp_path, monkeypatch):
    """The types' histories are merged page by page: with pages of 3 rows, every message is
    in (end, start, type, seq) order, each written once, each FrameTransforms right after
    its tf event, and progress is told at every 10,000th."""
    from slr_sql.viz import mcap_export
    monkeypatch.setattr(mcap_export, "PAGE", 3)
    with slr_sql.open(tmp_path / "r.db", clock=ManualClock(100.0)) as kb:
        batch = []
        for i in range(400):
            end = float(i // 4)         # equal end times across and within types
            batch.append(("a" if i % 3 else "b", (i,), end - (i % 2), end))
            if i % 7 == 0:
                batch.append(("tf", ("map", f"f{i}", Struct("pose", ([1.0, 2.0, 3.0],
                                                                     [0.0, 0.0, 0.0, 1.0]))),
                              end, end))
        kb.add_many(batch)
        kb.add_many([("c", (j,), float(j), float(j)) for j in range(20_500)])
        seen = []
        report = export_mcap(kb.store, tmp_path / "out.mcap", progress=seen.append)
        stored = kb.store
        expected = sorted(
            (row[n + 1], row[n], index, row[n + 3])
            for index, (name, n) in enumerate(sorted(stored.event_types()))
            for row in stored.raw_rows(name, n))
    assert report.messages == len(expected) == 400 + 58 + 20_500
    assert seen == [10_000, 20_000]
    with open(tmp_path / "out.mcap", "rb") as stream:
        written = [(c.topic, m.log_time, m.sequence, json.loads(m.data))
                   for _, c, m in make_reader(stream).iter_messages(log_time_order=False)]
    events = [(end, start, topic) for topic, _, _, m in written if topic != "/tf"
              for end, start in [(m["end"], m["start"])]]
    names = sorted(kb_type for kb_type in ("a", "b", "c", "tf"))
    assert [(e, s, f"/{names[i]}/{3 if names[i] == 'tf' else 1}") for e, s, i, _ in expected] \
        == events
    transforms = [i for i, w in enumerate(written) if w[0] == "/tf"]
    assert len(transforms) == 58
    for i in transforms:   # right after its tf event, with the same times and sequence
        assert written[i - 1][0] == "/tf/3" and written[i - 1][1:3] == written[i][1:3]
