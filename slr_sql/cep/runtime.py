"""Running event rules on a knowledge base: detection rounds, pending decisions, the
completeness of complex event types (docs/events.md).

A *round* runs inside a store transaction. It visits the rules in dependency order; for each
it runs the delta statements of the positions whose event types have new rows in this round,
decides the pending candidates that can be decided, and copies the new matches from the
rule's provenance table ``slr_cep_m_<key>`` into the complex event type's table (arrival =
the clock's time). Complex events derived by one rule are new rows for the rules after it,
so a hierarchy of rules completes in the same round.

Rounds run

* inside the transaction of every ``kb.add`` / ``add_many`` (:meth:`EventRules.before_add`,
  :meth:`EventRules.after_add`): detection is part of the transaction that stores the
  completing event, so after ``add`` returns its complex events are stored, and a crash loses
  either both or neither;
* when completeness advances (the clock moves, a ``fullyUpdated`` mark or ``mark_complete``,
  an in-order arrival): :meth:`EventRules.decide` decides the pending candidates whose
  histories are now complete, in their own transaction.

Both are stages of the knowledge base's event pipeline (:mod:`slr_sql.pipeline`), which
hands the complex events on like added events (synchronized queries, buffers,
subscriptions and ``kb.add_listeners`` see them) and re-checks the synchronized queries
waiting on a complex event type after the decisions.
"""
from __future__ import annotations

import json
import math
from functools import partial

import orjson
from itertools import pairwise
from operator import itemgetter
from typing import Any, Callable

from ..encoding import Unencodable, decode, encode
from ..errors import SLRError, SLRUnavailable
from ..host import Host
from ..store import DatabaseError, quote_identifier, store_error
from ..terms import Struct, Var, deref, format_term, is_ground, make_list, term_vars
from .rules import EventRule
from .sqlgen import (AltSQL, anchor_index, complex_copy, complex_read, create_index,
                     index_name, max_id, max_seq, pending_delete, pending_delete_listed,
                     pending_insert, pending_of_group, pending_of_rule, pending_row, pending_summary,
                     pending_wait, provenance_insert, query_plan, rows_by_seq, rule_record,
                     watermarks)
from .where import MustWait, Residual, describe_error, remembering

# the rowids of a pending row: a JSON array of sequence numbers (64-bit integers, which
# orjson reads exactly, ~5x faster than the json module)
_rowids = orjson.loads

_first, _second = itemgetter(0), itemgetter(1)
_end_of = itemgetter(3)   # of a derived event (name, args, start, end)

__all__ = ["EventRules", "RuleRuntime", "ready_prefix", "OTHERS_LOOK", "WRITTEN_ORDER_FROM"]

_INF = math.inf

# Seconds of the store's clock a clock move waits after the last look at whether another
# connection changed the pending rows (SQLite's data_version, a few microseconds: a third of
# what a clock move that decides nothing costs; a server's notifications, read from the
# socket) before it looks again; an add always looks.
OTHERS_LOOK = 0.1
# A rule whose alternatives have more event atoms than this runs its statements in the join
# order written on every engine (Dialect.written_join_order): PostgreSQL searches the order
# of up to 8 tables itself, which for the small joins of most rules is as cheap as it is
# good, and for a join of 30 tables took it half a second per statement.
WRITTEN_ORDER_FROM = 8
_FLOAT = frozenset((float,))


def _fmt(t: float) -> str:
    if t == _INF:
        return "inf"
    if t == -_INF:
        return "-inf"
    text = f"{t:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _type(key: tuple[str, int]) -> str:
    return f"{key[0]}/{key[1]}"


def _head_value(t: Any, bindings: dict) -> Any:
    """The term with the pattern's variables replaced by their values; None if one is
    unbound."""
    t = deref(t)
    if type(t) is Var:
        return bindings.get(id(t))
    if type(t) is Struct:
        args = []
        for a in t.args:
            v = _head_value(a, bindings)
            if v is None:
                return None
            args.append(v)
        return Struct(t.name, tuple(args))
    return t


def _may_pass(exc: BaseException, path: str | None) -> bool:
    """Whether an error a where goal raised is a condition that may pass (SLRUnavailable:
    a busy or full store, a lost connection, a service a defined predicate asks) rather
    than an answer of the goal (a type error, a timeout, a goal that cannot run).

    >>> _may_pass(SLRUnavailable("down"), None), _may_pass(SLRError("type_error"), None)
    (True, False)
    >>> import sqlite3
    >>> _may_pass(sqlite3.OperationalError("database is locked"), "robot.db")
    True
    """
    if isinstance(exc, SLRUnavailable):
        return True
    return isinstance(exc, DatabaseError) and isinstance(store_error(exc, path), SLRUnavailable)


def _sqlite_key(v: Any, from_column: Any = None) -> tuple:
    """A stored value's place in SQLite's order: numbers, then text, then blobs.
    ``from_column``: the store's reading of a column value (PostgreSQL's columns are text:
    ``'12'`` is the number 12, and ``{"$atom":"9"}`` the atom SQLite stores as ``9``).

    >>> from slr_sql.store.dialect import POSTGRES
    >>> _sqlite_key('12', POSTGRES.from_column), _sqlite_key('{"$atom":"9"}', POSTGRES.from_column)
    ((0, 12, 'integer'), (1, 0, '9'))
    """
    if from_column is not None:
        v = from_column(v)
        if (type(v) is str and v.startswith('{"$atom":"') and v[10:11] not in ("[", "{", "\\")
                and "\\u0000" not in v):
            v = json.loads(v)["$atom"]
    if type(v) is int:
        return (0, v, "integer")
    if type(v) is float:
        # (-0.0 before 0.0, as the statements' ORDER BY puts them: Prolog's standard order)
        return (0, v, "real", math.copysign(1.0, v))
    if isinstance(v, str):
        return (1, 0, v)
    return (2, 0, repr(v))


class _AddToken:
    """What :meth:`EventRules.before_add` read for the round of an add: the greatest seq
    of each added type (``seqs``) and of each complex type a rule reads (``derived``), the
    greatest provenance id of each rule the add may run (``before``, by runtime), and the
    events (described by the store as it stores them)."""

    __slots__ = ("seqs", "derived", "before", "events")

    def __init__(self, seqs: dict, derived: dict, before: dict):
        self.seqs, self.derived, self.before = seqs, derived, before
        self.events: Any = None


