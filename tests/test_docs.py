"""The documentation's examples run as written.

* docs/language.md: every ``prolog`` block loads into a fresh knowledge base (after the
  events its ``% events:`` comment lists), and every ``?- goal.  % answers`` line gives the
  answers its comment shows; every ``goal`` → ``answer`` example of its tables too.
* README.md: the tour's Python blocks run in order, and each line commented with a result
  (``kb.query(...)   # [{'C': Atom('green')}]``) returns exactly that.
* docs/sql.md: the sqlite-utils commands exist in the installed sqlite-utils and read the
  store of the page's example; the ``sqlite3`` examples print what the page shows.
* docs/semantics.md: its ``prolog`` blocks, as language.md's.
* docs/schema.md: the internal tables have the columns its table lists.
* docs/events.md, docs/synchronization.md, docs/subscriptions.md, docs/service.md,
  docs/api.md, docs/buffers.md, docs/fleet.md, docs/plots.md, docs/postgres.md and
  docs/ros.md: their self-contained Python examples run in a fresh folder (the client's
  against a real ``slr serve``, the rclpy client's against a real ``slr ros bridge``, the
  PostgreSQL ones on the suite's server), and each result they show (``...`` standing for
  a part left out) is what the line returns.
* Every ``slr ...`` line of every page's code blocks, README's command table, and every
  ``slr COMMAND ...`` a page's prose names, names commands and options ``slr`` has (the options its ``--help`` lists; a usage's
  ``[--port 8765]`` shows the default), and a line that shows a call parses as ``slr``
  parses it. The self-contained ones run as real ``slr`` processes and print what the page
  shows after them (README's shell lines and ``slr stats``, buffers.md's ``slr stats``,
  fleet.md's ``slr fleet status``, plots.md's ``slr plot``, ros.md's bag, ``tf_lookup``
  and export lines, sql.md's ``slr explain``, schema.md's ``slr sql``, subscriptions.md's
  ``slr subscribe``; fleet.md's worked session runs in tests/test_fleet.py).
* Parsed only, not run, because they cannot be self-contained: what runs until stopped
  or needs a live ROS graph or another machine -- ``slr foxglove`` and ``slr serve
  --foxglove`` (tests/test_foxglove.py runs them), ``slr ros bridge ... --map`` with
  ``--ros-args`` and ``ros2 launch`` (tests/test_ros_bridge.py), the ``ros2 topic`` lines
  (no ``ros2`` here: their requests go through the bridge's request reader instead),
  ``slr serve`` on a public address with TLS files, ``slr --token ... stats https://...``,
  ``slr ingest http://... events.jsonl`` (no such file is shown), service.md's ``slr add
  http://...`` (the same event its Python block adds: its ``slr query http://...`` line
  runs, after that block), ``slr fleet push ...
  http://fleet:8080 --follow``; the demo's plot (``slr demo --db demo.db`` alone takes
  seconds). ros.md's ``slr sql`` lines on ``robot_goal`` and ``detections`` (tables of
  bags imported with ``--all``) run their SQL in process on a store holding such events.
  The api.md ``for``/``async
  for`` lines over a live subscription take one answer each; ros.md's Bridge program runs
  a few spins (its ``running`` is the program's own).
* No page cites a specification that is not in the repository.
"""
from __future__ import annotations

import ast
import contextlib
import io
import json
import re
import shlex
import sqlite3
import subprocess
import sys
import tokenize
import warnings
from pathlib import Path

import click
import pytest

import slr_sql
from slr_sql.answers import unnamed_variables_named
from slr_sql.errors import SLREvaluationError, SLRSyntaxError
from slr_sql.parser import parse_term
from slr_sql.terms import Atom, String, Struct, Var, format_term, from_python, make_list

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
LANGUAGE = DOCS / "language.md"


def code_blocks(path: Path, lang: str) -> list[tuple[int, str]]:
    """(first line number, text) of each fenced block of ``lang`` in a Markdown file
    (``""``: the blocks whose fence names no language)."""
    return fenced_blocks(path.read_text(encoding="utf-8"), lang)


def fenced_blocks(markdown: str, lang: str) -> list[tuple[int, str]]:
    """:func:`code_blocks` of Markdown text."""
    out, current, start, indent, block_lang = [], None, 0, 0, ""
    for n, line in enumerate(markdown.splitlines(), start=1):
        if current is None and line.strip().startswith("```"):
            current, start, block_lang = [], n + 1, line.strip()[3:]
            indent = len(line) - len(line.lstrip())
        elif current is not None and line.strip() == "```":
            if block_lang == lang:
                out.append((start, "\n".join(current) + "\n"))
            current = None
        elif current is not None:
            current.append(line[indent:] if line[:indent].isspace() else line)
    return out


# ------------------------------------------------------------------ answers as text
def answer_text(value) -> str:
    """An answer value (as kb.query returns it: a string is a plain ``str``) as Prolog text."""
    return format_term(answer_term(value))


def answer_term(value):
    if type(value) is str:
        return String(value)
    if type(value) is list:
        return make_list([answer_term(v) for v in value])
    if type(value) is Struct:
        return Struct(value.name, tuple(answer_term(a) for a in value.args))
    return from_python(value)


def expected_answers(comment: str) -> list[dict[str, str]] | None:
    """``X = 1, T = 1.0 ; X = 2`` -> [{"X": "1", "T": "1.0"}, {"X": "2"}]; ``false`` -> [];
    ``true`` -> [{}]; None when the comment is prose, not answers."""
    comment = re.split(r"\s{2,}\(", comment.strip())[0].strip()  # drop a trailing (remark)
    if comment in ("false", "true"):
        return [] if comment == "false" else [{}]
    answers = []
    for alternative in re.split(r"\s;\s", comment):
        try:
            term, _ = parse_term(alternative)
        except SLRSyntaxError:
            return None
        bindings: dict[str, str] = {}
        goals = [term]
        while goals:
            g = goals.pop(0)
            if type(g) is Struct and g.name == "," and len(g.args) == 2:
                goals[:0] = list(g.args)
            elif type(g) is Struct and g.name == "=" and type(g.args[0]) is Var:
                bindings[g.args[0].name] = format_term(g.args[1])
            else:
                return None
        answers.append(bindings)
    return answers


def ours(kb, goal: str, names, at=None) -> list[dict[str, str]]:
    # (the variables no variable of the goal holds named as the CLI prints them: `_`, `_A`)
    return [{k: answer_text(v) for k, v in unnamed_variables_named(a).items() if k in names}
            for a in kb.query(goal, at=at)]


# ------------------------------------------------------------------ docs/language.md
def split_block(text: str) -> tuple[list[str], str, list[tuple[str, str]]]:
    """A block's events (from ``% events:`` lines), program text and ``?-`` lines."""
    events, program, queries = [], [], []
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("% events:"):
            events += split_events(stripped[len("% events:"):])
        elif stripped.startswith("?-"):
            goal, _, comment = stripped[2:].partition("%")
            queries.append((goal.strip().rstrip("."), comment.strip()))
        else:
            program.append(line)
    return events, "\n".join(program), queries


def split_events(text: str) -> list[str]:
    """``seen(x)^5  seen(y)^[1, 2]`` -> the two events: blanks inside brackets stay."""
    events, depth, current = [], 0, ""
    for ch in text:
        depth += (ch in "([{") - (ch in ")]}")
        if ch.isspace() and depth == 0:
            if current:
                events.append(current)
            current = ""
        else:
            current += ch
    return events + [current] if current else events


LANGUAGE_BLOCKS = code_blocks(LANGUAGE, "prolog")
# semantics.md's examples are written the same way (indented in its list items)
PROLOG_BLOCKS = [(f"language.md:{n}", t) for n, t in LANGUAGE_BLOCKS] + \
    [(f"semantics.md:{n}", t) for n, t in code_blocks(DOCS / "semantics.md", "prolog")]


@pytest.mark.parametrize("line,text", PROLOG_BLOCKS, ids=[w for w, _ in PROLOG_BLOCKS])
def test_language_blocks_load_and_answer_as_written(line, text):
    events, program, queries = split_block(text)
    # (the examples' small times are not the wall clock's: a ManualClock, or each type's
    # first event would arrive "decades late", a LearnedDelayWarning)
    with slr_sql.open(clock=slr_sql.ManualClock(0.0)) as kb:
        for event in events:
            kb.add(event)
        kb.load(program, ) if program.strip() else None
        for goal, comment in queries:
            at = None
            m = re.fullmatch(r"(.*), at (\d+(?:\.\d+)?)", goal)
            if m:  # `?- Goal, at 2.` writes the query <Goal, 2> of the stream view
                goal, at = m.group(1), float(m.group(2))
            expected = expected_answers(comment)
            got = kb.query(goal, at=at)
            if expected is not None:
                names = {k for e in expected for k in e}
                assert ours(kb, goal, names, at) == expected, f"{line}: ?- {goal}"
            else:
                assert got, f"{line}: ?- {goal} has no answer"


