"""PostgreSQL: a connection the server ended (an administrator's pg_terminate_backend) and
the store found closed is opened again by the next transaction that has sent nothing yet
-- its BEGIN, locks, savepoints and rows go on the new connection, and it commits -- as a
plain read opens it again (was: SLRServerUnreachable "the connection is closed" for every
transaction until a read outside one reconnected). A transaction whose BEGIN went before
the connection was lost is never carried on, on a new one: it fails as a whole."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql import ManualClock, SLRServerUnreachable

from pg_sessions import store_and_backend, terminate


def _end_the_stores_connection(kb, url: str) -> None:
    """Terminate the store's session, and let the store find its connection closed (the
    statement that finds it fails; nothing of a transaction was sent on it)."""
    terminate(url, kb.sql("SELECT pg_backend_pid()", write=True)[1][0][0])
    with pytest.raises(SLRServerUnreachable):
        kb.store.data_version()
    assert kb.store._db.conn.raw.closed


def _stored(url: str) -> list:
    with slr_sql.open(url, clock=ManualClock(0.0)) as other:
        return sorted(a["X"] for a in other.query("p(X)^_"))


def test_a_transaction_that_sent_nothing_opens_the_connection_again(postgres_url):
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add("p(0)^0")
        _end_the_stores_connection(kb, postgres_url)
        with kb.store.transaction():
            kb.add("p(1)^1")
        _end_the_stores_connection(kb, postgres_url)
        with kb.store.transaction():          # nested levels, their savepoints pending
            with kb.store.transaction():
                kb.add("p(2)^2")
            kb.add("p(3)^3")
        _end_the_stores_connection(kb, postgres_url)
        kb.add_many(["p(4)^4", "p(5)^5"])
        assert [a["X"] for a in kb.query("p(X)^_")] == [0, 1, 2, 3, 4, 5]
    assert _stored(postgres_url) == [0, 1, 2, 3, 4, 5]


def test_a_transaction_whose_begin_went_fails_as_a_whole(postgres_url):
    with store_and_backend(postgres_url) as (kb, pid):
        with pytest.raises(SLRServerUnreachable):
            with kb.store.transaction():
                kb.add("p(1)^1")
                kb.store.count("p", 1)          # (sent: the BEGIN went)
                terminate(postgres_url, pid)
                with pytest.raises(SLRServerUnreachable):
                    kb.store.data_version()     # found closed
                kb.add("p(2)^2")                # not on a new connection
        kb.add("p(3)^3")                        # the next transaction: a new one
    assert _stored(postgres_url) == [0, 3]