class RuleRuntime:
    """One installed event rule: its SQL (per alternative), residual goals, counters and
    the summary of its pending decisions."""

    def __init__(self, eng: "EventRules", rule: EventRule):
        self.rule = rule
        self.key = rule.key
        self.policy = rule.policy
        self.head_key = rule.head_key
        self.prov_name = f"slr_cep_m_{rule.key}"
        self.prov = quote_identifier(self.prov_name)
        self.used_name = f"slr_cep_u_{rule.key}" if rule.policy == "chronological" else None
        self.used = quote_identifier(self.used_name) if self.used_name else None
        self.width = max(len(alt.leaves) for alt in rule.alternatives)
        # per alternative: the types a terminator's decision waits for, through its end or
        # before it (the SQL's and the Python side's one answer)
        self.decisions = [rule.decision_inputs(n) for n in range(len(rule.alternatives))]
        self.alts: list[AltSQL] = []
        self.residuals: list[Residual | None] = []
        self.reads_store: list[bool] = []
        self.plain: list[tuple | None] = []   # per alternative: _plain_plan's plan or None
        self.waits: dict = {}       # (alt, kind, wait key | None) -> earliest time
        self.pmin = _INF            # earliest end of a pending decision
        self.pending = 0
        self.detections = 0
        self.errors = 0
        self.last_error: str | None = None
        self.generation = -1
        self.eng = eng
        self._prov_rows: list = []   # matches found by the Python side, not yet written
        # the stored texts of the points the plain path derived (lists of finite floats,
        # written as their reprs): the flush reads them back with orjson alone. Texts,
        # not the values: strings are no work for Python's garbage collector
        self._plain_points: set = set()
        self._before: int | None = None   # the provenance id a run's matches come after
        self._matched = False   # this run ran a statement that may add provenance rows
        self._queue: list = []  # statements whose result is not needed, not sent yet
        # around the statements of a rule of many parts, on an engine that would search
        # their join order (the order written is the plan: the new rows first)
        written = eng.store.dialect.written_join_order()
        self._join_order = written if written is not None \
            and self.width > WRITTEN_ORDER_FROM else None
        self._done: list = []        # pending rows decided, not yet deleted

    # ----------------------------------------------------------------- building
    def create_tables(self) -> None:
        """The rule's provenance table (and used-rows table), if they are not there yet."""
        self.eng.store.create_rule_tables(self.prov, self.width, self.rule.arity, self.used)

    def build(self) -> None:
        """(Re)build the SQL of every alternative for the tables that exist now."""
        eng = self.eng
        head_args = tuple(self.rule.head.args) if type(self.rule.head) is Struct else ()
        self.alts, self.residuals, self.reads_store, self.plain = [], [], [], []
        for n, alt in enumerate(self.rule.alternatives):
            tables = [eng.table(leaf.key) for leaf in alt.leaves]
            read_types = ({leaf.key for leaf in alt.leaves}
                          | {leaf.key for _, leaf in alt.negations})
            neg_tables = [eng.table(leaf.key) for _, leaf in alt.negations]
            names = [eng.table_name(leaf.key) for leaf in alt.leaves]
            sql = AltSQL(alt, n, tables, neg_tables, head_args, self.policy, eng.complete_sql,
                         used_table=self.used, prov_table=self.prov, table_names=names,
                         fact_table=eng.fact_table, dialect=eng.store.dialect,
                         decision=self.decisions[n],
                         on_statement=partial(eng.store.prepare_start_order,
                                              types=read_types))
            self.alts.append(sql)
            residual = None
            reads = False
            if sql.residual or sql.quiet:
                in_residual = {id(v) for g in sql.quiet + sql.residual for v in term_vars(g)}
                inputs = [v for v in sql.value_vars if id(v) in in_residual]
                outputs = [v for v in term_vars(self.rule.head) if id(v) not in sql.refs]
                residual = Residual(sql.residual, inputs, outputs, sql.quiet)
                reads = bool(residual.analyse(eng.kb.program, eng.known_types())
                             - {self.head_key})
            self.residuals.append(residual)
            self.reads_store.append(reads)
            self.plain.append(self._plain_plan(sql, residual)
                              if residual is not None and not reads else None)
        for key in self.rule.input_types():   # their completeness parameters exist
            eng.complete_sql(key, "x")
        for table, column in self.indexes():
            for first, second in (("t_end", "t_start"), ("t_start", "t_end")):
                name = index_name(table, column, first[2:])
                for statement in create_index(name, table, [column, first, second],
                                              eng.store.dialect):
                    eng.store.run_compiled(statement, {})
        for name, table, columns in self.anchor_indexes():
            for statement in create_index(name, table, columns, eng.store.dialect):
                eng.store.run_compiled(statement, {})
        self.generation = eng.generation

    def _plain_plan(self, sql: AltSQL, residual: Residual) -> tuple | None:
        """How a match of this alternative derives without terms (:meth:`_derive_plain`):
        the where goal is one builtin of plain values (``pos_multiply``, see
        :data:`where.PLAIN_BUILTINS`) reading value columns and binding a head variable, the
        other head arguments constants: ``(columns, their readers, apply, head)``. None
        when the terms' path must run."""
        eng = self.eng
        if eng.store.dialect.from_column is not None or residual.unknown or residual.reads \
                or residual.quiet:
            return None
        shape = residual.plain_function(eng.kb.engine)
        if shape is None:
            return None
        names, out_name, builtin = shape
        readers = builtin.readers(len(names))
        if readers is None:
            return None
        base = sql.k + 2
        by_name = {name: v for v, name in residual.inputs}
        position = {id(v): base + i for i, v in enumerate(sql.value_vars)}
        columns = []
        for name in names:
            v = by_name.get(name)
            if v is None or id(v) not in position:
                return None
            columns.append(position[id(v)])
        out_var = next((v for v, name in residual.outputs if name == out_name), None)
        head = []
        for a in sql.head_args:
            a = deref(a)
            if out_var is not None and a is out_var:
                head.append(None)
            elif type(a) is not Var and is_ground(a):
                try:
                    head.append(eng.encode(a))
                except Unencodable:
                    return None
            else:
                return None
        if None not in head:
            return None
        # each column's readings remembered: a pose at a fixed frame (a camera on its
        # mount) is stored again and again with the same text
        return (list(zip(columns, map(remembering, readers))), builtin.apply, head)

    def _derive_plain(self, n: int, row: tuple, now: float) -> bool | None:
        """:meth:`_derive_from` for an alternative with a plain plan, on the stored values
        themselves (no terms); None when the values are not plain (the terms' path
        decides)."""
        inputs, apply, head = self.plain[n]
        values = []
        for i, read in inputs:
            v = read(row[i])
            if v is None:
                return None
            values.append(v)
        try:
            out = apply(values)
        except Exception:   # (the terms' path raises what the builtin raises, as before)
            return None
        if out is None:
            return None
        try:
            encoded = self.eng.encode(out)
        except Unencodable:
            return None
        if type(out) is list and _FLOAT.issuperset(map(type, out)) and _INF not in out \
                and -_INF not in out:   # (a NaN is Unencodable)
            self._plain_points.add(encoded)
        k = self.alts[n].k
        self._prov_rows.append((n,) + tuple(row[:k]) + (None,) * (self.width - k)
                               + (row[k], row[k + 1])
                               + tuple(encoded if h is None else h for h in head) + (now,))
        return True

    def indexes(self) -> list[tuple[str, str]]:
        """(table, column) of the indexes the delta statements need beyond the event tables'
        own: an atom whose first argument is unconstrained but another is shared with a
        position or constant is searched by that argument and time."""
        out = []
        for alt in self.rule.alternatives:
            names = [self.eng.table_name(leaf.key) for leaf in alt.leaves]
            counts: dict[int, int] = {}
            for leaf in alt.leaves:
                for v in {id(a) for a in leaf.args if type(deref(a)) is Var}:
                    counts[v] = counts.get(v, 0) + 1

            def constrained(a: Any) -> bool:
                a = deref(a)
                return type(a) is not Var or (a.name != "_" and counts.get(id(a), 0) > 1)

            for leaf, table in zip(alt.leaves, names):
                if table is None or not leaf.args or constrained(leaf.args[0]):
                    continue
                for j, a in enumerate(leaf.args[1:], start=2):
                    if constrained(a):
                        if (table, f"arg{j}") not in out:
                            out.append((table, f"arg{j}"))
                        break
        return out

    def anchor_indexes(self) -> list[tuple[str, str, list[str]]]:
        """(name, table, columns) of the indexes the anchors of pushed where goals search
        (:meth:`AltSQL.anchored`)."""
        out = []
        for sql in self.alts:
            for pos, anchors in sql.anchors.items():
                table = sql.table_names[pos] if pos < len(sql.table_names) else None
                for column, _ in anchors:
                    if table is not None:
                        name, columns = anchor_index(table, sql.key_column(pos), column)
                        if (name, table, columns) not in out:
                            out.append((name, table, columns))
        return out

    def prepare_statements(self) -> int:
        """Build the statements that this rule's first add or decision runs (for an add of
        one type), without running them; returns how many were built.

        Building a statement asks for the start-ordered indexes its plan wants
        (``on_statement``: :meth:`EventStore.prepare_start_order`), and a store that already
        holds many events then builds them over the whole history: ~1.0-1.6 s CPU at
        1,000,000 events. A load calls this for the rules it installs (:meth:`EventRules.
        on_load`), so that this cost is the load's, not the first add's: the add is what a
        live stream waits on. An alternative some type of which has no table yet builds
        nothing (its statements are built once the table exists). Returns how many
        statements the rule has ready (built now, or before).

        >>> import slr_sql
        >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
        >>> _ = kb.add_many(["a(1)^1", "b(1)^2"])
        >>> sorted(kb.store.index_names("b"))
        ['slr_ix__b__a1_end', 'slr_ix__b__end']
        >>> kb.load("c(X) <- a(X) seq b(X).")   # (a new a searches the b after it by start)
        >>> sorted(kb.store.index_names("b"))
        ['slr_ix__b__a1_end', 'slr_ix__b__a1_start', 'slr_ix__b__end', 'slr_ix__b__start']
        >>> kb._cep.rules[0].prepare_statements()   # (the load's: built already)
        2
        """
        self.ensure_built()
        built = 0
        for n, alt in enumerate(self.alts):
            if not alt.runnable:
                continue
            for pos, leaf in enumerate(alt.alt.leaves):
                if self.policy == "unrestricted":
                    dirty = {leaf.key}
                    if alt.pure and not self.reads_store[n]:
                        statements = [alt.delta_insert(pos, dirty)]
                        if alt.negs:
                            statements.append(alt.delta_pending(pos, dirty))
                    else:
                        statements = [alt.delta_select(pos, dirty)]
                elif pos not in alt.alt.terminators:
                    continue
                elif self.policy == "recent" and alt.pure:
                    statements = [alt.recent_insert(pos), alt.term_span(pos),
                                  alt.term_pending(pos, True), alt.span_recent_insert(pos),
                                  alt.span_split(pos), alt.pending_recent_insert(pos)]
                elif self.policy == "recent":
                    statements = [alt.term_ready(pos), alt.term_pending(pos, True),
                                  alt.term_select(pos, False), alt.term_select_many(pos)]
                else:
                    statements = [alt.term_pending(pos, False), alt.term_select(pos, alt.pure)]
                built += len(statements)
        return built

    def ensure_built(self) -> None:
        if self.generation != self.eng.generation or self._tables_appeared():
            self.build()

    def _tables_appeared(self) -> bool:
        """A type that had no table when the SQL was built has one now: another process
        (or another store object) created it, so this one's table hooks never heard."""
        for sql in self.alts:
            for table, leaf in zip(sql.tables, sql.alt.leaves):
                if table is None and self.eng.table(leaf.key) is not None:
                    return True
            for table, (_, leaf) in zip(sql.neg_tables, sql.alt.negations):
                if table is None and self.eng.table(leaf.key) is not None:
                    return True
        return False

    # ----------------------------------------------------------------- running
    def run(self, new_from: dict, dirty: set, now: float, decide: bool,
            ends: dict | None = None, before: int | None = None) -> list:
        """Detection for this rule in the current round; returns the complex events
        derived, as ``(name, args, start, end)``. ``ends``: per event type with new rows,
        their earliest and latest end, when known (a terminator statement none of whose
        rows can qualify is not run); ``before``: the provenance table's greatest id, when
        the round read it already."""
        eng = self.eng
        self.ensure_built()
        self._before, self._matched = before, False
        self._forget_unsent()
        changed = False
        fresh_terms = False
        params = eng.params(now)
        params["rule"] = self.key
        for n, alt in enumerate(self.alts):
            positions = [p for p, leaf in enumerate(alt.alt.leaves) if leaf.key in dirty]
            if not positions or (self.policy == "unrestricted" and not alt.runnable):
                continue   # a type without a table has no row to match yet
            p2 = dict(params)
            p2.update(alt.params)
            for p, leaf in enumerate(alt.alt.leaves):
                if leaf.key in new_from:
                    p2[f"w{p}"] = new_from[leaf.key]
            if self.policy == "unrestricted":
                for pos in positions:
                    if alt.pure and not self.reads_store[n]:
                        self._before_matches()
                        self._send(alt.delta_insert(pos, dirty), p2)
                        if alt.negs:
                            self._send(alt.delta_pending(pos, dirty), p2)
                            changed = True
                    else:
                        rows = self._ask(alt.delta_select(pos, dirty), p2)
                        if rows:
                            changed |= self._candidates(n, rows, now)
            else:
                for pos in positions:
                    if pos not in alt.alt.terminators or alt.tables[pos] is None:
                        continue
                    # a terminator is kept even while a partner type has no table: its
                    # partners may still arrive (late) before it is decided
                    if self.policy == "recent" and alt.runnable:
                        # the statements of the new terminators complete now and of those
                        # not complete yet: completeness only shrinks as the end grows, so
                        # the new rows' earliest and latest ends tell when one of them has
                        # no row to find (the statement is then not run)
                        span = ends.get(alt.alt.leaves[pos].key) if ends else None
                        some_ready = span is None or self._inputs_complete(n, span[0], now)
                        all_ready = span is not None and self._inputs_complete(n, span[1],
                                                                               now)
                    if self.policy == "recent" and alt.pure and alt.runnable:
                        if some_ready:
                            self._before_matches()
                            self._send(alt.recent_insert(pos), p2)
                        if not all_ready and some_ready:
                            self._send(alt.term_pending(pos, True), p2)
                        elif not all_ready:   # (a live stream's add: none is complete yet)
                            self._send(alt.term_span(pos), p2)
                    elif self.policy == "recent" and alt.runnable:
                        # independent decisions: those that can be made now, at once
                        pend = []
                        ready = self._ask(alt.term_ready(pos), p2) if some_ready \
                            else []
                        for seq, end in ready:
                            try:
                                self._decide_term(n, pos, seq, end, now, p2, checked=True)
                            except MustWait as w:
                                pend.append(self._pending_row(n, "term", pos, [seq], end,
                                                              end, w))
                        if pend:
                            self._insert_pending(pend)
                        if not all_ready:
                            self._send(alt.term_pending(pos, True), p2)
                    else:
                        self._send(alt.term_pending(pos, False), p2)
                        fresh_terms = True
                    changed = True
        if decide or fresh_terms:
            changed |= self.decide(now, everything=fresh_terms and not decide)
        self._write_prov()
        self._delete_done()
        # the copy of the matches and the summary of what is pending: with the writes still
        # waiting, one call of the store
        statements, stored = self._copy(self._before, now) if self._matched else ([], None)
        summary = [(pending_summary(self.eng.store.dialect), {"rule": self.key}, False)] \
            if changed or decide else []
        rows = self._ask_all(statements + summary)   # (nothing to ask: the writes alone)
        if summary:
            self._summary(rows[-1])
        return stored(rows[len(statements) - 1]) if stored is not None else []

    def _forget_unsent(self) -> None:
        """Drop what a run found or wrote but did not send: it belonged to that run's
        transaction, which an error rolled back (a deferred write refused at a later read
        leaves the matches found meanwhile here), and must not reach the next one."""
        self._queue, self._prov_rows, self._done = [], [], []

    def _before_matches(self) -> None:
        """Before a statement that may add provenance rows: the table's greatest id (the
        flush copies the rows after it), unless known -- a run that adds none reads,
        copies and reads back nothing."""
        self._matched = True
        if self._before is None:
            self._before = self._ask(max_id(self.prov), {})[0][0]

    def _candidates(self, n: int, rows: list, now: float) -> bool:
        """unrestricted with Python work: decide each candidate now or keep it pending."""
        alt = self.alts[n]
        k = alt.k
        pend = []
        for row in rows:
            if alt.negs:
                if not row[-2]:
                    pend.append(self._pending_row(n, "match", None, row[:k], row[k],
                                                  row[k + 1], None))
                    continue
                if not row[-1]:
                    continue
            try:
                self._derive_from(n, row, now)
            except MustWait as w:
                pend.append(self._pending_row(n, "match", None, row[:k], row[k], row[k + 1],
                                              w))
        if pend:
            self._insert_pending(pend)
        return bool(pend)

    def _pending_row(self, n, kind, pos, rowids, start, end, wait) -> tuple:
        return (self.key, n, kind, pos, json.dumps(list(rowids)), start, end,
                wait.key[0] if wait else None, wait.key[1] if wait else None,
                wait.time if wait else None, wait.reason if wait else None,
                float(self.eng.clock.now()))

    def _insert_pending(self, rows: list) -> None:
        self._send_many(pending_insert(), [pending_row(row) for row in rows])

    def _bindings(self, n: int, row: tuple) -> dict:
        alt = self.alts[n]
        base = alt.k + 2
        dec = self.eng.decode
        return {id(v): dec(row[base + i]) for i, v in enumerate(alt.value_vars)}

    def _derive_from(self, n: int, row: tuple, now: float) -> bool:
        """Derive the complex events of one match (value columns ``row``); raises MustWait.
        Returns whether any was derived."""
        if self.plain[n] is not None:
            done = self._derive_plain(n, row, now)
            if done is not None:
                return done
        alt = self.alts[n]
        k = alt.k
        bindings = self._bindings(n, row)
        residual = self.residuals[n]
        solutions: list[dict] = [{}]
        if residual is not None:
            values = {name: bindings[id(v)] for v, name in residual.inputs}
            try:
                solutions = residual.solve(self.eng.kb, values, row[k + 1], self.eng.complete,
                                           skip=frozenset({self.head_key}),
                                           use_sql=self.reads_store[n])
            except MustWait:
                raise
            except (SLRError, RecursionError, ValueError, TypeError, DatabaseError) as exc:
                if _may_pass(exc, self.eng.store.path):
                    # the goal could not be asked (a service down, the store busy or full):
                    # rejecting this candidate would derive the next one in its place, a
                    # decision the moment's trouble made; the round fails instead, and the
                    # decision is made again (the add is retried, the clock moves again)
                    if isinstance(exc, DatabaseError):
                        raise store_error(exc, self.eng.store.path) from None
                    raise
                self.errors += 1
                self.last_error = describe_error(exc)
                return False
        rows = []
        seen: set = set()
        head_args = alt.head_args
        for sol in solutions:
            b = dict(bindings)
            if residual is not None:
                for v, name in residual.outputs:
                    b[id(v)] = sol[name]
            values = []
            for a in head_args:
                t = _head_value(a, b)
                if t is None:
                    break
                try:
                    values.append(self.eng.encode(t))
                except Unencodable as exc:   # (a non-ground or too large head value)
                    self.errors += 1
                    self.last_error = f"the complex event cannot be stored: {exc.reason}"
                    break
            else:
                key = tuple((type(v).__name__, v) for v in values)
                if key in seen:
                    continue   # two solutions, one complex event
                seen.add(key)
                rows.append((n,) + tuple(row[:k]) + (None,) * (self.width - k)
                            + (row[k], row[k + 1]) + tuple(values) + (now,))
        self._prov_rows += rows   # written together before the round's flush
        return bool(rows)

    def _write_prov(self) -> None:
        rows, self._prov_rows = self._prov_rows, []
        if rows:
            self._before_matches()
            self._send_many(provenance_insert(self.prov, self.width, self.rule.arity), rows)

    # ----------------------------------------------------------------- statements
    # The statements of a run whose result nothing needs (its writes to the provenance,
    # pending and used-rows tables) wait in ``_queue`` and go with the next statement whose
    # rows are needed, in order: on a server, one round trip for them all. Nothing else
    # reads those tables while they wait (the trackers and where goals read event tables).
    def _send(self, sql: str, params: dict) -> None:
        self._queue.append((sql, dict(params), False))   # (the caller reuses its dict)

    def _send_many(self, sql: str, rows: list) -> None:
        self._queue.append((sql, rows, True))

    def _ask(self, sql: str, params: dict) -> list:
        """The rows of ``sql``, after the statements waiting."""
        return self._ask_all([(sql, params, False)])[-1]

    def _ask_all(self, statements: list) -> list:
        """The rows of each of ``statements`` (``(sql, params, many)``), after the
        statements waiting, in one call of the store."""
        batch, self._queue = self._queue + statements, []
        if not batch:
            return []
        if self._join_order is not None:
            before, after = self._join_order
            batch = [(before, {}, False)] + batch + [(after, {}, False)]
            return self.eng.store.run_compiled_batch(batch)[
                len(batch) - 1 - len(statements):-1]
        if len(batch) == 1 and not batch[0][2]:
            return [self.eng.store.run_compiled(batch[0][0], batch[0][1])]
        return self.eng.store.run_compiled_batch(batch)[len(batch) - len(statements):]

    # ----------------------------------------------------------------- pending
    def ready_groups(self, now: float) -> list:
        """The pending groups whose condition holds now."""
        out = []
        for group, t in self.waits.items():
            if self._ready(group, t, now):
                out.append(group)
        return out

    def _ready(self, group: tuple, t: float, now: float) -> bool:
        """Can the pending rows of ``group`` ending at ``t`` be decided now? The same
        conditions as the SQL of the decisions (:meth:`EventRules.complete_sql`, with the
        same parameters), so that Python and SQL never judge a row differently."""
        n, kind, wait = group
        complete = self.eng.complete
        if wait is not None:
            return complete(wait, t, now)
        if n >= len(self.rule.alternatives):
            return True
        if kind == "match":   # a negated event lies strictly inside: before its end
            return all(complete(leaf.key, t, now, False)
                       for _, leaf in self.rule.alternatives[n].negations)
        return all(complete(key, t, now, through)
                   for key, through in self.decisions[n].items())

    def _inputs_complete(self, n: int, t: float, now: float) -> bool:
        """:meth:`AltSQL.inputs_complete` of alternative ``n`` at a terminator's end ``t``,
        evaluated here: what the terminator statements will find (a run that skipped a
        statement by another answer would neither match nor keep such a terminator)."""
        return self._ready((n, "term", None), t, now)

    def decide(self, now: float, everything: bool = False) -> bool:
        """Decide the pending rows that can be decided now. Chronological rules decide in
        occurrence order and stop at the first row that must still wait."""
        eng = self.eng
        base = eng.params(now)
        base["rule"] = self.key
        per_alt = [dict(base, **alt.params) for alt in self.alts]
        if self.policy == "chronological":
            rows = self._occurrence_order(self._ask(pending_of_rule(False),
                                                             {"rule": self.key}))
            changed = False
            for row in rows:
                if not self._decide_row(row, now, per_alt):
                    break
                changed = True
            return changed
        groups = self.ready_groups(now) if not everything else list(self.waits) + [None]
        if not groups:
            return False
        changed = False
        seen = set()
        # pure alternatives: all their ready decisions in one statement each
        for group in [g for g in groups if g is not None and g[2] is None]:
            n, kind, _ = group
            alt = self.alts[n] if n < len(self.alts) else None
            if alt is None or not alt.pure or not alt.runnable:
                continue
            p2 = per_alt[n]
            if kind == "term" and self.policy == "recent":
                self._before_matches()
                for pos in sorted(alt.alt.terminators):
                    self._send(alt.pending_recent_insert(pos), p2)
                    self._send(alt.pending_term_delete(pos), p2)
            elif kind == "span" and self.policy == "recent":
                self._before_matches()
                for pos in sorted(alt.alt.terminators):
                    self._send(alt.span_recent_insert(pos), p2)
                    self._send(alt.span_split(pos), p2)
                    self._send(alt.span_delete(pos), p2)
            elif kind == "match" and self.policy == "unrestricted":
                self._before_matches()
                self._send(alt.pending_match_insert(), p2)
                self._send(alt.pending_match_delete(), p2)
            else:
                continue
            groups.remove(group)
            changed = True
        if everything:
            rows = self._ask(pending_of_rule(True), {"rule": self.key})
            for row in rows:
                changed |= self._decide_row(row, now, per_alt)
            return changed
        for n, kind, wait in groups:
            group = {"rule": self.key, "alt": n, "kind": kind}
            if wait is not None:
                group.update(wait_type=wait[0], wait_arity=wait[1])
            rows = self._ask(pending_of_group(wait is not None), group)
            # recent, with Python work: the terminators of a group decide independently of
            # each other, so their candidates are read in one statement per position
            together = (kind == "term" and wait is None and self.policy == "recent"
                        and n < len(self.alts) and self.alts[n].runnable)
            if together:
                ready = ready_prefix([row for row in rows if row[0] not in seen],
                                     lambda t: self._ready((n, kind, wait), t, now), seen)
                if ready:
                    changed |= self._decide_terms(n, ready, now, per_alt[n])
                continue
            for row in rows:
                if row[0] in seen:
                    continue
                seen.add(row[0])
                wt = row[9] if row[7] is not None else row[6]
                if not self._ready((n, kind, wait), wt, now):
                    break   # the rest of the group needs a later time
                changed |= self._decide_row(row, now, per_alt)
        return changed

    def _decide_terms(self, n: int, rows: list, now: float, params: dict) -> bool:
        """Decide pending ``recent`` terminators of alternative ``n`` (pending rows whose
        inputs are complete up to their end, checked by the caller), as :meth:`_decide_row`
        does one by one: the candidates of up to 200 terminators come from one statement
        (:meth:`AltSQL.term_select_many`), then each terminator takes its first candidate
        that derives, in the order of ``rows``."""
        alt = self.alts[n]
        changed = False
        for i in range(0, len(rows), 200):
            chunk = [(row, _rowids(row[4])[0]) for row in rows[i:i + 200]]
            candidates: dict = {}
            for pos in sorted({row[3] for row, _ in chunk}):
                params["ts"] = orjson.dumps(
                    [seq for row, seq in chunk if row[3] == pos]).decode()
                for cand in self._ask(alt.term_select_many(pos), params):
                    candidates.setdefault((pos, cand[pos]), []).append(cand)
            for row, seq in chunk:
                try:
                    for cand in candidates.get((row[3], seq), ()):
                        if self._derive_from(n, cand, now):
                            break
                except MustWait as w:
                    self._park(row[0], w)
                    continue
                self._done.append(row[0])
                changed = True
        return changed

    def _occurrence_order(self, rows: list) -> list:
        """Pending terminators in occurrence order: end, start, alternative, position, then
        the row's arguments as SQLite orders them (numbers before text), then rowid -- never
        the arrival order (chronological decisions consume rows, so their order matters)."""
        args: dict = {}
        groups: dict = {}
        from_column = self.eng.store.dialect.from_column
        for row in rows:
            groups.setdefault((row[1], row[3]), []).append(_rowids(row[4])[0])
        for (n, pos), seqs in groups.items():
            if n >= len(self.alts) or self.alts[n].tables[pos] is None:
                continue
            arity = self.alts[n].alt.leaves[pos].arity
            for i in range(0, len(seqs), 500):
                chunk = seqs[i:i + 500]
                for r in self._ask(
                        rows_by_seq(self.alts[n].tables[pos], arity, len(chunk)),
                        {f"s{j}": seq for j, seq in enumerate(chunk)}):
                    args[(n, pos, r[0])] = tuple(_sqlite_key(v, from_column) for v in r[1:])

        def key(row: tuple) -> tuple:
            seq = _rowids(row[4])[0]
            return (row[6], row[5], row[1], row[3] if row[3] is not None else -1,
                    args.get((row[1], row[3], seq), ()), seq)

        return sorted(rows, key=key)

    def _decide_row(self, row: tuple, now: float, params: list | None = None) -> bool:
        """Decide one pending row; False if it must still wait (its wait is updated).
        ``params``: per alternative, the statement parameters of this round."""
        rid, n, kind, pos, rowids, start, end = row[:7]
        if n >= len(self.alts):
            self._done.append(rid)
            return True
        if not self.alts[n].runnable:
            # a partner type still has no event: once the inputs are complete, it never will
            if kind == "term" and self._ready((n, "term", None), end, now):
                self._done.append(rid)
                return True
            return False
        if row[7] is not None and not self.eng.complete((row[7], row[8]), row[9], now):
            return False
        if kind == "span":
            return self._decide_span(row, now, params)
        try:
            if kind == "match":
                done = self._decide_match(n, _rowids(rowids), end, now, params)
            else:
                done = self._decide_term(n, pos, _rowids(rowids)[0], end, now,
                                         params[n] if params else None)
        except MustWait as w:
            self._park(rid, w)
            return False
        if not done:
            if row[7] is not None:
                self._send(pending_wait(),
                           {"wait_type": None, "wait_arity": None, "wait_time": None,
                            "wait_reason": None, "id": rid})
            return False
        self._done.append(rid)
        return True

    def _decide_span(self, row: tuple, now: float, params: list | None) -> bool:
        """Decide a pending span one terminator at a time: those complete now are decided,
        the others (and those whose goal must wait) kept as terminators of their own, and
        the span deleted. (A span's alternative was all SQL when it was stored; a program
        that changed what its where goal calls makes it need the Python side, and the
        decision of all the rule's pending rows reads the spans with the others: the span
        statements would never see it, and deciding its first terminator alone would
        lose the rest.)"""
        rid, n, _, pos, rowids, _, end = row[:7]
        if not self._ready((n, "term", None), end, now):
            return False
        alt = self.alts[n]
        p2 = self._params_of(n, now, params)
        first, last = _rowids(rowids)[:2]
        p2.update(first=first, last=last)
        pend = []
        for seq, start, t_end in self._ask(alt.span_terms(pos), p2):
            if not self._ready((n, "term", None), t_end, now):
                pend.append(self._pending_row(n, "term", pos, [seq], start, t_end, None))
                continue
            try:
                self._decide_term(n, pos, seq, t_end, now, dict(p2), checked=True)
            except MustWait as w:
                pend.append(self._pending_row(n, "term", pos, [seq], start, t_end, w))
        if pend:
            self._insert_pending(pend)
        self._done.append(rid)
        return True

    def _params_of(self, n: int, now: float, params: list | None) -> dict:
        """Alternative ``n``'s statement parameters: a copy of this round's (``params``, per
        alternative), or made now."""
        if params:
            return dict(params[n])
        made = self.eng.params(now)
        made.update(self.alts[n].params)
        return made

    def _park(self, rid: int, wait: MustWait) -> None:
        """Record on pending row ``rid`` what it waits for (a history not complete yet)."""
        self._send(pending_wait(),
                   {"wait_type": wait.key[0], "wait_arity": wait.key[1],
                    "wait_time": wait.time, "wait_reason": wait.reason, "id": rid})

    def _delete_done(self) -> None:
        done, self._done = self._done, []
        if len(done) == 1:
            self._send(pending_delete(1), {"d0": done[0]})
        elif done:   # (their ids as one JSON array: one statement, whatever their count)
            self._send(pending_delete_listed(self.eng.store.dialect),
                       {"ids": orjson.dumps(done).decode()})

    def _decide_match(self, n: int, rowids: list, end: float, now: float,
                      params: list | None = None) -> bool:
        alt = self.alts[n]
        params = self._params_of(n, now, params)
        for p, r in enumerate(rowids):
            params[f"r{p}"] = r
        rows = self._ask(alt.match_select(), params)
        if not rows:
            return True  # its events are gone (a buffer pruned them)
        row = rows[0]
        if not row[-2]:
            return False
        if not row[-1]:
            return True
        self._derive_from(n, row, now)
        return True

    def _decide_term(self, n: int, pos: int, rowid: int, end: float, now: float,
                     params: dict | None = None, checked: bool = False) -> bool:
        alt = self.alts[n]
        if not checked and not self._ready((n, "term", None), end, now):
            return False
        if params is None:
            params = self.eng.params(now)
            params.update(alt.params)
        params["t"] = rowid
        rows = self._ask(alt.term_select(pos, alt.pure), params)
        for row in rows:
            if self._derive_from(n, row, now):
                if self.used is not None:
                    self._send_many(
                        alt.used_insert(),
                        [(alt.table_names[p], row[p]) for p in range(alt.k)])
                return True
        return True

    def refresh(self) -> None:
        """Re-read the summary of this rule's pending decisions."""
        self._forget_unsent()
        self._summary(self._ask(pending_summary(self.eng.store.dialect), {"rule": self.key}))

    def _summary(self, rows: list) -> None:
        """Take the summary of this rule's pending decisions from ``rows`` (those of
        :func:`pending_summary`)."""
        waits = {}
        pmin = _INF
        count = 0
        for n, kind, wtype, warity, t, tend, c in rows:
            waits[(n, kind, (wtype, warity) if wtype is not None else None)] = t
            pmin = min(pmin, tend)
            count += int(c)   # (a sum on PostgreSQL is a numeric: a Decimal)
        self.waits = waits
        self.pmin = pmin
        self.pending = count

    def flush(self, before: int, now: float) -> list:
        """Copy the matches found in this round (provenance rows after ``before``) into the
        complex event type's table; returns the events stored (a buffer's trigger may refuse
        some), as ``(name, args, start, end)``."""
        statements, stored = self._copy(before, now)
        return stored(self._ask_all(statements)[-1])

    def _copy(self, before: int, now: float) -> tuple[list, Callable[[list], list]]:
        """:meth:`flush` as the statements to run and what turns the rows of the last one
        into the events stored."""
        name, arity = self.head_key
        table = self.eng.table(self.head_key)
        if table is None:
            # (start-ordered indexes on first need: see declare_type)
            self.eng.store.declare_type(name, arity, start_order=False)
            table = self.eng.table(self.head_key)
        store = self.eng.store
        # a complex event is the deriving store's: its robot (NULL on an unnamed or fleet
        # store, whatever robots the constituent events came from)
        args = {"now": now, "before": before, "robot": store.robot}
        head_table = self.eng.table_name(self.head_key)
        returning = bool(store.dialect.copies_returning or store.triggers(head_table))
        if returning:
            # a buffer's trigger may refuse rows: the rows stored are those RETURNING gives
            statements = [(complex_copy(table, self.prov, arity, True), args, False)]
        else:
            # no trigger: every match is stored as it is; reading the provenance rows back
            # (a rowid range) costs less than RETURNING's buffered copy
            statements = [(complex_copy(table, self.prov, arity, False), args, False),
                          (complex_read(self.prov, arity), {"before": before}, False)]

        def stored(rows: list) -> list:
            points, self._plain_points = self._plain_points, set()
            if returning:   # RETURNING gives an integral REAL as an int: the times as stored
                rows = [r[:arity] + (float(r[arity]), float(r[arity + 1])) for r in rows]
            if not rows:
                return []
            self.detections += len(rows)
            dec = self.eng.decode
            if points:   # (decode's very terms: the reprs' floats in a list)
                decode_text = dec

                def dec(v: Any) -> Any:
                    return make_list(orjson.loads(v)) if v in points else decode_text(v)
            if arity == 0:
                return [(name, (), r[0], r[1]) for r in rows]
            if arity == 1:
                return [(name, (v if type(v) is int or type(v) is float else dec(v),), r[1],
                         r[2]) for r in rows for v in (r[0],)]
            return [(name, tuple(map(dec, r[:arity])), r[arity], r[arity + 1]) for r in rows]
        return statements, stored


