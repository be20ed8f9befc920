"""What `pip install .` ships: every package of the source tree (a subpackage left out of
pyproject.toml's list installs an `slr` whose first import fails, while the tests, which run
from the checkout, still pass)."""
from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_every_package_of_the_source_tree_is_installed():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    listed = set(config["tool"]["setuptools"]["packages"])
    found = {".".join(init.parent.relative_to(ROOT).parts)
             for init in (ROOT / "slr_sql").rglob("__init__.py")}
    assert found - listed == set(), "packages missing from pyproject.toml"
    package_dirs = config["tool"]["setuptools"].get("package-dir", {})
    for name in listed - found:     # the rest are mapped folders (migrations)
        assert name in package_dirs and (ROOT / package_dirs[name]).is_dir(), name


def test_the_grammar_and_migrations_ship_as_package_data():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    data = config["tool"]["setuptools"]["package-data"]
    assert "*.lark" in data["slr_sql.grammar"] and list((ROOT / "slr_sql/grammar").glob("*.lark"))
    assert "*.sql" in data["slr_sql.migrations"] and list((ROOT / "migrations").glob("*.sql"))


# an import statement's line: `import a.b [as c][, ...]` or `from a.b import ...` (not prose
# in a docstring that begins with "from" or "import")
_IMPORT_LINE = re.compile(r"^[ \t]*(?:import[ \t]+([A-Za-z_]\w*)[\w.]*(?:[ \t]+as[ \t]+\w+)?"
                          r"[ \t]*(?:,|#|;|$)|from[ \t]+([A-Za-z_]\w*)[\w.]*[ \t]+import[ \t(])",
                          re.MULTILINE)


def _imported_modules(folder: Path) -> set[str]:
    """The top-level names every ``import`` of ``folder``'s Python files names (in functions
    too), relative imports and optional ones (in a ``try`` that catches ImportError) left
    out. (A file without "ImportError" is read line by line, the others parsed: parsing
    every file took seconds.)"""
    import ast
    names: set[str] = set()
    for path in folder.rglob("*.py"):
        text = path.read_text(encoding="utf-8")
        if "ImportError" not in text:
            names.update(a or b for a, b in _IMPORT_LINE.findall(text))
            continue
        tree = ast.parse(text)
        optional = {id(inner) for node in ast.walk(tree) if isinstance(node, ast.Try)
                    and any(isinstance(h.type, ast.Name) and h.type.id in
                            ("ImportError", "ModuleNotFoundError") for h in node.handlers)
                    for statement in node.body for inner in ast.walk(statement)}
        for node in ast.walk(tree):
            if id(node) in optional:
                continue
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
    return names


def _requirement_closure(extra: str) -> set[str]:
    """The distributions ``pip install '.[extra]'`` installs, the project's own extras and
    every requirement's requirements included (as installed here), normalized names."""
    from importlib import metadata
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    extras = config["project"]["optional-dependencies"]

    def name_of(requirement: str) -> str:
        return re.split(r"[\s<>=!~;\[(]", requirement.strip(), maxsplit=1)[0].lower() \
            .replace("_", "-")

    wanted = [*config["project"].get("dependencies", []), *extras[extra]]
    seen: set[str] = set()
    while wanted:
        requirement = wanted.pop()
        if requirement.startswith("slr_sql["):
            for inner in requirement[len("slr_sql["):-1].split(","):
                wanted.extend(extras[inner])
            continue
        if ";" in requirement and "extra ==" in requirement:
            continue                    # another package's optional extra
        name = name_of(requirement)
        if name in seen:
            continue
        seen.add(name)
        try:
            wanted.extend(metadata.requires(name) or [])
        except metadata.PackageNotFoundError:
            pass                        # the import check below names what is missing
    return seen


def test_every_module_the_tests_import_is_installed_by_the_test_extra():
    """A package the tests import but ``.[test]`` does not install fails a clean clone's CI
    at collection, while a machine that happens to have it passes."""
    import sys
    from importlib import metadata
    local = {p.stem for p in (ROOT / "tests").glob("*.py")} | {
        p.stem for p in (ROOT / "examples").rglob("*.py")} | {"slr_sql", "_slr_sql_speedups"}
    third_party = {name for name in _imported_modules(ROOT / "tests") | _imported_modules(
        ROOT / "slr_sql") if name not in sys.stdlib_module_names and name not in local}
    installed = _requirement_closure("test")
    providers = metadata.packages_distributions()
    missing = {name: providers.get(name, ["(not installed)"]) for name in third_party
               if not any(d.lower().replace("_", "-") in installed
                          for d in providers.get(name, []))}
    assert missing == {}, f"imported, not installed by pip install '.[test]': {missing}"
