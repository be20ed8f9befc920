"""prev/next, buffers and temporal rules against SWI-Prolog, on SQLite and on PostgreSQL.

tests/test_swi_differential.py compares the interpreter with SWI-Prolog on general programs
whose events are only ever read by event goals; prev and next are compared there with the
SQL compiler (tests/test_sql_differential.py) and with a brute-force oracle
(tests/test_event_oracle.py), on SQLite. Here hypothesis draws programs built around them:
temporal rules (``h(K)^T :- prev(p(K, V)^Z, T), ...``) and plain rules over prev, next/2,
next/3, prev over an interval, event goals, comparisons, ``is``, negation, if-then-else,
findall and aggregate_all, with times written as constants, ``inf`` and expressions of bound
variables (``T - 0.5``), stamps as variables, intervals and numbers (integers match stored
floats by value); events of two types, points and intervals with ties, added in a random
arrival order in batches; sometimes a count or time buffer.

SWI-Prolog gets the events the store keeps (after the buffers pruned) as facts in store
order, and prev/next written in Prolog as SPEC §1 defines them (docs/language.md, "prev and
next": the pattern with its call-time bindings and its stamp matched by value, the greatest
end ≤ T, ties all in store order). Every query runs on a SQLite file and on a PostgreSQL
schema, each through the compiled path and through the interpreter (``max_steps``): the
same answers in the same order as SWI-Prolog's, or the same ISO error after the same
answers. Both stores keep the same events.
"""
from __future__ import annotations

import itertools
import os
import tempfile
from pathlib import Path

import pytest
import test_swi_differential as swidiff
from hypothesis import HealthCheck, example, given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock, SLREvaluationError
from slr_sql.terms import format_term

# a longer hunt: SLR_DIFF_EXAMPLES=500 (with HYPOTHESIS_PROFILE=explore for fresh examples)
EXAMPLES = int(os.environ.get("SLR_DIFF_EXAMPLES", "25"))
TYPES = {"p": 2, "q": 1}
# keys of colliding kinds: an atom that reads as a number or as JSON, a string, 1 and 1.0;
# values also -0.0 and 0.0 (equal numbers, two terms; not keys: a cBuffer on SQLite keys
# them as one, docs/buffers.md)
KEYS = ["a", "b", "a", "b", "'1'", '"s"', "1", "1.0", "'[x'"]
VALUES = ["0", "1", "2", "1.5", "1.0", "0", "1", "2", "'1'", "-0.0", "0.0"]
TIME_CONSTANTS = ["0", "1", "1.5", "2", "2.5", "3", "4", "4.0", "inf"]

