"""Query plans: SQL when the goal compiles exactly, the interpreter otherwise (docs/sql.md).

For a query goal the planner

1. walks the goal and the rules it calls with :class:`slr_sql.sqlcompile.Compiler`, which
   tracks the *binding mode* of every goal (which arguments are known when it is reached,
   left to right, per alternative) and emits one branch per path;
2. decides: a :class:`SqlPlan` (one prepared statement, parameters bound) or the interpreter,
   with the reason of the fallback (cut, recursion, call/N on an unknown goal, a builtin
   with no SQL form, a Python predicate in a non-functional mode, ...);
3. caches the decision on the kb's parsed plan (per goal text, names bound from Python and
   whether a stream view ``at`` is given), so it is reused across queries; loading a program
   or defining a Python predicate drops the parsed plans and so these too.

A compiled statement that meets, at run time, anything the interpreter would treat
differently (a type error in arithmetic, a non-ground result of a builtin) raises inside
SQLite; the query is then answered by the interpreter (which raises the proper error).

The inspection side: every ground-fact predicate is materialized as ``slr_facts_<n>_<name>``
and every non-temporal derived predicate that compiles to plain SQL (no slr_ functions) gets
a view of its name (docs/sql.md).
"""
from __future__ import annotations

import weakref
from typing import Any

from . import sqlcompile

from .encoding import Unencodable, decode, encode
from .encoding import load_json, term_from_json
from .answers import AnswerVariables
from .plans import instantiate
from .program import Slot, Template, build
from .sqlcompile import Col, ColRef, Compiler, Fallback, Part, resolve
from .errors import SLRBusy
from .store import DatabaseError
from .store.dialect import Unprintable, short_text
from .terms import Atom, Struct, Var, deref, from_python, int_text, make_list, \
    to_python

__all__ = ["SqlPlan", "plan_for", "try_sql", "explain", "attach", "refresh", "Fallback",
           "compile_goal", "CompiledCall", "compiled_calls"]


# ---------------------------------------------------------------------- per-kb state

class _Ctx:
    """What the compiler needs of a knowledge base."""

    def __init__(self, kb, state: "_State"):
        self.kb = kb
        self.program = kb.program
        self.engine = kb.engine
        self.library = kb.engine.library
        self.det = kb.engine.det
        self.nondet = kb.engine.nondet
        self.python_preds = kb.engine.python_preds
        self.dialect = kb.store.dialect
        self.state = state

    def event_table(self, name, n):
        return self.kb.store.event_table_sql(name, n)

    def fact_table(self, name, n):
        return self.state.fact_tables(self.kb).get((name, n))


class _State:
    def __init__(self, kb):
        self.kb = weakref.ref(kb)
        self.facts_program = None
        self.facts: dict = {}
        # the event types whose tables the views of kb's program wait for (None: not known
        # in this connection, whose program another connection loaded)
        self.view_missing: set | None = None
        # the (lower case) names views of a program may take, and that program
        self.view_names: set = set()
        self.view_names_program = None

    def fact_tables(self, kb) -> dict:
        """The fact tables of kb's program. They are written by whoever changes the stored
        program, in the same transaction, for the union of the stored programs; a kb whose
        program is that union (same version) only reads their names. A store whose tables
        were built for another version (written before versions existed) gets them
        rebuilt here, if the program is still the stored one when the write lock is ours."""
        program = kb.program
        if self.facts_program is not program:
            store = kb.store
            if store.facts_version() == kb.loader.version:
                self.facts = store.fact_tables_for(fact_rows(program))
            else:
                self.facts = {}
                try:
                    with store.transaction():
                        if store.program_version() == kb.loader.version:
                            self.facts = store.replace_fact_tables(
                                fact_rows(program), version=kb.loader.version)
                            self.facts_program = program
                            refresh_views(kb)   # views of the old tables go with them
                except SLRBusy:
                    pass   # compile without fact tables (facts unfolded) until next time
            self.facts_program = program
        return self.facts

    def materialize(self, kb) -> None:
        """Rebuild the fact tables for kb's program (inside its load transaction)."""
        self.facts = kb.store.replace_fact_tables(fact_rows(kb.program),
                                                  version=kb.loader.version)
        self.facts_program = kb.program


