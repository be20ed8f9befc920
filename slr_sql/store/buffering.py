"""Event-history buffers in the database: what a buffer pattern tests, printed per engine.

slr_sql.buffers compiles a buffer pattern (``cBuffer(inView(face(P, _)), 1)``) into a
:class:`PatternMatch`: typed tests on an event type's columns (a constant argument, a value
inside a compound at a JSON path, a list's length, two places holding the same term) and the
places of the pattern's named variables (the cBuffer key). A :class:`BufferPlan` adds what the
buffer keeps. This module prints both for one engine, and :class:`BufferTables` installs the
result as that engine's triggers:

* SQLite (:class:`SQLiteBufferPrinter`): ``CREATE TRIGGER`` statements with ``WHEN`` clauses
  and SQLite's JSON functions (``json_extract(arg1, '$."face"[0]')``);
* PostgreSQL (:class:`PostgresBufferPrinter`): one plpgsql trigger function per trigger
  (``slr_buf_<id>_late`` ...) with the match in the trigger's ``WHEN``, and the JSON tests
  through the null-safe helpers of migrations/pg_0008_buffers.sql (``slr_json``,
  ``slr_json_type``, ...): the data columns are text whose spelling says the type, so equality
  of the texts is Prolog's ``==`` on stored values.

Both keep the same contract (docs/buffers.md): a late event is counted in
``slr_counters.dropped`` and not stored; a cBuffer keeps the N newest events per key (by end,
start, then arrival); a tBuffer deletes what expired whenever ``slr_clock.now`` moves.
Constants appear as SQL literals (:func:`~slr_sql.store.sqltext.sql_literal`): trigger
bodies cannot have bound parameters.

>>> m = PatternMatch((ArgEquals(1, "bob"),), ((2, None),))
>>> SQLITE_BUFFERS.condition(m, "NEW.")
"NEW.arg1 = 'bob'"
>>> POSTGRES_BUFFERS.condition(m, "NEW.")
"NEW.arg1 = 'bob'"
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Callable
from typing import Any, Union

from .dialect import POSTGRES
from .sqltext import joined_balanced, quote_identifier, sql_literal

__all__ = ["ArgEquals", "JsonEquals", "JsonArray", "SameTerm", "MixedTerm", "PatternMatch",
           "BufferPlan", "BufferTables", "SQLiteBufferPrinter", "PostgresBufferPrinter",
           "SQLITE_BUFFERS", "POSTGRES_BUFFERS"]

# A JSON path inside a column: object keys (compound names, "$string"...) and array indexes.
Path = tuple[Union[str, int], ...]
# (column number, JSON path or None for the whole column)
Place = tuple[int, Union[Path, None]]

ORDER_NEWEST = "t_end DESC, t_start DESC, seq DESC"


# ----------------------------------------------------------------------------- the tests

@dataclass(frozen=True)
class ArgEquals:
    """Column ``arg<column>`` holds exactly the encoded constant ``value`` (int, float, str)."""

    column: int
    value: Any


@dataclass(frozen=True)
class JsonEquals:
    """At ``path`` inside the JSON of column ``column``: a JSON value of ``kind``
    (``text``, ``integer``, ``real``) equal to ``value``."""

    column: int
    path: Path
    kind: str
    value: Any


@dataclass(frozen=True)
class JsonArray:
    """At ``path``: a JSON array of ``length`` items (at least that many if ``open``)."""

    column: int
    path: Path
    length: int
    open: bool = False


@dataclass(frozen=True)
class SameTerm:
    """Two places hold the same term; both whole columns, or both inside JSON."""

    first: Place
    second: Place


@dataclass(frozen=True)
class MixedTerm:
    """Whole column ``column`` (top-level encoding) holds the same term as the JSON value at
    ``path`` in column ``inside`` (inside-JSON encoding)."""

    column: int
    inside: int
    path: Path


Test = Union[ArgEquals, JsonEquals, JsonArray, SameTerm, MixedTerm]


@dataclass(frozen=True)
class PatternMatch:
    """A buffer pattern over one event table: ``tests`` hold exactly for the rows whose event
    unifies with the pattern; ``keys`` are the places of its named variables."""

    tests: tuple[Test, ...] = ()
    keys: tuple[Place, ...] = ()


@dataclass(frozen=True)
class BufferPlan:
    """One installed buffer as the database sees it: ``kind`` (tBuffer, cBuffer, window),
    ``amount`` (seconds or a count), the window ``[t1, t2]``, and its pattern's match."""

    id: int
    kind: str
    match: PatternMatch
    amount: float | int | None = None
    t1: float | None = None
    t2: float | None = None


def _guarded(test: Test) -> tuple[int, ...]:
    """The columns whose JSON a test reads (SQLite evaluates JSON tests only behind a guard
    that the column holds JSON)."""
    if isinstance(test, (JsonEquals, JsonArray)):
        return (test.column,)
    if isinstance(test, SameTerm):
        if test.first[1] is None:
            return ()
        return tuple(sorted({test.first[0], test.second[0]}))
    if isinstance(test, MixedTerm):
        return (test.inside,)
    return ()


