"""A robot store restored from an older backup (docs/fleet.md, "A robot store restored").

Its AUTOINCREMENT counters go back with the file, so its new events reuse sequences the fleet
store holds already; shipping from the fleet's positions would skip them without a word until
the sequences passed the old position. A push notices the robot's counter below the fleet's
position and refuses (RobotStoreRestored, nothing shipped); ``--resync`` ships every type
again from its first row, the fleet skipping the rows it holds identically: the fleet ends
with every event once. Through real ``slr fleet push`` processes, into a fleet store file and
into a served one.
"""
from __future__ import annotations

import shutil
import sqlite3
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
from service_helpers import ServiceProcess, slr_env

import slr_sql
from slr_sql import fleet
from slr_sql.fleet import RobotStoreRestored

ROOT = Path(__file__).resolve().parent.parent


def slr(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, env=slr_env(), cwd=ROOT, timeout=120)


def add(db: Path, events: list[str], now: float) -> None:
    with slr_sql.open(str(db), robot="r1", clock=slr_sql.ManualClock(now)) as kb:
        for event in events:
            kb.add(event)


def backup(db: Path, to: Path) -> None:
    """A copy of the robot's store as a backup tool makes it: every commit in the main
    file (the WAL checkpointed and emptied), the file copied."""
    conn = sqlite3.connect(db)
    try:
        conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall()
    finally:
        conn.close()
    shutil.copyfile(db, to)


def restore(copy: Path, db: Path) -> None:
    for suffix in ("-wal", "-shm"):
        Path(str(db) + suffix).unlink(missing_ok=True)
    shutil.copyfile(copy, db)


def fleet_events(fleet_db: Path) -> Counter:
    """Every event of robot r1 in the fleet store, as (name, args..., start, end), counted."""
    conn = sqlite3.connect(fleet_db, timeout=30)
    try:
        out: Counter = Counter()
        for name, arity, table in conn.execute(
                "SELECT name, arity, table_name FROM slr_event_types"):
            args = "".join(f"arg{i}, " for i in range(1, arity + 1))
            for row in conn.execute(f'SELECT {args}t_start, t_end FROM "{table}" '
                                    "WHERE robot = 'r1'"):
                out[(name, *row)] += 1
        return out
    finally:
        conn.close()


def expected(*groups: list[str]) -> Counter:
    """The events ``seen(cN)^T`` / ``moved(cN, dock)^T`` as the fleet stores them."""
    out: Counter = Counter()
    for group in groups:
        for event in group:
            head, t = event.rsplit("^", 1)
            name, args = head.rstrip(")").split("(")
            out[(name, *args.split(", "), float(t), float(t))] += 1
    return out


def events(prefix: str, first: int, count: int) -> list[str]:
    """``count`` events of two types, with times from ``first`` (distinct per ``prefix``)."""
    return [f"seen({prefix}{i})^{i}" if i % 2 else f"moved({prefix}{i}, dock)^{i}"
            for i in range(first, first + count)]


@pytest.fixture(params=["file", "served"])
def fleet_target(request, tmp_path):
    """Where the robot ships: a fleet store file, or the same file served by `slr serve`;
    yields (what `slr fleet push` is given, the fleet store's file)."""
    fleet_db = tmp_path / "fleet.db"
    if request.param == "file":
        yield str(fleet_db), fleet_db
        return
    with ServiceProcess(fleet_db) as served:
        yield served.url, fleet_db


def shipped(done: subprocess.CompletedProcess) -> int:
    assert done.returncode == 0, done.stderr
    return int(done.stdout.split("shipped ")[1].split()[0])


