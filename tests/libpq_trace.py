"""The protocol messages a PostgreSQL knowledge base's connection exchanges while a call runs,
from libpq's own trace (no timing, no mock): what the round-trip tests count."""
from __future__ import annotations

import tempfile
from typing import Any, Callable

from psycopg import pq


def traced_messages(kb: Any, call: Callable[[], Any]) -> list[list[str]]:
    """The tab-separated fields of every message of ``kb``'s connection while ``call()``
    runs: direction (F: sent by the client, B: by the server), length, type, content."""
    raw = kb.store._conn.raw
    with tempfile.TemporaryFile("w+") as out:
        raw.pgconn.trace(out.fileno())
        raw.pgconn.set_trace_flags(pq.Trace.SUPPRESS_TIMESTAMPS | pq.Trace.REGRESS_MODE)
        try:
            call()
        finally:
            raw.pgconn.untrace()
        out.seek(0)
        return [line.split("\t") for line in out.read().splitlines()]