# prev/next as SPEC §1 defines them, over the facts N_stored(Args.., Start, End) in store
# order; a stamp matches a stored time by value ('$tm'), an unbound one gets the stored float;
# event goals see the stream view (end =< Z of view(Z), set by a query asked at Z), prev and
# next every event
SWI_LIBRARY = r"""
'$tm'(T, T0) :- var(T), !, T = T0.
'$tm'(T, T0) :- number(T), T =:= T0.
p(K, V, S, E) :- p_stored(K, V, S0, E0), view(Z), E0 =< Z, '$tm'(S, S0), '$tm'(E, E0).
q(K, S, E) :- q_stored(K, S0, E0), view(Z), E0 =< Z, '$tm'(S, S0), '$tm'(E, E0).
:- dynamic(view/1).
view(inf).
viewed(Z, G) :- retractall(view(_)), assertz(view(Z)), call(G).
% aggregate_all(max(X), G, M) fails when G has no solution (SWI-Prolog's documentation; its
% library answers M = X instead when X is bound before the call)
aggregate_all_(S, G, _) :- S \= sum(_), \+ G, !, fail.
aggregate_all_(S, G, R) :- aggregate_all(S, G, R).
p_m(K, V, S, E, S0, E0) :- p_stored(K, V, S0, E0), '$tm'(S, S0), '$tm'(E, E0).
q_m(K, S, E, S0, E0) :- q_stored(K, S0, E0), '$tm'(S, S0), '$tm'(E, E0).
prev_p(K, V, S, E, T) :- T1 is T,
    aggregate_all(max(E0), (p_m(K, V, S, E, _, E0), E0 =< T1), M),
    p_m(K, V, S, E, _, E0), E0 =:= M.
prev_q(K, S, E, T) :- T1 is T,
    aggregate_all(max(E0), (q_m(K, S, E, _, E0), E0 =< T1), M),
    q_m(K, S, E, _, E0), E0 =:= M.
prev_iv_p(K, V, S, E, A, B) :- A1 is A, B1 is B,
    aggregate_all(max(E0), (p_m(K, V, S, E, S0, E0), A1 =< S0, E0 =< B1), M),
    p_m(K, V, S, E, S0, E0), A1 =< S0, E0 =:= M.
prev_iv_q(K, S, E, A, B) :- A1 is A, B1 is B,
    aggregate_all(max(E0), (q_m(K, S, E, S0, E0), A1 =< S0, E0 =< B1), M),
    q_m(K, S, E, S0, E0), A1 =< S0, E0 =:= M.
next_p(K, V, S, E, A, B) :- A1 is A, B1 is B,
    aggregate_all(min(S0), (p_m(K, V, S, E, S0, E0), A1 =< S0, E0 =< B1), M),
    p_m(K, V, S, E, S0, E0), S0 =:= M, E0 =< B1.
next_q(K, S, E, A, B) :- A1 is A, B1 is B,
    aggregate_all(min(S0), (q_m(K, S, E, S0, E0), A1 =< S0, E0 =< B1), M),
    q_m(K, S, E, S0, E0), S0 =:= M, E0 =< B1.
"""


# ------------------------------------------------------------------------------ generator

