"""Event-history management: tBuffer, cBuffer and runtime history policies (docs/buffers.md).

* ``tBuffer(P, D)`` — events matching P are kept while ``end >= now - D`` (now: the store clock).
* ``cBuffer(P, N)`` — for each distinct value of P's named variables, only the last N matching
  events (by end time, then start time, then arrival: store order) are kept; ``_`` parts (and
  variables whose name starts with ``_``) are pooled.
* runtime policies (event-processing paper, section III) through :meth:`KnowledgeBase.add_buffer`:
  ``keep_last=N`` (a cBuffer), ``keep_seconds=L`` (a tBuffer), ``keep_between=(T1, T2)`` (a
  *window*: keep the events whose occurrence ``[start, end]`` lies inside ``[T1, T2]``).

Everything is done by SQLite triggers generated here from the pattern, so pruning also holds
for rows other tools insert through SQL:

* ``slr_buf_<id>_late`` (BEFORE INSERT on the type's table): an event that the buffer would not
  keep even on arrival (older than now - D; N newer events of its key already stored; outside
  the window) is counted in ``slr_counters.dropped`` and not stored (``RAISE(IGNORE)``).
* ``slr_buf_<id>_keep`` (cBuffer, AFTER INSERT): deletes the rows of the new row's key beyond
  the N newest, counting them in ``slr_counters.pruned``.
* ``slr_buf_<id>_tick`` (tBuffer, AFTER UPDATE OF now ON slr_clock): deletes the rows that
  expired, whenever "now" moves (the store records it on every add batch; the clock listener
  installed by :func:`attach` records it on every ManualClock / StreamClock move).

Matching is compiled from the pattern: constant arguments are compared as SQL literals
(:func:`slr_sql.store.sql_literal` — the one place literals appear in slr_sql's SQL, because
trigger bodies cannot have bound parameters), compound arguments are tested through SQLite's
JSON functions on the documented column encoding (``json_extract(arg1, '$."face"[0]')``), and
the cBuffer key is the list of (value, type) expressions of the named variables.

This module does not touch SQLite itself: every statement goes through
:class:`slr_sql.store.EventStore` methods.
"""
from __future__ import annotations

import math
import numbers
import threading
from dataclasses import dataclass, field
from typing import Any, Iterable

from .clocks import parse_duration
from .encoding import INT64_MAX, INT64_MIN, Unencodable, encode
from .unify import copy_term, undo, unify
from .errors import SLRError
from .host import Host
from .terms import format_term
from .program import event_key, split_event_atom
from .store import quote_identifier, sql_literal
from .store.checks import shown
from .terms import NIL, Atom, String, Struct, Var, deref, is_ground, list_items

__all__ = ["Pattern", "BufferSpec", "BufferInfo", "analyze", "attach", "conflicts",
           "trigger_sql", "KINDS"]

KINDS = ("tBuffer", "cBuffer", "window")

# The row prefix placeholder in generated conditions: "" (the scanned row) or "NEW.".
# sql_literal refuses NUL characters, so the placeholder never occurs inside a literal.
_ROW = "\x00"
_ORDER_DESC = "t_end DESC, t_start DESC, seq DESC"


# ----------------------------------------------------------------------------- analysis

@dataclass
class Pattern:
    """A buffer pattern compiled to SQL pieces over one event type's table.

    ``conds`` are SQL conditions (with the row placeholder) that hold exactly for the rows
    whose event unifies with the pattern; ``keys`` are the (value, type) SQL expressions of
    the pattern's named variables (first occurrences): the cBuffer key.
    """

    term: Any
    name: str
    arity: int
    text: str
    conds: list[str] = field(default_factory=list)
    keys: list[tuple[str, str]] = field(default_factory=list)
    key_columns: list[tuple[int, str | None]] = field(default_factory=list)

    def match(self, row: str = "") -> str:
        """The match condition for the scanned row (``""``) or ``"NEW."``; ``1`` if none."""
        if not self.conds:
            return "1"
        return " AND ".join(c.replace(_ROW, row) for c in self.conds)

    def key_equal(self) -> str:
        """Condition: the scanned row has the same key as NEW."""
        parts = []
        for value, vtype in self.keys:
            parts.append(f"{value.replace(_ROW, '')} = {value.replace(_ROW, 'NEW.')}")
            parts.append(f"{vtype.replace(_ROW, '')} = {vtype.replace(_ROW, 'NEW.')}")
        return " AND ".join(parts) if parts else "1"


def _strip_time(term: Any) -> Any:
    term = deref(term)
    ev = split_event_atom(term)
    if ev is None:
        return term
    atom, start, end = ev
    for stamp in (start, end):
        if type(deref(stamp)) is not Var:
            raise SLRError(f"buffer pattern {format_term(term)}: the time stamp must be a "
                           "variable (buffers select events by their arguments)")
    return deref(atom)


