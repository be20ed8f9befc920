"""A file's or a program's name is text wherever the CLI shows it: the progress bars of
``slr ingest`` and ``slr ros import`` (rich markup) show ``[bold red]x`` as written, not in
red, and ``slr load`` / ``slr unload`` name a program as the rest of the CLI names things
(printable.py), not as Python's repr. The bars are drawn only on a terminal: a pseudo-terminal
(real) takes stderr here."""
from __future__ import annotations

import os
import pty
import subprocess
import sys

from test_cli import ROOT, slr
from test_ros_import import make_bag, robot_items

RED = "\x1b[1;31m"


def on_a_terminal(*args: str, cwd) -> tuple[int, str, str]:
    """``slr ARGS`` with stderr on a pseudo-terminal: (exit code, stdout, what the terminal
    got)."""
    master, slave = pty.openpty()
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
               COLUMNS="200", TERM="xterm", SLR_HISTORY=os.devnull)
    try:
        done = subprocess.run([sys.executable, "-m", "slr_sql", *args], stdin=subprocess.DEVNULL,
                              stdout=subprocess.PIPE, stderr=slave, cwd=cwd, env=env,
                              timeout=120)
    finally:
        os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:        # (the terminal's other end is closed: all is read)
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    return done.returncode, done.stdout.decode(), b"".join(chunks).decode(errors="replace")


def test_ingest_shows_a_file_name_that_looks_like_markup_as_written(tmp_path):
    (tmp_path / "[bold red]x.slr").write_text("p(1)^1.\n", encoding="utf-8")
    code, out, terminal = on_a_terminal("ingest", "t.db", "[bold red]x.slr", "--progress",
                                        cwd=tmp_path)
    assert (code, out) == (0, "ingested 1 event\n"), terminal
    assert "ingesting [bold red]x.slr" in terminal and RED not in terminal


def test_ros_import_shows_a_bag_name_that_looks_like_markup_as_written(tmp_path):
    bag = make_bag.write_bag(tmp_path / "[bold red]rec", "mcap", robot_items("mcap"))
    (tmp_path / "robot.yaml").write_text("topics:\n  /battery:\n    args: [data]\n",
                                         encoding="utf-8")
    code, out, terminal = on_a_terminal("ros", "import", str(bag), "--db", "r.db", "--map",
                                        "robot.yaml", cwd=tmp_path)
    assert code == 0 and "imported 3 events" in out, terminal
    assert f"importing {os.path.basename(bag)}" in terminal and RED not in terminal


def test_load_and_unload_name_the_program_as_the_cli_names_things(tmp_path):
    (tmp_path / "tea.slr").write_text("hot(tea).\n", encoding="utf-8")
    db = str(tmp_path / "t.db")
    r = slr("load", db, str(tmp_path / "tea.slr"), "--name", "tea")
    assert r.stdout == f"loaded {tmp_path / 'tea.slr'} as program tea\n", r.stderr
    r = slr("load", db, str(tmp_path / "tea.slr"), "--name", "it's\nhot")
    assert r.stdout.endswith(" as program 'it\\'s\\nhot'\n"), r.stdout
    assert slr("unload", db, "tea").stdout == "unloaded program tea\n"


def test_the_shell_names_a_loaded_file_as_slr_load_does(tmp_path):
    # a file name with a tab: quoted and escaped as one name, as slr load prints it,
    # not escaped in place (which read as two words with a backslash)
    name = tmp_path / "te\ta.slr"
    name.write_text("hot(tea).\n", encoding="utf-8")
    db = str(tmp_path / "t.db")
    assert slr("load", db, str(tmp_path / "te\ta.slr"), "--name", "x").returncode == 0
    r = slr("shell", db, stdin=f"load '{name}'.\nhot(X).\n")
    assert f"loaded '{tmp_path}/te\\ta.slr'\n" in r.stdout, (r.stdout, r.stderr)
