"""The SPEC conformance files written for SQLite (§1–§4, §6–§7 examples) run unchanged on
PostgreSQL (tests/postgres_open_plugin.py: each store the tests open is a database of a server
this worker's session runs): SPEC §10's "the same API and the same answers", checked with SPEC's own
examples."""
from __future__ import annotations

import re

from test_conformance_remote import FILES, _conformance_dir, _count_tests, run_conformance_files


def test_the_conformance_files_pass_on_postgresql(tmp_path, postgres_server):
    # the worker's server (a database per store, dropped after its test): starting and
    # initializing one more for this run cost 1.5-2 s
    output = run_conformance_files(tmp_path, "postgres_open_plugin",
                                   {"SLR_PG_ADMIN_URL": postgres_server[1]})
    expected = sum(_count_tests(_conformance_dir() / f) for f in FILES)
    opened = int(re.search(r"PostgreSQL stores opened: (\d+)", output).group(1))
    assert opened >= expected, output[-3000:]
