"""Event rules with the operators nested, against a naive reference; streamed arrivals.

tests/test_cep_differential.py compares the engine with its reference on patterns of two
levels with ``within``, ``where`` and ``cnot`` on top (a ``cnot`` also on a left part), and
``or`` under ``unrestricted`` only. Here the same reference, widened, takes:

* ``within``, ``where`` (comparisons, also of times and differences) and ``cnot`` on any part,
  the part's own bindings in force (SPEC §6, scope);
* ``cnot`` of atoms joined by ``or`` (no event of any of them inside);
* time stamps in patterns: ``p(X)^T`` (point events only), ``p(X)^[S, E]``, ``p(X)^3.0``;
* ``or`` under every policy (``recent``: each alternative on its own; ``chronological``:
  terminators in occurrence order -- end, start, alternative, position, values -- sharing
  the used events), so also alternatives of a single atom;
* patterns three levels deep and streams with duplicated events.

Each example runs in a drawn arrival order (batches, marks, or one add at a time), and in a
second run as a live stream: every event arrives at its end plus a delay of at most the
declared ``max_delay``, the clock moved to each arrival, some types ``in_order`` when their
arrivals are in end order -- both must give the reference's complex events. The live
stream also runs with a tBuffer of the rule's window plus max_delay on every type (what
docs/events.md says loses no detection) and the clock jumping past everything at the end.
Another test puts a rule over the complex events of the first (a hierarchy), with its own
policy. The cases these comparisons found are kept at the end, on both backends.
"""
from __future__ import annotations

import itertools
import os

import pytest
import test_cep_differential as cd
from hypothesis import HealthCheck, given, settings, strategies as st

import slr_sql
from slr_sql import ManualClock

TYPES = {"a": 1, "b": 1, "c": 1, "d": 2}
# a longer hunt: SLR_DIFF_FACTOR=20 runs each test with twenty times its examples
FACTOR = int(os.environ.get("SLR_DIFF_FACTOR", "1"))
SETTINGS = dict(deadline=None, suppress_health_check=list(HealthCheck))

# A pattern is a tree: ("leaf", name, args[, stamp]) with stamp ("pt", T) or ("iv", S, E);
# (op, left, right) for the binary operators and or; ("within", part, seconds);
# ("where", part, [(op, x, y)]) with cd._operand's operands; ("cnot", part, [leaf, ...]).
DECORATIONS = ("within", "where", "cnot")


# ------------------------------------------------------------------------------ reference

def leaves(tree):
    if tree[0] == "leaf":
        return [tree]
    if tree[0] in DECORATIONS:
        return leaves(tree[1])
    return leaves(tree[1]) + leaves(tree[2])


def alternatives(tree):
    if tree[0] == "leaf":
        return [tree]
    if tree[0] == "or":
        return alternatives(tree[1]) + alternatives(tree[2])
    if tree[0] in DECORATIONS:
        return [(tree[0], part) + tree[2:] for part in alternatives(tree[1])]
    return [(tree[0], left, right) for left in alternatives(tree[1])
            for right in alternatives(tree[2])]


def bind_leaf(leaf, ev, bindings):
    """The bindings with the event's arguments and times matched to the leaf's, or None."""
    b = cd._bind(leaf[2], ev[1], bindings)
    stamp = leaf[3] if len(leaf) > 3 else None
    if b is None or stamp is None:
        return b
    if stamp[0] == "pt":
        if ev[2] != ev[3]:
            return None   # ^T: point events only
        pairs = [(stamp[1], ev[3])]
    else:
        pairs = [(stamp[1], ev[2]), (stamp[2], ev[3])]
    b = dict(b)
    for p, v in pairs:   # times match by value
        if isinstance(p, str):
            if p in b and b[p] != v:
                return None
            b[p] = v
        elif p != v:
            return None
    return b


def _own_bindings(part, chosen):
    b: dict = {}
    for leaf, ev in zip(leaves(part), chosen):
        b = bind_leaf(leaf, ev, b)
    return b


