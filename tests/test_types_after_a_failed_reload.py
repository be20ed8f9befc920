"""After a rollback the store reads its event types again (a type created inside the
transaction is gone with it). When that reading fails (PostgreSQL: the server ended the
connection under the transaction, and no new one can be opened for a while), the cache of
types is marked stale and read again at its next use, instead of keeping a type whose
table the rollback took back."""
from __future__ import annotations

import psycopg
import pytest

import slr_sql
from slr_sql import ManualClock, SLRError


def _as_admin(url: str, statement: str, params: tuple = ()) -> None:
    with psycopg.connect(url, autocommit=True) as admin:
        admin.execute(statement, params)


def _event_types_in_a_transaction(store) -> set:
    with store.transaction():   # (outside one, event_types reads the types again anyway)
        return set(store.event_types())


# each reader of the cache, the first to use it after the failed reading
READERS = {
    "table_for": lambda store: {("fresh", 1)} if store.table_for("fresh", 1) else set(),
    "declared_types": lambda store: store.declared_types(),
    "event_types": _event_types_in_a_transaction,
}


@pytest.mark.parametrize("reader", sorted(READERS))
def test_a_type_created_in_a_transaction_the_server_ended_is_forgotten(postgres_server,
                                                                       postgres_url, reader):
    admin = postgres_server[1]
    name = psycopg.conninfo.conninfo_to_dict(postgres_url)["dbname"]
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.add("p(0)^0")
        pid = kb.sql("SELECT pg_backend_pid()", write=True)[1][0][0]
        try:
            with pytest.raises(SLRError) as caught:
                with kb.store.transaction():
                    kb.store.declare_type("fresh", 1)   # (its table made in this transaction)
                    kb.add("fresh(1)^1")
                    # the connection ended, and none to be had while the rollback's
                    # listeners read the types again
                    _as_admin(admin, f'ALTER DATABASE "{name}" ALLOW_CONNECTIONS false')
                    _as_admin(admin, "SELECT pg_terminate_backend(%s, 10000)", (pid,))
                    raise SLRError("the body's own reason")
        finally:
            _as_admin(admin, f'ALTER DATABASE "{name}" ALLOW_CONNECTIONS true')
        assert str(caught.value) == "the body's own reason"
        kb.store.execute("SELECT 1")   # (the store's connection opened again)
        assert ("fresh", 1) not in READERS[reader](kb.store)
        kb.add("fresh(2)^2")
        assert [a["X"] for a in kb.query("fresh(X)^_")] == [2]
        assert [a["X"] for a in kb.query("p(X)^_")] == [0]
