"""SQL dialects: one object per database engine, through which the store and the two rule
compilers print what differs between engines.

A dialect prints: parameters (``?``/``:name`` in slr_sql's statements, the driver's style on
the wire), column types of the tables slr_sql creates, the few statements whose syntax
differs (``INSERT OR IGNORE``, the catalog of tables, infinity), the SQL type test behind
Prolog's ``1 \\= 1.0`` (``typeof``), and a data argument used as a number. It also says how
a data argument is stored in a column: SQLite keeps the encoding of
:mod:`slr_sql.encoding` as it is (INTEGER, REAL or TEXT values in an untyped column);
PostgreSQL columns have one type, so there every data argument is ``text`` and the text
itself says the type: an integer is its decimal digits (``42``), a float always has a
``.``, an exponent or is ``inf`` (``42.0``, ``1e+22``), and an atom that would read as a
number is written as JSON (``{"$atom":"42"}``, as atoms starting with ``[``, ``{`` or
``"`` are on both engines). Text equality is then exactly Prolog's ``==`` on stored values,
which jsonb equality is not (``'1'::jsonb = '1.0'::jsonb`` is true).

>>> SQLITE.typeof("e0.arg1"), POSTGRES.typeof("e0.arg1")
('typeof(e0.arg1)', 'slr_typeof(e0.arg1)')
>>> POSTGRES.to_column(1), POSTGRES.to_column(1.0), POSTGRES.to_column("1"), POSTGRES.to_column("cup")
('1', '1.0', '{"$atom":"1"}', 'cup')
>>> POSTGRES.from_column('{"$atom":"1"}'), POSTGRES.from_column("1.0"), POSTGRES.from_column("7")
('{"$atom":"1"}', 1.0, 7)
"""
from __future__ import annotations

import json
import re
from collections.abc import Callable
from typing import Any, Protocol

from .query_printers import PostgresQueryPrinter, SQLiteQueryPrinter, Unprintable

__all__ = ["KEY_TEXT_CHARACTERS", "block_comment_end", "POSTGRES", "SQLITE", "Dialect", "PostgresDialect",
           "SQLiteDialect", "Unprintable", "short_text"]

# A stored text that reads as a number (PostgreSQL columns): integers, and Python's float
# texts (repr: always a '.', an exponent, or inf).
_INT_TEXT = re.compile(r"-?[0-9]+\Z")
_FLOAT_TEXT = re.compile(r"-?(?:[0-9]+\.[0-9]*|\.[0-9]+|[0-9]+(?=[eE]))(?:[eE][-+]?[0-9]+)?\Z"
                         r"|-?inf\Z")


# a text of fewer characters is its own key in PostgreSQL's indexes (slr_key, pg_0013)
KEY_TEXT_CHARACTERS = 64


def short_text(value: Any) -> Any:
    """``value`` when it is a text that is its own key (fewer than 64 characters), else
    None: what a ``short`` parameter of :meth:`PostgresDialect.key_equal` is bound to.

    >>> short_text("cup1"), short_text("x" * 64), short_text(None)
    ('cup1', None, None)
    """
    return value if type(value) is str and len(value) < KEY_TEXT_CHARACTERS else None


class Dialect(Protocol):
    """What differs between the SQL of two engines, as printers."""

    name: str
    paramstyle: str
    text_holds_nul: bool
    equality_index: str
    zero_signs_in_sql: bool

    def key(self, expr: str) -> str: ...
    def key_indexes(self, keys: list[str], rest: list[str]) -> list[tuple[str, str]]: ...
    def key_equal(self, expr: str, value: str, short: str | None = None) -> str: ...
    def values_equal(self, lefts: list[str], rights: list[str]) -> str | None: ...

    def statement(self, sql: str) -> str: ...
    def typeof(self, expr: str) -> str: ...
    def byte_length(self, expr: str) -> str: ...
    def value_order(self, value: str) -> list[str]: ...
    def number(self, expr: str) -> str: ...
    def infinity(self, negative: bool = False) -> str: ...
    def insert_ignore(self, table: str, columns: str, values: str) -> str: ...
    def writers_in_flight(self) -> str | None: ...
    def written_join_order(self) -> tuple[str, str] | None: ...
    def to_column(self, value: Any) -> Any: ...
    def from_column(self, value: Any) -> Any: ...