def _bound(x, bindings):
    if isinstance(x, tuple):
        return _bound(x[1], bindings) and _bound(x[2], bindings)
    return not isinstance(x, str) or x in bindings


def interval(tree, chosen, k, events):
    """The interval of the sub-tree over the chosen events (leaves numbered from k[0]), or
    None when a relation, a window, a where or a cnot inside it rejects them."""
    kind = tree[0]
    if kind == "leaf":
        ev = chosen[k[0]]
        k[0] += 1
        return (ev[2], ev[3])
    if kind in DECORATIONS:
        first = k[0]
        iv = interval(tree[1], chosen, k, events)
        if iv is None:
            return None
        s, e = iv
        if kind == "within":
            return iv if e - s <= tree[2] else None
        own = _own_bindings(tree[1], chosen[first:k[0]])
        if kind == "where":
            # a variable its part does not bind is unbound there: an instantiation error
            # rejects the candidate, whatever another part binds (SPEC §6, scope)
            ok = all(_bound(x, own) and _bound(y, own)
                     and cd._compare(op, cd._operand(x, own), cd._operand(y, own))
                     for op, x, y in tree[2])
            return iv if ok else None
        for _, name, args in (leaf[:3] for leaf in tree[2]):
            if any(ev[0] == name and s < ev[2] and ev[3] < e
                   and cd._bind(args, ev[1], own) is not None for ev in events):
                return None
        return iv
    left = interval(tree[1], chosen, k, events)
    right = interval(tree[2], chosen, k, events)
    if left is None or right is None:
        return None
    return cd._interval(kind, left, right)


def reference(rule, events):
    """The complex events (head values, start, end) of the rule, as a sorted list."""
    out = []
    used: set = set()
    chrono = []

    def terminator(evs):
        return max(range(len(evs)), key=lambda p: (evs[p][3], evs[p][2], p))

    def newness(ev, i):
        return (ev[3], ev[2], cd._values(ev[1]), i)

    for n, alt in enumerate(alternatives(rule["pattern"])):
        atoms = leaves(alt)
        candidates = [[(i, ev) for i, ev in enumerate(events) if ev[0] == leaf[1]]
                      for leaf in atoms]
        matches = []
        for combo in itertools.product(*candidates):
            idx = [i for i, _ in combo]
            evs = [ev for _, ev in combo]
            if len(set(idx)) < len(idx):
                continue   # one event fills one position
            b: dict | None = {}
            for leaf, ev in zip(atoms, evs):
                b = bind_leaf(leaf, ev, b)
                if b is None:
                    break
            iv = interval(alt, evs, [0], events) if b is not None else None
            if b is not None and iv is not None:
                matches.append((idx, evs, tuple(b[v] for v in rule["head"])) + iv)
        if rule["policy"] == "unrestricted":
            out += [m[2:] for m in matches]
        elif rule["policy"] == "recent":
            best: dict = {}
            for m in matches:
                t = terminator(m[1])
                rank = tuple(newness(m[1][p], m[0][p])
                             for p in reversed(range(len(m[1]))) if p != t)
                if (t, m[0][t]) not in best or rank > best[(t, m[0][t])][0]:
                    best[(t, m[0][t])] = (rank, m)
            out += [m[2:] for _, m in best.values()]
        else:
            for m in matches:
                t = terminator(m[1])
                ev = m[1][t]
                chrono.append(((ev[3], ev[2], n, t, cd._values(ev[1]), m[0][t]), m))
    groups: dict = {}
    for key, m in chrono:
        groups.setdefault(key, []).append(m)
    for key in sorted(groups):
        t = key[3]
        free = [m for m in groups[key] if not used.intersection(m[0])]
        if free:
            m = min(free, key=lambda m: tuple(newness(m[1][p], m[0][p])
                                              for p in range(len(m[1])) if p != t))
            used.update(m[0])
            out.append(m[2:])
    return sorted(out, key=repr)


# ------------------------------------------------------------------------------ rules as text

def _value(a):
    return a if isinstance(a, str) else repr(a)


