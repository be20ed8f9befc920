"""slr export against the mcap writer alone, on the same messages.

    python benchmarks/bench_export.py               # 200,000 events, best of 3
    python benchmarks/bench_export.py --events 1000000 --repeat 1

The store holds N events of three types (seg(Object, [X,Y,Z]) vectors, tf poses, battery
numbers). The export (``export_mcap``: reading the store a page at a time, merging the types
by end time, writing each event as JSON, plus FrameTransforms for tf) is timed against the
mcap ``Writer`` alone writing the very same message bytes to the same channels with the same
compression (bytes prepared beforehand, not timed). The figure: export throughput / writer
throughput (target >= 0.5), in the same run: the two sides run ``--repeat`` times in
alternation (both meet the same machine state), the best of each is compared, in wall time
and in the process's CPU time (user + system: what a load of other processes moves least).
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from slr_sql import Struct  # noqa: E402
from slr_sql.viz.mcap_export import export_mcap  # noqa: E402


def build(path: Path, n: int) -> None:
    with slr_sql.open(str(path), clock=slr_sql.ManualClock(0.0), synchronous="OFF") as kb:
        batch = []
        for i in range(n):
            t = i * 0.001
            k = i % 3
            if k == 0:
                batch.append(("seg", (f"cup{i % 50}", [0.1 * (i % 7), 0.2, 0.3]), t, t))
            elif k == 1:
                batch.append(("tf", ("map", "base", Struct("pose", ([t, 0.0, 0.0],
                                                                    [0.0, 0.0, 0.0, 1.0]))), t, t))
            else:
                batch.append(("battery", (24.0 - t * 1e-3,), t, t))
            if len(batch) == 50_000:
                kb.add_many(batch)
                batch = []
        kb.add_many(batch)


def writer_alone(out: Path, messages: list) -> tuple[float, float]:
    from mcap.writer import CompressionType, Writer

    with open(out, "wb") as stream:
        t0, c0 = time.perf_counter(), time.process_time()
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile="", library="bench")
        ids = {}
        for topic, schema in sorted({(m[0], m[1]) for m in messages}):
            sid = writer.register_schema(schema, "jsonschema", b"{}")
            ids[topic] = writer.register_channel(topic, "json", sid, {})
        add = writer.add_message
        for topic, _, log_time, data, publish_time, seq in messages:
            add(ids[topic], log_time, data, publish_time, seq)
        writer.finish()
        return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--events", type=int, default=200_000)
    parser.add_argument("--repeat", type=int, default=3,
                        help="runs of each side, in alternation (the best of each compared)")
    args = parser.parse_args()
    from mcap.reader import make_reader

    load = os.getloadavg()
    exports, alones = [], []
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "r.db"
        build(db, args.events)
        messages = None
        for _ in range(args.repeat):
            with slr_sql.open(str(db)) as kb:
                t0, c0 = time.perf_counter(), time.process_time()
                report = export_mcap(kb.store, Path(tmp) / "export.mcap")
                exports.append((time.perf_counter() - t0, time.process_time() - c0))
            if messages is None:
                with open(Path(tmp) / "export.mcap", "rb") as stream:
                    reader = make_reader(stream)
                    schemas = {s.id: s.name for s in reader.get_summary().schemas.values()}
                    messages = [(c.topic, schemas[c.schema_id], m.log_time, m.data,
                                 m.publish_time, m.sequence)
                                for _, c, m in reader.iter_messages(log_time_order=False)]
            alones.append(writer_alone(Path(tmp) / "alone.mcap", messages))
    n = len(messages)
    export_s, export_cpu = min(e[0] for e in exports), min(e[1] for e in exports)
    alone_s, alone_cpu = min(a[0] for a in alones), min(a[1] for a in alones)
    print(f"events {report.messages}, messages {n} (tf also as FrameTransforms); "
          f"load average {load[0]:.1f} before, {os.getloadavg()[0]:.1f} after")
    print("runs (wall / CPU s): export " + ", ".join(f"{w:.2f}/{c:.2f}" for w, c in exports)
          + "; writer alone " + ", ".join(f"{w:.2f}/{c:.2f}" for w, c in alones))
    print(f"slr export      {export_s:7.3f} s  {n / export_s:10.0f} messages/s  "
          f"(CPU {export_cpu:.3f} s)")
    print(f"mcap writer     {alone_s:7.3f} s  {n / alone_s:10.0f} messages/s  "
          f"(CPU {alone_cpu:.3f} s)")
    print(f"ratio export / writer alone (throughput): {alone_s / export_s:.2f} wall, "
          f"{alone_cpu / export_cpu:.2f} CPU  (target >= 0.5)")


if __name__ == "__main__":
    main()