def test_a_restored_robot_store_is_refused_then_resynced_with_every_event_once(
        tmp_path, fleet_target):
    target, fleet_db = fleet_target
    db, copy = tmp_path / "r1.db", tmp_path / "r1.backup.db"
    first, lost, after = events("a", 1, 10), events("b", 11, 5), events("c", 21, 3)
    add(db, first, 100.0)
    assert shipped(slr("fleet", "push", str(db), target)) == 10
    backup(db, copy)
    add(db, lost, 200.0)
    assert shipped(slr("fleet", "push", str(db), target)) == 5
    restore(copy, db)
    add(db, after, 300.0)

    # the events after the restore reuse sequences the fleet holds: refused, in words
    done = slr("fleet", "push", str(db), target)
    assert done.returncode != 0
    assert "restored from an older backup" in done.stderr and "--resync" in done.stderr
    assert "Traceback" not in done.stderr
    assert fleet_events(fleet_db) == expected(first, lost)   # nothing shipped, nothing lost

    # a following pusher stops with the same words (waiting would ship with a hole)
    done = slr("fleet", "push", "--follow", str(db), target)
    assert done.returncode != 0 and "--resync" in done.stderr

    assert shipped(slr("fleet", "push", "--resync", str(db), target)) == 3
    held = fleet_events(fleet_db)
    assert held == expected(first, lost, after)
    assert sum(held.values()) == 18 and set(held.values()) == {1}

    # from here on, plain pushes ship what is new and nothing twice
    assert shipped(slr("fleet", "push", str(db), target)) == 0
    more = events("d", 31, 2)
    add(db, more, 400.0)
    assert shipped(slr("fleet", "push", str(db), target)) == 2
    assert fleet_events(fleet_db) == expected(first, lost, after, more)


def test_resync_after_the_counter_passed_the_fleets_position_ships_every_new_event(tmp_path):
    # more events after the restore than were lost: the robot's counter is past the fleet's
    # position again, so a push cannot tell (docs/fleet.md); --resync still ships them all
    db, copy, fleet_db = tmp_path / "r1.db", tmp_path / "r1.backup.db", tmp_path / "fleet.db"
    first, lost, after = events("a", 1, 10), events("b", 11, 5), events("c", 21, 8)
    add(db, first, 100.0)
    fleet.push(str(db), str(fleet_db))
    backup(db, copy)
    add(db, lost, 200.0)
    fleet.push(str(db), str(fleet_db))
    restore(copy, db)
    add(db, after, 300.0)
    assert fleet.push(str(db), str(fleet_db), resync=True, batch=2).shipped == 8
    assert fleet_events(fleet_db) == expected(first, lost, after)
    assert fleet.push(str(db), str(fleet_db)).shipped == 0


def test_a_restored_store_is_refused_in_process_with_nothing_shipped(tmp_path):
    db, copy, fleet_db = tmp_path / "r1.db", tmp_path / "r1.backup.db", tmp_path / "fleet.db"
    add(db, events("a", 1, 4), 100.0)
    fleet.push(str(db), str(fleet_db))
    backup(db, copy)
    add(db, events("b", 11, 4), 200.0)
    fleet.push(str(db), str(fleet_db))
    restore(copy, db)
    add(db, events("c", 21, 1), 300.0)
    with pytest.raises(RobotStoreRestored, match="up to seq"):
        fleet.push(str(db), str(fleet_db))
    assert sum(fleet_events(fleet_db).values()) == 8


def test_a_resync_tells_an_integer_from_the_same_float(tmp_path):
    """A lost event p(1)^1 and a new p(1.0)^1 are different terms: the resync stores the
    new one beside the old."""
    db, copy, fleet_db = tmp_path / "r1.db", tmp_path / "r1.backup.db", tmp_path / "fleet.db"
    add(db, ["p(0)^0"], 100.0)
    fleet.push(str(db), str(fleet_db))
    backup(db, copy)
    add(db, ["p(1)^1"], 200.0)
    fleet.push(str(db), str(fleet_db))
    restore(copy, db)
    add(db, ["p(1.0)^1"], 300.0)
    fleet.push(str(db), str(fleet_db), resync=True)
    with slr_sql.open(str(fleet_db)) as kb:
        assert sorted((type(r["X"]).__name__, r["X"]) for r in kb.query("p(X)^_")) == \
            [("float", 1.0), ("int", 0), ("int", 1)]