def leaf_text(leaf):
    text = f"{leaf[1]}({', '.join(_value(a) for a in leaf[2])})" if leaf[2] else leaf[1]
    stamp = leaf[3] if len(leaf) > 3 else None
    if stamp is None:
        return text
    if stamp[0] == "pt":
        return f"{text}^{_value(stamp[1])}"
    return f"{text}^[{_value(stamp[1])}, {_value(stamp[2])}]"


def pattern_text(tree):
    kind = tree[0]
    if kind == "leaf":
        return leaf_text(tree)
    if kind == "cnot":
        negated = " or ".join(leaf_text(leaf) for leaf in tree[2])
        return f"({pattern_text(tree[1])}) cnot " + (
            negated if len(tree[2]) == 1 else f"({negated})")
    if kind == "within":
        return f"({pattern_text(tree[1])}) within {tree[2]}"
    if kind == "where":
        goal = ", ".join(f"{cd._operand_text(x)} {op} {cd._operand_text(y)}"
                         for op, x, y in tree[2])
        return f"({pattern_text(tree[1])}) where ({goal})"
    return f"({pattern_text(tree[1])}) {kind} ({pattern_text(tree[2])})"


def rule_text(rule, name="r"):
    head = f"{name}({', '.join(rule['head'])})" if rule["head"] else name
    return f"{head} <- {pattern_text(rule['pattern'])}."


# ------------------------------------------------------------------------------ generator

def variables(tree):
    """(data variables, time variables) every match binds."""
    kind = tree[0]
    if kind == "leaf":
        stamp = tree[3] if len(tree) > 3 else ()
        return ({a for a in tree[2] if isinstance(a, str) and a != "_"},
                {x for x in stamp[1:] if isinstance(x, str)} if stamp else set())
    if kind in DECORATIONS:
        return variables(tree[1])
    (d1, t1), (d2, t2) = variables(tree[1]), variables(tree[2])
    return (d1 & d2, t1 & t2) if kind == "or" else (d1 | d2, t1 | t2)


OPERATORS = cd.BINARY + ["seq", "and", "and", "par", "starts", "finishes"]


class Generator:
    """Rules and streams drawn from a random source (hypothesis's, so examples replay)."""

    def __init__(self, rnd):
        self.r = rnd
        self.times = itertools.count(1)

    def leaf(self):
        name = self.r.choice(["a", "a", "b", "b", "d"] if self.r.random() < 0.7 else ["a", "b"])
        args = tuple(self.r.choice(["X", "X", "Y", "_", "_", 0, 1]) for _ in range(TYPES[name]))
        x = self.r.random()
        if x < 0.15:
            return ("leaf", name, args, ("pt", f"T{next(self.times)}"))
        if x < 0.25:
            k = next(self.times)
            return ("leaf", name, args, ("iv", f"S{k}", f"E{k}"))
        if x < 0.28:
            return ("leaf", name, args, ("pt", float(self.r.randint(0, 6))))
        return ("leaf", name, args)

    def pattern(self, depth, allow_or):
        if depth == 0 or self.r.randint(0, 3) == 0:
            return self.leaf()
        op = self.r.choice(OPERATORS + (["or", "or"] if allow_or else []))
        return self.decorate((op, self.pattern(depth - 1, allow_or),
                              self.pattern(depth - 1, allow_or)))

    def decorate(self, tree):
        x = self.r.random()
        data, times = variables(tree)
        if x < 0.15:
            return ("within", tree, self.r.choice([0, 1, 2, 3]))
        if x < 0.3 and data | times:
            names = sorted(data | times)
            left = self.r.choice(names)
            if self.r.random() < 0.3:
                left = ("-", self.r.choice(names), self.r.choice(names))
            op = self.r.choice(["<", ">", "=<", ">=", "=:=", "=\\="])
            # (now and then a variable of another part: unbound in this one's scope)
            right = self.r.choice(names + [0, 1, 2] + (["X", "Y"] if self.r.random() < 0.2
                                                      else []))
            return ("where", tree, [(op, left, right)])
        if x < 0.42:
            negated = [("leaf", "c", (self.r.choice(sorted(data) + ["_", 1]),))]
            if self.r.random() < 0.3:
                negated.append(("leaf", "b", (self.r.choice(sorted(data) + ["_", 0]),)))
            return ("cnot", tree, negated)
        return tree

    def rule(self):
        pattern = self.pattern(self.r.choice([2, 2, 3]), self.r.random() < 0.5)
        if pattern[0] == "leaf":
            pattern = ("seq", pattern, self.leaf())
        data, _ = variables(pattern)
        return {"pattern": pattern, "head": [v for v in sorted(data) if self.r.random() < 0.5],
                "policy": self.r.choice(["unrestricted", "unrestricted", "recent",
                                         "chronological"])}

    def stream(self):
        out = []
        for _ in range(self.r.randint(3, 12)):
            name = self.r.choice(["a", "a", "b", "b", "c", "d"])
            args = tuple(self.r.choice([0, 1, 1, 1.0]) for _ in range(TYPES[name]))
            s = float(self.r.randint(0, 5))
            out.append((name, args, s, s + float(self.r.choice([0, 0, 1, 2]))))
        if self.r.random() < 0.2:
            out.append(self.r.choice(out))   # the same event twice
        return out


