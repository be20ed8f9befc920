"""The SPEC conformance files written for SQLite (§1–§4, §6–§7 examples) run unchanged on
PostgreSQL (tests/postgres_open_plugin.py: each store the tests open is a database of a server
the plugin starts): SPEC §10's "the same API and the same answers", checked with SPEC's own
examples."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

from test_conformance_remote import FILES, _conformance_dir, _count_tests

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent


def test_the_conformance_files_pass_on_postgresql(tmp_path):
    directory = _conformance_dir()
    files = [str(directory / f) for f in FILES]
    expected = sum(_count_tests(Path(f)) for f in files)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(TESTS), env.get("PYTHONPATH", "")])
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p",
         "postgres_open_plugin", "--rootdir", str(tmp_path), "-o", "timeout=120", *files],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-5000:]
    assert re.search(rf"\b{expected} passed\b", output), output[-3000:]
    opened = int(re.search(r"PostgreSQL stores opened: (\d+)", output).group(1))
    assert opened >= expected, output[-3000:]
