"""Example files: a program, its events and the queries with their expected answers in one
``.slr`` text (format: examples/README.md), and running them (``slr run FILE``).

The program is everything before the line ``%% events``; every non-comment line after it is
one event (``obj(cup1, cup, red)^2.0.``), added in file order, so the file order is the
arrival order. ``%% query:``, ``%% at:``, ``%% expect:`` and ``%% tolerance:`` comment lines
anywhere say what to ask and what must come back (JSON in the store's encoding: a string is
an atom, ``{"$string": ..}`` a string, ``{"f": [..]}`` a compound, ``{"$var": true}`` an
unbound variable).

>>> example = parse_example('''p(X)^T :- prev(q(X)^Z, T).
... %% events
... q(a)^1.
... %% query: p(X)^2
... %% expect: [{"X": "a"}]''')
>>> example.events, example.cases[0].goal
(['q(a)^1'], 'p(X)^2')
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any

from .api import KnowledgeBaseAPI
from .errors import SLRError
from .terms import NIL, Atom, Struct, Var, list_items

__all__ = ["Case", "CaseResult", "Example", "check_case", "event_like_facts", "parse_example",
           "expected_term", "answer_term", "same_term"]

_KEY = re.compile(r"^%%\s*(query|at|expect|tolerance):\s?(.*)$")
_CONTINUATION = re.compile(r"^%%\s+(.*)$")


@dataclass
class Case:
    """One ``%% query``: the goal, where it is, its stream view and what must come back."""

    goal: str
    line: int
    at: float | None = None
    expect: str | None = None      # JSON text; None: print the answers, compare nothing
    tolerance: float = 1e-6


@dataclass
class Example:
    program: str
    events: list[str] = field(default_factory=list)
    event_lines: list[int] = field(default_factory=list)
    cases: list[Case] = field(default_factory=list)
    has_events_part: bool = False


def parse_example(text: str, filename: str = "<example>") -> Example:
    """The parts of an example file (see the module's text).

    >>> example = parse_example('''color(O, C)^T :- prev(obj(O, _, C)^Z, T).
    ... %% events
    ... obj(cup1, cup, red)^2.0.
    ... %% query: color(cup1, C)^5
    ... %% expect: [{"C": "red"}]
    ... %% query: color(cup1, C)^1
    ... %% at: 1
    ... %% expect: []''')
    >>> example.program.strip(), example.events, example.event_lines
    ('color(O, C)^T :- prev(obj(O, _, C)^Z, T).', ['obj(cup1, cup, red)^2.0'], [3])
    >>> [(case.goal, case.line, case.at, case.expect) for case in example.cases]
    [('color(cup1, C)^5', 4, None, '[{"C": "red"}]'), ('color(cup1, C)^1', 6, 1.0, '[]')]
    """
    program: list[str] = []
    example = Example("")
    in_events = False
    last_key = None
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if stripped == "%% events":
            in_events, last_key, example.has_events_part = True, None, True
            program.append("")
            continue
        key = _KEY.match(stripped)
        if key:
            name, value = key.group(1), key.group(2).strip()
            if name == "query":
                example.cases.append(Case(value, lineno))
            elif not example.cases:
                raise SLRError(f"{filename}:{lineno}: '%% {name}:' before any '%% query:'")
            else:
                case = example.cases[-1]
                try:
                    if name == "at":
                        case.at = float(value)
                    elif name == "tolerance":
                        case.tolerance = float(value)
                    else:
                        case.expect = value
                except ValueError:
                    raise SLRError(f"{filename}:{lineno}: '%% {name}:' wants a number, "
                                   f"not {value!r}") from None
            last_key = name
            program.append("")
            continue
        more = _CONTINUATION.match(stripped)
        if more and last_key in ("query", "expect"):
            case = example.cases[-1]
            if last_key == "query":
                case.goal += " " + more.group(1).strip()
            else:
                case.expect = (case.expect or "") + more.group(1).strip()
            program.append("")
            continue
        last_key = None
        if in_events:
            program.append("")
            if stripped and not stripped.startswith("%"):
                example.events.append(stripped[:-1].rstrip() if stripped.endswith(".")
                                      and not stripped.endswith("..") else stripped)
                example.event_lines.append(lineno)
        else:
            program.append(line)
    # blank lines keep the program's line numbers those of the file (errors point into it)
    example.program = "\n".join(program) + "\n"
    return example


def event_like_facts(text: str, filename: str = "<string>") -> list[tuple[int, str]]:
    """The facts of a program text that look like events (``obj(cup1, red)^2.0.``): with a
    number or ``[S, E]`` of numbers after ``^``. They are rules' facts, which prev and next
    never see (SPEC §1); (line, text) of each.

    >>> event_like_facts("color(O,C)^T :- prev(obj(O,_,C)^Z, T).\\nobj(cup1, cup, red)^2.0.\\n"
    ...                  "seen(a)^[1, 2].")
    [(2, 'obj(cup1, cup, red)^2.0.'), (3, 'seen(a)^[1, 2].')]
    """
    from .parser import parse_program

    found = []
    for clause in parse_program(text, filename):
        head = clause.head
        if clause.body != Atom("true") or not (isinstance(head, Struct) and head.name == "^"
                                               and len(head.args) == 2):
            continue
        stamp = head.args[1]
        numbers, tail = list_items(stamp) if isinstance(stamp, Struct) else ([stamp], NIL)
        if tail != NIL:
            continue
        if numbers and len(numbers) <= 2 and all(
                isinstance(n, (int, float)) and not isinstance(n, bool) for n in numbers):
            found.append((clause.span.line if clause.span else 0, clause.text))
    return found


# -- comparing answers with an expectation -------------------------------------------------

def expected_term(data: Any) -> Any:
    """Expected JSON -> a comparable tree: ('atom', s), ('string', s), numbers,
    ('list', [..]), ('struct', name, [..]), ('var',).

    >>> expected_term({"-": ["a", 1.0]})
    ('struct', '-', [('atom', 'a'), 1.0])
    """
    if isinstance(data, str):
        return ("list", []) if data == "[]" else ("atom", data)
    if isinstance(data, bool) or data is None:
        raise SLRError(f"expect: {json.dumps(data)} is no term (write an atom as a string)")
    if isinstance(data, (int, float)):
        return data
    if isinstance(data, list):
        return ("list", [expected_term(x) for x in data])
    if isinstance(data, dict) and len(data) == 1:
        ((key, val),) = data.items()
        if key == "$var":
            return ("var",)
        if key == "$string" and isinstance(val, str):
            return ("string", val)
        if isinstance(val, list):
            return ("struct", key, [expected_term(x) for x in val])
    raise SLRError(f"expect: {json.dumps(data)} is no term in the store's JSON encoding")


def answer_term(value: Any) -> Any:
    """An answer value of ``kb.query`` -> the same tree as :func:`expected_term`.

    >>> answer_term([Atom("a"), 1])
    ('list', [('atom', 'a'), 1])
    """
    if isinstance(value, Atom):
        return ("atom", str(value))
    if isinstance(value, str):
        return ("string", value)
    if isinstance(value, (int, float)):
        return value
    if isinstance(value, list):
        return ("list", [answer_term(x) for x in value])
    if isinstance(value, Struct):
        return ("struct", str(value.name), [answer_term(x) for x in value.args])
    if isinstance(value, Var):
        return ("var",)
    return ("other", repr(value))


def same_term(expected: Any, got: Any, tolerance: float) -> bool:
    """Whether two trees agree, numbers within ``tolerance`` (integers exactly).

    >>> same_term(("list", [1.0]), ("list", [1.0000001]), 1e-6)
    True
    """
    if isinstance(expected, (int, float)):
        if isinstance(got, bool) or not isinstance(got, (int, float)):
            return False
        if isinstance(expected, int) and isinstance(got, int):
            return expected == got
        return math.isclose(expected, got, rel_tol=0.0, abs_tol=tolerance)
    if not isinstance(got, tuple) or expected[0] != got[0]:
        return False
    if expected[0] == "var":
        return True
    if expected[0] in ("atom", "string"):
        return bool(expected[1] == got[1])
    if expected[0] == "list":
        return len(expected[1]) == len(got[1]) and all(
            same_term(e, g, tolerance) for e, g in zip(expected[1], got[1]))
    return (expected[1] == got[1] and len(expected[2]) == len(got[2])
            and all(same_term(e, g, tolerance) for e, g in zip(expected[2], got[2])))


@dataclass
class CaseResult:
    case: Case
    answers: list[dict[str, Any]]
    ok: bool | None                 # None: no expectation to compare with


def check_case(kb: KnowledgeBaseAPI, case: Case) -> CaseResult:
    """Ask ``case`` on ``kb`` and compare the answers with its expectation: the same
    answers in the same order; an unbound variable the expectation does not name is not
    compared; floats within the case's tolerance.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0)); kb.add("q(a)^1")
    >>> check_case(kb, Case("q(X)^T", 1, expect='[{"X": "a", "T": 1.0}]')).ok
    True
    """
    answers = kb.query(case.goal, at=case.at)
    if case.expect is None:
        return CaseResult(case, answers, None)
    try:
        data = json.loads(case.expect)
    except json.JSONDecodeError as exc:
        raise SLRError(f"line {case.line}: expect is not JSON ({exc.msg})") from None
    if not isinstance(data, list):
        raise SLRError(f"line {case.line}: expect is a JSON list of answers")
    expected = [{k: expected_term(v) for k, v in a.items()} for a in data]
    got = [{k: answer_term(v) for k, v in a.items() if not (isinstance(v, Var) and k not in e)}
           for a, e in zip(answers, expected + [{}] * len(answers))]
    ok = len(expected) == len(got) and all(
        e.keys() == g.keys() and all(same_term(e[k], g[k], case.tolerance) for k in e)
        for e, g in zip(expected, got))
    return CaseResult(case, answers, ok)