def fact_rows(program) -> dict:
    """``{(name, arity): [encoded rows]}`` for every predicate made of ground facts only.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> fact_rows(kb.program)  # in_kitchen/1 has a rule: not a fact table
    {('color', 2): [('cup1', 'red')]}
    """
    out = {}
    for key, pred in program.preds.items():
        if not pred.clauses or key[1] == 0:
            continue
        rows = []
        for c in pred.clauses:
            if c.body or c.nslots or any(type(h) in (Slot, Template) for h in c.head):
                rows = None
                break
            try:
                rows.append(tuple(encode(h) for h in c.head))
            except Unencodable:
                rows = None
                break
        if rows is not None:
            out[key] = rows
    return out


def state_of(kb) -> _State:
    """The planner's state of ``kb`` (its fact tables and views), made on first use.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> st = state_of(kb); st is state_of(kb), sorted(st.facts)
    (True, [('color', 2)])
    """
    st = kb.attached_state.get("planner")
    if st is None:
        st = kb.attached_state["planner"] = _State(kb)
    return st


def attach(kb) -> None:
    """Install the SQL side on a knowledge base: functions, fact tables and views on load.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> sorted(kb.engine.sql_calls)  # open() called attach(kb): in_kitchen/1 is called through SQL
    [('in_kitchen', 1)]
    >>> kb.store.execute("SELECT * FROM in_kitchen")  # and the load made its view
    [('r1',)]
    """
    state_of(kb)
    kb.engine.sql_calls = compiled_calls(kb)   # the program restored from the file
    kb.load_listeners.append(refresh)
    kb.reload_listeners.append(reloaded)
    ref = weakref.ref(kb)

    def on_tables(new):
        # once per batch of new tables (an add of several new types), in its transaction
        k = ref()
        if k is None:
            return
        st = state_of(k)
        missing = st.view_missing
        if missing is None or any((name, arity) in missing for name, arity, _ in new):
            try:
                k.loader.ensure_current()   # (inside the add's transaction: the stored program)
                if k.program.preds:
                    refresh_views(k)
                else:
                    st.view_missing = set()   # no predicates, no views
            except Exception:
                pass

    def view_names():
        # the names the views of the program in force may take (a new table named one of
        # them while a refresh is pending is named after it: as without batches)
        k = ref()
        if k is None:
            return ()
        st = state_of(k)
        program = k.program
        if st.view_names_program is not program:
            view_name = k.store.view_name
            st.view_names = {view_name(name).lower() for name, _ in program.preds}
            st.view_names_program = program
        return st.view_names

    kb.store.tables_created_hooks.append(on_tables)
    kb.store.batch_names.append(view_names)


def reloaded(kb) -> None:
    """Reload listener: the program was re-read from the file (another connection changed
    it); its fact tables and views were written by that connection: only choose again the
    predicates an interpreter run calls through SQL.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> kb.engine.sql_calls = {}; reloaded(kb); sorted(kb.engine.sql_calls)
    [('in_kitchen', 1)]
    """
    state_of(kb).view_missing = None   # that connection's views, not known here
    kb.engine.sql_calls = compiled_calls(kb)


def refresh(kb) -> None:
    """Load listener: materialize the fact tables, rebuild the views (in the load
    transaction) and choose the predicates an interpreter run calls through SQL.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> kb.engine.sql_calls = {}; refresh(kb); sorted(kb.engine.sql_calls)
    [('in_kitchen', 1)]
    >>> kb.store.execute("SELECT * FROM color")
    [('cup1', 'red')]
    """
    st = state_of(kb)
    st.materialize(kb)
    refresh_views(kb)
    kb.engine.sql_calls = compiled_calls(kb)


# ---------------------------------------------------------------------- plans

