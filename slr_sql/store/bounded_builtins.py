"""SQLite built-ins whose one call can run for minutes, wrapped so that it cannot.

A statement's timeout (``kb.sql(..., timeout=)``, the service's ``/sql``) works through
SQLite's progress handler, which runs *between* the steps of a statement: a single call of
a built-in function runs to its end first. Four built-ins do work that grows with the
product of their arguments' lengths, and ``printf`` repeats a character as often as asked
even past the length limit:

* ``x LIKE pattern`` and ``x GLOB pattern`` (``like(pattern, x[, escape])``,
  ``glob(pattern, x)``): backtracking, ~1.3 ns per character of ``x`` times characters of
  the pattern (a 1 MB text against a 10,000-character pattern: 18 s);
* ``instr(x, y)`` and ``replace(x, y, z)``: a compare of ``y`` at each place of ``x``;
* ``trim``/``ltrim``/``rtrim(x, chars)``: a compare with each character of ``chars`` for
  each character taken off; ``json_patch(target, patch)``: each key of the patch looked up
  along the target's keys;
* ``printf('%.*c', n, 'x')`` (and ``format``): ``n`` steps even when the result is over the
  length limit and comes back NULL (n = 2,000,000,000: 9 s).

On a store connection such a call would hold the store's lock for all that time: one
request could stop every writer of a served store. Each wrapper here checks the size of
its call first and then runs SQLite's own built-in, on a private in-memory connection with
the caller's length limit, so results are SQLite's, bit for bit:

* a call whose lengths multiply past :data:`MOST_WORK` is refused: the reason is left on the
  connection's :class:`~slr_sql.store.authorizer.SqlGuard` (``denied``) and the statement
  fails with it, in words;
* a ``printf``/``format`` that repeats a character past the connection's length limit gives
  NULL at once (what SQLite gives after the long loop).

The wrappers are registered on every connection of a SQLite store
(``store/connection.py``'s registrar). The store's own SQL calls none of these functions
except ``LIKE`` on the schema's names; PostgreSQL's own built-ins honour
``statement_timeout`` and need no wrapper.

>>> import sqlite3
>>> from slr_sql.store.authorizer import harden_connection
>>> conn = sqlite3.connect(":memory:"); guard = harden_connection(conn)
>>> for f in bounded_builtins(conn, guard).functions:
...     conn.create_function(f.name, f.arity, f.fn, deterministic=f.deterministic)
>>> conn.execute("SELECT 'Cup1' LIKE 'cup%', instr('abc', 'c'), printf('%.*c', 3, 'x')").fetchall()
[(1, 3, 'xxx')]
>>> conn.execute("SELECT length(printf('%.*c', 2000000000, 'x'))").fetchall()
[(None,)]
"""
from __future__ import annotations

import re
import sqlite3
import threading
from typing import Any

from .authorizer import SqlGuard
from .functions import Native, SqlFunction, SqlFunctions

__all__ = ["bounded_builtins", "MOST_WORK", "MOST_TRIM_WORK", "MOST_JSON_PATCH_WORK"]

# The most work one call may do: the product of the lengths (in characters or bytes) of
# the text searched and of the pattern or needle. LIKE, the slowest, runs this in ~0.35 s.
MOST_WORK = 1 << 28

# trim/ltrim/rtrim(x, chars): characters taken off times characters of the set (a compare
# each, ~10 ns: the bound takes ~0.3 s).
MOST_TRIM_WORK = 1 << 25
# json_patch(target, patch): (target's length + patch's) times patch's (~30 ps each: ~0.3 s).
MOST_JSON_PATCH_WORK = 1 << 33

# A printf conversion: flags, width, precision, length modifier, conversion letter.
_CONVERSION = re.compile(r"%([-+ 0#!,]*)(\*|\d+)?(?:\.(\*|\d+))?(l{0,2})(.)", re.S)


def _length(value: Any) -> int:
    if isinstance(value, (str, bytes)):
        return len(value)
    return 0 if value is None else len(str(value))


