"""BackgroundServer: the service of an open knowledge base from a thread of the program that
holds it; the remote client reaches it as it reaches `slr serve`."""
from __future__ import annotations

import httpx
import pytest

import slr_sql
from slr_sql.service.background import BackgroundServer, ServerState


def test_a_client_adds_and_queries_and_the_holder_sees_it_in_its_own_knowledge_base(tmp_path):
    with slr_sql.open(tmp_path / "robot.db", clock=slr_sql.ManualClock(10.0)) as local:
        with BackgroundServer(local) as server, slr_sql.connect(server.url) as remote:
            remote.add("seen(cup1)^2")
            remote.load("cup(X) :- seen(X)^_.", name="cups")
            assert [str(a["X"]) for a in remote.query("cup(X)")] == ["cup1"]
            assert [str(a["X"]) for a in local.query("cup(X)")] == ["cup1"]
        # stopped: the knowledge base is still the holder's, open, with what was added
        assert server.state is ServerState.STOPPED
        local.add("seen(cup2)^3")
        assert sorted(str(a["X"]) for a in local.query("seen(X)^_")) == ["cup1", "cup2"]


def test_a_stopped_server_listens_no_more_and_does_not_start_again():
    with slr_sql.open() as local:
        server = BackgroundServer(local).start()
        url = server.url
        assert httpx.get(url + "/health").json()["status"] == "ok"
        server.stop()
        with pytest.raises(httpx.ConnectError):
            httpx.get(url + "/health")
        with pytest.raises(slr_sql.SLRError, match="stopped, not serving"):
            server.url
        with pytest.raises(slr_sql.SLRError, match="make another"):
            server.start()
        server.stop()          # (again: nothing to do)


def test_a_token_is_asked_of_every_client_and_none_is_refused_beyond_loopback():
    with slr_sql.open() as local:
        with BackgroundServer(local, token="s3cret") as server:
            assert httpx.get(server.url + "/programs").status_code == 401
            with slr_sql.connect(server.url, token="s3cret") as remote:
                assert remote.health()["status"] == "ok"
        with pytest.raises(slr_sql.SLRError, match="without a token"):
            BackgroundServer(local, host="0.0.0.0")
        assert BackgroundServer(local).state is ServerState.MADE
