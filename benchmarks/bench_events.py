"""Event rules: detection throughput against ETALIS, latency, and history-size independence.

    python benchmarks/bench_events.py                    # everything
    python benchmarks/bench_events.py --part throughput  # or latency, flat
    python benchmarks/bench_events.py --part throughput --rules equals3 --policies recent --no-one
    ETALIS_DIR=/tmp/etalis python benchmarks/bench_events.py --part throughput

* **throughput** -- events/s through ``kb.add_many`` (batches of 1,000) and through ``kb.add``
  (one transaction per event), on a file store (``synchronous=FULL`` unless
  ``--synchronous``), for three rules under ``recent`` and ``unrestricted``:
  ``seq2`` (``c(X) <- a(X) seq b(X)``, 100 keys), ``seq3`` (the relFace rule: a three-part
  ``seq`` with ``within 5`` and ``where``) and ``equals3`` (softDrinkRec: ``equals`` of three
  with ``where (softDrink(O), pos_multiply(...))``). The same events run through ETALIS on
  SWI-Prolog (``swipl --traditional``, in memory, in-order mode, detections counted from its
  fired events) when ``swipl`` and an ETALIS checkout (``$ETALIS_DIR``, with ``src/etalis.P``)
  are present. Both engines get the same rule text, except seq3's ``within 5``, which ETALIS
  cannot run on a three-part sequence: it gets the window as ``T3 - T1 =< 5`` in ``where``
  (the times are also data arguments), and the ``seq3where`` row runs that text on both
  (both sides count their detections, printed next to the rates). ETALIS processes one event
  at a time: its rate stands beside ours through ``kb.add_many`` (batches of 1,000) and
  through ``kb.add_event`` (one transaction per event), each with its ratio; ``no rule`` is
  our own ingest of the same events without the rule, the ceiling of the batched rate.
* **latency** -- from the start of ``kb.add`` of a completing event to its return, when the
  complex event is stored (same transaction): p50 and p99 over 2,000 completing adds.
* **flat** -- events/s of seq2 (recent) and seq3 (unrestricted, within 5) with 10,000 and
  1,000,000 events already stored: the delta statements search from the new rows through
  the indexes, so the history's size should not matter.

The clock is a ManualClock that reaches each batch's last occurrence time as the batch is
added, with ``max_delay 0`` declared: a live stream whose events arrive as they occur, so
``recent`` decides at the add (the batch's last instant at the next add). The rates are
wall clock and CPU time of the measuring process (the machine is shared: CPU time is the
steadier figure), as ratios against ETALIS measured in the same run.
"""
from __future__ import annotations

import argparse
import math
import os
import random
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from slr_sql.store import quote_identifier  # noqa: E402
from slr_sql import ManualClock  # noqa: E402

# ----------------------------------------------------------------------------- scenarios

SOFT = ["cola", "fanta", "whisky", "water"]


