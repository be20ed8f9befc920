"""The package's layers (docs/architecture.md): every import points down, no import cycles,
and only the store talks to SQLite.

Imports inside functions count: a deferred import is still a dependency. A new module must be
given its layer here, which is the point: placing it is a design decision.
"""
from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "slr_sql"

# Lower numbers are lower layers; a module may import only modules of a lower layer, or
# modules of its own family (the same subpackage). Mirrors the table in docs/architecture.md.
LAYERS = {
    "errors": -1, "terms": 0, "grammar": 0,  # grammar/: the generated parser, self-contained
    "unichars": -1,  # which characters are which to SWI-Prolog's reader (data only)
    "lockorder": 0,  # the order of the locks, checked in debug mode (SLR_DEBUG_LOCKS=1)
    "api": 1,  # the KnowledgeBaseAPI protocol: typing only (errors for EventRejected)
    "unify": 1, "arith": 1, "encoding": 1, "program": 1, "parser": 1,
    "robotlib": 1, "clocks": 1, "answers": 1,
    "printable": 0.5,  # text a stranger controls, made safe to print (terms' writeq escapes)
    "arguments": 0.75,  # checks of public arguments shared by layers (seconds, callables)
    "log_throttle": 1.5,  # log lines a stranger can cause, bounded (printable, clocks)
    "library_terms": 1,  # generated: the library's clauses as Python (terms only)
    "store": 2, "frames": 2,
    "builtins": 3,
    "library_generate": 3.5,  # writes library_terms from builtins' Prolog text
    "analysis": 4, "engine": 4, "sqlcompile": 4,
    "plans": 4.5,  # query plans: parsed, cached, instantiated; the prev fast path
    "sql_functions": 4.6,  # the Python functions SQL calls, listed once (store/functions)
    "host": 4.75,  # the Protocol of what the facade offers the parts it attaches
    "planner": 5,
    "sync": 6, "buffers": 6, "cep": 6, "plot": 6, "subscriptions": 6, "shipping": 6,
    "pipeline": 6.5,  # the stages of an add: drives sync, cep, buffers, subscriptions
    "loader": 6.5,  # program building (event rules compiled by cep/) and refresh
    "kb": 7,
    "viz": 7.5,  # Foxglove and MCAP views of a store; serve --foxglove uses it
    "demo": 8, "service": 8, "example_files": 8,
    "ros": 9,  # its request protocol speaks the service's JSON (service/encoding, errors)
    "fleet": 9,  # pushes to a fleet store in this process or through the service's client
    "__init__": 10,  # the public surface: open() from kb, connect() from service
    "cli": 11,
    "__main__": 12,
}


def _family(path: Path) -> str:
    """The first component under slr_sql/: ``store/events.py`` belongs to ``store``."""
    return path.relative_to(PACKAGE).parts[0].removesuffix(".py")


@functools.cache
def _tree(path: Path) -> ast.Module:
    """The parsed module at ``path``, parsed once for this file's tests (the package is 2 MB
    of source; each scan parsing it again took seconds). The scans only read the trees."""
    return ast.parse(path.read_text())


def _imports(path: Path) -> list[tuple[str, int]]:
    """(family imported, line) for every import of another slr_sql module in ``path``."""
    rel = path.relative_to(PACKAGE)
    package_parts = list(rel.parts[:-1])  # the importing module's package inside slr_sql
    found = []
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package_parts[: len(package_parts) - (node.level - 1)]
                if node.level - 1 > len(package_parts):
                    continue
                parts = base + (node.module.split(".") if node.module else [])
                targets = [parts] if parts else [[alias.name] for alias in node.names]
            elif node.module and node.module.split(".")[0] == "slr_sql":
                parts = node.module.split(".")[1:]
                targets = [parts] if parts else [[alias.name] for alias in node.names]
            else:
                continue
            found += [(t[0], node.lineno) for t in targets if t]
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "slr_sql" and len(parts) > 1:
                    found.append((parts[1], node.lineno))
    return found


