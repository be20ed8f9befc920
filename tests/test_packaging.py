"""What `pip install .` ships: every package of the source tree (a subpackage left out of
pyproject.toml's list installs an `slr` whose first import fails, while the tests, which run
from the checkout, still pass)."""
from __future__ import annotations

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