class EventRules:
    """The event rules of one knowledge base (created by :func:`slr_sql.cep.attach`)."""

    def __init__(self, kb: Host):
        self.kb = kb
        self.store = kb.store
        # the store's columns: encoded terms as they are (SQLite) or as a server holds them
        from_column, to_column = kb.store.dialect.from_column, kb.store.dialect.to_column
        self.decode: Any = decode if from_column is None else \
            (lambda v: decode(from_column(v)))
        self.encode: Any = encode if to_column is None else (lambda t: to_column(encode(t)))
        self.clock = kb.clock
        self.sync = kb.synchronizer
        self.tracker = self.sync.tracker if self.sync is not None else None
        self.rules: list[RuleRuntime] = []
        self.by_head: dict[tuple[str, int], list[RuleRuntime]] = {}
        self.types: frozenset = frozenset()          # complex event types (rule heads)
        self.leaf_types: frozenset = frozenset()     # types read by positive event atoms
        self.inputs: dict = {}                       # head -> types its events are made of
        self.closing: dict = {}                      # head -> those that may end its events
        self.key_index: dict[tuple[str, int], int] = {}
        self.generation = 0
        self._decls: Any = None
        self._woken: dict = {}     # type -> the time a wake-up was asked for
        self._wake_due = False     # rules installed since the timers were last asked for
        self.closed = False
        # a rollback may undo what the rules' pending summaries were read after (decisions
        # made, rows kept pending): they are read again before they are used next
        self._summaries_stale = False
        kb.store.rollback_listeners.append(self.reread_pending)
        # and it may take back a start-ordered index a new statement's first run built:
        # the statements are built again (and their indexes asked for) when next used
        self._builds_undone = kb.store.start_order_builds_undone
        kb.store.rollback_listeners.append(self._forget_statements)
        # another process may leave decisions pending and stop: seeing whether another
        # connection changed them costs no I/O (SQLite's data_version; on a server the
        # notifications the store's connection heard), so the summaries are read again
        # when it moved, and a clock move or an in-order event here decides them too
        self._watch_others = kb.store.path is not None
        self._others_version: int | None = None   # others_version when last looked
        self._others_looked_at: float | None = None   # and the store clock's time then

    # ----------------------------------------------------------------- install
    @property
    def active(self) -> bool:
        self.sync_rules()
        return bool(self.rules)

    def sync_rules(self) -> None:
        """Follow the kb's declarations (a load replaces them; a failed load restores the
        previous object)."""
        decls = self.kb.declarations
        if decls is not self._decls:
            with self.store.lock:
                if decls is not self._decls:
                    try:
                        self.install(list(getattr(decls, "event_rules", ())))
                    except BaseException:
                        # install may have made the refused rules the ones in force before
                        # it failed (a head wider than a table); the load restores the
                        # declarations, which the next call installs again
                        self._decls = None
                        raise
                    self._decls = decls
        self.wake_if_due()

    def install(self, rules: list[EventRule]) -> None:
        """Make ``rules`` (already in dependency order, policies resolved) the active rules:
        their tables exist, their SQL is built, their pending summary read."""
        old = {rt.key: rt for rt in self.rules}
        runtimes = []
        for rule in rules:
            rt = old.get(rule.key)
            if rt is None or rt.rule is not rule:
                keep = rt
                rt = RuleRuntime(self, rule)
                if keep is not None:
                    rt.detections, rt.errors, rt.last_error = \
                        keep.detections, keep.errors, keep.last_error
            runtimes.append(rt)
        by_head: dict = {}
        for rt in runtimes:
            by_head.setdefault(rt.head_key, []).append(rt)
        self.types = frozenset(by_head)
        self.leaf_types = frozenset(leaf.key for rt in runtimes
                                    for alt in rt.rule.alternatives for leaf in alt.leaves)
        self.inputs = {h: sorted({leaf.key for rt in rts for alt in rt.rule.alternatives
                                  for leaf in alt.leaves}) for h, rts in by_head.items()}
        self.closing = {h: frozenset().union(*(rt.rule.closing_types() for rt in rts))
                        for h, rts in by_head.items()}
        self.rules = runtimes
        self.by_head = by_head
        self.generation += 1
        # writers of types one rule joins take turns (a server's concurrent writers would
        # each miss the other's half of a match); other writers do not wait for them
        self.store.set_write_groups(_rule_groups(runtimes))
        if runtimes:
            with self.store.transaction():
                for rt in runtimes:
                    name, arity = rt.head_key
                    if self.store.table_for(name, arity) is None:
                        # a complex type's events come in end order: its start-ordered
                        # indexes, random inserts, are built when a reader needs them
                        self.store.declare_type(name, arity, start_order=False)
                    rt.create_tables()
                    self.store.run_compiled(rule_record(), {
                        "key": rt.key, "head": _type(rt.head_key), "rule": rt.rule.text,
                        "policy": rt.policy, "source": rt.rule.source,
                        "prov_table": rt.prov_name, "installed_at": float(self.clock.now())})
                for rt in runtimes:
                    rt.build()
                    rt.refresh()
        if self.tracker is not None:
            self.tracker.derived = self if runtimes else None
        # the synchronizer's lock comes before the store's (slr_sql.lockorder), which the
        # caller holds: the timers are asked for once it is let go (wake_if_due)
        self._wake_due = True

    def on_load(self, kb: Host) -> None:
        """Load listener (inside the load's transaction): the rules the load installs
        build their statements, and so the start-ordered indexes these want, now
        (:meth:`RuleRuntime.prepare_statements`), not at the first add."""
        installed = {rt.key for rt in self.rules}
        self.sync_rules()
        with self.store.lock:
            for rt in self.rules:
                if rt.key not in installed:
                    rt.prepare_statements()

    def on_table(self, name: str, arity: int, table: str) -> None:
        """A new event table: rules reading that type can now match (rebuild their SQL)."""
        self.generation += 1

    def table(self, key: tuple[str, int]) -> str | None:
        name = self.store.table_for(*key)
        return None if name is None else quote_identifier(name)

    def table_name(self, key: tuple[str, int]) -> str | None:
        return self.store.table_for(*key)

    def fact_table(self, key: tuple[str, int]) -> str | None:
        """The SQL table of a predicate made only of ground facts (the planner keeps them),
        or None."""
        from ..planner import state_of

        if not self.kb.sql_enabled:
            return None
        return state_of(self.kb).fact_tables(self.kb).get(key)

    def known_types(self) -> set:
        return set(self.store.event_types()) | set(self.kb.declarations.event_types)

    # ----------------------------------------------------------------- completeness
    def _index(self, key: tuple[str, int]) -> int:
        n = self.key_index.get(key)
        if n is None:
            n = self.key_index[key] = len(self.key_index)
        return n

    def complete_sql(self, key: tuple[str, int], x: str, through: bool = True) -> str:
        """SQL: the history of ``key`` is complete up to the time ``x`` (an SQL expression),
        with the inputs as parameters (:meth:`params`) -- :meth:`complete` in SQL. ``through``:
        every event ending at or before x is in; else only those ending before x (what a
        cnot or a decision needs of a type none of whose events can end with the match)."""
        n = self._index(key)
        if key in self.types:
            closing = self.closing.get(key, ())
            inner = " AND ".join(f"({self.complete_sql(t, x, through and t in closing)})"
                                 for t in self.inputs[key])
            return (f"{x} <= :mk{n} OR (({inner or self.store.dialect.true}) AND "
                    f"{x} {'<' if through else '<='} :pm{n})")
        return f"{x} <= :mk{n} OR {x} + :dl{n} < :now OR {x} {'<' if through else '<='} :le{n}"

    def params(self, now: float) -> dict:
        """The parameters of the completeness conditions, now."""
        tracker = self.tracker
        out: dict = {"now": now}
        for key, n in self.key_index.items():
            if tracker is None:
                out[f"mk{n}"], out[f"dl{n}"], out[f"le{n}"], out[f"pm{n}"] = \
                    _INF, 0.0, -_INF, _INF
                continue
            out[f"mk{n}"] = tracker.mark(key)
            if key in self.types:
                out[f"pm{n}"] = self.pmin(key)
            else:
                out[f"dl{n}"] = tracker.delay(key)
                out[f"le{n}"] = tracker.latest_end(key) if tracker.in_order(key) else -_INF
        return out

    def pmin(self, key: tuple[str, int]) -> float:
        return min((rt.pmin for rt in self.by_head.get(key, ())), default=_INF)

    def complete(self, key: tuple[str, int], z: float, now: float | None = None,
                 through: bool = True) -> bool:
        """Is the history of ``key`` complete up to ``z``: through z (no event ending at or
        before z can still come), or with ``through=False`` before z (none ending before
        z)? The two differ for an in_order type at the end of its newest event: a later
        event of it ends there at the earliest, so it is complete before that end, not
        through it (docs/events.md, "in_order and ties"). For a complex event type: a mark
        says so, or every type its events are made of is complete up to z (through z for
        the types whose events may end a match, :meth:`EventRule.closing_types`) and no
        pending decision ends at or before z (before z: no pending decision ends before
        z). Exactly :meth:`complete_sql`."""
        tracker = self.tracker
        if tracker is None:
            return True
        if key not in self.types:
            return tracker.complete(key, z, now) or (
                not through and tracker.in_order(key) and z <= tracker.latest_end(key))
        if z <= tracker.mark(key):
            return True
        if now is None:
            now = float(self.clock.now())
        closing = self.closing.get(key, ())
        for t in self.inputs[key]:
            if not self.complete(t, z, now, through and t in closing):
                return False
        return z < self.pmin(key) if through else z <= self.pmin(key)

    def horizon(self, key: tuple[str, int], now: float | None = None) -> float:
        tracker = self.tracker
        if now is None:
            now = float(self.clock.now())
        h = min([tracker.horizon(t, now) for t in self.inputs[key]] + [self.pmin(key)])
        return max(h, tracker.mark(key))

    def deadline(self, key: tuple[str, int], z: float) -> float:
        """When the clock alone makes ``key`` complete up to ``z``: once its inputs are, if
        no decision up to z is pending (a pending decision releases waiting queries through
        :meth:`recheck` when it is made, not by a timer)."""
        if self.pmin(key) <= z:
            return _INF
        return max((self.tracker.deadline(t, z) for t in self.inputs[key]), default=_INF)

    def why(self, key: tuple[str, int], z: float, now: float) -> str:
        if z <= self.tracker.mark(key):
            return self.tracker.mark_src.get(key) or f"a mark >= {_fmt(z)}"
        reads = ", ".join(_type(t) for t in self.inputs[key])
        return (f"{reads} complete up to {_fmt(z)} and every decision of its event rules up "
                f"to {_fmt(z)} made")

    def describe(self, key: tuple[str, int], now: float | None = None) -> str:
        if now is None:
            now = float(self.clock.now())
        parts = [f"complex event type of {len(self.by_head[key])} event "
                 f"rule{'s' if len(self.by_head[key]) != 1 else ''}"]
        for t in self.inputs[key]:
            parts.append(f"{_type(t)} complete up to {_fmt(self.tracker.horizon(t, now))}")
        pending = sum(rt.pending for rt in self.by_head[key])
        if pending:
            parts.append(f"{pending} pending decision{'s' if pending != 1 else ''} from "
                         f"{_fmt(self.pmin(key))}")
        return "; ".join(parts)

    # ----------------------------------------------------------------- rounds
    def _max_seq(self, key: tuple[str, int]) -> int:
        table = self.table(key)
        if table is None:
            return 0
        return self.store.run_compiled(max_seq(table), {})[0][0]

    def _watermarks(self, keys: set) -> _AddToken:
        """Where the new rows of an add of the types ``keys`` will start, and of the complex
        types the rules read, and the provenance id after which the matches of each rule
        the add may run will come: one statement (one round trip to a server) instead of
        one per type and per rule."""
        derived = [key for key in self.types & self.leaf_types if key not in keys]
        types = [key for key in list(keys) + derived if self.table(key) is not None]
        reach = set(keys)
        runs = []
        tables = set()
        for rt in self.rules:   # (in dependency order: a head feeds the rules after it)
            if any(k in reach for k in rt.rule.input_types()):
                reach.add(rt.head_key)
                if rt.prov not in tables:   # (a rule given twice reads its own, later)
                    tables.add(rt.prov)
                    runs.append(rt)
        values = self.store.run_compiled(
            watermarks([self.table(key) for key in types], [rt.prov for rt in runs]),
            {})[0] if types or runs else ()
        seqs = dict.fromkeys(keys, 0)
        seqs.update(zip(types, values))
        return _AddToken({key: seqs[key] for key in keys},
                         {key: seqs[key] for key in derived},
                         dict(zip(runs, values[len(types):])))

    def before_add(self, events: list) -> Any:
        """Inside the add's transaction, before the events are stored: where each type's
        new rows will start."""
        if not self.active or not events:
            return None
        leaf = self.leaf_types
        try:   # (column-wise: no loop in Python over a big batch)
            keys = set(zip(map(_first, events), map(len, map(_second, events)))) & leaf
        except (TypeError, IndexError, KeyError):
            keys = set()
            for ev in events:
                try:
                    key = (ev[0], len(ev[1]))
                    if key in leaf:  # (an unhashable name: the store rejects that event)
                        keys.add(key)
                except (TypeError, IndexError, KeyError):
                    continue
        if not keys:
            return None
        self.store.lock_for_write(keys)   # before the watermarks: see set_write_groups
        token = self._watermarks(keys)
        token.events = events
        return token

    def store_events(self, events: list, atomic: bool) -> list:
        """``store.add_events``, joining the round's transaction (the pipeline's, which any
        error leaves through) with no savepoint of its own. (The store takes an
        interleaved stream -- a, b, a, b -- one insert per type, each type's rows in their
        order: no grouping is needed here.)"""
        return self.store.add_events(events, atomic=atomic, join=True)

    def rounds(self, events: list) -> list[tuple[int, int]]:
        """Where a batch must be cut into rounds so that it derives what its events added one
        by one derive (SPEC §6): before each event of a type a rule's event atoms read and a
        count buffer prunes as rows go in (its insert may prune a row an earlier event of
        the batch still pairs with). One round, ``[(0, len)]``, when no buffer meets a rule.

        >>> import slr_sql
        >>> kb = slr_sql.open(); kb.load("c(X) <- a(X) seq b(X).\\ncBuffer(a(_), 2).")
        >>> kb._cep.rounds([("a", (1,), 1.0, 1.0), ("b", (1,), 2.0, 2.0), ("a", (1,), 3.0, 3.0)])
        [(0, 2), (2, 3)]
        """
        whole = [(0, len(events))]
        if len(events) < 2 or not self.leaf_types or not self.store.has_active_buffer("cBuffer"):
            return whole
        pruned = {(row["type_name"], row["type_arity"]) for row in self.store.buffer_rows()
                  if row["kind"] == "cBuffer"} & self.leaf_types
        if not pruned:
            return whole
        cuts = []
        for i, ev in enumerate(events):
            try:
                key = (ev[0], len(ev[1]))
            except (TypeError, IndexError, KeyError):
                continue
            if i and key in pruned:
                cuts.append(i)
        return list(pairwise([0] + cuts + [len(events)]))

    def after_add(self, token: Any) -> list:
        """Inside the add's transaction, after the events are stored: the round. Returns
        the complex events derived."""
        if not token:
            return []
        # the stored events' earliest and latest ends per type (store_events describes the
        # batch it stored; a plain list is not described)
        ends = getattr(token.events, "ends", None)
        return self._round(dict(token.seqs), set(token.seqs), False,
                           dict(ends) if ends is not None else None, token)

    def _round(self, new_from: dict, dirty: set, decide: bool, ends: dict | None = None,
               token: _AddToken | None = None, ran: list | None = None) -> list:
        """One round of the rules: each whose input changed (``dirty``), or with decisions
        pending when ``decide``, derives what it can; their rows join the transaction
        around. ``ran``: the rules that ran are appended to it."""
        self._read_stale_summaries()
        now = float(self.clock.now())
        for key in self.types & self.leaf_types:
            if key not in new_from:
                new_from[key] = token.derived[key] if token is not None \
                    and key in token.derived else self._max_seq(key)
        derived: list = []
        for rt in self.rules:
            if not decide and not (rt.rule.input_types() and
                                   any(k in dirty for k in rt.rule.input_types())):
                continue
            if decide and not rt.waits and not any(k in dirty
                                                   for k in rt.rule.input_types()):
                continue
            if ran is not None:
                ran.append(rt)
            try:
                out = rt.run(new_from, dirty, now, decide, ends,
                             token.before.get(rt) if token is not None else None)
            except (DatabaseError, SLRError) as exc:
                # (kept on the rule: after an add, whose events are committed, a failed
                # decision round is not raised -- its decisions stay pending -- and this
                # says why, in kb.event_rules())
                if not isinstance(exc, DatabaseError):
                    # the store's words for its file (the disk full, the store busy or gone),
                    # or a where goal that could not be asked: raised as they are (retryable)
                    rt.last_error = f"the round rolled back: {describe_error(exc)}"
                    raise
                rt.last_error = f"its statements failed, the round rolled back: {exc}"
                raise SLRError(f"event rule {rt.rule.text} ({rt.rule.source}): {exc}") \
                    from None
            if out:
                dirty.add(rt.head_key)
                derived += out
                if ends is not None and rt.head_key in self.leaf_types:
                    # the head's new rows, for the rules after this one: these (and any added)
                    lo, hi = min(map(_end_of, out)), max(map(_end_of, out))
                    known = ends.get(rt.head_key)
                    ends[rt.head_key] = (lo, hi) if known is None else \
                        (min(known[0], lo), max(known[1], hi))
        return derived

    def reread_pending(self, now: bool = False) -> None:
        """Read every rule's summary of its pending decisions again before the next
        decision: after a rollback (what they were read after may be undone), or when a mark
        moved completeness, which may complete the decisions another connection left pending
        (this one's summaries know only its own). ``now``: read them at once -- before
        marks raised without a mark's pipeline are re-read (a fleet store's shipments and
        retirements), which releases the queries on the complex types whose pending
        decisions this connection would not know of yet."""
        self._summaries_stale = True
        if now:
            self._read_stale_summaries()

    def _forget_statements(self) -> None:
        """After a rollback that may have taken back a start-ordered index: every
        alternative's statements built again when next used."""
        undone = self.store.start_order_builds_undone
        if undone == self._builds_undone:
            return
        self._builds_undone = undone
        for rt in self.rules:
            for alt in rt.alts:
                alt.forget_statements()

    def _read_stale_summaries(self) -> None:
        """After a rollback or a mark: every rule's summary of its pending decisions read
        again."""
        if self._summaries_stale:
            with self.store.lock:
                rules = self.rules
                for rt in rules:
                    rt._forget_unsent()
                # (one call of the store for them all: one round trip to a server)
                rows = self.store.run_compiled_batch(
                    [(pending_summary(self.store.dialect), {"rule": rt.key}, False)
                     for rt in rules]) \
                    if rules else []
                for rt, summary in zip(rules, rows):
                    rt._summary(summary)
                self._summaries_stale = False

    def _others_committed(self, now: float) -> None:
        """Mark the summaries stale when another connection committed since the last look
        (it may have left decisions pending; its own summaries are not ours)."""
        self._others_looked_at = now
        version = self.store.others_version()
        if version != self._others_version:
            self._others_version = version
            self._summaries_stale = True

    def ready(self, now: float, added: bool = False) -> bool:
        """Can some pending decision be made at ``now`` (its histories are complete)?
        ``added``: after an add (which looks whether another connection committed; a clock
        move looks once the clock moved on by :data:`OTHERS_LOOK` since the last look)."""
        if self._watch_others:
            last = self._others_looked_at
            if added or last is None or not 0.0 <= now - last < OTHERS_LOOK:
                self._others_committed(now)
        self._read_stale_summaries()
        for rt in self.rules:
            if rt.waits and rt.ready_groups(now):
                return True
        return False

    def decide(self) -> list:
        """One round of the pending decisions that can be made now, in a transaction of its
        own (the event pipeline's decision stage). Returns the complex events derived."""
        ran: list[RuleRuntime] = []
        derived: list | None = None
        try:
            with self.store.transaction():
                self.store.lock_for_write(self.types | self.leaf_types)
                # (no new rows but those derived)
                derived = self._round({}, set(), True, {}, ran=ran)
        except SLRError as exc:
            if derived is not None:
                # the round's statements ran and its commit was refused (a full disk meets
                # the write-ahead log only now): the rules that decided in it say why, as
                # when their statements fail (kb.event_rules(); the caller after an add
                # does not raise it)
                why = f"the round rolled back: {describe_error(exc)}"
                for rt in ran:
                    rt.last_error = why
            raise
        return derived

    def recheck(self) -> None:
        """Synchronized queries waiting on a complex event type: release those that can go."""
        if self.sync is not None and self.types:
            self.sync.recheck(self.types)

    def wake_if_due(self) -> None:
        """Ask for the timers of rules installed since, unless this thread holds the store's
        lock (a load's transaction: the load asks once it committed)."""
        if self._wake_due and not self.store.owns_lock():
            self.wake_timers()

    def wake_timers(self) -> None:
        """Ask the synchronizer's timer to call us when a pending decision's history will be
        complete by the clock (wall clock; clocks that tell when they move need no timer)."""
        self._wake_due = False
        if self.sync is None:
            return
        due: dict = {}
        for rt in self.rules:
            for (n, kind, wait), t in rt.waits.items():
                if wait is not None:
                    keys = [wait]
                elif n < len(rt.rule.alternatives):
                    # (a term decision: what it waits for, chronological's other
                    # alternatives' terminators included)
                    keys = list(rt.decisions[n]) if kind in ("term", "span") else \
                        [leaf.key for _, leaf in rt.rule.alternatives[n].negations]
                else:
                    keys = []
                for key in keys:
                    if key not in self.types and t < due.get(key, _INF):
                        due[key] = t
        for key, t in due.items():   # the earliest time per type (the next wake asks again)
            if self._woken.get(key) != t:
                self._woken[key] = t
                self.sync.wake_at(key, t)

    def close(self) -> None:
        self.closed = True

    # ----------------------------------------------------------------- inspection
    def infos(self) -> list[dict]:
        self.sync_rules()
        # (after a rolled-back round the counts in memory may be those it took back)
        self._read_stale_summaries()
        out = []
        for rt in self.rules:
            rule = rt.rule
            out.append({"head": _type(rt.head_key), "rule": rule.text,
                        "pattern": format_term(rule.pattern, priority=1199),
                        "policy": rt.policy, "program": rule.program,
                        "source": rule.source, "line": rule.line,
                        "key": rt.key, "table": self.store.table_for(*rt.head_key),
                        "provenance": rt.prov_name, "detections": rt.detections,
                        "pending": rt.pending, "errors": rt.errors,
                        "last_error": rt.last_error})
        return out

    def explain_rule(self, rt: RuleRuntime) -> list[str]:
        rt.ensure_built()
        rule = rt.rule
        lines = [f"event rule {rule.text}   ({rule.source})",
                 f"  derives {_type(rt.head_key)} (table {self.store.table_for(*rt.head_key)}; "
                 f"each match recorded in {rt.prov_name}), consumption policy {rt.policy}"]
        for n, alt in enumerate(rt.alts):
            leaves = ", ".join(f"{p}: {leaf.text}" for p, leaf in enumerate(alt.alt.leaves))
            lines.append(f"  alternative {n + 1}: positions {leaves}")
            s, e = alt.alt.interval
            lines.append(f"    interval of the complex event: [{_show(s)}, {_show(e)}]")
            for (_, seconds, _) in alt.alt.windows:
                lines.append(f"    within {_fmt(seconds)} s: the search window of every "
                             f"delta statement")
            if alt.pushed:
                lines.append("    where, in SQL: " + ", ".join(format_term(g)
                                                               for g in alt.pushed))
            if alt.quiet:
                lines.append("    where, first, per candidate in Python (SQLite decides it in "
                             "SQL; an error is no match): "
                             + ", ".join(format_term(g) for g in alt.quiet))
            if alt.residual:
                how = "reads the store: decided once its goal set and prev/next are complete " \
                      "up to the match's end" if rt.reads_store[n] else \
                      "reads no stored event: run at once"
                lines.append("    where, per candidate (compiled SQL or the interpreter): "
                             + ", ".join(format_term(g) for g in alt.residual) + f" -- {how}")
            for _, leaf in alt.alt.negations:
                lines.append(f"    cnot {leaf.text}: decided once {leaf.name}/{leaf.arity} "
                             f"is complete up to the end of the interval; until then the "
                             f"candidate waits in slr_cep_pending")
            if rt.policy != "unrestricted":
                terms = ", ".join(str(p) for p in sorted(alt.alt.terminators))
                through = [_type(k) for k, t in alt.decision.items() if t]
                before = [_type(k) for k, t in alt.decision.items() if not t]
                lines.append(f"    {rt.policy}: a row at position {terms} ends a match; it "
                             f"is decided once every input type is complete up to its end "
                             f"(through its end: {', '.join(through) or 'none'}; before "
                             f"it: {', '.join(before) or 'none'})")
            if not alt.runnable:
                missing = [leaf.text for leaf, t in zip(alt.alt.leaves, alt.tables)
                           if t is None]
                lines.append("    no statement yet: no event of " + ", ".join(missing)
                             + " has been stored")
                continue
            dirty = {leaf.key for leaf in alt.alt.leaves}
            for pos in range(alt.k):
                if rt.policy == "unrestricted":
                    if alt.pure and not rt.reads_store[n]:
                        sql = alt.delta_insert(pos, dirty)
                    else:
                        sql = alt.delta_select(pos, dirty)
                    lines.append(f"    delta SQL when position {pos} "
                                 f"({alt.alt.leaves[pos].text}) has new rows:")
                elif pos in alt.alt.terminators:
                    if rt.policy == "recent" and alt.pure:
                        sql = alt.recent_insert(pos)
                        lines.append(f"    SQL when position {pos} ({alt.alt.leaves[pos].text}) "
                                     f"has new rows (terminators complete now):")
                        lines.extend("      " + line for line in _wrap(sql))
                        lines.extend("      plan: " + step
                                     for step in self._query_plan_lines(alt, sql))
                        # (an add none of whose terminators is complete keeps them as a span)
                        sql = alt.span_recent_insert(pos)
                        lines.append(f"    SQL deciding the spans of position {pos} kept in "
                                     f"slr_cep_pending (an add's terminators, none complete "
                                     f"then), once complete:")
                    else:
                        sql = alt.term_select(pos, alt.pure)
                        lines.append(f"    SQL deciding a terminator :t at position {pos}:")
                else:
                    continue
                lines.extend("      " + line for line in _wrap(sql))
                lines.extend("      plan: " + step for step in self._query_plan_lines(alt, sql))
        closing = self.closing.get(rt.head_key, ())
        lines.append(f"  {_type(rt.head_key)} is complete up to z once "
                     + ", ".join(_type(t) + ("" if t in closing else " (before z)")
                                 for t in self.inputs.get(rt.head_key, ()))
                     + " are complete up to z and no pending decision ends at or before z")
        lines.append(f"  now: {rt.detections} detections in this session, {rt.pending} "
                     f"pending, {rt.errors} rejected by errors"
                     + (f" (last: {rt.last_error})" if rt.last_error else ""))
        return lines

    def _query_plan_lines(self, alt: AltSQL, sql: str) -> list[str]:
        """The database's query plan of a statement (how the indexes bound it): SQLite's
        ``EXPLAIN QUERY PLAN`` steps, PostgreSQL's ``EXPLAIN`` lines (it has no ``EXPLAIN
        QUERY PLAN``: asked that, every plan of an explained rule read as a syntax error)."""
        params = self.params(float(self.clock.now()))
        params.update(alt.params)
        params.update({f"w{p}": 0 for p in range(alt.k)})
        params.update({f"r{p}": 0 for p in range(alt.k)})
        params.update(rule="", t=0)
        sqlite = self.store.dialect.name == "sqlite"
        try:
            rows = self.store.run_compiled(
                query_plan(sql) if sqlite else "EXPLAIN (COSTS OFF) " + sql, params)
        except DatabaseError as exc:  # pragma: no cover - explain must not fail
            return [f"(no plan: {exc})"]
        return [row[3] if sqlite else row[0] for row in rows]

    def explain(self, goal: str) -> tuple[bool, list[str]] | None:
        """How the event rules behind ``goal`` run: ``(True, lines)`` for a rule's text,
        ``(False, lines)`` for a goal on a complex event type, None otherwise."""
        from ..parser import parse_program, parse_term
        from .rules import compile_rule, is_event_rule, order_rules

        self.sync_rules()
        try:
            term, _ = parse_term(goal, "<explain>")
        except SLRError:
            return None
        if is_event_rule(term):
            clause = parse_program(goal.rstrip().rstrip(".") + " .", "<explain>")[0]
            rule = compile_rule(clause)
            consumption = self.kb.declarations.consumption
            # the loaded rule of this text under the policy of the program holding it; if
            # none, the rule as kb.load would add it to its default program, main
            for program in sorted({rt.rule.program for rt in self.rules}) + ["main"]:
                rule.program = program
                order_rules([rule], consumption)
                for rt in self.rules:
                    if rt.key == rule.key:
                        return True, self.explain_rule(rt)
            rt = RuleRuntime(self, rule)
            return True, ["(not loaded: how it would run)"] + self.explain_rule(rt)
        t = deref(term)
        if type(t) is Struct and t.name == "^" and len(t.args) == 2:
            t = deref(t.args[0])
        if type(t) is not Struct and not isinstance(t, str):
            return None  # a number or a variable: never an event type
        key = (str(t.name), len(t.args)) if type(t) is Struct else (str(t), 0)
        if key not in self.by_head:
            return None
        lines = [f"{_type(key)} is a complex event type, derived by "
                 f"{len(self.by_head[key])} event rule(s):"]
        for rt in self.by_head[key]:
            lines += self.explain_rule(rt)
        return False, lines


