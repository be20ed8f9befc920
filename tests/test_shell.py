"""`slr shell`: through a pseudo-terminal (pexpect), Ctrl-C included, and with piped input."""
from __future__ import annotations

import errno
import os
import re
import sys
import termios
import time
from pathlib import Path

import pexpect
import pytest
from conftest import copy_of_store
from test_cli import ROOT, slr

import slr_sql
from slr_sql.cli import _completion_words

PROMPT = r"\?-"


@pytest.fixture(scope="module")
def prepared_store(tmp_path_factory) -> Path:
    """The store of ``store``, made once for the module by ``slr add``."""
    db = tmp_path_factory.mktemp("shell") / "robot.db"
    assert slr("add", str(db), "seg(cup1, table)^1", "seg(cup2, shelf)^2",
               "gripper_state(open)^1").returncode == 0
    return db


@pytest.fixture
def signals_land_in_the_shell():
    """For a test that sends this process a SIGINT: the garbage collector paused meanwhile.
    Python raises the KeyboardInterrupt in whatever Python code runs when the signal is
    handled, and a collection runs callbacks in Python (hypothesis, run in this worker
    earlier, installs one): an interrupt landing there is swallowed as "unraisable" and
    never reaches the shell under test."""
    import gc
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


@pytest.fixture
def store(tmp_path, prepared_store) -> str:
    """Three events: the test's own copy of ``prepared_store``."""
    return copy_of_store(prepared_store, tmp_path)


def spawn_shell(db: str) -> pexpect.spawn:
    env = dict(os.environ, PYTHONPATH=str(ROOT), SLR_HISTORY=os.devnull, TERM="xterm",
               PROMPT_TOOLKIT_NO_CPR="1")
    child = pexpect.spawn(sys.executable, ["-m", "slr_sql", "shell", db], env=env,
                          cwd=str(ROOT), encoding="utf-8", timeout=60, dimensions=(40, 160))
    child.expect("Ctrl-D leaves")
    child.expect(PROMPT)
    return child


def wait_for_terminal(child: pexpect.spawn, raw: bool) -> None:
    """Wait (up to a deadline) until the shell has put its terminal in raw mode (reading
    keys: the line editor, the key after an answer) or back in cooked mode (running a goal:
    Ctrl-C is a signal). A key sent in the other mode means something else."""
    deadline = time.monotonic() + 30
    while bool(termios.tcgetattr(child.child_fd)[3] & termios.ICANON) == raw:
        assert time.monotonic() < deadline, f"the terminal never became {'raw' if raw else 'cooked'}"
        child.expect([pexpect.TIMEOUT], timeout=0.02)


def press(child: pexpect.spawn, keys: str) -> None:
    wait_for_terminal(child, raw=True)
    child.send(keys)


def interrupt_the_goal(child: pexpect.spawn) -> None:
    wait_for_terminal(child, raw=False)
    child.sendintr()


def leave(child: pexpect.spawn) -> None:
    wait_for_terminal(child, raw=True)
    child.sendeof()
    child.expect(pexpect.EOF)
    child.close()
    assert child.exitstatus == 0


