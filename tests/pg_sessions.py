"""What the PostgreSQL tests that end the store's session share: a store holding one event
and the server process of its connection, and ending that process as an administrator would."""
from __future__ import annotations

import contextlib
from typing import Any, Iterator

import psycopg

import slr_sql
from slr_sql import ManualClock


@contextlib.contextmanager
def store_and_backend(url: str) -> Iterator[tuple[Any, int]]:
    """A store at ``url`` holding ``p(0)^0``, and the pid of its connection's backend."""
    with slr_sql.open(url, clock=ManualClock(0.0)) as kb:
        kb.add("p(0)^0")
        yield kb, kb.sql("SELECT pg_backend_pid()", write=True)[1][0][0]


def terminate(url: str, pid: int) -> None:
    """End the backend ``pid`` (pg_terminate_backend, waiting up to 10 s for it to go)."""
    with psycopg.connect(url, autocommit=True) as admin:
        admin.execute("SELECT pg_terminate_backend(%s, 10000)", (pid,))
