"""`slr shell URL` against a real `slr serve` process: answers one at a time as on a local
store (WebSocket `/solutions`): the first shown as soon as the server has it, the next
computed only when asked, and the query ended on the server when the shell stops it,
is interrupted or goes away. The server's `/health` says what it still runs."""
from __future__ import annotations

import json
import queue
import subprocess
import sys
import threading
import time

import pytest
from service_helpers import HTTP, ROOT, ServiceProcess, slr_env
from test_cli import slr
from test_shell import PROMPT, PipedShell, interrupt_the_goal, leave, press, spawn_shell

import slr_sql

DEADLINE = 30.0      # seconds for what takes milliseconds (a loaded machine is slow)


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    """A server whose queries may run 10 minutes: a query it still runs after a test
    ended it is seen in /health, not ended by its time."""
    db = tmp_path_factory.mktemp("served") / "robot.db"
    with ServiceProcess(db, "--max-query-time", "600") as s:
        yield s


def queries(server) -> dict:
    return HTTP.get(server.url + "/health", timeout=10).json()["queries"]


def wait_for_queries(server, **expected: int) -> dict:
    """/health's ``queries`` once each of ``expected`` has its value (up to a deadline)."""
    end = time.monotonic() + DEADLINE
    while True:
        now = queries(server)
        if all(now.get(name) == value for name, value in expected.items()):
            return now
        assert time.monotonic() < end, f"the server's queries stayed {now}, not {expected}"


def test_an_endless_goal_shows_its_first_answer_at_once_and_the_next_only_when_asked(server):
    """The answers came all at once, after the server's whole query time: an endless goal
    showed nothing (for 600 s here) and `;` could not work as in SWI-Prolog."""
    shell = PipedShell(server.url)
    try:
        shell.send("between(1, inf, X).")
        assert shell.expect("X = 1", deadline=DEADLINE) == "X = 1"
        # the query is open on the server and computes nothing while the answer is read
        assert wait_for_queries(server, solutions=1)["running"] == 0
        shell.send(";")
        assert shell.expect("X = 2", deadline=DEADLINE) == " ;\nX = 2"
        shell.send(";")
        assert shell.expect("X = 3", deadline=DEADLINE) == " ;\nX = 3"
        shell.send("")                    # Enter: stop; nothing of it runs on the server
        assert shell.expect(" .\n", deadline=DEADLINE) == " .\n"
        wait_for_queries(server, solutions=0, running=0)
        shell.send("member(X, [a, b]).")  # the answers' end is false, as on a local store
        assert shell.expect("X = a", deadline=DEADLINE) == "X = a"
        shell.send(";")
        assert shell.expect("X = b", deadline=DEADLINE) == " ;\nX = b"
        shell.send(";")
        assert shell.expect("false.\n", deadline=DEADLINE) == " ;\nfalse.\n"
        out, errors = shell.end()
    finally:
        shell.kill()
    assert (out, errors) == ("", "")
    assert queries(server)["solutions"] == 0


def test_a_goal_after_the_answer_stops_the_answers_and_ends_the_query_on_the_server(server):
    shell = PipedShell(server.url)
    try:
        shell.send("repeat.")
        assert shell.expect("true", deadline=DEADLINE) == "true"
        wait_for_queries(server, solutions=1)
        shell.send("X = next.")           # no response: the next goal, the answers stop
        assert shell.expect("X = next", deadline=DEADLINE) == " .\nX = next"
        out, errors = shell.end()
    finally:
        shell.kill()
    assert (out, errors) == (" .\n", "")
    wait_for_queries(server, solutions=0, running=0)


def test_a_shell_that_goes_away_while_the_server_looks_for_an_answer_ends_that_search(server):
    """A disconnect mid-query: the server's search for the next answer (no answer for
    ever) ends at once, not at its query time."""
    shell = PipedShell(server.url)
    try:
        shell.send("(X = 1 ; repeat, fail).")
        assert shell.expect("X = 1", deadline=DEADLINE) == "X = 1"
        shell.send(";")
        wait_for_queries(server, running=1, solutions=1)   # it searches
    finally:
        shell.kill()                      # SIGKILL: the connection just breaks
    wait_for_queries(server, running=0, solutions=0, waiting=0)