class SqlPlan:
    """One compiled query: the statement, its constant parameters and how rows become
    answers."""

    def __init__(self, sql, params, arg_params, has_at, recipes, missing, sites, modes, goal,
                 time_sites=(), guards=(), has_robot=False, start_ordered=(), read_types=(),
                 key_forms=()):
        self.sql = sql
        # event types read in start order: their indexes made sure of before each run
        # (built on first need; once built, an attribute read per run)
        self.start_ordered = tuple(sorted(start_ordered))
        # the event types it reads: before the first run, the start-ordered indexes its
        # plan would use are built; again after a rollback that may have taken a build
        # back (the store's count of those when last done, None before)
        self.read_types = tuple(sorted(read_types))
        self.prepared_at: int | None = None
        self.has_robot = has_robot        # restricted to one robot's events (:robot)
        self.guards = guards              # statements run first: goals that may raise
        # arguments from Python the statement uses as numbers: a non-number goes to the
        # interpreter (which raises, or not, exactly when a goal reaches it)
        self.num_args = frozenset(sqlcompile.NUM_ARG.findall(
            (sql or "") + "".join(guards))) & frozenset(arg_params.values())
        # arguments from Python matched with stored times: one beyond 64 bits goes to the
        # interpreter (SQL holds it as text, the interpreter compares it by value)
        self.time_args = frozenset(sqlcompile.TIME_ARG.findall(
            (sql or "") + "".join(guards))) & frozenset(arg_params.values())
        self.time_sites = time_sites      # ((name, n), time parameter or SQL) per prev/next
        self.params = params
        self.arg_params = arg_params      # variable name -> parameter name
        # arguments compared with an event's first argument on PostgreSQL: (parameter,
        # the statement's condition for a short text, for a long one; Compiler.key_forms)
        self.key_forms = tuple(key_forms)
        self._long_texts: dict[frozenset, tuple] = {}
        self.has_at = has_at
        self.recipes = recipes            # per branch: [(name, how, data)]
        self.missing = missing            # event types without a table when compiled
        self.sites = sites                # keep the function call sites alive
        self.modes = modes
        self.goal = goal

    def stale(self, store) -> bool:
        return any(store.event_table_sql(n, a) is not None for n, a in self.missing)

    def _rows(self, kb, values: dict, at, limit, deadline, robot=None,
              instructions=None, stop=None) -> list:
        """Bind the parameters (``values``: answer variable name -> term), run the guards,
        then the statement. ``stop``: the query's (``Solutions.stop()`` ends the statement
        under way)."""
        params = self.params
        dialect = kb.store.dialect
        if self.arg_params or self.has_at or self.has_robot:
            params = dict(params)
            if self.has_robot:
                params["robot"] = robot
            for name, pname in self.arg_params.items():
                params[pname] = encode(values[name])
                if pname in self.time_args and type(params[pname]) is str \
                        and type(values[name]) is int:
                    raise TypeError(f"argument :{pname} is a time beyond 64 bits")
            if self.has_at:
                params["at"] = float(at)
        for name in self.num_args:
            t = type(params[name])
            if t is not int and t is not float:
                raise TypeError(f"argument :{name} is not a number")  # -> the interpreter
        to_column = dialect.to_column
        if to_column is not None and self.arg_params:
            # (after the checks above, which read the encoded values)
            for pname in self.arg_params.values():
                params[pname] = to_column(params[pname])
        for key in self.start_ordered:
            kb.store.ensure_start_order(*key)
        undone = kb.store.start_order_builds_undone
        if self.read_types and self.prepared_at != undone:
            for sql in (self.sql, *self.guards):
                if sql is not None:
                    # (where the planner cannot be asked, only next's types, above)
                    kb.store.prepare_start_order(sql, self.read_types, build_if_unsure=False)
            self.prepared_at = undone
        sql, guards = self.sql, self.guards
        if self.key_forms:
            long = frozenset(p for p, _, _ in self.key_forms if short_text(params[p]) is None)
            if long:
                sql, guards = self._with_long_texts(long)
        for guard in guards:
            kb.store.run_compiled(guard, params, None, deadline, may_fall_back=True,
                                  instructions=instructions, stop=stop)
        if sql is None:
            return []
        rows = kb.store.run_compiled(sql, params, limit, deadline, may_fall_back=True,
                                     instructions=instructions, stop=stop)
        from_column = dialect.from_column
        if from_column is not None:   # answer columns are the columns' text there
            rows = [(row[0],) + tuple([from_column(v) for v in row[1:]]) for row in rows]
        return rows

    def _with_long_texts(self, long: frozenset) -> tuple:
        """The statement and guards for the arguments ``long`` bound to long texts: their
        equalities with a first argument in the form that reads its slr_key's index."""
        texts = self._long_texts.get(long)
        if texts is None:
            def swap(text):
                for pname, short_form, long_form in self.key_forms:
                    if pname in long and text is not None:
                        text = text.replace(short_form, long_form)
                return text
            texts = self._long_texts[long] = (swap(self.sql), tuple(map(swap, self.guards)))
        return texts

    def run(self, kb, args, at, limit, deadline=None, robot=None, stop=None):
        values = {name: from_python(args[name]) for name in self.arg_params}
        rows = self._rows(kb, values, at, limit, deadline, robot, stop=stop)
        recipes = self.recipes
        out = []
        for row in rows:
            answer = {}
            varmap: dict = {}
            for name, how, data in recipes[row[0]]:
                if how == 0:
                    answer[name] = _value(row[data])
                elif how == 1:
                    answer[name] = to_python(data)
                elif how == 2:
                    answer[name] = to_python(_inst_row(data, row, varmap))
            out.append(answer)
        return out

    def history_times(self, at) -> list | None:
        """``[((name, n), time)]``: up to when each prev/next of the statement reads its
        history; None when a time is only known row by row (computed from the data)."""
        out = []
        for key, hi in self.time_sites:
            if hi == ":at":
                t = at
            elif hi[:2] == ":c" and hi[1:] in self.params:
                t = self.params[hi[1:]]
            else:
                return None
            out.append((key, t))
        return out

    def term_rows(self, kb, bound: dict, at, deadline=None, instructions=None,
                  stop=None) -> list:
        """The answers as terms, for an interpreter that called the goal: per row, the
        ``(name, term)`` pairs of the answer variables that are bound (fresh variables for
        the unbound parts of non-ground answers, shared within the row). ``instructions``:
        each statement's budget of SQLite instructions (``run_compiled``); ``stop``: the
        interpreter's (its query's ``Solutions.stop()``)."""
        recipes = self.recipes
        out = []
        for row in self._rows(kb, bound, at, None, deadline, instructions=instructions,
                              stop=stop):
            varmap: dict = {}
            vals = []
            for name, how, data in recipes[row[0]]:
                if how == 0:
                    vals.append((name, decode(row[data])))
                elif how == 1:
                    vals.append((name, data))
                else:
                    vals.append((name, _inst_row(data, row, varmap)))
            out.append(vals)
        return out


