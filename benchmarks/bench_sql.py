"""SQL compiler figures, recorded in benchmarks/README.md.

1. The paper's tea/coffee findall (obj ⨝ usedFor ⨝ prev(seg) ⨝ position, position through
   the tf interpolation/extrapolation rules) over a store of 100,000 events: the compiled
   plan against the interpreter on the same store.
2. prev/next lookups: the compiled plan (kb.query with args, answers decoded) against a
   hand-written SQL statement for the same answer (run on the same connection, rows decoded
   the same way).
3. prev/next SQL forms: the compiler's indexed correlated subqueries against hand-written
   window-function forms (RANK() OVER (PARTITION BY ...)), raw SQL, identical rows asserted.
4. Compile time of a 50-rule program; the plan-cache hit path.

Run:  python benchmarks/bench_sql.py [--events 100000] [--repeat 3]
"""
from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import slr_sql  # noqa: E402
from slr_sql.encoding import decode  # noqa: E402
from slr_sql.planner import compile_goal, plan_for  # noqa: E402
from slr_sql.terms import Atom, Struct, to_python  # noqa: E402

TEA_PROGRAM = (Path(__file__).resolve().parent.parent / "examples" / "tea.slr").read_text(
    encoding="utf-8").split("%% events")[0]
TEA_QUERY = ("findall(object(O, WPos), (obj(O, Type, _Color)^_T1, usedFor(Type, tea), "
             "prev(seg(O, RPos)^T2, Z), position(seg(O, RPos)^T2, WPos)), List)")
TYPES = ["cup", "mug", "glass", "plate", "bowl"]


def pose(rng, z):
    return Struct("pose", ([round(rng.uniform(-1, 1), 3), round(rng.uniform(-1, 1), 3), z],
                           [0.0, 0.0, round(rng.uniform(-0.3, 0.3), 3), 1.0]))


def tea_store(n_events: int, seed: int = 7):
    """A robot run: tf(cam,base) and tf(base,world) at 2 Hz (4 % of the events), objects
    recognized (16 %) and segmented (80 %)."""
    rng = random.Random(seed)
    kb = slr_sql.open()
    kb.load(TEA_PROGRAM)
    events = []
    n_tf = n_events // 25             # 4 %: both transforms
    n_obj = n_events * 4 // 25        # 16 %: obj
    n_seg = n_events - n_tf - n_obj   # 80 %: seg
    steps = n_tf // 2
    for i in range(steps):
        t = i * 0.5
        events.append(("tf", ["cam", "base", pose(rng, 1.0)], t, t))
        events.append(("tf", ["base", "world", pose(rng, 0.0)], t + 0.25, t + 0.25))
    horizon = steps * 0.5
    objects = [f"o{i}" for i in range(2000)]
    kinds = {o: TYPES[i % len(TYPES)] for i, o in enumerate(objects)}
    for _ in range(n_obj):
        o = rng.choice(objects)
        t = round(rng.uniform(0.2, horizon - 0.2), 3)
        events.append(("obj", [o, kinds[o], "red"], t, t))
    for _ in range(n_seg):
        o = rng.choice(objects)
        t = round(rng.uniform(0.2, horizon - 0.2), 3)
        events.append(("seg", [o, [round(rng.uniform(0, 1), 3) for _ in range(3)]], t, t))
    events.sort(key=lambda e: e[3])
    assert kb.add_many(events) == []
    return kb, horizon


def best(fn, repeat):
    times = []
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def best_interleaved(fns, repeat):
    """best() for several functions, run in turn in each round, so a burst of load on the
    machine hits them all alike: [(min time, last result)] in the order of fns."""
    times = [[] for _ in fns]
    outs = [None] * len(fns)
    for _ in range(repeat):
        for i, fn in enumerate(fns):
            t0 = time.perf_counter()
            outs[i] = fn()
            times[i].append(time.perf_counter() - t0)
    return [(min(ts), out) for ts, out in zip(times, outs)]