def test_ctrl_c_in_a_served_shell_stops_the_search_on_the_server(server):
    child = spawn_shell(server.url)
    child.sendline("(X = 1 ; repeat, fail).")
    child.expect("X = 1")
    press(child, ";")
    child.expect(r" ;\r\n")
    wait_for_queries(server, running=1, solutions=1)
    interrupt_the_goal(child)
    child.expect("% interrupted")
    child.expect(PROMPT)
    wait_for_queries(server, running=0, solutions=0)
    child.sendline("X = again.")
    child.expect("X = again")
    press(child, "\r")
    child.expect(PROMPT)
    leave(child)


def test_slr_query_of_a_served_endless_goal_with_a_limit_prints_its_answers(server):
    """`slr query URL GOAL --limit N` waited for the server's whole query time and printed
    only its timeout: the client asked for every answer before taking N."""
    r = subprocess.run([sys.executable, "-m", "slr_sql", "query", server.url,
                        "between(1, inf, X)", "--limit", "3"], capture_output=True, text=True,
                       cwd=ROOT, env=slr_env(), timeout=DEADLINE)
    assert (r.returncode, r.stdout, r.stderr) == (0, "X = 1\nX = 2\nX = 3\n", "")
    wait_for_queries(server, running=0, solutions=0)


def test_the_client_takes_served_answers_one_at_a_time(server):
    with slr_sql.connect(server.url) as kb:
        answers = kb.solutions("between(1, inf, X), Y is 10 / (3 - X)")
        assert [next(answers), next(answers)] == [{"X": 1, "Y": 5}, {"X": 2, "Y": 10}]
        with pytest.raises(slr_sql.SLREvaluationError, match="zero_divisor"):
            next(answers)                 # the query's error, after its answers
        assert answers.closed and list(answers) == []
        assert list(kb.solutions("member(X, [a, b])", args={"X": "b"}, at=5.0)) == \
            [{"X": slr_sql.Atom("b")}]        # (the options go along)
        with pytest.raises(slr_sql.SLRSyntaxError):
            next(kb.solutions("member(X, "))
    wait_for_queries(server, running=0, solutions=0)


def test_closing_the_client_ends_its_open_answers_on_the_server(server):
    """A program that closes its client with answers still open (it left a for loop with
    break): each query ends on the server, and a later next() says the connection closed;
    answers that ended before stay ended."""
    kb = slr_sql.connect(server.url)
    endless, finished = kb.solutions("between(1, inf, X)"), kb.solutions("X = 1")
    assert next(endless) == {"X": 1} and list(finished) == [{"X": 1}]
    assert wait_for_queries(server, solutions=1)["solutions"] == 1
    kb.close()
    wait_for_queries(server, running=0, solutions=0)
    with pytest.raises(slr_sql.SLRError, match="the connection to the knowledge base was closed"):
        next(endless)
    assert list(finished) == []


@pytest.mark.parametrize("message, words", [
    ('{"op": "next"}', 'the first message must be {"op": "solutions", "goal": ...}'),
    ('{"op": "solutions"}', '"goal" is required'),
    ('{"op": "solutions", "goal": "true", "timeout": -1}', '"timeout"'),
])
def test_a_bad_first_message_is_an_error_message_and_a_close(server, message, words):
    from websockets.sync.client import connect

    with connect("ws" + server.url[4:] + "/solutions") as ws:
        ws.send(message)
        reply = json.loads(ws.recv(DEADLINE))
        assert reply["type"] == "error" and words in reply["error"]["message"], reply
    assert ws.close_code == 4400


def test_a_message_that_is_neither_next_nor_close_ends_the_query_in_words(server):
    from websockets.sync.client import connect

    with connect("ws" + server.url[4:] + "/solutions") as ws:
        ws.send('{"op": "solutions", "goal": "repeat"}')
        assert json.loads(ws.recv(DEADLINE)) == {"type": "answer", "seq": 1, "answer": {}}
        ws.send('{"op": "more"}')
        reply = json.loads(ws.recv(DEADLINE))
        assert reply["type"] == "error" and reply["error"]["message"].startswith(
            'expected {"op": "next"} or {"op": "close"}, got'), reply
    assert ws.close_code == 4400
    wait_for_queries(server, running=0, solutions=0)


@pytest.fixture(scope="module")
def short_server(tmp_path_factory):
    """A server whose queries may run one second."""
    db = tmp_path_factory.mktemp("short") / "robot.db"
    with ServiceProcess(db, "--max-query-time", "1") as s:
        yield s