def _wait_until_its_statement_runs(child: pexpect.spawn, where: str) -> None:
    """Until the shell's goal is inside its long statement (up to a deadline): on SQLite,
    once the shell's process has spent 0.3 s of CPU after this call (planning the statement
    takes milliseconds; a Ctrl-C before it starts stops the interpreter, which is another
    test's); on PostgreSQL, once the server shows another session of the database active
    for 100 ms."""
    deadline = time.monotonic() + 30

    def cpu_ticks() -> int:
        fields = Path(f"/proc/{child.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return int(fields[11]) + int(fields[12])   # utime + stime

    if not where.startswith("postgresql:"):
        began, needed = cpu_ticks(), 0.3 * os.sysconf("SC_CLK_TCK")
        while cpu_ticks() - began < needed:
            assert time.monotonic() < deadline, "the statement did not run"
            child.expect([pexpect.TIMEOUT], timeout=0.02)
        return
    import psycopg
    active = ("SELECT count(*) FROM pg_stat_activity WHERE datname = current_database() "
              "AND pid <> pg_backend_pid() AND state = 'active' "
              "AND clock_timestamp() - query_start > interval '100 milliseconds'")
    with psycopg.connect(where, autocommit=True) as admin:
        while not admin.execute(active).fetchone()[0]:
            assert time.monotonic() < deadline, "the statement did not run"
            child.expect([pexpect.TIMEOUT], timeout=0.02)


def test_ctrl_c_stops_a_goal_compiled_to_sql_and_the_store_answers_the_next(backend):
    """Ctrl-C during a goal's statement compiled to SQL (here a compiled sub-goal the
    interpreter calls, a minute or more of the engine's work) did nothing on SQLite: the
    KeyboardInterrupt, raised in SQLite's progress handler, was cleared there, and the goal
    went on in the interpreter. The shell now stops the goal's query instead: the statement
    ends (interrupted on SQLite, cancelled on PostgreSQL, whose connection is left ready:
    a KeyboardInterrupt inside psycopg's wait could leave it "another command is already in
    progress"), and the next goal is answered."""
    from test_close_ends_running_queries import _slow_store

    _slow_store(backend, signalled=False)[0].close()
    child = spawn_shell(backend)
    # (its statement compiled first, so that it starts as soon as `started` is written)
    child.sendline("explain slow.")
    child.expect("engine: sql")
    child.expect(PROMPT)
    child.sendline("write(started), nl, slow.")
    child.expect("started\r\n")
    _wait_until_its_statement_runs(child, backend)
    interrupt_the_goal(child)
    child.expect("% interrupted", timeout=30)
    child.expect(PROMPT)
    child.sendline("p(X)^_, X > 498.")
    child.expect("X = 499")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_ctrl_c_stops_a_long_goal_and_gives_the_prompt_back(store):
    child = spawn_shell(store)
    # the goal says it runs: the echo of the line is no proof (a Ctrl-C sent as the prompt
    # ended, its terminal cooked already, was lost and the goal ran on for ever)
    child.sendline("write(started), nl, between(1, inf, X), X < 0.")
    child.expect("started\r\n")
    interrupt_the_goal(child)
    child.expect("% interrupted")
    child.expect(PROMPT)
    # the shell and the store still work: a new event, a new goal
    assert slr("add", store, "seg(cup3, floor)^3").returncode == 0
    child.sendline("seg(cup3, L)^T.")
    child.expect(r"L = floor, T = 3\.0")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_answers_come_one_at_a_time_semicolon_for_more_enter_to_stop(store):
    child = spawn_shell(store)
    child.sendline("seg(O, L)^T.")
    child.expect(r"O = cup1, L = \(table\), T = 1\.0")
    press(child, ";")
    child.expect(r" ;\r\n")
    child.expect(r"O = cup2, L = shelf, T = 2\.0")
    press(child, ";")
    child.expect(r"false\.")
    child.sendline("between(1, inf, X).")
    child.expect("X = 1")
    press(child, "\r")          # Enter stops an endless goal after its first answer
    child.expect(r" \.\r\n")
    child.expect(PROMPT)
    leave(child)


def test_long_answers_are_abbreviated_and_w_shows_them_whole(store):
    child = spawn_shell(store)
    child.sendline("numlist(1, 30, L).")
    child.expect(re.escape("L = [1,2,3,4,5,6,7,8,9|...]"))
    press(child, "w")
    child.expect(re.escape("L = [" + ",".join(map(str, range(1, 31))) + "]"))
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_tab_completes_predicate_and_event_type_names(store):
    child = spawn_shell(store)
    child.sendline("assert(tabletop_item(x)).")
    child.expect(r"true\.")
    child.send("tablet")
    child.send("\t")
    child.expect("op_item")
    child.sendline("(X).")
    child.expect("X = x")
    press(child, "\r")
    child.expect(PROMPT)
    child.send("grip")     # an event type of the store
    child.send("\t")
    child.expect("per_state")
    child.sendline("(S)^T.")
    child.expect(r"S = open, T = 1\.0")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_tab_completes_library_predicates_and_never_an_internal_helper(store):
    """The library's predicates and the control constructs are completed too; its internal
    helpers, named with a leading $ ('$nth_gen', '$ord_union'), are not."""
    child = spawn_shell(store)
    child.send("mapl")
    child.send("\t")
    child.expect("ist")
    child.sendline("(succ, [1, 2], L).")
    child.expect(re.escape("L = [2,3]"))
    press(child, "\r")
    child.expect(PROMPT)
    child.send("aggregate_al")      # a control construct
    child.send("\t")
    child.expect("l")
    child.sendline("(count, member(_, [a, b]), N).")
    child.expect("N = 2")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)
    with slr_sql.open(store, clock=slr_sql.ManualClock(0)) as kb:
        words = _completion_words(kb)
    assert {"member", "nth0", "ord_union", "findall", "forall"} <= set(words)
    assert not [w for w in words
                if w.startswith("$") or w in ("nth_gen", "ord_union2", "member_")]


def test_user_consult_in_the_terminal_ends_with_ctrl_d(store):
    child = spawn_shell(store)
    child.sendline("[user].")
    child.expect(r"\|:")
    child.sendline("on_table(O) :- seg(O, table)^_.")
    # the next prompt, on a line of its own: the line just sent is drawn again after "|: " as
    # it is accepted, its prompt still raw; a Ctrl-D sent then reached the terminal in the
    # cooked gap between the two prompts and was lost (the consult never ended)
    child.expect(r"\n[^\n]*\|:")
    wait_for_terminal(child, raw=True)
    child.sendeof()
    child.expect("consulted into the program 'user'")
    child.expect(PROMPT)
    child.sendline("on_table(O).")
    child.expect("O = cup1")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def await_reader(fifo: str, child: pexpect.spawn) -> int:
    """Wait (up to a deadline) until the shell opened the FIFO ``fifo`` for reading; the
    writing end, opened without blocking (ENXIO: no reader yet)."""
    deadline = time.monotonic() + 30
    while True:
        try:
            return os.open(fifo, os.O_WRONLY | os.O_NONBLOCK)
        except OSError as exc:
            assert exc.errno == errno.ENXIO, exc
            assert time.monotonic() < deadline, "the shell never opened the file"
            child.expect([pexpect.TIMEOUT], timeout=0.02)