def _anonymous(var: Var) -> bool:
    return var.name.startswith("_")


def _path_key(name: str) -> str:
    bad = [c for c in name if c in '"\\' or ord(c) < 0x20]
    if bad:
        raise SLRError(f"buffer patterns cannot look inside compounds named {name!r} "
                       "(quotes, backslashes and control characters cannot be written in a "
                       "JSON path)")
    return f'."{name}"'


class _Analyzer:
    def __init__(self) -> None:
        self.conds: list[tuple[tuple[int, ...], str]] = []   # (guarded columns, condition)
        self.keys: list[tuple[str, str]] = []
        self.key_columns: list[tuple[int, str | None]] = []
        self.first: dict[int, tuple[int, str | None]] = {}

    @staticmethod
    def col(i: int) -> str:
        return f"{_ROW}arg{i}"

    @staticmethod
    def guard(i: int) -> str:
        c = _Analyzer.col(i)
        return (f"typeof({c}) = 'text' AND substr({c}, 1, 1) IN ('[', '{{') "
                f"AND json_valid({c})")

    def value(self, i: int, path: str | None) -> str:
        c = self.col(i)
        if path is None:
            return c
        return f"CASE WHEN {self.guard(i)} THEN json_extract({c}, {sql_literal(path)}) END"

    def vtype(self, i: int, path: str | None) -> str:
        c = self.col(i)
        if path is None:
            return f"typeof({c})"
        return f"CASE WHEN {self.guard(i)} THEN json_type({c}, {sql_literal(path)}) END"

    def add(self, cols: tuple[int, ...], cond: str) -> None:
        self.conds.append((cols, cond))

    def top(self, i: int, t: Any) -> None:
        t = deref(t)
        if type(t) is Var:
            self.var(t, i, None)
            return
        if is_ground(t):
            c = self.col(i)
            try:
                value = encode(t)
            except Unencodable as exc:
                raise SLRError(f"buffer pattern constant cannot be stored: {exc.reason}")
            if type(value) is int:
                self.add((), f"({c} = {sql_literal(value)} AND typeof({c}) = 'integer')")
            elif type(value) is float:
                self.add((), f"({c} = {sql_literal(value)} AND typeof({c}) = 'real')")
            else:
                self.add((), f"{c} = {sql_literal(value)}")
            return
        self.nested(i, t, "$")

    def nested(self, i: int, t: Any, path: str) -> None:
        t = deref(t)
        tt = type(t)
        c = self.col(i)
        p = sql_literal(path)
        if tt is Var:
            self.var(t, i, path)
        elif tt is Atom:
            if t == NIL:
                self.add((i,), f"json_type({c}, {p}) = 'array' AND json_array_length({c}, {p}) = 0")
            else:
                self.add((i,), f"json_type({c}, {p}) = 'text' AND json_extract({c}, {p}) = "
                               f"{sql_literal(str(t))}")
        elif tt is int:
            if INT64_MIN <= t <= INT64_MAX:
                self.add((i,), f"json_type({c}, {p}) = 'integer' AND json_extract({c}, {p}) = "
                               f"{sql_literal(t)}")
            elif t.bit_length() > 14000:  # more digits than a stored event may hold
                raise SLRError("buffer pattern constant cannot be stored: integer too large to "
                               "be stored (more than 4300 digits)")
            else:
                self.tagged(i, path, "$int", str(t))
        elif tt is float:
            if t != t:
                raise SLRError("buffer pattern constant cannot be NaN")
            self.add((i,), f"json_type({c}, {p}) = 'real' AND json_extract({c}, {p}) = "
                           f"{sql_literal(t)}")
        elif tt is String:
            self.tagged(i, path, "$string", str(t))
        elif tt is Struct:
            if t.name == "." and len(t.args) == 2:
                items, tail = list_items(t)
                if type(tail) is Atom and tail == NIL:
                    self.add((i,), f"json_type({c}, {p}) = 'array' AND "
                                   f"json_array_length({c}, {p}) = {len(items)}")
                    for k, item in enumerate(items):
                        self.nested(i, item, f"{path}[{k}]")
                    return
                if type(tail) is Var:
                    if not _anonymous(tail) or id(tail) in self.first:
                        raise SLRError("buffer patterns cannot bind a list tail to a named "
                                       f"variable ({tail.name}); use _ for the tail")
                    self.first[id(tail)] = (i, None)
                    self.add((i,), f"json_type({c}, {p}) = 'array' AND "
                                   f"json_array_length({c}, {p}) >= {len(items)}")
                    for k, item in enumerate(items):
                        self.nested(i, item, f"{path}[{k}]")
                    return
                # an improper list [a|b] is stored as the compound '.'(a, b): fall through
            if "/" in str(t.name):
                raise SLRError(f"buffer patterns cannot look inside compounds named {t.name!r} "
                               f"(a message type: messages are stored as objects of fields); "
                               f"write _ or a variable for the message")
            inner = path + _path_key(str(t.name))
            q = sql_literal(inner)
            self.add((i,), f"json_type({c}, {q}) = 'array' AND "
                           f"json_array_length({c}, {q}) = {len(t.args)}")
            for k, arg in enumerate(t.args):
                self.nested(i, arg, f"{inner}[{k}]")
        else:
            raise SLRError(f"unsupported term in a buffer pattern: {shown(t)}")

    def tagged(self, i: int, path: str, tag: str, text: str) -> None:
        c = self.col(i)
        q = sql_literal(path + _path_key(tag))
        self.add((i,), f"json_type({c}, {q}) = 'text' AND json_extract({c}, {q}) = "
                       f"{sql_literal(text)}")

    def var(self, v: Var, i: int, path: str | None) -> None:
        if v.name == "_":
            return
        first = self.first.get(id(v))
        if first is None:
            self.first[id(v)] = (i, path)
            if not _anonymous(v):
                self.keys.append((self.value(i, path), self.vtype(i, path)))
                self.key_columns.append((i, path))
            return
        j, other = first
        if (path is None) != (other is None):
            if path is None:
                self.add((j,), self.mixed_equal(i, j, other))
            else:
                self.add((i,), self.mixed_equal(j, i, path))
            return
        cols = tuple(sorted({i, j})) if path is not None else ()
        self.add(cols, f"{self.value(i, path)} = {self.value(j, other)} AND "
                       f"{self.vtype(i, path)} = {self.vtype(j, other)}")

    def mixed_equal(self, i: int, j: int, path: str) -> str:
        """Column i (a whole argument, top-level encoding) holds the same term as the JSON
        value at ``path`` in column j (inside-JSON encoding): one case per kind of term."""
        a = self.col(i)
        b = self.col(j)
        p = sql_literal(path)
        tag = lambda key: sql_literal(path + _path_key(key))  # noqa: E731
        first = f"substr({a}, 1, 1)"
        quote = sql_literal('"')
        atom = sql_literal('$."$atom"')
        return (
            f"(CASE typeof({a})"
            f" WHEN 'integer' THEN json_type({b}, {p}) = 'integer' AND json_extract({b}, {p}) = {a}"
            f" WHEN 'real' THEN json_type({b}, {p}) = 'real' AND json_extract({b}, {p}) = {a}"
            f" WHEN 'text' THEN CASE"
            f" WHEN {first} = {quote} AND json_valid({a}) THEN json_type({b}, {tag('$string')})"
            f" = 'text' AND json_extract({b}, {tag('$string')}) = json_extract({a}, '$')"
            f" WHEN {first} IN ('[', '{{') AND json_valid({a}) THEN CASE"
            f" WHEN json_type({a}, {atom}) = 'text' THEN json_type({b}, {p}) = 'text' "
            f"AND json_extract({b}, {p}) = json_extract({a}, {atom})"
            f" ELSE json({a}) = ({b} -> {p}) END"
            f" WHEN {first} IN ('[', '{{', {quote}) THEN 0"
            f" ELSE json_type({b}, {p}) = 'text' AND json_extract({b}, {p}) = {a} END"
            f" ELSE 0 END)")

    def finish(self) -> list[str]:
        """Group conditions by their JSON guards: ``CASE WHEN guards THEN conds ELSE 0 END``
        (SQLite does not promise left-to-right AND, and json_* functions raise on text that
        is not JSON, so JSON tests only run on rows whose column holds JSON)."""
        groups: dict[tuple[int, ...], list[str]] = {}
        for cols, cond in self.conds:
            groups.setdefault(cols, []).append(cond)
        out = []
        for cols, conds in groups.items():
            body = " AND ".join(conds)
            if cols:
                guards = " AND ".join(self.guard(i) for i in cols)
                out.append(f"(CASE WHEN {guards} THEN ({body}) ELSE 0 END)")
            else:
                out.append(body if len(conds) == 1 else f"({body})")
        return out