def test_a_served_search_past_the_servers_time_keeps_the_answers_shown(short_server):
    """The answers found before the server's query time ran out were lost: the shell showed
    the timeout only. Now they are shown as found, and the timeout ends the search for the
    next one in words; the shell goes on with the next goal."""
    r = slr("shell", short_server.url, stdin="(X = 1 ; X = 2 ; repeat, fail).\n;\n;\nX = 3.\n")
    assert r.returncode == 0, r.stderr
    assert r.stdout == "X = 1 ;\nX = 2 ;\nX = 3 .\n"
    assert r.stderr.startswith("error: query timed out after 1.0 s") and \
        r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr


def test_the_servers_time_counts_the_wait_for_the_next_request(short_server):
    """The query's time is the whole interaction's: a query left at an answer ends on the
    server at its time (nothing is held open), and the `;` that comes after says so."""
    shell = PipedShell(short_server.url)
    try:
        shell.send("between(1, inf, X).")
        assert shell.expect("X = 1", deadline=DEADLINE) == "X = 1"
        wait_for_queries(short_server, solutions=0, running=0)   # ended at its time
        shell.send(";")
        shell.send("X = 2.")
        assert shell.expect("X = 2", deadline=DEADLINE) == " ;\nX = 2"
        shell.send("")
        out, errors = shell.end()
    finally:
        shell.kill()
    assert out == " .\n"
    assert errors.startswith("error: query timed out after 1 s (its time counts from the "
                             "first request, the waits for the next request included; 1 "
                             "answer sent)") and errors.count("\n") == 1, errors


OLDER_SERVER = """\
import sys
import uvicorn
import slr_sql
from slr_sql.service.app import create_app
from slr_sql.service.background import listen_on

with slr_sql.open(sys.argv[1]) as kb:
    app = create_app(kb)
    app.router.routes = [r for r in app.router.routes if r.path != "/solutions"]
    sock = listen_on("127.0.0.1", 0)
    print(f"http://127.0.0.1:{sock.getsockname()[1]}", flush=True)
    uvicorn.Server(uvicorn.Config(app, log_level="warning", lifespan="off")).run(
        sockets=[sock])
"""


