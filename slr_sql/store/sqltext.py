"""SQL text for SQLite: quoting identifiers and constants, splitting scripts, safe table names,
the ``file:`` URI of a store and the identity of its file.

Every identifier the store writes into SQL goes through :func:`quote_identifier`; values are
bound parameters, except in ``CREATE TRIGGER`` bodies (which cannot have parameters), where
:func:`sql_literal` writes them strictly.
"""
from __future__ import annotations

import math
import os
import re
import sqlite3
from collections.abc import Iterable, Mapping
from typing import Any

from ..errors import SLRBusy, SLRError, SLRStoreFull, naming_the_store

__all__ = ["joined_balanced", "quote_identifier", "qualified_identifier", "sql_literal", "split_sql_script",
           "SAFE_IDENTIFIER", "RESERVED_PREFIXES", "SQL_KEYWORDS", "busy_error", "store_error", "disk_is_full",
           "file_uri", "file_identity"]

SAFE_IDENTIFIER = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
# Names a table or view of the store may not have, on either engine: slr_sql's own, and the
# engines' catalogs'. PostgreSQL searches pg_catalog before the store's schema (putting it
# later would let a table named ``text`` take over the type ``text`` in every cast), so a
# table named like a catalog relation (every one starts ``pg_``) would never be reached by
# an unqualified name: its inserts went to pg_catalog.pg_class, a DROP VIEW to a system view.
RESERVED_PREFIXES = ("slr_", "sqlite_", "pg_")
# SQLite keywords: an event named like one gets a sanitized table name, so that
# ``SELECT * FROM <table>`` works without quoting for every table we create.
SQL_KEYWORDS = frozenset("""
abort action add after all alter always analyze and as asc attach autoincrement before begin
between by cascade case cast check collate column commit conflict constraint create cross
current current_date current_time current_timestamp database default deferrable deferred
delete desc detach distinct do drop each else end escape except exclude exclusive exists
explain fail filter first following for foreign from full generated glob group groups having
if ignore immediate in index indexed initially inner insert instead intersect into is isnull
join key last left like limit match materialized natural no not nothing notnull null nulls of
offset on or order others outer over partition plan pragma preceding primary query raise range
recursive references regexp reindex release rename replace restrict returning right rollback
row rows savepoint select set table temp temporary then ties to transaction trigger unbounded
union unique update using vacuum values view virtual when where window with without
rowid oid _rowid_
""".split())


def busy_error(exc: BaseException, path: str | None,
               timeout: float | None = None) -> SLRBusy | None:
    """The :class:`SLRBusy` to raise for ``exc`` if it says the database stayed locked by
    another connection past the busy timeout (``SQLITE_BUSY``), else None.

    >>> print(busy_error(sqlite3.OperationalError("database is locked"), "robot.db", 5))
    robot.db: locked by another writer (a process or knowledge base) for more than 5 s
    >>> busy_error(sqlite3.OperationalError("no such table: x"), "robot.db") is None
    True
    """
    code = getattr(exc, "sqlite_errorcode", None)
    busy = (code is not None and code & 0xFF == sqlite3.SQLITE_BUSY) or \
        (code is None and "database is locked" in str(exc))
    if not busy:
        return None
    waited = f" for more than {timeout:g} s" if timeout is not None else ""
    return SLRBusy(f"{path or ':memory:'}: locked by another writer (a process or knowledge "
                   f"base){waited}")


def _primary_code(exc: BaseException) -> int | None:
    code = getattr(exc, "sqlite_errorcode", None)
    return None if code is None else code & 0xFF


def disk_is_full(path: str | None) -> bool:
    """Is the file system holding ``path`` out of space (less than 64 KiB left for this
    user)? Asked after an I/O error, whose code alone does not say (a failed ``-shm`` or
    ``-wal`` extension is ``SQLITE_IOERR``).

    >>> import tempfile
    >>> disk_is_full(tempfile.gettempdir() + "/robot.db"), disk_is_full(None)
    (False, False)
    """
    if path is None:
        return False
    import os

    try:
        info = os.statvfs(os.path.dirname(os.path.abspath(path)))
    except OSError:
        return False
    return info.f_bavail * info.f_frsize < 65536