class SQLiteDialect(SQLiteQueryPrinter):
    """SQLite, the reference: every printer gives the text slr_sql always wrote.

    >>> SQLITE.insert_ignore("slr_counters", "buffer_id", "?")
    'INSERT OR IGNORE INTO slr_counters (buffer_id) VALUES (?)'
    """

    name = "sqlite"
    paramstyle = "qmark"
    integer_key = "INTEGER PRIMARY KEY"
    # an event table's seq: AUTOINCREMENT so that a sequence once used (and shipped to a
    # fleet) is never handed out again after its row is deleted (a buffer's prune)
    sequence_key = "INTEGER PRIMARY KEY AUTOINCREMENT"
    real = "REAL"
    value = ""               # an untyped column keeps INTEGER / REAL / TEXT as given
    index_hints = True       # INDEXED BY: lookups name the index they must use
    # a copy of rows reads them back with RETURNING even when no trigger may refuse one
    # (here a separate read costs less than RETURNING's buffered copy)
    copies_returning = False
    text_holds_nul = True    # a TEXT value may contain U+0000
    equality_index = ""      # how an index used only by ``=`` is built (a B-tree)
    identifier_bytes: int | None = None   # names of any length
    without_rowid = " WITHOUT ROWID"
    pages_streams = False    # a statement's rows are read as needed (sqlite3 steps it)
    to_column: Callable[[Any], Any] | None = None     # identity: no conversion at all
    from_column: Callable[[Any], Any] | None = None

    true = "1"
    false = "0"
    python_functions = True  # statements may call Python functions (create_function)

    def statement(self, sql: str) -> str:
        return sql

    def key(self, expr: str) -> str:
        """What a unique B-tree index holds of a text users choose (a type's name, a
        subscription's id): the text itself here (SQLite's keys have no length limit)."""
        return expr

    def key_indexes(self, keys: list[str], rest: list[str]) -> list[tuple[str, str]]:
        """The B-tree indexes over the texts ``keys`` (data arguments, or expressions of
        them) followed by ``rest`` (times): ``(name suffix, columns and WHERE)`` of each.

        >>> SQLITE.key_indexes(["arg1"], ["t_end", "t_start"])
        [('', '(arg1, t_end, t_start)')]
        >>> POSTGRES.key_indexes(["arg1"], ["t_end"])
        [('', '(arg1, t_end) WHERE char_length(arg1) < 64'), ('_k', '(slr_key(arg1), t_end)')]
        >>> POSTGRES.key_indexes(["arg1", "arg3"], ["t_end"])
        [('', '(arg1, arg3, t_end) WHERE char_length(arg1) < 64 AND char_length(arg3) < 64')]
        """
        return [("", f"({', '.join(keys + rest)})")]

    def key_equal(self, expr: str, value: str, short: str | None = None) -> str:
        """``expr = value``, written so that the :meth:`key_indexes` over ``expr`` serve
        it. ``value`` is an SQL expression (a named parameter may appear more than once, a
        ``?`` is then bound as often); ``short``, where the caller knows it, is ``value``
        itself for a value of fewer than 64 characters, ``"NULL"`` for a longer one, or a
        parameter bound to :func:`short_text` of the value (None: not known, a column).

        >>> SQLITE.key_equal("arg1", ":v", ":s")
        'arg1 = :v'
        >>> POSTGRES.key_equal("arg1", ":v", ":v")
        'arg1 = :v AND char_length(arg1) < 64'
        >>> POSTGRES.key_equal("arg1", "t0.arg1")
        'slr_key(arg1) = slr_key(t0.arg1) AND t0.arg1 = arg1'
        >>> POSTGRES.key_equal("arg1", ":v", ":s")
        '(CAST(:s AS text) IS NOT NULL AND arg1 = :v AND char_length(arg1) < 64 OR CAST(:s AS text) IS NULL AND slr_key(arg1) = slr_key(:v) AND :v = arg1)'
        """
        return f"{expr} = {value}"

    def values_equal(self, lefts: list[str], rights: list[str]) -> str | None:
        """One condition that every stored value of ``lefts`` is the same term as the one
        of ``rights`` at its place, or None: here each pair needs an equality of its own
        beside the SQL types' (``=`` takes 1 for 1.0), and SQLite's planner takes hundreds
        of them in its stride.

        >>> SQLITE.values_equal(["e0.arg2"], ["e1.arg2"]) is None
        True
        """
        return None

    def scalar(self, name: str) -> str:
        """The two-argument ``max``/``min`` of values (not the aggregates)."""
        return name

    def json_array(self, items: str) -> str:
        return f"json_array({items})"

    def json_integer(self, expr: str, index: int) -> str:
        return f"json_extract({expr}, '$[{index}]')"

    def json_integers(self, param: str) -> str:
        return f"SELECT value FROM json_each({param})"

    def typeof(self, expr: str) -> str:
        return f"typeof({expr})"

    def byte_length(self, expr: str) -> str:
        """A stored value's size in bytes (a number's as its text)."""
        return f"length(CAST({expr} AS BLOB))"

    def number(self, expr: str) -> str:
        return expr

    def infinity(self, negative: bool = False) -> str:
        return "-9e999" if negative else "9e999"

    def insert_ignore(self, table: str, columns: str, values: str) -> str:
        return f"INSERT OR IGNORE INTO {table} ({columns}) VALUES ({values})"

    def writers_in_flight(self) -> str | None:
        """The statement listing the other transactions that may hold uncommitted rows of
        the table named by its one parameter (None: one writer at a time commits its
        sequences in order, so a reader's snapshot never has a gap that fills later)."""
        return None

    def written_join_order(self) -> tuple[str, str] | None:
        """The statements before and after statements whose joins must run in the order
        written (None: ``CROSS JOIN`` keeps it already, as SQLite's does).

        >>> SQLITE.written_join_order() is None
        True
        """
        return None


