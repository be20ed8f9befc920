"""Runs every case of every examples/*.slr file through the Python API (format: examples/README.md)."""
from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import pytest

import slr_sql
from slr_sql.example_files import answer_term, expected_term, same_term

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
KEY = re.compile(r"^%%\s*(query|at|expect|tolerance):\s?(.*)$")
CONTINUATION = re.compile(r"^%%\s+(.*)$")


@dataclass
class Case:
    goal: str
    line: int
    at: float | None = None
    expect: str = ""
    tolerance: float = 1e-6


@dataclass
class Example:
    program: str
    events: list[str] = field(default_factory=list)
    cases: list[Case] = field(default_factory=list)


def parse_example(path: Path) -> Example:
    lines = path.read_text(encoding="utf-8").splitlines()
    program: list[str] = []
    example = Example("")
    in_events = False
    last_key = None
    for lineno, line in enumerate(lines, start=1):
        stripped = line.strip()
        if stripped == "%% events":
            in_events, last_key = True, None
            continue
        key = KEY.match(stripped)
        if key:
            name, value = key.group(1), key.group(2).strip()
            if name == "query":
                example.cases.append(Case(value, lineno))
            elif not example.cases:
                raise ValueError(f"{path}:{lineno}: '{name}' before any query")
            elif name == "at":
                example.cases[-1].at = float(value)
            elif name == "expect":
                example.cases[-1].expect = value
            elif name == "tolerance":
                example.cases[-1].tolerance = float(value)
            last_key = name
            continue
        more = CONTINUATION.match(stripped)
        if more and last_key in ("query", "expect"):
            case = example.cases[-1]
            if last_key == "query":
                case.goal += " " + more.group(1).strip()
            else:
                case.expect += more.group(1).strip()
            continue
        last_key = None
        if in_events:
            if stripped and not stripped.startswith("%"):
                example.events.append(stripped.rstrip(".").rstrip() if stripped.endswith(".") else stripped)
        else:
            program.append(line)
    example.program = "\n".join(program) + "\n"
    return example


expected_value, answer_value, same = expected_term, answer_term, same_term


def collect_cases():
    params = []
    for path in sorted(EXAMPLES.glob("*.slr")):
        example = parse_example(path)
        for case in example.cases:
            params.append(pytest.param(path, case, id=f"{path.stem}:{case.line}"))
    return params


def test_every_example_has_cases():
    paths = sorted(EXAMPLES.glob("*.slr"))
    assert paths, "no examples found"
    for path in paths:
        example = parse_example(path)
        assert example.cases, f"{path.name} has no %% query"
        for case in example.cases:
            json.loads(case.expect)  # every expectation is valid JSON


@pytest.fixture(scope="module")
def loaded_examples(tmp_path_factory):
    """One store per example file, shared by its cases (queries do not change the store)."""
    kbs = {}
    yield kbs, tmp_path_factory
    for kb in kbs.values():
        kb.close()


def _kb_for(path: Path, loaded_examples):
    kbs, factory = loaded_examples
    if path not in kbs:
        example = parse_example(path)
        kb = slr_sql.open(str(factory.mktemp(path.stem) / "example.db"), clock=slr_sql.ManualClock(0.0))
        kb.load(example.program)
        kb.add_many(example.events)
        kbs[path] = kb
    return kbs[path]


@pytest.mark.parametrize("path, case", collect_cases())
def test_example(path: Path, case: Case, loaded_examples):
    kb = _kb_for(path, loaded_examples)
    answers = kb.query(case.goal, at=case.at)
    expected = [{k: expected_value(v) for k, v in a.items()} for a in json.loads(case.expect)]
    # Variables left unbound (the template variables of a findall, say) are only compared
    # when the expectation names them, as {"$var": true}.
    got = [{k: answer_value(v) for k, v in a.items()
            if not (isinstance(v, slr_sql.Var) and k not in e)}
           for a, e in zip(answers, expected + [{}] * len(answers))]
    ok = len(expected) == len(got) and all(
        e.keys() == g.keys() and all(same(e[k], g[k], case.tolerance) for k in e)
        for e, g in zip(expected, got))
    assert ok, f"{path.name}:{case.line}: ?- {case.goal}\n  expected {expected}\n  got      {got}"


def test_parse_example_format(tmp_path):
    path = tmp_path / "x.slr"
    path.write_text(
        "p(X) :- q(X).\n%% events\nq(a)^1.\n% comment\nq(b)^[2, 3].\n"
        "%% query: p(X)\n%% at: 2\n%% expect: [{\"X\":\n%%   \"a\"}]\n", encoding="utf-8")
    ex = parse_example(path)
    assert ex.program.strip() == "p(X) :- q(X)."
    assert ex.events == ["q(a)^1", "q(b)^[2, 3]"]
    [case] = ex.cases
    assert (case.goal, case.at, json.loads(case.expect)) == ("p(X)", 2.0, [{"X": "a"}])
    assert same(expected_value({"-": ["a", 1.0]}), ("struct", "-", [("atom", "a"), 1.0000001]), 1e-6)
    assert not same(expected_value({"$string": "a"}), ("atom", "a"), 1e-6)


# -- the same files through the command line: `slr run FILE` ---------------------------------

@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.slr")), ids=lambda p: p.stem)
def test_every_example_runs_with_slr_run(path: Path):
    from test_cli import slr

    example = parse_example(path)
    r = slr("run", str(path), "-q")
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout == f"{len(example.cases)} of {len(example.cases)} expected answers matched\n"