def store_error(exc: BaseException, path: str | None, timeout: float | None = None,
                outcome: str = "nothing of this call was written") -> SLRError:
    """The :class:`SLRError` in words for a database error ``exc`` on the store ``path``:
    :class:`SLRBusy` for a lock held too long, :class:`SLRStoreFull` for a full disk (or
    size limit), "damaged" only when SQLite found the file corrupt or not a database, and
    otherwise what failed, without guessing. ``outcome`` says what became of the call.

    >>> print(store_error(sqlite3.OperationalError("database or disk is full"), "robot.db"))
    robot.db: the disk is full (or the store reached its size limit; database or disk is full); nothing of this call was written: free space and retry
    >>> print(store_error(sqlite3.OperationalError("attempt to write a readonly database"), "robot.db"))
    robot.db: the store is read-only (attempt to write a readonly database: the file, its folder or its file system may not be written by this process); nothing of this call was written: it can be read, not changed
    >>> print(store_error(sqlite3.OperationalError("datatype mismatch"), "robot.db"))
    robot.db: the store failed (datatype mismatch)
    """
    where = path or ":memory:"
    busy = busy_error(exc, path, timeout)
    if busy is not None:
        return busy
    code = _primary_code(exc)
    text = str(exc)
    if code == sqlite3.SQLITE_FULL or (code is None and "disk is full" in text) or \
            (code in (sqlite3.SQLITE_IOERR, sqlite3.SQLITE_CANTOPEN) and disk_is_full(path)):
        return SLRStoreFull(f"{where}: the disk is full (or the store reached its size limit; "
                            f"{text}); {outcome}: free space and retry")
    if code in (sqlite3.SQLITE_CORRUPT, sqlite3.SQLITE_NOTADB):
        return naming_the_store(SLRError(f"{where}: the file is damaged ({text}); restore it "
                                         f"from a copy"), where, failure=True)
    if code == sqlite3.SQLITE_READONLY or (code is None and "readonly database" in text):
        return naming_the_store(SLRError(f"{where}: the store is read-only ({text}: the file, "
                                         f"its folder or its file system may not be written "
                                         f"by this process); {outcome}: it can be read, "
                                         f"not changed"), where)
    if code == sqlite3.SQLITE_IOERR:
        return naming_the_store(SLRError(f"{where}: the disk failed to read or write the "
                                         f"store ({text})"), where, failure=True)
    # (a statement's error: a value the store cannot hold, a table another process dropped)
    return naming_the_store(SLRError(f"{where}: the store failed ({text})"), where)


def file_uri(path: str, mode: str = "ro") -> str:
    """A ``file:`` URI for ``path`` opened in ``mode`` (``ro``, or ``rw``: never made anew)
    (``%``, ``?`` and ``#`` escaped).

    >>> file_uri("/data/50%/robot?#1.db", "rw")
    'file:///data/50%25/robot%3f%231.db?mode=rw'
    >>> file_uri("//data/robot.db")
    'file:////data/robot.db?mode=ro'
    """
    quoted = os.path.abspath(path).replace("%", "%25").replace("?", "%3f").replace("#", "%23")
    # (an empty authority, then the path: a path that begins with two slashes, which POSIX
    # allows and abspath keeps, was read as 'file://AUTHORITY/...', refused by SQLite)
    return f"file://{quoted}?mode={mode}"


def file_identity(name: str) -> tuple[int, int] | None:
    """``(device, inode)`` of the file ``name``, None when there is none.

    >>> file_identity("/no/such/file") is None
    True
    """
    try:
        info = os.stat(name)
    except OSError:
        return None
    return info.st_dev, info.st_ino


# terms of one flat chain: the most that stay as written (a plan's or a lookup's usual text)
FLAT_CHAIN = 64


def joined_balanced(terms: list[str], op: str) -> str:
    """``terms`` joined by ``op`` (``AND``, ``+``: associative), as written when they are at
    most :data:`FLAT_CHAIN`, else as a balanced tree of parenthesized halves: SQLite refuses
    an expression deeper than 1000 ('Expression tree is too large'), and a chain of one term
    per argument of an event type of 1,000 arguments or more (a store holds up to ~1,990)
    was that deep, so its events could be stored but not looked up, buffered or exported.

    >>> joined_balanced(["a", "b", "c"], "AND")
    'a AND b AND c'
    >>> text = joined_balanced([f"x{i}" for i in range(200)], "+")
    >>> text.startswith("((x0 + x1 + "), text.count("x")
    (True, 200)
    """
    if len(terms) <= FLAT_CHAIN:
        return f" {op} ".join(terms)
    half = len(terms) // 2
    return f"({joined_balanced(terms[:half], op)}) {op} ({joined_balanced(terms[half:], op)})"


