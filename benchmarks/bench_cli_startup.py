"""What each ``slr`` command costs as a whole process, and what ``import slr_sql.cli`` imports.

    python benchmarks/bench_cli_startup.py
    python benchmarks/bench_cli_startup.py --code /tmp/old --runs 20   # before/after, alternated

Every command pays the CLI's start-up (the test suite starts ``slr`` ~300 times). Per command,
the CPU time (user + system) of a whole ``python -m slr_sql ...`` process on a small file store:
one store holding a rule and events, one holding events only (a process that parses nothing
needs no parser). With ``--code DIR`` (an earlier checkout, its C module built) each command
runs for DIR and for this checkout in turn, the order swapped every run, and the table gives
the medians, the minima, and the median of the paired differences (each run's this - DIR:
what the machine's load does to both cancels best there). The read-only commands' outputs
must be the same for both. Then ``python -X importtime -c "import slr_sql.cli"``: the
cumulative time of the import (medians) and the number of modules it adds.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

RULES = "red_cup(O)^T :- obj(O, cup, red)^T.\n"

# name -> arguments after `python -m slr_sql` (RULED: the store with a rule; PLAIN: events only)
COMMANDS = {
    "--help": ["--help"],
    "query": ["query", "RULED", "obj(O, cup, C)^T"],
    "query rule": ["query", "RULED", "red_cup(O)^T"],
    "query plain": ["query", "PLAIN", "obj(O, cup, C)^T"],
    "add plain": ["add", "PLAIN", "obj(cupx, cup, blue)^100.0"],
    "sql": ["sql", "RULED", "SELECT count(*) FROM obj"],
    "sql plain": ["sql", "PLAIN", "SELECT count(*) FROM obj"],
    "stats plain": ["stats", "PLAIN"],
}
CHANGING = {"add plain", "stats plain"}   # their output differs run to run (sizes, counts)

IMPORT_CHILD = ("import sys; before = len(sys.modules); import slr_sql.cli; "
                "print(len(sys.modules) - before)")


def run(code: Path, args: list[str]) -> tuple[float, str]:
    """CPU milliseconds (user + system) of one ``python -m slr_sql ARGS`` and its stdout."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run([sys.executable, "-m", "slr_sql", *args], capture_output=True,
                          text=True, cwd=code, env=dict(os.environ, PYTHONPATH=str(code)),
                          timeout=120)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise SystemExit(f"{code}: slr {' '.join(args)} failed: {done.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu * 1e3, done.stdout


def import_figures(code: Path) -> tuple[float, int]:
    """``-X importtime``'s cumulative ms of ``slr_sql.cli``, and the modules it added."""
    done = subprocess.run([sys.executable, "-X", "importtime", "-c", IMPORT_CHILD],
                          capture_output=True, text=True, cwd=code,
                          env=dict(os.environ, PYTHONPATH=str(code)), timeout=120)
    if done.returncode != 0:
        raise SystemExit(done.stderr[-2000:])
    cumulative = [int(line.split("|")[1]) / 1e3 for line in done.stderr.splitlines()
                  if line.count("|") == 2 and line.split("|")[2].strip() == "slr_sql.cli"]
    return cumulative[0], int(done.stdout)


def stores(code: Path, where: Path) -> dict[str, str]:
    """The two stores of one checkout (made by its own `slr`)."""
    ruled, plain = str(where / "ruled.db"), str(where / "plain.db")
    for db in (ruled, plain):
        run(code, ["add", db, *[f"obj(cup{k}, cup, red)^{k}.0" for k in range(20)]])
    rules = where / "rules.slr"
    rules.write_text(RULES)
    run(code, ["load", ruled, str(rules)])
    return {"RULED": ruled, "PLAIN": plain}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--code", type=Path, help="another checkout, measured in the same run")
    ap.add_argument("--runs", type=int, default=10, help="processes per command and checkout")
    args = ap.parse_args()
    codes = [ROOT] if args.code is None else [args.code.resolve(), ROOT]
    with tempfile.TemporaryDirectory() as tmp:
        dbs = {}
        for i, code in enumerate(codes):
            (Path(tmp) / str(i)).mkdir()
            dbs[code] = stores(code, Path(tmp) / str(i))
        cpu: dict = {(name, code): [] for name in COMMANDS for code in codes}
        outputs: dict = {}
        for k in range(args.runs):
            for name, template in COMMANDS.items():
                for code in (codes if k % 2 == 0 else codes[::-1]):
                    ms, out = run(code, [dbs[code].get(a, a) for a in template])
                    cpu[name, code].append(ms)
                    for alias, path in dbs[code].items():
                        out = out.replace(path, alias)
                    outputs.setdefault((name, code), out)
        imports: dict = {code: [] for code in codes}
        for k in range(args.runs):
            for code in (codes if k % 2 == 0 else codes[::-1]):
                imports[code].append(import_figures(code))
    label = {code: (code.name or str(code))[:12] for code in codes}
    print(f"{args.runs} processes per command and checkout; CPU ms (user + system) per process")
    head = "".join(f" | {label[c]:>12} median | min" for c in codes)
    print(f"{'command':12}{head}" + (" | paired difference (median)" if len(codes) == 2 else ""))
    for name in COMMANDS:
        row = "".join(f" | {statistics.median(cpu[name, c]):19.0f} | {min(cpu[name, c]):3.0f}"
                      for c in codes)
        if len(codes) == 2:
            paired = statistics.median(b - a for a, b in zip(cpu[name, codes[0]],
                                                             cpu[name, codes[1]]))
            row += f" | {paired:+.0f}"
            if name not in CHANGING and outputs[name, codes[0]] != outputs[name, codes[1]]:
                row += "  (OUTPUT DIFFERS)"
        print(f"{name:12}{row}")
    for code in codes:
        ms = statistics.median(m for m, _ in imports[code])
        print(f"import slr_sql.cli ({label[code]}): {ms:.1f} ms by -X importtime (median), "
              f"{imports[code][0][1]} modules added")


if __name__ == "__main__":
    main()