MODULES = sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_imports_point_down(path):
    family = _family(path)
    assert family in LAYERS, f"{family} has no layer: place it in LAYERS and docs/architecture.md"
    upward = [(target, line) for target, line in _imports(path)
              if target != family and target in LAYERS and LAYERS[target] >= LAYERS[family]]
    assert not upward, f"{path.relative_to(PACKAGE)} imports its own layer or above: {upward}"


def test_no_import_cycles_between_modules():
    graph: dict[str, set[str]] = {}
    names = {p: ".".join(p.relative_to(PACKAGE).with_suffix("").parts) for p in MODULES}
    known = set(names.values())
    for path, name in names.items():
        rel = path.relative_to(PACKAGE)
        package_parts = list(rel.parts[:-1])
        edges = set()
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = package_parts[: len(package_parts) - (node.level - 1)]
                module = base + (node.module.split(".") if node.module else [])
                for candidate in [module] + [module + [a.name] for a in node.names]:
                    dotted = ".".join(candidate)
                    for target in (dotted, dotted + ".__init__"):
                        if target in known and target != name:
                            edges.add(target)
        graph[name] = edges
    state: dict[str, int] = {}

    def visit(node: str, trail: list[str]) -> None:
        state[node] = 1
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                cycle = trail[trail.index(nxt):] + [nxt] if nxt in trail else [node, nxt]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt, trail + [nxt])
        state[node] = 2

    for node in graph:
        if node not in state:
            visit(node, [node])


def test_only_the_store_imports_sqlite3():
    users = []
    for path in MODULES:
        for node in ast.walk(_tree(path)):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                     else [])
            if any(n.split(".")[0] == "sqlite3" for n in names):
                users.append(str(path.relative_to(PACKAGE)))
    assert all(_family(PACKAGE / u) == "store" for u in users), users


# ---------------------------------------------------------------------- the store boundary
# SQL text lives in the store (backends and dialects) and in the two compilers of rules to
# SQL; nothing else runs raw statements. Today's offenders are listed with their counts: a
# file may only go down (and then its number here must be lowered, so the list shrinks);
# a file not listed may have none.

SQL_HOMES = ("store/", "sqlcompile/", "cep/sqlgen.py")
_SQL_START = re.compile(r"^\s*(SELECT|INSERT|UPDATE|DELETE|CREATE|DROP|ALTER|PRAGMA|WITH|BEGIN|"
                        r"COMMIT|ROLLBACK|SAVEPOINT|RELEASE|REPLACE|VACUUM|ANALYZE)\b", re.I)
_RAW_CALLS = {"execute", "executemany", "executescript"}
SQL_TEXT_ALLOWED: dict[str, int] = {}
RAW_CALLS_ALLOWED: dict[str, int] = {}


def _docstring_ids(tree: ast.AST) -> set[int]:
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


@functools.cache   # two tests read it
def _boundary_counts() -> tuple[dict[str, int], dict[str, int]]:
    """Per module outside the SQL homes: lines with SQL text, raw statement calls."""
    sql: dict[str, set] = {}
    calls: dict[str, int] = {}
    for path in MODULES:
        rel = str(path.relative_to(PACKAGE))
        if rel.startswith(SQL_HOMES):
            continue
        tree = _tree(path)
        skip = _docstring_ids(tree)
        for node in ast.walk(tree):
            text = None
            if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and id(node) not in skip:
                text = node.value
            elif isinstance(node, ast.JoinedStr):
                text = "".join(v.value for v in node.values if isinstance(v, ast.Constant))
            if text and _SQL_START.match(text) and len(text.split()) > 1:
                sql.setdefault(rel, set()).add(node.lineno)
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                    and node.func.attr in _RAW_CALLS:
                calls[rel] = calls.get(rel, 0) + 1
    return {rel: len(lines) for rel, lines in sql.items()}, calls


def _assert_counts_within(found: dict, allowed: dict, grown_words: str, fewer: str) -> None:
    """No file has more of a counted kind than ``allowed`` says (``grown_words`` names the
    kind, ``{grown}`` the files), and none has fewer: a count that fell is lowered in
    ``allowed``, so that it cannot grow back unseen."""
    grown = {rel: n for rel, n in found.items() if n > allowed.get(rel, 0)}
    assert not grown, grown_words.format(grown=grown)
    shrunk = {rel: (n, found.get(rel, 0)) for rel, n in allowed.items()
              if found.get(rel, 0) < n}
    assert not shrunk, f"{fewer} now: lower the allowance to {shrunk}"


