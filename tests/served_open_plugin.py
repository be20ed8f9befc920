"""A pytest plugin (``-p served_open_plugin``) that runs tests written for a local knowledge
base against the network service: ``slr_sql.open(...)`` opens the store as asked (the same
path, clock and options), serves it on a real uvicorn server on a free loopback port, and
returns ``slr_sql.connect``'s client of it; closing the client stops that server and closes
the store. tests/test_conformance_remote.py runs the SPEC conformance files with it.

The server runs in the test's process, so a ``ManualClock`` the test holds is the served
store's clock (``clock.set(t)`` releases the server's waiting queries); every call of the
test goes through HTTP and WebSocket. Each test must have opened at least one knowledge base
(an autouse fixture checks), so a test that bypassed ``slr_sql.open`` cannot pass unseen.
"""
from __future__ import annotations

import socket
import threading
import time

import pytest
import uvicorn

import slr_sql
from slr_sql.service.app import create_app
from slr_sql.service.client import RemoteKnowledgeBase

_local_open = slr_sql.open
OPENED = [0]
START_DEADLINE = 30.0


class _ServedStore:
    def __init__(self, *args, **kwargs):
        self.kb = _local_open(*args, **kwargs)
        sock = socket.socket()
        sock.bind(("127.0.0.1", 0))
        sock.listen(128)
        self.url = f"http://127.0.0.1:{sock.getsockname()[1]}"
        config = uvicorn.Config(create_app(self.kb), log_level="warning", lifespan="off")
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [sock]},
                                       daemon=True, name="served-store")
        self.thread.start()
        deadline = time.monotonic() + START_DEADLINE
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                self.kb.close()
                raise RuntimeError("the served store did not start")
            time.sleep(0.01)
        self.sock = sock

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(START_DEADLINE)
        self.sock.close()
        self.kb.close()


class ServedClient(RemoteKnowledgeBase):
    """The client of a store served for one test; ``close()`` also stops the server."""

    def __init__(self, served: _ServedStore):
        super().__init__(served.url)
        self._served = served

    def close(self) -> None:
        if self.closed:
            return
        try:
            super().close()
        finally:
            self._served.stop()


def served_open(*args, **kwargs) -> ServedClient:
    OPENED[0] += 1
    return ServedClient(_ServedStore(*args, **kwargs))


def pytest_configure(config) -> None:
    slr_sql.open = served_open


def pytest_unconfigure(config) -> None:
    slr_sql.open = _local_open


@pytest.fixture(autouse=True)
def _through_the_service():
    before = OPENED[0]
    yield
    assert OPENED[0] > before, "the test opened no knowledge base through the service"


def pytest_terminal_summary(terminalreporter) -> None:
    terminalreporter.write_line(f"served stores opened: {OPENED[0]}")