def bench_tea(n_events, repeat, interpreter=True):
    kb, horizon = tea_store(n_events)
    z = round(horizon * 0.5, 1)
    args = {"Z": z}
    compiled, sql_answers = best(lambda: kb.query(TEA_QUERY, args=args, at=z), repeat)
    assert not hasattr(plan_for(kb, kb.plans.plan(TEA_QUERY, ("Z",)), True), "reason")
    n = len(sql_answers[0]["List"])
    if not interpreter:
        print(f"tea findall over {n_events} events: compiled {compiled * 1000:.1f} ms")
        return kb, horizon
    kb.sql_enabled = False
    interp, interp_answers = best(lambda: kb.query(TEA_QUERY, args=args, at=z), 1)
    kb.sql_enabled = True
    assert sql_answers == interp_answers, "answers differ"
    print(f"tea findall over {n_events} events (z={z}, {n} objects in the list):")
    print(f"  compiled    {compiled * 1000:9.1f} ms")
    print(f"  interpreter {interp * 1000:9.1f} ms")
    print(f"  speed-up    {interp / compiled:9.1f} x")
    return kb, horizon


SUBGOAL_RULE = ("tea_object(O, WPos, Z) :- obj(O, Type, _Color)^_T1, usedFor(Type, tea), "
                "prev(seg(O, RPos)^T2, Z), position(seg(O, RPos)^T2, WPos).")
SUBGOAL_QUERY = "findall(O-W, tea_object(O, W, Z), L), !"


def bench_subgoals(n_events, repeat):
    """A query the compiler leaves to the interpreter (a cut) calling a rule that compiles:
    the interpreter run with compiled sub-goals against the interpreter alone."""
    kb, horizon = tea_store(n_events)
    kb.load(SUBGOAL_RULE)
    z = round(horizon * 0.5, 1)
    args = {"Z": z}
    assert hasattr(plan_for(kb, kb.plans.plan(SUBGOAL_QUERY, ("Z",)), True), "reason")
    call = kb.engine.sql_calls[("tea_object", 3)]
    with_sql, a1 = best(lambda: kb.query(SUBGOAL_QUERY, args=args, at=z), repeat)
    assert call.answered > 0
    kb.sql_enabled = False
    alone, a2 = best(lambda: kb.query(SUBGOAL_QUERY, args=args, at=z), 1)
    kb.sql_enabled = True
    assert a1 == a2, "answers differ"
    print(f"interpreter run calling a compiled rule ({SUBGOAL_QUERY}), {n_events} events, "
          f"{len(a1[0]['L'])} objects:")
    print(f"  with compiled sub-goals {with_sql * 1000:9.1f} ms")
    print(f"  interpreter alone       {alone * 1000:9.1f} ms")
    print(f"  speed-up                {alone / with_sql:9.1f} x")