def seq2_events(n: int, t0: float = 0.0) -> list:
    """a(K)^t, b(K)^t alternating; K = (i // 2) mod 100: each b follows its a."""
    return [("a" if i % 2 == 0 else "b", ((i // 2) % 100,), t0 + float(i)) for i in range(n)]


def seq3_events(n: int, t0: float = 0.0, seed: int = 1) -> list:
    """face(F, R, T)^T: 20 faces, reliability 50..100, 10 events a second."""
    rng = random.Random(seed)
    out = []
    for i in range(n):
        t = round(t0 + i * 0.1, 6)
        out.append(("face", (f"f{i % 20}", rng.randint(50, 100), t), t))
    return out


def _yaw(deg: float) -> list:
    h = math.radians(deg) / 2
    return [0.0, 0.0, round(math.sin(h), 9), round(math.cos(h), 9)]


def equals3_events(n: int, t0: float = 0.0, seed: int = 2) -> list:
    """camTF, baseTF and one objRec per instant (n // 3 instants)."""
    rng = random.Random(seed)
    out = []
    for k in range(n // 3):
        t = t0 + float(k)
        cam = ("pose", ([0.1, 0.0, 1.2], _yaw(rng.choice([-30, 0, 30]))))
        base = ("pose", ([round(rng.uniform(0, 5), 3), 0.0, 0.0], _yaw(0)))
        obj = (rng.choice(SOFT), [round(rng.uniform(0.5, 1.5), 3), 0.0, -0.4])
        out.append(("camTF", (cam, t), t))
        out.append(("baseTF", (base, t), t))
        out.append(("objRec", obj + (t,), t))
    return out


RULES = {
    "seq2": ("c(X) <- a(X) seq b(X).", [("a", 1), ("b", 1)], "c"),
    "seq3": ("r(F) <- (face(F, R1, _) seq face(F, R2, _) seq face(F, R3, _)) within 5 "
             "where (R1 > 60, R2 > R1, R3 > R2).", [("face", 3)], "r"),
    # seq3's window written as ETALIS can run it (see ETALIS_RULES): the same text on both
    "seq3where": ("r(F) <- face(F, R1, T1) seq face(F, R2, _) seq face(F, R3, T3) "
                  "where (R1 > 60, R2 > R1, R3 > R2, T3 - T1 =< 5).", [("face", 3)], "r"),
    # the operands in the stream's order (camTF, baseTF, objRec at each instant): `equals`
    # is symmetric for us (SPEC §6), but ETALIS's detects only when its operands arrive in
    # the written order (with objRec first it detects nothing on this stream)
    "equals3": ("softDrink(cola). softDrink(fanta).\n"
                "softDrinkRec(APos) <- camTF(CTF, _) equals baseTF(BTF, _) equals "
                "objRec(O, Pos, _) where (softDrink(O), pos_multiply([Pos, CTF, BTF], APos)).",
                [("objRec", 3), ("camTF", 2), ("baseTF", 2)], "softDrinkRec"),
}
# What ETALIS is given. Its `within` is implemented for a two-part `seq` only, and only with
# its datime/7 time stamps (a three-part sequence within 5 detects nothing, with numeric or
# datime times: checked on ETALIS's src/binarizer.P and compiler.P), so seq3 gets its window
# as a `where` test of the times (the seq3where row runs that same text on both engines). The
# other rules are our text as it is: ETALIS reads `equals` (operands in arrival order, see
# equals3), and `pos_multiply/2` is defined for it in Prolog (POS_MULTIPLY_PL), with
# softDrink/1 as facts.
ETALIS_RULES = {
    "seq2": RULES["seq2"][0],
    "seq3": RULES["seq3where"][0],
    "seq3where": RULES["seq3where"][0],
    "equals3": RULES["equals3"][0].split("\n")[1],
}
EVENTS = {"seq2": seq2_events, "seq3": seq3_events, "seq3where": seq3_events,
          "equals3": equals3_events}


def _term(v) -> str:
    if isinstance(v, tuple) and len(v) == 2 and isinstance(v[0], str) and isinstance(v[1], tuple):
        return f"{v[0]}({', '.join(_term(a) for a in v[1])})"
    if isinstance(v, list):
        return "[" + ", ".join(_term(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(v)
    return str(v)


def _value(v):
    """A scenario value as a Python value for kb.add_event (compound terms as Struct)."""
    if isinstance(v, tuple) and len(v) == 2 and isinstance(v[0], str) and isinstance(v[1], tuple):
        return slr_sql.Struct(v[0], tuple(_value(a) for a in v[1]))
    if isinstance(v, list):
        return [_value(x) for x in v]
    return v


def event_text(ev) -> str:
    name, args, t = ev
    return f"{name}({', '.join(_term(a) for a in args)})^{t!r}"


# ----------------------------------------------------------------------------- slr_sql

def _program(scenario: str, policy: str) -> str:
    rule, types, _ = RULES[scenario]
    delays = " ".join(f":- max_delay({n}/{a}, 0)." for n, a in types)
    return f":- consumption({policy}).\n{delays}\n{rule}\n"


def ours(scenario: str, policy: str, n: int, batch: int, synchronous: str,
         history: int = 0, with_rule: bool = True) -> tuple[float, float, int]:
    """events/s (wall clock, and CPU time of this process) and detections for n events
    (after ``history`` events already stored)."""
    folder = tempfile.mkdtemp(prefix="bench_events_")
    try:
        clock = ManualClock(0.0)
        kb = slr_sql.open(os.path.join(folder, "b.db"), clock=clock, synchronous=synchronous)
        gen = EVENTS[scenario]
        if history:
            old = gen(history)
            for i in range(0, history, 20_000):
                chunk = old[i:i + 20_000]
                clock.set(chunk[-1][2] + 0.5)
                kb.add_many([(name, args, t, t) for name, args, t in chunk])
            start = old[-1][2] + 10.0
        else:
            start = 0.0
        if with_rule:
            kb.load(_program(scenario, policy))
        else:
            kb.declarations.event_types.add(("x", 0))   # no rule: the ingest baseline
        evs = gen(n, start)
        n = len(evs)
        # as Python values, the way a ROS bridge hands them over (ETALIS gets terms too)
        items = [(name, [_value(a) for a in args], t, t) for name, args, t in evs]
        table = RULES[scenario][2]
        before = kb.sql(f"SELECT count(*) FROM {quote_identifier(table)}")[1][0][0] if with_rule else 0
        t0 = time.perf_counter()
        c0 = time.process_time()
        # once a batch is added the clock reaches its last occurrence time: everything
        # before it is complete (max_delay 0); events at that very time may still come in
        # the next batch (the clock never passes an event that has not arrived yet)
        if batch == 1:
            for ev, item in zip(evs, items):
                clock.set(max(clock.now(), ev[2]))
                kb.add_event(*item)
        else:
            for i in range(0, n, batch):
                kb.add_many(items[i:i + batch])
                clock.set(max(clock.now(), evs[min(i + batch, n) - 1][2]))
        clock.set(evs[-1][2] + 1.0)   # the last decisions
        elapsed = time.perf_counter() - t0
        cpu = time.process_time() - c0
        detections = (kb.sql(f"SELECT count(*) FROM {quote_identifier(table)}")[1][0][0] - before
                      if with_rule else 0)
        kb.close()
        return n / elapsed, n / max(cpu, 1e-9), detections
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def latency(n: int, synchronous: str, rule: bool = True,
            checkpoint: str = "auto") -> tuple[float, float, float]:
    """p50, p99, max (ms) of kb.add of a completing b for seq2 under recent (``rule=False``:
    the same adds without the rule, the baseline); ``checkpoint``: the store's option (SQLite's
    own checkpoint inside a commit, or the store's background thread)."""
    folder = tempfile.mkdtemp(prefix="bench_events_")
    try:
        clock = ManualClock(0.0)
        kb = slr_sql.open(os.path.join(folder, "b.db"), clock=clock, synchronous=synchronous,
                          checkpoint=checkpoint)
        kb.load(_program("seq2", "recent") if rule else ":- max_delay(a/1, 0).")
        samples = []
        for ev in seq2_events(2 * n):
            clock.set(ev[2] + 0.5)
            name, args, t = ev
            t0 = time.perf_counter()
            kb.add_event(name, args, t, t)
            if ev[0] == "b":
                samples.append((time.perf_counter() - t0) * 1000)
        if rule:
            assert kb.sql("SELECT count(*) FROM c")[1][0][0] == n
        kb.close()
        samples.sort()
        return (statistics.median(samples), samples[int(0.99 * (len(samples) - 1))],
                samples[-1])
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# ----------------------------------------------------------------------------- ETALIS

POS_MULTIPLY_PL = r"""
bench_rot([QX,QY,QZ,QW], [X,Y,Z], [RX,RY,RZ]) :-
    TX is 2*(QY*Z - QZ*Y), TY is 2*(QZ*X - QX*Z), TZ is 2*(QX*Y - QY*X),
    RX is X + QW*TX + (QY*TZ - QZ*TY),
    RY is Y + QW*TY + (QZ*TX - QX*TZ),
    RZ is Z + QW*TZ + (QX*TY - QY*TX).
bench_apply(pose([TX,TY,TZ], Q), P, [X,Y,Z]) :-
    bench_rot(Q, P, [RX,RY,RZ]), X is RX + TX, Y is RY + TY, Z is RZ + TZ.
bench_pos_multiply(P, A, B, R) :- bench_apply(A, P, P1), bench_apply(B, P1, R).
pos_multiply([P, A, B], R) :- bench_pos_multiply(P, A, B, R).
softDrink(cola). softDrink(fanta).
"""


def etalis(scenario: str, policy: str, n: int, etalis_dir: str,
           timeout: float) -> tuple[float, float, int] | str:
    """events/s (wall, CPU) and detections of ETALIS for the same events, or why not."""
    swipl = shutil.which("swipl")
    if swipl is None:
        return "no swipl"
    folder = Path(tempfile.mkdtemp(prefix="bench_etalis_"))
    try:
        (folder / "rules.event").write_text(ETALIS_RULES[scenario] + "\n")
        facts = []
        for name, args, t in EVENTS[scenario](n):
            args = args if scenario != "seq2" else args
            facts.append(f"ev({name}({', '.join(_term(a) for a in args)}), {t!r}).")
        (folder / "events.pl").write_text("\n".join(facts) + "\n")
        head = RULES[scenario][2]
        arity = {"c": 1, "r": 1, "softDrinkRec": 1}[head]
        template = f"{head}({', '.join('_' * arity)})"
        (folder / "bench.pl").write_text(POS_MULTIPLY_PL + f"""
:- initialization(main, main).
main :-
    ['{etalis_dir}/src/etalis.P'],
    set_etalis_flag(store_fired_events, off),
    set_etalis_flag(event_consumption_policy, {policy}),
    set_etalis_flag(out_of_order, off),
    compile_event_file('{folder}/rules.event'),
    consult('{folder}/events.pl'),
    findall(E-T, ev(E, T), L),
    statistics(walltime, [T0, _]), statistics(cputime, C0),
    forall(member(E-T, L), event(E, [T, T])),
    statistics(walltime, [T1, _]), statistics(cputime, C1),
    aggregate_all(count, fired_event({template}, _), N),
    D is T1 - T0, C is C1 - C0, format("RESULT ~w ~w ~w~n", [D, C, N]).
""")
        try:
            proc = subprocess.run([swipl, "--traditional", "--stack-limit=4g",
                                   str(folder / "bench.pl")], capture_output=True, text=True,
                                  timeout=timeout, cwd=str(folder))
        except subprocess.TimeoutExpired:
            return f"> {timeout:g} s"
        for line in proc.stdout.splitlines():
            if line.startswith("RESULT"):
                _, ms, cpu, count = line.split()
                return (n / max(float(ms) / 1000, 1e-9), n / max(float(cpu), 1e-9),
                        int(count))
        return "failed: " + (proc.stderr.strip().splitlines() or ["?"])[-1]
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# ----------------------------------------------------------------------------- main

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=["throughput", "latency", "flat", "all"], default="all")
    ap.add_argument("--n", type=int, default=10_000, help="events per throughput run")
    ap.add_argument("--n-one", type=int, default=2_000, help="events for kb.add one at a time")
    ap.add_argument("--synchronous", default="FULL")
    ap.add_argument("--etalis-dir", default=os.environ.get("ETALIS_DIR", ""))
    ap.add_argument("--etalis-timeout", type=float, default=600.0)
    ap.add_argument("--history", type=int, nargs="*", default=[10_000, 1_000_000])
    ap.add_argument("--rules", nargs="*", choices=sorted(RULES),
                    default=["seq2", "seq3", "seq3where", "equals3"],
                    help="throughput: only these rules")
    ap.add_argument("--policies", nargs="*", choices=["recent", "unrestricted"],
                    default=["recent", "unrestricted"], help="throughput: only these policies")
    ap.add_argument("--no-one", action="store_true",
                    help="throughput: skip the kb.add one-at-a-time runs")
    args = ap.parse_args()
    etalis_dir = args.etalis_dir
    if etalis_dir and not (Path(etalis_dir) / "src" / "etalis.P").exists():
        etalis_dir = ""
    print(f"# bench_events  n={args.n}  synchronous={args.synchronous}  "
          f"ETALIS={'yes: ' + etalis_dir if etalis_dir else 'no (set ETALIS_DIR)'}")
    if args.part in ("throughput", "all"):
        print("\n| rule | policy | detections (ours / ETALIS) | add_many ev/s (wall / CPU) | "
              "add_many / ETALIS (wall / CPU) | add ev/s (wall / CPU) | add / ETALIS "
              "(wall / CPU) | ETALIS ev/s (wall / CPU) | no rule ev/s (CPU) | add_many / "
              "no rule (CPU) |")
        print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|")
        for scenario in args.rules:
            for policy in args.policies:
                rate, cpu, det = ours(scenario, policy, args.n, 1000, args.synchronous)
                one = (ours(scenario, policy, args.n_one, 1, args.synchronous)
                       if not args.no_one else (math.nan, math.nan, 0))
                base = ours(scenario, policy, args.n, 1000, args.synchronous,
                            with_rule=False)
                if etalis_dir:
                    e = etalis(scenario, policy, args.n, etalis_dir, args.etalis_timeout)
                else:
                    e = "not run"
                if isinstance(e, tuple):
                    erate, ecpu, edet = e
                    cells = (f"{det:,} / {edet:,} | {rate:,.0f} / {cpu:,.0f} | "
                             f"**{rate / erate:.2f}x / {cpu / ecpu:.2f}x** | "
                             f"{one[0]:,.0f} / {one[1]:,.0f} | "
                             f"{one[0] / erate:.3f}x / {one[1] / ecpu:.2f}x | "
                             f"{erate:,.0f} / {ecpu:,.0f}")
                else:
                    cells = (f"{det:,} / - | {rate:,.0f} / {cpu:,.0f} | - | "
                             f"{one[0]:,.0f} / {one[1]:,.0f} | - | {e}")
                print(f"| {scenario} | {policy} | {cells} | {base[1]:,.0f} | "
                      f"{cpu / base[1]:.2f} |", flush=True)
    if args.part in ("latency", "all"):
        print("\n| synchronous | checkpoint | rule | p50 ms | p99 ms | max ms |")
        print("|---|---|---|---:|---:|---:|")
        for sync in ("FULL", "NORMAL"):
            for checkpoint in ("auto", "background"):
                for rule in (True, False):
                    p50, p99, worst = latency(args.n_one, sync, rule, checkpoint)
                    print(f"| {sync} | {checkpoint} | "
                          f"{'seq2 recent' if rule else 'none (baseline)'} | "
                          f"{p50:.3f} | {p99:.3f} | {worst:.3f} |", flush=True)
    if args.part in ("flat", "all"):
        print("\n| rule | policy | stored before | add_many ev/s (wall / CPU) | detections | "
              "no rule ev/s (wall / CPU) |")
        print("|---|---|---:|---:|---:|---:|")
        for scenario, policy in (("seq2", "recent"), ("seq3", "unrestricted")):
            for history in args.history:
                rate, cpu, det = ours(scenario, policy, 20_000, 1000, args.synchronous,
                                      history)
                base, bcpu, _ = ours(scenario, policy, 20_000, 1000, args.synchronous,
                                     history, with_rule=False)
                print(f"| {scenario} | {policy} | {history:,} | {rate:,.0f} / {cpu:,.0f} | "
                      f"{det:,} | {base:,.0f} / {bcpu:,.0f} |", flush=True)


if __name__ == "__main__":
    main()
