"""An interleaved batch (a, b, a, b, ...) goes into each table with its rows in their order,
one insert per type -- with or without event rules, and when a bad event sends the batch
down the event-by-event path -- and a rejected event keeps its index in the batch."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock

from test_cep_rounds import _sqlite_statements


def _batch(bad_at: int | None) -> list:
    events = [("a" if i % 2 == 0 else "b", (i,), float(i), float(i)) for i in range(40)]
    if bad_at is not None:
        events[bad_at] = ("a", (object(),), float(bad_at), float(bad_at))   # (not a term)
    return events


@pytest.mark.parametrize("rules", [False, True])
@pytest.mark.parametrize("bad_at", [None, 16])
def test_an_interleaved_batch_takes_one_insert_per_type(tmp_path, rules, bad_at):
    with slr_sql.open(tmp_path / "i.db", clock=ManualClock(0.0)) as kb:
        kb.add_many([("a", (-1,), -2.0, -2.0), ("b", (-1,), -1.0, -1.0)])   # (tables exist)
        if rules:
            kb.load(":- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\nc(X) <- a(X) seq b(X).\n")
        errors: list = []
        statements = _sqlite_statements(kb, lambda: errors.extend(kb.add_many(_batch(bad_at))))
        inserts = [s for s in statements if s.startswith(('INSERT INTO "a"', 'INSERT INTO "b"'))]
        # (each type's 20 or 19 rows: multi-row statements of power-of-two sizes, 16 + 4 + ...)
        per_type = {t: [s for s in inserts if s.startswith(f'INSERT INTO "{t}"')] for t in "ab"}
        assert [len(per_type[t]) for t in "ab"] == ([2, 2] if bad_at is None else [3, 2])
        assert [e.index for e in errors] == ([] if bad_at is None else [bad_at])
        kept = [i for i in range(40) if i != bad_at]
        for name in "ab":
            rows = kb.sql(f'SELECT arg1 FROM "{name}" WHERE arg1 >= 0 ORDER BY seq')[1]
            assert [r[0] for r in rows] == [i for i in kept if (i % 2 == 0) == (name == "a")]
