"""The inspection views are made again once per add that brings new event types, not once
per new type: after a batch they are the views (and the tables have the names) the same
events added one at a time give, on SQLite and PostgreSQL, and a batch that fails changes
nothing."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import EventRejected, planner

# r0..r2 read one new type each, "both" three of them, f is a fact table's view; r3/2's
# view takes the name the table of the event type r3/2 would have (whichever comes first)
PROGRAM = """
r0(X) :- e0(X)^_.
r1(X) :- e1(X)^_.
r2(X) :- e2(X)^_.
both(X) :- e0(X)^_, e1(X)^_, e2(X)^_.
r3(X, T) :- a(X)^T.
f(a). f(b).
"""

BATCHES = {
    "three new types": ["e0(a)^1", "e1(a)^2", "e2(a)^3", "other(x)^4"],
    "a view named before a table of that name": ["a(1)^1", "r3(x, y)^2"],
    "a table named before a view of that name": ["r3(x, y)^2", "a(1)^1"],
    "interleaved": ["e0(a)^1", "a(1)^1", "e0(b)^2", "r3(x, y)^2", "e1(a)^3", "a(2)^3"],
}


@pytest.fixture(params=["memory", "file", "postgres"])
def places(request, tmp_path):
    """Where two fresh stores live: None twice (in memory), two files or two databases."""
    if request.param == "memory":
        yield None, None
    elif request.param == "file":
        yield tmp_path / "one.db", tmp_path / "two.db"
    else:
        from conftest import drop_postgres_database, postgres_database

        admin = request.getfixturevalue("postgres_server")[1]
        urls = postgres_database(admin), postgres_database(admin)
        yield urls
        for url in urls:
            drop_postgres_database(admin, url)


def _schema(kb) -> list[tuple]:
    """The store's views (name, definition) and event tables (name, arity, table)."""
    if kb.store.dialect.name == "sqlite":
        _, views = kb.sql("SELECT name, sql FROM sqlite_master WHERE type = 'view'")
    else:
        _, views = kb.sql("SELECT table_name, view_definition FROM information_schema.views "
                          "WHERE table_schema = current_schema()")
    tables = sorted((name, arity, table) for (name, arity), table
                    in kb.store.event_types().items())
    return sorted(tuple(v) for v in views) + tables


@pytest.mark.parametrize("batch", list(BATCHES))
def test_the_views_after_a_batch_are_those_of_its_events_added_one_at_a_time(places, batch):
    events = BATCHES[batch]
    one, two = places
    with slr_sql.open(one, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(PROGRAM)
        assert kb.add_many(events) == []
        batched = _schema(kb)
    with slr_sql.open(two, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(PROGRAM)
        for event in events:
            kb.add(event)
        assert _schema(kb) == batched


def test_a_batch_of_new_types_makes_the_views_again_once(monkeypatch):
    made = []
    refresh = planner.refresh_views
    monkeypatch.setattr(planner, "refresh_views", lambda kb: made.append(1) or refresh(kb))
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(PROGRAM)
        made.clear()
        assert kb.add_many(["e0(a)^1", "e1(a)^2", "e0(b)^2", "e2(a)^3", "a(1)^3"]) == []
        assert len(made) == 1
        assert [a["X"] for a in kb.query("both(X)")] == ["a"]
        _, rows = kb.sql("SELECT arg1 FROM both")
        assert rows == [("a",)]
        made.clear()
        kb.add_many(["e0(c)^4", "e1(c)^4"])   # no new type: the views stand
        assert made == []
        # a new table that would take a view's name is named once the views stand
        assert kb.add_many(["e3(a)^5", "r3(x, y)^5", "e4(a)^6"]) == []
        assert kb.store.table_for("r3", 2) == "r3__2"


def test_a_batch_of_new_types_with_event_rules_makes_the_views_again_once(monkeypatch):
    """With event rules the batch is stored in the rules' transaction (their complex types
    have tables since the load): still one making of the views, after all the tables."""
    made = []
    refresh = planner.refresh_views
    monkeypatch.setattr(planner, "refresh_views", lambda kb: made.append(1) or refresh(kb))
    with slr_sql.open(clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(PROGRAM + ":- consumption(recent).\npair(X) <- e0(X) seq e1(X).\n"
                "seen(X) :- pair(X)^_.\n")
        made.clear()
        assert kb.add_many(["e0(a)^1", "e1(a)^2", "e2(a)^3"]) == []
        assert len(made) == 1
        _, rows = kb.sql("SELECT arg1 FROM both")
        assert rows == [("a",)]
        _, rows = kb.sql("SELECT arg1 FROM seen")
        assert rows == [(a["X"],) for a in kb.query("seen(X)")]


def test_a_failing_batch_of_new_types_changes_no_view(places):
    one, _ = places
    with slr_sql.open(one, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(PROGRAM)
        kb.add("e0(a)^1")
        before = _schema(kb)
        with pytest.raises(EventRejected):
            kb.add_many(["e1(a)^2", "e2(a)^3", "r3(x, y)^2", "a(1)^[3, 2]"], atomic=True)
        assert _schema(kb) == before


def test_a_load_declaring_new_types_makes_the_views_once(places, monkeypatch):
    """A load's declared types and its event rules' complex types are one batch: the views
    are made by the load (and once more for complex types made after them), and are those
    of the program over all its tables."""
    made = []
    refresh = planner.refresh_views
    monkeypatch.setattr(planner, "refresh_views", lambda kb: made.append(1) or refresh(kb))
    one, two = places
    declared = ":- event e0/1, e1/1, e2/1, a/1.\n"
    with slr_sql.open(one, clock=slr_sql.ManualClock(10.0)) as kb:
        made.clear()
        kb.load(declared + PROGRAM)
        assert len(made) == 1
        loaded = _schema(kb)
    with slr_sql.open(two, clock=slr_sql.ManualClock(10.0)) as kb:
        kb.load(declared)   # the tables first, then the program over them
        kb.load(PROGRAM)
        assert _schema(kb) == loaded