def test_ctrl_d_typed_while_the_shell_is_busy_is_read_at_the_next_prompt(store, tmp_path):
    """Between two prompts (a goal running, a file loading, a consulted line handled) the
    terminal is cooked. A Ctrl-D typed there became the terminal's end-of-file mark, which
    the next prompt (raw) read as a NUL byte: the key was lost and the shell stayed. It is
    a key typed ahead now, read by the next prompt: at ?- it leaves the shell. (A file read
    from a FIFO holds the shell between two prompts for as long as the test wants.)"""
    fifo = str(tmp_path / "rules.pl")
    os.mkfifo(fifo)
    child = spawn_shell(store)
    child.sendline(f"load {fifo}")
    writer = await_reader(fifo, child)
    wait_for_terminal(child, raw=False)
    child.sendeof()                         # typed while the shell reads the file
    os.write(writer, b"on_table(O) :- seg(O, table)^_.\n")
    os.close(writer)
    child.expect("loaded")
    child.expect(pexpect.EOF)               # read at the next prompt: the shell left
    child.close()
    assert child.exitstatus == 0


def test_a_shell_killed_outright_leaves_the_terminals_keys_as_they_were(store):
    """The shell changes no setting of the cooked terminal: killed (SIGKILL) while a goal
    runs, it leaves the end-of-file key Ctrl-D working (it disabled it while it ran, and a
    kill left it disabled until `reset`)."""
    import signal

    child = spawn_shell(store)
    before = termios.tcgetattr(child.child_fd)
    child.sendline("between(1, inf, X), X < 0.")
    wait_for_terminal(child, raw=False)
    os.kill(child.pid, signal.SIGKILL)
    child.expect(pexpect.EOF)
    after = termios.tcgetattr(child.child_fd)
    child.close()
    assert after[6][termios.VEOF] == before[6][termios.VEOF] == b"\x04"
    assert after[3] & termios.ICANON


def test_lines_and_ctrl_d_typed_while_a_goal_runs_are_read_in_order(store, tmp_path):
    """Keys typed while the terminal is cooked (a file loading) reach the next prompts in
    the order typed: a goal's line, then Ctrl-D, read by the prompt after the goal's: it
    leaves the shell."""
    fifo = str(tmp_path / "rules.pl")
    os.mkfifo(fifo)
    child = spawn_shell(store)
    child.sendline(f"load {fifo}")
    writer = await_reader(fifo, child)
    wait_for_terminal(child, raw=False)
    child.send("seg(O, shelf)^T.\r")      # typed while the shell reads the file
    child.sendeof()
    os.write(writer, b"on_table(O) :- seg(O, table)^_.\n")
    os.close(writer)
    child.expect("loaded")
    child.expect(r"O = cup2, T = 2\.0")
    press(child, "\r")                      # the key after the answer: no more
    child.expect(pexpect.EOF)               # the Ctrl-D, read by the next prompt: left
    child.close()
    assert child.exitstatus == 0


def test_ctrl_d_typed_with_a_consulted_line_ends_the_consult(store):
    """Ctrl-D sent in one write with the Enter of a consulted line (the prompt still raw as
    it takes the line): read as a key typed ahead by the next |: prompt, it ends the
    consult."""
    child = spawn_shell(store)
    child.sendline("[user].")
    child.expect(r"\|:")
    press(child, "on_table(O) :- seg(O, table)^_.\r\x04")
    child.expect("consulted into the program 'user'")
    child.expect(PROMPT)
    child.sendline("on_table(O).")
    child.expect("O = cup1")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_ctrl_c_typed_with_enter_stops_the_goal_before_it_starts(store):
    """Enter and Ctrl-C read together (in one write, the terminal still raw): the line
    editor kept the Ctrl-C as a key typed ahead for its next prompt, and the goal ran on
    for ever. The Ctrl-C stops the goal before it starts."""
    child = spawn_shell(store)
    press(child, "write(ran), nl, between(1, inf, X), X < 0.\r\x03")
    child.expect("% interrupted")
    assert "ran" not in child.before.replace("write(ran)", "")
    child.expect(PROMPT)
    child.sendline("seg(cup1, L)^T.")       # the shell goes on; no Ctrl-C is left over
    child.expect(r"L = \(table\), T = 1\.0")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_ctrl_d_after_an_answer_stops_the_answers(store):
    """Ctrl-D at the key after an answer: no more answers, as Enter (it said "error:
    EOFError (this is a bug in slr_sql ...)")."""
    child = spawn_shell(store)
    child.sendline("between(1, 3, X).")
    child.expect("X = 1")
    press(child, "\x04")
    child.expect(r" \.\r\n")
    child.expect(PROMPT)
    assert "error" not in child.before
    leave(child)


