"""Ask slr_sql and a live SWI-Prolog the same goals and print where they differ (a probe for
gaps, before a goal becomes a test of tests/test_swi_builtins.py).

    python tests/golden/probe_swi.py GOALS.txt

GOALS.txt holds one goal a line (``#`` starts a comment line). Each goal runs as
``test_swi_builtins.py`` runs its goals (``test_swi_differential.builtin_example`` and
``check_example``: slr_sql's interpreter and its compiled path against SWI-Prolog, the
answers in order or the same error after the same answers) and prints ``OK``, ``DIFF``
(and both sides' results), ``DISC`` (outside the comparison: a cyclic term, too many
answers) or ``SWIFAIL`` (SWI-Prolog's side could not be read: a goal that writes to its
standard output, say; wrap it in ``with_output_to/2``). A ``'$VAR'(N)`` in an answer
reads as a variable on SWI-Prolog's side (its driver numbers variables so): compare such
terms through their printed text. Exits 1 when a goal differs.
"""
from __future__ import annotations

import sys
from pathlib import Path

TESTS = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(TESTS))
sys.path.insert(0, str(TESTS.parent))

import test_swi_differential as swidiff  # noqa: E402


def probe(goals: list[str]) -> int:
    """Print each goal's comparison; the number of goals that differ."""
    differ = 0
    with swidiff.live_swipl() as swipl:
        for goal in goals:
            example = swidiff.builtin_example(goal)
            try:
                theirs = swipl.run(example[2])
            except AssertionError as exc:
                print(f"SWIFAIL {goal}: {str(exc).splitlines()[0][:200]}")
                continue
            try:
                discarded = swidiff.check_example(example, theirs) is swidiff.DISCARDED
            except swidiff.slr_sql.SLRSyntaxError as exc:   # (1r3, `abc`: no SWI syntax)
                differ += 1
                print(f"DIFF {goal}\n     slr_sql: {str(exc).splitlines()[0]}")
                continue
            except AssertionError as exc:
                differ += 1
                print(f"DIFF {goal}\n     {str(exc).split(chr(10) + 'program:')[0][:300]}"
                      f"\n     swi={str(theirs.get(0))[:300]}")
                continue
            print(("DISC " if discarded else "OK   ") + goal)
    print("goals that differ:", differ)
    return differ


if __name__ == "__main__":
    lines = Path(sys.argv[1]).read_text(encoding="utf-8").splitlines()
    sys.exit(1 if probe([g for g in lines if g.strip() and not g.startswith("#")]) else 0)