def quote_identifier(name: str) -> str:
    """Quote an SQL identifier (``"`` doubled).

    >>> print(quote_identifier('a"b'))
    "a""b"
    """
    return '"' + name.replace('"', '""') + '"'


def qualified_identifier(schema: str | None, name: str) -> str:
    """``name`` quoted, after its quoted ``schema`` when there is one (PostgreSQL).

    >>> print(qualified_identifier("slr", "slr_subj_p"), qualified_identifier(None, "p"))
    "slr"."slr_subj_p" "p"
    """
    if schema is None:
        return quote_identifier(name)
    return f"{quote_identifier(schema)}.{quote_identifier(name)}"


def sql_literal(value: Any) -> str:
    """Quote a constant as an SQL literal, strictly.

    The buffer triggers (slr_sql.buffers) are the one place where slr_sql writes constants
    into SQL text: ``CREATE TRIGGER`` bodies cannot have bound parameters, so a pattern
    constant such as ``bob`` in ``cBuffer(face(bob, L), 1)`` must appear as a literal. Only
    ``int`` (64-bit), finite or infinite ``float`` and ``str`` without NUL are accepted;
    quotes are doubled; anything else is rejected.

    >>> sql_literal("it's"), sql_literal(3), sql_literal(0.5), sql_literal(float("inf"))
    ("'it''s'", '3', '0.5', '9e999')
    >>> sql_literal(True)
    Traceback (most recent call last):
    ...
    TypeError: no SQL literal for bool value True
    """
    tv = type(value)
    if tv is int or (isinstance(value, int) and tv is not bool):
        value = int(value)
        if not -(2 ** 63) <= value < 2 ** 63:
            raise ValueError(f"integer {value} does not fit an SQL literal")
        return repr(value)
    if tv is float or (isinstance(value, float) and tv is not bool):
        value = float(value)
        if value != value:
            raise ValueError("NaN has no SQL literal")
        if value == math.inf:
            return "9e999"
        if value == -math.inf:
            return "-9e999"
        return repr(value)
    if isinstance(value, str):
        text = str.__str__(value)
        if "\x00" in text:
            raise ValueError("a NUL character cannot be written as an SQL literal")
        return "'" + text.replace("'", "''") + "'"
    raise TypeError(f"no SQL literal for {tv.__name__} value {value!r}")


def split_sql_script(script: str) -> list[str]:
    """Split SQL text into complete statements (trigger bodies stay whole).

    >>> split_sql_script("CREATE TABLE a(x); CREATE TABLE b(y);")
    ['CREATE TABLE a(x);', 'CREATE TABLE b(y);']
    """
    statements = []
    buffer = ""
    pieces = script.split(";")
    for number, piece in enumerate(pieces):
        buffer += piece
        if number < len(pieces) - 1:
            buffer += ";"
            # a ';' inside a string or a trigger body does not end the statement
            if sqlite3.complete_statement(buffer):
                if _has_sql(buffer):
                    statements.append(buffer.strip())
                buffer = ""
    if _has_sql(buffer):  # a last statement without its ';'
        statements.append(buffer.strip())
    return statements


def _has_sql(text: str) -> bool:
    stripped = re.sub(r"--[^\n]*|/\*.*?\*/", "", text, flags=re.S)
    return stripped.strip(" \t\r\n;") != ""


def bound_parameters(params: Iterable[Any] | Mapping[str, Any]) -> tuple[Any, ...] | dict[str, Any]:
    """``kb.sql``'s parameters as a driver takes them: a mapping (for ``:name`` placeholders)
    stays a mapping, anything else becomes a tuple (for ``?``); a mapping must not become
    the tuple of its keys.

    >>> bound_parameters({"x": 1}), bound_parameters([1, 2])
    ({'x': 1}, (1, 2))
    """
    if isinstance(params, Mapping):
        return dict(params)
    return tuple(params)