# ----------------------------------------------------------------------------- SQLite

class SQLiteBufferPrinter:
    """Buffers as SQLite triggers (the text slr_sql always generated, so stores written by
    earlier versions keep their triggers)."""

    name = "sqlite"

    @staticmethod
    def path(path: Path) -> str:
        return "$" + "".join(f'."{p}"' if isinstance(p, str) else f"[{p}]" for p in path)

    @staticmethod
    def guard(c: str) -> str:
        return f"typeof({c}) = 'text' AND substr({c}, 1, 1) IN ('[', '{{') AND json_valid({c})"

    def value(self, row: str, place: Place) -> str:
        c = f"{row}arg{place[0]}"
        if place[1] is None:
            return c
        return (f"CASE WHEN {self.guard(c)} THEN json_extract({c}, "
                f"{sql_literal(self.path(place[1]))}) END")

    def vtype(self, row: str, place: Place) -> str:
        c = f"{row}arg{place[0]}"
        if place[1] is None:
            return f"typeof({c})"
        return (f"CASE WHEN {self.guard(c)} THEN json_type({c}, "
                f"{sql_literal(self.path(place[1]))}) END")

    def test(self, t: Test, row: str) -> str:
        if isinstance(t, ArgEquals):
            c = f"{row}arg{t.column}"
            if type(t.value) is int:
                return f"({c} = {sql_literal(t.value)} AND typeof({c}) = 'integer')"
            if type(t.value) is float:
                return f"({c} = {sql_literal(t.value)} AND typeof({c}) = 'real')"
            return f"{c} = {sql_literal(t.value)}"
        if isinstance(t, JsonEquals):
            c, p = f"{row}arg{t.column}", sql_literal(self.path(t.path))
            return (f"json_type({c}, {p}) = '{t.kind}' AND json_extract({c}, {p}) = "
                    f"{sql_literal(t.value)}")
        if isinstance(t, JsonArray):
            c, p = f"{row}arg{t.column}", sql_literal(self.path(t.path))
            return (f"json_type({c}, {p}) = 'array' AND json_array_length({c}, {p}) "
                    f"{'>=' if t.open else '='} {t.length}")
        if isinstance(t, SameTerm):
            if t.first[1] is None:
                a, b = f"{row}arg{t.first[0]}", f"{row}arg{t.second[0]}"
                return f"{a} = {b} AND typeof({a}) = typeof({b})"
            return (f"{self.value(row, t.first)} = {self.value(row, t.second)} AND "
                    f"{self.vtype(row, t.first)} = {self.vtype(row, t.second)}")
        return self.mixed(t, row)

    def mixed(self, t: MixedTerm, row: str) -> str:
        a, b = f"{row}arg{t.column}", f"{row}arg{t.inside}"
        p = sql_literal(self.path(t.path))
        def tag(key: str) -> str:
            return sql_literal(self.path(t.path + (key,)))
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

    def condition(self, match: PatternMatch, row: str = "") -> str:
        """The match of one row (``""``: the scanned row, ``"NEW."``: the new one): tests
        grouped by their JSON guards, ``CASE WHEN guards THEN tests ELSE 0 END`` (SQLite does
        not promise left-to-right AND, and its json_* functions raise on text that is not
        JSON)."""
        groups: dict[tuple[int, ...], list[str]] = {}
        for t in match.tests:
            groups.setdefault(_guarded(t), []).append(self.test(t, row))
        out = []
        for cols, conds in groups.items():
            body = joined_balanced(conds, "AND")
            if cols:
                guards = joined_balanced([self.guard(f"{row}arg{i}") for i in cols], "AND")
                out.append(f"(CASE WHEN {guards} THEN ({body}) ELSE 0 END)")
            else:
                out.append(body if len(conds) == 1 else f"({body})")
        return joined_balanced(out, "AND") if out else "1"

    def key_equal(self, match: PatternMatch) -> str:
        parts = []
        for place in match.keys:
            parts.append(f"{self.value('', place)} = {self.value('NEW.', place)}")
            parts.append(f"{self.vtype('', place)} = {self.vtype('NEW.', place)}")
        return joined_balanced(parts, "AND") if parts else "1"

    def objects(self, plan: BufferPlan, table: str) -> dict[str, str]:
        """The ``CREATE TRIGGER`` / ``CREATE INDEX`` statements of one buffer, by name."""
        bid = int(plan.id)
        m = plan.match
        t = quote_identifier(table)
        late = f"slr_buf_{bid}_late"
        count_drop = f"UPDATE slr_counters SET dropped = dropped + 1 WHERE buffer_id = {bid};"
        count_pruned = (f"UPDATE slr_counters SET pruned = pruned + changes() "
                        f"WHERE buffer_id = {bid} AND changes() > 0;")
        new_match, row_match = self.condition(m, "NEW."), self.condition(m, "")
        out: dict[str, str] = {}
        if plan.kind == "tBuffer":
            d = sql_literal(float(plan.amount or 0.0))
            now = "(SELECT now FROM slr_clock WHERE id = 1)"
            out[late] = (
                f"CREATE TRIGGER {quote_identifier(late)} BEFORE INSERT ON {t}\n"
                f"WHEN NEW.t_end < {now} - {d} AND {new_match}\n"
                f"BEGIN\n  {count_drop}\n  SELECT RAISE(IGNORE);\nEND")
            tick = f"slr_buf_{bid}_tick"
            cutoff = f"(SELECT cutoff FROM slr_buffers WHERE id = {bid})"
            out[tick] = (
                f"CREATE TRIGGER {quote_identifier(tick)} AFTER UPDATE OF now ON slr_clock\n"
                f"WHEN {cutoff} < NEW.now - {d}\n"
                f"BEGIN\n"
                f"  DELETE FROM {t} WHERE t_end >= {cutoff} AND t_end < NEW.now - {d} "
                f"AND {row_match};\n"
                f"  {count_pruned}\n"
                f"  UPDATE slr_buffers SET cutoff = NEW.now - {d} WHERE id = {bid};\n"
                f"END")
        elif plan.kind == "cBuffer":
            n = int(plan.amount or 0)
            same = f"{row_match} AND {self.key_equal(m)}"
            newer = (f"SELECT 1 FROM {t} WHERE {same} AND t_end >= NEW.t_end "
                     f"AND (t_end > NEW.t_end OR t_start > NEW.t_start) LIMIT {n}")
            out[late] = (
                f"CREATE TRIGGER {quote_identifier(late)} BEFORE INSERT ON {t}\n"
                f"WHEN {new_match} AND (SELECT count(*) FROM ({newer})) >= {n}\n"
                f"BEGIN\n  {count_drop}\n  SELECT RAISE(IGNORE);\nEND")
            keep = f"slr_buf_{bid}_keep"
            out[keep] = (
                f"CREATE TRIGGER {quote_identifier(keep)} AFTER INSERT ON {t}\n"
                f"WHEN {new_match}\n"
                f"BEGIN\n"
                f"  DELETE FROM {t} WHERE seq IN (SELECT seq FROM {t} WHERE {same} "
                f"ORDER BY {ORDER_NEWEST} LIMIT -1 OFFSET {n});\n"
                f"  {count_pruned}\n"
                f"END")
            if m.keys and m.keys[0] != (1, None):
                # the key is not the first column (already indexed): a partial expression
                # index over exactly the rows this buffer manages, for the newest-first scans
                values = ", ".join(self.value("", place) for place in m.keys)
                where = f" WHERE {row_match}" if m.tests else ""
                index = f"slr_bix_{bid}"
                out[index] = (f"CREATE INDEX {quote_identifier(index)} ON {t} "
                              f"({values}, t_end, t_start){where}")
        elif plan.kind == "window":
            t1, t2 = sql_literal(float(plan.t1)), sql_literal(float(plan.t2))  # type: ignore[arg-type]
            out[late] = (
                f"CREATE TRIGGER {quote_identifier(late)} BEFORE INSERT ON {t}\n"
                f"WHEN (NEW.t_start < {t1} OR NEW.t_end > {t2}) AND {new_match}\n"
                f"BEGIN\n  {count_drop}\n  SELECT RAISE(IGNORE);\nEND")
        else:  # pragma: no cover - internal misuse
            raise ValueError(plan.kind)
        return out

    def prune(self, plan: BufferPlan, table: str, now: float) -> str | None:
        """The DELETE applying a newly installed buffer to the rows already stored."""
        t = quote_identifier(table)
        match = self.condition(plan.match, "")
        if plan.kind == "tBuffer":
            if not now > -math.inf:
                return None
            return (f"DELETE FROM {t} WHERE t_end < {sql_literal(float(now))} - "
                    f"{sql_literal(float(plan.amount or 0.0))} AND {match}")
        if plan.kind == "cBuffer":
            partition = ""
            if plan.match.keys:
                parts = []
                for place in plan.match.keys:
                    parts += [self.value("", place), self.vtype("", place)]
                partition = "PARTITION BY " + ", ".join(parts) + " "
            return (f"DELETE FROM {t} WHERE seq IN (SELECT seq FROM (SELECT seq, row_number() "
                    f"OVER ({partition}ORDER BY {ORDER_NEWEST}) AS rn FROM {t} WHERE {match}) "
                    f"WHERE rn > {int(plan.amount or 0)})")
        return (f"DELETE FROM {t} WHERE (t_start < {sql_literal(float(plan.t1))} OR "  # type: ignore[arg-type]
                f"t_end > {sql_literal(float(plan.t2))}) AND {match}")  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- PostgreSQL

