"""What a query writes on a server (`slr serve`): dropped, never in the server's stdout or
stderr (the operator's logs), whichever output built-in wrote it (real processes)."""
from __future__ import annotations

import subprocess
import sys

import slr_sql

from service_helpers import ROOT, ServiceProcess, slr_env

MARK = "client-text-in-the-log"
# a forged log line too: the text a client chose, as the operator would read it
WRITES = [
    f"write('{MARK} 1')", f"print('{MARK} 2')", f"writeln('{MARK} 3')", f"writeq('{MARK} 4')",
    f"write_canonical('{MARK} 5')", f"format('{MARK} 6~n')", f"format('~w~n', ['{MARK} 7'])",
    f"nl, tab(3), write('\\nINFO:     127.0.0.1 - \"GET /health\" {MARK} 8')",
    f"write(user_error, '{MARK} 9')", f"format(user_error, '~w', ['{MARK} 10'])",
    f"nl(user_error), writeln(user_output, '{MARK} 11')",
    f"with_output_to(user_error, write('{MARK} 12'))",
    f"print_message(error, format('~w', ['{MARK} 13']))",
    f"print_message(informational, '{MARK} 14')",
]
PROGRAM = f"noisy(X) :- write('{MARK} rule'), print_message(warning, format('{MARK} ~w', [X])).\n"


def test_what_a_query_writes_on_a_server_reaches_neither_its_stdout_nor_its_stderr(tmp_path):
    server = ServiceProcess(tmp_path / "robot.db")
    try:
        with slr_sql.connect(server.url) as kb:
            kb.load(PROGRAM, name="noisy")
            for goal in WRITES:
                assert kb.query(goal) == [{}], goal
            assert kb.query("noisy(x), noisy(y)") == [{}]
            assert kb.query("member(X, [a, b]), write(X)", limit=2) == [{"X": "a"}, {"X": "b"}]
            # the text a query writes still reaches the query itself, as a binding
            assert kb.query(f"with_output_to(string(S), write('{MARK}'))") == \
                [{"S": slr_sql.String(MARK)}]
            assert kb.query("format(atom(A), '~w', [x]), write(A)", at=5, wait=True,
                            timeout=30) == [{"A": "x"}]
        # the shell given the server's URL: the goal's output is the server's, dropped too
        shell = subprocess.run([sys.executable, "-m", "slr_sql", "shell", server.url],
                               input=f"write('{MARK} shell'), X = 1.\n", capture_output=True,
                               text=True, cwd=ROOT, env=slr_env(), timeout=120)
        assert shell.returncode == 0 and shell.stdout == "X = 1 .\n", shell
        server.proc.terminate()
        stdout, _ = server.proc.communicate(timeout=60)
    finally:
        server.stop()
    assert server.proc.returncode == 0
    stdout_text = server.first_line + stdout.decode("utf-8", "replace")
    log = server.log.read_text(encoding="utf-8", errors="replace")
    assert MARK not in stdout_text, stdout_text
    assert MARK not in log, log
