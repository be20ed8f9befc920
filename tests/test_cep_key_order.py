"""The recent policy chooses each partner by a correlated sub-query, newest first, ties
broken by the stored values: an argument the sub-query's conditions fix (a variable shared
with a chosen row, a constant) orders nothing, so it is left out of the ORDER BY and the
(key, end, start) index gives the order without a sort.
"""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock


def _chooser(rule: str, events: list[str]) -> tuple[str, list, str]:
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(":- consumption(recent).\n" + rule)
        kb.add_many(events)
        clock.set(100.0)
        head = rule.split("(")[0]
        text = kb.explain(f"{head}(X)")
        _, rows = kb.sql(f"SELECT arg1, t_start, t_end FROM {head} ORDER BY t_end")
    sub = text[text.index("(SELECT q0_e0.seq"):]
    return sub[:sub.index("LIMIT 1")], rows, text


def test_a_shared_first_argument_is_not_sorted_on():
    order, rows, text = _chooser("c(X) <- a(X) seq b(X).",
                                 ["a(1)^1", "a(1.0)^1", "a(2)^1", "b(1)^2", "b(2)^3"])
    assert "ORDER BY q0_e0.t_end DESC, q0_e0.t_start DESC, q0_e0.seq DESC" in order
    assert "TEMP B-TREE" not in text
    assert rows == [(1, 1.0, 2.0), (2, 1.0, 3.0)]


def test_a_free_argument_still_breaks_ties_by_its_value_and_type():
    order, rows, text = _chooser("c(X) <- a(X, Y) seq b(X).",
                                 ["a(1, 7)^1", "a(1, 9)^1", "a(1, 8)^1", "b(1)^2"])
    assert "q0_e0.arg1 DESC" not in order
    assert "q0_e0.arg2 DESC, typeof(q0_e0.arg2) DESC, (CASE WHEN q0_e0.arg2 = 0 AND " \
        "typeof(q0_e0.arg2) = 'real' THEN 1 - slr_sign_bit(q0_e0.arg2) END) DESC, " \
        "q0_e0.seq DESC" in order
    assert rows == [(1, 1.0, 2.0)]


@pytest.mark.parametrize("rule", ["c(X) <- a(1) seq b(X).", "c(X) <- a(_) seq b(X)."])
def test_a_constant_is_fixed_an_anonymous_variable_is_not(rule):
    order, _, _ = _chooser(rule, ["a(1)^1", "b(1)^2"])
    fixed = "(_)" not in rule
    assert ("q0_e0.arg1 DESC" in order) is not fixed