def test_sql_text_only_in_the_store_and_the_compilers():
    found, _ = _boundary_counts()
    _assert_counts_within(found, SQL_TEXT_ALLOWED,
                          "SQL text outside store/, sqlcompile/ and cep/sqlgen.py: {grown} "
                          "(put the statement behind a store method, or a dialect printer)",
                          "fewer SQL places")


def test_raw_statements_only_in_the_store_and_the_compilers():
    _, found = _boundary_counts()
    _assert_counts_within(found, RAW_CALLS_ALLOWED,
                          "raw execute/executemany calls outside the store: {grown}",
                          "fewer raw calls")


# Every row a SQLite connection of the store reads goes through store/stored_text.py's
# fetch_rows or fetch_row: sqlite3's decoding in C, and a text that is no UTF-8 read with
# U+FFFD and a warning, not an error for its whole table (no connection has a text_factory:
# it cost a call per text cell). A cursor's own fetchall/fetchmany/fetchone, or a loop over
# a connection's execute(), would raise sqlite3's error for such a text. PostgreSQL's driver
# (store/postgres.py) refuses such text when it is written. Allowed, with their counts:
# bounded_builtins.py's private in-memory connection reads a built-in's result, not a
# stored text (its error is said in words: tests/test_bounded_trim_json.py).
_FETCHES = {"fetchall", "fetchmany", "fetchone"}
FETCHES_ALLOWED = {"store/bounded_builtins.py": 1}


def _names_a_connection(node: ast.expr) -> bool:
    return isinstance(node, ast.Name) and node.id in {"conn", "copy", "connection"} or \
        isinstance(node, ast.Attribute) and node.attr == "conn"


def _own_fetches(tree: ast.Module) -> list[int]:
    """Lines of ``tree`` that read a sqlite3 cursor's rows themselves."""
    lines = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and node.func.attr in _FETCHES:
            lines.append(node.lineno)
        iterated = [node.iter] if isinstance(node, (ast.For, ast.comprehension)) else \
            list(node.args) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
            and node.func.id in {"list", "tuple", "set", "dict", "sorted", "next", "iter"} \
            else []
        lines.extend(it.lineno for it in iterated
                     if isinstance(it, ast.Call) and isinstance(it.func, ast.Attribute)
                     and it.func.attr == "execute" and _names_a_connection(it.func.value))
    return lines


def test_the_stores_rows_are_read_through_stored_text():
    found = {}
    for path in MODULES:
        rel = str(path.relative_to(PACKAGE))
        if rel.startswith("store/") and rel not in ("store/stored_text.py",
                                                   "store/postgres.py"):
            lines = _own_fetches(_tree(path))
            if lines:
                found[rel] = len(lines)
    _assert_counts_within(found, FETCHES_ALLOWED,
                          "rows read past store/stored_text.py's fetch_rows/fetch_row: {grown} "
                          "(a text that is no UTF-8 would fail the read)",
                          "fewer own fetches")


def test_the_check_of_own_fetches_sees_each_kind():
    tree = ast.parse("rows = conn.execute('SELECT 1').fetchall()\n"
                     "for row in self.db.conn.execute('SELECT 1'): pass\n"
                     "names = {r[0] for r in copy.execute('SELECT 1')}\n"
                     "pairs = dict(conn.execute('SELECT 1, 2'))\n"
                     "fine = [r for r in self.db.execute('SELECT 1')]\n"
                     "also = fetch_rows(conn.execute('SELECT 1'))\n")
    assert sorted(_own_fetches(tree)) == [1, 2, 3, 4]


# SQL only one engine understands is printed by that engine's dialect (store/dialect.py and
# its query printers): none in the query compiler or the planner; today's
# offenders above them are listed with their counts of lines, which may only go down.
_SQLITE_ONLY = re.compile(r"\b(typeof|json_[a-z_]+|group_concat|sqlite_master)\(|INSERT OR |"
                          r"INDEXED BY|PRAGMA |AUTOINCREMENT|RAISE\(IGNORE|-9e999")