def analyze(pattern: Any) -> Pattern:
    """Compile a buffer pattern (an event atom, optionally stamped ``^T``).

    >>> from slr_sql.parser import parse_term
    >>> p = analyze(parse_term("inView(face(P, _))", "x")[0])
    >>> (p.name, p.arity, p.text, len(p.keys))
    ('inView', 1, 'inView(face(P,_))', 1)
    """
    atom = _strip_time(pattern)
    if type(atom) not in (Struct, Atom):
        raise SLRError(f"a buffer pattern must be an event term, not {format_term(atom)}")
    name, arity = event_key(atom)
    args = atom.args if type(atom) is Struct else ()
    an = _Analyzer()
    for i, arg in enumerate(args, 1):
        an.top(i, arg)
    return Pattern(atom, name, arity, format_term(atom), an.finish(), an.keys, an.key_columns)


def unifiable(a: Any, b: Any) -> bool:
    """Whether two patterns unify (on renamed copies; nothing stays bound)."""
    trail: list = []
    try:
        return unify(copy_term(a), copy_term(b), trail)
    finally:
        undo(trail, 0)


# ----------------------------------------------------------------------------- specs

@dataclass
class BufferSpec:
    """One buffer: what it keeps, where it comes from."""

    kind: str                      # tBuffer | cBuffer | window
    pattern: Pattern
    amount: float | int | None     # seconds (tBuffer) or count (cBuffer)
    t1: float | None = None        # window bounds
    t2: float | None = None
    source: str = "program"        # program | runtime
    origin: str = ""               # "file:line" or "kb.add_buffer"
    id: int | None = None

    @property
    def label(self) -> str:
        if self.kind == "window":
            return f"keep_between({self.pattern.text}, [{_num(self.t1)}, {_num(self.t2)}])"
        if self.source == "runtime":
            policy = "keep_seconds" if self.kind == "tBuffer" else "keep_last"
            return f"{policy}({self.pattern.text}, {_num(self.amount)})"
        return f"{self.kind}({self.pattern.text}, {_num(self.amount)})"

    @property
    def where(self) -> str:
        if self.source == "runtime":
            return f"runtime buffer #{self.id} (kb.add_buffer)"
        return self.origin

    def identity(self) -> tuple:
        return (self.kind, self.pattern.text, float(self.amount) if self.amount is not None
                else None, self.t1, self.t2, self.source, self.origin)


