"""Write SWI-Prolog's answers for the tests into tests/golden (run with ``swipl`` installed).

    python tests/golden/make_swi_corpus.py

* ``swi_print.json``: how SWI-Prolog prints each text of tests/test_parser.py's SWI_TEXTS
  (read_term + writeq);
* ``swi_differential.json``: 200 examples drawn (deterministically) from the program
  generator of tests/test_swi_differential.py, each with SWI-Prolog's answers to its
  queries; examples outside the comparison (cyclic terms, too many answers, no termination)
  are left out. Then one example per query of its BUILTIN_GOALS (the atom builtins in every
  mode, their errors, SWI-7's lists).

The tests replay both files on every machine and, where ``swipl`` is installed, check that
SWI-Prolog still gives exactly these answers. Review the diff after regenerating: a changed
answer is either a new SWI-Prolog version or a changed test.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent
sys.path.insert(0, str(TESTS))
sys.path.insert(0, str(TESTS.parent))

import test_parser  # noqa: E402  (the texts and the SWI printing script)
import test_swi_differential as differential  # noqa: E402  (the generator and the driver)
from hypothesis import HealthCheck, given, settings  # noqa: E402

N_EXAMPLES = 200


def swipl_version() -> str:
    out = subprocess.run(["swipl", "--version"], capture_output=True, text=True, check=True)
    return out.stdout.strip()


def write_json(path: Path, head: dict, key: str, items: list) -> None:
    """``head`` plus ``key``: the items, one JSON line each (readable diffs)."""
    lines = [json.dumps(x, ensure_ascii=False, sort_keys=True) for x in items]
    text = json.dumps(head, ensure_ascii=False, sort_keys=True)[:-1]
    text += f', "{key}": [\n' + ",\n".join(lines) + "\n]}\n"
    json.loads(text)  # well-formed
    path.write_text(text, encoding="utf-8")


def print_corpus(workdir: Path) -> list[dict]:
    texts = test_parser.SWI_TEXTS
    printed = test_parser.swi_writeq(texts, workdir)
    rejected = [t for t, p in zip(texts, printed) if p == "<syntax error>"]
    if rejected:
        raise SystemExit(f"SWI-Prolog rejects {rejected}: fix SWI_TEXTS")
    return [{"text": t, "printed": p} for t, p in zip(texts, printed)]


def draw_examples() -> list[tuple]:
    drawn: list[tuple] = []

    @settings(max_examples=N_EXAMPLES, derandomize=True, database=None, deadline=None,
              suppress_health_check=list(HealthCheck))
    @given(differential.examples())
    def draw(example):
        drawn.append(example)

    draw()
    return drawn


def differential_corpus(workdir: Path) -> list[dict]:
    swipl = differential.Swipl(workdir)
    entries = []
    builtins = [differential.builtin_example(g) for g in differential.BUILTIN_GOALS]
    try:
        for example in draw_examples() + builtins:
            program, events, swi_program, queries = example
            swi = swipl.run(swi_program)
            if differential.check_example(example, swi) is differential.DISCARDED:
                continue
            entries.append({"program": program, "events": [list(e) for e in events],
                            "swi_program": swi_program, "queries": [list(q) for q in queries],
                            "swi": {str(k): v for k, v in sorted(swi.items())}})
    finally:
        swipl.close()
    return entries


def main() -> None:
    if shutil.which("swipl") is None:
        raise SystemExit("swipl (SWI-Prolog) is not installed: apt-get install swi-prolog-nox")
    with tempfile.TemporaryDirectory(prefix="slr_corpus_") as d:
        head = {"swipl": swipl_version()}
        write_json(HERE / "swi_print.json", head, "texts", print_corpus(Path(d)))
        examples = differential_corpus(Path(d))
        write_json(HERE / "swi_differential.json", head, "examples", examples)
    print(f"wrote swi_print.json ({len(test_parser.SWI_TEXTS)} texts) and "
          f"swi_differential.json ({len(examples)} examples)")


if __name__ == "__main__":
    main()