class Drawer:
    """Draws goals as (SLR text, SWI text) pairs over a fixed set of variable names."""

    def __init__(self, draw):
        self.draw = draw

    def pick(self, xs):
        return self.draw(st.sampled_from(xs))

    def chance(self, percent: int) -> bool:
        return self.draw(st.integers(0, 99)) < percent

    def time(self, bound: list[str]) -> str:
        """A time argument: a constant, or an expression of a variable meant to be bound."""
        if bound and self.chance(50):
            v = self.pick(bound)
            return self.pick([v, v, f"{v} + 1", f"{v} - 0.5", f"max({v}, 1)"])
        if self.chance(3):   # no number: the same error as SWI-Prolog's
            return self.pick(["foo", "1 + a", "Unbound"])
        return self.pick(TIME_CONSTANTS)

    def interval(self, bound: list[str]) -> tuple[str, str]:
        """[A, B], mostly with A <= B."""
        if self.chance(15):
            return self.time(bound), self.time(bound)
        if bound and self.chance(50):
            v = self.pick(bound)
            return self.pick([(v, "inf"), (f"{v} - 1", v), (v, f"{v} + 1.5"),
                              (f"{v} - 0.5", f"{v} + 0.5")])
        return self.pick([("0", "inf"), ("1", "inf"), ("1.5", "3"), ("0", "2"), ("2", "4.0"),
                          ("1", "1.5"), ("3", "inf")])

    def pattern(self) -> tuple[str, list[str], list[str]]:
        """An event pattern: (type, data arguments, [start, end] of its stamp) and the SLR
        stamp text."""
        name = self.pick(["p", "p", "q"])
        args = [self.pick(["K", "K", "K", "W", "a", "b", "_", "'1'", "1", '"s"', "1.0"])]
        if name == "p":
            args.append(self.pick(["V"] * 6 + ["_", "_", "0", "1", "1.5", "1.0"]))
        kind = self.draw(st.integers(0, 9))
        if kind < 5:
            stamp, times = "Z", ["Z", "Z"]
        elif kind < 9:
            stamp, times = "[S, E]", ["S", "E"]
        else:
            c = self.pick(["1", "2", "1.0", "3", "1.5"])
            stamp, times = c, [c, c]
        return name, args, times + [stamp]

    def event_goal(self, bound: list[str]) -> tuple[str, str]:
        name, args, (s, e, stamp) = self.pattern()
        slr_atom = f"{name}({', '.join(args)})^{stamp}"
        swi_args = ", ".join(args + [s, e])
        kind = self.draw(st.integers(0, 9))
        if kind < 4:
            t = self.time(bound)
            return f"prev({slr_atom}, {t})", f"prev_{name}({swi_args}, {t})"
        if kind < 5:
            a, b = self.interval(bound)
            return f"prev({slr_atom}, [{a}, {b}])", f"prev_iv_{name}({swi_args}, {a}, {b})"
        if kind < 7:
            a, b = self.interval(bound)
            return f"next({slr_atom}, [{a}, {b}])", f"next_{name}({swi_args}, {a}, {b})"
        if kind < 8:
            a, b = self.interval(bound)
            return f"next({slr_atom}, {a}, {b})", f"next_{name}({swi_args}, {a}, {b})"
        return slr_atom, f"{name}({swi_args})"

    def test(self) -> tuple[str, str]:
        kind = self.draw(st.integers(0, 3))
        x = self.pick(["V", "Z", "S", "E"])
        if kind == 0:
            text = f"D is {x} - {self.pick(['Z', 'S', '1'])}"
        elif kind == 1:
            op = self.pick(["<", ">=", "=:=", "=\\="])
            text = f"{x} {op} {self.pick(['1', '1.5', 'Z', 'V'])}"
        elif kind == 2:
            op = self.pick(["==", "\\=="])
            text = f"K {op} {self.pick(['a', 'W'])}"
        else:
            text = f"{self.pick(['number', 'integer', 'float', 'var'])}({x})"
        return text, text

    def goal(self, bound: list[str], depth: int = 0) -> tuple[str, str]:
        kind = self.draw(st.integers(0, 12)) if depth < 2 else 0
        if kind < 6:
            return self.event_goal(bound)
        if kind < 8:   # a test after the goal that binds its variables
            a, b = self.goal(bound, depth + 1), self.test()
            return f"({a[0]}, {b[0]})", f"({a[1]}, {b[1]})"
        if kind < 9:
            g = self.goal(bound, depth + 1)
            return f"\\+ {g[0]}", f"\\+ {g[1]}"
        if kind < 10:
            c, t, e = (self.goal(bound, depth + 1) for _ in range(3))
            return f"({c[0]} -> {t[0]} ; {e[0]})", f"({c[1]} -> {t[1]} ; {e[1]})"
        if kind < 11:
            a, b = self.goal(bound, depth + 1), self.goal(bound, depth + 1)
            return f"({a[0]} ; {b[0]})", f"({a[1]} ; {b[1]})"
        g = self.goal(bound, depth + 1)
        template = self.pick(["V", "K-Z", "[S, E]", "Z"])
        agg = self.draw(st.integers(0, 2))
        if agg == 0:
            return (f"findall({template}, {g[0]}, L)", f"findall({template}, {g[1]}, L)")
        if agg == 1:
            return (f"aggregate_all(count, {g[0]}, N)", f"aggregate_all(count, {g[1]}, N)")
        spec = self.pick(["max(Z)", "max(V)", "min(V)", "sum(V)", "max(V, K)"])
        return (f"aggregate_all({spec}, {g[0]}, M)", f"aggregate_all_({spec}, {g[1]}, M)")

    def body(self, bound: list[str]) -> tuple[str, str]:
        parts = [self.goal(bound) for _ in range(self.draw(st.integers(1, 2)))]
        if self.chance(30):
            parts.append(self.test())
        return ", ".join(p[0] for p in parts), ", ".join(p[1] for p in parts)