def _num(x: Any) -> str:
    if x is None:
        return "_"
    if type(x) is float and x.is_integer() and math.isfinite(x):
        return str(int(x))
    if x == math.inf:
        return "inf"
    if x == -math.inf:
        return "-inf"
    return repr(x)


# The largest count a cBuffer may keep per key: slr_buffers stores the amount as a REAL, exact
# up to 2^53 (and a trigger's LIMIT must stay a 64-bit integer).
MAX_KEEP_LAST = 2 ** 53


def check_count(value: Any, what: str = "keep_last") -> int:
    """A cBuffer's count: an integer from 0 to :data:`MAX_KEEP_LAST`, else an SLRError in
    words.

    >>> check_count(5)
    5
    >>> check_count(10 ** 30)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: keep_last is out of range: at most 9007199254740992 events per key, not an integer of 31 digits
    """
    if type(value) is not int or value < 0:
        raise SLRError(f"{what} must be a non-negative integer, not {_shown(value)}")
    if value > MAX_KEEP_LAST:
        raise SLRError(f"{what} is out of range: at most {MAX_KEEP_LAST} events per key, not "
                       f"{_shown(value)}")
    return value


def check_seconds(value: Any, what: str = "keep_seconds") -> float:
    """A tBuffer's duration: a number of seconds >= 0 (``inf``: keep everything), else an
    SLRError in words.

    >>> check_seconds(2), check_seconds(float("inf"))
    (2.0, inf)
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value \
            or value < 0:
        raise SLRError(f"{what} must be a non-negative number of seconds, not {_shown(value)}")
    try:
        return float(value)
    except OverflowError:
        raise SLRError(f"{what} is out of range: {_shown(value)} is more seconds than a "
                       f"float holds (inf keeps everything)") from None


def check_time(value: Any, what: str) -> float:
    """A window bound: a number (``-inf``/``inf`` allowed), else an SLRError in words."""
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise SLRError(f"{what} must be a number, not {_shown(value)}") from None
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or value != value:
        raise SLRError(f"{what} must be a number, not {_shown(value)}")
    try:
        return float(value)
    except OverflowError:
        raise SLRError(f"{what} is out of range: {_shown(value)} is larger than a float "
                       f"holds (-inf/inf are the unbounded ends)") from None


def _shown(value: Any) -> str:
    """``repr`` for a message, short; an integer too long to print by its digit count."""
    if type(value) is int and value.bit_length() > 64:
        digits = len(str(abs(value))) if value.bit_length() < 14000 else \
            f"about {int(value.bit_length() * math.log10(2)) + 1}"
        return f"an integer of {digits} digits"
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a value that cannot print itself
        return f"a {type(value).__name__}"
    return text if len(text) <= 80 else text[:80] + "..."


def _lenient_amount(kind: str, amount: Any) -> Any:
    """The amount of a buffer read back from a store (or its stored program) that older
    versions accepted out of range: as the nearest bound that works (a count above
    :data:`MAX_KEEP_LAST` keeps that many, a duration beyond a float is ``inf``)."""
    if amount is None:
        return None
    if kind == "cBuffer":
        return min(int(amount), MAX_KEEP_LAST) if amount == amount else MAX_KEEP_LAST
    try:
        return float(amount)
    except OverflowError:
        return math.inf


@dataclass
class BufferInfo:
    """What :meth:`KnowledgeBase.buffers` returns for each active buffer."""

    id: int
    kind: str          # tBuffer | cBuffer | window
    pattern: str
    amount: float | int | None
    keep_between: tuple[float, float] | None
    source: str        # program | runtime
    origin: str
    pruned: int
    dropped: int

    def __str__(self) -> str:
        what = {"tBuffer": f"keep while end >= now - {_num(self.amount)}s",
                "cBuffer": f"keep the last {_num(self.amount)} per key",
                "window": (f"keep occurrences inside [{_num(self.keep_between[0])}, "
                           f"{_num(self.keep_between[1])}]" if self.keep_between else "")}
        return (f"#{self.id} {self.kind} {self.pattern}: {what[self.kind]} "
                f"({self.source}, {self.origin}; pruned {self.pruned}, dropped {self.dropped})")


def conflicts(specs: list[BufferSpec]) -> None:
    """Raise SLRError for the first two buffers whose patterns unify (SLR paper: an event
    matching both would be kept by one buffer and pruned by the other)."""
    for i, a in enumerate(specs):
        for b in specs[i + 1:]:
            if (a.pattern.name, a.pattern.arity) != (b.pattern.name, b.pattern.arity):
                continue
            if unifiable(a.pattern.term, b.pattern.term):
                raise SLRError(
                    f"conflicting buffers: {a.label} at {a.where} and {b.label} at {b.where} "
                    "have unifiable patterns (an event matching both would be kept by one and "
                    "pruned by the other); declare at most one buffer per event")


# ----------------------------------------------------------------------------- SQL

def _n(spec: BufferSpec) -> int:
    return _lenient_amount("cBuffer", spec.amount)


def trigger_sql(spec: BufferSpec, table: str) -> dict[str, str]:
    """The ``CREATE TRIGGER`` / ``CREATE INDEX`` statements of one installed buffer over its
    type's table, by object name."""
    bid = int(spec.id)
    p = spec.pattern
    t = quote_identifier(table)
    late = f"slr_buf_{bid}_late"
    count_drop = f"UPDATE slr_counters SET dropped = dropped + 1 WHERE buffer_id = {bid};"
    count_pruned = (f"UPDATE slr_counters SET pruned = pruned + changes() "
                    f"WHERE buffer_id = {bid} AND changes() > 0;")
    out: dict[str, str] = {}
    if spec.kind == "tBuffer":
        d = sql_literal(float(spec.amount))
        now = "(SELECT now FROM slr_clock WHERE id = 1)"
        out[late] = (
            f"CREATE TRIGGER {quote_identifier(late)} BEFORE INSERT ON {t}\n"
            f"WHEN NEW.t_end < {now} - {d} AND {p.match('NEW.')}\n"
            f"BEGIN\n  {count_drop}\n  SELECT RAISE(IGNORE);\nEND")
        tick = f"slr_buf_{bid}_tick"
        cutoff = f"(SELECT cutoff FROM slr_buffers WHERE id = {bid})"
        out[tick] = (
            f"CREATE TRIGGER {quote_identifier(tick)} AFTER UPDATE OF now ON slr_clock\n"
            f"WHEN {cutoff} < NEW.now - {d}\n"
            f"BEGIN\n"
            f"  DELETE FROM {t} WHERE t_end >= {cutoff} AND t_end < NEW.now - {d} "
            f"AND {p.match('')};\n"
            f"  {count_pruned}\n"
            f"  UPDATE slr_buffers SET cutoff = NEW.now - {d} WHERE id = {bid};\n"
            f"END")
    elif spec.kind == "cBuffer":
        n = _n(spec)
        same = f"{p.match('')} AND {p.key_equal()}"
        newer = (f"SELECT 1 FROM {t} WHERE {same} AND t_end >= NEW.t_end "
                 f"AND (t_end > NEW.t_end OR t_start > NEW.t_start) LIMIT {n}")
        out[late] = (
            f"CREATE TRIGGER {quote_identifier(late)} BEFORE INSERT ON {t}\n"
            f"WHEN {p.match('NEW.')} AND (SELECT count(*) FROM ({newer})) >= {n}\n"
            f"BEGIN\n  {count_drop}\n  SELECT RAISE(IGNORE);\nEND")
        keep = f"slr_buf_{bid}_keep"
        out[keep] = (
            f"CREATE TRIGGER {quote_identifier(keep)} AFTER INSERT ON {t}\n"
            f"WHEN {p.match('NEW.')}\n"
            f"BEGIN\n"
            f"  DELETE FROM {t} WHERE seq IN (SELECT seq FROM {t} WHERE {same} "
            f"ORDER BY {_ORDER_DESC} LIMIT -1 OFFSET {n});\n"
            f"  {count_pruned}\n"
            f"END")
        if p.keys and p.key_columns[0] != (1, None):
            # the key is not the first column (already indexed): a partial expression index
            # over exactly the rows this buffer manages, ordered for the newest-first scans
            values = ", ".join(v.replace(_ROW, "") for v, _ in p.keys)
            where = f" WHERE {p.match('')}" if p.conds else ""
            index = f"slr_bix_{bid}"
            out[index] = (f"CREATE INDEX {quote_identifier(index)} ON {t} "
                          f"({values}, t_end, t_start){where}")
    elif spec.kind == "window":
        t1, t2 = sql_literal(float(spec.t1)), sql_literal(float(spec.t2))
        out[late] = (
            f"CREATE TRIGGER {quote_identifier(late)} BEFORE INSERT ON {t}\n"
            f"WHEN (NEW.t_start < {t1} OR NEW.t_end > {t2}) AND {p.match('NEW.')}\n"
            f"BEGIN\n  {count_drop}\n  SELECT RAISE(IGNORE);\nEND")
    else:  # pragma: no cover - internal misuse
        raise ValueError(spec.kind)
    return out