def _value(v):
    """``to_python(decode(v))``, with a shortcut for numbers, atoms and JSON lists."""
    tv = type(v)
    if tv is float or tv is int:
        return v
    if tv is str:
        if not v or v[0] not in '[{"':
            return Atom(v)
        if v[0] == "[":
            return _py_list(load_json(v))
    return to_python(decode(v))


def _py_list(items):
    out = []
    for x in items:
        tx = type(x)
        if tx is str:
            out.append(Atom(x))
        elif tx is float or tx is int:
            out.append(x)
        elif tx is list:
            out.append(_py_list(x))
        else:
            out.append(_py_term(x))
    return out


def _py_term(x):
    """``to_python(term_from_json(x))`` for one JSON element, compounds without the round trip."""
    tx = type(x)
    if tx is str:
        return Atom(x)
    if tx is float or tx is int:
        return x
    if tx is list:
        return _py_list(x)
    if tx is dict and len(x) == 1:
        ((key, val),) = x.items()
        if type(val) is list and key != ".":
            return Struct(Atom(key), tuple([_py_term(a) for a in val]))
    return to_python(term_from_json(x))


def _inst_row(t, row, varmap):
    tt = type(t)
    if tt is ColRef:
        return decode(row[t.i])
    if tt is Var:
        v = varmap.get(id(t))
        if v is None:
            v = varmap[id(t)] = Var(t.name)
        return v
    if tt is Struct:
        return Struct(t.name, tuple(_inst_row(a, row, varmap) for a in t.args))
    return t


def _conj(goals: list) -> Any:
    if not goals:
        return Atom("true")
    goal = goals[-1]
    for g in reversed(goals[:-1]):
        goal = Struct(",", (g, goal))
    return goal