# `goal` → `answer` (or → true / false / an error term) in the tables and the text
ARROW = re.compile(r"`([^`]+)`\s*→\s*(`[^`]+`|true|false)")
LANGUAGE_EXAMPLES = [(m.group(1), m.group(2).strip("`"))
                     for m in ARROW.finditer(LANGUAGE.read_text(encoding="utf-8"))]


def test_the_language_page_has_examples():
    assert len(LANGUAGE_BLOCKS) >= 5 and len(LANGUAGE_EXAMPLES) >= 40


@pytest.mark.parametrize("goal,result", LANGUAGE_EXAMPLES,
                         ids=[g for g, _ in LANGUAGE_EXAMPLES])
def test_language_examples_give_the_documented_answer(goal, result):
    with slr_sql.open() as kb:
        expected = expected_answers(result)
        if expected is not None:
            names = {k for e in expected for k in e}
            assert ours(kb, goal, names) == expected
            return
        # an error: `X is a + 1` → `type_error(evaluable, a/0)`
        with pytest.raises(SLREvaluationError) as ei:
            kb.query(goal)
        assert format_term(ei.value.term.args[0]) == format_term(parse_term(result)[0])


def test_the_buffer_example_loads_as_one_program():
    """The declarations block of language.md is one program: no two of its buffers clash
    (two buffers whose patterns unify are an error when loaded)."""
    (text,) = [t for _, t in LANGUAGE_BLOCKS if "cBuffer" in t]
    declared = [line.split("(", 1)[0] for line in text.splitlines()
                if line.startswith(("tBuffer(", "cBuffer("))]
    with slr_sql.open() as kb:
        kb.load(text)
        assert [info.kind for info in kb.buffers()] == declared   # every one, as declared


# ------------------------------------------------------------------------ README.md
def run_python_block(text: str, env: dict, where: str) -> int:
    """Run a block statement by statement; a one-line expression followed by a comment
    that starts with ``[`` or ``{`` must evaluate to a value whose repr is that text, and a
    statement commented ``raises slr_sql.X`` must raise X. Returns how many were checked."""
    comments = {}
    lines = text.splitlines()
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            comments[tok.start[0]] = tok.string[1:].strip()
    checked = 0
    for node in ast.parse(text).body:
        expected = comments.get(node.end_lineno, "")
        below = node.end_lineno + 1  # or the result on a comment line of its own below
        if not expected and below in comments and lines[below - 1].lstrip().startswith("#"):
            expected = comments[below]
        source = ast.get_source_segment(text, node)
        raises = re.match(r"raises (slr_sql\.\w+)", expected)
        if raises:   # `kb.query("...", timeout=0.5)   # raises slr_sql.SLRTimeout`
            with pytest.raises(eval(raises.group(1), env)):
                exec(compile(ast.Module([node], []), where, "exec"), env)
            checked += 1
        elif (isinstance(node, ast.Expr) and node.lineno == node.end_lineno
                and expected[:1] in ("[", "{")):
            value = eval(compile(ast.Expression(node.value), where, "eval"), env)
            assert shows(repr(value), balanced_prefix(expected)), f"{where}: {source}"
            checked += 1
        else:
            exec(compile(ast.Module([node], []), where, "exec"), env)
    return checked


def shows(got: str, shown: str) -> bool:
    """A page shows a result exactly, or with ``...`` standing for the part it leaves out
    (``[<PendingQuery 'cups' ...: waiting for obj/3 ..., seg/2 ...>]``)."""
    if "..." not in shown:
        return got == shown
    pattern = ".*?".join(re.escape(part) for part in shown.split("..."))
    return re.fullmatch(pattern, got, flags=re.S) is not None


def balanced_prefix(text: str) -> str:
    """The leading bracketed expression of a comment (``[{'L': [a]}]   one per ...``)."""
    depth = 0
    quote = None
    for i, ch in enumerate(text):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch in "[{(":
            depth += 1
        elif ch in "]})":
            depth -= 1
            if depth == 0:
                return text[:i + 1]
    return text


def test_the_readme_tour_runs_as_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the tour writes robot.db in the current directory
    env: dict = {}
    checked = 0
    try:
        for line, text in code_blocks(ROOT / "README.md", "python"):
            checked += run_python_block(text, env, f"README.md:{line}")
    finally:
        if "kb" in env:
            env["kb"].close()
    assert checked >= 8


# ------------------------------------------------------------------------- docs/sql.md
def test_the_sql_page_commands_read_its_example(tmp_path):
    sql_md = DOCS / "sql.md"
    (program,) = [t for _, t in code_blocks(sql_md, "prolog") if "teaThing" in t]
    db = tmp_path / "robot.db"
    with slr_sql.open(db, clock=slr_sql.ManualClock(0.0)) as kb:
        kb.add("obj(cup1, cup, red)^2")
        kb.add("seg(cup1, [0.4, 0.1, 0.9])^3")
        kb.load(program)
    # the sqlite3 examples: `$ sqlite3 robot.db "SQL"` followed by its output lines
    shown = [t for _, t in code_blocks(sql_md, "sh") if t.startswith("$ sqlite3")]
    assert shown
    for block in shown:
        for command in re.split(r"^(?=\$ )", block, flags=re.M):
            if not command.strip():
                continue
            first, *output = command.strip().splitlines()
            sql = re.fullmatch(r'\$ sqlite3 robot\.db "(.*)"', first).group(1)
            with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as conn:
                rows = conn.execute(sql).fetchall()
            assert ["|".join(map(str, r)) for r in rows] == output, first
    # the sqlite-utils commands, through the installed sqlite-utils
    (utils,) = [t for _, t in code_blocks(sql_md, "sh") if "sqlite-utils" in t]
    outputs = []
    for command in utils.strip().splitlines():
        args = re.findall(r'"[^"]*"|\S+', command)
        assert args[0] == "sqlite-utils"
        proc = subprocess.run([sys.executable, "-m", "sqlite_utils"] +
                              [a.strip('"') for a in args[1:]],
                              cwd=tmp_path, capture_output=True, text=True, timeout=60)
        assert proc.returncode == 0, f"{command}: {proc.stderr}"
        outputs.append(proc.stdout)
    assert any("teaThing" in out for out in outputs)  # the view is listed and readable


# ------------------------------------------ the Python examples of the other pages
# (each runs in a fresh folder, as a new user would run it; a LearnedDelayWarning is an
# error there: an example whose event times are not its store's clock prints a warning the
# page does not show)
def page_block(name: str, marker: str) -> tuple[str, str]:
    """(``name:line``, text) of the Python block of docs/``name`` that contains ``marker``."""
    (found,) = [(f"{name}:{n}", t) for n, t in code_blocks(DOCS / name, "python")
                if marker in t]
    return found


def run_page_blocks(*blocks: tuple[str, str], env: dict | None = None) -> int:
    env = {} if env is None else env
    exec("import slr_sql", env)   # the page's first block imports it
    checked = 0
    try:
        for where, text in blocks:
            checked += run_python_block(text, env, where)
    finally:
        if "kb" in env:
            env["kb"].close()
    return checked


@pytest.mark.filterwarnings("error::slr_sql.clocks.LearnedDelayWarning")
def test_the_event_rules_example_runs_as_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (rules,) = code_blocks(DOCS / "events.md", "prolog")   # "these rules saved as rules.slr"
    (tmp_path / "rules.slr").write_text(rules[1], encoding="utf-8")
    assert run_page_blocks(page_block("events.md", "rules.slr")) == 1


@pytest.mark.filterwarnings("error::slr_sql.clocks.LearnedDelayWarning")
def test_the_synchronized_query_example_runs_as_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run_page_blocks(page_block("synchronization.md", "kb.submit(")) == 3


@pytest.mark.filterwarnings("error::slr_sql.clocks.LearnedDelayWarning")
def test_the_subscription_condition_example_runs_as_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert run_page_blocks(page_block("subscriptions.md", "size(cup1, small)")) == 1


@pytest.mark.filterwarnings("error::slr_sql.clocks.LearnedDelayWarning")
def test_the_python_api_examples_run_as_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "robot.slr").write_text("holds(gripper, nothing).\n", encoding="utf-8")
    # the store of the page's "tests and simulation" line: the examples' times are small
    env: dict = {}
    exec('import slr_sql\nclock = slr_sql.ManualClock(0.0)\n'
         'kb = slr_sql.open("sim.db", clock=clock)', env)
    blocks = [page_block("api.md", marker) for marker in (
        "def colors(", 'kb.load_file("robot.slr")', "kb.define(", 'kb.add("obj(cup1',
        "kb.solutions(", 'kb.submit("findall(W', "relFace(F) <-", 'kb.sql("SELECT', "kb.plot(",
        "b(2) :- .")]
    assert run_page_blocks(*blocks, env=env) == 11
    with slr_sql.open("sim.db") as kb:
        # the function of "Local or remote", given the store the examples filled
        assert env["colors"](kb, 5.0) == [{"O": Atom("cup1"), "C": Atom("red"), "T": 5.0}]
    assert (tmp_path / "timeline.png").stat().st_size > 0