def test_a_ctrl_c_as_the_prompt_is_taken_down_stops_the_goal_before_it_starts(store, signals_land_in_the_shell):
    """A Ctrl-C after Enter while the line editor takes its prompt down: the terminal is
    cooked again, so it is a SIGINT, and asyncio.run's own handler (installed while the
    editor's event loop ran) cancelled the prompt: the line was dropped without a word.
    The shell's SIGINT handler stays installed across the prompt: the goal is interrupted
    before it starts. The moment is reached in this process with the real line editor: a
    task of the editor's that sends the SIGINT when the editor cancels it on its way out."""
    import asyncio
    import signal

    from prompt_toolkit import PromptSession
    from prompt_toolkit.input import create_pipe_input
    from prompt_toolkit.output import DummyOutput

    import slr_sql
    from slr_sql.cli import Shell, interactive

    said: list[str] = []
    # (whatever this worker had: SIG_IGN when the suite was started in the background)
    signal_before = signal.getsignal(signal.SIGINT)
    with slr_sql.open(store) as kb, create_pipe_input() as keys:
        prompt: PromptSession = PromptSession(input=keys, output=DummyOutput())

        def ctrl_c_on_the_way_out() -> None:
            async def wait_then_interrupt() -> None:
                try:
                    await asyncio.Event().wait()
                except asyncio.CancelledError:   # the editor is taking its prompt down
                    os.kill(os.getpid(), signal.SIGINT)
                    raise
            prompt.app.create_background_task(wait_then_interrupt())

        prompt.app.pre_run_callables.append(ctrl_c_on_the_way_out)   # (the first prompt)
        keys.send_text("seg(O, table)^T.\r")
        keys.send_text("seg(O, shelf)^T.\r\x04")
        interactive(Shell(kb, echo=said.append, echo_err=said.append), prompt,
                    echo=said.append)
    assert said == ["\n% interrupted", "O = cup2, T = 2.0"]
    assert signal.getsignal(signal.SIGINT) is signal_before   # the shell's handler is gone


def test_a_sigint_while_a_line_is_edited_drops_the_line_as_ctrl_c_does(store, signals_land_in_the_shell):
    """A SIGINT sent (kill) while the line editor reads keys reaches it as its Ctrl-C key:
    the unfinished line is dropped and the shell goes on (raised inside the editor's event
    loop, it landed in one of the editor's tasks, which printed it)."""
    import asyncio
    import signal

    from prompt_toolkit import PromptSession
    from prompt_toolkit.input import create_pipe_input
    from prompt_toolkit.output import DummyOutput

    import slr_sql
    from slr_sql.cli import Shell, interactive

    said: list[str] = []
    with slr_sql.open(store) as kb, create_pipe_input() as keys:
        prompt: PromptSession = PromptSession(input=keys, output=DummyOutput())

        def interrupt_once_typed() -> None:
            async def wait_then_interrupt() -> None:
                deadline = time.monotonic() + 30
                while prompt.app.current_buffer.text != "seg(cup":
                    assert time.monotonic() < deadline, prompt.app.current_buffer.text
                    await asyncio.sleep(0.01)    # (the editor's loop reads the keys)
                os.kill(os.getpid(), signal.SIGINT)
                keys.send_text("seg(O, table)^T.\r\x04")
            prompt.app.create_background_task(wait_then_interrupt())

        prompt.app.pre_run_callables.append(interrupt_once_typed)
        keys.send_text("seg(cup")
        interactive(Shell(kb, echo=said.append, echo_err=said.append), prompt,
                    echo=said.append)
    assert said == ["O = cup1, T = 1.0"]


def test_a_sigint_between_two_lines_reaches_the_next_prompt_as_its_ctrl_c(store, signals_land_in_the_shell):
    """A SIGINT sent (kill) between two lines, before the line editor runs: it was raised
    where the shell's loop stood, outside the editor's call, and ended the shell with
    KeyboardInterrupt. It is kept for the editor, which takes it as its Ctrl-C key: the
    unfinished goal is dropped and the shell goes on."""
    import signal

    from prompt_toolkit import PromptSession
    from prompt_toolkit.input import create_pipe_input
    from prompt_toolkit.output import DummyOutput

    import slr_sql
    from slr_sql.cli import Shell, interactive

    said: list[str] = []
    # (whatever this worker had: SIG_IGN when the suite was started in the background)
    signal_before = signal.getsignal(signal.SIGINT)
    prompts = []
    with slr_sql.open(store) as kb, create_pipe_input() as keys:
        prompt: PromptSession = PromptSession(input=keys, output=DummyOutput())
        session = Shell(kb, echo=said.append, echo_err=said.append)

        def between_lines() -> None:
            prompts.append(session.continuing)
            if len(prompts) == 2:    # an unfinished goal typed: the SIGINT lands here
                os.kill(os.getpid(), signal.SIGINT)
            elif len(prompts) == 3:
                keys.send_text("seg(O, shelf)^T.\r\x04")

        keys.send_text("seg(O,\r")
        interactive(session, prompt, echo=said.append, before_prompt=between_lines)
    assert prompts == [False, True, False, False]   # the unfinished goal was dropped
    assert said == ["O = cup2, T = 2.0"]
    assert signal.getsignal(signal.SIGINT) is signal_before   # the shell's handler is gone


