"""An event type of more than 1,000 arguments (a store holds up to about 1,990: SQLite's 2,000
columns less the store's own) is read as any other: its events were stored, but every
statement with one condition or term per argument (a lookup with the arguments bound, the
compiled goal, prev/next, a buffer's trigger, an export's or the Foxglove view's page) was
deeper than SQLite's limit of 1,000 ('Expression tree is too large')."""
from __future__ import annotations

from mcap.reader import make_reader

import slr_sql
from slr_sql import ManualClock
from slr_sql.viz.mcap_export import export_mcap

ARITY = 1500
ARGS = ",".join(str(i) for i in range(ARITY))


def test_a_type_of_1500_arguments_is_looked_up_buffered_and_exported(tmp_path):
    with slr_sql.open(tmp_path / "wide.db", clock=ManualClock(10)) as kb:
        kb.add_buffer(f"wide({ARGS})", keep_last=2)
        for t in (1.0, 2.0, 3.0):
            kb.add_event("wide", list(range(ARITY)), start=t, end=t)
        assert [a["T"] for a in kb.query(f"wide({ARGS})^T")] == [2.0, 3.0]   # the buffer kept 2
        assert kb.query(f"wide({ARGS})^T", at=2.5) == [{"T": 2.0}]
        assert kb.query(f"prev(wide({ARGS})^T, 2.5)") == [{"T": 2.0}]
        assert kb.query(f"next(wide({ARGS})^T, [2.5, inf])") == [{"T": 3.0}]
        kb.load(f"seen_wide(T) :- wide({ARGS})^T.", name="wide")
        assert kb.query("aggregate_all(count, seen_wide(_), N)") == [{"N": 2}]
        page = kb.store.raw_page("wide", ARITY, rows=10, max_bytes=1 << 20, after_seq=0)
        assert len(page.rows) == 2 and not page.more
        report = export_mcap(kb.store, tmp_path / "wide.mcap")
    assert report.per_type == {("wide", ARITY): 2}
    with open(tmp_path / "wide.mcap", "rb") as stream:
        assert sum(1 for _ in make_reader(stream).iter_messages()) == 2


def test_an_event_rule_over_a_type_of_1500_arguments_loads_and_detects():
    # its load was refused: the rule's statements held a condition per argument
    clock = ManualClock(0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(f":- max_delay(wide/{ARITY}, 0).\nwide_alone(1) <- wide({ARGS}) cnot bump(1).",
                name="rules")
        for t in (1.0, 3.0):
            clock.set(t)
            kb.add_event("wide", list(range(ARITY)), start=t, end=t)
        clock.set(10)
        kb.add("bump(2)^10")
        assert kb.query("wide_alone(X)^_") == [{"X": 1}, {"X": 1}]