@st.composite
def programs(draw):
    """(SLR program, SWI rules, events, arrival order, batch cuts, buffers, queries)."""
    d = Drawer(draw)
    slr, swi = [], []
    # a temporal rule h(K)^T and a plain rule g(K, T), both reading prev/next at T
    for _ in range(draw(st.integers(1, 2))):
        body = d.body(["T"])
        slr.append(f"h(K)^T :- {body[0]}.")
        swi.append(f"h(K, T, T) :- {body[1]}.")
    if d.chance(60):
        body = d.body(["T"])
        slr.append(f"g(K, T) :- {body[0]}.")
        swi.append(f"g(K, T) :- {body[1]}.")
    else:
        swi.append("g(_, _) :- fail.")
        slr.append("g(_, _) :- fail.")
    events = []
    for _ in range(draw(st.integers(0, 10))):
        name = d.pick(["p", "p", "q"])
        args = [d.pick(KEYS)] + ([d.pick(VALUES)] if name == "p" else [])
        s = float(d.pick([0, 1, 1.5, 2, 3]))
        e = s + float(d.pick([0, 0, 0, 0, 0.5, 1]))
        events.append((name, tuple(args), s, e))
    order = draw(st.permutations(range(len(events))))
    cuts = draw(st.lists(st.integers(0, len(events)), max_size=2))
    buffers = []
    if d.chance(30):
        buffers.append(d.pick(["cBuffer(p(K, _), 1).", "cBuffer(p(_, _), 2).",
                               "cBuffer(q(K), 1).", "tBuffer(p(_, _), 1.5)."]))
    queries = []
    for _ in range(draw(st.integers(1, 3))):
        at = d.pick([None, None, "0", "1", "1.5", "2", "3"])
        kind = draw(st.integers(0, 4))
        t = d.pick(TIME_CONSTANTS[:-1] + ["T"] if d.chance(10) else TIME_CONSTANTS[:-1])
        if kind == 0:
            queries.append((f"h(K)^{t}", f"h(K, {t}, {t})", at))
        elif kind == 1:
            queries.append((f"findall(K, h(K)^{t}, L)", f"findall(K, h(K, {t}, {t}), L)", at))
        elif kind == 2:
            queries.append((f"g(K, {t})", f"g(K, {t})", at))
        else:
            queries.append(d.body([]) + (at,))
    return "\n".join(slr) + "\n", "\n".join(swi) + "\n", events, order, cuts, buffers, queries


# ------------------------------------------------------------------------------ running

def event_text(ev) -> str:
    name, args, s, e = ev
    stamp = repr(s) if s == e else f"[{s!r}, {e!r}]"
    return f"{name}({', '.join(args)})^{stamp}"


def stored_facts(kb) -> list[tuple]:
    """The events the store keeps, type by type in store order (end, start, arrival), as
    fact texts."""
    facts = []
    for name, arity in TYPES.items():
        for args, s, e, seq in kb.store.scan(name, arity):
            values = ", ".join(format_term(a) for a in args)
            facts.append((name, e, s, seq, f"{name}_stored({values}, {s!r}, {e!r})."))
    facts.sort(key=lambda f: f[:4])   # (arrival sequences are compared within a type only)
    return [f[4] for f in facts]


def fill(where: str | None, program: str, events, order, cuts, buffers):
    kb = slr_sql.open(where, clock=ManualClock(2.5))
    try:
        kb.load(program + "\n".join(buffers))
        texts = [event_text(events[i]) for i in order]
        start = 0
        for cut in sorted(set(cuts)) + [len(texts)]:
            if start < cut:
                if cut - start == 1:
                    kb.add(texts[start])
                else:
                    assert kb.add_many(texts[start:cut]) == []
                start = cut
    except BaseException:
        kb.close()
        raise
    return kb


def swi_program(rules: str, facts: list[str], queries) -> str:
    lines = [":- dynamic(p_stored/4).", ":- dynamic(q_stored/3).", *facts, SWI_LIBRARY, rules]
    for qi, (q_slr, q_swi, at) in enumerate(queries):
        names = swidiff.var_names(q_slr)
        lines.append(f"query({qi}, viewed({at or 'inf'}, ({q_swi})), [{', '.join(repr(n) for n in names)}], "
                     f"[{', '.join(names)}]).")
    return "\n".join(lines) + "\n"