def test_a_server_without_solutions_is_asked_with_one_query(tmp_path):
    """An older `slr serve` (no WebSocket /solutions: its handshake is refused) still
    answers the client's solutions() and the shell, all at once as before."""
    db = tmp_path / "robot.db"
    assert slr("add", str(db), "seg(cup1, table)^1").returncode == 0
    proc = subprocess.Popen([sys.executable, "-c", OLDER_SERVER, str(db)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ROOT, env=slr_env())
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://"), proc.stderr.read()
        end = time.monotonic() + DEADLINE
        with slr_sql.connect(url) as kb:
            while True:
                try:
                    kb.health()
                    break
                except slr_sql.SLRUnavailable:
                    assert time.monotonic() < end
            assert list(kb.solutions("member(X, [1, 2])")) == [{"X": 1}, {"X": 2}]
        r = slr("shell", url, stdin="seg(O, L)^T.\n")
        assert (r.returncode, r.stdout, r.stderr) == (0, "O = cup1, L = (table), T = 1.0 .\n",
                                                      "")
    finally:
        proc.terminate()
        proc.communicate(timeout=DEADLINE)


@pytest.mark.parametrize("how", ["stop", "close"])
@pytest.mark.parametrize("where", ["local", "served"])
def test_stop_from_another_thread_ends_the_search_for_the_next_answer(server, where, how):
    """`solutions(...).stop()` or `.close()`: the search for the next answer, under way in
    another thread (no answer for ever), ends with an SLRError, on a local knowledge base
    as over the service, where the server's query ends too; after close() the iteration
    has ended, after stop() each next() says it was stopped."""
    searching = threading.Event()
    if where == "local":
        kb = slr_sql.open()
        kb.define("searching", 0, lambda: searching.set() or True)
        goal = "(X = 1 ; searching, repeat, fail)"
    else:
        kb = slr_sql.connect(server.url)
        goal = "(X = 1 ; repeat, fail)"
    outcome: queue.Queue = queue.Queue()

    def search() -> None:
        try:
            outcome.put(next(answers))
        except BaseException as exc:  # noqa: BLE001 - what ended it is the test's answer
            outcome.put(exc)

    with kb:
        answers = kb.solutions(goal, timeout=600)
        assert next(answers) == {"X": 1}
        threading.Thread(target=search, daemon=True).start()
        if where == "local":
            assert searching.wait(DEADLINE)
        else:
            wait_for_queries(server, running=1, solutions=1)
        getattr(answers, how)()
        ended = outcome.get(timeout=DEADLINE)
        assert isinstance(ended, slr_sql.SLRError) and \
            str(ended) == "the query was stopped while it looked for its next answer", ended
        if how == "close":
            assert list(answers) == []
        else:
            with pytest.raises(slr_sql.SLRError, match="stopped"):
                next(answers)
    if where == "served":
        wait_for_queries(server, running=0, solutions=0)


def test_a_server_stopping_with_a_query_open_at_an_answer_stops_at_once(tmp_path):
    """A query left open at an answer holds no stopping server (600 s of grace here): it is
    closed with the connection, and the shell's next `;` says so in words: that the server
    stopped (it said websockets' "received 1012 (service restart); then sent 1012 (service
    restart)")."""
    with ServiceProcess(tmp_path / "robot.db", "--max-query-time", "600",
                        "--shutdown-grace", "600") as own:
        shell = PipedShell(own.url)
        try:
            shell.send("between(1, inf, X).")
            assert shell.expect("X = 1", deadline=DEADLINE) == "X = 1"
            wait_for_queries(own, solutions=1)
            own.proc.terminate()
            assert own.proc.wait(timeout=DEADLINE) == 0
            shell.send(";")
            out, errors = shell.end()
        finally:
            shell.kill()
    assert out == " ;\n"
    assert errors == ("error: the query's connection closed: the server stopped or restarted; "
                      "ask again once it is back (WebSocket close code 1012)\n"), errors


class _HeldHandshakeProxy:
    """A TCP proxy (threads) in front of the server that holds the WebSocket handshake of
    ``/solutions`` until ``release`` is set (``handshaking`` is set once it holds one); every
    other connection goes through at once."""

    def __init__(self, url: str):
        import socket
        self.target = url.rsplit(":", 1)
        self.handshaking = threading.Event()
        self.release = threading.Event()
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{self._listener.getsockname()[1]}"
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self._listener.accept()
            except OSError:
                return
            threading.Thread(target=self._one, args=(conn,), daemon=True).start()

    def _one(self, conn) -> None:
        import socket
        first = conn.recv(65536)
        if first.startswith(b"GET /solutions"):
            self.handshaking.set()
            self.release.wait(DEADLINE)
        host = self.target[0].split("//")[1]
        upstream = socket.create_connection((host, int(self.target[1])))
        upstream.sendall(first)

        def pump(source, sink) -> None:
            try:
                while data := source.recv(65536):
                    sink.sendall(data)
            except OSError:
                pass
            for end in (source, sink):
                try:
                    end.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass
        threading.Thread(target=pump, args=(upstream, conn), daemon=True).start()
        pump(conn, upstream)

    def close(self) -> None:
        self._listener.close()


def test_stop_during_the_handshake_of_the_first_answer_ends_that_next(server):
    """`stop()` from another thread while the first `next()` still opened its WebSocket:
    the connection it then opened was kept, its goal sent and its answer waited for (here
    none comes: the `next()` hung for the server's whole query time, and the server kept
    the query)."""
    proxy = _HeldHandshakeProxy(server.url)
    outcome: queue.Queue = queue.Queue()
    try:
        with slr_sql.connect(proxy.url) as kb:
            answers = kb.solutions("repeat, fail", timeout=600)

            def search() -> None:
                try:
                    outcome.put(next(answers))
                except BaseException as exc:  # noqa: BLE001 - the test's answer
                    outcome.put(exc)
            threading.Thread(target=search, daemon=True).start()
            assert proxy.handshaking.wait(DEADLINE)
            answers.stop()
            proxy.release.set()
            ended = outcome.get(timeout=DEADLINE)
            assert isinstance(ended, slr_sql.SLRError) and \
                str(ended) == "the query was stopped while it looked for its next answer", ended
    finally:
        proxy.release.set()
        proxy.close()
    wait_for_queries(server, running=0, solutions=0)


def test_slr_query_of_a_served_goal_without_a_limit_asks_one_query(short_server):
    """Without --limit every answer is wanted: one request gives them (here 10000 in well
    under the server's one second). Taken one at a time over /solutions, each answer was a
    round trip the server's query time counted: the command ran out of it."""
    r = subprocess.run([sys.executable, "-m", "slr_sql", "query", short_server.url,
                        "between(1, 10000, X)"], capture_output=True, text=True,
                       cwd=ROOT, env=slr_env(), timeout=DEADLINE)
    assert (r.returncode, r.stderr) == (0, ""), r.stderr
    assert r.stdout.splitlines() == [f"X = {n}" for n in range(1, 10001)]