def compile_goal(kb, plan, has_at: bool, robot: bool = False) -> SqlPlan:
    """Compile a parsed query plan (kb._plan) to SQL; raises :class:`Fallback`. ``robot``:
    every event row read must be the robot's of the parameter ``:robot``.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> sql_plan = compile_goal(kb, kb.plans.plan("in_kitchen(R)", ()), False)
    >>> sql_plan.run(kb, {}, None, None, None, None)
    [{'R': Atom('r1')}]
    """
    ctx = _Ctx(kb, state_of(kb))
    comp = Compiler(ctx, has_at, robot=robot)
    frame: list = [None] * plan.compiled.nslots
    arg_params = {}
    for name, slot in plan.bind_slots.items():
        pname = f"a{slot}"
        frame[slot] = Col(f":{pname}")
        arg_params[name] = pname
    for name, slot in plan.names:
        if frame[slot] is None:
            frame[slot] = Var(name)
    goal = _conj([build(g, frame) for g in plan.compiled.body])
    names = plan.names
    parts: list[Part] = []

    def emit(st):
        cols: list[str] = []
        index: dict[str, int] = {}
        # the answer's unbound variables named as the interpreter's answers name them
        # (answers.answer_bindings): after the query's variables holding them, else new
        variables = AnswerVariables(plan.named or names, frame)

        def recipe(t):
            t = deref(t)
            if type(t) is Col:
                i = index.get(t.sql)
                if i is None:
                    i = index[t.sql] = len(cols)
                    cols.append(t.sql)
                    printed.append(comp.dialect.answer(t.sql, t.kind))
                return ColRef(i)
            if type(t) is Struct:
                return Struct(t.name, tuple(recipe(a) for a in t.args))
            if type(t) is Var:
                return variables(t)
            return t

        printed: list[str] = []
        values = [(name, resolve(frame[slot])) for name, slot in names]
        free = [id(v) for _, v in values if type(v) is Var]
        recipes = []
        for name, v in values:
            if type(v) is Var and free.count(id(v)) < 2:
                continue
            r = recipe(v)
            if type(r) is ColRef:
                recipes.append((name, 0, r.i))
            elif sqlcompile.has_var(r) or _has_ref(r):
                recipes.append((name, 2, r))
            else:
                recipes.append((name, 1, r))
        conds = list(st.conds)
        st.branches.append((list(st.froms), list(conds), frozenset(st.live)))
        conds += sqlcompile.unused_checks(st.checks, conds + st.keys + cols)
        parts.append(Part(list(st.froms), conds, list(st.keys), printed, recipes))

    comp.compile(goal, emit)
    guards = sqlcompile.guards(comp.state.raising, comp.state.branches, comp.dialect)
    if not parts:
        sql = None
    else:
        nv = max(len(p.proj) for p in parts)
        nk = max(len(p.keys) for p in parts)
        keys = sqlcompile.key_columns(parts, comp.dialect)
        selects = []
        for b, p in enumerate(parts):
            off = 1
            recipes = []
            for name, how, data in p.extra:
                if how == 0:
                    data = data + off
                elif how == 2:
                    data = _shift(data, off)
                recipes.append((name, how, data))
            p.extra = recipes
            cols = [f"{b} AS b"]
            cols += [f"{x} AS v{i}" for i, x in enumerate(p.proj)]
            cols += [f"NULL AS v{i}" for i in range(len(p.proj), nv)]
            cols += keys[b]
            selects.append(p.select(cols))
        sql = "\nUNION ALL\n".join(selects)
        if nk and (len(parts) > 1 or any(p.keys for p in parts)):
            sql += "\nORDER BY " + ", ".join(f"k{i}" for i in range(nk))
    return SqlPlan(sql, dict(comp.params), arg_params, has_at,
                   [p.extra for p in parts], frozenset(comp.missing), comp.sites, comp.modes,
                   plan.text, tuple(dict.fromkeys(comp.time_sites)), guards, robot,
                   comp.start_ordered, comp.read_types, comp.key_forms)


def _has_ref(t) -> bool:
    stack = [t]
    while stack:
        x = stack.pop()
        if type(x) is ColRef:
            return True
        if type(x) is Struct:
            stack.extend(x.args)
    return False


def _shift(t, off):
    if type(t) is ColRef:
        return ColRef(t.i + off)
    if type(t) is Struct:
        return Struct(t.name, tuple(_shift(a, off) for a in t.args))
    return t


def plan_for(kb, plan, has_at: bool, robot: bool = False):
    """The cached SqlPlan for a parsed query plan, or the Fallback explaining why none.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> plan = kb.plans.plan("in_kitchen(R)", ())
    >>> type(plan_for(kb, plan, False)).__name__, plan_for(kb, plan, False) is plan_for(kb, plan, False)
    ('SqlPlan', True)
    >>> plan_for(kb, kb.plans.plan("between(1, inf, X)", ()), False).reason
    'the builtin between/3 has no SQL form'
    """
    cache = getattr(plan, "sql_plans", None)
    if cache is None:
        cache = plan.sql_plans = {}
    key = (has_at, True) if robot else has_at
    entry = cache.get(key)
    if entry is not None and (type(entry) is Fallback or not entry.missing
                              or not entry.stale(kb.store)):
        return entry
    try:
        entry = compile_goal(kb, plan, has_at, robot)
    except Fallback as exc:
        entry = exc
    except Unprintable as exc:   # this engine's SQL has no exact form of a part of it
        entry = Fallback(exc.reason)
    except RecursionError:
        entry = Fallback("the goal is nested too deeply to compile")
    except (ValueError, OverflowError) as exc:  # e.g. an integer constant beyond 64 bits
        entry = Fallback(f"a constant SQL cannot hold ({exc})")
    cache[key] = entry
    return entry


