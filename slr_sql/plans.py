"""Query plans: a goal parsed and compiled once per (text, names bound from Python), cached,
and instantiated for each call; the plan of the robot's most frequent question (one ``prev``
lookup) is recognised here and answered by one indexed statement.

The facade (``kb.plans``) and the parts that run goals for it (the planner, synchronized
queries, event-rule ``where`` conditions) share one :class:`PlanCache`; a load or
``define`` clears it.

>>> from slr_sql.store import EventStore
>>> cache = PlanCache()
>>> plan = cache.plan("p(X, Y)", ("X",))
>>> plan.names, plan.bind_slots
([('X', 0), ('Y', 1)], {'X': 0})
>>> goal, frame = instantiate(plan, {"X": "a"})
>>> print(goal)
p(a,Y)
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, cast

from .answers import answer_bindings
from .encoding import JSON_STARTS, Unencodable, decode_answer, encode
from .errors import SLRError
from .parser import parse_term
from .program import Slot, Template, build, compile_clause
from .store import EventStore
from .store.checks import shown
from .terms import Atom, String, Struct, Var, deref, from_python, same_float, to_python

__all__ = ["Plan", "PlanCache", "PrevLookup", "BoundPrev", "instantiate", "argument_term",
           "check_goal", "not_a_variable", "python_words"]

# at most this many plans are kept; past it the cache starts again (goals built by string
# splicing would otherwise grow it without bound)
PLAN_CACHE_LIMIT = 1024


@dataclass
class Plan:
    """A parsed, compiled goal cached per (text, names bound from Python)."""

    compiled: Any                 # CompiledClause of the goal
    names: list[tuple[str, int]]  # answer variables: (name, slot index)
    bind_slots: dict[str, int]    # args name -> slot index
    text: str
    lookup: "PrevLookup | None" = None
    bound_lookup: "BoundPrev | None" = None
    # all the goal's named variables (those starting with _ too), in the goal's order: an
    # answer names the unbound variables they hold after them (answers.answer_bindings)
    named: list[tuple[str, int]] | None = None


_ATOMIC = (Atom, String, int, float)


class PrevLookup:
    """Fast path for the robot's most frequent question, a single ``prev(p(..)^Z, T)`` whose
    arguments are constants or distinct variables: one indexed SQL statement, no interpreter.

    Whenever a run-time binding does not fit (a compound or unbound-variable argument value,
    an int/float clash that SQL cannot see), :meth:`run` returns None and the query takes the
    general path, so answers never differ from the interpreter's.
    """

    __slots__ = ("name", "arity", "args", "stamp", "time", "point")

    def __init__(self, name, arity, args, stamp, time, point):
        self.name, self.arity, self.args = name, arity, args
        self.stamp, self.time, self.point = stamp, time, point

    @classmethod
    def recognise(cls, compiled) -> "PrevLookup | None":
        body = compiled.body
        if len(body) != 1 or type(body[0]) is not Template or body[0].name != "prev" \
                or len(body[0].args) != 2:
            return None
        event, time = body[0].args
        if type(event) is not Template or event.name != "^" or type(time) not in (Slot, int, float):
            return None
        atom, stamp = event.args
        if type(stamp) is Slot:
            stamp_slots, point = (stamp.index,), True
        elif type(stamp) is Template and stamp.name == "." and type(stamp.args[0]) is Slot \
                and type(stamp.args[1]) is Template and type(stamp.args[1].args[0]) is Slot \
                and stamp.args[1].args[1] == "[]":
            stamp_slots, point = (stamp.args[0].index, stamp.args[1].args[0].index), False
            if stamp_slots[0] == stamp_slots[1]:
                return None
        else:
            return None
        if type(atom) is Atom:
            name, args = str(atom), ()
        elif type(atom) in (Template, Struct):
            name, args = str(atom.name), atom.args
        else:
            return None
        seen = set(stamp_slots)
        if type(time) is Slot:
            if time.index in seen:
                return None
            seen.add(time.index)
        spec = []
        for a in args:
            if type(a) is Slot:
                if a.index in seen:
                    return None
                seen.add(a.index)
                spec.append(a.index)
            elif type(a) in _ATOMIC:
                spec.append(("const", a))
            else:
                return None
        return cls(name, len(args), tuple(spec), stamp_slots,
                   time.index if type(time) is Slot else ("const", time), point)

    def run(self, store, frame: list, names: list) -> list | None:
        for slot in self.stamp:
            if frame[slot] is not None:
                return None
        t = self.time
        t = t[1] if type(t) is tuple else frame[t]
        t = deref(t)
        if type(t) is not int and type(t) is not float:
            return None
        bound = {}
        free = []
        for i, a in enumerate(self.args):
            if type(a) is tuple:
                bound[i] = a[1]
                continue
            v = frame[a]
            if v is None:
                free.append((i, a))
                continue
            v = deref(v)
            if type(v) not in _ATOMIC or (type(v) is float and v != v):
                return None
            bound[i] = v
        rows = store.latest_at_or_before(self.name, self.arity, bound, t, self.point)
        if rows is None:
            return None
        answers = []
        for values, start, end, _seq in rows:
            for i, v in bound.items():
                # (SQL's = takes 1 for 1.0, and on SQLite -0.0 for 0.0: not Prolog matches)
                if type(values[i]) is not type(v) or (type(v) is float and not v
                                                      and not same_float(values[i], v)):
                    return None
            f = list(frame)
            for i, slot in free:
                f[slot] = values[i]
            if self.point:
                f[self.stamp[0]] = end
            else:
                f[self.stamp[0]] = start
                f[self.stamp[1]] = end
            answers.append(answer_bindings(names, f))
        return answers


class BoundPrev:
    """A :class:`PrevLookup` with the names its ``args`` bind, prepared once per plan (goal
    text and argument names): a call encodes the bound Python values, runs the cached
    statement and builds the answer dicts straight from the rows, with no frame, term or
    unification in between. Anything unusual in a call (a value of another type, a number
    stored as another type) returns None and the caller takes :meth:`PrevLookup.run`'s
    path, so answers never differ.

    What each answer variable shows is sorted out here, once, rather than per row: the row's
    argument columns to decode, its time columns, and the values of the call (a bound
    argument, the time) set before the rows are read.

    >>> from slr_sql.store import EventStore
    >>> store = EventStore(None); store.add_events([("p", ("a", 1), 2.0, 2.0)])
    []
    >>> plan = PlanCache().plan("prev(p(A, X)^Z, T)", ("A", "T"))
    >>> plan.bound_lookup.answer(store, {"A": "a", "T": 3.0})[0]
    [{'A': Atom('a'), 'X': 1, 'Z': 2.0, 'T': 3.0}]
    """

    __slots__ = ("name", "arity", "point", "time", "positions", "sources", "template",
                 "decoded", "columns", "given")

    def __init__(self, name: str, arity: int, point: bool, time: Any,
                 sources: tuple[tuple[int, Any], ...], template: dict[str, Any],
                 decoded: tuple[tuple[str, int], ...], columns: tuple[tuple[str, int], ...],
                 given: tuple[tuple[str, int], ...]):
        self.name, self.arity, self.point, self.time = name, arity, point, time
        # the bound argument positions, in increasing order, and where each value comes
        # from: ("const", term) of the goal text, or the name of an args entry
        self.positions = tuple(position for position, _ in sources)
        self.sources = sources
        self.template = template   # the answer variables in order, none set (dict.fromkeys)
        self.decoded = decoded     # (name, column): a row's argument, decoded
        self.columns = columns     # (name, column): a row's time, as it is
        self.given = given         # (name, k): the k-th bound value, or the time (k = -1)

    @classmethod
    def prepare(cls, lookup: PrevLookup, bind_slots: dict[str, int],
                names: list[tuple[str, int]]) -> "BoundPrev | None":
        by_slot = {slot: name for name, slot in bind_slots.items()}
        if any(slot in by_slot for slot in lookup.stamp):
            return None   # a bound stamp: the general path compares it
        if type(lookup.time) is tuple:
            time: Any = ("const", lookup.time[1])
        elif lookup.time in by_slot:
            time = by_slot[lookup.time]
        else:
            return None   # an unbound time: the general path raises the instantiation error
        sources: list[tuple[int, Any]] = []
        column = {}
        for i, a in enumerate(lookup.args):
            if type(a) is tuple:
                sources.append((i, ("const", a[1])))
            elif a in by_slot:
                sources.append((i, by_slot[a]))
            else:
                column[a] = i
        positions = [position for position, _ in sources]
        stamp = {lookup.stamp[0]: lookup.arity + 1} if lookup.point else {
            lookup.stamp[0]: lookup.arity, lookup.stamp[1]: lookup.arity + 1}
        decoded, columns, given = [], [], []
        for name, slot in names:
            if slot in column:
                decoded.append((name, column[slot]))
            elif slot in stamp:
                columns.append((name, stamp[slot]))
            elif slot == lookup.time:
                given.append((name, -1))
            elif slot in lookup.args:
                given.append((name, positions.index(lookup.args.index(slot))))
            else:
                return None
        return cls(lookup.name, lookup.arity, lookup.point, time, tuple(sources),
                   dict.fromkeys(name for name, _ in names), tuple(decoded), tuple(columns),
                   tuple(given))

    def answer(self, store: EventStore, args: dict) -> tuple[list, tuple | None] | None:
        """The answers and the (program, progress) versions read with them (None when
        nothing matched), or None when the general path must answer."""
        t = self.time
        t = t[1] if type(t) is tuple else args[t]
        if type(t) is not float and type(t) is not int:
            return None
        terms = []
        values = []
        checks: list[tuple[int, type, Any]] = []
        for position, source in self.sources:
            v = source[1] if type(source) is tuple else args[source]
            tv = type(v)
            if tv is str:
                if v.isascii() and v[:1] not in JSON_STARTS:
                    # stored as it is (what encode(Atom(v)) gives); made an atom only if
                    # an answer shows it
                    values.append(v)
                    terms.append(v)
                    continue
                v = Atom(v)
            elif tv is float:
                if v != v:
                    return None
                checks.append((position, float, v))
            elif tv is int:
                checks.append((position, int, v))
            elif tv is not Atom and tv is not String:
                return None
            try:
                values.append(encode(v))
            except Unencodable:
                return None
            terms.append(v)
        rows = store.latest_rows(self.name, self.arity, self.positions, values, t, self.point)
        if not rows:
            return [], None
        for position, kind, value in checks:
            for row in rows:
                x = row[position]
                if type(x) is not kind or (kind is float and not value
                                           and not same_float(cast(float, x), value)):
                    return None   # SQL's 1 = 1.0 (on SQLite -0.0 = 0.0): not a Prolog match
        base = self.template
        if self.given:
            base = base.copy()
            for name, k in self.given:
                if k < 0:
                    base[name] = t
                else:
                    term = terms[k]
                    base[name] = Atom(term) if type(term) is str else to_python(term)
        decoded, columns = self.decoded, self.columns
        answers = []
        for row in rows:
            answer = base.copy()
            for name, i in decoded:
                answer[name] = decode_answer(row[i])
            for name, i in columns:
                answer[name] = row[i]
            answers.append(answer)
        return answers, rows[0][-2:]


class PlanCache:
    """The parsed, compiled plans of goals, per (goal text, names bound from Python).

    ``entries`` is the dict itself, for the facade's one lookup on its fastest path; the
    plans depend on the program (and the Python predicates), so whoever changes those calls
    :meth:`clear`.
    """

    def __init__(self) -> None:
        self.entries: dict[tuple, Plan] = {}

    def clear(self) -> None:
        """Forget every plan (the program or the Python predicates changed)."""
        self.entries.clear()

    def plan(self, goal: str, arg_names: tuple) -> Plan:
        """The plan of ``goal`` with the variables ``arg_names`` bound by the caller, from
        the cache or parsed and compiled now (an :class:`SLRError` for bad text, or an
        argument name that is no variable of the goal).

        >>> PlanCache().plan("q(A), r(A, B)", ()).names
        [('A', 0), ('B', 1)]
        """
        key = (goal, arg_names)
        try:
            plan = self.entries.get(key)
        except TypeError:   # an unhashable goal (a list): no goal text, said as such
            check_goal(goal)
            raise
        if plan is not None:
            return plan
        check_goal(goal)
        term, varnames = parse_term(goal, "<query>")
        compiled = compile_clause((), term)
        slots: dict[str, int] = {}
        # map names to slots through the compiled body: find Slot objects by name
        def walk(t):
            stack = [t]
            while stack:
                x = stack.pop()
                if type(x) is Slot:
                    slots.setdefault(x.name, x.index)
                elif type(x) is Template:
                    stack.extend(x.args)
        for g in compiled.body:
            walk(g)
        for name in arg_names:
            if name not in varnames:
                raise not_a_variable(name, goal)
        names = [(n, slots[n]) for n in varnames if not n.startswith("_") and n in slots]
        plan = Plan(compiled, names, {n: slots[n] for n in arg_names if n in slots}, goal,
                    PrevLookup.recognise(compiled),
                    named=[(n, slots[n]) for n in varnames if n in slots])
        if plan.lookup is not None:
            plan.bound_lookup = BoundPrev.prepare(plan.lookup, plan.bind_slots, names)
        if len(self.entries) > PLAN_CACHE_LIMIT:
            self.entries.clear()
        self.entries[key] = plan
        return plan



def instantiate(plan: Plan, args: dict | None, terms: bool = False) -> tuple[Any, list]:
    """The goal of ``plan`` with ``args`` bound, and its frame. ``terms``: the values
    are ground terms already (decoded stored values), bound as they are; the variables left
    unbound are named as in the goal.

    >>> goal, frame = instantiate(PlanCache().plan("p(X), q(X, Y)", ("X",)), {"X": 1})
    >>> print(goal), frame
    p(1),q(1,Y)
    (None, [1, Var('Y')])
    """
    frame: list = [None] * plan.compiled.nslots
    if args:
        for name, value in args.items():
            slot = plan.bind_slots.get(name)
            if slot is not None:
                frame[slot] = value if terms else argument_term(name, value)
    goals = [build(g, frame) for g in plan.compiled.body]
    if not goals:
        goal: Any = Atom("true")
    else:
        goal = goals[-1]
        for g in reversed(goals[:-1]):
            goal = Struct(",", (g, goal))
    for name, slot in plan.names:
        if frame[slot] is None:
            frame[slot] = Var(name)
    return goal, frame


def not_a_variable(name: Any, goal: str) -> SLRError:
    """The error of ``args`` naming ``name``, which is no variable of ``goal`` (the client
    of ``slr serve`` raises it too for a name that is no str, which names none).

    >>> print(not_a_variable(5, "X = 1"))
    args names 5, which is not a variable of the goal 'X = 1'
    """
    return SLRError(f"args names {shown(name)}, which is not a variable of the goal "
                    f"{shown(goal)}")


def check_goal(goal: Any) -> None:
    """A goal is SLR text, else an :class:`SLRError` (run by the client of ``slr serve``
    too, before sending).

    >>> check_goal(42)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: a goal is SLR text (a str), not int 42
    """
    if not isinstance(goal, str):
        raise SLRError(f"a goal is SLR text (a str), not {type(goal).__name__} {shown(goal)}")


def argument_term(name: str, value: Any) -> Any:
    """The term for ``args[name]`` of a query (a Python value bound to a goal variable), or
    an :class:`SLRError` naming the argument.

    >>> argument_term("X", ["a", 1])
    Struct('.', (Atom('a'), Struct('.', (1, Atom('[]')))))
    """
    try:
        return from_python(value)
    except (TypeError, ValueError) as exc:
        raise SLRError(f"args[{shown(name)}] = {shown(value)} is not a term: "
                       f"{python_words(exc)} (atoms are str, strings slr_sql.String, numbers "
                       f"int or float, lists list, compounds slr_sql.Struct)") from None
    except RecursionError:
        raise SLRError(f"args[{shown(name)}]: the term is nested too deeply") from None


def python_words(exc: BaseException) -> str:
    """The message of a Python exception raised by a conversion, in the user's terms (the
    advice about ``sys.set_int_max_str_digits`` is for Python programmers, not users).

    >>> python_words(ValueError("Exceeds the limit (4300 digits) for integer string conversion:"
    ...                         " value has 5000 digits; use sys.set_int_max_str_digits()"))
    'an integer too long (5000 digits): at most 4300 digits are read'
    """
    text = str(exc)
    digits = re.search(r"limit \((\d+) digits\) for integer string conversion(?:: value has "
                       r"(\d+) digits)?", text)
    if digits:
        has = f" ({digits.group(2)} digits)" if digits.group(2) else ""
        return f"an integer too long{has}: at most {digits.group(1)} digits are read"
    return text.split("; use sys.")[0]