SQLITE_ONLY_ALLOWED = {"cep/sqlgen.py": 2}


def _sqlite_only_lines() -> dict[str, int]:
    found: dict[str, set] = {}
    for path in MODULES:
        rel = str(path.relative_to(PACKAGE))
        if rel.startswith("store/"):
            continue
        tree = _tree(path)
        skip = _docstring_ids(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and id(node) not in skip and _SQLITE_ONLY.search(node.value):
                found.setdefault(rel, set()).add(node.lineno)
    return {rel: len(lines) for rel, lines in found.items()}


def test_engine_specific_sql_is_printed_by_a_dialect():
    found = _sqlite_only_lines()
    assert not any(rel.startswith(("sqlcompile/", "planner.py")) for rel in found), found
    _assert_counts_within(found, SQLITE_ONLY_ALLOWED,
                          "SQLite-only SQL outside the dialects: {grown} (add a dialect printer)",
                          "fewer SQLite-only places")


# ------------------------------------------------------------ private names stay private
# A name with one leading underscore belongs to the module that defines it: another module
# reaching it (``kb._plan``, ``from .model import _fmt``) depends on what its owner may
# change without notice. Such a name is made public (and documented) or the code moves to
# its owner. The allow-list is empty and is to stay so.

PRIVATE_REACHES_ALLOWED: set[str] = set()


def _private_definitions(trees: dict[str, ast.AST]) -> dict[str, set[str]]:
    """Private name -> the modules defining it (functions, classes, assigned names and
    attributes)."""
    defined: dict[str, set[str]] = {}
    for rel, tree in trees.items():
        for node in ast.walk(tree):
            name = None
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = node.name
            elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
                name = node.attr
            elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                name = node.id
            if name and name.startswith("_") and not name.startswith("__"):
                defined.setdefault(name, set()).add(rel)
    return defined


def private_reaches(trees: dict[str, ast.AST]) -> list[str]:
    """Each place where a module reads a private name another module defines (an attribute
    of anything but ``self``/``cls``, or a ``from ... import _name``)."""
    defined = _private_definitions(trees)
    places = []
    for rel, tree in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                places += [f"{rel}:{node.lineno}: imports {a.name}" for a in node.names
                           if a.name.startswith("_") and not a.name.startswith("__")]
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) \
                    and node.func.id in ("getattr", "hasattr", "setattr") and len(node.args) >= 2 \
                    and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str) \
                    and not (isinstance(node.args[0], ast.Name) and node.args[0].id in ("self", "cls")):
                name = node.args[1].value
                owners = defined.get(name, set())
                if name.startswith("_") and not name.startswith("__") and owners \
                        and rel not in owners:
                    places.append(f"{rel}:{node.lineno}: {node.func.id}(..., {name!r}) (defined in "
                                  f"{', '.join(sorted(owners))})")
            elif isinstance(node, ast.Attribute) and node.attr.startswith("_") \
                    and not node.attr.startswith("__") \
                    and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
                owners = defined.get(node.attr, set())
                if owners and rel not in owners:
                    places.append(f"{rel}:{node.lineno}: .{node.attr} (defined in "
                                  f"{', '.join(sorted(owners))})")
    return places


def test_no_module_reaches_a_private_name_of_another():
    trees = {str(p.relative_to(PACKAGE)): _tree(p) for p in MODULES}
    found = [p for p in private_reaches(trees) if p.split(":")[0] not in PRIVATE_REACHES_ALLOWED]
    assert not found, ("private names reached from another module (make the name public "
                       "and documented, or move the code to its owner):\n" + "\n".join(found))


