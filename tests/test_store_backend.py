"""The backend protocols (slr_sql/store/backend.py) and the dialects (store/dialect.py):
both engines implement the same interface, and the SQLite printer is today's text."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from slr_sql.cep.sqlgen import AltSQL
from slr_sql.store import EventStore
from slr_sql.store.backend import Backend, CompiledSQL, RawStatements
from slr_sql.store.dialect import POSTGRES, SQLITE

PACKAGE = Path(__file__).resolve().parent.parent / "slr_sql"


def _protocol_members(protocol: type) -> set[str]:
    return {name for name in vars(protocol) if not name.startswith("_")}


def test_every_public_store_method_is_in_a_protocol():
    public = {name for name in vars(EventStore) if not name.startswith("_")}
    covered = set().union(*(_protocol_members(p) for p in (Backend, CompiledSQL, RawStatements)))
    assert public - covered == set(), "give the new store method a place in store/backend.py"
    assert covered - public == set()


@pytest.mark.parametrize("protocol", [Backend, CompiledSQL, RawStatements])
def test_both_engines_implement_the_protocols(protocol, backend):
    store = EventStore(backend)
    try:
        assert isinstance(store, protocol)
        assert store.dialect is (POSTGRES if backend.startswith("postgresql") else SQLITE)
    finally:
        store.close()


def test_only_the_store_imports_a_database_driver():
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] == "store":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
            assert not any(n.split(".")[0] in ("psycopg", "psycopg_pool") for n in names), rel


def test_the_sqlite_printer_prints_todays_text():
    """Event-rule statements printed for SQLite are the text slr_sql always ran; the
    PostgreSQL printer differs exactly in the engine's spellings."""
    import slr_sql
    kb = slr_sql.open(clock=slr_sql.ManualClock(0.0))
    kb.load("r(X) <- (a(X) seq b(X, 1.0)) within 5 where X > 2.")
    kb.add_many(["a(1)^1", "b(1, 1.0)^2"])
    alt: AltSQL = kb._cep.rules[0].alts[0]
    sql = alt.delta_select(0, {("a", 1), ("b", 2)})
    assert "typeof(e1.arg2) = 'real'" in sql and "slr_typeof" not in sql
    kb.close()
    pg = AltSQL(alt.alt, 0, ['"a"', '"b"'], [], alt.head_args, "unrestricted",
                lambda key, x: "TRUE", dialect=POSTGRES)
    printed = pg.delta_select(0, {("a", 1), ("b", 2)})
    assert "slr_typeof(e1.arg2) = 'real'" in printed and "typeof(e1" not in \
        printed.replace("slr_typeof(e1", "")
    assert pg.params[next(k for k, v in pg.params.items() if v == "1.0")] == "1.0"
