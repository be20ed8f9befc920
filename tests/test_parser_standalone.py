"""The parser is grammar/slr_parser.py, lark's standalone parser generated from slr.lark: it
is the grammar's parser (same trees, same errors as a parser the installed lark builds from
slr.lark), the committed module is current, and slr_sql parses with no `lark` importable --
so it does not matter whether lark 1.x or the lark-parser 0.12 of ROS 2's rosidl won the
shared `lark/` directory."""
from __future__ import annotations

import importlib.util
import json
import re
import subprocess
import sys
from pathlib import Path

import lark
import pytest

from slr_sql.grammar import slr_parser
from slr_sql.grammar.generate import generate, grammar_digest
from slr_sql.parser import _EXAMPLES, _GRAMMAR_PATH

ROOT = Path(__file__).resolve().parent.parent


def corpus() -> list[tuple[str, str]]:
    """(start, text): every example file, the documentation's Prolog blocks, and the texts
    the error messages are built from (bad input on purpose)."""
    texts = [("program", p.read_text(encoding="utf-8"))
             for p in sorted((ROOT / "examples").glob("*.slr"))]
    for page in sorted((ROOT / "docs").glob("*.md")):
        for block in re.findall(r"```prolog\n(.*?)```", page.read_text(encoding="utf-8"), re.DOTALL):
            texts.append(("program", block))
    texts += [("program", bad) for examples in _EXAMPLES.values() for bad in examples]
    texts += [("query", goal) for goal in ("color(cup1, C)^12.5", "X = [1,2|T], Y = - 1",
                                            "a :- (b", "'unterminated", "f(x) :- 0'", "a.b.")]
    return texts


def outcome(parser, start: str, text: str):
    """A parse's result as plain data: the tree, or the error's kind, place and expectations."""
    def plain(node):
        if isinstance(node, str):   # a Token
            return [node.type, str(node), node.start_pos]
        return [node.data, [plain(child) for child in node.children]]
    try:
        return plain(parser.parse(text, start=start))
    except Exception as exc:  # noqa: BLE001 - comparing what the two parsers raise
        where = getattr(exc, "pos_in_stream", None)
        token = getattr(exc, "token", None)
        return [type(exc).__name__, where, None if token is None else [token.type, str(token)],
                sorted(getattr(exc, "expected", None) or ())]


def test_the_standalone_module_parses_like_the_grammar_built_by_lark():
    assert lark.__version__.split(".")[0] != "0", "the test extra needs lark 1.x"
    reference = lark.Lark(_GRAMMAR_PATH.read_text(encoding="utf-8"), parser="lalr",
                          lexer="basic", start=["program", "query"], maybe_placeholders=False)
    standalone = slr_parser.Lark_StandAlone()
    texts = corpus()
    assert len(texts) > 60
    errors = 0
    for start, text in texts:
        expected = outcome(reference, start, text)
        assert outcome(standalone, start, text) == expected, (start, text)
        errors += expected[0].startswith("Unexpected")
    assert errors > 20   # the error paths were compared too, not only good text


def test_the_committed_module_was_generated_from_the_grammar_as_it_is():
    assert slr_parser.GRAMMAR_SHA256 == grammar_digest(), (
        "grammar/slr.lark changed after grammar/slr_parser.py was generated: run "
        "python -m slr_sql.grammar.generate")


def test_the_generator_makes_a_parser_like_the_committed_one(tmp_path):
    fresh_path = generate(tmp_path / "fresh_parser.py")
    spec = importlib.util.spec_from_file_location("fresh_parser", fresh_path)
    fresh = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fresh)
    assert fresh.GRAMMAR_SHA256 == slr_parser.GRAMMAR_SHA256
    committed, made = slr_parser.Lark_StandAlone(), fresh.Lark_StandAlone()
    for start, text in corpus():
        assert outcome(made, start, text) == outcome(committed, start, text), (start, text)


PROGRAM_RUN = """
import json, sys
{block}
import slr_sql
from slr_sql.parser import parse_program, parse_term
out = {{"lark": repr(sys.modules.get("lark"))}}
kb = slr_sql.open(clock=slr_sql.ManualClock(0))
kb.load("color(O, C)^T :- prev(obj(O, _, C)^_Z, T).  p(X) :- X = f(- 1, -1, a- (b, c), [1|T]).")
kb.add_many(["obj(cup1, cup, red)^2", "obj(cup1, cup, green)^9"])
out["answers"] = [str(a["C"]) for a in kb.query("color(cup1, C)^12")]
out["terms"] = [str(c.body) for c in parse_program(open({path!r}).read())]
errors = []
for bad in ["a :- (b", "a(b,", "f(x) :- 0'", "'open", "a :- b c."]:
    try:
        kb.load(bad)
    except slr_sql.SLRSyntaxError as exc:
        errors.append([exc.line, exc.column, str(exc).splitlines()[0]])
out["errors"] = errors
print(json.dumps(out))
"""


def run_parser_process(block: str) -> dict:
    code = PROGRAM_RUN.format(block=block, path=str(ROOT / "examples" / "location.slr"))
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       timeout=120, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("block, what", [
    ("sys.modules['lark'] = None   # `import lark` fails: as if neither were installed", "none"),
    # a lark-parser 0.12 that won the directory: its version, and none of lark 1.x's API
    ("import types; fake = types.ModuleType('lark'); fake.__version__ = '0.12.0'\n"
     "sys.modules['lark'] = fake", "0.12"),
])
def test_slr_parses_the_same_whichever_lark_is_importable(block, what):
    with_lark = run_parser_process("import lark")
    without = run_parser_process(block)
    assert without["answers"] == with_lark["answers"] == ["green"]
    assert without["terms"] == with_lark["terms"] and len(without["terms"]) > 3
    assert without["errors"] == with_lark["errors"] and len(without["errors"]) == 5
    # the run really had another `lark` (none, or the stand-in without lark 1.x's API)
    assert without["lark"] != with_lark["lark"]
    assert without["lark"] == "None" if what == "none" else "module 'lark'" in without["lark"]


def test_parsing_never_imports_the_regex_module():
    """lark's standalone parser imports the third-party ``regex`` where installed (for Unicode
    categories, which slr.lark does not use): ~15 ms of every process that parses."""
    probe = subprocess.run([sys.executable, "-c", "import sys, slr_sql\n"
                            "slr_sql.open().load('p(X) :- q(X).')\n"
                            "print('regex' in sys.modules)"],
                           capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert probe.stdout.strip() == "False", probe.stderr
