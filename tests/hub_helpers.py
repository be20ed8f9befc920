"""A store whose subscription hub runs a delivery pass only when a test asks for one."""
from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pytest

import slr_sql
from slr_sql import ManualClock

DEADLINE = 30.0   # seconds a wait may take before the test fails


@contextmanager
def hub_with_one_delivery(where: str, caplog: pytest.LogCaptureFixture,
                          **open_kwargs: Any) -> Iterator[tuple[Any, Any, Any]]:
    """``(kb, hub, sub)``: the store at ``where`` (a file or a PostgreSQL URL) opened with a
    ManualClock, its hub passing only on ``hub.drain`` (no timer), a subscription to
    ``p(X)^T`` that got ``p(1)^1`` already, and the slr_sql WARNING lines in ``caplog``."""
    with slr_sql.open(where, clock=ManualClock(0.0), **open_kwargs) as kb, \
            caplog.at_level(logging.WARNING, logger="slr_sql"):
        hub = kb._subscriptions
        hub.poll_interval = 3600.0        # a pass runs when asked for, not on a timer
        sub = kb.subscribe("p(X)^T", since=0)
        kb.add("p(1)^1")
        assert sub.get(timeout=DEADLINE)["X"] == 1
        yield kb, hub, sub