def compiles_for(store) -> bool:
    """Whether the SQL compiler's statements run on ``store``: its dialect prints them
    (SQLite and PostgreSQL do; a goal part of which one cannot print exactly, such as a
    Python function on PostgreSQL, falls back to the interpreter goal by goal).

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> compiles_for(kb.store)
    True
    """
    return hasattr(store.dialect, "list_of")


def try_sql(kb, plan, args, at, limit=None, deadline=None, robot=None, stop=None):
    """Answers through SQL, or None when the interpreter must answer. Past ``deadline``
    (``time.monotonic()``) the statement stops with SLRTimeout; once ``stop`` (a
    ``threading.Event``: the query's, which ``Solutions.stop()`` sets) is set, with SLRError
    ``STOPPED_BY_CALLER``. ``robot``: only that robot's events.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> try_sql(kb, kb.plans.plan("in_kitchen(R)", ()), {}, None)
    [{'R': Atom('r1')}]
    """
    if not getattr(kb, "sql_enabled", True) or not compiles_for(kb.store):
        return None
    entry = plan_for(kb, plan, at is not None, robot is not None)
    if type(entry) is Fallback:
        return None
    try:
        return entry.run(kb, args or {}, at, limit, deadline, robot, stop)
    except (DatabaseError, Unencodable, ValueError, TypeError, KeyError, OverflowError,
            MemoryError, RecursionError):
        # (a defined predicate called from SQL that runs out of memory surfaces here as
        # MemoryError): the interpreter answers, and reports it as an ISO resource error
        return None


def explain(kb, plan, at=None) -> list[str]:
    """Lines describing how a goal runs: the SQL with its parameters, or the fallback.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> for line in explain(kb, kb.plans.plan("in_kitchen(R)", ()))[:3]: print(line)
    engine: sql (one prepared statement; rows decoded into answers)
    modes (+ bound, - free when the goal is reached):
      in_kitchen(-)
    """
    entry = plan_for(kb, plan, at is not None)
    if type(entry) is Fallback:
        lines = ["engine: interpreter (top-down SLDNF over the event store)",
                 f"reason: {entry.reason}"]
        subs = _compiled_subgoals(kb, plan, at is not None)
        if subs:
            lines.append("compiled sub-goals (SQL when called with ground or fresh-variable "
                         "arguments): " + ", ".join(subs))
        return lines
    lines = ["engine: sql (one prepared statement; rows decoded into answers)"]
    if entry.modes:
        lines.append("modes (+ bound, - free when the goal is reached):")
        lines.extend(f"  {m}" for m in entry.modes)
    for guard in entry.guards:
        lines.append("guard (run first: evaluates a goal that may raise on the rows Prolog "
                     "reaches it with):")
        lines.append("  " + guard)
    if entry.sql is None:
        lines.append("sql: none (no branch can succeed: the goal fails)")
    else:
        lines.append("sql:")
        lines.extend("  " + line for line in entry.sql.splitlines())
    if entry.params or entry.arg_params:
        shown = {k: v for k, v in entry.params.items()}
        lines.append("parameters: " + ", ".join(f":{k} = {_parameter_text(v)}"
                                                for k, v in shown.items())
                     + "".join(f", :{p} = <{n} from args>" for n, p in entry.arg_params.items()))
    return lines


def _parameter_text(value) -> str:
    """A parameter's value as explain prints it: its repr, an integer in all its digits."""
    if type(value) is int:
        return int_text(value)  # (Python's repr refuses more than 4,300 digits)
    return repr(value)


def _compiled_subgoals(kb, plan, has_at: bool) -> list[str]:
    """The predicates with a CompiledCall that an interpreter run of ``plan`` may reach and
    that compile when called with every argument fresh or every one ground (one whose body
    the compiler cannot take in either, as a ``repeat``, always runs its clauses: not
    listed)."""
    calls = kb.engine.sql_calls
    if not calls or not kb.sql_enabled:
        return []
    from .analysis import analyze, goal_refs, reachable

    a = analyze(kb.program)
    goal, _ = instantiate(plan, None)
    refs = goal_refs(goal, a.program, a.library, a.meta)
    nodes = reachable(kb.program, refs.nodes)
    out = []
    for n in nodes:
        key = (n.name, n.arity) if n.kind == "pred" else ("^", n.name, n.arity)
        call = calls.get(key)
        if call is not None and any(_compiles(kb, call, bound, has_at) for bound in (False, True)):
            out.append(str(n))
    return sorted(out)


