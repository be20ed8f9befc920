"""`slr shell` ended by SIGTERM or SIGHUP (a supervisor stopping it, the terminal's window
closed): the shell gives the terminal back as it found it (cooked: line editing and echo),
closes its store and ends as killed by that signal. The signals' default action ended the
process at once, inside the line editor or the wait for the key after an answer, with the
terminal raw: a parent that does not reset it (not every shell does) was left without echo
and line editing.

The shell runs under a parent of the test's in the pseudo-terminal (pexpect), a Python
process that resets nothing: once the shell is gone it prints the shell's exit status and the
terminal's modes, read from the terminal itself."""
from __future__ import annotations

import os
import signal
import sys
import textwrap
import time

import pexpect
import pytest
from conftest import copy_of_store
from test_cli import ROOT, slr
from test_shell import PROMPT, prepared_store, wait_for_terminal  # noqa: F401 - a fixture

PARENT = textwrap.dedent("""
    import subprocess, sys, termios
    shell = subprocess.Popen([sys.executable, "-m", "slr_sql", "shell", sys.argv[1]])
    print("SHELL", shell.pid, flush=True)
    status = shell.wait()
    lflag = termios.tcgetattr(0)[3]
    print("STATUS", status, "ICANON", int(bool(lflag & termios.ICANON)),
          "ECHO", int(bool(lflag & termios.ECHO)), flush=True)
""")


@pytest.fixture
def store(tmp_path, prepared_store) -> str:  # noqa: F811 - the module fixture of test_shell
    return copy_of_store(prepared_store, tmp_path)


def shell_under_a_parent(db: str) -> tuple[pexpect.spawn, int]:
    env = dict(os.environ, PYTHONPATH=str(ROOT), SLR_HISTORY=os.devnull, TERM="xterm",
               PROMPT_TOOLKIT_NO_CPR="1")
    parent = pexpect.spawn(sys.executable, ["-c", PARENT, db], env=env, cwd=str(ROOT),
                           encoding="utf-8", timeout=60, dimensions=(40, 160))
    parent.expect(r"SHELL (\d+)")
    pid = int(parent.match.group(1))
    parent.expect("Ctrl-D leaves")
    parent.expect(PROMPT)
    return parent, pid


@pytest.mark.parametrize("signum, where", [
    (signal.SIGTERM, "editing a line"),
    (signal.SIGHUP, "editing a line"),
    (signal.SIGTERM, "waiting for the key after an answer"),
    (signal.SIGTERM, "running a goal"),
], ids=["SIGTERM-prompt", "SIGHUP-prompt", "SIGTERM-answer", "SIGTERM-goal"])
def test_a_terminated_shell_gives_the_terminal_back_cooked(store, signum, where):
    parent, pid = shell_under_a_parent(store)
    if where == "editing a line":
        wait_for_terminal(parent, raw=True)
        parent.send("seg(O, ")                 # a line half typed
        parent.expect(r"seg\(O,")
    elif where == "running a goal":
        parent.sendline("write(started), nl, between(1, inf, X), X < 0.")
        parent.expect("started\r\n")
    else:
        parent.sendline("seg(O, L)^T.")
        parent.expect(r"O = cup1, L = \(table\), T = 1\.0")
    wait_for_terminal(parent, raw=where != "running a goal")
    os.kill(pid, signum)
    parent.expect(r"STATUS (-?\d+) ICANON (\d) ECHO (\d)")
    status, icanon, echo = (int(g) for g in parent.match.groups())
    output = parent.before
    parent.expect(pexpect.EOF)
    parent.close()
    assert (icanon, echo) == (1, 1)          # line editing and echo, as before the shell
    assert status == -signum                 # ended as killed by the signal
    assert "Traceback" not in output
    # the store was closed cleanly: it opens and answers
    done = slr("query", store, "seg(O, L)^T")
    assert done.returncode == 0 and "cup2" in done.stdout, done.stderr


HUNG_UP_SHELL = textwrap.dedent("""
    import os, sys
    errors = os.open(sys.argv[2], os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    os.dup2(errors, 2)              # stderr outlives the terminal: the test reads it
    os.execv(sys.executable, [sys.executable, "-m", "slr_sql", "shell", sys.argv[1]])
""")


def test_a_shell_whose_terminal_hangs_up_ends_quietly_by_sighup(store, tmp_path):
    """The terminal itself goes away (its window closed, the ssh connection lost): the
    kernel sends SIGHUP, and every write to the terminal fails. The shell ends by SIGHUP with
    its store closed, and says nothing on its stderr (prompt_toolkit's last redraw failed on
    the dead terminal: a traceback and exit status 1)."""
    errors = tmp_path / "stderr.txt"
    env = dict(os.environ, PYTHONPATH=str(ROOT), SLR_HISTORY=os.devnull, TERM="xterm",
               PROMPT_TOOLKIT_NO_CPR="1")
    child = pexpect.spawn(sys.executable, ["-c", HUNG_UP_SHELL, store, str(errors)], env=env,
                          cwd=str(ROOT), encoding="utf-8", timeout=60, dimensions=(40, 160))
    child.expect("Ctrl-D leaves")
    child.expect(PROMPT)
    wait_for_terminal(child, raw=True)
    child.send("seg(O, ")
    os.close(child.child_fd)         # the terminal hangs up
    child.child_fd = -1
    _, status = os.waitpid(child.pid, 0)
    child.closed, child.terminated = True, True
    assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGHUP, status
    assert errors.read_text() == ""
    assert not os.path.exists(store + "-wal")    # closed: its log checkpointed and removed
    done = slr("query", store, "seg(O, L)^T")
    assert done.returncode == 0 and "cup2" in done.stdout, done.stderr


def test_sigterm_during_a_goals_statement_compiled_to_sql_ends_the_shell_at_once(tmp_path):
    """SIGTERM while SQLite runs a goal's compiled statement: the ShellTerminated its handler
    raised was cleared inside SQLite's progress handler, and the goal went on in the
    interpreter for a minute or more before the shell ended. The goal's query is stopped
    now, and the shell ends as killed by the signal, the terminal cooked."""
    from test_close_ends_running_queries import _slow_store

    db = str(tmp_path / "slow.db")
    _slow_store(db, signalled=False)[0].close()
    parent, pid = shell_under_a_parent(db)
    parent.sendline("explain slow.")          # (compiled first: it starts at once below)
    parent.expect("engine: sql")
    parent.expect(PROMPT)
    parent.sendline("write(started), nl, slow.")
    parent.expect("started\r\n")
    # inside its statement: once the shell has spent 0.3 s of CPU since (planning takes
    # milliseconds), as test_shell's _wait_until_its_statement_runs waits
    def cpu_ticks() -> int:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
        return int(fields[11]) + int(fields[12])

    began, deadline = cpu_ticks(), time.monotonic() + 30
    while cpu_ticks() - began < 0.3 * os.sysconf("SC_CLK_TCK"):
        assert time.monotonic() < deadline, "the statement did not run"
        parent.expect([pexpect.TIMEOUT], timeout=0.02)
    os.kill(pid, signal.SIGTERM)
    parent.expect(r"STATUS (-?\d+) ICANON (\d) ECHO (\d)", timeout=30)
    status, icanon, echo = (int(g) for g in parent.match.groups())
    output = parent.before
    parent.expect(pexpect.EOF)
    parent.close()
    assert (icanon, echo) == (1, 1)
    assert status == -signal.SIGTERM
    assert "Traceback" not in output and "interrupted" not in output