# ------------------------------------------------------------------------------ running

def _rows(kb, name, arity):
    return sorted(((tuple(args), s, e) for args, s, e, _ in kb.store.scan(name, arity)),
                  key=repr)


def run(text, policy, events, order, cuts, marks, one_by_one, head=("r", 0)):
    """The complex events of ``head`` once ``events`` arrived in ``order`` (batches cut at
    ``cuts``, correct ``fullyUpdated`` marks after each event when ``marks``, or one add at
    a time) and the clock passed everything."""
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(f":- consumption({policy}).\n" + text)
        cd.feed(kb, [events[i] for i in order], cuts, marks, one_by_one)
        clock.set(100.0)
        return _rows(kb, *head)


def run_streamed(rule, events, delays, max_delay, in_order, buffers=""):
    """The complex events when each event arrives at its end + its delay (the clock moved
    there first), with ``max_delay`` declared for every type and ``in_order`` types; the
    clock then jumps past everything."""
    clock = ManualClock(0.0)
    with slr_sql.open(clock=clock) as kb:
        kb.load(f":- consumption({rule['policy']}).\n"
                + "".join(f":- max_delay({n}/{a}, {max_delay}).\n" for n, a in TYPES.items())
                + "".join(f":- in_order({n}/{TYPES[n]}).\n" for n in in_order)
                + rule_text(rule) + "\n" + buffers)
        for i in sorted(range(len(events)), key=lambda i: (events[i][3] + delays[i], i)):
            clock.set(max(clock.now(), events[i][3] + delays[i]))
            kb.add(cd._event_text(events[i]))
        clock.set(100.0)
        return _rows(kb, "r", len(rule["head"]))


def _expected(rows):
    return cd._typed([(tuple(h), s, e) for h, s, e in rows])


@settings(max_examples=60 * FACTOR, **SETTINGS)
@given(st.randoms(use_true_random=False))
def test_nested_operators_in_any_arrival_order_equal_the_reference(rnd):
    gen = Generator(rnd)
    rule, events = gen.rule(), gen.stream()
    order = list(range(len(events)))
    rnd.shuffle(order)
    cuts = [rnd.randint(0, 2 * len(events)) for _ in range(rnd.randint(0, 3))]
    got = run(rule_text(rule), rule["policy"], events, order, cuts, rnd.random() < 0.5,
              rnd.random() < 0.25, ("r", len(rule["head"])))
    assert cd._typed(got) == _expected(reference(rule, events)), (rule_text(rule), events)