def initial_prune_sql(spec: BufferSpec, table: str, now: float) -> str | None:
    """The DELETE that applies a newly installed buffer to the rows already stored."""
    p = spec.pattern
    t = quote_identifier(table)
    if spec.kind == "tBuffer":
        if not now > -math.inf:
            return None
        return (f"DELETE FROM {t} WHERE t_end < {sql_literal(float(now))} - "
                f"{sql_literal(float(spec.amount))} AND {p.match('')}")
    if spec.kind == "cBuffer":
        partition = ""
        if p.keys:
            parts = []
            for value, vtype in p.keys:
                parts += [value.replace(_ROW, ""), vtype.replace(_ROW, "")]
            partition = "PARTITION BY " + ", ".join(parts) + " "
        return (f"DELETE FROM {t} WHERE seq IN (SELECT seq FROM (SELECT seq, row_number() OVER "
                f"({partition}ORDER BY {_ORDER_DESC}) AS rn FROM {t} WHERE {p.match('')}) "
                f"WHERE rn > {_n(spec)})")
    return (f"DELETE FROM {t} WHERE (t_start < {sql_literal(float(spec.t1))} OR "
            f"t_end > {sql_literal(float(spec.t2))}) AND {p.match('')}")


# ----------------------------------------------------------------------------- manager