@contextlib.contextmanager
def each_store_closed_after(monkeypatch):
    """Inside: ``slr_sql.open`` as ever, and each store it opened is closed at the end (a
    page's block that opens one store after another, ``kb = slr_sql.open(...)`` each time,
    closes none of those it leaves)."""
    opened: list = []
    real_open = slr_sql.open

    def open_and_keep(*args, **kwargs):
        opened.append(real_open(*args, **kwargs))
        return opened[-1]

    with monkeypatch.context() as patched:
        patched.setattr(slr_sql, "open", open_and_keep)
        try:
            yield
        finally:
            for kb in opened:
                kb.close()


def test_the_api_pages_opening_examples_run_as_written(tmp_path, monkeypatch):
    """api.md, "Opening a knowledge base": each way of opening, in a fresh folder (the
    `...` of its `with` block is Python's Ellipsis)."""
    monkeypatch.chdir(tmp_path)
    env: dict = {}
    where, text = page_block("api.md", 'slr_sql.open("robot.db", busy_timeout=2.0)')
    exec("import slr_sql", env)
    with each_store_closed_after(monkeypatch):
        run_python_block(text, env, where)
    assert {p.name for p in tmp_path.glob("*.db")} == {"robot.db", "sim.db", "shop.db", "r1.db"}


@pytest.mark.filterwarnings("error::slr_sql.clocks.LearnedDelayWarning")
def test_the_api_pages_subscription_lines_run_as_written(tmp_path, monkeypatch):
    """api.md, "Subscriptions", on the face/2 events of its "Event rules" block: a `for` or
    `async for` over a live subscription never ends, so each of those lines takes the next
    answer only (the `for` line's is the one its comment shows); the other lines run."""
    monkeypatch.chdir(tmp_path)
    env: dict = {}
    exec('import slr_sql\nclock = slr_sql.ManualClock(0.0)\n'
         'kb = slr_sql.open("sim.db", clock=clock)', env)
    import asyncio
    where, text = page_block("api.md", 'sub = kb.subscribe("face(F, R)^T"')
    comments = {tok.start[0]: tok.string[1:].strip()
                for tok in tokenize.generate_tokens(io.StringIO(text).readline)
                if tok.type == tokenize.COMMENT}
    taken = []
    try:
        run_python_block(page_block("api.md", "relFace(F) <-")[1], env, "api.md")
        for node in ast.parse(text).body:
            if isinstance(node, (ast.For, ast.AsyncFor)):
                source = ast.get_source_segment(text, node.iter)
                subscription = eval(source, env)
                if isinstance(node, ast.For):
                    answer = next(iter(subscription))
                    assert repr(answer) == balanced_prefix(comments[node.lineno])
                else:
                    async def first(aiter):
                        async for answer in aiter:
                            return answer
                    answer = asyncio.run(first(subscription))
                taken.append(answer)
            else:
                exec(compile(ast.Module([node], []), where, "exec"), env)
    finally:
        env["kb"].close()
    assert [a["R"] for a in taken] == [65, 70]   # the async one goes on where the for stopped


