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
* docs/events.md, docs/synchronization.md, docs/subscriptions.md, docs/service.md: their
  self-contained Python examples run in a fresh folder (the client's against a real
  ``slr serve``), and each result they show (``...`` standing for a part left out) is what
  the line returns.
* No page cites a specification that is not in the repository.
"""
from __future__ import annotations

import ast
import io
import re
import sqlite3
import subprocess
import sys
import tokenize
from pathlib import Path

import pytest

import slr_sql
from slr_sql.errors import SLREvaluationError, SLRSyntaxError
from slr_sql.parser import parse_term
from slr_sql.terms import Atom, String, Struct, Var, format_term, from_python, make_list

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
LANGUAGE = DOCS / "language.md"


def code_blocks(path: Path, lang: str) -> list[tuple[int, str]]:
    """(first line number, text) of each fenced block of ``lang`` in a Markdown file."""
    out, current, start, indent = [], None, 0, 0
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if current is None and line.strip() == f"```{lang}":
            current, start = [], n + 1
            indent = len(line) - len(line.lstrip())
        elif current is not None and line.strip() == "```":
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
    return [{k: answer_text(v) for k, v in a.items() if k in names}
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
    with slr_sql.open() as kb:
        kb.load(text)


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
        'kb.load_file("robot.slr")', "kb.define(", 'kb.add("obj(cup1', "kb.solutions(",
        'kb.submit("findall(W', "relFace(F) <-", 'kb.sql("SELECT', "b(2) :- .")]
    assert run_page_blocks(*blocks, env=env) == 11


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