def run_piped(db: str, *lines: str):
    return slr("shell", db, stdin="\n".join(lines) + "\n")


def test_only_directives_are_program_text_a_goal_with_neck_is_a_goal(store):
    r = run_piped(store,
                  "assert((nearby(X) :- seg(X, table)^_)).",
                  "nearby(X).",
                  "retract((nearby(X) :- B)).",
                  "listing.",
                  ":- event seen/1.",
                  "programs.")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [
        "true.",
        "X = cup1 .",
        "true.",                                 # retracted, not stored as a clause
        "% the program 'user' is empty",
        "true.",
        "user: 1 text",
    ]
    assert slr("programs", store, "--source").stdout.splitlines()[1:] == ["    :- event seen/1."]


def test_a_clause_typed_as_a_goal_says_how_to_add_it(store):
    r = run_piped(store, "nearby(X) :- seg(X, table)^_.", "listing.")
    assert r.stderr == ("error: a clause typed at ?- is a goal, and (:-)/2 is no predicate: "
                        "add it with assert((Head :- Body)). or [user].\n")
    assert r.stdout == "% the program 'user' is empty\n"


def test_consult_assert_asserta_retract_and_listing(store):
    r = run_piped(store,
                  "[user].",
                  "near(cup1).",
                  "near(cup2).",
                  "end_of_file.",
                  "asserta(near(cup0)).",
                  "assertz(near(cup9)).",
                  "retract(near(cup2)).",
                  "near(X).", ";", ";", ";",
                  "listing(near/1).",
                  "retract(near(nothing)).")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[lines.index("true.") + 3:] == [
        "X = cup0 ;", "X = cup1 ;", "X = cup9 ;", "false.",
        "near(cup0).   % user", "near(cup1).   % user", "near(cup9).   % user",
        "false."]
    # what the shell changed is the store's program 'user', seen by every later process
    assert slr("query", store, "near(X)", "--limit", "1").stdout == "X = cup0\n"


def test_a_bad_assert_changes_nothing(store):
    r = run_piped(store, "assert((broken(X) :- )).", "listing.")
    assert r.stderr.startswith("<shell>:1:") and "unexpected" in r.stderr
    assert r.stdout.splitlines() == ["% the program 'user' is empty"]


def test_a_sigint_as_the_editor_accepts_the_line_stops_its_goal_before_it_starts(
        store, signals_land_in_the_shell):
    """A SIGINT sent (kill) while the line editor handles Enter (its validator runs: the
    line is being accepted) is the goal's: the goal is interrupted before it starts, the
    shell goes on."""
    import signal

    from prompt_toolkit import PromptSession
    from prompt_toolkit.input import create_pipe_input
    from prompt_toolkit.output import DummyOutput
    from prompt_toolkit.validation import Validator

    import slr_sql
    from slr_sql.cli import Shell, interactive

    said: list[str] = []
    sent = []

    def interrupt_once(text: str) -> bool:
        if text.startswith("seg(O, table)") and not sent:
            sent.append(text)
            os.kill(os.getpid(), signal.SIGINT)
        return True

    with slr_sql.open(store) as kb, create_pipe_input() as keys:
        prompt: PromptSession = PromptSession(input=keys, output=DummyOutput(),
                                              validator=Validator.from_callable(interrupt_once))
        keys.send_text("seg(O, table)^T.\r")
        keys.send_text("seg(O, shelf)^T.\r\x04")
        interactive(Shell(kb, echo=said.append, echo_err=said.append), prompt,
                    echo=said.append)
    assert sent and said == ["\n% interrupted", "O = cup2, T = 2.0"]


def test_a_comment_after_the_full_stop_ends_the_goal_and_a_full_stop_inside_one_does_not(store):
    """The end of a goal is its full stop as the reader sees it (SWI-Prolog's toplevel): a
    goal followed by a comment ran never (the line did not end with '.'), and the next goal
    was joined to it, both lost in one syntax error; a '.' inside a comment or a quoted
    atom spanning lines ended the goal there, and its rest was an error of its own."""
    r = run_piped(store,
                  "seg(cup1, L)^T.   % where was cup1?",
                  "X = 1. /* a block comment */",
                  "X = 2 % this is not the end.",
                  ", Y = 3.",
                  "assert(near(a)). % a command too",
                  "near(N).%",
                  "X = 'a. b'.",
                  "X = 'a.",                      # a quoted atom may span lines
                  "b'.",
                  "X = a\x00b.")                    # no token: its error, not a wait
    assert r.returncode == 0, r.stderr
    assert r.stderr.startswith("<shell>:1:6: unexpected character") and r.stderr.count("\n") == 3
    assert r.stdout.splitlines() == ["L = (table), T = 1.0 .", "X = 1 .", "X = 2, Y = 3 .",
                                     "true.", "N = a .", "X = 'a. b' .", "X = 'a.\\nb' ."]