def bench_prev_next(kb, horizon, repeat, n=2000):
    rng = random.Random(3)
    store = kb.store
    lookups = [(f"o{rng.randrange(2000)}", round(rng.uniform(1, horizon), 2)) for _ in range(n)]
    results = {}
    for label, goal, hand in [
        ("prev", "prev(seg(O, L)^Z, T)",
         "SELECT arg2, t_start FROM seg WHERE arg1 = ? AND t_start = t_end AND t_end = "
         "(SELECT t_end FROM seg WHERE arg1 = ? AND t_start = t_end AND t_end <= ? "
         "ORDER BY t_end DESC LIMIT 1) ORDER BY t_start, seq"),
        ("next", "next(seg(O, L)^Z, [T, inf])",
         "SELECT arg2, t_start FROM seg WHERE arg1 = ? AND t_start = t_end AND t_start = "
         "(SELECT t_start FROM seg WHERE arg1 = ? AND t_start = t_end AND t_start >= ? "
         "ORDER BY t_start LIMIT 1) ORDER BY t_end, seq"),
    ]:
        def compiled():
            out = []
            for o, t in lookups:
                out.append(kb.query(goal, args={"O": o, "T": t}))
            return out

        conn = store._conn

        def handwritten():
            out = []
            for o, t in lookups:
                rows = conn.execute(hand, (o, o, t)).fetchall()
                out.append([{"O": Atom(o), "L": to_python(decode(r[0])), "Z": r[1], "T": t}
                            for r in rows])
            return out

        (c, a1), (h, a2) = best_interleaved([compiled, handwritten], repeat)
        assert a1 == a2, label
        results[label] = (c / n, h / n)
        print(f"{label} lookup (kb.query, args bound) {c / n * 1e6:7.1f} us   hand-written SQL "
              f"{h / n * 1e6:7.1f} us   ratio {c / h:4.2f}")
    # one statement for many lookups: the compiled findall against a hand-written join
    goal = "findall(O-L, (obj(O, cup, _)^T, prev(seg(O, L)^_, T)), Xs)"
    hand = ("SELECT o.arg1, s.arg2 FROM obj o JOIN seg s ON s.arg1 = o.arg1 AND s.t_start = s.t_end "
            "AND s.t_end = (SELECT t_end FROM seg WHERE arg1 = o.arg1 AND t_start = t_end AND "
            "t_end <= o.t_end ORDER BY t_end DESC LIMIT 1) WHERE o.arg2 = 'cup' AND "
            "o.t_start = o.t_end ORDER BY o.t_end, o.t_start, o.seq, s.t_start, s.seq")
    (c, a1), (h, rows) = best_interleaved(
        [lambda: kb.query(goal),
         lambda: [Struct("-", (to_python(decode(a)), to_python(decode(b))))
                  for a, b in conn.execute(hand).fetchall()]], repeat)
    assert a1[0]["Xs"] == rows
    print(f"prev join ({len(rows)} pairs): compiled {c * 1000:.1f} ms   hand-written "
          f"{h * 1000:.1f} ms   ratio {c / h:4.2f}")


def _compiled(kb, goal, bound=()):
    """The SQL the compiler emits for goal: (sql, names of the goal's variables, params(args),
    project(row) -> the encoded values of those variables)."""
    sp = plan_for(kb, kb.plans.plan(goal, tuple(bound)), False)
    assert not hasattr(sp, "reason"), sp
    (recipe,) = sp.recipes
    assert all(how == 0 for _, how, _ in recipe), recipe
    cols = [i for _, _, i in recipe]

    def params(args=None):
        out = dict(sp.params)
        for name, pname in sp.arg_params.items():
            out[pname] = args[name]
        return out

    def project(rows):
        return [tuple(r[i] for i in cols) for r in rows]

    return sp.sql, [name for name, _, _ in recipe], params, project


