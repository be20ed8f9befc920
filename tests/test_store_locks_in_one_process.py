"""Two knowledge bases on one store in one process (threads of an application, `slr serve
--foxglove`: the service's and the Foxglove view's) keep the store's locks while a third
opens: POSIX drops every lock a process holds on a file when the process closes any
descriptor of it, and opening a store read its header through a descriptor of its own. With
the first knowledge base's lock gone, the next other process to close the store took itself
for its last user: it checkpointed and deleted the -wal and -shm, and every later write of
the process was refused (SLRStoreGone: the log deleted) until it was restarted."""
from __future__ import annotations

import subprocess
import sys

import slr_sql
from slr_sql import ManualClock
from service_helpers import slr_env
from test_cli import slr


def _open_and_close_elsewhere(db) -> None:
    """Another process reads the store and closes it (as `slr query DB` does)."""
    subprocess.run([sys.executable, "-c", "import sqlite3, sys\n"
                    "conn = sqlite3.connect(sys.argv[1])\n"
                    "conn.execute('SELECT count(*) FROM slr_meta').fetchall()\n"
                    "conn.close()", str(db)], check=True, timeout=60)


def test_a_second_knowledge_base_in_the_process_keeps_the_firsts_locks(tmp_path):
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=ManualClock(10)) as first:
        first.add("seen(a)^1")
        with slr_sql.open(db, clock=ManualClock(10)) as second:
            _open_and_close_elsewhere(db)
            assert (tmp_path / "robot.db-wal").exists()
            first.add("seen(b)^2")
            assert [str(a["X"]) for a in second.query("seen(X)^_")] == ["a", "b"]


def test_a_reader_of_the_file_beside_a_served_store_with_its_foxglove_view_breaks_nothing(
        tmp_path):
    db = tmp_path / "robot.db"
    server = subprocess.Popen([sys.executable, "-m", "slr_sql", "serve", str(db), "--port", "0",
                               "--foxglove", "--foxglove-port", "0"], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=slr_env())
    try:
        assert server.stdout.readline().startswith("slr serve: foxglove on ws://")
        url = server.stdout.readline().split(" on ")[1].strip()
        added = slr("add", url, "seen(a)^1")
        assert added.returncode == 0, added.stderr
        asked = slr("query", str(db), "seen(X)^_")     # another process, on the file
        assert asked.stdout == "X = a\n", asked.stderr
        added = slr("add", url, "seen(b)^2")
        assert added.returncode == 0, added.stderr
        assert slr("query", url, "seen(X)^_").stdout == "X = a\nX = b\n"
    finally:
        server.terminate()
        server.communicate(timeout=60)