def test_a_comment_after_the_full_stop_in_the_terminal(store):
    child = spawn_shell(store)
    child.sendline("seg(cup2, L)^T.  % where was cup2?")
    child.expect(r"L = shelf, T = 2\.0")
    press(child, "\r")
    child.expect(PROMPT)
    child.sendline("X = 2 % not the end.")
    child.expect(r"\|")                     # the goal goes on on the next line
    child.sendline(", Y = 3.")
    child.expect(r"X = 2, Y = 3")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_keys_pressed_faster_than_the_answers_come_each_count(store):
    """Two ';' read at once (pressed quickly, a key held down) were taken as one key of two
    characters, which is no ';': the answers stopped after the first."""
    child = spawn_shell(store)
    child.sendline("between(1, 3, X).")
    child.expect("X = 1")
    press(child, ";;")                      # in one write: one read of the terminal
    child.expect(r"X = 2 ;\r\n")
    child.expect("X = 3")
    press(child, "\r")
    child.expect(r" \.\r\n")
    child.expect(PROMPT)
    child.sendline("X = done.")             # nothing of the keys is left over
    child.expect(r"X = done")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_a_key_typed_while_the_goal_runs_answers_its_first_answer(store):
    """A ';' typed before the first answer came (the terminal cooked, the goal running) was
    thrown away as the shell took the terminal raw for the key (TCSAFLUSH): it waited for
    another key."""
    child = spawn_shell(store)
    child.sendline("\\+ \\+ (numlist(1, 300000, L), msort(L, _)), member(X, [a, b]).")
    wait_for_terminal(child, raw=False)     # the goal runs
    child.send(";")
    child.expect(r"X = a ;\r\n")
    child.expect("X = b")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


DEEP = 5000   # deeper than Python's recursion


def test_an_answer_nested_deeper_than_pythons_recursion_is_printed(tmp_path):
    """The goal answered, but printing its answer said "the term is nested too deeply" (the
    answer's printer and the shell's abbreviation recursed), in `slr query`, the piped
    shell and the terminal shell alike (the shell's answer in full: `w`)."""
    db = str(tmp_path / "deep.db")
    program = tmp_path / "deep.pl"
    program.write_text("deep(" + "f(" * DEEP + "a" + ")" * DEEP + ").\n")
    assert slr("load", db, str(program)).returncode == 0
    expected = "X = " + "f(" * DEEP + "a" + ")" * DEEP
    query = slr("query", db, "deep(X)")
    assert query.returncode == 0, query.stderr
    assert query.stdout.splitlines() == [expected]
    # (the shell cuts it at depth 10, as swipl's top level; `w` prints it whole)
    cut = "X = " + "f(" * 10 + "..." + ")" * 10
    piped = run_piped(db, "deep(X).", "w", "", "Y = ok.")
    assert piped.stderr == "" and piped.stdout.splitlines() == [cut, expected + " .", "Y = ok ."]
    child = spawn_shell(db)
    child.sendline("deep(X), L = [1,2,3,4,5,6,7,8,9,10,11].")
    child.expect(re.escape(cut + ", L = [1,2,3,4,5,6,7,8,9|...]"))
    press(child, "w")
    child.expect(r"X = (f\()+a")
    child.expect(r"\)+, L = \[1,2,3,4,5,6,7,8,9,10,11\]")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_end_of_file_with_a_comment_after_it_ends_the_consult(store):
    """It was taken as one more consulted line: the goals after it became program text."""
    r = run_piped(store, "[user].", "q(1).", "end_of_file.  % done", "q(X).")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["% type clauses; end_of_file. or Ctrl-D ends",
                                     "% consulted into the program 'user'", "X = 1 ."]


def test_at_nan_is_refused_at_once_in_the_queries_words_and_the_view_stays(store):
    """`at nan` was echoed as a stream view, and then every goal failed with "at must be a
    number of seconds, not nan". It is refused as it is typed, in those words, and the view
    set before stays; `at inf` is a view queries take (every stored event)."""
    r = run_piped(store, "at 1", "at nan", "seg(X, P)^T.", "at inf", "seg(X, P)^T.", ";", ";")
    assert r.returncode == 0, r.stderr
    assert r.stderr == "error: at must be a number of seconds, not nan\n"
    assert r.stdout.splitlines() == [
        "stream view: at 1",
        "X = cup1, P = (table), T = 1.0 .",
        "stream view: at inf",
        "X = cup1, P = (table), T = 1.0 ;",
        "X = cup2, P = shelf, T = 2.0 ;",
        "false.",
    ]