@pytest.mark.parametrize("source, reached", [
    ({"a.py": "def _helper(): pass", "b.py": "from a import _helper"}, ["b.py:1: imports _helper"]),
    ({"a.py": "class K:\n    def __init__(self):\n        self._lock = 1",
      "b.py": "def f(k):\n    return k._lock"}, ["b.py:2: ._lock (defined in a.py)"]),
    ({"a.py": "class K:\n    def __init__(self):\n        self._lock = 1\n"
              "    def f(self):\n        return self._lock"}, []),
    ({"a.py": "def _helper(): pass", "b.py": "def _helper(): pass\nx = y._helper"}, []),
    ({"a.py": "class K:\n    def __init__(self):\n        self._sync = 1",
      "b.py": "s = getattr(kb, '_sync', None)"}, ["b.py:1: getattr(..., '_sync') (defined in a.py)"]),
])
def test_the_private_name_scan_finds_reaches_and_only_those(source, reached):
    trees = {rel: ast.parse(text) for rel, text in source.items()}
    assert private_reaches(trees) == reached


# ------------------------------------------------------------------ the host Protocol
# The parts the facade attaches (layer 6 and the planner) reach it only through what
# slr_sql.host.Host names; a knowledge base is a Host.

HOSTED = ["sync.py", "buffers.py", "cep/__init__.py", "cep/runtime.py", "cep/where.py",
          "subscriptions/__init__.py", "subscriptions/hub.py", "shipping.py", "planner.py"]


def _protocol_members(cls: type) -> set[str]:
    return {n for n in dir(cls) if not n.startswith("_")} | set(cls.__annotations__)


def test_a_knowledge_base_is_a_host():
    import slr_sql
    from slr_sql.host import Host, LoadedProgram

    with slr_sql.open() as kb:
        assert isinstance(kb, Host) and isinstance(kb.loader, LoadedProgram)
        for name in _protocol_members(Host):
            assert hasattr(kb, name), name


@pytest.mark.parametrize("rel", HOSTED)
def test_the_attached_parts_use_only_what_the_host_offers(rel):
    from slr_sql.host import Host

    offered = _protocol_members(Host)
    used = set()
    for node in ast.walk(ast.parse((PACKAGE / rel).read_text())):
        if isinstance(node, ast.Attribute):
            base = node.value
            if (isinstance(base, ast.Name) and base.id == "kb") or (
                    isinstance(base, ast.Attribute) and base.attr == "kb"
                    and isinstance(base.value, ast.Name) and base.value.id == "self"):
                used.add(node.attr)
    assert used <= offered, f"{rel} uses {sorted(used - offered)} of the kb, not in host.Host"


# ------------------------------------------------------------ a typed knowledge base
# Above the facade (the service, the ROS bridge, the command line, ...) a knowledge base is
# typed: api.KnowledgeBaseAPI when a local or a remote one will do, kb.KnowledgeBase when
# the code needs the store in this process. ``kb: Any`` would let a renamed method break
# them with no error from mypy.

def untyped_knowledge_bases(trees: dict[str, ast.AST]) -> list[str]:
    """``file:line: function`` of each parameter named ``kb`` annotated ``Any``."""
    found = []
    for rel, tree in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                args = node.args
                for arg in args.posonlyargs + args.args + args.kwonlyargs:
                    note = arg.annotation
                    text = ast.unparse(note) if note is not None else ""
                    if arg.arg == "kb" and text.strip("'\"") in ("Any", "typing.Any"):
                        found.append(f"{rel}:{arg.lineno}: {getattr(node, 'name', 'lambda')}")
    return found


def test_no_knowledge_base_above_the_facade_is_typed_any():
    trees = {str(p.relative_to(PACKAGE)): _tree(p) for p in MODULES
             if LAYERS[_family(p)] >= LAYERS["demo"]}
    assert len(trees) > 20
    assert untyped_knowledge_bases(trees) == [], (
        "type kb with slr_sql.api.KnowledgeBaseAPI (or kb.KnowledgeBase where the store "
        "must be in this process)")


@pytest.mark.parametrize("source, found", [
    ("def f(kb: Any): pass", ["m.py:1: f"]),
    ("class S:\n    def __init__(self, x, kb: 'Any' = None): pass", ["m.py:2: __init__"]),
    ("async def g(*, kb: typing.Any): pass", ["m.py:1: g"]),
    ("def f(kb: KnowledgeBaseAPI, other: Any): pass", []),
])
def test_the_untyped_kb_scan_finds_those(source, found):
    assert untyped_knowledge_bases({"m.py": ast.parse(source)}) == found
