"""Every arithmetic function slr_sql evaluates, on every combination of operands from a
grid of infinities, NaN, overflowing floats, signed zeros, plain numbers and integers beyond
the floats and beyond 2**53 (where SWI-Prolog makes a float of an integer), against a live
SWI-Prolog (its default flags: float_overflow=error, float_zero_div=error,
float_undefined=error): the same number, or the same error.

One SWI-Prolog process evaluates the whole grid. The functions are slr_sql's own table, so a
function SWI-Prolog does not evaluate shows as a difference (its type_error(evaluable, F/N));
an answer beyond a 64-bit integer is compared as "big". ``LEFT_ALONE``: the integer to a
negative integer power, ISO's type error (tests/test_swi_builtins.py keeps it as such);
left out: max/min of an infinity and an integer beyond the floats, which slr_sql compares by
their exact values on purpose (docs/language.md, "Arithmetic").
"""
from __future__ import annotations

import subprocess

import pytest
import test_swi_differential as swidiff

from slr_sql.arith import BINARY, UNARY, evaluate
from slr_sql.errors import SLREvaluationError
from slr_sql.parser import parse_term
from slr_sql.terms import format_term

SPECIAL = ["inf", "-inf", "nan", "1.0e308", "-1.0e308"]
PLAIN = ["0", "1", "-2", "0.0", "-0.0", "2.5", "0.5"]
# integers beyond the floats (SWI-Prolog makes an integer a float where a float function or a
# float operand needs one: float_overflow) and one beyond 2**53 (a float of it is rounded)
BIG = ["2**1100", "-(2**1100)", "9007199254740993"]


def expressions() -> list[tuple[str, int, str]]:
    """(function, arity, expression text) of the grid."""
    out = []
    for op in sorted(UNARY):
        out.extend((op, 1, f"{op}({v})") for v in SPECIAL + PLAIN + BIG
                   if not (op == "random" and v in BIG))   # (a random number)
    operands = SPECIAL + PLAIN + BIG
    for op in sorted(BINARY):
        for a in operands:
            for b in operands:
                if b in BIG and (op in ("<<", ">>") or op in ("**", "^") and a not in SPECIAL
                                 and "." not in a):
                    continue   # beyond every integer: SWI-Prolog's GMP aborts the process
                text = f"{op}({a}, {b})" if op.isalnum() else f"({a}) {op} ({b})"
                if text not in LEFT_ALONE and not _compares_apart(op, a, b):
                    out.append((op, 2, text))
    return out


def _compares_apart(op: str, a: str, b: str) -> bool:
    """max/min of an infinity and an integer beyond the floats: slr_sql compares the two
    by their exact values (docs/language.md, "Arithmetic"); SWI-Prolog 9.0 makes the integer
    a float first, float_overflow."""
    return op in ("max", "min") and {a, b} & {"inf", "-inf"} != set() and {a, b} & set(BIG[:2]) != set()


# ISO's type_error(float, -2) (SWI-Prolog answers 0.25 unless its iso flag is set), also for
# an integer beyond the floats (SWI-Prolog: float_overflow, making a float of it)
LEFT_ALONE = {"(-2) ^ (-2)", "(2**1100) ^ (-2)", "(-(2**1100)) ^ (-2)", "(9007199254740993) ^ (-2)"}


GRID = expressions()
FUNCTIONS = sorted({(op, n) for op, n, _ in GRID})


DRIVER = """
show(E) :-
    catch(( X is E,
            ( float(X), X =\\= X -> format('nan~n')
            ; integer(X), abs(X) > 9223372036854775807 -> format('big~n')
            ; format('~q~n', [X]) ) ),
          error(Err, _),
          format('error ~q~n', [Err])).
:- initialization(main, main).
main :- read(Es), forall(member(E, Es), show(E)).
"""


def ours(text: str) -> str:
    term, _ = parse_term(text, "<test>")
    try:
        x = evaluate(term)
    except SLREvaluationError as exc:
        return "error " + format_term(exc.term.args[0], quoted=True)
    if type(x) is float and x != x:
        return "nan"
    if type(x) is int and abs(x) > 9223372036854775807:
        return "big"
    return format_term(x, quoted=True)


@pytest.fixture(scope="module")
def swi_results(tmp_path_factory) -> dict[str, str]:
    if not swidiff.HAVE_SWIPL:
        pytest.fail("swipl (SWI-Prolog) is not installed: this differential test needs it "
                    "(apt-get install swi-prolog-nox)")
    exprs = [text for _, _, text in GRID]
    driver = tmp_path_factory.mktemp("specials") / "driver.pl"
    driver.write_text(DRIVER, encoding="utf-8")
    run = subprocess.run(["swipl", str(driver)], input="[" + ",\n".join(exprs) + "].\n",
                         capture_output=True, text=True, timeout=120, check=True)
    lines = run.stdout.splitlines()
    assert len(lines) == len(exprs), run.stderr
    return dict(zip(exprs, lines))


def test_the_grid_covers_every_function():
    assert FUNCTIONS == sorted([(op, 1) for op in UNARY] + [(op, 2) for op in BINARY])


@pytest.mark.parametrize("op,arity", FUNCTIONS, ids=[f"{op}/{n}" for op, n in FUNCTIONS])
def test_a_function_answers_as_swipl(swi_results, op, arity):
    mine = [text for f, n, text in GRID if (f, n) == (op, arity)]
    diffs = [(e, swi_results[e], ours(e)) for e in mine if swi_results[e] != ours(e)]
    assert diffs == []


@pytest.mark.parametrize("text", ["sqrt(2)", "sin(2.5)", "log(7)", "atan2(1, 2.0)",
                                  "atan(1.0, 2)", "nexttoward(1, 2)"])
def test_a_float_function_runs_no_python_beyond_its_wrapper(text):
    """sqrt, sin, atan2, ... are evaluated for every row a compiled statement hands to
    slr_ar1/slr_ar2 and every `is` of the interpreter: checking and promoting the operands
    is straight-line code, no generator (a generator over the operands made these ~1.7 times
    slower to evaluate)."""
    import sys

    term, _ = parse_term(text)
    frames: list[str] = []

    def profile(frame, event, arg):
        if event == "call":
            frames.append(frame.f_code.co_name)

    sys.setprofile(profile)
    try:
        value = evaluate(term)
    finally:
        sys.setprofile(None)
    assert type(value) is float
    assert "<genexpr>" not in frames, frames