def test_at_that_is_no_number_is_refused_in_words_and_the_view_stays(store):
    """`at soon` said Python's "could not convert string to float: 'soon'"."""
    r = run_piped(store, "at 1", "at soon", "seg(X, P)^T.")
    assert r.returncode == 0, r.stderr
    assert r.stderr == "error: at takes a number of seconds (or none), not soon\n"
    assert r.stdout.splitlines() == ["stream view: at 1", "X = cup1, P = (table), T = 1.0 ."]


class PipedShell:
    """`slr shell DB` with its standard input a pipe kept open: a line is sent, and what the
    shell prints is read as it comes, up to a deadline (never all of it at the end)."""

    def __init__(self, db: str):
        import subprocess
        env = dict(os.environ, PYTHONPATH=str(ROOT), SLR_HISTORY=os.devnull)
        self.proc = subprocess.Popen([sys.executable, "-m", "slr_sql", "shell", db],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, env=env, cwd=str(ROOT))
        self.out = b""

    def send(self, line: str) -> None:
        self.proc.stdin.write(line.encode() + b"\n")
        self.proc.stdin.flush()

    def expect(self, text: str, deadline: float = 60) -> str:
        """Read until ``text`` has come; what came up to its end (the rest is kept)."""
        import select
        end = time.monotonic() + deadline
        fd = self.proc.stdout.fileno()
        while text.encode() not in self.out:
            left = end - time.monotonic()
            assert left > 0, f"{text!r} did not come; the shell printed {self.out!r}"
            if select.select([fd], [], [], left)[0]:
                chunk = os.read(fd, 4096)
                assert chunk, f"the shell ended before {text!r}: {self.out!r}"
                self.out += chunk
        upto = self.out.index(text.encode()) + len(text)
        came, self.out = self.out[:upto], self.out[upto:]
        return came.decode()

    def end(self) -> tuple[str, str]:
        """Close the input: the rest of the output and the errors; the shell ended (0)."""
        rest, errors = self.proc.communicate(timeout=60)   # (which closes the input)
        assert self.proc.returncode == 0, errors
        return (self.out + rest).decode(), errors.decode()

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.communicate(timeout=60)


def test_piped_goal_with_endless_answers_prints_its_first_at_once_and_reads_the_response(
        store):
    """`repeat.` or `length(L, N).` piped in ran for ever and printed nothing: the shell
    collected every answer before printing. An answer is printed as it is found, and the
    response to it (`;` the next, an empty line stop) is a line of the same input, as
    SWI-Prolog's top level reads it when its input is no terminal."""
    shell = PipedShell(store)
    try:
        shell.send("repeat.")
        assert shell.expect("true") == "true"
        shell.send(";")
        assert shell.expect("true") == " ;\ntrue"
        shell.send("")
        assert shell.expect(" .\n") == " .\n"
        shell.send("length(L, N).")
        assert shell.expect("N = 0") == "L = [], N = 0"
        shell.send(";")
        assert shell.expect("N = 1").startswith(" ;\nL = [")
        shell.send("seg(O, L)^T.")        # no response: the next goal, the answers stop
        assert shell.expect("O = cup1, L = (table), T = 1.0") == " .\nO = cup1, L = (table), T = 1.0"
        out, errors = shell.end()         # the end of the input stops the answers too
    finally:
        shell.kill()
    assert out == " .\n" and errors == ""


def test_piped_responses_next_full_answer_stop_and_a_goal_in_their_place(store):
    r = run_piped(store,
                  "member(X, [1, 2, 3]).", ";", "n", ";",       # every answer, then false
                  "numlist(1, 12, L).", "w", ".",                # in full, then stop
                  "member(X, [a, b]).", "  ;  ", "c",            # (blanks around the key)
                  "member(X, [a, b]).",
                  "X = next.",                                   # a goal: stops, then runs
                  "",
                  "member(X, [1, 0]), Y is 1 / X.", ";",          # an error after an answer
                  "X = last.")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == [
        "X = 1 ;", "X = 2 ;", "X = 3 ;", "false.",
        "L = [1,2,3,4,5,6,7,8,9|...]", "L = [1,2,3,4,5,6,7,8,9,10,11,12] .",
        "X = a ;", "X = b .",
        "X = a .",
        "X = next .",
        "X = 1, Y = 1 ;",
        "X = last .",
    ]
    assert r.stderr == "error: arithmetic: division by zero\n"


