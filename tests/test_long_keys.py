"""Values of kilobytes in indexed positions: PostgreSQL answers as SQLite does (a B-tree entry
of PostgreSQL holds at most ~2.7 KB, so a long key must not reach one as it is)."""
from __future__ import annotations

import random
import string

import slr_sql
from slr_sql import ManualClock

# random letters: a repeated letter would be compressed by PostgreSQL below the limit and prove
# nothing
LONG = "".join(random.Random(7).choices(string.ascii_lowercase, k=10_000))


def test_a_fact_whose_first_argument_is_ten_kilobytes_loads_and_answers_on_both(backend):
    with slr_sql.open(backend, clock=ManualClock(10.0)) as kb:
        kb.load(f"f('{LONG}', 1).\nf(short, 2).\n")
        assert [a["N"] for a in kb.query(f"f('{LONG}', N)")] == [1]
        assert [a["N"] for a in kb.query("f(short, N)")] == [2]
        assert sorted(len(a["X"]) for a in kb.query("f(X, _)")) == [5, 10_000]