def test_the_runtime_buffer_examples_run_as_written(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    env: dict = {}
    exec('import slr_sql\nkb = slr_sql.open("robot.db")', env)   # a live robot's store
    blocks = [page_block("buffers.md", marker) for marker in ("kb.add_buffer(", "prune_now(kb)")]
    assert run_page_blocks(*blocks, env=env) == 1
    with slr_sql.open(tmp_path / "robot.db") as kb:
        assert [b.kind for b in kb.buffers()] == ["cBuffer", "tBuffer"]   # the window went


def test_the_client_example_runs_against_slr_serve(tmp_path):
    from service_helpers import ServiceProcess, slr_env
    where, text = page_block("service.md", "slr_sql.connect(")
    with ServiceProcess(tmp_path / "robot.db") as server:
        env: dict = {}
        assert run_page_blocks((where, text.replace("http://127.0.0.1:8765", server.url)),
                               env=env) == 2
        # the shell block below it asks the rule the Python block stored in the server's file
        shown = [t for _, t in code_blocks(DOCS / "service.md", "sh") if "slr query http" in t]
        (query,) = [line for line in shown[0].splitlines() if line.startswith("slr query")]
        goal = query.split("'")[1]
        done = subprocess.run([sys.executable, "-m", "slr_sql", "query", server.url, goal],
                              capture_output=True, text=True, env=slr_env(), cwd=tmp_path,
                              timeout=120)
        assert done.returncode == 0 and done.stdout.splitlines() == ["C = red"], done.stderr


# ------------------------------------------------------------------- docs/schema.md
def test_the_schema_page_names_the_columns_a_store_has(tmp_path):
    """Each internal table of the page's table has exactly the columns it lists, in order."""
    rows = re.findall(r"^\| `(slr_[a-z_]+)` \| `([^|]+)`", (DOCS / "schema.md").read_text(
        encoding="utf-8"), flags=re.M)
    assert len(rows) >= 9
    with slr_sql.open(tmp_path / "robot.db") as kb:
        for table, columns in rows:
            listed = [c.split()[0] for c in columns.partition("`")[0].split(",")]
            _, got = kb.sql("SELECT name FROM pragma_table_info(?)", [table])
            assert [name for (name,) in got] == listed, table


# ---------------------------------------------------------------- pages stand alone
@pytest.mark.parametrize("path", sorted([*DOCS.glob("*.md"), ROOT / "README.md"]),
                         ids=lambda p: p.name)
def test_pages_cite_nothing_outside_the_repository(path):
    text = path.read_text(encoding="utf-8")
    assert "SPEC" not in text and "§" not in text, path.name


_PRIVATE_REACH = re.compile(r"\b(kb|store|sub|engine)\._[a-z]")


@pytest.mark.parametrize("path", sorted([*DOCS.glob("*.md"), ROOT / "README.md"]),
                         ids=lambda p: p.name)
def test_pages_send_no_user_to_a_private_name(path):
    """What a page tells users to call is public (``kb._buffers.prune_now()`` was
    advice once: a rename would break their code without a word)."""
    found = [line for line in path.read_text(encoding="utf-8").splitlines()
             if _PRIVATE_REACH.search(line)]
    assert not found, f"{path.name}: {found}"


def test_atoms_and_strings_in_answers_print_as_in_the_docs():
    assert answer_text(Atom("cup1")) == "cup1" and answer_text("outdated") == '"outdated"'
    assert answer_text([Atom("a"), 1]) == "[a,1]"


# ------------------------------------------------ the `slr` command lines of every page
# Every `slr ...` line of a page's code blocks, and every command of README's table, names
# commands and options the installed `slr` has: what `slr COMMAND --help` would list, read
# from the same click commands in this process (a subprocess per line would cost a second
# each). A line that shows a real call (no `[...]`, no placeholder such as DB) is parsed as
# `slr` would parse it; a usage line's `[--option VALUE]` shows the option's default.
_USAGE_WORD = re.compile(r"[A-Z][A-Z_]*(\.[a-z]+)?|[A-Z]+x[A-Z]+")   # DB, FILE.mcap, WxH


def slr_lines(path: Path) -> list[tuple[str, str]]:
    """(``page:line``, text) of every ``slr ...`` line in the fenced blocks of a page: a
    ``$ `` prompt dropped, a line ending in ``\\`` or inside an open quote joined with the
    next, the indented ``[...]`` lines of a usage joined to it; psql's ``slr | face`` rows
    (a schema named slr) are no command."""
    found: list[tuple[str, str]] = []
    in_block, pending, usage = False, "", False
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        text = line.strip()
        if text.startswith("```"):
            in_block, pending, usage = not in_block, "", False
            continue
        if not in_block:
            continue
        if usage and text.startswith("["):
            found[-1] = (found[-1][0], f"{found[-1][1]} {text}")
            continue
        usage = False
        text = pending + " " + text if pending else text.removeprefix("$ ")
        pending = ""
        if text.startswith("slr ") and (text.endswith("\\") or text.count('"') % 2
                                        or text.count("'") % 2):
            pending = text.rstrip("\\").rstrip()
            continue
        if re.match(r"slr [^|]", text):
            found.append((f"{path.name}:{n}", text))
            usage = "[" in text
    return found


def readme_table_commands() -> list[tuple[str, str]]:
    """The ``slr ...`` usages of README's command table (each cell may hold several, ``·``)."""
    found = []
    for n, line in enumerate((ROOT / "README.md").read_text(encoding="utf-8").splitlines(),
                             start=1):
        if line.startswith("| `slr "):
            cell = line.split(" | ")[0]
            found += [(f"README.md:{n}", c) for c in re.findall(r"`(slr [^`]+)`", cell)]
    return found


def slr_command(words: list[str]) -> tuple[click.Command, list[str], list[str]]:
    """The click command a line names (its group options checked on the way), the command
    path and the words after it."""
    from slr_sql.cli import main
    command: click.Command = main
    path = ["slr"]
    while isinstance(command, click.Group):
        if not words or words[0] == "...":   # a mention of a group: `slr fleet`, `slr ros ...`
            break
        word = words.pop(0)
        if word.startswith("-"):
            (option,) = [p for p in command.params if word in p.opts]
            if not getattr(option, "is_flag", False) and words:
                words.pop(0)
            continue
        found = command.get_command(click.Context(command), word)
        assert found is not None, f"{' '.join(path)} has no command {word}"
        command, path = found, [*path, word]
    return command, path, words


def option_names(command: click.Command) -> set[str]:
    return {o for p in command.params for o in (*p.opts, *p.secondary_opts)} | {"-h", "--help"}


def check_usage(line: str) -> None:
    words = re.findall(r"[^\s\[\]…|]+", line)
    command, path, rest = slr_command(words[1:])
    known = option_names(command)
    for word in rest:
        if word == "--ros-args":   # ROS's own arguments follow (`--params-file F`)
            break
        for option in re.findall(r"(?:^|/)(--?[a-z][a-z-]*)", word.split("=")[0]):
            assert option in known, f"{' '.join(path)} has no option {option}"
    # `[--port 8765]`: the value shown is the default
    for option, value in re.findall(r"\[(--[a-z-]+)[ =]([^\]\s|]+)\]", line):
        if not re.fullmatch(r"[a-z0-9_.]+", value):   # a placeholder: `p/N…`, `TYPE:ARG`
            continue
        (param,) = [p for p in command.params if option in p.opts]
        default = param.default
        assert str(default) == value or (isinstance(default, (int, float))
                                         and float(default) == float(value)), \
            f"{' '.join(path)} {option}: the page shows {value}, the default is {default}"


def check_call(line: str) -> None:
    from slr_sql.cli import main
    argv = shlex.split(line, comments=True)
    for stop in ("&", ">", "|"):
        argv = argv[:argv.index(stop)] if stop in argv else argv
    context = None
    command: click.Command = main
    name, args = "slr", argv[1:]
    while True:
        try:
            context = command.make_context(name, list(args), parent=context)
        except click.BadParameter as exc:
            # a file of the user's that this folder has not (`--ssl-keyfile /etc/...`)
            assert "does not exist" in str(exc), str(exc)
            return
        if not isinstance(command, click.Group):
            return
        # (click 8.2 keeps the subcommand's words in _protected_args; 8.1 in protected_args)
        protected = getattr(context, "_protected_args", None)
        rest = [*(context.protected_args if protected is None else protected), *context.args]
        name, found, args = command.resolve_command(context, rest)
        assert found is not None, line
        command = found


SLR_LINES = [(where, line) for page in [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
             for where, line in slr_lines(page)] + readme_table_commands()


def test_the_pages_show_many_slr_command_lines():
    pages = {where.split(":")[0] for where, _ in SLR_LINES}
    assert len(SLR_LINES) >= 80 and {"README.md", "ros.md", "fleet.md", "plots.md",
                                     "service.md", "buffers.md"} <= pages


def prose_slr_commands(path: Path) -> list[tuple[str, str]]:
    """(``page:line``, text) of each ``slr COMMAND ...`` in a page's prose (backquoted, a
    known command or ``--token`` after ``slr``; code blocks left out)."""
    from slr_sql.cli import main
    names = set(main.list_commands(click.Context(main))) | {"--token"}
    found = []
    text = path.read_text(encoding="utf-8")
    for block in re.finditer(r"^\s*```.*?^\s*```$", text, flags=re.S | re.M):
        text = text.replace(block.group(0), "\n" * block.group(0).count("\n"))
    for match in re.finditer(r"`(slr [^`]+)`", text):
        if match.group(1).split()[1] in names:
            line = text.count("\n", 0, match.start()) + 1
            found.append((f"{path.name}:{line}", " ".join(match.group(1).split())))
    return found


PROSE_SLR = [found for page in [ROOT / "README.md", *sorted(DOCS.glob("*.md"))]
             for found in prose_slr_commands(page)]


@pytest.mark.parametrize("where,line", PROSE_SLR, ids=[w for w, _ in PROSE_SLR])
def test_each_slr_command_named_in_the_prose_is_one_slr_has(where, line):
    """`slr sql --write`, `slr fleet push --robot NAME`, ...: the command and its options."""
    check_usage(line)


def is_usage(line: str) -> bool:
    """A usage (``slr query DB GOAL [--at Z]``), not a call (``slr query robot.db 'p(X)'``)."""
    return "[" in line.split("'")[0].split('"')[0] or "…" in line or any(
        _USAGE_WORD.fullmatch(w) for w in line.split("#")[0].split()[1:])


@pytest.mark.parametrize("where,line", SLR_LINES, ids=[w for w, _ in SLR_LINES])
def test_each_slr_command_line_names_what_slr_has(where, line, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)   # a call's file arguments are looked for in an empty folder
    check_usage(line)
    if not is_usage(line):
        check_call(line)


# ---------------------------------------------------- `slr` lines run as a user runs them
def slr_processes(folder: Path, *calls: tuple) -> list[subprocess.CompletedProcess]:
    """Run ``slr`` calls as real processes, all at once (they are independent: one second
    of start-up for all, not one each), and return what each did, in order. A call is the
    argv after ``slr``, or ``(argv, {"input": text, "cwd": folder})`` (default: ``folder``,
    no input)."""
    from service_helpers import slr_env
    started = []
    for call in calls:
        argv, how = (call[0], call[1]) if call and isinstance(call[0], tuple) else (call, {})
        started.append((argv, how.get("input"), subprocess.Popen(
            [sys.executable, "-m", "slr_sql", *argv], cwd=how.get("cwd", folder),
            env=slr_env(), text=True, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            stdin=subprocess.DEVNULL if how.get("input") is None else subprocess.PIPE)))
    done = []
    for argv, stdin, process in started:
        try:
            out, err = process.communicate(stdin, timeout=120)
        finally:
            if process.poll() is None:
                process.kill()
                process.wait()
        done.append(subprocess.CompletedProcess(argv, process.returncode, out, err))
    return done


def slr_argv(line: str) -> tuple[str, ...]:
    """``slr query robot.db 'p(X)'   # X = 1`` -> ("query", "robot.db", "p(X)")."""
    argv = shlex.split(line, comments=True)
    assert argv[0] == "slr", line
    return tuple(argv[1:])


def shell_session(text: str) -> list[tuple[str, list[str]]]:
    """The ``$ command`` lines of a block, each with the lines it prints."""
    steps: list[tuple[str, list[str]]] = []
    for line in text.strip("\n").splitlines():
        if line.startswith("$ "):
            steps.append((line[2:], []))
        else:
            steps[-1][1].append(line)
    return steps


_NUMBER = re.compile(r"\d+(\.\d+)?")


def prints_as_shown(got: str, shown: list[str]) -> bool:
    """``slr stats``-like output against a page's lines: the same lines, except that the
    numbers of the ``file ...`` line (sizes that move with the schema and SQLite) and of
    ``buffer clock (now):`` (the wall clock's time on a live store) are compared as numbers
    of any value."""
    lines = got.splitlines()
    if len(lines) != len(shown):
        return False
    for line, page in zip(lines, shown):
        if page.startswith(("file ", "buffer clock (now):")):
            line, page = _NUMBER.sub("N", line), _NUMBER.sub("N", page)
        if not shows(line, page):
            return False
    return True


def tour_store(folder: Path) -> None:
    """The robot.db the README's tour leaves in ``folder`` (the current folder)."""
    env: dict = {}
    try:
        for line, text in code_blocks(ROOT / "README.md", "python"):
            exec(compile(text, f"README.md:{line}", "exec"), env)
    finally:
        env["kb"].close()
    assert (folder / "robot.db").exists()


def test_the_readme_shell_lines_run_as_written(tmp_path, monkeypatch):
    """README's `slr` lines, each a real `slr` process, on the store its tour leaves: a
    result shown in a comment (`# C = blue`) is what the line prints, the others succeed;
    the shell gets a goal with a comment after its full stop. Then its `slr stats` example,
    on the store the `slr add` it names makes, prints the lines shown."""
    monkeypatch.chdir(tmp_path)
    tour_store(tmp_path)
    (block,) = [t for _, t in code_blocks(ROOT / "README.md", "sh") if "slr add robot.db" in t]
    lines = [line for line in block.splitlines() if line.startswith("slr ")]
    assert [slr_argv(line)[0] for line in lines] == ["add", "query", "query", "explain", "sql",
                                                     "shell"]
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    (made_by,) = re.findall(r"`slr stats` on a store made by\n`(slr add [^`]+)`", readme)
    (stats,) = [t for _, t in code_blocks(ROOT / "README.md", "") if "$ slr stats" in t]
    ((stats_line, shown_stats),) = shell_session(stats)
    stats_folder = tmp_path / "stats"
    stats_folder.mkdir()
    for done in slr_processes(tmp_path, slr_argv(lines[0]),
                              (slr_argv(made_by), {"cwd": stats_folder})):
        assert done.returncode == 0, done.stderr
    *asked, shell, stats_done = slr_processes(
        tmp_path, *[slr_argv(line) for line in lines[1:5]],
        (slr_argv(lines[5]), {"input": "color(cup2, C)^20.   % the colour at 20\n"}),
        (slr_argv(stats_line), {"cwd": stats_folder}))
    for line, done in zip(lines[1:5], asked):
        assert done.returncode == 0, (line, done.stderr)
        comment = line.partition("#")[2].strip()
        if comment:
            assert done.stdout.splitlines() == [comment], line
    assert asked[2].stdout.startswith("goal: color(cup2, C)^20\nengine: sql")
    assert "cup2\tblue\t11.0" in asked[3].stdout.splitlines()
    assert shell.returncode == 0 and "C = blue" in shell.stdout, shell.stderr
    assert stats_done.returncode == 0 and prints_as_shown(stats_done.stdout, shown_stats), \
        stats_done.stdout


def test_the_buffers_pages_declarations_load_and_conflict_as_shown(tmp_path, monkeypatch):
    """buffers.md: its declarations block loads as one program; a robot.slr with the two
    buffers its conflict example names, on the lines it names, is refused with the error
    shown (the page wraps it; `(...)` leaves the explanation out) and nothing is loaded."""
    monkeypatch.chdir(tmp_path)
    ((_, declarations),) = code_blocks(DOCS / "buffers.md", "prolog")
    conflict = " ".join(fenced_blocks(
        (DOCS / "buffers.md").read_text(encoding="utf-8").split("### Conflicts", 1)[1], "")[0][1]
        .split())
    first, line1, second, line2 = re.match(
        r"conflicting buffers: (.*) at robot\.slr:(\d) and (.*) at robot\.slr:(\d) ",
        conflict).groups()
    lines = [""] * int(line2)
    lines[int(line1) - 1], lines[int(line2) - 1] = first + ".", second + "."
    (tmp_path / "robot.slr").write_text("\n".join(lines) + "\n", encoding="utf-8")
    with slr_sql.open() as kb:
        kb.load(declarations)
        assert len(kb.buffers()) == 4
    with slr_sql.open() as kb:
        with pytest.raises(slr_sql.SLRError) as refused:
            kb.load_file("robot.slr")
        # (the message goes on after the parenthesis the page ends with: advice)
        assert shows(str(refused.value), conflict + "...")
        assert kb.buffers() == [] and kb.programs() == {}


@pytest.mark.filterwarnings("error::slr_sql.clocks.LearnedDelayWarning")
def test_the_buffer_counters_example_prints_as_shown(tmp_path, monkeypatch):
    """buffers.md, "Counters and `slr stats`": the page's s.slr (the two buffers it names
    with their lines) and Python block make the store whose `slr stats` the page shows."""
    monkeypatch.chdir(tmp_path)
    text = (DOCS / "buffers.md").read_text(encoding="utf-8")
    section = text.split("## Counters and `slr stats`", 1)[1]
    clauses = re.findall(r"`([ct]Buffer\([^`]+\)\.)` on its line (\d)", section)
    assert [int(n) for _, n in clauses] == [1, 2]
    (tmp_path / "s.slr").write_text("".join(c + "\n" for c, _ in clauses), encoding="utf-8")
    assert run_page_blocks(page_block("buffers.md", 'kb.load_file("s.slr")')) == 0
    (stats,) = [t for _, t in code_blocks(DOCS / "buffers.md", "") if "$ slr stats" in t]
    ((line, shown),) = shell_session(stats)
    (done,) = slr_processes(tmp_path, slr_argv(line))
    assert done.returncode == 0 and prints_as_shown(done.stdout, shown), done.stdout


# ------------------------------------------------------------------------ docs/plots.md
def test_the_plots_page_examples_run_as_written(tmp_path, monkeypatch):
    """plots.md on the store the README's tour leaves: its two `$ slr plot` lines print what
    follows them (real processes), its Python block draws the rows its comment shows, and
    the keyword arguments it lists for `kb.plot` are those `timeline` takes. (The
    `slr demo --db demo.db` plot is not drawn here: the demo alone takes several seconds;
    its line is parsed by the command-line test above.)"""
    monkeypatch.chdir(tmp_path)
    tour_store(tmp_path)
    (block,) = [t for _, t in code_blocks(DOCS / "plots.md", "sh") if "$ slr plot" in t]
    steps = shell_session(block)
    assert len(steps) == 2
    for (line, shown), done in zip(steps, slr_processes(tmp_path, *[slr_argv(line)
                                                                    for line, _ in steps])):
        assert done.returncode == 0 and done.stdout.splitlines() == shown, (line, done.stderr)
    env: dict = {}
    where, text = page_block("plots.md", "fig.slr_timeline.rows")
    run_page_blocks((where, text), env=env)
    # its last line is inside the `with` block: asked again of the figure it drew
    (line,) = [line.strip() for line in text.splitlines() if "fig.slr_timeline.rows" in line]
    expression, _, comment = line.partition("#")
    assert repr(eval(expression, env)) == balanced_prefix(comment.strip())
    assert (tmp_path / "sweep.png").stat().st_size > 0
    # `--dpi N`: the width and a given height stay; an automatic height grows with the text
    with slr_sql.open("robot.db") as kb:
        drawn = {(dpi, size): kb.plot(size=size, dpi=dpi).slr_timeline
                 for dpi in (100, 200) for size in ((1200, None), (1200, 400))}
    sizes = {dpi: [(drawn[dpi, size].width, drawn[dpi, size].height)
                   for size in ((1200, None), (1200, 400))] for dpi in (100, 200)}
    assert sizes[200][1] == sizes[100][1] == (1200, 400)
    assert sizes[200][0][0] == sizes[100][0][0] == 1200 and sizes[200][0][1] > sizes[100][0][1]
    import inspect

    from slr_sql.plot import timeline
    text = (DOCS / "plots.md").read_text(encoding="utf-8")
    (listed,) = re.findall(r"`kb\.plot\((types=None, \*,[^`]+)\)` takes", text)
    names = [part.split("=")[0].strip() for part in listed.replace("\n", " ").split(",")]
    assert [n for n in names if n != "*"] == list(inspect.signature(timeline).parameters)[1:]


# ------------------------------------------------------------------------ docs/fleet.md
_CONTACT = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d UTC \(\d+ s ago\)")


def test_the_fleet_pages_examples_run_as_written(tmp_path, monkeypatch):
    """fleet.md (its worked example's session runs in tests/test_fleet.py): the Python line
    names a store; `slr fleet status` on the warehouse of the worked example (made here
    through the Python API) and on a fleet store a site store relays r1 and r2 to prints the
    tables shown (the time of the last contact by shape), `--json` the keys the page lists;
    `slr_sql.fleet.push` has the signature the page gives, and its report the fields."""
    import dataclasses
    import inspect

    from slr_sql import fleet
    monkeypatch.chdir(tmp_path)
    env: dict = {}
    run_page_blocks(page_block("fleet.md", 'robot="r1"'), env=env)
    with slr_sql.open("r1.db") as kb:
        # (slr_meta holds JSON values)
        assert kb.sql("SELECT value FROM slr_meta WHERE key = 'robot'")[1] == [('"r1"',)]
    text = (DOCS / "fleet.md").read_text(encoding="utf-8")
    session = text.split("## A worked example", 1)[1].split("```sh\n", 1)[1].split("```", 1)[0]
    for command, _ in shell_session(session):
        argv = slr_argv(command)
        clock = slr_sql.ManualClock(100.0)   # the page's small times are the robots' own
        if argv[:2] == ("fleet", "name"):
            slr_sql.open(argv[2], robot=argv[3], clock=clock).close()
        elif argv[0] == "add":
            with slr_sql.open(argv[1], clock=clock) as kb:
                kb.add_many(list(argv[2:]))
        elif argv[:2] == ("fleet", "push"):
            fleet.push(argv[2], argv[3])
    for name, events in (("a1", ["seen(p1, dock)^1", "seen(p2, dock)^2"]),
                         ("a2", ["seen(p3, dock)^3"])):
        with slr_sql.open(f"{name}.db", robot=f"r{name[1]}", clock=slr_sql.ManualClock(9)) as kb:
            kb.add_many(events)
        fleet.push(f"{name}.db", "site.db")
    fleet.push("site.db", "central.db", robot="site")
    direct, relayed = [t for _, t in code_blocks(DOCS / "fleet.md", "")
                       if t.startswith(("$ slr fleet status", "robot  shipped"))]
    ((status_line, shown),) = shell_session(direct)
    done = slr_processes(tmp_path, slr_argv(status_line), ("fleet", "status", "central.db"),
                         ("fleet", "status", "warehouse.db", "--json"))
    assert all(d.returncode == 0 for d in done), [d.stderr for d in done]
    for got, page in ((done[0].stdout, "\n".join(shown)), (done[1].stdout, relayed)):
        assert _CONTACT.sub("T", got).splitlines() == _CONTACT.sub("T", page).splitlines()
    listed = re.search(r"`--json` prints the same as a list of objects \(([^)]*)\)",
                       text.replace("\n", " ")).group(1)
    assert [row.keys() for row in json.loads(done[2].stdout)][0] == set(
        re.findall(r"`(\w+)`", listed))
    signature = re.search(r"Python: `slr_sql\.fleet\.push\(([^`]+)\)` returns a `PushReport` "
                          r"\(([^)]+)\)", text.replace("\n", " "))
    params = [p.split("=")[0].strip() for p in signature.group(1).split(",") if p.strip() != "*"]
    assert params == list(inspect.signature(fleet.push).parameters)
    assert re.findall(r"`(\w+)`", signature.group(2)) == [
        f.name for f in dataclasses.fields(fleet.PushReport)]


# --------------------------------------------------------------------- docs/postgres.md
def test_the_postgres_pages_examples_run_as_written(postgres_url, tmp_path, monkeypatch):
    """postgres.md against the suite's server: its Python block's URLs, with the server's
    user, database and socket for the page's (a server of one's own is not
    self-contained), open stores in the schemas they name; the psql session's tables are
    there once a rule and a subscription use face/2, and `SELECT * FROM slr.face` holds
    the rows shown; `slr stats URL` words its first line as the page says."""
    import psycopg
    monkeypatch.chdir(tmp_path)
    where, text = page_block("postgres.md", "postgresql://robot@db.example/fleet")
    info = psycopg.conninfo.conninfo_to_dict(postgres_url)
    user, database, socket = info["user"], info["dbname"], info["host"]
    text = text.replace("robot@db.example/fleet", f"{user}@/{database}?host={socket}")
    text = text.replace("robot@/fleet?host=/run/postgresql", f"{user}@/{database}?host={socket}")
    assert text.count(database) == 2
    with each_store_closed_after(monkeypatch):
        run_python_block(text, {}, where)
    page = (DOCS / "postgres.md").read_text(encoding="utf-8")
    psql = page.split("## The schema as seen in psql", 1)[1].split("```", 2)[1]
    with slr_sql.open(postgres_url, clock=slr_sql.ManualClock(100.0)) as kb:
        kb.add("face(antonio, 65)^28")
        kb.add("face(antonio, 65.0)^29")
        kb.add("obj(cup1, cup, red)^2")
        kb.load("relFace(F) <- (face(F, R1) seq face(F, R2) seq face(F, R3)) within 5.")
        kb.subscribe("face(F, R)^T", id="faces").close()
        _, tables = kb.sql("SELECT table_schema, table_name FROM information_schema.tables "
                           "WHERE table_schema IN ('slr', 'lab2')")
        columns, rows = kb.sql("SELECT * FROM slr.face")
    listed = re.findall(r"^ slr \| (\w+)", psql, flags=re.M)
    assert len(listed) == 7
    names = {name for schema, name in tables if schema == "slr"}
    for name in listed:
        assert name in names or (name.startswith("slr_cep_m_")
                                 and any(n.startswith("slr_cep_m_") for n in names)), name
    assert "slr_meta" in {name for schema, name in tables if schema == "lab2"}
    table = psql.split("SELECT * FROM slr.face;", 1)[1].strip().splitlines()
    assert [c.strip() for c in table[0].split("|")] == columns
    shown = [[c.strip() for c in line.split("|")] for line in table[2:]]
    assert shown == [[format(v, "g") if isinstance(v, float) else "" if v is None else str(v)
                      for v in row] for row in rows]
    (stats,) = slr_processes(tmp_path, ("stats", postgres_url))
    assert stats.returncode == 0, stats.stderr
    assert re.match(r"store postgresql://\S+: \d+ bytes \([\d.]+ MiB\) in its schema's tables "
                    r"and indexes", stats.stdout), stats.stdout


# -------------------------------------------------------------------------- docs/ros.md
def ros_section(title: str) -> str:
    return (DOCS / "ros.md").read_text(encoding="utf-8").split(title, 1)[1].split("\n## ", 1)[0]


def section_blocks(section: str, lang: str) -> list[str]:
    return [text for _, text in fenced_blocks(section, lang)]


@pytest.fixture(scope="module")
def ros_recording(tmp_path_factory):
    """A folder with the page's recording (`python examples/ros/make_bag.py demo_bag`, as the
    page runs it from the repository; the script is run in this process, as `python` would
    run it) and what the commands of "From a bag to tf_lookup to Foxglove"'s first steps
    print: the import into robot.db, `slr ros info` with and without `--map-only`."""
    import runpy
    folder = tmp_path_factory.mktemp("ros_docs")
    (folder / "examples").symlink_to(ROOT / "examples")
    worked = ros_section("## From a bag to tf_lookup to Foxglove")
    first, second = section_blocks(worked, "sh")[:2]
    make, info = first.strip().splitlines()
    assert make == "python examples/ros/make_bag.py demo_bag"
    argv = sys.argv
    sys.argv = shlex.split(make)[1:]
    try:
        with contextlib.chdir(folder), contextlib.redirect_stdout(io.StringIO()):
            runpy.run_path(sys.argv[0], run_name="__main__")
    finally:
        sys.argv = argv
    map_only, imported = second.strip().splitlines()
    assert map_only.endswith(" > draft.yaml")
    done = slr_processes(folder, slr_argv(imported), slr_argv(info),
                         slr_argv(map_only.removesuffix(" > draft.yaml")))
    assert all(d.returncode == 0 for d in done), [d.stderr for d in done]
    (folder / "draft.yaml").write_text(done[2].stdout, encoding="utf-8")
    return folder, {"import": done[0], "info": done[1], "import line": imported}


def test_the_ros_pages_import_and_info_print_as_shown(ros_recording):
    """ros.md: the import of the page's recording prints the table "Importing bags" shows;
    `slr ros info` lists the topics and frames its worked example names; the draft MAP
    `--map-only` writes imports every topic (a real `slr ros import`); the Python API's
    import (run in process, on a store of its own) stores the events it prints."""
    folder, done = ros_recording
    ((command, shown),) = shell_session(section_blocks(ros_section("## Importing bags"), "sh")[1])
    assert command == done["import line"]
    assert done["import"].stdout.splitlines() == shown
    # "`info` lists `/battery` (std_msgs/Float64, 12 messages), `/detections` ... (1)"
    prose = " ".join(ros_section("## From a bag to tf_lookup to Foxglove").split())
    for named in ("`/battery` (std_msgs/Float64, 12 messages)", "(geometry_msgs/PoseArray, 24)",
                  "`/tf` (123) and `/tf_static` (1)", "`map -> base` (121 transforms, 0 to 12 s)",
                  "`cam -> base` (2) in `/tf`", "`base -> cam_mount` (1) in `/tf_static`"):
        assert named in prose
    rows = [[cell.strip() for cell in line.split("│")[1:-1]]
            for line in done["info"].stdout.splitlines() if line.startswith("│")]
    assert {row[0]: (row[1], row[2]) for row in rows[:4]} == {
        "/battery": ("std_msgs/msg/Float64", "12"),
        "/detections": ("geometry_msgs/msg/PoseArray", "24"),
        "/tf": ("tf2_msgs/msg/TFMessage", "123"), "/tf_static": ("tf2_msgs/msg/TFMessage", "1")}
    assert {(row[0], row[1], row[2]): row[3] for row in rows[4:]} == {
        ("/tf", "map", "base"): "121", ("/tf", "cam", "base"): "2",
        ("/tf_static", "base", "cam_mount"): "1"}
    assert rows[5][4:] == ["1700000000.000", "1700000012.000"]   # map -> base: 0 to 12 s
    (draft,) = slr_processes(folder, ("ros", "import", "demo_bag", "draft.db", "--map",
                                      "draft.yaml"))
    assert draft.returncode == 0 and "imported 160 events from 160 messages" in draft.stdout
    assert "not imported" not in draft.stdout
    where, text = page_block("ros.md", "import_bag(kb,")
    text = text.replace('"robot.db"', '"python.db"')
    printed = io.StringIO()
    with contextlib.chdir(folder), contextlib.redirect_stdout(printed), \
            warnings.catch_warnings():
        warnings.simplefilter("error", slr_sql.clocks.LearnedDelayWarning)
        exec(compile(text, where, "exec"), {})
    (line,) = [line for line in text.splitlines() if "print(report" in line]
    assert printed.getvalue().strip() == line.partition("#")[2].strip()


def test_the_ros_pages_rules_lookups_and_exports_run_as_written(ros_recording):
    """ros.md on the imported recording: the paper's tf rule (`slr load`
    examples/ros/tf_rules.slr, the block the page shows) answers the TF shown; each
    `tf_lookup` line answers as its comment says (the pose shown, the inverse, none after
    the last transform, one when extrapolating); the position rule gives the answer shown
    first and one per detection; the export lines write what `slr ros import` reads back.
    (`slr foxglove`, `slr ros bridge` and `ros2 launch` run until stopped, on a live graph:
    their lines are checked by the command-line test; `slr foxglove` is tests/test_foxglove.py's.)"""
    folder, _ = ros_recording
    tf_example = ros_section("## The paper's tf example on a recording")
    commands = section_blocks(tf_example, "sh")[0].strip().splitlines()
    load, tf_query = [line for line in commands if line.startswith("slr ")][-2:]
    (rule,) = section_blocks(tf_example, "prolog")
    assert rule in (ROOT / "examples" / "ros" / "tf_rules.slr").read_text(encoding="utf-8")
    (tf_shown,) = section_blocks(tf_example, "")
    worked = ros_section("## From a bag to tf_lookup to Foxglove")
    lookups = [line for line in section_blocks(worked, "sh")[2].splitlines()
               if line.startswith("slr ")]
    (position,) = [b for b in section_blocks(worked, "prolog") if b.startswith("position(")]
    (folder / "position.slr").write_text(position, encoding="utf-8")
    gives = re.search(r"\(`slr load robot.db position.slr; (slr query [^`]+)` gives\n`([^`]+)`",
                      worked)
    exports = [line for b in section_blocks(worked, "sh") for line in b.splitlines()
               if line.startswith(("slr export", "slr ros import robot.mcap"))]
    assert len(lookups) == 4 and len(exports) == 3
    # "the events also form a log of the imports (`slr query DB ...`, or `slr sql DB ...`)"
    logs = re.findall(r"`(slr (?:query|sql) DB [^`]+)`",
                      ros_section("## Importing bags").split("form a log of the imports")[1])
    assert len(logs) == 2
    loaded = slr_processes(folder, slr_argv(load), ("load", "robot.db", "position.slr",
                                                    "--name", "position"))
    assert all(d.returncode == 0 for d in loaded), [d.stderr for d in loaded]
    done = slr_processes(folder, slr_argv(tf_query), *map(slr_argv, lookups),
                         slr_argv(gives.group(1)), *map(slr_argv, exports[:2]),
                         *[slr_argv(log.replace(" DB ", " robot.db ")) for log in logs])
    assert all(d.returncode == 0 for d in done), [d.stderr for d in done]
    tf, *looked, positions, _, _, log_query, log_sql = [d.stdout.splitlines() for d in done]
    assert len(log_query) == 4 and len(log_sql) == 5   # one per topic (and the header)
    assert tf == tf_shown.strip().splitlines()
    assert looked[0] == [re.search(r"#\s+(P = .*)", worked).group(1)]
    assert looked[1] == ["P = pose([-0.505,0.0,-1.0],[0.0,0.0,0.0,1.0])"]   # the inverse
    assert looked[2] == ["false."] and len(looked[3]) == 1     # none after it; held
    assert positions[0] == gives.group(2) and len(positions) == 24   # one per detection
    (copied,) = slr_processes(folder, slr_argv(exports[2]))
    assert copied.returncode == 0, copied.stderr
    with slr_sql.open(folder / "robot.db") as original, slr_sql.open(folder / "copy.db") as copy:
        for table in ("tf", "tf_static", "seg", "battery"):
            rows = f"SELECT * FROM {table} ORDER BY t_end, t_start, seq"
            assert [r[1:-2] for r in copy.sql(rows)[1]] == [r[1:-2] for r in original.sql(rows)[1]]


def ros_environment() -> dict:
    """The environment of a process that starts rclpy in a test: discovery on loopback only,
    in a ROS domain of its own (docs/ros.md, "Isolation when testing")."""
    import random

    from service_helpers import slr_env
    env = slr_env({"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
                   "ROS_DOMAIN_ID": str(random.SystemRandom().randint(1, 200))})
    env.pop("ROS_LOCALHOST_ONLY", None)
    return env


def test_the_ros_pages_request_example_runs_against_slr_ros_bridge(tmp_path):
    """ros.md, "A worked example from the command line": the store of its `slr add`, a real
    `slr ros bridge robot.db`, and the page's rclpy client as it is (a process of its own,
    on loopback in a ROS domain of the test's): each reply it prints is the one its comment
    shows; `ros2` itself is not installed here, so the requests of its `ros2 topic pub` lines
    (q2 and the add_input; its add_buffer is the client's own) are sent after the client's
    through the client's `send`, and each reply the `ros2 topic echo` lines show is the one
    the bridge gives; a `list` then replies what "list" shows, and the add_input is kept as
    the fact "Durable control state" shows.
    Beside it, in a domain of its own, the "Python
    API" block that runs a Bridge and a RequestServer in a program, for a few spins (its
    `running` is the program's own flag)."""
    import queue
    import signal
    import threading
    import time

    import yaml

    from slr_sql.ros.protocol import parse_query, read_request
    section = ros_section("### A worked example from the command line")
    store_lines = section_blocks(section, "sh")[0].strip().splitlines()
    assert store_lines[1] == "slr ros bridge robot.db &"
    # the requests of the `ros2 topic pub` lines (YAML whose `data` is the request's JSON)
    published = " ".join(section_blocks(section, "sh")[1].split("\\\n"))
    requests = [(topic, yaml.safe_load(payload)["data"]) for topic, payload in re.findall(
        r"ros2 topic pub --once -w 1 (/slr/\w+) std_msgs/msg/String\s+'([^']+)'", published)]
    assert [topic for topic, _ in requests] == ["/slr/query"] * 2 + ["/slr/control"] * 2
    (client,) = section_blocks(section, "python")
    # after the page's client, as it is, the test's own lines send two of those requests
    # through its `send`: q2 and the add_input (the add_buffer is the client's own, again)
    (tmp_path / "client.py").write_text(client + (
        "\n# the test's: requests of the ros2 lines, one JSON reply a line\n"
        "for topic, text in json.loads(open('requests.json').read()):\n"
        "    publisher = query if topic == '/slr/query' else control\n"
        "    print(json.dumps(send(publisher, json.loads(text))))\n"), encoding="utf-8")
    listing = ("/slr/control", json.dumps({"token": "c4", "op": "list"}))   # "#### list"
    (tmp_path / "requests.json").write_text(json.dumps([*requests[1:3], listing]),
                                            encoding="utf-8")
    where, api_block = page_block("ros.md", "Bridge(kb, mapping).start()")
    (tmp_path / "live.yaml").write_text("version: 1\n", encoding="utf-8")
    (tmp_path / "program.py").write_text(
        "import slr_sql\nfrom slr_sql.ros.mapping import load_mapping\n\n"
        "class Spins:   # the program's own flag: a few spins, then stop\n"
        "    left = 10\n"
        "    def __bool__(self):\n"
        "        Spins.left -= 1\n"
        "        return Spins.left >= 0\n\n"
        "running = Spins()\n" + api_block + "print('spun', requests.resumed)\n",
        encoding="utf-8")
    (added,) = slr_processes(tmp_path, slr_argv(store_lines[0]))
    assert added.returncode == 0, added.stderr
    env = ros_environment()
    bridge_log = (tmp_path / "bridge.log").open("w")
    bridge = subprocess.Popen([sys.executable, "-m", "slr_sql", "ros", "bridge", "robot.db"],
                              cwd=tmp_path, env=env, text=True, stdout=subprocess.PIPE,
                              stderr=bridge_log, stdin=subprocess.DEVNULL)
    bridge_log.close()
    program = subprocess.Popen([sys.executable, "program.py"], cwd=tmp_path,
                               env=ros_environment(), text=True, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, stdin=subprocess.DEVNULL)
    lines: queue.Queue = queue.Queue()

    def read_lines() -> None:
        with bridge.stdout:
            for line in bridge.stdout:
                lines.put(line)

    threading.Thread(target=read_lines, daemon=True).start()
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                if lines.get(timeout=max(0.1, deadline - time.monotonic())).startswith(
                        "bridge ready"):
                    break
            except queue.Empty:
                raise AssertionError("the bridge did not start: " + (
                    tmp_path / "bridge.log").read_text(encoding="utf-8")) from None
        asked = subprocess.run([sys.executable, "client.py"], cwd=tmp_path, env=env,
                               capture_output=True, text=True, timeout=120)
        assert asked.returncode == 0, asked.stderr
        program_out, program_err = program.communicate(timeout=120)
        assert program.returncode == 0 and program_out == "spun []\n", program_err
    finally:
        for process in (bridge, program):
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
                try:
                    process.wait(timeout=30)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
    assert bridge.returncode == 0, (tmp_path / "bridge.log").read_text(encoding="utf-8")
    comments = [line.lstrip("# ") for line in client.splitlines() if line.startswith("# {")]
    *page_client, q2, c1, listed = asked.stdout.splitlines()
    (list_reply,) = section_blocks(ros_section("#### list"), "json")
    assert json.loads(listed) == json.loads(list_reply)
    assert page_client == comments
    printed = [ast.literal_eval(line) for line in comments]
    echoed = [json.loads(ast.literal_eval(line[len("data: "):]))
              for block in section_blocks(section, "") for line in block.splitlines()
              if line.startswith("data: ")]
    assert [echoed[0], echoed[3]] == [printed[0], dict(printed[1], token="c2")]
    assert [echoed[1], echoed[2]] == [json.loads(q2), json.loads(c1)]
    for (topic, text), reply in zip(requests, echoed):
        token, body = read_request(text)
        assert token == reply["token"]
        if topic == "/slr/query":
            parse_query(body)
    # "Durable control state": the add_input is kept as the fact the page shows
    (fact,) = [line.strip() for line in ros_section("### Durable control state").splitlines()
               if line.strip().startswith("slr_ros_control(slr_bridge, input")]
    with slr_sql.open(tmp_path / "robot.db") as kb:
        assert [f"slr_ros_control(slr_bridge, input, '/battery', {answer_text(a['S'])})."
                for a in kb.query("slr_ros_control(slr_bridge, input, '/battery', S)")] == [fact]


def test_the_ros_pages_maps_and_requests_read_as_the_page_says(ros_recording):
    """ros.md's MAP examples load (the structure, the `/tf` entry written out, the publish
    entries, the pub_sub.xml), a misspelt key and a field the bag's type lacks give the
    errors "Mapping reference" shows, and its request and reply examples are what the
    request protocol reads and writes: the query request parses, the error replies are
    those of the goal and text they name; the SQL and the goal of "Messages: fields by
    name" read the fields of the page's PointStamped term and of the recording's
    /detections imported with `--all`. (In this process: no ROS needed.)"""
    import yaml

    from slr_sql.ros.bag_import import import_bag
    from slr_sql.ros.mapping import MappingError, load_mapping, mapping_from_dict
    from slr_sql.ros.protocol import dumps_reply, error_reply, parse_query, read_request
    folder, _ = ros_recording
    page = (DOCS / "ros.md").read_text(encoding="utf-8")
    structure, tf_entry, publish = section_blocks(page, "yaml")
    assert mapping_from_dict(yaml.safe_load(structure)).publish
    assert mapping_from_dict({"topics": yaml.safe_load(tf_entry)}).topics["/tf"]
    assert len(mapping_from_dict(yaml.safe_load(publish)).publish) == 2
    (xml,) = section_blocks(page, "xml")
    (folder / "pub_sub.xml").write_text(xml, encoding="utf-8")
    assert load_mapping(folder / "pub_sub.xml").publish[0].topic == "/marker1"
    shown = section_blocks(ros_section("## Mapping reference"), "")[0].strip().splitlines()
    (folder / "odom.yaml").write_text("topics:\n  /odom:\n    evnt: odom\n", encoding="utf-8")
    (folder / "dta.yaml").write_text("topics:\n  /battery:\n    args: [dta]\n",
                                     encoding="utf-8")
    with pytest.raises(MappingError) as misspelt:
        load_mapping(folder / "odom.yaml")
    with slr_sql.open(folder / "maps.db", clock=slr_sql.ManualClock(0.0)) as kb, \
            pytest.raises(MappingError) as missing:
        import_bag(kb, folder / "demo_bag", load_mapping(folder / "dta.yaml"))
    assert [f"error: {misspelt.value}", f"error: {missing.value}"] == shown
    # requests and replies: one JSON object a line, or one object over several lines
    requests = ros_section("## Requests: queries and control over ROS")
    objects = []
    for block in section_blocks(requests, "json"):
        text, at = block.strip(), 0
        while at < len(text):
            found, at = json.JSONDecoder().raw_decode(text, at)
            objects.append(found)
            at = len(text) - len(text[at:].lstrip())
    query = next(o for o in objects if o.get("goal") == "color(O, C)^T")
    assert parse_query(read_request(json.dumps(query))[1]).args == {"O": Atom("cup1")}
    with slr_sql.open() as kb, pytest.raises(slr_sql.SLRSyntaxError) as bad_goal:
        kb.query("obj(O, cup, C")
    with pytest.raises(Exception) as not_json:
        read_request("this is not JSON")
    errors = [line for block in section_blocks(requests, "json") for line in block.splitlines()
              if '"error"' in line]
    assert errors == [dumps_reply(error_reply("q3", bad_goal.value)),
                      dumps_reply(error_reply(None, not_json.value))]
    for o in objects:
        if "op" in o and "ok" not in o:   # a control request: a JSON object with a token
            token, body = read_request(json.dumps(o))
            assert token == o["token"] and body["op"] == o["op"]
    # "Messages: fields by name": the page's PointStamped term as a /robot_goal event, and
    # the recording imported with --all (its /detections whole); its SQL and SLR read them
    messages = ros_section("### Messages: fields by name")
    term = " ".join(re.search(r"compound — `('geometry_msgs/msg/PointStamped'[^`]+)`",
                              messages).group(1).split())
    selects = [" ".join(re.search(r'"(SELECT .*)"', line, flags=re.S).group(1).split())
               for line in re.split(r"\n(?=slr )", section_blocks(messages, "sh")[0])]
    (goal,) = [block.strip()[3:].rstrip(".") for block in section_blocks(page, "prolog")
               if block.startswith("?- robot_goal")]
    with slr_sql.open(folder / "messages.db", clock=slr_sql.ManualClock(0.0),
                      max_learned_delay=0.0) as kb:
        kb.add(f"robot_goal({term})^50.1")
        import_bag(kb, folder / "demo_bag", None, all_topics=True)
        assert kb.sql(selects[0])[1] == [(1.0, "map", 50.1)]
        assert kb.sql(selects[1])[1][:1] == [(0.9,)]
        assert [a["X"] for a in kb.query(goal)] == [1.0]


# ------------------------------------- the `slr` lines of sql.md, schema.md, subscriptions.md
def test_the_explain_sql_and_subscribe_lines_print_as_shown(tmp_path, monkeypatch):
    """Real `slr` processes on the README tour's robot.db (which has sql.md's `color/2`),
    with sql.md's `reach/2` rules and a `conn/2` event added: sql.md's two `$ slr explain`
    sessions print what the page shows (its long SQL lines wrapped: compared word by word);
    schema.md's two `slr sql` lines read the store (`--json`: a JSON list); subscriptions.md's
    `slr subscribe` line prints, for the face events its output names, those lines, and
    ends with status 0 on Ctrl-C."""
    import signal
    monkeypatch.chdir(tmp_path)
    tour_store(tmp_path)
    (reach,) = [t for _, t in code_blocks(DOCS / "sql.md", "prolog") if "reach(" in t]
    with slr_sql.open("robot.db", clock=slr_sql.StreamClock()) as kb:
        kb.load(reach, name="reach")
        kb.add("conn(r1, r2)^1")
    with slr_sql.open("faces.db", clock=slr_sql.ManualClock(10.0)) as kb:
        kb.add_many(["face(bob, 50)^1", "face(antonio, 65)^2", "face(carl, 99.5)^3"])
    sessions = [shell_session(t)[0] for _, t in code_blocks(DOCS / "sql.md", "")
                if t.startswith("$ slr explain")]
    schema_lines = [line for line in code_blocks(DOCS / "schema.md", "sh")[0][1].splitlines()
                    if line.startswith("slr ")]
    (subscribe_block,) = [t for _, t in code_blocks(DOCS / "subscriptions.md", "sh")
                          if t.startswith("slr subscribe")]
    subscribe_line, *subscribed = subscribe_block.strip().splitlines()
    from service_helpers import slr_env
    subscriber = subprocess.Popen(
        [sys.executable, "-m", "slr_sql", *slr_argv(subscribe_line.replace("robot.db",
                                                                           "faces.db"))],
        cwd=tmp_path, env=slr_env(), text=True, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, stdin=subprocess.DEVNULL)
    try:
        done = slr_processes(tmp_path, *[slr_argv(line) for line, _ in sessions],
                             *map(slr_argv, schema_lines))
        got = [subscriber.stdout.readline().rstrip("\n") for _ in subscribed]
        subscriber.send_signal(signal.SIGINT)
        rest, err = subscriber.communicate(timeout=60)
    finally:
        if subscriber.poll() is None:
            subscriber.kill()
            subscriber.communicate()
    assert len(sessions) == 2 and len(schema_lines) == 2
    assert all(d.returncode == 0 for d in done), [d.stderr for d in done]
    for (line, shown), printed in zip(sessions, done):
        assert printed.stdout.split() == " ".join(shown).split(), line
    assert "cup1\t2.0" in done[2].stdout.splitlines()
    assert [row["seq"] for row in json.loads(done[3].stdout)] == [2, 1, 3]
    assert got == subscribed and rest == "" and subscriber.returncode == 0, err