@settings(max_examples=30 * FACTOR, **SETTINGS)
@given(st.randoms(use_true_random=False))
def test_a_live_stream_within_max_delay_equals_the_reference(rnd):
    gen = Generator(rnd)
    rule, events = gen.rule(), gen.stream()
    max_delay = rnd.choice([0, 0.5, 1, 2, 3])
    delays = [rnd.choice([0, 0, max_delay / 2, max_delay]) for _ in events]
    arrivals = sorted(range(len(events)), key=lambda i: (events[i][3] + delays[i], i))
    in_order = [name for name in TYPES if rnd.random() < 0.4
                and (lambda ends: ends == sorted(ends))(
                    [events[i][3] for i in arrivals if events[i][0] == name])]
    got = run_streamed(rule, events, delays, max_delay, in_order)
    assert cd._typed(got) == _expected(reference(rule, events)), (
        rule_text(rule), events, delays, max_delay, in_order)


@settings(max_examples=30 * FACTOR, **SETTINGS)
@given(st.randoms(use_true_random=False))
def test_time_buffers_covering_window_and_delay_lose_no_detection(rnd):
    # docs/events.md: a tBuffer of the rule's window plus max_delay on every type it reads
    # keeps what a late terminator needs, and what a waiting decision needs when it is made
    gen = Generator(rnd)
    window = rnd.choice([1, 2, 3])
    rule = gen.rule()
    rule["pattern"] = ("within", rule["pattern"], window)
    events = gen.stream()
    max_delay = rnd.choice([0, 0.5, 1, 2])
    delays = [rnd.choice([0, 0, max_delay / 2, max_delay]) for _ in events]
    buffers = "".join(f"tBuffer({name}({', '.join(['_'] * n)}), {window + max_delay}).\n"
                      for name, n in TYPES.items() if name != "r")
    got = run_streamed(rule, events, delays, max_delay, (), buffers)
    assert cd._typed(got) == _expected(reference(rule, events)), (
        rule_text(rule), events, delays, max_delay)


@settings(max_examples=30 * FACTOR, **SETTINGS)
@given(st.randoms(use_true_random=False))
def test_a_rule_over_complex_events_equals_the_reference(rnd):
    gen = Generator(rnd)
    rule, events = gen.rule(), gen.stream()
    arity = len(rule["head"])
    TYPES["r"] = arity
    r_atom = ("leaf", "r", tuple(rnd.choice(["X", "_", 1]) if i == 0 else "_"
                                  for i in range(arity)))
    other = gen.leaf()
    op = rnd.choice(["seq", "and", "par", "during", "seq", "starts", "finishes"])
    pattern = (op, r_atom, other) if rnd.random() < 0.5 else (op, other, r_atom)
    if rnd.random() < 0.2:
        pattern = ("cnot", pattern, [("leaf", "c", ("_",))])
    top = {"pattern": pattern, "head": sorted(variables(pattern)[0]),
           "policy": rnd.choice(["unrestricted", "recent", "chronological"])}
    derived = [("r", h, s, e) for h, s, e in reference(rule, events)]
    text = (rule_text(rule) + f"\n:- consumption(top/{len(top['head'])}, {top['policy']}).\n"
            + rule_text(top, "top"))
    order = list(range(len(events)))
    rnd.shuffle(order)
    got = run(text, rule["policy"], events, order, [rnd.randint(0, len(events))],
              rnd.random() < 0.5, False, ("top", len(top["head"])))
    assert cd._typed(got) == _expected(reference(top, events + derived)), (text, events)


# ------------------------------------------------------------------------------ found here

def another_store(backend: str, k: int) -> str:
    """The ``k``-th store of a test beside ``backend``'s: a schema of its own on PostgreSQL,
    a file beside it on SQLite."""
    if backend.startswith("postgresql"):
        return backend + ("&" if "?" in backend else "?") + f"schema=s{k}"
    return f"{backend}.{k}"


