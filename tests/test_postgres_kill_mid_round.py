"""PostgreSQL: a writer SIGKILLed while the server runs its pipelined event-rule round.

The rule's statements of one add (the provenance rows, the copy into the complex type's
table, the pending summary) go to the server in one pipeline; the writer is killed while
the server is inside them (a trigger another session put on the complex type's table
sleeps, so the kill lands there, not before or after). The server rolls the transaction
back when it finds the client gone: none of that add's events, matches or pending rows
are stored, and the next writer derives each complex event once.
"""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock

REPO = Path(__file__).resolve().parent.parent
DEADLINE = 30.0   # seconds; each wait ends as soon as its condition holds
pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="needs SIGKILL")

WRITER = r"""
import sys
import slr_sql
from slr_sql import ManualClock
with slr_sql.open(sys.argv[1], clock=ManualClock(10.0)) as kb:
    kb.add_many(["a(2)^3", "b(2)^4"])
print("returned", flush=True)
"""


def _wait_for(conn: psycopg.Connection, sql: str, want: bool) -> None:
    deadline = time.monotonic() + DEADLINE
    while bool(conn.execute(sql).fetchone()[0]) != want:
        assert time.monotonic() < deadline, sql
        time.sleep(0.02)


@pytest.mark.parametrize("policy", ["unrestricted", "recent", "chronological"])
def test_a_writer_killed_inside_its_rule_round_leaves_nothing_half_stored(postgres_url,
                                                                         tmp_path, policy):
    program = (f":- consumption({policy}).\n:- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n"
               "c(X) <- a(X) seq b(X).\n")
    with psycopg.connect(postgres_url, autocommit=True) as admin:
        database = admin.execute("SELECT current_database()").fetchone()[0]
        # (the server checks for a vanished client while a statement runs)
        admin.execute(f'ALTER DATABASE "{database}" SET client_connection_check_interval = 50')
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.load(program)
        kb.add_many(["a(1)^1", "b(1)^2"])
    with psycopg.connect(postgres_url, autocommit=True) as other:
        other.execute("SET search_path = slr")
        other.execute("CREATE FUNCTION slr_test_slow() RETURNS trigger LANGUAGE plpgsql AS "
                      "$$ BEGIN IF NEW.arg1 = '2' THEN PERFORM pg_sleep(60); END IF; "
                      "RETURN NEW; END $$")
        other.execute("CREATE TRIGGER slow BEFORE INSERT ON c "
                      "FOR EACH ROW EXECUTE FUNCTION slr_test_slow()")
        script = tmp_path / "writer.py"
        script.write_text(WRITER)
        child = subprocess.Popen([sys.executable, str(script), postgres_url],
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                 env=dict(os.environ, PYTHONPATH=str(REPO)))
        try:
            sleeping = ("SELECT count(*) FROM pg_stat_activity WHERE datname = "
                        "current_database() AND wait_event = 'PgSleep'")
            _wait_for(other, sleeping, True)
            child.kill()
            assert child.wait(timeout=DEADLINE) != 0
            _wait_for(other, sleeping, False)   # (the server rolled the transaction back)
        finally:
            if child.poll() is None:
                child.kill()
                child.wait()
        counts = [other.execute(f"SELECT count(*) FROM {t}").fetchone()[0]
                  for t in ("a", "b", "c", "slr_cep_pending")]
        prov = other.execute("SELECT prov_table FROM slr_cep_rules").fetchone()[0]
        assert counts + [other.execute(f'SELECT count(*) FROM "{prov}"').fetchone()[0]] == \
            [1, 1, 1, 0, 1]
        other.execute("DROP TRIGGER slow ON c")
    with slr_sql.open(postgres_url, clock=ManualClock(10.0)) as kb:
        kb.add_many(["a(2)^3", "b(2)^4"])
        assert sorted((r["X"], r["S"], r["E"]) for r in kb.query("c(X)^[S, E]")) == \
            [(1, 1.0, 2.0), (2, 3.0, 4.0)]