def _parse_pattern(text: str) -> Any:
    from .parser import parse_term

    term, _ = parse_term(text, "<buffer pattern>")
    return term


def _spec_from_row(row: dict) -> BufferSpec:
    pattern = analyze(_parse_pattern(row["pattern_text"]))
    amount = _lenient_amount(row["kind"], row["amount"])
    return BufferSpec(row["kind"], pattern, amount, row["t1"], row["t2"], row["source"],
                      row["origin"], row["id"])


def _where(clause: Any) -> str:
    span = getattr(clause, "span", None)
    if span is None:
        return "<program>"
    return f"{span.filename}:{span.line}"


class BufferManager:
    """The buffers of one knowledge base (installed by :func:`attach`)."""

    def __init__(self, kb: Host):
        self.kb = kb
        self.store = kb.store
        self.lock = threading.RLock()
        self._clock = None

    # -- specs -----------------------------------------------------------------------
    def program_specs(self, strict: bool = False) -> list[BufferSpec]:
        """The buffers the loaded program declares. ``strict`` (a program being loaded): an
        amount out of range is an SLRError naming the clause; otherwise (a program read back
        from the store, which older versions may have accepted) it is taken as the nearest
        bound that works."""
        specs = []
        for decl in self.kb.declarations.buffers:
            where = _where(decl.clause)
            try:
                pattern = analyze(decl.pattern)
                if not strict:
                    amount = _lenient_amount(decl.kind, decl.amount)
                elif decl.kind == "cBuffer":
                    amount = check_count(decl.amount, "the count")
                else:
                    amount = check_seconds(decl.amount, "the duration")
            except SLRError as exc:
                raise SLRError(f"{where}: {decl.kind}: {exc}") from None
            specs.append(BufferSpec(decl.kind, pattern, amount, None, None, "program", where))
        return specs

    def active(self) -> list[BufferSpec]:
        return [_spec_from_row(row) for row in self.store.buffer_rows()]

    # -- installation ----------------------------------------------------------------
    def install(self, spec: BufferSpec) -> int:
        """Persist a new buffer, create its triggers and apply it to the stored rows."""
        spec.id = self.store.insert_buffer(
            spec.kind, spec.source, spec.pattern.text, spec.pattern.name, spec.pattern.arity,
            None if spec.amount is None else float(spec.amount), spec.t1, spec.t2,
            spec.origin)
        table = self.store.table_for(spec.pattern.name, spec.pattern.arity)
        if table is not None:
            self.store.install_buffer_objects(spec.id, trigger_sql(spec, table))
            if spec.kind == "tBuffer":  # clock moves were not recorded without a tBuffer
                self.store.record_now(self.kb.clock.now())
            now = self.store.recorded_now()
            sql = initial_prune_sql(spec, table, now)
            if sql is not None:
                self.store.prune(sql, spec.id)
            if spec.kind == "tBuffer" and now > -math.inf:
                self.store.set_buffer_cutoff(spec.id, now - float(spec.amount))
        return spec.id

    def uninstall(self, spec: BufferSpec) -> None:
        self.store.drop_buffer_objects(spec.id)
        self.store.mark_buffer_removed(spec.id)

    def ensure_objects(self, specs: Iterable[BufferSpec] | None = None) -> None:
        """(Re)create missing or outdated triggers of active buffers whose table exists."""
        for spec in self.active() if specs is None else specs:
            table = self.store.table_for(spec.pattern.name, spec.pattern.arity)
            if table is not None:
                self.store.install_buffer_objects(spec.id, trigger_sql(spec, table))

    def sync_program(self, check: bool = True) -> None:
        """Make the installed program buffers those the loaded program declares."""
        with self.lock, self.store.transaction():
            desired = self.program_specs(strict=check)
            installed = self.active()
            runtime = [s for s in installed if s.source == "runtime"]
            if check:
                conflicts(desired + runtime)
            current = {s.identity(): s for s in installed if s.source == "program"}
            wanted = {s.identity() for s in desired}
            for key, spec in current.items():
                if key not in wanted:
                    self.uninstall(spec)
            for spec in desired:
                if spec.identity() not in current:
                    self.install(spec)

    def up_to_date(self) -> bool:
        """Are the installed program buffers those the program declares, and every active
        buffer's triggers those this version generates? (Reads only.)"""
        installed = self.active()
        current = {s.identity() for s in installed if s.source == "program"}
        if current != {s.identity() for s in self.program_specs()}:
            return False
        for spec in installed:
            table = self.store.table_for(spec.pattern.name, spec.pattern.arity)
            if table is not None and self.store.buffer_objects(spec.id) != trigger_sql(spec, table):
                return False
        return True

    # -- listeners -------------------------------------------------------------------
    def on_load(self, kb: Host) -> None:
        self.sync_program(check=True)

    def on_table_created(self, name: str, arity: int, table: str) -> None:
        for row in self.store.buffer_rows():
            if row["type_name"] == name and row["type_arity"] == arity:
                spec = _spec_from_row(row)
                self.store.install_buffer_objects(spec.id, trigger_sql(spec, table))

    def on_tick(self, now: float) -> None:
        store = self.store
        if store.closed:
            clock = self._clock
            if clock is not None:
                clock.unsubscribe(self.on_tick)
            return
        # Only a tBuffer's trigger reads the recorded "now" between adds (every add records it
        # in its own transaction): without one, a clock move costs no durable commit.
        if not store.has_active_buffer("tBuffer"):
            return
        store.record_now(now)
        if not store.in_transaction:
            store.reclaim_space()

    def on_add(self, stored: list) -> None:
        if not self.store.closed and not self.store.in_transaction:
            self.store.reclaim_space()

    # -- runtime policies ------------------------------------------------------------
    def add_runtime(self, pattern: Any, keep_last: Any = None, keep_seconds: Any = None,
                    keep_between: Any = None) -> int:
        given = [name for name, value in (("keep_last", keep_last),
                                          ("keep_seconds", keep_seconds),
                                          ("keep_between", keep_between)) if value is not None]
        if len(given) != 1:
            raise SLRError("add_buffer needs exactly one of keep_last=N, keep_seconds=L, "
                           f"keep_between=(T1, T2) (got {', '.join(given) or 'none'})")
        term = _parse_pattern(pattern) if isinstance(pattern, str) else pattern
        compiled = analyze(term)
        t1 = t2 = amount = None
        if keep_last is not None:
            kind, amount = "cBuffer", check_count(keep_last)
        elif keep_seconds is not None:
            kind, amount = "tBuffer", _seconds(keep_seconds)
        else:
            try:
                t1, t2 = keep_between
            except (TypeError, ValueError):
                raise SLRError("keep_between must be a pair of times (T1, T2)") from None
            t1, t2 = check_time(t1, "keep_between's T1"), check_time(t2, "keep_between's T2")
            if not t1 <= t2:
                raise SLRError(f"keep_between=({t1}, {t2}): T1 must not be after T2")
            kind = "window"
        spec = BufferSpec(kind, compiled, amount, t1, t2, "runtime", "kb.add_buffer")
        with self.kb.loader.load_lock, self.lock, self.store.transaction():
            conflicts(self.active() + [spec])
            return self.install(spec)

    def remove_runtime(self, buffer_id: int) -> None:
        with self.kb.loader.load_lock, self.lock, self.store.transaction():
            for spec in self.active():
                if spec.id == buffer_id:
                    if spec.source != "runtime":
                        raise SLRError(f"buffer #{buffer_id} {spec.label} is declared by the "
                                       f"program at {spec.origin}; it goes with the program")
                    self.uninstall(spec)
                    return
        raise SLRError(f"no active buffer #{buffer_id}")

    def infos(self) -> list[BufferInfo]:
        out = []
        for row in self.store.buffer_rows():
            amount = _lenient_amount(row["kind"], row["amount"])
            window = (row["t1"], row["t2"]) if row["kind"] == "window" else None
            out.append(BufferInfo(row["id"], row["kind"], row["pattern_text"], amount, window,
                                  row["source"], row["origin"], row["pruned"], row["dropped"]))
        return out

    def prune_now(self) -> None:
        """Record the clock's now (running the time-driven pruning) and reclaim space."""
        self.store.record_now(self.kb.clock.now())
        if not self.store.in_transaction:
            self.store.reclaim_space()


