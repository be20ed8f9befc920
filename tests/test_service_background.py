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


def test_stop_is_prompt_once_nothing_is_in_flight():
    # uvicorn's serving loop looked at should_exit every 0.1 s and its shutdown paused 0.1 s
    # and looked for the connections' end every 0.1 s: every stop took 0.1-0.3 s (each of
    # the client's examples starts and stops a server). The fastest of a few stops, each
    # after a client's request, is well under one such pause now.
    import time

    took = []
    with slr_sql.open(clock=slr_sql.ManualClock(10)) as local:
        for _ in range(5):
            server = BackgroundServer(local).start()
            with slr_sql.connect(server.url) as remote:
                remote.add("seen(cup1)^2")
                began = time.monotonic()
                server.stop()
                took.append(time.monotonic() - began)
    assert min(took) < 0.09, took


def test_the_installed_uvicorn_keeps_what_the_prompt_stop_reads():
    # the prompt stop reads uvicorn.Server's state; a uvicorn that moved it gets its own
    # (slower) stop -- this says the one installed is the one the prompt stop was written for
    import threading
    import time

    from slr_sql.service.app import Limits, create_app
    from slr_sql.service.background import listen_on, service_server, uvicorn_config

    with slr_sql.open() as local:
        server = service_server(uvicorn_config(create_app(local), Limits()))
        assert not server.knows_uvicorn_shutdown()     # (its state comes with the start)
        sock = listen_on("127.0.0.1", 0)
        serving = threading.Thread(target=server.run, kwargs={"sockets": [sock]})
        serving.start()
        deadline = time.monotonic() + 30
        while not server.started and serving.is_alive() and time.monotonic() < deadline:
            threading.Event().wait(0.005)
        try:
            assert server.started and server.knows_uvicorn_shutdown()
        finally:
            server.request_exit()
            serving.join(30)
            sock.close()
        assert not serving.is_alive()


@pytest.mark.parametrize("uvicorn_moved", [False, True], ids=["prompt stop", "uvicorn's stop"])
def test_a_request_in_flight_when_stop_is_asked_is_still_answered(uvicorn_moved, monkeypatch):
    # the prompt stop keeps what a stop does for requests in flight: listening ends at
    # once, the request running gets the grace (stop_grace) and its answer; so does
    # uvicorn's own stop, taken when uvicorn no longer has what the prompt one reads
    import threading
    import time

    if uvicorn_moved:
        from slr_sql.service import background
        monkeypatch.setattr(background, "_UVICORN_SHUTDOWN_ATTRIBUTES",
                            background._UVICORN_SHUTDOWN_ATTRIBUTES + ("moved_away",))

    entered, release = threading.Event(), threading.Event()

    def gate(x):
        entered.set()
        release.wait(30)
        return (1,)

    with slr_sql.open(clock=slr_sql.ManualClock(10)) as local:
        local.define("gate", 1, gate)
        server = BackgroundServer(local, stop_grace=30.0).start()
        url = server.url
        answers: list = []
        remote = slr_sql.connect(url)
        asking = threading.Thread(target=lambda: answers.append(remote.query("gate(X)")))
        asking.start()
        assert entered.wait(30), "the query never reached the server"
        stopping = threading.Thread(target=server.stop)
        stopping.start()
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:     # until the server listens no more
            try:
                httpx.get(url + "/health", timeout=1)
            except httpx.TransportError:
                break
            threading.Event().wait(0.01)
        else:
            pytest.fail("the stopping server still listens")
        assert stopping.is_alive()     # waiting for the request in flight
        release.set()
        asking.join(30)
        stopping.join(30)
        remote.close()
        assert answers == [[{"X": 1}]]
        assert not stopping.is_alive()
