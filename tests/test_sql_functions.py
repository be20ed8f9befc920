"""The Python functions SQL statements call are listed once (slr_sql/sql_functions.py):
the SQLite backend registers that list on each of its connections and nothing else
registers a function; every entry exists on a PostgreSQL server under the same name and
number of arguments, or is marked interpreter only there (and then does not exist)."""
from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import pytest

import slr_sql
from slr_sql.sql_functions import SQL_FUNCTIONS
from slr_sql.store.functions import Native

PACKAGE = Path(slr_sql.__file__).resolve().parent
REPO = PACKAGE.parent
# the one function that hands the list to a connection
REGISTRAR = ("store/connection.py", "register_functions")


def registrations(trees: dict[str, ast.AST]) -> list[str]:
    """``file:line: name`` of every ``create_function``/``create_aggregate`` call outside
    the registrar."""
    found = []
    for rel, tree in trees.items():
        inside: set[int] = set()
        if rel == REGISTRAR[0]:
            for node in ast.walk(tree):
                if isinstance(node, ast.FunctionDef) and node.name == REGISTRAR[1]:
                    inside |= {id(n) for n in ast.walk(node)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                    and node.func.attr in ("create_function", "create_aggregate") \
                    and id(node) not in inside:
                found.append(f"{rel}:{node.lineno}: {node.func.attr}")
    return found


def _trees_that_may_register(files, root: Path) -> dict[str, ast.AST]:
    # a call whose attribute is create_function/create_aggregate spells that name in its
    # file: the files that do not are left unparsed (parsing all 2 MB took seconds)
    texts = {str(f.relative_to(root)): f.read_text() for f in files}
    return {rel: ast.parse(text) for rel, text in texts.items()
            if "create_function" in text or "create_aggregate" in text}


def test_no_function_is_registered_outside_the_list():
    trees = _trees_that_may_register(sorted(PACKAGE.rglob("*.py")), PACKAGE)
    assert REGISTRAR[0] in trees   # the scan reaches the one registrar
    trees |= _trees_that_may_register(sorted((REPO / "benchmarks").glob("*.py")), REPO)
    assert registrations(trees) == [], ("register SQL functions only by listing them in "
                                        "slr_sql/sql_functions.py")


@pytest.mark.parametrize("source, found", [
    ("store.create_function('f', 1, len)", ["m.py:1: create_function"]),
    ("def attach(kb):\n    kb.store.conn.create_aggregate('g', 1, object)",
     ["m.py:2: create_aggregate"]),
    ("store.install_functions(SQL_FUNCTIONS)", []),
])
def test_the_registration_scan_finds_registrations(source, found):
    assert registrations({"m.py": ast.parse(source)}) == found


def test_the_list_names_each_function_once():
    names = [name for name, _ in SQL_FUNCTIONS.names()]
    assert len(names) == len(set(names)) and all(n.startswith("slr_") for n in names)


def _registered(rows: list[tuple]) -> set[tuple[str, int]]:
    return {(name, narg) for name, narg in rows}


def test_every_connection_of_a_sqlite_store_has_every_function(tmp_path):
    listing = "SELECT name, narg FROM pragma_function_list WHERE name LIKE 'slr\\_%' ESCAPE '\\'"
    with slr_sql.open(tmp_path / "f.db") as kb:
        main = _registered(kb.store.sql(listing)[1])
        reader = kb.store.open_reader()
        try:
            by_reader = _registered(reader.execute(listing))
        finally:
            reader.close()
    assert set(SQL_FUNCTIONS.names()) <= main
    assert set(SQL_FUNCTIONS.names()) <= by_reader


def test_the_sqlite_printers_call_only_listed_functions():
    from slr_sql.cep import sqlgen
    from slr_sql.store.query_printers import SQLiteQueryPrinter

    called = set()
    for source in (inspect.getsource(SQLiteQueryPrinter), inspect.getsource(sqlgen)):
        called |= set(re.findall(r"\b(slr_[a-z0-9_]+)\(", source))
    for path in (PACKAGE / "sqlcompile").glob("*.py"):
        called |= set(re.findall(r"['\"](slr_[a-z0-9_]+)['\"]", path.read_text()))
    listed = {name for name, _ in SQL_FUNCTIONS.names()}
    assert called and called <= listed, called - listed


def test_each_function_is_on_postgresql_or_marked_interpreter_only(postgres_url):
    import psycopg

    with slr_sql.open(postgres_url):  # applies the migrations
        pass
    with psycopg.connect(postgres_url) as conn:
        rows = conn.execute("SELECT proname, pronargs, provariadic <> 0 FROM pg_proc "
                            "WHERE proname LIKE 'slr\\_%'").fetchall()
    on_server = {(name, -1 if variadic else n) for name, n, variadic in rows}
    names_on_server = {name for name, _ in on_server}
    entries = [(f.name, f.arity, f.on_postgres) for f in SQL_FUNCTIONS.functions] + \
        [(a.name, a.arity, a.on_postgres) for a in SQL_FUNCTIONS.aggregates]
    for name, arity, native in entries:
        if native is Native.MIGRATION:
            assert (name, arity) in on_server, f"{name}/{arity}: no such function on PostgreSQL"
        else:
            assert name not in names_on_server, (f"{name} exists on PostgreSQL: mark it "
                                                 "Native.MIGRATION")
    assert any(native is Native.MIGRATION for _, _, native in entries)


def test_a_builtin_reading_the_machines_deadline_runs_inside_sql(kb):
    """term_to_atom reads its machine's deadline: called from SQL it must find one, or the
    statement fails there and the interpreter runs the whole goal again (the defined
    predicate before it is then called twice)."""
    calls = []

    def tick(x, n):
        calls.append(x)
        return x, len(calls)

    kb.define("tick", 2, tick)
    kb.load("q(N, A) :- tick(7, N), term_to_atom(f(N), A).")
    assert "engine: sql" in kb.explain("q(N, A)")
    assert kb.query("q(N, A)") == [{"N": 1, "A": slr_sql.Atom("f(1)")}]
    assert calls == [7]


def test_slr_key_is_the_same_text_in_python_and_on_postgresql(postgres_url):
    import psycopg

    from slr_sql.sql_functions import _key
    values = ["", "cup1", "x" * 63, "x" * 64, "é" * 70, "a\\b" * 30, "日本" * 40, "\\x00" * 20]
    with slr_sql.open(postgres_url):  # applies the migrations
        pass
    with psycopg.connect(postgres_url) as conn:
        on_server = [conn.execute("SELECT slr.slr_key(%s)", (v,)).fetchone()[0] for v in values]
    assert on_server == [_key(v) for v in values]
    assert [len(k) for k in on_server[:4]] == [0, 4, 63, 64] and on_server[3] != "x" * 64