class PostgresDialect(PostgresQueryPrinter):
    """PostgreSQL 15 or newer, through psycopg 3 (``%s`` / ``%(name)s`` parameters).

    >>> POSTGRES.statement("SELECT a FROM t WHERE b = ? AND c = :c AND d LIKE 'x%'")
    "SELECT a FROM t WHERE b = %s AND c = %(c)s AND d LIKE 'x%%'"
    >>> POSTGRES.statement("SELECT x::text, ':no' FROM t")
    "SELECT x::text, ':no' FROM t"
    """

    name = "postgresql"
    paramstyle = "format"
    integer_key = "BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY"
    sequence_key = integer_key   # an identity's sequence never hands a value out twice
    real = "DOUBLE PRECISION"
    value = " TEXT"
    index_hints = False      # the planner chooses (no INDEXED BY)
    # (a catalog read for triggers and a separate read are two more round trips)
    copies_returning = True
    text_holds_nul = False   # text cannot contain U+0000 (values escape it as JSON)
    # a B-tree entry holds at most 2,704 bytes, a hash index's only the value's 4-byte hash:
    # an index read only by ``=`` (a fact's first argument) takes a value of any length
    equality_index = " USING hash"
    identifier_bytes: int | None = 63     # longer names are cut, silently (NAMEDATALEN)
    without_rowid = ""
    pages_streams = True     # psycopg reads a whole result: lookups read growing pages

    def __init__(self) -> None:
        self._printed: dict[str, str] = {}

    def statement(self, sql: str) -> str:
        """slr_sql's parameters (``?``, ``:name``) in psycopg's style, ``%`` doubled;
        strings, quoted names, comments and ``::`` casts left alone."""
        printed = self._printed.get(sql)
        if printed is None:
            printed = self._printed[sql] = _format_params(sql)
            if len(self._printed) > 4096:
                self._printed.clear()
        return printed

    true = "TRUE"
    false = "FALSE"
    python_functions = False

    def key(self, expr: str) -> str:
        """What a unique B-tree index holds of a text users choose: ``slr_key(text)``
        (migration ``pg_0013``: the text when it has fewer than 64 characters, else its
        SHA-256 in hex), so that no entry passes the server's 2,704 bytes."""
        return f"slr_key({expr})"

    def key_indexes(self, keys: list[str], rest: list[str]) -> list[tuple[str, str]]:
        # Two indexes. A text of fewer than 64 characters (at most 252 bytes) is indexed as
        # it is, in a partial index over such rows: a lookup of a value keeps the column's
        # statistics and reads the times from the index alone, as before (over slr_key
        # only, a prev lookup read the rows of its key from the table: 2-3 times slower).
        # Every row is in the index over its slr_key: a join searches it with one
        # condition (over the long texts only, a join read both indexes as bitmaps:
        # 3 times slower). An index over two texts holds the rows whose texts are short
        if len(keys) == 1:
            key = keys[0]
            return [("", f"({', '.join(keys + rest)}) WHERE char_length({key}) < 64"),
                    ("_k", f"({', '.join([f'slr_key({key})'] + rest)})")]
        return [("", f"({', '.join(keys + rest)}) WHERE "
                     + " AND ".join(f"char_length({key}) < 64" for key in keys))]

    def key_equal(self, expr: str, value: str, short: str | None = None) -> str:
        # a short value reads the partial index (its predicate named), a long one or a
        # column the index over slr_key (key_indexes); the planner, given a value for
        # ``short``, keeps one branch of the last. (The long form's exact comparison is
        # written the other way round: an equality common to both branches would be
        # taken out of the OR)
        near = f"{expr} = {value} AND char_length({expr}) < 64"
        far = f"slr_key({expr}) = slr_key({value}) AND {value} = {expr}"
        if short == value:
            return near
        if short is None or short == "NULL":
            return far
        short = f"CAST({short} AS text)"
        return f"({short} IS NOT NULL AND {near} OR {short} IS NULL AND {far})"

    def values_equal(self, lefts: list[str], rights: list[str]) -> str | None:
        """Every stored value of ``lefts`` the same term as the one of ``rights`` at its
        place (the texts are equal exactly when the terms are: the SQL type is spelled in
        the text), as one condition of the planner's: the row comparison is the equalities
        joined by AND, under an IS TRUE that keeps the planner from taking it apart.

        One equality per argument made each its own equivalence class, and planning grew
        as the cube of their number: a rule over two events of 101 shared arguments took
        0.13 s to plan each statement, of 401 arguments 12 s (its run, milliseconds);
        folded, 1 ms and 9 ms for 1,501. (A comparison of two arrays, exact too since no
        value column holds NULL, planned 5 times slower at 1,501 arguments.) The
        equalities an index serves stay apart (:meth:`AltSQL._folded`).

        >>> POSTGRES.values_equal(["e0.arg2", "e0.arg3"], ["e1.arg2", "e1.arg3"])
        '(ROW(e0.arg2, e0.arg3) = ROW(e1.arg2, e1.arg3)) IS TRUE'
        """
        return f"(ROW({', '.join(lefts)}) = ROW({', '.join(rights)})) IS TRUE"

    def scalar(self, name: str) -> str:
        return {"max": "GREATEST", "min": "LEAST"}.get(name, name)

    def json_array(self, items: str) -> str:
        return f"json_build_array({items})::text"

    def json_integer(self, expr: str, index: int) -> str:
        return f"(({expr})::json->>{int(index)})::bigint"

    def json_integers(self, param: str) -> str:
        return f"SELECT value::bigint FROM json_array_elements_text(({param})::json)"

    def typeof(self, expr: str) -> str:
        return f"slr_typeof({expr})"

    def byte_length(self, expr: str) -> str:
        """A stored value's size in bytes (every value column is text)."""
        return f"octet_length({expr})"

    def number(self, expr: str) -> str:
        return f"slr_number({expr})"

    def infinity(self, negative: bool = False) -> str:
        return "'-infinity'::float8" if negative else "'infinity'::float8"

    def writers_in_flight(self) -> str | None:
        # a sequence is handed out at the insert, not at the commit: seq 11 may be visible
        # while 10 is still in flight. Every writer of a table holds ROW EXCLUSIVE on it
        # until its commit; a lock that waited for them (SHARE) would queue new writers
        # behind it and could close a cycle with the journals' advisory locks
        return ("SELECT virtualtransaction FROM pg_locks WHERE locktype = 'relation' "
                "AND relation = CAST(? AS regclass) AND mode = 'RowExclusiveLock' "
                "AND granted AND pid <> pg_backend_pid()")

    def insert_ignore(self, table: str, columns: str, values: str) -> str:
        return f"INSERT INTO {table} ({columns}) VALUES ({values}) ON CONFLICT DO NOTHING"

    def written_join_order(self) -> tuple[str, str] | None:
        """PostgreSQL searches the best order of up to ``join_collapse_limit`` (8) tables
        of explicit joins: for a join of 32 tables that search was ~0.5 s of planning,
        paid at every run of the statement before it is prepared. At 1 it joins in the
        order written, as the event rules' statements are written to run.

        >>> POSTGRES.written_join_order()[0]
        'SET LOCAL join_collapse_limit = 1'
        """
        return ("SET LOCAL join_collapse_limit = 1",
                "SET LOCAL join_collapse_limit TO DEFAULT")

    @staticmethod
    def to_column(value: Any) -> Any:
        """A value of :func:`slr_sql.encoding.encode` as the text of a PostgreSQL column."""
        tv = type(value)
        if tv is str:
            # an atom that would read as a number, and one holding U+0000 (which PostgreSQL
            # text cannot hold; JSON escapes it), take the tagged JSON form
            if (value and (value[0].isdigit() or value[0] in "-.i") and
                    (_INT_TEXT.match(value) or _FLOAT_TEXT.match(value))) or "\x00" in value:
                return '{"$atom":' + json.dumps(value, ensure_ascii=False) + "}"
            return value
        if tv is int:
            return str(value)
        if tv is float:
            return repr(value)
        if value is None:
            return None
        if isinstance(value, bool):
            return str(int(value))
        if isinstance(value, int):
            return str(int(value))
        if isinstance(value, float):
            return repr(float(value))
        return str(value)

    @staticmethod
    def from_column(value: Any) -> Any:
        """The inverse of :meth:`to_column`: the value :func:`slr_sql.encoding.decode` reads."""
        if type(value) is not str or not value:
            return value
        c = value[0]
        if c.isdigit() or c in "-.i":
            if _INT_TEXT.match(value):
                return int(value)
            if _FLOAT_TEXT.match(value):
                return float(value)
        return value


