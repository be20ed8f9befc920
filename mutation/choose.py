"""Choose which mutants of a cosmic-ray session run: mark the rest SKIPPED.

Two steps, both recorded in the session (``cr-report`` shows them as skipped):

1. Mutants that only touch a type annotation are equivalent by construction: every module
   mutated here starts with ``from __future__ import annotations``, so annotations are never
   evaluated at run time (nothing in slr_sql calls ``get_type_hints``). They are skipped with
   the output ``equivalent: annotation``.
2. Of the remaining mutants, ``--sample N`` keeps a uniform random subset of N (``--seed``,
   default 19, so a rerun picks the same mutants); the others are skipped with the output
   ``not sampled``. Without ``--sample`` every remaining mutant runs.

Usage: python mutation/choose.py SESSION.sqlite [--sample N] [--seed S]
"""
from __future__ import annotations

import argparse
import ast
import random
import sys
from functools import lru_cache
from pathlib import Path

from cosmic_ray.work_db import WorkDB, use_db
from cosmic_ray.work_item import WorkerOutcome, WorkResult


@lru_cache
def annotation_spans(path: Path) -> list[tuple[tuple[int, int], tuple[int, int]]]:
    """(start, end) positions, (line, column) with 1-based lines, of every annotation."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    if not any(isinstance(n, ast.ImportFrom) and n.module == "__future__"
               and any(a.name == "annotations" for a in n.names) for n in tree.body):
        return []   # annotations are evaluated: a mutant there is not equivalent by construction
    spans = []
    for node in ast.walk(tree):
        found = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            found.append(node.returns)
            a = node.args
            for arg in a.posonlyargs + a.args + a.kwonlyargs + [a.vararg, a.kwarg]:
                if arg is not None:
                    found.append(arg.annotation)
        elif isinstance(node, ast.AnnAssign):
            found.append(node.annotation)
        for ann in found:
            if ann is not None:
                spans.append(((ann.lineno, ann.col_offset), (ann.end_lineno, ann.end_col_offset)))
    return spans


def in_annotation(mutation) -> bool:
    start, end = tuple(mutation.start_pos), tuple(mutation.end_pos)
    return any(a <= start and end <= b for a, b in annotation_spans(Path(mutation.module_path)))


def skip(db: WorkDB, job_id: str, why: str) -> None:
    db.set_result(job_id, WorkResult(output=why, worker_outcome=WorkerOutcome.SKIPPED))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("session")
    parser.add_argument("--sample", type=int, default=None)
    parser.add_argument("--seed", type=int, default=19)
    args = parser.parse_args(argv)
    with use_db(args.session, WorkDB.Mode.open) as db:
        items = list(db.pending_work_items)
        live = []
        annotations = 0
        for item in items:
            if all(in_annotation(m) for m in item.mutations):
                skip(db, item.job_id, "equivalent: annotation")
                annotations += 1
            else:
                live.append(item)
        chosen = live
        if args.sample is not None and args.sample < len(live):
            chosen = random.Random(args.seed).sample(live, args.sample)
            keep = {i.job_id for i in chosen}
            for item in live:
                if item.job_id not in keep:
                    skip(db, item.job_id, "not sampled")
        print(f"{args.session}: {len(items)} mutants, {annotations} annotation-only "
              f"(equivalent), {len(live)} others, {len(chosen)} to run")
    return 0


if __name__ == "__main__":
    sys.exit(main())
