"""A pytest-xdist worker ends quickly once its session is finished (tests/xdist_worker_exit.py):
the objects the session left are frozen before the worker reports it finished, so pytest's
last full collections -- run while execnet waits at most 5 s before it sends the worker a
SIGINT -- traverse none of them. A real run of pytest with two workers, in a subprocess."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
KEPT = 200_000   # objects a session keeps (the suite's workers keep far more)


def test_a_workers_last_collections_traverse_none_of_its_sessions_objects(tmp_path):
    (tmp_path / "conftest.py").write_text(
        "import gc, json, os\n"
        "from xdist_worker_exit import pytest_sessionfinish  # noqa: F401\n"
        "def pytest_unconfigure(config):\n"
        "    if hasattr(config, 'workerinput'):\n"
        "        seen = {'traversed': len(gc.get_objects()), 'frozen': gc.get_freeze_count()}\n"
        "        name = config.workerinput['workerid'] + '.json'\n"
        "        with open(os.path.join(os.environ['SEEN'], name), 'w') as out:\n"
        "            json.dump(seen, out)\n")
    (tmp_path / "test_kept.py").write_text(
        "KEPT = []\n"
        "def test_a_session_that_keeps_many_objects():\n"
        f"    KEPT.extend([] for _ in range({KEPT}))\n"
        "def test_another():\n"
        "    pass\n")
    seen = tmp_path / "seen"
    seen.mkdir()
    # only xdist among the installed plugins: each of the three processes loaded every one
    # (hypothesis alone ~1 s of CPU), 5 s of CPU for a run whose tests take milliseconds;
    # what is checked is this hook's in a real two-worker run
    env = dict(os.environ, SEEN=str(seen), PYTEST_DISABLE_PLUGIN_AUTOLOAD="1",
               PYTHONPATH=os.pathsep.join(
                   [str(TESTS)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                          "-p", "xdist.plugin", "-n", "2", str(tmp_path)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stdout + run.stderr
    workers = {p.stem: json.loads(p.read_text()) for p in seen.iterdir()}
    assert sorted(workers) == ["gw0", "gw1"], workers
    # the kept objects are frozen in the worker that made them, and no worker's last
    # collections traverse them
    assert max(w["frozen"] for w in workers.values()) >= KEPT, workers
    assert all(w["traversed"] < KEPT // 2 for w in workers.values()), workers