def _seconds(value: Any) -> float:
    if isinstance(value, str):
        value = parse_duration(_parse_pattern(value))
    return check_seconds(value)


def attach(kb: Host) -> BufferManager:
    """Install buffer management on a knowledge base (called by KnowledgeBase.__init__):
    the load listener (conflict check, triggers created in the load's transaction), the
    table-creation hook, the clock listener and the space reclaimer."""
    manager = BufferManager(kb)
    kb.load_listeners.append(manager.on_load)
    kb.add_listeners.append(manager.on_add)
    kb.store.table_created_hooks.append(manager.on_table_created)
    kb.store.limit_wal()
    clock = kb.clock
    if hasattr(clock, "subscribe"):
        clock.subscribe(manager.on_tick)
        manager._clock = clock
    if (kb.declarations.buffers or kb.store.buffer_rows()) and not manager.up_to_date():
        # reopen: the program restored from the file declares the same buffers as before;
        # re-create any trigger that is missing or was generated by an older slr_sql (only
        # then: opening a store that is up to date takes no write lock)
        with kb.store.transaction():
            manager.sync_program(check=False)
            manager.ensure_objects()
    return manager


def stats(store: Any) -> dict[str, Any]:
    """Counters and sizes for ``slr stats``: space, rows per type, buffers (all, removed too)."""
    return {"space": store.space_stats(), "rows": store.table_rows(),
            "buffers": store.buffer_rows(active_only=False), "now": store.recorded_now()}