def _show(e: tuple) -> str:
    if e[0] == "s":
        return f"start of {e[1]}"
    if e[0] == "e":
        return f"end of {e[1]}"
    return f"{e[0]}({_show(e[1])}, {_show(e[2])})"


def _wrap(sql: str) -> list[str]:
    """Break a long statement at its clauses, for explain."""
    out = []
    for part in sql.replace(" FROM ", "\nFROM ").replace(" WHERE ", "\nWHERE ") \
            .replace(" ORDER BY ", "\nORDER BY ").split("\n"):
        out.append(part)
    return out


def _rule_groups(runtimes: list) -> list[set]:
    """The event types rules tie together (head, positive and negated atoms), merged into
    groups: two rules sharing a type are one group."""
    groups: list[set] = []
    for rt in runtimes:
        types = {rt.head_key}
        for alt in rt.rule.alternatives:
            types |= {leaf.key for leaf in alt.leaves}
            types |= {leaf.key for _, leaf in alt.negations}
        joined = [g for g in groups if g & types]
        for g in joined:
            groups.remove(g)
            types |= g
        groups.append(types)
    return groups


def ready_prefix(rows: list, ready: Callable[[float], bool], seen: set) -> list:
    """The leading rows of ``rows`` (pending rows ``(id, .., t_end at [6], ..)`` in
    ascending end time) that are ``ready`` at their end, up to the first that is not -- as a
    walk checking each in turn finds them; ``seen`` gets what that walk sees: those and the
    first row not ready. Readiness only shrinks as the end time grows (a history complete
    up to z is complete up to any earlier time), so the last row is checked first (usually
    all are ready) and otherwise the first row not ready is found by bisection: a few checks
    of the trackers instead of one per row.

    >>> rows = [(i, None, None, None, None, None, float(i)) for i in range(1, 9)]
    >>> seen = set(); [r[0] for r in ready_prefix(rows, lambda t: t < 5.5, seen)], sorted(seen)
    ([1, 2, 3, 4, 5], [1, 2, 3, 4, 5, 6])
    """
    if not rows:
        return []
    end = 6
    if ready(rows[-1][end]):
        k = len(rows)
    else:
        lo, hi = 0, len(rows) - 1  # rows[hi] is not ready; rows[:lo] are
        while lo < hi:
            mid = (lo + hi) // 2
            if ready(rows[mid][end]):
                lo = mid + 1
            else:
                hi = mid
        k = lo
    seen.update(row[0] for row in rows[:k + 1])
    return rows[:k]
