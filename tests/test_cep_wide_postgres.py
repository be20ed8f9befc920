"""Event rules over wide event types on PostgreSQL: the answers equal SQLite's, and the
statements hold the equalities of the shared arguments as one condition.

With one equality per shared argument, PostgreSQL's planning time grew as the cube of their
number (0.13 s a statement at 101 arguments, 12 s at 401; a rule over two events of 1,501
shared arguments ran for more than ten minutes an add). The events here differ from each
other in one argument anywhere in the row (the first, the middle, the last) and in the
kinds of their values (1, 1.0, '1', a: one stored text each), so the folded comparison must
tell them apart as the per-argument equalities did.
"""
from __future__ import annotations

import random

import pytest

import slr_sql
from slr_sql import ManualClock
from slr_sql.cep.sqlgen import AltSQL
from slr_sql.store.dialect import POSTGRES

WIDTH = 301          # arguments of the wide types
VARS = ", ".join(f"X{i}" for i in range(WIDTH))
REVERSED = ", ".join(f"X{i}" for i in reversed(range(WIDTH)))
KINDS = ["1", "1.0", "'1'", "a"]

RULES = {
    "seq": f"c(X0) <- w({VARS}) seq w({VARS}).",
    "and recent": f":- consumption(recent).\nc(X0) <- w({VARS}) and w({VARS}).",
    "seq chronological": f":- consumption(chronological).\nc(X0, X150) <- w({VARS}) seq "
                         f"w({VARS}).",
    "reversed": f"c(X0, X300) <- w({VARS}) seq w({REVERSED}).",
    "three": f"c(X0) <- w({VARS}) seq w({VARS}) seq w({VARS}).",
    "cnot": f"c(X0) <- (w({VARS}) seq w({VARS})) cnot v({VARS}).",
    "where fact": f"c(X0) <- w({VARS}) seq w({VARS}) where ok({VARS}).",
}


def _row(rng: random.Random) -> list[str]:
    """An event's arguments: a few shapes, each differing from the base row in one place."""
    row = [str(min(i, WIDTH - 1 - i) % 7) for i in range(WIDTH)]   # a palindrome
    where = rng.choice([0, 1, WIDTH // 2, WIDTH - 1])
    row[where] = rng.choice(KINDS)
    return row


def _events(seed: int) -> list[str]:
    rng = random.Random(seed)
    out = []
    for k in range(24):
        kind = "v" if k % 6 == 5 else "w"
        out.append(f"{kind}({', '.join(_row(rng))})^{k + 1}")
    return out


def _facts(seed: int) -> str:
    rng = random.Random(seed + 1)
    return "".join(f"ok({', '.join(_row(rng))}).\n" for _ in range(6))


def _detected(where: str | None, rule: str, events: list[str], facts: str) -> list:
    with slr_sql.open(where, clock=ManualClock(0)) as kb:
        kb.load(facts + rule, name="wide")
        for event in events:
            kb.add(event)
        kb.clock.set(100.0)
        head = "c(X, Y)" if rule.split(" <- ")[0].endswith(", X150)") or \
            rule.split(" <- ")[0].endswith(", X300)") else "c(X)"
        return kb.query(f"findall({head}-[S, E], {head}^[S, E], L0), msort(L0, L)")[0]["L"]


@pytest.mark.parametrize("name", sorted(RULES))
def test_a_rule_over_events_of_301_arguments_detects_on_postgres_what_sqlite_does(
        name, postgres_url, tmp_path):
    events, facts = _events(len(name)), _facts(len(name))
    rule = RULES[name]
    on_sqlite = _detected(str(tmp_path / "wide.db"), rule, events, facts)
    assert on_sqlite, "the stream must match the rule at least once"
    assert _detected(postgres_url, rule, events, facts) == on_sqlite


def test_the_statements_of_a_wide_rule_hold_no_condition_or_sort_key_per_argument():
    # what made PostgreSQL's planning time grow as the cube of the width: an equality (with
    # its key and type tests) per shared argument, in the joins, the cnot's NOT EXISTS and
    # the where fact's EXISTS; and a terminator's partners sorted by four keys per argument
    # its own row fixes. The rules are built on SQLite (the tables exist), their statements
    # printed for PostgreSQL as the server's store prints them
    names = ["seq", "and recent", "seq chronological", "cnot", "where fact"]
    policies = ["unrestricted", "recent", "chronological", "unrestricted", "unrestricted"]
    statements = []
    for name, policy in zip(names, policies):   # (one policy for a store's rules)
        with slr_sql.open(None, clock=ManualClock(0)) as kb:
            kb.load(_facts(0) + f":- consumption({policy}).\n" + RULES[name].split("\n")[-1],
                    name="wide")
            for event in _events(0):
                kb.add(event)
            for alt in kb._cep.rules[0].alts:
                pg = AltSQL(alt.alt, alt.index, alt.tables, alt.neg_tables, alt.head_args,
                            alt.policy, lambda *a: "TRUE", used_table=alt.used_table,
                            prov_table=alt.prov_table, fact_table=alt.fact_table,
                            table_names=alt.table_names, dialect=POSTGRES)
                dirty = {leaf.key for leaf in alt.alt.leaves}
                for pos in range(pg.k):
                    statements += [pg.delta_insert(pos, dirty), pg.delta_select(pos, dirty)]
                    if policy != "unrestricted":
                        statements += [pg.term_select(pos, True), pg.recent_insert(pos)]
    assert len(statements) == 2 * 2 * 5 + 2 * 2 * 2
    for sql in statements:
        assert sql.count("slr_key(") < 10 and sql.count("slr_typeof(") < 10, sql[:300]
        assert sql.count("ROW(") <= 2 * 3 * 2   # (a cnot: its row and each of the two)