def format_stats(store: Any, path: str = "") -> str:
    """The text ``slr stats DB`` prints."""
    data = stats(store)
    space = data["space"]
    total = space["file_bytes"] + space["wal_bytes"]
    lines = [f"file {path}: {total} bytes ({total / 1048576:.2f} MiB) = "
             f"{space['file_bytes']} bytes database + {space['wal_bytes']} bytes WAL; "
             f"{space['page_count']} pages of {space['page_size']} bytes, "
             f"{space['free_pages']} free"]
    now = data["now"]
    lines.append(f"buffer clock (now): {_num(now) if now > -math.inf else 'not recorded yet'}")
    rows = data["rows"]
    pruned_by_type: dict = {}
    for b in data["buffers"]:
        key = (b["type_name"], b["type_arity"])
        pruned_by_type[key] = pruned_by_type.get(key, 0) + b["pruned"]
    lines.append(f"events stored: {sum(rows.values())} now "
                 f"(+ {sum(pruned_by_type.values())} pruned by buffers)")
    for (name, arity), count in rows.items():
        extra = pruned_by_type.get((name, arity), 0)
        lines.append(f"  {name}/{arity}: {count} stored" + (f", {extra} pruned" if extra else ""))
    buffers = data["buffers"]
    lines.append(f"buffers: {sum(1 for b in buffers if b['removed_at'] is None)} active"
                 f"; dropped late/outside: {sum(b['dropped'] for b in buffers)}"
                 f"; pruned: {sum(b['pruned'] for b in buffers)}")
    for b in buffers:
        if b["kind"] == "window":
            amount = f"[{_num(b['t1'])}, {_num(b['t2'])}]"
        elif b["kind"] == "cBuffer":
            amount = f"last {int(b['amount'])}"
        else:
            amount = f"{_num(b['amount'])}s"
        state = "" if b["removed_at"] is None else " (removed)"
        lines.append(f"  #{b['id']} {b['kind']} {b['pattern_text']} {amount} "
                     f"[{b['source']}, {b['origin']}]{state}: "
                     f"pruned {b['pruned']}, dropped {b['dropped']}")
    return "\n".join(lines)
