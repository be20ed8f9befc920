"""An event type given as text ``Name/Arity`` (or ``Name``) with its name quoted as Prolog
writes it -- ``'x/seen'/2``, the form slr_sql's messages print -- is read as Prolog reads
it (quotes, doubled quotes, escapes), wherever the public API and the command line take
one: ``kb.mark_complete``, ``kb.complete_until``, ``slr describe``, ``slr export``,
``slr fleet push --type``, the types of a plot. A quoted one that is malformed is a clear
SLRError and changes nothing. The unquoted forms keep their meaning (``x/seen/2``: the name
is the text before the last slash). On a SQLite file and on PostgreSQL.
"""
from __future__ import annotations

import pytest
from test_cli import slr

import slr_sql
from slr_sql import ManualClock
from slr_sql.plot import collect_timeline

NAMES = [("'x/seen'/2", ("x/seen", 2)), ("'it''s'/1", ("it's", 1)),
         ("'a\\nb'/0", ("a\nb", 0)), ("'\\x41\\b'/1", ("Ab", 1)), ("x/seen/2", ("x/seen", 2))]
MALFORMED = ["'x/seen/2", "'x'y/2", "'x'/two", "'x'/2.0", "'x'/2/3", "'x'/X", "''/1",
             "'p'(1)/2"]


def _marks(kb) -> dict:
    return kb.store.meta_items("sync/mark/")


def test_a_quoted_name_marks_the_type_prolog_reads(backend):
    clock = ManualClock(0.0)
    with slr_sql.open(backend, clock=clock) as kb:
        kb.add_event("x/seen", ["r1", 3], 1.0, 1.0)
        waiting = kb.submit("'x/seen'(R, N)^T", at=5)
        assert not waiting.done()
        for k, (text, key) in enumerate(NAMES):
            kb.mark_complete(text, 5 + k)
            assert kb.complete_until(key) == 5 + k
            assert kb.complete_until(text) == 5 + k
        assert waiting.result(timeout=30) == [{"R": "r1", "N": 3, "T": 1.0}]
        marks = _marks(kb)
        assert "sync/mark/x/seen/2" in marks and "sync/mark/'x/seen'/2" not in marks
        kb.mark_complete("'seg'", 2)     # a quoted name alone: every arity
        assert kb.complete_until(("seg", 1)) == 2
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:   # the marks were stored so
        assert kb.complete_until(("x/seen", 2)) == 5 + len(NAMES) - 1
        assert kb.complete_until(("it's", 1)) == 6


@pytest.mark.parametrize("text", MALFORMED)
def test_a_malformed_quoted_indicator_is_refused_and_marks_nothing(backend, text):
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        kb.mark_complete("x/seen/2", 4)
        before = _marks(kb)
        with pytest.raises(slr_sql.SLRError, match="mark_complete: .* is not an indicator "
                                                   "Name/Arity or Name"):
            kb.mark_complete(text, 9)
        with pytest.raises(slr_sql.SLRError, match="is not an indicator"):
            kb.complete_until(text)
        assert _marks(kb) == before
        assert kb.complete_until(("x/seen", 2)) == 4


def test_a_plot_chooses_the_type_of_a_quoted_name():
    with slr_sql.open(None, clock=ManualClock(0.0)) as kb:
        kb.add_event("x/seen", ["r1", 3], 1.0, 1.0)
        kb.add_event("x", [1], 2.0, 2.0)
        rows = collect_timeline(kb, ["'x/seen'/2"]).rows
        assert [(r.type.name, r.type.arity) for r in rows] == [("x/seen", 2)]
        with pytest.raises(slr_sql.SLRError, match="is not an indicator"):
            collect_timeline(kb, ["'x/seen/2"])


def test_a_fleet_push_ships_the_type_of_a_quoted_name(tmp_path, backend):
    robot = str(tmp_path / "robot1.db")
    with slr_sql.open(robot, clock=ManualClock(0.0), robot="r1") as kb:
        kb.add_event("x/seen", ["pallet", 3], 1.0, 1.0)
        kb.add_event("x", [1], 2.0, 2.0)
    from slr_sql.fleet import push
    report = push(robot, backend, types=["'x/seen'/2"])
    assert report.per_type == {"x/seen/2": 1}
    with pytest.raises(slr_sql.SLRError, match="is not an indicator"):
        push(robot, backend, types=["'x/seen/2"])


@pytest.fixture(scope="module")
def store(tmp_path_factory) -> str:
    path = str(tmp_path_factory.mktemp("types") / "robot.db")
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.add_event("x/seen", ["r1", 3], 1.0, 1.0)
        kb.add_event("x", [1], 2.0, 2.0)
    return path


def test_slr_describe_and_export_take_a_quoted_name(store, tmp_path):
    shown = slr("describe", store, "'x/seen'/2")
    assert shown.returncode == 0, shown.stderr
    assert "x/seen" in shown.stdout and "x/1" not in shown.stdout
    exported = slr("export", store, str(tmp_path / "out.mcap"), "'x/seen'/2")
    assert exported.returncode == 0, exported.stderr
    assert "1 event" in exported.stdout + exported.stderr
    for args in (("describe", store), ("export", store, str(tmp_path / "bad.mcap"))):
        bad = slr(*args, "'x/seen/2")
        assert bad.returncode != 0
        assert "is not an indicator Name/Arity or Name" in bad.stderr
        assert "Traceback" not in bad.stderr
    assert not (tmp_path / "bad.mcap").exists()


def test_slr_fleet_push_takes_a_quoted_name(store, tmp_path):
    fleet = str(tmp_path / "fleet.db")
    pushed = slr("fleet", "push", store, fleet, "--robot", "r1", "--type", "'x/seen'/2")
    assert pushed.returncode == 0, pushed.stderr
    with slr_sql.open(fleet, clock=ManualClock(0.0)) as kb:
        assert [a["N"] for a in kb.query("'x/seen'(_, N)^_")] == [3]
        assert kb.query("x(_)^_") == []
    bad = slr("fleet", "push", store, fleet, "--robot", "r1", "--type", "'x/seen/2")
    assert bad.returncode != 0 and "is not an indicator" in bad.stderr
    assert "Traceback" not in bad.stderr


@pytest.mark.parametrize("text", ["seen/²", "seen/１"])
def test_an_arity_of_digits_other_than_ascii_is_refused_in_words(text):
    """``str.isdigit`` holds for a superscript two, which ``int`` cannot read: the
    SLRError said ``ValueError: invalid literal for int()``; a fullwidth digit was read as
    the arity, where the other readers of a type take the text for a name."""
    with slr_sql.open(clock=ManualClock(0.0)) as kb:
        for call in (lambda: kb.mark_complete(text, 9), lambda: kb.complete_until(text)):
            with pytest.raises(slr_sql.SLRError, match="expected an event type p/N or p"):
                call()
        assert _marks(kb) == {}