# The column texts of the two float zeros (Python's repr, as written by the dialect)
_PG_ZEROS = "('0.0', '-0.0')"


def _pg_float(value: float) -> str:
    value = float(value)
    if value == math.inf:
        return "'Infinity'::float8"
    if value == -math.inf:
        return "'-Infinity'::float8"
    return f"{sql_literal(repr(value))}::float8"


class PostgresBufferPrinter:
    """Buffers as plpgsql trigger functions. Every JSON test goes through the null-safe
    helpers of migrations/pg_0008_buffers.sql, so a test never raises on a value of another
    shape (PostgreSQL does not promise left-to-right AND either): a row a test cannot read
    does not match."""

    name = "postgresql"

    def __init__(self, schema: str | None = None):
        # the store's schema: each trigger function runs with the search path of the
        # store's connections (None: the caller's, for printing alone)
        self.schema = schema

    @staticmethod
    def path(path: Path) -> str:
        return sql_literal("{" + ",".join(f'"{p}"' for p in path) + "}")

    def at(self, row: str, column: int, path: Path) -> str:
        j = f"slr_json({row}arg{column})"
        return f"({j} #> {self.path(path)})" if path else j

    def value(self, row: str, place: Place) -> str:
        if place[1] is None:
            return f"{row}arg{place[0]}"
        return f"({self.at(row, place[0], place[1])} #>> '{{}}')"

    def vtype(self, row: str, place: Place) -> str | None:
        if place[1] is None:
            return None   # the text alone says the type
        return f"slr_json_type({self.at(row, place[0], place[1])})"

    def test(self, t: Test, row: str) -> str:
        if isinstance(t, ArgEquals):
            if type(t.value) is float and t.value == 0.0:   # either zero, as SQLite's `=`
                return f"{row}arg{t.column} IN {_PG_ZEROS}"
            return f"{row}arg{t.column} = {sql_literal(POSTGRES.to_column(t.value))}"
        if isinstance(t, JsonEquals):
            x = self.at(row, t.column, t.path)
            if t.kind == "integer":
                return f"slr_json_type({x}) = 'integer' AND slr_json_number({x}) = {int(t.value)}"
            if t.kind == "real":
                return (f"slr_json_type({x}) = 'real' AND slr_json_float({x}) = "
                        f"{_pg_float(t.value)}")
            return f"slr_json_type({x}) = 'text' AND ({x} #>> '{{}}') = {sql_literal(t.value)}"
        if isinstance(t, JsonArray):
            x = self.at(row, t.column, t.path)
            return f"slr_json_length({x}) {'>=' if t.open else '='} {t.length}"
        if isinstance(t, SameTerm):
            a, b = self.value(row, t.first), self.value(row, t.second)
            if t.first[1] is None:
                return f"({a} = {b} OR {a} IN {_PG_ZEROS} AND {b} IN {_PG_ZEROS})"
            a_type, b_type = self.vtype(row, t.first), self.vtype(row, t.second)
            return (f"({a} = {b} OR {a_type} = 'real' AND {a} IN {_PG_ZEROS} AND "
                    f"{b} IN {_PG_ZEROS}) AND {a_type} = {b_type}")
        return f"slr_json_same({row}arg{t.column}, {self.at(row, t.inside, t.path)})"

    def zero(self, row: str, place: Place) -> str:
        """Whether the value at ``place`` is a float zero (either sign)."""
        value, vtype = self.value(row, place), self.vtype(row, place)
        is_zero = f"{value} IN {_PG_ZEROS}"
        # (a whole column's text is a float's only when it reads as one: '0.0' is no atom's
        # or string's spelling there; inside JSON a string's text may be '0.0')
        return is_zero if vtype is None else f"({vtype} = 'real' AND {is_zero})"

    @staticmethod
    def index_safe(t: Test) -> bool:
        """Whether the test may stand in an index's predicate. CREATE INDEX (REINDEX,
        ANALYZE, a restore) runs with ``search_path = pg_catalog, pg_temp`` from PostgreSQL
        17 on, and the server reads the body of an SQL function it calls then:
        ``slr_json_same`` and ``slr_json_float`` call the store's other helpers by their
        bare names, which are not found there (an add that made the index failed with
        "function slr_typeof(text) does not exist"). The helpers the other tests call read
        built-in functions only.

        >>> POSTGRES_BUFFERS.index_safe(JsonEquals(1, ("f", 0), "real", 1.0))
        False
        """
        if isinstance(t, MixedTerm):
            return False
        return not (isinstance(t, JsonEquals) and t.kind == "real")

    def index_condition(self, match: PatternMatch) -> str | None:
        """The predicate of a buffer's index over the rows it governs: the scanned row's
        match without the tests :meth:`index_safe` keeps out (None: none left). A statement
        that names every test of the match still reads the index: its conditions imply the
        predicate's.

        >>> m = PatternMatch((MixedTerm(2, 1, ("f", 0)), JsonArray(1, ("f",), 1)), ((2, None),))
        >>> print(POSTGRES_BUFFERS.index_condition(m))
        slr_json_length((slr_json(arg1) #> '{"f"}')) = 1
        """
        kept = tuple(t for t in match.tests if self.index_safe(t))
        return self.condition(PatternMatch(kept, match.keys), "") if kept else None

    def key_value(self, place: Place) -> str:
        """The scanned row's value at key ``place`` with a float zero's sign dropped: one key
        for both zeros (the partition of a newly installed count buffer)."""
        return f"(CASE WHEN {self.zero('', place)} THEN '0.0' ELSE {self.value('', place)} END)"

    def condition(self, match: PatternMatch, row: str = "") -> str:
        """The match of one row (``""``: the scanned row, ``"NEW."``: the new one)."""
        conds = [self.test(t, row) for t in match.tests]
        if not conds:
            return "TRUE"
        return conds[0] if len(conds) == 1 else "(" + joined_balanced(conds, "AND") + ")"

    def key_equal(self, match: PatternMatch, zeros: bool = False) -> str:
        """The scanned row has the new row's key. ``zeros``: a float zero of the new row's
        key also finds the other zero (the condition of :meth:`new_zero`'s branch)."""
        # the keys' B-tree indexes (the event table's first argument, slr_bix_N) are
        # PostgreSQL's key indexes: a key of any length (dialect.key_indexes)
        parts = []
        for place in match.keys:
            value, new = self.value('', place), self.value('NEW.', place)
            if zeros:
                # either text; an array of both still reads the key index (a zero is short:
                # slr_key of it is itself)
                mate = (f"CASE WHEN {self.zero('NEW.', place)} THEN CASE {new} WHEN '0.0' "
                        f"THEN '-0.0' ELSE '0.0' END END")
                parts.append(f"slr_key({value}) = ANY (ARRAY[slr_key({new}), {mate}]) AND "
                             f"{value} = ANY (ARRAY[{new}, {mate}])")
            else:
                parts.append(POSTGRES.key_equal(value, new))
            vtype = self.vtype("", place)
            if vtype is not None:
                parts.append(f"{vtype} = {self.vtype('NEW.', place)}")
        return joined_balanced(parts, "AND") if parts else "TRUE"

    def new_zero(self, match: PatternMatch) -> str | None:
        """Whether the new row's key holds a float zero (None: the pattern has no key)."""
        if not match.keys:
            return None
        return " OR ".join(self.zero("NEW.", place) for place in match.keys)

    def _trigger(self, name: str, table: str, timing: str, when: str | None, body: str,
                 declare: str = "") -> str:
        """A trigger function and its trigger, both named ``name`` (so dropping the function
        drops the trigger too).

        >>> print(PostgresBufferPrinter("slr")._trigger("f", '"p"', "AFTER INSERT", None,
        ...                                             "  RETURN NULL;"))
        CREATE FUNCTION "f"() RETURNS trigger LANGUAGE plpgsql SET search_path = "slr", pg_temp AS $slr$
        BEGIN
          RETURN NULL;
        END $slr$;
        CREATE TRIGGER "f" AFTER INSERT ON "p" FOR EACH ROW EXECUTE FUNCTION "f"()
        """
        q = quote_identifier(name)
        when_clause = f"\nWHEN ({when})" if when else ""
        tag, n = "$slr$", 0
        while tag in body:   # a pattern constant holding the quote's own tag
            n += 1
            tag = f"$slr{n}$"
        # a function runs with the search path of the session that inserts, which may be
        # another tool's (docs/buffers.md: its rows are buffered too), without the store's
        # schema or with pg_temp first: the body's unqualified names (the event table,
        # slr_counters, slr_clock, slr_json) and the count buffer's lock key
        # (current_schema()) are then read as on the store's connections
        path = "" if self.schema is None else \
            f" SET search_path = {quote_identifier(self.schema)}, pg_temp"
        return (f"CREATE FUNCTION {q}() RETURNS trigger LANGUAGE plpgsql{path} AS {tag}\n"
                f"{declare}BEGIN\n{body}\nEND {tag};\n"
                f"CREATE TRIGGER {q} {timing} ON {table} FOR EACH ROW{when_clause} "
                f"EXECUTE FUNCTION {q}()")

    def objects(self, plan: BufferPlan, table: str) -> dict[str, str]:
        """The trigger functions with their triggers, and the index, of one buffer, by name."""
        bid = int(plan.id)
        m = plan.match
        t = quote_identifier(table)
        late = f"slr_buf_{bid}_late"
        drop = (f"  UPDATE slr_counters SET dropped = dropped + 1 WHERE buffer_id = {bid};\n"
                f"  RETURN NULL;")
        count_pruned = (f"  GET DIAGNOSTICS n = ROW_COUNT;\n  IF n > 0 THEN UPDATE slr_counters "
                        f"SET pruned = pruned + n WHERE buffer_id = {bid}; END IF;")
        new_match, row_match = self.condition(m, "NEW."), self.condition(m, "")
        when = None if new_match == "TRUE" else new_match
        out: dict[str, str] = {}
        if plan.kind == "tBuffer":
            d = _pg_float(float(plan.amount or 0.0))
            out[late] = self._trigger(
                late, t, "BEFORE INSERT", when,
                f"  IF NEW.t_end < (SELECT now FROM slr_clock WHERE id = 1) - {d} THEN\n"
                f"{drop}\n  END IF;\n  RETURN NEW;")
            tick = f"slr_buf_{bid}_tick"
            out[tick] = self._trigger(
                tick, "slr_clock", "AFTER UPDATE OF now", None,
                f"  SELECT cutoff INTO cut FROM slr_buffers WHERE id = {bid};\n"
                f"  IF cut < NEW.now - {d} THEN\n"
                f"  DELETE FROM {t} WHERE t_end >= cut AND t_end < NEW.now - {d} "
                f"AND {row_match};\n"
                f"{count_pruned}\n"
                f"  UPDATE slr_buffers SET cutoff = NEW.now - {d} WHERE id = {bid};\n"
                f"  END IF;\n  RETURN NULL;",
                "DECLARE cut float8; n bigint;\n")
        elif plan.kind == "cBuffer":
            n = int(plan.amount or 0)
            # the floats -0.0 and 0.0 are one key, as on SQLite, whose triggers compare
            # keys with SQL's `=` (docs/buffers.md): a new row whose key holds a zero runs
            # the statements that find both (the other rows keep their plans as before)
            new_zero = self.new_zero(m)

            def by_key(statement: Callable[[str], str]) -> str:
                plain = statement(f"{row_match} AND {self.key_equal(m)}")
                if new_zero is None:
                    return plain
                zeros = statement(f"{row_match} AND {self.key_equal(m, True)}")
                return f"  IF {new_zero} THEN\n{zeros}\n  ELSE\n{plain}\n  END IF;"

            def newer(same: str) -> str:
                return (f"  IF (SELECT count(*) FROM (SELECT 1 FROM {t} WHERE {same} "
                        f"AND t_end >= NEW.t_end AND (t_end > NEW.t_end OR t_start > "
                        f"NEW.t_start) LIMIT {n}) AS newer) >= {n} THEN\n{drop}\n  END IF;")

            def older(same: str) -> str:
                return (f"  DELETE FROM {t} WHERE seq IN (SELECT seq FROM {t} WHERE {same} "
                        f"ORDER BY {ORDER_NEWEST} OFFSET {n});")
            # concurrent writers take turns per count buffer until their commits: each
            # must see the rows the other stored, or both keep N of their own
            lock = (f"  PERFORM pg_advisory_xact_lock(hashtext(current_schema() || "
                    f"':buffers'), {bid % 2147483647});\n")
            out[late] = self._trigger(late, t, "BEFORE INSERT", when,
                                      f"{lock}{by_key(newer)}\n  RETURN NEW;")
            keep = f"slr_buf_{bid}_keep"
            out[keep] = self._trigger(
                keep, t, "AFTER INSERT", when,
                f"{by_key(older)}\n"
                f"{count_pruned}\n  RETURN NULL;",
                "DECLARE n bigint;\n")
            if m.keys and m.keys[0] != (1, None):
                index_match = self.index_condition(m)
                values = [f"({self.value('', place)})" for place in m.keys]
                for suffix, indexed in POSTGRES.key_indexes(values, ["t_end", "t_start"]):
                    index = f"slr_bix_{bid}{suffix}"
                    # (over the rows the buffer governs, beside a key index's own predicate)
                    where = "" if index_match is None else \
                        f" AND {index_match}" if " WHERE " in indexed else f" WHERE {index_match}"
                    out[index] = f"CREATE INDEX {quote_identifier(index)} ON {t} {indexed}{where}"
        elif plan.kind == "window":
            t1, t2 = _pg_float(plan.t1), _pg_float(plan.t2)  # type: ignore[arg-type]
            outside = f"(NEW.t_start < {t1} OR NEW.t_end > {t2})"
            out[late] = self._trigger(
                late, t, "BEFORE INSERT",
                outside if when is None else f"{outside} AND {when}",
                drop)
        else:  # pragma: no cover - internal misuse
            raise ValueError(plan.kind)
        return out

    def prune(self, plan: BufferPlan, table: str, now: float) -> str | None:
        """The DELETE applying a newly installed buffer to the rows already stored."""
        t = quote_identifier(table)
        match = self.condition(plan.match, "")
        if plan.kind == "tBuffer":
            if not now > -math.inf:
                return None
            return (f"DELETE FROM {t} WHERE t_end < {_pg_float(now)} - "
                    f"{_pg_float(float(plan.amount or 0.0))} AND {match}")
        if plan.kind == "cBuffer":
            partition = ""
            if plan.match.keys:
                parts = []
                for place in plan.match.keys:
                    parts.append(self.key_value(place))
                    vtype = self.vtype("", place)
                    if vtype is not None:
                        parts.append(vtype)
                partition = "PARTITION BY " + ", ".join(parts) + " "
            return (f"DELETE FROM {t} WHERE seq IN (SELECT seq FROM (SELECT seq, row_number() "
                    f"OVER ({partition}ORDER BY {ORDER_NEWEST}) AS rn FROM {t} WHERE {match}) "
                    f"AS ranked WHERE rn > {int(plan.amount or 0)})")
        return (f"DELETE FROM {t} WHERE (t_start < {_pg_float(plan.t1)} OR "  # type: ignore[arg-type]
                f"t_end > {_pg_float(plan.t2)}) AND {match}")  # type: ignore[arg-type]