def test_a_buffer_that_empties_a_table_is_not_taken_for_a_restore(tmp_path):
    # the counter, not the greatest stored seq: rows deleted on the robot after shipping
    db, fleet_db = tmp_path / "r1.db", tmp_path / "fleet.db"
    add(db, events("a", 1, 6), 100.0)
    fleet.push(str(db), str(fleet_db))
    conn = sqlite3.connect(db)
    try:
        for (table,) in conn.execute("SELECT table_name FROM slr_event_types").fetchall():
            conn.execute(f'DELETE FROM "{table}"')
        conn.commit()
    finally:
        conn.close()
    add(db, events("b", 11, 2), 200.0)
    assert fleet.push(str(db), str(fleet_db)).shipped == 2
    assert sum(fleet_events(fleet_db).values()) == 8


def answers(where: str) -> Counter:
    """The events of a store (any backend) as (name, args..., start, end), counted."""
    with slr_sql.open(where, clock=slr_sql.ManualClock(1000.0)) as kb:
        out: Counter = Counter()
        for a in kb.query("seen(X)^T"):
            out[("seen", str(a["X"]), a["T"], a["T"])] += 1
        for a in kb.query("moved(X, Y)^T"):
            out[("moved", str(a["X"]), str(a["Y"]), a["T"], a["T"])] += 1
        return out


def test_a_postgresql_fleet_store_resyncs_a_restored_robot_with_every_event_once(
        tmp_path, postgres_url):
    db, copy = tmp_path / "r1.db", tmp_path / "r1.backup.db"
    first, lost, after = events("a", 1, 6), events("b", 11, 4), events("c", 21, 2)
    add(db, first, 100.0)
    fleet.push(str(db), postgres_url)
    backup(db, copy)
    add(db, lost, 200.0)
    fleet.push(str(db), postgres_url)
    restore(copy, db)
    add(db, after, 300.0)
    with pytest.raises(RobotStoreRestored):
        fleet.push(str(db), postgres_url)
    assert fleet.push(str(db), postgres_url, resync=True).shipped == 2
    assert answers(postgres_url) == expected(first, lost, after)
    assert fleet.push(str(db), postgres_url).shipped == 0


def test_a_postgresql_robot_stores_counters_go_back_only_with_its_sequences(
        tmp_path, postgres_url):
    # a PostgreSQL robot store: deleted rows keep the counter (no false refusal); a restore
    # of an older dump sets the identity sequences back (pg_dump writes their setval)
    import psycopg

    fleet_db = tmp_path / "fleet.db"
    with slr_sql.open(postgres_url, robot="r1", clock=slr_sql.ManualClock(100.0)) as kb:
        for event in events("a", 1, 6):
            kb.add(event)
    assert fleet.push(postgres_url, str(fleet_db)).shipped == 6
    with psycopg.connect(postgres_url, autocommit=True) as c:
        c.execute("SET search_path = slr")   # (the store's default schema)
        tables = [t for (t,) in c.execute("SELECT table_name FROM slr_event_types")]
        for table in tables:
            c.execute(f'DELETE FROM "{table}"')
    with slr_sql.open(postgres_url, robot="r1", clock=slr_sql.ManualClock(200.0)) as kb:
        kb.add("seen(b1)^11")
    assert fleet.push(postgres_url, str(fleet_db)).shipped == 1
    with psycopg.connect(postgres_url, autocommit=True) as c:
        c.execute("SET search_path = slr")
        for table in tables:   # a dump from when each table held none of these rows
            c.execute(f'DELETE FROM "{table}"')
            c.execute("SELECT setval(pg_get_serial_sequence(%s, 'seq'), 1)", (f'"{table}"',))
    with slr_sql.open(postgres_url, robot="r1", clock=slr_sql.ManualClock(300.0)) as kb:
        kb.add("seen(c1)^21")
    with pytest.raises(RobotStoreRestored):
        fleet.push(postgres_url, str(fleet_db))
    assert fleet.push(postgres_url, str(fleet_db), resync=True).shipped == 1
    assert sum(fleet_events(fleet_db).values()) == 8
    # moved/2, emptied on the robot, is no restore the next push refuses either
    assert fleet.push(postgres_url, str(fleet_db)).shipped == 0
