"""The SPEC conformance files (SPEC §1–§4, §3, §6–§7 examples), written for a local knowledge
base, run unchanged against `slr_sql.connect`'s client of a served store
(tests/served_open_plugin.py): the remote client keeps SPEC's contract word for word."""
from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
FILES = ("test_core.py", "test_sync.py", "test_events.py")


def _conformance_dir() -> Path:
    for candidate in (os.environ.get("SLR_CONFORMANCE"), ROOT.parent / "shared" / "conformance",
                      "/work/shared/conformance"):
        if candidate and all((Path(candidate) / f).is_file() for f in FILES):
            return Path(candidate)
    raise AssertionError("the SPEC conformance files were not found: set SLR_CONFORMANCE to "
                         "the directory holding " + ", ".join(FILES))


def _count_tests(path: Path) -> int:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return sum(1 for node in tree.body
               if isinstance(node, ast.FunctionDef) and node.name.startswith("test"))


def run_conformance_files(tmp_path: Path, plugin: str, env_extra: dict | None = None) -> str:
    """Run SPEC's conformance files in a pytest of their own with ``plugin`` (``env_extra``
    added to its environment); assert every test passed and return the output (the plugin's
    summary line is in it)."""
    directory = _conformance_dir()
    files = [str(directory / f) for f in FILES]
    expected = sum(_count_tests(Path(f)) for f in files)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(TESTS), env.get("PYTHONPATH", "")])
    # of the installed pytest plugins only pytest-timeout (the conformance files use no
    # other): loading every one (hypothesis, benchmark, anyio, xdist) cost a second or two
    # of CPU per run
    env["PYTEST_DISABLE_PLUGIN_AUTOLOAD"] = "1"
    env.update(env_extra or {})
    result = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "pytest_timeout",
         "-p", plugin, "--rootdir", str(tmp_path), "-o", "timeout=120", *files],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-5000:]
    assert re.search(rf"\b{expected} passed\b", output), output[-3000:]
    return output


def test_the_conformance_files_pass_against_a_served_store(tmp_path):
    output = run_conformance_files(tmp_path, "served_open_plugin")
    expected = sum(_count_tests(_conformance_dir() / f) for f in FILES)
    opened = int(re.search(r"served stores opened: (\d+)", output).group(1))
    assert opened >= expected, output[-3000:]