@pytest.mark.parametrize("policy", ["unrestricted", "recent", "chronological"])
def test_a_one_atom_pattern_with_cnot_is_blocked_by_an_event_inside(backend, policy):
    # recent chose each terminator's partners in nested sub-queries, which also checked the
    # negations: a pattern of one atom has no partner, and its cnot was not checked at all
    # (whether decided when the clock moved, streamed with max_delay, or in_order at once)
    stores = itertools.count()

    def derived(declarations, steps):
        where = another_store(backend, next(stores))
        clock = ManualClock(0.0)
        with slr_sql.open(where, clock=clock) as kb:
            kb.load(f":- consumption({policy}).\n{declarations}r(X) <- a(X) cnot c(_).")
            for step in steps:
                if isinstance(step, float):
                    clock.set(step)
                else:
                    kb.add_many(step)
            clock.set(100.0)
            return _rows(kb, "r", 1)

    # c(1)^4 lies inside a(1)^[3,5]: only a(2) derives
    only_a2 = [((2,), 6.0, 8.0)]
    assert derived("", [["c(1)^4", "a(1)^[3,5]", "a(2)^[6,8]"]]) == only_a2
    assert derived(":- max_delay(a/1, 1).\n:- max_delay(c/1, 1).\n",
                   [4.0, ["c(1)^4"], 5.0, ["a(1)^[3,5]"], 8.0, ["a(2)^[6,8]"]]) == only_a2
    ordered = derived(":- in_order(a/1).\n:- in_order(c/1).\n",
                      [["c(1)^4"], ["a(1)^[3,5]"], ["c(2)^9", "a(2)^[6,8]"]])
    assert ordered == only_a2


def test_a_where_inside_a_pattern_sees_only_its_parts_bindings(backend):
    # a where goal on a part ran on the whole match's bindings: another part's Y was bound
    # in `(a(X) where X < Y) seq b(Y)`; the goal runs with its part's bindings (SPEC §6,
    # scope, as cnot does), and what it binds still reaches the rest of the pattern
    clock = ManualClock(0.0)
    with slr_sql.open(backend, clock=clock) as kb:
        kb.load("lt <- (a(X) where X < Y) seq b(Y).\n"
                "none_of(X) <- (a(X) where \\+ c(Y)^_) seq b(Y).\n"
                "next_one(Y) <- (a(X) where Y is X + 1) seq b(Y).\n"
                "both_parts <- ((a(X) seq b(Y)) where X < Y) seq d(_, _).\n")
        kb.add_many(["c(5)^0.5", "a(1)^1", "b(2)^2", "b(1)^3", "d(0, 0)^4"])
        clock.set(100.0)
        assert _rows(kb, "lt", 0) == []   # (Y unbound there: an instantiation error)
        assert _rows(kb, "none_of", 1) == []   # (any c blocks: Y is free there)
        assert _rows(kb, "next_one", 1) == [((2,), 1.0, 2.0)]
        assert _rows(kb, "both_parts", 0) == [((), 1.0, 4.0)]
        errors = {r["head"]: (r["errors"], r["last_error"]) for r in kb.event_rules()}
        assert errors["lt/0"] == (2, "error(instantiation_error,_)")


@pytest.mark.parametrize("policy", ["recent", "chronological"])
def test_a_clock_jump_makes_the_decisions_it_allows_before_time_buffers_prune(backend, policy):
    # a decision due at 4 (max_delay 0) waited for the clock; a jump to 100 pruned its
    # events (tBuffer 3 s, the window plus max_delay as docs/events.md advises) before the
    # decision was made, so the match was lost: a ManualClock set far ahead, or a
    # StreamClock at a gap of a recording; moved in small steps, the same clock found it
    stores = itertools.count()

    def derived(clock, steps):
        where = another_store(backend, next(stores))
        with slr_sql.open(where, clock=clock) as kb:
            kb.load(f":- consumption({policy}).\n"
                    ":- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n:- max_delay(x/0, 0).\n"
                    "tBuffer(a(_), 3).\ntBuffer(b(_), 3).\nr(X) <- (b(X) seq a(X)) within 3.")
            for step in steps:
                if isinstance(step, float):
                    clock.set(step)
                else:
                    kb.add(step)
            return _rows(kb, "r", 1)

    found = [((1,), 2.0, 4.0)]
    assert derived(ManualClock(0.0), [2.0, "b(1)^2", 4.0, "a(1)^4", 100.0]) == found
    assert derived(slr_sql.StreamClock(), ["b(1)^2", "a(1)^4", "x^100"]) == found
