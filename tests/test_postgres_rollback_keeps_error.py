"""PostgreSQL: a nested transaction's level ends with an error after the server ended the
connection under it (an administrator's termination). Its ROLLBACK TO cannot be sent: the
error its caller hears is the body's own, not the rollback's; and an enclosing level that
goes on never commits on a connection opened again (the transaction is gone: it fails)."""
from __future__ import annotations

import pytest

from slr_sql import SLRError, SLRUnavailable

from pg_sessions import store_and_backend, terminate


def _count(kb) -> int:
    return kb.query("aggregate_all(count, p(_)^_, N)")[0]["N"]


def test_the_bodys_error_survives_a_rollback_that_cannot_be_sent(postgres_url):
    with store_and_backend(postgres_url) as (kb, pid):
        with pytest.raises(SLRError) as caught:
            with kb.store.transaction():
                kb.add("p(1)^1")
                with kb.store.transaction():
                    kb.add("p(2)^2")
                    terminate(postgres_url, pid)
                    raise SLRError("the body's own reason")
        assert str(caught.value) == "the body's own reason"
        assert _count(kb) == 1


def test_an_enclosing_level_that_goes_on_does_not_commit_on_a_new_connection(postgres_url):
    with store_and_backend(postgres_url) as (kb, pid):
        with pytest.raises(SLRUnavailable):
            with kb.store.transaction():
                kb.add("p(1)^1")
                try:
                    with kb.store.transaction():
                        kb.add("p(2)^2")
                        terminate(postgres_url, pid)
                        raise SLRError("the body's own reason")
                except SLRError:
                    pass
        assert _count(kb) == 1