def _compiles(kb, call: CompiledCall, bound: bool, has_at: bool) -> bool:
    """Whether ``call`` compiles with all its arguments ground (``bound``) or all fresh (not
    through the call's ``plans``, which hold the modes an interpreter run called it with)."""
    width = call.arity + (1 if call.event else 0)
    text = call._goal(tuple(range(width)) if bound else (), width)
    return type(plan_for(kb, kb.plans.plan(*text), has_at)) is not Fallback


# ---------------------------------------------------------------------- views

def view_sql(kb, name: str, arity: int):
    """The SELECT of the inspection view of name/arity (arg1..argN, encoded values), or
    (None, reason).

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> sql, reason, missing = view_sql(kb, "in_kitchen", 1); reason
    >>> print(sql)
    SELECT arg1 FROM (SELECT +(t0.arg1) AS arg1, ... FROM "at" AS t0 WHERE t0.arg2 = 'kitchen' ...)
    >>> view_sql(kb, "nowhere", 0)[:2]
    (None, 'unknown predicate nowhere/0 (existence error at run time)')
    """
    ctx = _Ctx(kb, state_of(kb))
    comp = Compiler(ctx, False, literal=True)
    xs = [Var(f"A{i + 1}") for i in range(arity)]
    goal = Struct(name, tuple(xs)) if arity else Atom(name)
    parts: list[Part] = []

    def emit(st):
        proj = []
        for x in xs:
            v = resolve(x)
            if type(v) is Var:
                proj.append("NULL")
            else:
                proj.append(comp.value_sql(v))
        conds = list(st.conds)
        conds += sqlcompile.unused_checks(st.checks, conds + st.keys + proj)
        parts.append(Part(list(st.froms), conds, list(st.keys), proj))

    try:
        comp.compile(goal, emit)
    except Fallback as exc:
        return None, exc.reason, comp.missing
    except Unprintable as exc:   # this engine's SQL has no exact form of a part of it
        return None, exc.reason, comp.missing
    except RecursionError:  # as plan_for: a term nested too deeply for the compiler's walks
        return None, "a clause is nested too deeply to compile", comp.missing
    except (ValueError, OverflowError) as exc:  # a constant SQL cannot hold: no view
        return None, str(exc), comp.missing
    if comp.uses_udf:
        # slr_sql's own SQL functions: on SQLite they exist only inside its connection, on
        # PostgreSQL they find each other through the store's search_path, which a psql
        # session does not have
        return None, "uses slr_ functions", comp.missing
    if not parts:
        return None, "no rows", comp.missing
    try:
        return sqlcompile.view_select(parts, arity, comp.dialect), None, comp.missing
    except Unprintable as exc:   # the branches' keys cannot share the engine's columns
        return None, exc.reason, comp.missing


def refresh_views(kb) -> list[str]:
    """Replace the store's inspection views (one per predicate name: a fact table's rows or a
    rule's SELECT) by those of the loaded program; the names of the views.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> refresh_views(kb)
    ['color', 'in_kitchen']
    >>> kb.store.execute("SELECT * FROM in_kitchen")
    [('r1',)]
    """
    st = state_of(kb)
    views = {}
    missing: set = set()
    facts = st.fact_tables(kb)
    for (name, arity), pred in sorted(kb.program.preds.items()):
        if (name, arity) in facts:
            views.setdefault(name, kb.store.fact_view_select(facts[(name, arity)], arity))
            continue
        if not compiles_for(kb.store):
            continue
        sql, _reason, miss = view_sql(kb, name, arity)
        missing |= set(miss)
        if sql is not None and name not in views:
            views[name] = sql
    st.view_missing = missing
    return kb.store.replace_views(views)


# ---------------------------------------------------------------------- compiled sub-goals