def answers(kb, goal: str, names: list[str], interpreted: bool, at: str | None):
    """("answers", [...]) or ("error", formal term, the answers before it) of ``goal``
    asked at ``at`` (no stream view: None)."""
    options: dict = {"max_steps": swidiff.SLR_MAX_STEPS} if interpreted else {}
    if at is not None:
        options["at"] = float(at)
    try:
        got = kb.query(goal, limit=swidiff.MAX_ANSWERS + 1, timeout=swidiff.SLR_TIMEOUT,
                       **options)
        return ("answers", [swidiff.slr_answer(a, names) for a in got])
    except SLREvaluationError as exc:
        error = swidiff.canonical_error(exc.term)
    before = []
    for n in itertools.count(1):
        try:
            got = kb.query(goal, limit=n, timeout=swidiff.SLR_TIMEOUT, **options)
        except SLREvaluationError:
            break
        before = [swidiff.slr_answer(a, names) for a in got]
        if len(got) < n:
            break
    return ("error", error, before)


# SWI-Prolog's library tests the first X of aggregate_all(max(X, W), ..) (and min) with
# number/1 and raises type_error(number, _) when it is unbound; slr_sql raises ISO's
# instantiation_error there, a deviation left alone on purpose (tests/test_swi_builtins.py)
_SWI_UNBOUND_NUMBER = ("c", "type_error", (("a", "number"), ("v", 0)))


def expected(result: dict, names: list[str]):
    answers_ = [swidiff.swi_answer(a, names) for a in result["answers"]]
    if result["error"] is not None:
        error = swidiff.from_swi(result["error"], {})
        if error == _SWI_UNBOUND_NUMBER:
            error = ("a", "instantiation_error")
        return ("error", error, answers_)
    return ("answers", answers_)


def compare(swipl, example_, pg_url: str | None):
    program, rules, events, order, cuts, buffers, queries = example_
    with tempfile.TemporaryDirectory(prefix="slr-prevnext-") as d:
        places = [str(Path(d) / "s.db")] + ([pg_url] if pg_url else [])
        kept = None
        for where in places:
            with fill(where, program, events, order, cuts, buffers) as kb:
                facts = stored_facts(kb)
                if kept is None:
                    kept = facts
                    swi = swipl.run(swi_program(rules, facts, queries))
                assert facts == kept, f"the backends keep different events: {where}"
                if any(r["cyclic"] or r["limit"] or len(r["answers"]) > swidiff.MAX_ANSWERS
                       for r in swi.values()):
                    return
                for qi, (q_slr, _, at) in enumerate(queries):
                    names = swidiff.var_names(q_slr)
                    want = expected(swi[qi], names)
                    context = (f"\nstore: {where.split('?')[0]}\nprogram:\n{program}"
                               f"buffers: {buffers}\nfacts: {facts}\nquery: {q_slr} at {at}")
                    with swidiff.watchdog(30, context):
                        for interpreted in (True, False):
                            got = answers(kb, q_slr, names, interpreted, at)
                            assert got == want, (
                                f"{'interpreter' if interpreted else 'compiled'}: {got}\n"
                                f"SWI-Prolog: {want}{context}\n{kb.explain(q_slr)}")
                        if at is not None and want[0] == "answers":
                            # the synchronized query at the same time, once complete (for
                            # ever: a prev up to inf waits for a history complete that far);
                            # h(K)^T is an event goal too, whose events may still come
                            for name in [f"{n}/{a}" for n, a in TYPES.items()] + ["h/1"]:
                                kb.mark_complete(name, float("inf"))
                            got = [swidiff.slr_answer(a, names) for a in
                                   kb.submit(q_slr, at=float(at)).result(timeout=30)]
                            assert ("answers", got) == want, f"synchronized: {got}{context}"


_SCHEMAS = itertools.count()


@pytest.fixture(scope="module")
def database(postgres_server):
    """One database for the module's examples, a schema each."""
    from conftest import postgres_database
    return postgres_database(postgres_server[1])


@pytest.fixture(scope="module")
def swipl():
    with swidiff.live_swipl() as s:
        yield s