SQLITE_BUFFERS = SQLiteBufferPrinter()
POSTGRES_BUFFERS = PostgresBufferPrinter()

# what BufferTables.buffer_rows reads: each dict's keys, in order, and the columns they are
_BUFFER_KEYS = ("id", "kind", "source", "pattern_text", "type_name", "type_arity", "amount",
                "t1", "t2", "origin", "cutoff", "created_at", "removed_at", "pruned", "dropped")
_BUFFER_COLUMNS = ", ".join([f"b.{key}" for key in _BUFFER_KEYS[:-2]] +
                            ["coalesce(c.pruned, 0)", "coalesce(c.dropped, 0)"])


# ----------------------------------------------------------------------------- the tables

class BufferTables:
    """The rows of ``slr_buffers`` / ``slr_counters`` and each buffer's triggers and indexes.

    >>> from slr_sql.store import EventStore
    >>> s = EventStore(None); s.insert_buffer("cBuffer", "program", "p(_)", "p", 1, 2.0,
    ...                                       None, None, "cBuffer(p(_), 2)")
    1
    >>> [(row["id"], row["kind"], row["pruned"]) for row in s.buffer_rows()]
    [(1, 'cBuffer', 0)]
    """

    def __init__(self, db: Any):
        self.db = db
        self.printer: SQLiteBufferPrinter | PostgresBufferPrinter = \
            SQLITE_BUFFERS if db.dialect.name == "sqlite" else PostgresBufferPrinter(db.schema)

    def buffer_rows(self, active_only: bool = True) -> list[dict[str, Any]]:
        """The rows of ``slr_buffers`` (oldest first) with their counters, as dicts.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).buffer_rows()
        []
        """
        where = " WHERE b.removed_at IS NULL" if active_only else ""
        rows = self.db.execute(
            f"SELECT {_BUFFER_COLUMNS} FROM slr_buffers b LEFT JOIN slr_counters c "
            f"ON c.buffer_id = b.id{where} ORDER BY b.id")
        return [dict(zip(_BUFFER_KEYS, row)) for row in rows]

    def has_active_buffer(self, kind: str) -> bool:
        """Whether a buffer of ``kind`` (``"tBuffer"``, ``"cBuffer"``, ...) is active, in any
        process (one probe of a table of a few rows: asked at every clock move).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).has_active_buffer("tBuffer")
        False
        """
        return bool(self.db.execute(
            "SELECT 1 FROM slr_buffers WHERE kind = ? AND removed_at IS NULL LIMIT 1",
            (kind,)))

    def insert_buffer(self, kind: str, source: str, pattern_text: str, type_name: str,
                      type_arity: int, amount: float | None, t1: float | None,
                      t2: float | None, origin: str) -> int:
        """Add a row to ``slr_buffers`` (and its counters); returns the new buffer id."""
        with self.db.transaction():
            buffer_id = int(self.db.execute(
                "INSERT INTO slr_buffers (kind, source, pattern_text, type_name, type_arity, "
                "amount, t1, t2, origin, created_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?) "
                "RETURNING id",
                (kind, source, pattern_text, type_name, type_arity, amount, t1, t2, origin,
                 float(self.db.clock.now())))[0][0])
            if kind == "tBuffer" and hasattr(self.db, "tbuffers_active"):
                self.db.tbuffers_active = True
            self.db.execute(self.db.dialect.insert_ignore("slr_counters", "buffer_id", "?"),
                            (buffer_id,))
            return buffer_id

    def mark_buffer_removed(self, buffer_id: int) -> None:
        """Deactivate a buffer (its row and counters stay, for statistics)."""
        with self.db.transaction():
            self.db.execute("UPDATE slr_buffers SET removed_at = ? WHERE id = ?",
                            (float(self.db.clock.now()), int(buffer_id)))
            if hasattr(self.db, "tbuffers_active"):
                self.db.tbuffers_active = None   # (others may remain: the next add asks)

    def count_buffer(self, buffer_id: int, pruned: int = 0, dropped: int = 0) -> None:
        """Add to a buffer's counters."""
        with self.db.transaction():
            self.db.execute("UPDATE slr_counters SET pruned = pruned + ?, "
                            "dropped = dropped + ? WHERE buffer_id = ?",
                            (int(pruned), int(dropped), int(buffer_id)))

    def set_buffer_cutoff(self, buffer_id: int, cutoff: float) -> None:
        """Record the time before which a buffer has dropped events."""
        with self.db.transaction():
            self.db.execute("UPDATE slr_buffers SET cutoff = ? WHERE id = ?",
                            (float(cutoff), int(buffer_id)))

    def buffer_statements(self, plan: BufferPlan, table: str) -> dict[str, str]:
        """What :meth:`install_buffer_objects` creates for ``plan`` over ``table``, by name."""
        return self.printer.objects(plan, table)

    def buffer_objects(self, buffer_id: int) -> dict[str, str]:
        """The triggers and indexes of one buffer as installed: ``{name: sql}``."""
        bid = int(buffer_id)
        with self.db.lock:
            self.db.check_open()
            if self.printer is SQLITE_BUFFERS:
                rows = self.db.execute(
                    "SELECT name, sql FROM sqlite_master WHERE type IN ('trigger', 'index') "
                    "AND (name LIKE ? ESCAPE '!' OR name = ?)",
                    (f"slr!_buf!_{bid}!_%", f"slr_bix_{bid}"))
            else:
                # the statements are kept as the comments of the function (whose trigger
                # must exist too) and of the index
                rows = self.db.execute(
                    "SELECT p.proname, obj_description(p.oid, 'pg_proc') FROM pg_proc p "
                    "JOIN pg_namespace s ON s.oid = p.pronamespace "
                    "JOIN pg_trigger t ON t.tgfoid = p.oid AND t.tgname = p.proname "
                    "WHERE s.nspname = current_schema() AND p.proname LIKE ? "
                    "UNION ALL SELECT c.relname, obj_description(c.oid, 'pg_class') "
                    "FROM pg_class c JOIN pg_namespace s ON s.oid = c.relnamespace "
                    "WHERE s.nspname = current_schema() AND c.relkind = 'i' "
                    "AND c.relname IN (?, ?)",   # (slr_bix_N_k: its long keys, key_indexes)
                    (f"slr\\_buf\\_{bid}\\_%", f"slr_bix_{bid}", f"slr_bix_{bid}_k"))
        return {name: sql for name, sql in rows}

    def install_buffer_objects(self, plan: BufferPlan, table: str) -> bool:
        """Make the triggers/indexes of buffer ``plan`` over ``table`` exactly those this
        version generates: objects whose SQL differs are re-created, missing ones created,
        others dropped. Returns True if anything changed."""
        return self._make(int(plan.id), self.printer.objects(plan, table))

    def drop_buffer_objects(self, buffer_id: int) -> None:
        """Drop every trigger and index of one buffer."""
        self._make(int(buffer_id), {})

    def _make(self, buffer_id: int, statements: dict[str, str]) -> bool:
        sqlite = self.printer is SQLITE_BUFFERS
        with self.db.transaction():
            if not sqlite:
                self.db.lock_named("buffers")   # processes change buffer objects in turn
            existing = self.buffer_objects(buffer_id)
            changed = False
            for name, sql in existing.items():
                if statements.get(name) != sql:
                    # with the schema on PostgreSQL, as every name of a buffer's object
                    # here: the name alone reaches on to a temporary object of the session
                    # once the store's is gone
                    q = self.db.qualified(name)
                    if name.startswith("slr_bix_"):
                        self.db.execute(f"DROP INDEX IF EXISTS {q}")
                    elif sqlite:
                        self.db.execute(f"DROP TRIGGER IF EXISTS {q}")
                    else:
                        self.db.execute(f"DROP FUNCTION IF EXISTS {q}() CASCADE")
                    changed = True
            for name, sql in statements.items():
                if existing.get(name) == sql:
                    continue
                if sqlite:
                    self.db.execute(sql)
                else:
                    q = self.db.qualified(name)
                    kind = "INDEX" if name.startswith("slr_bix_") else "FUNCTION"
                    if kind == "FUNCTION":   # a half-made object of an older version
                        self.db.execute(f"DROP FUNCTION IF EXISTS {q}() CASCADE")
                    self.db.conn.execute_script(sql)
                    self.db.conn.execute_script(
                        f"COMMENT ON {kind} {q}{'()' if kind == 'FUNCTION' else ''} IS "
                        f"{sql_literal(sql)}")
                changed = True
            return changed

    def apply_buffer(self, plan: BufferPlan, table: str, now: float) -> int:
        """Apply a newly installed buffer to the rows of ``table`` already stored (what it
        would not have kept, judged at ``now``) and add them to its ``pruned`` counter."""
        sql = self.printer.prune(plan, table, now)
        if sql is None:
            return 0
        with self.db.transaction():
            if self.printer is SQLITE_BUFFERS:
                self.db.execute(sql)
                deleted = self.db.changes()
            else:   # the text as printed (no parameters)
                deleted = int(self.db.conn.execute_script(sql).rowcount)
            if deleted > 0:
                self.db.execute("UPDATE slr_counters SET pruned = pruned + ? "
                                "WHERE buffer_id = ?", (deleted, int(plan.id)))
            return max(deleted, 0)