def bench_window(kb, horizon, repeat, n=2000):
    """prev/next as the compiler's indexed correlated subqueries against hand-written
    window-function forms, raw SQL only (rows fetched, not decoded), same connection. Each
    form must return the same rows in the same order."""
    rng = random.Random(5)
    conn = kb.store._conn
    lookups = [(f"o{rng.randrange(2000)}", round(rng.uniform(1, horizon), 2)) for _ in range(n)]
    table = []

    # (a), (b): one lookup, O and T bound. Window: RANK() over the arg1 partition, the time
    # filter inside the window's subquery, the top rank kept.
    single = [
        ("prev(seg(O, L)^Z, T)", "prev lookup, O and T bound",
         "SELECT :o, arg2, t_start, :t FROM (SELECT arg2, t_start, seq, RANK() OVER "
         "(PARTITION BY arg1 ORDER BY t_end DESC) AS r FROM seg WHERE arg1 = :o AND "
         "t_start = t_end AND t_end <= :t) WHERE r = 1 ORDER BY t_start, seq"),
        ("next(seg(O, L)^Z, [T, inf])", "next lookup, O and T bound",
         "SELECT :o, arg2, t_start, :t FROM (SELECT arg2, t_start, t_end, seq, RANK() OVER "
         "(PARTITION BY arg1 ORDER BY t_start) AS r FROM seg WHERE arg1 = :o AND "
         "t_start = t_end AND t_start >= :t AND t_end <= 1e999) WHERE r = 1 "
         "ORDER BY t_end, seq"),
    ]
    for goal, label, window in single:
        sql, names, params, project = _compiled(kb, goal, ("O", "T"))
        assert names == ["O", "L", "Z", "T"], names
        ps = [params({"O": o, "T": t}) for o, t in lookups]
        pw = [{"o": o, "t": t} for o, t in lookups]
        (s, r1), (w, r2) = best_interleaved(
            [lambda: [conn.execute(sql, p).fetchall() for p in ps],
             lambda: [conn.execute(window, p).fetchall() for p in pw]], repeat)
        assert [project(r) for r in r1] == r2, label
        assert sum(map(len, r1)) > n // 2, label  # most lookups find an event
        table.append((f"{label} (per lookup, {n} lookups)", s / n * 1e6,
                      [("RANK window", w / n * 1e6)], "us"))

    # (c): the batch prev join over every obj(O, cup, _)^T event.
    goal = "obj(O, cup, _)^T, prev(seg(O, L)^_, T)"
    sql, names, params, project = _compiled(kb, goal)
    assert names == ["O", "T", "L"], names
    order = "ORDER BY k0, k1, k2, k3, k4"
    forms = [
        # the arg1-partition window with the time filter inside, correlated to each obj event
        ("RANK window per arg1, correlated",
         "SELECT o.arg1, o.t_start, s.arg2 FROM obj o JOIN seg s ON s.arg1 = o.arg1 AND "
         "s.t_start = s.t_end AND s.t_end = (SELECT w.t_end FROM (SELECT t_end, RANK() OVER "
         "(PARTITION BY arg1 ORDER BY t_end DESC) AS r FROM seg WHERE arg1 = o.arg1 AND "
         "t_start = t_end AND t_end <= o.t_start) AS w WHERE w.r = 1 LIMIT 1) WHERE "
         "o.arg2 = 'cup' AND o.t_start = o.t_end "
         "ORDER BY o.t_end, o.t_start, o.seq, s.t_start, s.seq"),
        # one statement, no correlation: rank each obj event's earlier segs (PARTITION BY the
        # obj event), keep the top rank
        ("RANK window per obj event, one join",
         "SELECT a1, k1, a2 FROM (SELECT o.arg1 AS a1, s.arg2 AS a2, o.t_end AS k0, "
         "o.t_start AS k1, o.seq AS k2, s.t_start AS k3, s.seq AS k4, RANK() OVER "
         "(PARTITION BY o.seq ORDER BY s.t_end DESC) AS r FROM obj o JOIN seg s ON "
         "s.arg1 = o.arg1 AND s.t_start = s.t_end AND s.t_end <= o.t_start WHERE "
         "o.arg2 = 'cup' AND o.t_start = o.t_end) WHERE r = 1 " + order),
        # one pass: obj and seg events merged per object in time order, a running MAX of the
        # seg end times carried to each obj event (segs before objs at equal times)
        ("running MAX window, one pass",
         "WITH ev AS (SELECT arg1, t_start, t_end, seq, 1 AS kind FROM obj WHERE "
         "arg2 = 'cup' AND t_start = t_end UNION ALL SELECT arg1, t_start, t_end, seq, 0 "
         "FROM seg WHERE t_start = t_end), m AS (SELECT arg1, t_start, t_end, seq, kind, "
         "MAX(CASE WHEN kind = 0 THEN t_end END) OVER (PARTITION BY arg1 ORDER BY t_end, "
         "kind ROWS UNBOUNDED PRECEDING) AS last FROM ev) SELECT m.arg1, m.t_start, s.arg2 "
         "FROM m JOIN seg s ON s.arg1 = m.arg1 AND s.t_start = s.t_end AND s.t_end = m.last "
         "WHERE m.kind = 1 ORDER BY m.t_end, m.t_start, m.seq, s.t_start, s.seq"),
    ]
    p = params()
    timed = best_interleaved([lambda: conn.execute(sql, p).fetchall()]
                             + [lambda sql=sql: conn.execute(sql).fetchall() for _, sql in forms],
                             repeat)
    s, r1 = timed[0]
    r1 = project(r1)
    assert r1, "the batch prev join found no pair: nothing to compare"
    others = []
    for (label, _), (w, r2) in zip(forms, timed[1:]):
        assert r1 == r2, label
        others.append((label, w * 1000))
    table.append((f"batch prev join, {len(r1)} obj(O, cup, _)^T events", s * 1000, others, "ms"))

    print("prev/next SQL forms (raw SQL, rows fetched, identical rows asserted):")
    print(f"  {'what':<56} {'form':<36} {'time':>10} {'vs subquery':>11}")
    for what, s, others, unit in table:
        print(f"  {what:<56} {'correlated subquery (compiler)':<36} {s:>7.1f} {unit}")
        for label, w in others:
            print(f"  {'':<56} {label:<36} {w:>7.1f} {unit} {w / s:>10.2f}x")


