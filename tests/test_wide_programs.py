"""Programs whose clauses are wider than a table has columns (SQLite 2000, PostgreSQL 1600):
Prolog takes any arity, and the store's fact tables are a speed-up only, so such a program
loads and answers on both backends, interpreted and through the compiler."""
from __future__ import annotations

import slr_sql

WIDE = 2001   # wider than either backend's tables


def wide_fact(name: str, first: str) -> str:
    return f"{name}({first}" + ", 0" * (WIDE - 1) + ")."


def test_a_program_of_facts_wider_than_a_table_loads_and_answers(backend):
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.load(wide_fact("wide", "a") + "\n" + wide_fact("wide", "b"), name="wide")
        # a rule over them: the compiler's candidates read facts
        kb.load("first_of_wide(X) :- wide(X" + ", _" * (WIDE - 1) + ").", name="rule")
        kb.add("seen(b)^1.0")
        kb.load("seen_wide(X) :- seen(X)^_, first_of_wide(X).", name="joined")
        assert sorted(a["X"] for a in kb.query("first_of_wide(X)")) == ["a", "b"]
        assert kb.query("seen_wide(X)") == [{"X": "b"}]
        assert sorted(kb.programs()) == ["joined", "rule", "wide"]
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:   # and after a reopen
        assert kb.query("seen_wide(X)") == [{"X": "b"}]


def test_an_event_too_wide_names_the_limit_of_its_own_backend(backend):
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        limit = kb.store.max_event_arity
        assert limit == (1595 if backend.startswith("postgresql:") else 1995)
        try:
            kb.add_event("wide", [0] * (limit + 1), start=1.0, end=1.0)
        except slr_sql.EventRejected as exc:
            assert f"an event has at most {limit}, the column limit of the store's tables" \
                in str(exc)
        else:
            raise AssertionError("a too wide event was stored")
        assert kb.store.event_types() == {}


def test_an_event_rule_whose_head_is_wider_than_a_table_is_refused_and_changes_nothing(backend):
    """The load was refused, but the refused rule stayed in force in the knowledge base that
    loaded it: every later add of its pattern's events failed with "the store failed (no
    such table: slr_cep_m_...)" until the process opened the store again."""
    with slr_sql.open(backend, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.load("seen(X) <- a(X).", name="ok")
        rules_before = [r["rule"] for r in kb.event_rules()]
        too_wide = kb.store.max_event_arity + 1
        head = "big(" + ", ".join(["X"] * too_wide) + ")"
        try:
            kb.load(f"{head} <- a(X).", name="wide")
        except slr_sql.SLRError as exc:
            assert f"cannot declare event big/{too_wide}: too many arguments" in str(exc)
        else:
            raise AssertionError("a rule too wide for its table was loaded")
        assert kb.add("a(1)^1.0") is None and kb.add_many(["a(2)^2.0"]) == []
        assert kb.query("seen(X)^T") == [{"X": 1, "T": 1.0}, {"X": 2, "T": 2.0}]
        assert [r["rule"] for r in kb.event_rules()] == rules_before
        assert sorted(kb.programs()) == ["ok"]