@settings(max_examples=EXAMPLES, deadline=None,
          suppress_health_check=list(HealthCheck))
@given(programs())
@example((   # the event goal inside aggregate_all sees the stream view, prev does not
    "h(K)^T :- prev(p(K, V)^Z, T), aggregate_all(max(Z), p(K, V)^Z, M), V < 1.\n",
    "h(K, T, T) :- prev_p(K, V, Z, Z, T), aggregate_all_(max(Z), p(K, V, Z, Z), M), V < 1.\n",
    [("p", ("a", "0"), 0.0, 0.0), ("p", ("a", "0"), 2.0, 2.0), ("q", ("a",), 0.0, 0.0)],
    [0, 1, 2], [], [], [("h(K)^2", "h(K, 2, 2)", "0"), ("h(K)^2", "h(K, 2, 2)", None)]))
@example((   # a tie of 1 and 1.0: Prolog's max/2 gives 1.0, compiled as interpreted
    "g(K, T) :- aggregate_all(max(V), prev(p(K, V)^[S, E], [0, T]), M).\n",
    "g(K, T) :- aggregate_all_(max(V), prev_iv_p(K, V, S, E, 0, T), M).\n",
    [("p", ("a", "1"), 1.0, 1.0), ("p", ("a", "1.0"), 1.0, 1.0), ("p", ("a", "0"), 1.0, 1.0)],
    [0, 1, 2], [], [], [("g(K, 3)", "g(K, 3)", None), ("aggregate_all(min(V), p(a, V)^_, M)",
                        "aggregate_all_(min(V), p(a, V, Z_, Z_), M)", None)]))
@example((   # -0.0 is below 0 and 0.0 in Prolog's max/2 and min/2 (min gives -0.0, in any order)
    "",
    "",
    [("p", ("a", "0.0"), 1.0, 1.0), ("p", ("a", "-0.0"), 1.0, 1.0), ("p", ("a", "0"), 1.0, 1.0)],
    [0, 1, 2], [], [], [("aggregate_all(min(V), p(a, V)^_, M)",
                         "aggregate_all_(min(V), p(a, V, Z_, Z_), M)", None),
                        ("aggregate_all(max(V), p(a, V)^_, M)",
                         "aggregate_all_(max(V), p(a, V, Z_, Z_), M)", None),
                        ("findall(V, p(a, V)^_, L), min_list(L, M), max_list(L, N)",
                         "findall(V, p(a, V, Z_, Z_), L), min_list(L, M), max_list(L, N)",
                         None)]))
@example((   # 0.0 / 0 is undefined, a float index of nth0 a type error, max(V, W)'s witness
    "",
    "",
    [("p", ("b", "1"), 1.0, 1.0), ("p", ("a", "0.0"), 2.0, 2.0), ("p", ("c", "1.0"), 3.0, 3.0)],
    [0, 1, 2], [], [], [("p(K, V)^_, X is V / 0", "p(K, V, Z_, Z_), X is V / 0", None),
                        ("p(K, V)^_, nth0(V, [x, y], E)", "p(K, V, Z_, Z_), nth0(V, [x, y], E)",
                         None),
                        ("aggregate_all(max(V, K), p(K, V)^_, M)",
                         "aggregate_all_(max(V, K), p(K, V, Z_, Z_), M)", None),
                        ("aggregate_all(min(V, K), p(K, V)^_, M)",
                         "aggregate_all_(min(V, K), p(K, V, Z_, Z_), M)", None)]))
@example((   # max(V, K) of a V no solution binds: ISO's instantiation_error (see expected)
    "",
    "",
    [("p", ("a", "0"), 0.0, 0.0)],
    [0], [], [], [("aggregate_all(max(V, K), prev(p(K, _)^Z, 0), M)",
                   "aggregate_all_(max(V, K), prev_p(K, _, Z, Z, 0), M)", None)]))
def test_prev_next_programs_answer_as_swipl_on_both_backends(swipl, database, example_):
    url = database + ("&" if "?" in database else "?") + f"schema=pn{next(_SCHEMAS)}"
    compare(swipl, example_, url)
