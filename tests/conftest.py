"""Shared fixtures: a fresh knowledge base in memory and on disk.

Other test files may add fixtures here; keep each one independent of the others.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # run from a checkout without installing the package
    sys.path.insert(0, str(REPO))

import slr_sql  # noqa: E402
from hypothesis import settings  # noqa: E402

# CI must not be flaky: every hypothesis test replays the same examples on every run (a failure
# found locally with HYPOTHESIS_PROFILE=explore is added to the test as an @example).
settings.register_profile("ci", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("explore", deadline=None)
settings.load_profile(__import__("os").environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture
def kb():
    """A fresh in-memory knowledge base (no file), closed after the test."""
    k = slr_sql.open()
    try:
        yield k
    finally:
        k.close()


@pytest.fixture
def db_path(tmp_path: Path) -> Path:
    """The path of a not yet existing database file in a per-test directory."""
    return tmp_path / "robot.db"


@pytest.fixture
def file_kb(db_path: Path):
    """A fresh knowledge base in a file (``file_kb.path``), closed after the test."""
    k = slr_sql.open(db_path)
    try:
        yield k
    finally:
        k.close()


@pytest.fixture(params=["memory", "file"])
def any_kb(request, tmp_path: Path):
    """The same test once on an in-memory and once on an on-disk knowledge base."""
    k = slr_sql.open(None if request.param == "memory" else tmp_path / "robot.db")
    try:
        yield k
    finally:
        k.close()