class CompiledCall:
    r"""Calls of one derived predicate, made by an interpreter run, answered by SQL.

    The interpreter takes over a query the compiler cannot handle (a cut, recursion, ...),
    but the predicates that query calls may still compile: ``reach(A, B)`` may recurse over
    ``near(A, B)``, a join of prev lookups. For such a call the engine asks this object for
    the answers; it compiles ``name(A1..An)`` for the call's binding pattern (which arguments
    are ground: they become parameters) once, and returns the rows as terms, in the order
    the interpreter would find them. ``None`` means "run the clauses": an argument that is
    neither ground nor a fresh variable (an instance the compiled goal does not stand for,
    as var/1 or ``\+`` may tell the difference), a mode that does not compile, or a statement
    that meets at run time something only the interpreter handles exactly.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("near(A, B) :- at(A, P)^_, at(B, P)^_, A \\== B.")
    >>> kb.add_many(["at(r1, k)^1", "at(r2, k)^2"])
    []
    >>> call = kb.engine.sql_calls[("near", 2)]
    >>> m = kb.engine.machine(); x = slr_sql.terms.Var("X")
    >>> [[(i, str(t)) for i, t in row] for row in call(m, (slr_sql.Atom("r1"), x))]
    [[(1, 'r2')]]
    """

    __slots__ = ("kb", "name", "arity", "event", "plans", "answered", "__weakref__")

    def __init__(self, kb, name: str, arity: int, event: bool = False):
        self.kb = weakref.ref(kb)
        self.name = name
        self.arity = arity
        # event: the temporal predicate name/arity, called as an event goal ``p(..)^T`` or
        # ``p(..)^[S,E]`` (stored events, then the rules); args then end with T, or S and E
        self.event = event
        self.plans: dict = {}
        self.answered = 0   # calls answered through SQL (explain and the tests read it)

    def __call__(self, m, args: tuple):
        bound = []
        terms = {}
        seen = set()
        for i, a in enumerate(args):
            a = deref(a)
            if type(a) is Var:
                if id(a) in seen:
                    return None
                seen.add(id(a))
            elif sqlcompile.has_var(a):
                return None
            else:
                bound.append(i)
                terms[f"A{i + 1}"] = a
        kb = self.kb()
        if kb is None:
            return None
        key = (tuple(bound), len(args))
        text = self.plans.get(key)
        if text is None:
            text = self.plans[key] = self._goal(*key)
        # through kb._plan (a dict hit): define() and load() drop the parsed plans
        entry = plan_for(kb, kb.plans.plan(*text), m.at is not None)
        if type(entry) is Fallback:
            return None
        try:
            rows = entry.term_rows(kb, terms, m.at, m.deadline, stop=m.stop)
        except (DatabaseError, Unencodable, ValueError, TypeError, KeyError, OverflowError):
            return None
        self.answered += 1
        return [[(int(name[1:]) - 1, t) for name, t in row if name not in terms]
                for row in rows]

    def _goal(self, bound: tuple, width: int) -> tuple:
        from .terms import format_term

        xs = [Var(f"A{i + 1}") for i in range(width)]
        n = self.arity
        goal = Struct(self.name, tuple(xs[:n])) if n else Atom(self.name)
        if self.event:
            stamp = xs[n] if width == n + 1 else make_list(xs[n:])
            goal = Struct("^", (goal, stamp))
        return format_term(goal), tuple(f"A{i + 1}" for i in bound)


def compiled_calls(kb) -> dict:
    """``{(name, arity): CompiledCall}`` for the derived predicates worth calling through SQL
    from the interpreter: not recursive, with at least one rule, and reading events (directly
    or through the rules they call). Plain fact predicates stay in the interpreter, whose
    first-argument index answers them faster than a statement would.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.load("color(cup1, red). in_kitchen(R) :- at(R, kitchen)^_.")
    >>> kb.add_many(["at(r1, kitchen)^1", "at(r2, hall)^2"])
    []

    >>> sorted(compiled_calls(kb))   # color/2 (facts only) stays in the interpreter
    [('in_kitchen', 1)]
    """
    from .analysis import Node, analyze, reachable, recursive_predicates

    if not compiles_for(kb.store):
        return {}
    program = kb.program
    a = analyze(program)
    recursive = recursive_predicates(program)
    out = {}
    for key, pred in program.preds.items():
        if Node("pred", *key) in recursive or not any(c.body for c in pred.clauses):
            continue
        if any(a.stored.get(n) for n in reachable(program, [Node("pred", *key)])):
            out[key] = CompiledCall(kb, *key)
    for key, pred in program.temporal.items():   # p(..)^T goals: they read stored p events
        if pred.clauses and Node("event", *key) not in recursive:
            out[("^",) + key] = CompiledCall(kb, *key, event=True)
    return out
