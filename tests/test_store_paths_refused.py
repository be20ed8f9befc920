"""The commands that only read a store refuse a path that holds none (missing, or an empty
file SQLite would turn into a database) with one check and one message, and take a
PostgreSQL URL as every command taking DB does (docs/postgres.md): `slr fleet push URL
FLEET` ships a robot store that lives on a server."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock
from test_cli import slr
from test_fleet_routes import seen


def test_fleet_push_ships_a_robot_store_on_postgresql(tmp_path, postgres_url):
    with slr_sql.open(postgres_url, robot="r1", clock=ManualClock(1000)) as kb:
        kb.add_many(["seen(a)^10", "seen(b)^20"])
    fleet_db = str(tmp_path / "fleet.db")
    done = slr("fleet", "push", postgres_url, fleet_db)
    assert done.returncode == 0, done.stderr
    assert seen(fleet_db) == [("r1", "a", 10.0), ("r1", "b", 20.0)]


@pytest.mark.parametrize("command", [
    ["stats", "{db}"], ["export", "{db}", "{out}"], ["fleet", "push", "{db}", "{out}"],
    ["fleet", "status", "{db}"]])
def test_a_reading_command_says_an_empty_file_is_no_store_in_the_same_words(tmp_path, command):
    db = tmp_path / "robot.db"
    db.write_bytes(b"")
    out = tmp_path / "out.mcap"
    done = slr(*[part.format(db=db, out=out) for part in command])
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stderr == (f"error: no such store: {db} is an empty file (only load, add, "
                           f"ingest, run, demo and serve create a store)\n")
    assert not out.exists() and db.stat().st_size == 0


@pytest.mark.parametrize("command", [
    ["export", "{url}", "{out}"], ["fleet", "push", "{url}", "{out}.db"],
    ["foxglove", "{url}"]])
def test_a_command_that_needs_the_store_itself_says_so_of_a_servers_url(tmp_path, command):
    # (the URL of slr serve, which most commands take for DB: it was called no PostgreSQL URL)
    url = "http://127.0.0.1:9"
    out = tmp_path / "out"
    done = slr(*[part.format(url=url, out=out) for part in command])
    assert done.returncode == 1, (done.stdout, done.stderr)
    assert done.stderr.startswith(f"error: {url}: the URL of a server (slr serve), not a "
                                  f"store: this needs the store itself"), done.stderr
    assert list(tmp_path.iterdir()) == []


def test_slr_plot_draws_a_served_store_as_the_help_says_db_may_be(tmp_path):
    # `slr plot URL` was refused before it connected, though kb.plot draws a served store
    # through its SQL and the help says DB may be the URL of slr serve
    from service_helpers import ServiceProcess

    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=ManualClock(100)) as kb:
        kb.add_many(["seen(a)^10", "seen(b)^20"])
    out = tmp_path / "served.png"
    with ServiceProcess(db) as server:
        done = slr("plot", server.url, "-o", str(out))
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(f"wrote {out} (") and out.stat().st_size > 0