_NAMED = re.compile(r":([A-Za-z_][A-Za-z0-9_]*)")
# a dollar quote's opening tag: $$ or $tag$ (a tag does not start with a digit: $1 is a
# positional parameter)
_DOLLAR = re.compile(r"\$(?:[A-Za-z_\x80-\uffff][A-Za-z0-9_\x80-\uffff]*)?\$")


def block_comment_end(sql: str, at: int) -> int:
    """Where the block comment that starts at ``at`` (``/*``) ends: past its ``*/``, or the
    text's end; PostgreSQL's block comments nest.

    >>> block_comment_end("/* a /* b */ c */ SELECT 1", 0)
    17
    """
    depth, j, n = 1, at + 2, len(sql)
    while j < n and depth:
        if sql.startswith("/*", j):
            depth, j = depth + 1, j + 2
        elif sql.startswith("*/", j):
            depth, j = depth - 1, j + 2
        else:
            j += 1
    return j


def _format_params(sql: str) -> str:
    r"""``sql`` with slr_sql's parameters (``?``, ``:name``) in psycopg's style and every
    other ``%`` doubled. What PostgreSQL reads as text is left as it is: strings (``'..'``,
    escape strings ``E'..\'..'``, dollar-quoted ``$$..$$``, ``$tag$..$tag$``), quoted names,
    ``--`` and (nested) ``/* */`` comments, and ``::`` casts.

    >>> print(_format_params("SELECT /* ? 5% */ ?, $$:a$$, E'\\'?', arg1::text FROM p WHERE x = :a"))
    SELECT /* ? 5%% */ %s, $$:a$$, E'\'?', arg1::text FROM p WHERE x = %(a)s
    """
    out = []
    i = 0
    n = len(sql)
    while i < n:
        c = sql[i]
        if c == "'" or c == '"':
            # (an escape string, E'..', takes a backslash before its quote)
            escapes = c == "'" and i > 0 and sql[i - 1] in "eE" and (
                i == 1 or not (sql[i - 2].isalnum() or sql[i - 2] in "_$"))
            j = i + 1
            while j < n:
                if escapes and sql[j] == "\\":
                    j += 2
                    continue
                if sql[j] == c:
                    if j + 1 < n and sql[j + 1] == c:
                        j += 2
                        continue
                    break
                j += 1
            out.append(sql[i:j + 1].replace("%", "%%"))
            i = j + 1
        elif c == "-" and sql.startswith("--", i):
            j = sql.find("\n", i)
            j = n if j < 0 else j
            out.append(sql[i:j].replace("%", "%%"))
            i = j
        elif c == "/" and sql.startswith("/*", i):
            j = block_comment_end(sql, i)
            out.append(sql[i:j].replace("%", "%%"))
            i = j
        elif c == "$" and (m := _DOLLAR.match(sql, i)) is not None and not (
                i > 0 and (sql[i - 1].isalnum() or sql[i - 1] in "_$")):
            j = sql.find(m.group(0), m.end())
            j = n if j < 0 else j + len(m.group(0))
            out.append(sql[i:j].replace("%", "%%"))
            i = j
        elif c == "?":
            out.append("%s")
            i += 1
        elif c == ":":
            if sql.startswith("::", i):
                out.append("::")
                i += 2
                continue
            m = _NAMED.match(sql, i)
            if m:
                out.append(f"%({m.group(1)})s")
                i = m.end()
            else:
                out.append(c)
                i += 1
        elif c == "%":
            out.append("%%")
            i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


SQLITE = SQLiteDialect()
POSTGRES = PostgresDialect()