def bench_compile():
    kb = slr_sql.open()
    rules = []
    for i in range(50):
        if i % 5 == 0:
            rules.append(f"r{i}(O, V) :- prev(seg(O, V)^T, 10), T > 1.0.")
        elif i % 5 == 1:
            rules.append(f"r{i}(O, V) :- obj(O, T, C)^Z, usedFor(T, V), \\+ r{i - 1}(O, _).")
        elif i % 5 == 2:
            rules.append(f"r{i}(O, N) :- findall(X, r{i - 1}(O, X), L), length(L, N).")
        elif i % 5 == 3:
            rules.append(f"r{i}(O, V) :- ( r{i - 3}(O, V) ; r{i - 2}(O, V) ), V \\== none.")
        else:
            rules.append(f"r{i}(O, V) :- seg(O, V)^Z, Z >= 2.0, Z =< 9.0.")
    kb.load("usedFor(cup, tea). usedFor(mug, coffee).\n" + "\n".join(rules))
    kb.add_many(["seg(a, 1)^1", "obj(a, cup, red)^1"])
    plans = [kb.plans.plan(f"r{i}(O, V)", ()) for i in range(50)]
    t0 = time.perf_counter()
    compiled = 0
    for plan in plans:
        try:
            compile_goal(kb, plan, False)
            compiled += 1
        except Exception:
            pass
    total = time.perf_counter() - t0
    print(f"compile a 50-rule program (one plan per predicate, {compiled} compiled): "
          f"{total * 1000:.1f} ms")
    # the cache hit path: kb._plan lookup + cached SqlPlan
    goal = "r4(O, V)"
    kb.query(goal)
    n = 20000
    t0 = time.perf_counter()
    for _ in range(n):
        plan_for(kb, kb.plans.plan(goal, ()), False)
    hit = (time.perf_counter() - t0) / n
    t0 = time.perf_counter()
    for _ in range(2000):
        kb.query(goal)
    whole = (time.perf_counter() - t0) / 2000
    print(f"plan cache hit: {hit * 1e6:.2f} us   (whole kb.query of a small goal: "
          f"{whole * 1e6:.1f} us)")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--events", type=int, default=100_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-interpreter", action="store_true",
                    help="skip the (slow) interpreter run of the tea query")
    ap.add_argument("--subgoal-events", type=int, default=10_000,
                    help="store size of the compiled-sub-goal comparison (the interpreter "
                         "alone grows with the square of the tf history)")
    a = ap.parse_args()
    bench_subgoals(a.subgoal_events, a.repeat)
    kb, horizon = bench_tea(a.events, a.repeat, not a.no_interpreter)
    bench_prev_next(kb, horizon, a.repeat)
    bench_window(kb, horizon, a.repeat)
    bench_compile()


if __name__ == "__main__":
    main()
