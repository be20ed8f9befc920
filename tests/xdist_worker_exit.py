"""The end of a pytest-xdist worker: its last garbage collections made cheap, so that it ends
before execnet stops waiting for it.

When the last worker reports its session finished, the controller asks every worker to end,
and execnet's side of the worker waits 5 s for the run to return, then sends its own process
a SIGINT (``execnet.gateway_base.WorkerGateway._terminate_execution``). What a worker still
does then is pytest's unconfigure, whose clean-up runs five full collections (to bring out
unraisable exceptions): on a worker that ran half the suite, on a shared machine, they took
longer than 5 s, and the SIGINT's KeyboardInterrupt landed in the only Python code a
collection runs, hypothesis's gc callback -- a ``PytestUnraisableExceptionWarning`` printed
after every test had passed. (On this machine, loaded: 370,000 objects left by three test
files took 3.4 s for the five.)

So a worker collects once more when its session's fixtures are torn down, before it reports
the session finished (nothing waits for it yet), and freezes what is left (``gc.freeze``):
the later collections traverse only what was made after. The garbage of the session is
still collected (and its unraisable exceptions reported) by that collection.
"""
from __future__ import annotations

import gc

import pytest


@pytest.hookimpl(trylast=True)   # (after the runner's, which tears the session's fixtures down)
def pytest_sessionfinish(session: pytest.Session) -> None:
    if hasattr(session.config, "workerinput"):   # an xdist worker (execnet's clock follows)
        gc.collect()
        gc.freeze()