# goals whose answers hold variables the query did not name, in shapes where SWI-Prolog's top
# level prints them as `_` (held once) or `_A`, `_B`, ... (held more than once)
UNNAMED_VARIABLE_GOALS = [
    "copy_term(f(A, A, B), X).",
    "length(L, 2), L = [P|_].",
    "X = g(_Y, _Y, _Z).",
    "copy_term([A-B, B], X).",
    "length(L, 3), copy_term(L-L, C).",
    "length(L, 28), copy_term(L, C), append(C, C, D).",
    # (the copy of V held twice in C, once past the `|...` cut: named over the whole answer)
    "length(T, 12), append(T, [V], L), copy_term([V|L], C).",
]
# a program's clauses holding shared and singleton variables, some named as the goals' are
CLAUSES = """\
q(f(Y, Y, Z)).
r(A, B) :- A = g(B, C, C).
s([A, B, A | _]).
long(L) :- length(L, 14), L = [A|_], last(L, A).
pair(X, Y) :- X = Y.
t(g(X, _), X).
"""
CLAUSE_VARIABLE_GOALS = [
    "q(X).",
    "q(X), Y = 1.",              # (the clause's Y is no query's Y)
    "q(f(P, Q, R)).",
    "r(X, Y).",
    "X = f(Y), r(Z, Y).",
    "s(L).",
    "long(L).",                  # (its _A held twice, once past the `|...` cut)
    "pair(X, Y).",
    "pair(f(A), B).",
    "t(X, f(Y)).",
    "q(X), q(Y).",
]
# query variables bound to variables no query variable is: the last of those holding one
# names it (swipl's top level), where before the engine's binding did or no name was left
FRESH_BINDING_GOALS = [
    "X = f(Y, _), Y = _.",
    "X = f(Z), Y = Z.",
    "X = Y.",
    "Y = _, X = f(Y), Z = Y.",
    "X = f(_), Y = g(X).",
    "X = f(Y, _), Y = _, Z = g(_).",
    "length(L, 12), L = [A|_], last(L, A).",
]
SWI_NAMING = {
    "builtins' variables": (None, UNNAMED_VARIABLE_GOALS),
    "clauses' variables": (CLAUSES, CLAUSE_VARIABLE_GOALS),
    "query variables bound to fresh ones": (None, FRESH_BINDING_GOALS),
}


@pytest.mark.parametrize("program, goals", SWI_NAMING.values(), ids=list(SWI_NAMING))
def test_variables_the_query_did_not_name_are_printed_as_swi_prologs_top_level_prints_them(
        store, tmp_path, program, goals):
    """`copy_term(f(A, A, B), X).` printed `X = f(_G974,_G974,_G975)`: the engine's names;
    with the clause `q(f(Y, Y, Z)).`, `q(X), Y = 1.` printed `X = f(Y,Y,Z), Y = 1` (the
    clause's names, one the query's); `X = f(Y, _), Y = _.` printed `X = f(_,_)`.
    Compared with swipl's top level given the same piped goals (and program); its answers'
    other layout (a binding a line, a space after each comma) is put as the shell's before
    comparing."""
    import shutil
    import subprocess

    swipl = shutil.which("swipl")
    assert swipl, "SWI-Prolog is the reference: install swi-prolog (.ci/run does)"
    consult = []
    if program is not None:
        path = tmp_path / "clauses.pl"
        path.write_text(program, encoding="utf-8")
        loaded = slr("load", store, str(path))
        assert loaded.returncode == 0, loaded.stderr
        consult = [str(path)]
    text = "\n".join(goals) + "\n"
    ours = slr("shell", store, stdin=text)
    assert ours.returncode == 0 and ours.stderr == "", ours.stderr
    theirs = subprocess.run([swipl, "-q", *consult], input=text, capture_output=True,
                            text=True, timeout=60)
    assert theirs.returncode == 0, theirs.stderr

    def layout(answer: str) -> str:
        return re.sub(r",\s+", ",", answer.strip()).rstrip(".").strip()

    expected = [layout(a) for a in theirs.stdout.split("\n\n") if a.strip()]
    assert len(expected) == len(goals), theirs.stdout
    assert [layout(a) for a in ours.stdout.splitlines()] == expected
    assert not re.search(r"_G\d", ours.stdout)


def test_a_name_the_query_gave_is_not_given_again(store):
    """swipl 9.0 prints `Y = g(_A, _A)` here, two different variables under one name
    (docs/printed_text.md)."""
    named = slr("shell", store, stdin="X = f(_A), copy_term(g(P, P), Y).\n")
    assert named.stdout == "X = f(_A), Y = g(_B,_B) .\n", named.stderr


def test_a_ctrl_c_after_the_searchs_last_check_ends_the_goal_without_its_answer(store):
    """A Ctrl-C (or SIGTERM) that stopped a local goal's search after the search's last look
    at its stop -- in the Python work after a compiled statement ended, here a defined
    predicate the answer's search calls, as the shell's signal handler would run there --
    showed the answer found and waited for a key: the goal ended only at the next one."""
    import signal

    import slr_sql
    from slr_sql.cli import Shell, ShellTerminated

    said: list[str] = []
    with slr_sql.open(store) as kb:
        shell = Shell(kb, echo=lambda text, nl=True: said.append(text),
                      echo_err=lambda text, nl=True: said.append(text), ask=lambda: ";")
        kb.define("ctrl_c", 1, lambda x: shell.stop_goal())
        kb.define("sigterm", 1, lambda x: shell.stop_goal(signal.SIGTERM))
        with pytest.raises(KeyboardInterrupt):
            shell.feed("between(1, 3, X), ctrl_c(X).")
        with pytest.raises(ShellTerminated):
            shell.feed("between(1, 3, X), sigterm(X).")
    assert said == []