class _Builtins:
    """SQLite's own built-ins, called on a private connection (never the store's)."""

    def __init__(self, caller: sqlite3.Connection, guard: SqlGuard) -> None:
        self.caller = caller
        self.guard = guard
        self.conn = sqlite3.connect(":memory:", check_same_thread=False)
        self.lock = threading.Lock()
        self.statements: dict[tuple[str, int], str] = {}

    def call(self, name: str, args: tuple) -> Any:
        sql = self.statements.get((name, len(args)))
        if sql is None:
            sql = f"SELECT {name}({', '.join('?' * len(args))})"
            self.statements[(name, len(args))] = sql
        with self.lock:
            # the caller's limit (a read-only statement's is lower): a result over it is
            # SQLite's "string or blob too big" here as it would be there
            self.conn.setlimit(sqlite3.SQLITE_LIMIT_LENGTH, self.length_limit())
            try:
                return self.conn.execute(sql, args).fetchone()[0]
            except sqlite3.Error as exc:
                # the caller's statement says only "user-defined function raised
                # exception": the guard keeps SQLite's own words for it
                self.guard.denied = f"{name}(): {exc}"
                raise

    def length_limit(self) -> int:
        return self.caller.getlimit(sqlite3.SQLITE_LIMIT_LENGTH)

    def bounded(self, name: str, text: Any, pattern: Any) -> None:
        """Refuse a call of ``name`` whose work (``text``'s length times ``pattern``'s) is
        over :data:`MOST_WORK`."""
        self.refuse_over(name, _length(text) * _length(pattern), MOST_WORK, text, pattern,
                         f"the two lengths may multiply to at most {MOST_WORK:,}")

    def like(self, pattern: Any, text: Any, *escape: Any) -> Any:
        # (an ESCAPE NULL is a third argument, whose answer is NULL: kept as given)
        self.bounded("like", text, pattern)
        return self.call("like", (pattern, text, *escape))

    def glob(self, pattern: Any, text: Any) -> Any:
        self.bounded("glob", text, pattern)
        return self.call("glob", (pattern, text))

    def instr(self, text: Any, needle: Any) -> Any:
        self.bounded("instr", text, needle)
        return self.call("instr", (text, needle))

    def replace(self, text: Any, old: Any, new: Any) -> Any:
        self.bounded("replace", text, old)
        return self.call("replace", (text, old, new))

    def trim(self, name: str, text: Any, chars: Any) -> Any:
        """``trim``/``ltrim``/``rtrim(text, chars)``: SQLite compares each character it
        takes off (and the first it keeps, at each end) with every character of ``chars``,
        ~10 ns a compare. The run it would take off is measured first (Python's strip,
        on at most as many characters as the bound lets through)."""
        if isinstance(text, (str, bytes)) and type(chars) is type(text) and chars:
            most = MOST_TRIM_WORK // len(chars)   # the longest run the bound lets through
            run = 0
            if name != "rtrim":
                head: Any = text[:most + 1]
                run += len(head) - len(head.lstrip(chars))
            if name != "ltrim":
                tail: Any = text[-(most + 1):]
                run += len(tail) - len(tail.rstrip(chars))
            work = (min(run, len(text)) + 2) * len(chars)
        else:
            work = _length(text) * _length(chars)
        self.refuse_over(name, work, MOST_TRIM_WORK, text, chars)
        return self.call(name, (text, chars))

    def json_patch(self, target: Any, patch: Any) -> Any:
        """``json_patch(target, patch)``: each key of ``patch`` is looked up along the keys
        of ``target``, which grows by the keys it did not have (~30 ps per character of
        the grown target times a character of the patch)."""
        work = (_length(target) + _length(patch)) * _length(patch)
        self.refuse_over("json_patch", work, MOST_JSON_PATCH_WORK, target, patch)
        return self.call("json_patch", (target, patch))

    def refuse_over(self, name: str, work: int, most: int, first: Any, second: Any,
                    bound: str = "") -> None:
        """Refuse a call of ``name`` whose ``work`` is over ``most`` (``bound``: the bound
        in words, said in parentheses)."""
        if work > most:
            self.guard.denied = (
                f"{name}() over values of {_length(first):,} and {_length(second):,} "
                f"characters is refused: one call could run for minutes, and a statement's "
                f"timeout cannot stop a call midway" + (f" ({bound})" if bound else ""))
            raise ValueError(self.guard.denied)

    def printf(self, name: str, *args: Any) -> Any:
        if args and isinstance(args[0], str) and self.repeats_past_limit(args[0], args[1:]):
            return None
        return self.call(name, args)

    def repeats_past_limit(self, form: str, args: tuple) -> bool:
        """Whether a ``%c`` of ``form`` repeats its character more often than the length
        limit allows (SQLite then loops to NULL)."""
        limit = self.length_limit()
        place = 0
        for match in _CONVERSION.finditer(form):
            _, width, precision, _, letter = match.groups()
            if letter == "%":
                continue
            if width == "*":
                place += 1
            repeat: Any = precision
            if precision == "*":
                repeat = args[place] if place < len(args) else 0
                place += 1
            place += 1
            if letter == "c" and repeat is not None:
                try:
                    if int(repeat) > limit:
                        return True
                except (TypeError, ValueError, OverflowError):
                    pass
        return False


def bounded_builtins(caller: sqlite3.Connection, guard: SqlGuard) -> SqlFunctions:
    """The wrappers of the module for one connection ``caller`` (whose length limit they
    follow, and whose ``guard`` gets the reason of a refusal).

    >>> import sqlite3
    >>> from slr_sql.store.authorizer import harden_connection
    >>> conn = sqlite3.connect(":memory:")
    >>> sorted({f.name for f in bounded_builtins(conn, harden_connection(conn)).functions})
    ['format', 'glob', 'instr', 'json_patch', 'like', 'ltrim', 'printf', 'replace', 'rtrim', 'trim']
    """
    builtins = _Builtins(caller, guard)

    def function(name: str, arity: int, fn: Any) -> SqlFunction:
        return SqlFunction(name, arity, fn, on_postgres=Native.BUILTIN)

    def printf(*args: Any) -> Any:
        return builtins.printf("printf", *args)

    def format_(*args: Any) -> Any:
        return builtins.printf("format", *args)

    def trim(name: str) -> Any:
        return lambda text, chars: builtins.trim(name, text, chars)

    return SqlFunctions((
        function("like", 2, builtins.like), function("like", 3, builtins.like),
        function("glob", 2, builtins.glob), function("instr", 2, builtins.instr),
        function("replace", 3, builtins.replace),
        function("printf", -1, printf), function("format", -1, format_),
        function("trim", 2, trim("trim")), function("ltrim", 2, trim("ltrim")),
        function("rtrim", 2, trim("rtrim")), function("json_patch", 2, builtins.json_patch),
    ), ())
