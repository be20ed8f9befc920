"""One store in a PostgreSQL schema: the connection, transactions, deadlines and raw SQL.

:class:`PgDatabase` offers what :class:`~slr_sql.store.connection.Database` offers the parts
of an :class:`~slr_sql.store.EventStore` (``conn``, ``lock``, ``transaction()``,
``tx_depth``...), so the parts run unchanged where the SQL is the same and ask
``db.dialect`` (:data:`~slr_sql.store.dialect.POSTGRES`) where it is not. ``conn`` is a
:class:`PgConnection`: it prints every statement's parameters in psycopg's style, runs it
on one psycopg 3 connection in autocommit mode (transactions are explicit ``BEGIN`` /
``SAVEPOINT``, as on SQLite), and turns every psycopg error into an
:class:`~slr_sql.errors.SLRError` or a :class:`PgStatementError` (a ``DatabaseError``).

URL: ``postgresql://USER@HOST:PORT/DB`` or ``postgres://``; every libpq parameter in the
query string is passed through (``?host=/socket/dir&sslmode=require``), except ``schema``
(default ``slr``): the PostgreSQL schema holding the store's tables. A schema with tables
but no store is refused unless ``adopt=True``. ``timeout=`` of queries becomes the
statement's ``statement_timeout``; a lock wait longer than ``busy_timeout`` is
:class:`~slr_sql.errors.SLRBusy` (``lock_timeout``).
"""
from __future__ import annotations

import math
import re
import sqlite3
import threading
import time
import weakref
import zlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager, nullcontext, suppress
from itertools import chain
from typing import Any
from urllib.parse import parse_qsl, urlencode, urlsplit

from ..errors import CLOSED_WHILE_RUNNING, STOPPED_BY_CALLER, SLRBusy, SLRCancelled, SLRError, \
    SLRServerUnreachable, SLRStatementTimeout, SLRTimeout, SLRUnavailable, naming_the_store
from ..lockorder import ordered_lock
from .connection import ChangedMeanwhile, Database, DatabaseError, drop_commit_callbacks, in_own_transaction, \
    is_postgres_url, merge_commit_callbacks, run_after_rollback, \
    password_token, run_commit_callbacks, shown_location
from .authorizer import transaction_control_refusal
from .dialect import POSTGRES, block_comment_end
from .functions import SqlFunctions
from .schema import postgres_migration_scripts
from .sqltext import bound_parameters, qualified_identifier, quote_identifier

__all__ = ["PgDatabase", "PgStatementError", "is_postgres_url", "split_url", "PENDING_CHANNEL"]

_STORE_TABLES = frozenset({"slr_meta", "slr_program", "slr_event_types"})

# The channel the event rules' pending rows notify when a statement inserts or updates some
# (payload: the store's schema; migration pg_0011_pending_notify.sql)
PENDING_CHANNEL = "slr_pending"
# How often the connection of an idle store that listens reads its socket on its own
# (seconds): the server then moves the store's place in its notification queue on
DRAIN_PERIOD = 0.5


class PgStatementError(sqlite3.DatabaseError):
    """A statement failed on the PostgreSQL server (the message is the server's).

    It derives from ``sqlite3.DatabaseError`` only so that the store's one
    :data:`~slr_sql.store.DatabaseError` (which the layers above catch, and which is
    ``sqlite3.Error``) covers both engines without a tuple in every ``except``."""


def split_url(url: str) -> tuple[str, str]:
    """``(libpq connection string, schema)``: ``?schema=`` taken out, the rest passed on.

    >>> split_url("postgres://u@/db?host=/tmp&schema=fleet")
    ('postgresql://u@/db?host=%2Ftmp', 'fleet')
    >>> split_url("postgresql://u@h:5432/db")[1]
    'slr'
    """
    try:
        parts = urlsplit(url)
    except ValueError as exc:       # a bracket of an IPv6 address missing, ...
        raise SLRError(f"{shown_location(url)}: not a PostgreSQL URL ({exc})") from None
    query = parse_qsl(parts.query, keep_blank_values=True)
    schema = "slr"
    kept = []
    for key, value in query:
        if key == "schema":
            schema = value
        else:
            kept.append((key, value))
    if not schema or "\x00" in schema:
        raise SLRError(f"{shown_location(url)}: schema= must name a PostgreSQL schema")
    # (written out rather than urlunsplit, which drops the "//" of a URL with no host --
    # postgresql:///db, the local server's socket -- and libpq reads no URL in the rest)
    query = urlencode(kept)
    return f"postgresql://{parts.netloc}{parts.path}{'?' if query else ''}{query}", schema


def _psycopg() -> Any:
    try:
        import psycopg
    except ImportError:  # pragma: no cover - the extra is installed in tests
        raise SLRError("a postgresql:// store needs psycopg 3: pip install "
                       "'slr_sql[postgres]'") from None
    return psycopg


def _error(exc: BaseException, where: str, busy_timeout: float | None = None,
           connected: bool | None = None) -> Exception:
    """The slr_sql exception for a psycopg error, by what happened rather than by psycopg's
    class (which makes an invalid savepoint name or a function without RETURN an
    ``OperationalError``, as it does a lost server). ``connected``: the connection is still
    up after the error (None: not known; then an error with an SQLSTATE other than one the
    server ends a session with is an answer of the server, so its connection is up). In
    this order:

    * a deadlock (40P01), a serialization conflict (40001), a lock wait past
      ``busy_timeout`` (55P03), an object in use by another session (55006: a database
      another session is connected to; not the session's own use of it, such as a table
      its own open query reads, which a retry meets again): :class:`SLRBusy`;
    * a cancel (57014) at the session's ``statement_timeout`` (the server's words say so):
      :class:`SLRStatementTimeout`, not retryable; any other cancel: :class:`SLRCancelled`
      (the call's own timeout, a ``statement_timeout`` set for it, is told apart by the
      caller: :func:`_own_deadline`);
    * the server short of resources (class 53: disk, memory, connections):
      :class:`SLRUnavailable`;
    * the connection refused for good (class 28: authentication; 3D000: no such database;
      57P04: the database was dropped): a plain :class:`SLRError`;
    * the connection gone (closed, broken, never made; the server ends a session with
      08xxx or 57P01..57P05, as it does a restart): :class:`SLRServerUnreachable`;
    * anything else on a live connection is the statement's: a :class:`PgStatementError`
      with the server's words (an error the client raised without an SQLSTATE, such as
      more parameters than the protocol carries, a plain :class:`SLRError`).
    """
    psycopg = _psycopg()
    errors = psycopg.errors
    state = getattr(exc, "sqlstate", None) or ""
    if isinstance(exc, errors.DeadlockDetected):   # (broken by the server, not waited out)
        return SLRBusy(f"{where}: two writers waited for each other and the server gave "
                       f"this one up; retry ({_first_line(exc)})")
    if isinstance(exc, errors.SerializationFailure):
        return SLRBusy(f"{where}: refused as a conflicting change of another writer; retry "
                       f"({_first_line(exc)})")
    if isinstance(exc, errors.LockNotAvailable):
        waited = f" for more than {busy_timeout:g} s" if busy_timeout is not None else ""
        return SLRBusy(f"{where}: locked by another writer{waited} ({_first_line(exc)})")
    if isinstance(exc, errors.ObjectInUse) and not _in_this_session(exc):
        return SLRBusy(f"{where}: in use by another session; retry ({_first_line(exc)})")
    if isinstance(exc, errors.QueryCanceled) and _at_statement_timeout(exc):
        # (the call's own timeout= is told apart where it is set: _own_deadline)
        timed_out = SLRStatementTimeout(
            f"{where}: the server cancelled the statement at its statement_timeout setting "
            f"({_first_line(exc)}): a limit set for the server, the database or the role, "
            f"not the call's timeout=, so a retry meets it again; nothing of the call was "
            f"stored. A call's own timeout= replaces the setting for that call; otherwise "
            f"the setting must be raised (SHOW statement_timeout; ALTER ROLE ... SET "
            f"statement_timeout)")
        timed_out.reason = _first_line(exc)
        return timed_out
    if isinstance(exc, errors.QueryCanceled):
        # (the call's own timeout= is told apart where it is set: _own_deadline)
        cancelled = SLRCancelled(f"{where}: the server cancelled the statement "
                                 f"({_first_line(exc)}); nothing of the call was stored, "
                                 f"and it may be retried")
        cancelled.reason = _first_line(exc)
        return cancelled
    if state.startswith("53"):   # insufficient resources: disk, memory, connections
        return SLRUnavailable(f"{where}: the server is short of resources "
                              f"({_first_line(exc)})")
    if connected is None:
        connected = not (state.startswith("08") or state in _SESSION_ENDED or (
            not state and isinstance(exc, (psycopg.OperationalError, psycopg.InterfaceError))))
    if not connected:
        if state.startswith("28") or state in ("3D000", "57P04"):   # (no retry helps)
            return naming_the_store(SLRError(f"{where}: the server refused the connection "
                                             f"({_first_line(exc)})"), where, failure=True)
        return SLRServerUnreachable(f"{where}: the server is not reachable "
                                    f"({_first_line(exc)})")
    if isinstance(exc, (psycopg.OperationalError, psycopg.InterfaceError)) and not state:
        # e.g. more parameters than the protocol carries: refused before it was sent
        return naming_the_store(SLRError(f"{where}: the statement cannot be sent "
                                         f"({_first_line(exc)})"), where)
    if isinstance(exc, psycopg.DataError) and not state and "NUL" in str(exc):
        # (psycopg refuses it before sending: its words name its own API)
        return PgStatementError("PostgreSQL text cannot hold the character U+0000 (a value "
                                "of the statement holds it; an event's arguments can: they "
                                "are stored escaped)")
    if isinstance(exc, errors.ReadOnlySqlTransaction):
        return SLRError(f"read-only: the statement would change the store "
                        f"({_first_line(exc)}); pass write=True to allow it")
    return PgStatementError(_first_line(exc))


# SQLSTATEs (besides class 08) the server ends a session with: an administrator's or a
# shutdown's termination, a crash of another backend, a server still starting, the
# session idle too long
_SESSION_ENDED = frozenset({"57P01", "57P02", "57P03", "57P05"})


# The server's words for a cancel at its statement_timeout (postgres.c, ProcessInterrupts),
# in English; another cancel says "due to user request" (pg_cancel_backend, a client's
# cancel). A server speaking another language (lc_messages) says neither: its cancels are
# all SLRCancelled, as they were.
_STATEMENT_TIMEOUT_WORDS = "canceling statement due to statement timeout"


# The server's words for a 55006 of the session itself (tablecmds.c CheckTableNotInUse, the
# current database): nothing another session holds, so a retry meets it again. In another
# language they are not told apart: SLRBusy, as every 55006.
_OWN_USE_WORDS = ("in this session", "pending trigger events", "currently open database")


def _in_this_session(exc: BaseException) -> bool:
    """Whether an object-in-use error (55006) is about the session's own use of it."""
    diag = getattr(exc, "diag", None)
    words = getattr(diag, "message_primary", None) or str(exc)
    return any(own in words for own in _OWN_USE_WORDS)


def _at_statement_timeout(exc: BaseException) -> bool:
    """Whether a cancel (57014) came from the session's ``statement_timeout``, by the
    server's words (its primary message; SQLSTATE and severity are the same for every
    cancel)."""
    diag = getattr(exc, "diag", None)
    words = getattr(diag, "message_primary", None) or str(exc)
    return words.strip().startswith(_STATEMENT_TIMEOUT_WORDS)


def _own_deadline(exc: BaseException, deadline: float) -> BaseException:
    """``exc``, or SLRTimeout when it is a cancel of the ``statement_timeout`` set for the
    call's own ``deadline`` (``time.monotonic()``), now passed. The server's words are the
    same for that cancel and one at a ``statement_timeout`` an administrator set: the time
    tells them apart, the timeout being rounded up (:func:`_timeout_ms`) so that the
    server's never fires before the deadline (and while the call's own is set, it is the
    transaction's, replacing the administrator's)."""
    if isinstance(exc, (SLRCancelled, SLRStatementTimeout)) and time.monotonic() >= deadline:
        return SLRTimeout(f"query timed out ({exc.reason})")
    return exc


def _timeout_ms(seconds: float) -> int:
    """``statement_timeout`` (whole milliseconds, at least 1) for ``seconds``, rounded up."""
    return max(1, math.ceil(seconds * 1000))


def _connected(raw: Any) -> bool:
    """Whether a psycopg connection is still up (after an error)."""
    return not raw.closed and not getattr(raw, "broken", False)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


# Fewer rows go in as one multi-row INSERT statement; COPY takes two round trips (its start
# is answered before the data goes), and wins only on many rows.
_COPY_FROM = 64

# Parameters of one statement at most (the protocol's limit is 65,535): a wider insert is
# sent in parts.
_MAX_PARAMS = 30_000

# INSERT INTO "table" (columns) VALUES (?, ...): nothing but values, so COPY does the same
_PLAIN_INSERT = re.compile(r'INSERT INTO ("(?:[^"]|"")+"|[A-Za-z_][A-Za-z0-9_]*) '
                           r'\(([A-Za-z0-9_, ]+)\) VALUES \(\?(?:, \?)*\)\Z')


def _multi_row_insert(table: str, columns: str, width: int, rows: int) -> str:
    """``INSERT INTO table (columns) VALUES (%s, ...), ...`` for ``rows`` rows (their order
    is the order of the rows' identity values, as with one INSERT per row).

    >>> _multi_row_insert('"a"', "arg1, t_end", 2, 2)
    'INSERT INTO "a" (arg1, t_end) VALUES (%s, %s), (%s, %s)'
    """
    row = "(" + ", ".join(["%s"] * width) + ")"
    return f"INSERT INTO {table} ({columns}) VALUES " + ", ".join([row] * rows)


class _NoRowsCursor:
    """The cursor of a statement not sent yet (deferred inserts): no rows, no description."""

    rowcount = -1
    description = None

    def close(self) -> None:
        pass


_NoRows = _NoRowsCursor()


class PgCursor:
    """The part of a DB-API cursor the store's parts use, over a psycopg cursor."""

    __slots__ = ("__weakref__", "_cursor", "_owner", "description", "rowcount")

    def __init__(self, cursor: Any, owner: PgConnection):
        self._cursor = cursor
        self._owner = owner
        self.rowcount = cursor.rowcount
        self.description = cursor.description

    def fetchone(self) -> Any:
        return self._owner._guard(self._cursor.fetchone) if self.description else None

    def fetchall(self) -> list:
        return self._owner._guard(self._cursor.fetchall) if self.description else []

    def fetchmany(self, size: int) -> list:
        return self._owner._guard(lambda: self._cursor.fetchmany(size)) \
            if self.description else []

    def __iter__(self) -> Iterator:
        return iter(self.fetchall())

    def close(self) -> None:
        self._cursor.close()


def _read_notifications(raw: Any) -> None:
    """Hand what the connection's socket holds (notifications of an idle connection) to
    psycopg's handlers, without a round trip."""
    pgconn = raw.pgconn
    for _ in range(64):   # (a flood is read in rounds; the rest at the next call)
        pgconn.consume_input()
        read = 0
        while (notify := pgconn.notifies()) is not None:
            pgconn.notify_handler(notify)
            read += 1
        if not read:
            return


class WriteCheck:
    """The change check an add owes before its first statement (:meth:`PgConnection.owe`):
    ``sql`` (psycopg's placeholders, ``params``) reads one row of what another connection may
    have changed, its last column ``slr_fresh`` whether the add's decisions still hold.
    ``row`` is that row once read (None: not sent yet); ``failed``, that it said no.

    >>> check = WriteCheck("SELECT ...", ()); check.row is None
    True
    >>> check.read((7, "3", "2", False, False)); check.failed
    True
    """

    __slots__ = ("thread", "sql", "params", "row", "failed")

    def __init__(self, sql: str, params: tuple) -> None:
        self.thread = threading.get_ident()
        self.sql = sql
        self.params = params
        self.row: tuple | None = None
        self.failed = False

    def read(self, row: tuple) -> None:
        self.row = row
        self.failed = not row[-1]


# the values an add's rows may hold for its rows to go into the check's statement: a VALUES
# list outside an INSERT types its columns by itself (text and float8 here), and the
# INSERT then assigns them to the event table's text and double precision columns
_CHECKED_VALUE_TYPES = {str, float}


class PgConnection:
    """``execute``/``executemany`` with slr_sql's parameters, on one psycopg connection."""

    def __init__(self, conn: Any, where: str, busy_timeout: float):
        self.raw = conn
        self.where = where
        self.busy_timeout = busy_timeout
        self.last_rowcount = 0
        # set by PgDatabase: open a new connection, and whether a transaction is open
        self.reopen: Callable[[], Any] | None = None
        self.in_transaction: Callable[[], bool] = lambda: False
        # a BEGIN not sent yet: it goes with the transaction's first statement, in one
        # round trip (a transaction that runs nothing sends nothing)
        self.begin_pending = False
        # plain inserts of a transaction whose BEGIN is still pending, not sent yet:
        # ``{(table, columns): rows}`` in the order they came. A transaction that runs
        # nothing else (an add of a few events without rules) sends them at its COMMIT as
        # one statement, which commits on its own: one round trip instead of three.
        self.deferred: dict[tuple[str, str], list[tuple]] = {}
        self.deferred_params = 0
        # statements without a result not sent yet -- advisory locks asked for, savepoints
        # opened and released (``(text, params)``, psycopg's style): they go in the round
        # trip of the transaction's next statement, ahead of it
        self.prelude: list[tuple[str, Any]] = []
        # the change checks adds owe, by thread (WriteCheck): sent before the thread's next
        # statement, or inside it when that statement is the deferred inserts alone
        self.checks: dict[int, WriteCheck] = {}

    def owe(self, check: WriteCheck) -> WriteCheck | None:
        """Send ``check`` before (or with) this thread's next statement; returns the check
        this thread owed before, for :meth:`settle`."""
        outer = self.checks.get(check.thread)
        self.checks[check.thread] = check
        return outer

    def settle(self, check: WriteCheck, outer: WriteCheck | None) -> None:
        """The add that owed ``check`` is done with it (sent or not)."""
        if self.checks.get(check.thread) is check:
            if outer is None:
                del self.checks[check.thread]
            else:
                self.checks[check.thread] = outer

    def _before_send(self) -> None:
        """Before a statement: the change check this thread owes, if not sent yet -- first
        in the pipeline of a statement that sends the transaction's BEGIN (whose work is
        rolled back if the check says no: :meth:`_pipelined_check`), else as a statement of
        its own; after a check that said no, no statement of the add goes (the add is made
        again)."""
        if not self.checks:
            return
        check = self.checks.get(threading.get_ident())
        if check is None:
            return
        if check.row is None:
            if self.begin_pending:
                return   # (the send that opens the transaction carries it)
            self._alive()
            raw = self.raw
            check.read(self._guard(lambda: raw.execute(check.sql, check.params).fetchone()))
        if check.failed:
            raise ChangedMeanwhile("the program changed meanwhile")

    def _pipelined_check(self, begin: bool) -> WriteCheck | None:
        """The change check this thread owes and has not sent, when the pipeline about to
        go opens the transaction (``begin``): it goes first, ahead of the BEGIN, and
        :meth:`_read_pipelined` reads its answer after the pipeline."""
        if not begin or not self.checks:
            return None
        check = self.checks.get(threading.get_ident())
        return check if check is not None and check.row is None else None

    @staticmethod
    def _read_pipelined(check: WriteCheck, cursor: Any) -> None:
        """The answer of a check sent first in a pipeline; one that says no ends the add
        (the transaction the pipeline opened is rolled back, with what it ran)."""
        check.read(cursor.fetchone())
        if check.failed:
            raise ChangedMeanwhile("the program changed meanwhile")

    def _checked_inserts(self, check: WriteCheck, deferred: dict) -> tuple[str, list] | None:
        """The deferred inserts as one statement that also makes ``check``: each table's
        rows go in only when the check's ``slr_fresh`` holds (the same snapshot), and the
        statement answers the check's row. None when a row holds a value of another type
        (the check then goes as a statement of its own)."""
        params = list(check.params)
        parts = []
        for i, ((table, columns), rows) in enumerate(deferred.items()):
            if not set(map(type, chain.from_iterable(rows))) <= _CHECKED_VALUE_TYPES:
                return None
            row = "(" + ", ".join(["%s"] * len(rows[0])) + ")"
            parts.append(f"slr_part{i} AS (INSERT INTO {table} ({columns}) SELECT * FROM "
                         f"(VALUES {', '.join([row] * len(rows))}) AS slr_rows "
                         f"WHERE (SELECT slr_fresh FROM slr_check))")
            for values in rows:
                params += values
        return (f"WITH slr_check AS ({check.sql}), {', '.join(parts)} "
                f"SELECT * FROM slr_check"), params

    def lock_later(self, key: int, shared: bool = False) -> None:
        """``pg_advisory_xact_lock(key)`` (``_shared`` with ``shared``) before the next
        statement, sent with it (with the transaction's BEGIN when it is still pending)."""
        self.prelude.append((f"SELECT pg_advisory_xact_lock{'_shared' if shared else ''}(%s)",
                             (key,)))

    def savepoint_later(self, name: str) -> None:
        """``SAVEPOINT name`` before the next statement, sent with it."""
        self.prelude.append((f"SAVEPOINT {name}", None))

    def release_later(self, name: str) -> None:
        """``RELEASE name`` before the next statement, sent with it; nothing at all when
        nothing was sent since the savepoint."""
        if self.prelude and self.prelude[-1] == (f"SAVEPOINT {name}", None):
            self.prelude.pop()
        else:
            self.prelude.append((f"RELEASE {name}", None))

    def execute_unanswered(self, sql: str, params: Any = ()) -> None:
        """Run ``sql``, whose answer nobody reads (an upsert, a row count moved), in the
        open transaction: it goes in the round trip of the transaction's next statement,
        ahead of it, or with its COMMIT (its failure is that statement's, and fails the
        transaction as a whole; a rollback drops it unsent). Outside a transaction, or
        before its BEGIN went, it runs at once."""
        if self.begin_pending or not self.in_transaction():
            self.execute(sql, params)
            return
        # (parameters never None: what the COMMIT keeps of what waits, see execute)
        self.prelude.append((POSTGRES.statement(sql), tuple(params)))

    def roll_back_to(self, name: str) -> None:
        """``ROLLBACK TO name`` and ``RELEASE name``; when the savepoint itself is not sent
        yet, nothing was sent inside it: it and what followed it are dropped instead."""
        opened = (f"SAVEPOINT {name}", None)
        # (the latest of that name: an earlier nested transaction of the same depth,
        # released with its statements still waiting, may have queued it too)
        for at in range(len(self.prelude) - 1, -1, -1):
            if self.prelude[at] == opened:
                del self.prelude[at:]
                return
        self.execute(f"ROLLBACK TO {name}")
        self.execute(f"RELEASE {name}")

    def begin(self) -> None:
        """Open a transaction with the next statement."""
        self.begin_pending = True

    def send_begin(self) -> None:
        """Send a pending BEGIN now (before a statement that cannot go with it), with the
        inserts deferred until then."""
        if self.deferred:
            self.flush()
        if self.begin_pending or self.prelude:
            self._before_send()
            self._alive()
            self._guard(self._with_begin(lambda: None))

    def flush(self) -> None:
        """Send the deferred inserts (after the pending BEGIN, in the same round trip):
        before any other statement of their transaction, which may read their rows."""
        if self.deferred:
            self._before_send()
        text, params = self._take_deferred()
        if text:
            self._alive()
            raw = self.raw
            cursor = raw.cursor()
            # the rows were deferred while nothing else waited: what waits now (a lock, a
            # savepoint) came after them, and goes after them
            begin, self.begin_pending = self.begin_pending, False
            prelude, self.prelude = self.prelude, []
            check = self._pipelined_check(begin)

            def send() -> None:
                with raw.pipeline():
                    checked = raw.execute(check.sql, check.params) if check else None
                    if begin:
                        raw.execute("BEGIN")
                    cursor.execute(text, params)
                    for sql, args in prelude:
                        raw.execute(sql, args)
                if check is not None:
                    self._read_pipelined(check, checked)
            self._guard(send)

    def _take_deferred(self) -> tuple[str, list]:
        """The deferred inserts as one statement and its parameters (and none left): one
        table's rows as one multi-row INSERT, several tables' as data-modifying WITH
        parts of one statement (tables do not see each other's rows; each table's rows go
        in their order, in one INSERT)."""
        deferred = self.deferred
        if not deferred:
            return "", []
        self.deferred = {}
        self.deferred_params = 0
        parts = []
        params: list = []
        for (table, columns), rows in deferred.items():
            parts.append(_multi_row_insert(table, columns, len(rows[0]), len(rows)))
            for row in rows:
                params += row
        if len(parts) == 1:
            return parts[0], params
        ctes = ", ".join(f"slr_part{i} AS ({part})" for i, part in enumerate(parts[:-1]))
        return f"WITH {ctes} {parts[-1]}", params

    def _with_begin(self, call: Callable[[], Any]) -> Callable[[], Any]:
        """``call`` preceded by the pending BEGIN and advisory locks in one pipeline (one
        round trip)."""
        if not self.begin_pending and not self.prelude:
            return call
        begin, self.begin_pending = self.begin_pending, False
        prelude, self.prelude = self.prelude, []
        raw = self.raw
        check = self._pipelined_check(begin)

        def both() -> Any:
            with raw.pipeline():
                checked = raw.execute(check.sql, check.params) if check else None
                if begin:
                    raw.execute("BEGIN")
                for text, params in prelude:
                    raw.execute(text, params)
                result = call()
            if check is not None:
                self._read_pipelined(check, checked)
            return result
        return both

    def _alive(self) -> None:
        """A connection the server dropped (a restart, a terminated backend) is opened
        again before the next statement outside a transaction: the failed statement was an
        SLRError, the next one works. So it is in a transaction that has sent nothing yet
        (its BEGIN pending: what waits to go with it, locks, savepoints, deferred rows,
        goes on the new connection). Inside a transaction whose BEGIN went it stays an
        error (what the transaction did is gone: it must fail as a whole)."""
        if self.raw.closed and self.reopen is not None and (
                self.begin_pending or not self.in_transaction()):
            try:
                self.raw = self.reopen()
            except _psycopg().Error as exc:
                raise _error(exc, self.where, self.busy_timeout, False) from None

    def _guard(self, call: Callable[[], Any]) -> Any:
        psycopg = _psycopg()
        try:
            return call()
        except psycopg.Error as exc:
            raise _error(exc, self.where, self.busy_timeout, _connected(self.raw)) from None

    def execute(self, sql: str, params: Any = ()) -> PgCursor:
        text = POSTGRES.statement(sql)
        if isinstance(params, dict):
            args: Any = params
        else:
            args = tuple(params) if params else None
        if sql != "COMMIT" or self.begin_pending:
            # (a COMMIT whose BEGIN went, on a connection the server dropped: the server
            # rolled the transaction back; one opened again would "commit" nothing and say
            # nothing -- the transaction fails)
            self._alive()
        cursor = self._guard(self.raw.cursor)
        if self.prelude and sql in ("COMMIT", "ROLLBACK"):
            # the savepoints end with the transaction; the locks (and the statements nobody
            # reads) go before a COMMIT (what the transaction stores is stored under them),
            # not before a ROLLBACK; with the COMMIT itself once its BEGIN went
            self.prelude = [(text, params) for text, params in self.prelude
                            if sql == "COMMIT" and params is not None]
            if self.prelude and (self.begin_pending or self.deferred):
                self.send_begin()
        if self.begin_pending and sql in ("COMMIT", "ROLLBACK"):
            self.begin_pending = False   # no BEGIN was sent: nothing to end
            self.last_rowcount = 0
            check = self.checks.get(threading.get_ident()) if self.checks else None
            checked = None
            if check is not None and check.row is None and self.deferred and sql == "COMMIT":
                # the change check the add owes goes in the same statement: one round trip
                checked = self._checked_inserts(check, self.deferred)
            if checked is not None:
                self.deferred = {}
                self.deferred_params = 0
                deferred, params = checked
            else:
                if self.deferred and sql == "COMMIT":
                    self._before_send()
                deferred, params = self._take_deferred()
            if deferred and sql == "COMMIT":
                # the transaction's only statement: it commits on its own (autocommit), as
                # durably as a COMMIT, and an error in it stores none of its rows
                self._guard(lambda: cursor.execute(deferred, params))
                if checked is not None:
                    check.read(self._guard(cursor.fetchone))   # type: ignore[union-attr]
                    if check.failed:   # type: ignore[union-attr]
                        # no row went in; the transaction, which sent nothing, ends as one
                        # that did not begin
                        self.begin_pending = True
                        raise ChangedMeanwhile("the program changed meanwhile")
            return PgCursor(cursor, self)
        if self.deferred:
            self.flush()
        self._before_send()
        self._guard(self._with_begin(lambda: cursor.execute(text, args, prepare=None)))
        self.last_rowcount = cursor.rowcount
        return PgCursor(cursor, self)

    def execute_batch(self, statements: list) -> list[list[tuple]]:
        """Statements ``(sql, params, many)`` in order, in one pipeline with the pending
        BEGIN and locks (one round trip); each one's rows ([] for ``many``, whose params
        are a list of rows)."""
        if self.deferred:
            self.flush()
        self._before_send()
        self._alive()
        raw = self.raw
        cursors: list = []
        begin, self.begin_pending = self.begin_pending, False
        prelude, self.prelude = self.prelude, []
        check = self._pipelined_check(begin)

        def run() -> None:
            with raw.pipeline():
                checked = raw.execute(check.sql, check.params) if check else None
                if begin:
                    raw.execute("BEGIN")
                for text, params in prelude:
                    raw.execute(text, params)
                for sql, params, many in statements:
                    cursor = raw.cursor()
                    text = POSTGRES.statement(sql)
                    if many:
                        rows = [r if isinstance(r, dict) else tuple(r) for r in params]
                        if rows:
                            cursor.executemany(text, rows)
                        cursors.append(None)
                        continue
                    args = params if isinstance(params, dict) else (tuple(params) or None)
                    cursor.execute(text, args, prepare=None)
                    cursors.append(cursor)
            if check is not None:
                self._read_pipelined(check, checked)
        self._guard(run)
        return [self._guard(c.fetchall) if c is not None and c.description else []
                for c in cursors]

    def executemany(self, sql: str, rows: Iterable[Iterable[Any]],
                    column_types: Sequence[str] | None = None) -> PgCursor:
        """Run ``sql`` for each of ``rows``. Many rows of a plain INSERT go in by one COPY:
        in binary form when ``column_types`` names the PostgreSQL type of each column
        (numbers go as their bytes instead of being printed here and parsed by the
        server), else as text."""
        rows = [r if type(r) is tuple else tuple(r) for r in rows]
        plain = _PLAIN_INSERT.match(sql)
        if plain is not None and rows and len(rows) <= _COPY_FROM:
            return self._insert_rows(plain.group(1), plain.group(2), rows)
        if self.deferred:
            self.flush()
        self._before_send()
        self._alive()
        cursor = self.raw.cursor()
        if plain is not None and len(rows) > _COPY_FROM:
            self.send_begin()   # (COPY does not go in a pipeline)
            # many rows into one table: COPY (one stream) rather than one INSERT per row
            binary = " (FORMAT BINARY)" if column_types is not None else ""

            def copy() -> None:
                with cursor.copy(f"COPY {plain.group(1)} ({plain.group(2)}) FROM STDIN"
                                 f"{binary}") as out:
                    if column_types is not None:
                        out.set_types(list(column_types))
                    for row in rows:
                        out.write_row(row)
            self._guard(copy)
            self.last_rowcount = len(rows)
            return PgCursor(cursor, self)
        text = POSTGRES.statement(sql)
        if rows:
            self._guard(self._with_begin(lambda: cursor.executemany(text, rows)))
        self.last_rowcount = cursor.rowcount
        return PgCursor(cursor, self)

    def _insert_rows(self, table: str, columns: str, rows: list[tuple]) -> PgCursor:
        """A few rows into one table: deferred while the transaction's BEGIN is pending
        (see ``deferred``), else one multi-row INSERT now (one statement, not one per
        row: the Python work per row is the parameters alone)."""
        width = len(rows[0])
        key = (table, columns)
        if (self.begin_pending and not self.prelude
                and self.deferred_params + width * len(rows) <= _MAX_PARAMS
                and (key in self.deferred or not any(t == table for t, _ in self.deferred))):
            self.deferred.setdefault(key, []).extend(rows)
            self.deferred_params += width * len(rows)
            self.last_rowcount = len(rows)
            return PgCursor(_NoRows, self)
        if self.deferred:
            self.flush()
        self._before_send()
        self._alive()
        cursor = self.raw.cursor()
        step = max(1, _MAX_PARAMS // width)
        for at in range(0, len(rows), step):
            part = rows[at:at + step]
            params = [value for row in part for value in row]
            text = _multi_row_insert(table, columns, width, len(part))
            self._guard(self._with_begin(lambda: cursor.execute(text, params)))
        self.last_rowcount = len(rows)
        return PgCursor(cursor, self)

    @contextmanager
    def pipeline(self, rows: int) -> Iterator[None]:
        """Send the statements of the block together, in one round trip (psycopg's
        pipeline mode), when none of them copies: each of at most ``rows`` rows. While
        the transaction's BEGIN is pending the block's inserts are deferred instead
        (nothing to pipeline)."""
        if rows > _COPY_FROM or self.begin_pending:
            yield
            return
        self._before_send()
        self._alive()
        psycopg = _psycopg()
        try:
            with self.raw.pipeline():
                prelude, self.prelude = self.prelude, []
                for text, params in prelude:
                    self.raw.execute(text, params)
                yield
        except psycopg.Error as exc:
            raise _error(exc, self.where, self.busy_timeout, _connected(self.raw)) from None

    def execute_script(self, sql: str) -> PgCursor:
        """Run SQL text exactly as written (no parameters: DDL, trigger functions whose
        bodies hold ``%``, ``?`` or ``:`` of their own); several statements may be given."""
        self.send_begin()
        self._before_send()
        self._alive()
        cursor = self.raw.cursor()
        self._guard(lambda: cursor.execute(sql, None, prepare=False))
        self.last_rowcount = cursor.rowcount
        return PgCursor(cursor, self)

    def close(self) -> None:
        # closing a connection the server already dropped: nothing is left to close
        with suppress(_psycopg().Error):
            self.raw.close()

    def rollback(self) -> None:
        """ROLLBACK, if the connection still works (a dropped connection's transaction is
        rolled back by the server)."""
        self.deferred = {}
        self.deferred_params = 0
        self.prelude = []
        if self.begin_pending:
            self.begin_pending = False
            return
        with suppress(_psycopg().Error):
            self.raw.execute("ROLLBACK")


def _read_error(exc: BaseException, where: str) -> SLRError:
    """The SLRError of a read that failed with ``exc``: itself when it is one (the server's
    conditions), else the statement's own error named after it, in SQLite's words.

    >>> _read_error(PgStatementError('relation "j" does not exist'), "db")
    SLRError('db: the store failed (relation "j" does not exist)')
    """
    return exc if isinstance(exc, SLRError) else \
        naming_the_store(SLRError(f"{where}: the store failed ({exc})"), where)


# The greatest lock_timeout (ms) the server takes: an int setting
_MOST_LOCK_TIMEOUT_MS = 2 ** 31 - 1


def _lock_timeout_ms(busy_timeout: float) -> int:
    """``lock_timeout`` in milliseconds for ``busy_timeout`` seconds (checked: a number
    >= 0): at least 1, since 0 means no limit to the server, and at most what the server
    takes (~24 days).

    >>> _lock_timeout_ms(0.3), _lock_timeout_ms(0), _lock_timeout_ms(1e30)
    (300, 1, 2147483647)
    """
    return min(max(1, int(busy_timeout * 1000)), _MOST_LOCK_TIMEOUT_MS)


# How often (ms) the server looks whether the client of a running statement is still there.
# Without it a statement whose process was killed (SIGKILL, a crash, a timeout's kill)
# runs on to its end -- an add's event-rule detection holding the writer's locks of its
# types for as long as it takes, minutes for a join the planner does badly -- since the
# server only notices a closed socket when it next sends; with it, within a second.
_CLIENT_CHECK_MS = 1000


def _check_client_while_running(raw: Any) -> None:
    """Make the server of the psycopg connection ``raw`` (autocommit, no transaction open)
    end a statement of it whose client has gone (:data:`_CLIENT_CHECK_MS`). A server that
    cannot look (an operating system without the check) keeps its default: the setting is
    refused there, which changes nothing else."""
    try:
        raw.execute(f"SET client_connection_check_interval = {_CLIENT_CHECK_MS}")
    except _psycopg().Error:
        pass


class PgReadConnection:
    """A read-only connection of its own to a store's schema (see
    :meth:`PgDatabase.open_reader`): each statement sees what was committed when it
    started."""

    def __init__(self, conninfo: str, schema: str, where: str, busy_timeout: float):
        psycopg = _psycopg()
        self.lock = ordered_lock("store.reader")
        self.closed = False
        # a failure is classified as the store's own connection's when it is opened again
        # (PgConnection._alive): a server that does not answer is SLRServerUnreachable
        opening = f"{where}: cannot open a reading connection"

        def prepare(raw: Any) -> None:
            raw.execute("SET default_transaction_read_only = on")
            # a lock of another session (LOCK TABLE, an ALTER TABLE not committed yet) is
            # waited for busy_timeout at most, then SLRBusy (55P03), as on the store's own
            # connection; without it a read would wait as long as the lock is held
            raw.execute(f"SET lock_timeout = {_lock_timeout_ms(busy_timeout)}")
            _check_client_while_running(raw)
            raw.execute(_search_path(schema))

        try:
            raw = psycopg.connect(conninfo, autocommit=True)
        except psycopg.Error as exc:
            raise _error(exc, opening, busy_timeout, False) from None
        try:
            prepare(raw)
        except psycopg.Error as exc:
            reason = _error(exc, opening, busy_timeout, _connected(raw))
            raw.close()
            raise reason if isinstance(reason, SLRError) else \
                SLRError(f"{opening} ({_first_line(exc)})") from None

        def reopen() -> Any:
            again = psycopg.connect(conninfo, autocommit=True)
            try:
                prepare(again)
            except BaseException:
                again.close()
                raise
            return again

        self.conn = PgConnection(raw, where, busy_timeout)
        # a connection the server dropped (a restart, a terminated backend) is opened again
        # before the next read, as the store's own is: the subscriptions' hub keeps one
        # reader for its whole life, and a reader left closed failed every delivery pass
        # after a restart (no subscriber got anything more until the process restarted)
        self.conn.reopen = reopen

    def execute(self, sql: str, params: Iterable[Any] = ()) -> list[tuple]:
        """Run one reading statement and return its rows. Every failure is an
        :class:`SLRError`, as a SQLite store's reading connection says it: the server's
        conditions in the connection's words, a statement's own error (a journal another
        session dropped) named after it."""
        with self.lock:
            if self.closed:
                raise SLRError("the event store is closed")
            try:
                return self.conn.execute(sql, tuple(params)).fetchall()
            except PgStatementError as exc:
                raise _read_error(exc, self.conn.where) from None

    def close(self) -> None:
        """Close the connection (idempotent)."""
        with self.lock:
            if not self.closed:
                self.closed = True
                self.conn.close()


# The most read-only statements of kb.sql that may still run on the server after their
# callers gave up at their timeouts: a built-in such as LIKE over long values runs to its end
# before the server looks at statement_timeout (a 6 MB text LIKE a 20,000-character pattern:
# 258 s past a 0.5 s timeout). Past it, kb.sql answers SLRUnavailable (retryable).
MOST_ABANDONED = 2
# The most read-only statements of kb.sql that run on connections of their own at once (the
# abandoned ones included): more callers wait for one to end, so threads or a service's
# requests do not open a connection each (the server's max_connections is shared).
MOST_RUNNING = 4
# Seconds past its timeout a caller waits for the server to stop the statement itself.
STOP_GRACE = 0.5

# Seconds stop_queries waits for a query's cancelled statement to end before it cancels it
# again (doubling up to 2 s), and seconds one cancel request may take
CANCEL_AGAIN = 0.1
STOP_CANCEL_TIMEOUT = 5.0
# Seconds a stopped read-only statement of kb.sql (on a connection of its own) is cancelled
# again for, until its thread has ended
CANCEL_AGAIN_FOR = 60.0
# around a statement no stop can end (PgDatabase.run_compiled without one)
_NOT_STOPPABLE = nullcontext()


# A transaction-control statement, by its first keywords (PostgreSQL's "Transaction
# Control" commands: COMMIT PREPARED and ROLLBACK PREPARED start as COMMIT and ROLLBACK)
_TRANSACTION_CONTROL = re.compile(
    r"(BEGIN|START(?:\s+TRANSACTION)?|COMMIT|END|ROLLBACK|ABORT|SAVEPOINT|RELEASE"
    r"|PREPARE\s+TRANSACTION|SET\s+TRANSACTION|SET\s+SESSION\s+CHARACTERISTICS)\b", re.I | re.A)
_WORD = re.compile(r"\w+", re.A)
_LINE_END = re.compile(r"[\n\r]")


def _transaction_control(statement: str) -> str | None:
    """The keywords of ``statement`` when it is a transaction-control statement (which the
    store refuses in a hand-written statement: its connection's transactions are the
    store's), else None. Comments before it are skipped as the server skips them, block
    comments nested, and a line comment ends at ``\\n`` or ``\\r``; whatever the server takes
    for layout, ``str.isspace`` takes too (a misreading could only refuse more, never let a
    transaction-control statement through).

    >>> _transaction_control("/* a /* nested */ comment */ -- a line\\r  commit work")
    'COMMIT'
    >>> _transaction_control("SET TRANSACTION READ ONLY"), _transaction_control("SELECT 1")
    ('SET TRANSACTION', None)
    """
    found = _TRANSACTION_CONTROL.match(statement, _first_word(statement))
    if found is None:
        return None
    return " ".join(_WORD.findall(found.group(1))).upper()


def _search_path(schema: str, local: bool = False) -> str:
    """The ``SET search_path`` of a connection of the store: its schema, then ``pg_temp``
    named last. Unnamed, the session's temporary schema is searched first, and a temporary
    table a written statement made (``CREATE TEMP TABLE p (x int)``) would hide the store's
    table of the same name from every later statement of the connection.

    >>> _search_path('slr'), _search_path('slr', local=True)
    ('SET search_path = "slr", pg_temp', 'SET LOCAL search_path = "slr", pg_temp')
    """
    return f"SET{' LOCAL' if local else ''} search_path = {quote_identifier(schema)}, pg_temp"


def _first_word(statement: str) -> int:
    """Where ``statement``'s first word begins: past the layout and comments before it, as
    :func:`_transaction_control` says."""
    at, n = 0, len(statement)
    while at < n:
        if statement[at].isspace():
            at += 1
        elif statement.startswith("--", at):   # (to the end of the line, \n or \r)
            end = _LINE_END.search(statement, at)
            at = n if end is None else end.end()
        elif statement.startswith("/*", at):
            at = block_comment_end(statement, at)
        else:
            break
    return at


def _refuse_transaction_control(statement: str) -> None:
    """Raise the SLRError of a hand-written transaction-control ``statement``."""
    keywords = _transaction_control(statement)
    if keywords is not None:
        raise SLRError(f"sql: {transaction_control_refusal(keywords)}")


# A statement that changes a setting of the session by its first keywords (SET CONSTRAINTS
# is the transaction's constraint timing, no setting; SET TRANSACTION and SET SESSION
# CHARACTERISTICS are transaction control)
_SETTING = re.compile(r"(?:RESET|SET(?!\s+CONSTRAINTS\b))\b", re.I | re.A)

# What a statement with write=True may not change on the store's connection: every setting a
# session may set (contexts user and superuser: SET, SET LOCAL, RESET, set_config() however
# called, a function's body included), and the role and session user (SET ROLE, SET SESSION
# AUTHORIZATION), read in the statement's transaction before and after it: the users, and a
# digest of the settings named (their names, read once: pg_settings itself costs the server
# ~1 ms a read, these ~0.15 ms). The digest is read only while the users are those given
# (None: any): another role may not be allowed to read some of the settings.
_SETTING_NAMES = ("SELECT string_agg(name, ',' ORDER BY name) FROM pg_settings "
                  "WHERE context IN ('user', 'superuser')")
_SESSION_STATE = ("SELECT current_user || '/' || session_user, CASE WHEN %(users)s::text IS "
                  "NULL OR current_user || '/' || session_user = %(users)s::text THEN (SELECT "
                  "md5(string_agg(coalesce(current_setting(n, true), ''), ',' ORDER BY i)) "
                  "FROM unnest(string_to_array(%(names)s, ',')) WITH ORDINALITY AS s(n, i)) "
                  "END")
_SESSION_SETTINGS = ("SELECT name, setting FROM pg_settings "
                     "WHERE context IN ('user', 'superuser') "
                     "UNION ALL SELECT 'role', current_user::text "
                     "UNION ALL SELECT 'session_authorization', session_user::text")
# Each table of a schema (the parameter) -> the rows inserted and updated in it by this
# transaction so far (None for every table when the server keeps no such counters)
_ROWS_WRITTEN = ("SELECT relname, CASE WHEN current_setting('track_counts')::boolean "
                 "THEN n_tup_ins + n_tup_upd END FROM pg_stat_xact_user_tables "
                 "WHERE schemaname = %s")
_SETTING_REFUSAL = ("a setting of the store's own connection would last for every later "
                    "statement of the store (its search_path, role, timeouts, durability, "
                    "how values print); a setting for every session of a role or database: "
                    "ALTER ROLE ... SET, ALTER DATABASE ... SET")


def _refuse_setting(statement: str) -> None:
    """Raise the SLRError of a hand-written written statement that is a ``SET`` or ``RESET``
    (of a setting, the role, the session authorization; ``LOCAL`` or not)."""
    found = _SETTING.match(statement, _first_word(statement))
    if found is not None:
        raise SLRError(f"sql: {found.group(0).upper()} is not allowed with write=True: "
                       f"{_SETTING_REFUSAL}")


def _settings_taken_back(raw: Any, own: bool) -> str:
    """Roll back a written statement that changed the session's settings (``own``: its own
    transaction; else to the savepoint ``slr_sql_write`` before it, released) and name what
    it had changed (``''`` when that cannot be told: a setting hidden from the role it
    set)."""
    after = dict(raw.execute(_SESSION_SETTINGS).fetchall())
    if own:
        raw.execute("ROLLBACK")
    else:
        raw.execute("ROLLBACK TO SAVEPOINT slr_sql_write")
        raw.execute("RELEASE SAVEPOINT slr_sql_write")
    before = dict(raw.execute(_SESSION_SETTINGS).fetchall())
    return ", ".join(sorted(name for name, setting in after.items()
                            if name in before and before[name] != setting))


def _one_statement(raw: Any, statement: str, bound: Any) -> tuple[list[str], list[tuple]]:
    """Run the one read-only ``statement`` of a caller on ``raw`` and return ``(column
    names, rows)``. Sent in a pipeline, so always by the extended protocol, which refuses a
    second statement in the text (the simple protocol, psycopg's choice without parameters,
    would run ``COMMIT; SET ...; COMMIT; DELETE ...`` past the READ ONLY transaction)."""
    cursor = raw.cursor()
    with raw.pipeline():
        cursor.execute(statement, bound, prepare=False)
    columns = [d.name for d in cursor.description] if cursor.description else []
    rows = [tuple(r) for r in cursor.fetchall()] if cursor.description else []
    return columns, rows


def _leave_nothing(raw: Any) -> None:
    """End a read-only statement's transaction on ``raw`` so that nothing of it outlives it:
    ROLLBACK (not COMMIT) takes back the session settings it changed (``SET``,
    ``set_config``: the read-only default, search_path, how floats print), and the session
    advisory locks it took are let go (the store's own are transaction locks)."""
    raw.execute("ROLLBACK; SELECT pg_advisory_unlock_all()")   # (one round trip)


class _DetachedStatement:
    """One statement of :class:`DetachedStatements` while it runs: its connection (once it
    has one), the event its caller waits for, and what ended the wait early (the caller
    gave up at its timeout, or the store stopped its queries)."""

    __slots__ = ("raw", "finished", "ended", "abandoned", "stopped")

    def __init__(self) -> None:
        self.raw: Any = None
        self.finished = threading.Event()   # its caller stops waiting
        self.ended = threading.Event()      # its thread is done with the server
        self.abandoned = False
        self.stopped = False


class DetachedStatements:
    """The read-only statements of ``kb.sql`` outside a transaction, each on a connection of
    its own in a thread of its own: the store's connection and lock are never held by them
    (a writer goes on while one runs), and a caller with a timeout gets SLRTimeout when the
    timeout (plus :data:`STOP_GRACE`) has passed even if the server has not stopped the
    statement yet. The abandoned statement's thread closes its connection when the server
    is done; at most :data:`MOST_ABANDONED` may be abandoned at once. One idle connection
    is kept for the next statement. :meth:`stop` (a close is coming) ends the callers
    still waiting at once and cancels their statements."""

    def __init__(self, conninfo: str, schema: str, where: str, busy_timeout: float):
        self.conninfo = conninfo
        self.schema = schema
        self.where = where
        self.busy_timeout = busy_timeout
        self.lock = threading.Lock()
        self.idle: Any = None          # a psycopg connection ready for the next statement
        self.abandoned = 0
        self.closed = False
        self.stopped = False           # stop(): no statement starts any more
        self.running: set[_DetachedStatement] = set()
        # a slot per statement running on a connection of its own (MOST_RUNNING at most)
        self.slots = threading.BoundedSemaphore(MOST_RUNNING)

    def _connect(self) -> Any:
        psycopg = _psycopg()
        raw = psycopg.connect(self.conninfo, autocommit=True)
        try:
            raw.execute("SET default_transaction_read_only = on")
            raw.execute("SET TIME ZONE 'UTC'")
            raw.execute(f"SET lock_timeout = {_lock_timeout_ms(self.busy_timeout)}")
            _check_client_while_running(raw)
            raw.execute(_search_path(self.schema))
        except BaseException:
            raw.close()
            raise
        return raw

    def _refuse_if_ended(self) -> None:
        """(the lock held) The store's words once it stopped its queries or closed."""
        if self.closed:
            raise SLRError("the event store is closed")
        if self.stopped:
            raise SLRError(CLOSED_WHILE_RUNNING)

    def run(self, statement: str, bound: Any,
            timeout: float | None) -> tuple[list[str], list[tuple]]:
        """Run one read-only ``statement`` (already in psycopg's style; ``bound``: its
        parameters or None) and return ``(column names, rows)``."""
        with self.lock:
            self._refuse_if_ended()
            if self.abandoned >= MOST_ABANDONED:
                raise SLRUnavailable(
                    f"{self.where}: {self.abandoned} earlier SQL statements still run on the "
                    f"server past their timeouts (a built-in over long values runs to its end "
                    f"before the server stops it); try again later")
        deadline = None if timeout is None else time.monotonic() + timeout
        # (waiting for a slot counts against the caller's timeout)
        if not self.slots.acquire(timeout=timeout):
            # (a condition that passes as the others end: SLRBusy, the service's 503 with
            # Retry-After, not a timeout of a statement that never started)
            raise SLRBusy(f"{self.where}: the {MOST_RUNNING} connections that run read-only "
                          f"SQL statements were all busy for the {timeout:g} s this one could "
                          f"wait; it did not start (try again)")
        one = _DetachedStatement()
        with self.lock:
            raw, self.idle = self.idle, None
            try:
                self._refuse_if_ended()
            except SLRError:
                self.slots.release()
                if raw is not None:
                    with suppress(Exception):
                        raw.close()
                raise
            self.running.add(one)
            one.raw = raw
        if deadline is not None:   # (what is left of it; a statement_timeout of 0 is none)
            timeout = max(0.001, deadline - time.monotonic())
        outcome: dict[str, Any] = {}

        def connected(new: Any) -> None:
            """(a new connection) Stop cancels its statement from now on; and once stop
            ran (while it connected, when no cancel could reach it), nothing is sent."""
            with self.lock:
                one.raw = new
                if one.stopped:
                    raise SLRError(CLOSED_WHILE_RUNNING)

        def refuse_if_stopped() -> None:
            # the last look before the statement is sent: a stop from now on is met by its
            # cancels (again until this thread is done, as a cancel that comes before the
            # statement is lost)
            with self.lock:
                if one.stopped:
                    raise SLRError(CLOSED_WHILE_RUNNING)

        def work() -> None:
            nonlocal raw
            psycopg = _psycopg()
            try:
                if raw is None:
                    raw = self._connect()
                    connected(raw)
                    raw.execute("BEGIN READ ONLY")
                else:
                    try:
                        raw.execute("BEGIN READ ONLY")
                    except psycopg.OperationalError:
                        # the kept connection was dropped while idle (a server restart,
                        # idle_session_timeout, an administrator): nothing was sent, a new
                        # one runs the statement
                        with suppress(Exception):
                            raw.close()
                        raw = None
                        raw = self._connect()
                        connected(raw)
                        raw.execute("BEGIN READ ONLY")
                try:
                    if timeout is not None:
                        raw.execute(f"SET LOCAL statement_timeout = {_timeout_ms(timeout)}")
                    refuse_if_stopped()
                    columns, rows = _one_statement(raw, statement, bound)
                finally:
                    # (the connection is kept for the next statement: see _leave_nothing)
                    if _connected(raw):
                        _leave_nothing(raw)
                outcome["value"] = (columns, rows)
            except psycopg.Error as exc:
                error = _error(exc, self.where, self.busy_timeout,
                               raw is not None and _connected(raw))
                outcome["error"] = error if deadline is None else _own_deadline(error, deadline)
            except BaseException as exc:   # handed to the caller, whatever it is
                outcome["error"] = exc
            finally:
                with self.lock:
                    self.running.discard(one)
                    if one.abandoned:
                        self.abandoned -= 1
                    keep = (raw is not None and _connected(raw) and not self.closed
                            and not self.stopped and self.idle is None
                            and "value" in outcome)
                    if keep:
                        self.idle = raw
                if not keep and raw is not None:
                    with suppress(Exception):
                        raw.close()
                self.slots.release()
                one.ended.set()
                one.finished.set()

        threading.Thread(target=work, name="slr-sql-statement", daemon=True).start()
        if not one.finished.wait(None if timeout is None else timeout + STOP_GRACE):
            with self.lock:
                if not one.finished.is_set():
                    one.abandoned = True
                    self.abandoned += 1
            if one.abandoned:
                raise SLRTimeout(
                    f"query timed out (the server had not stopped the statement "
                    f"{timeout + STOP_GRACE:g} s after it began; it is left to finish on "
                    f"its own connection)")
            one.finished.wait()
        if "value" in outcome:
            return outcome["value"]
        if one.stopped:   # (ended by stop(), or the server's cancel it sent)
            raise SLRError(CLOSED_WHILE_RUNNING)
        raise outcome["error"]

    def stop(self) -> None:
        """End the statements running now, a close coming: each caller gets SLRError
        "the knowledge base was closed while the query ran" at once, and each statement is
        cancelled on the server (``cancel_safe``), again until its thread is done with it
        -- a cancel that reaches the server before the statement runs is lost (the server
        shows it active from its Parse message on) -- in a thread of its own, so the close
        does not wait; none starts any more."""
        with self.lock:
            self.stopped = True
            running = list(self.running)
            for one in running:
                one.stopped = True
        for one in running:
            one.finished.set()
        if running:
            threading.Thread(target=self._cancel_until_ended, args=(running,),
                             name="slr-sql-cancel", daemon=True).start()

    def _cancel_until_ended(self, running: list[_DetachedStatement]) -> None:
        """Cancel each of ``running``'s statements until its thread has ended (a pause of
        :data:`CANCEL_AGAIN` doubling up to 2 s between rounds), for at most
        :data:`CANCEL_AGAIN_FOR` seconds: past that the statement runs on to its end on its
        own connection, as one abandoned at its timeout."""
        pause = CANCEL_AGAIN
        give_up = time.monotonic() + CANCEL_AGAIN_FOR
        while True:
            left = [one for one in running if not one.ended.is_set()]
            if not left or time.monotonic() > give_up:
                return
            for one in left:
                with self.lock:
                    raw = one.raw
                if raw is not None:
                    with suppress(Exception):   # (its thread may be closing it meanwhile)
                        raw.cancel_safe(timeout=STOP_CANCEL_TIMEOUT)
            left[0].ended.wait(pause)
            pause = min(pause * 2, 2.0)

    def close(self) -> None:
        """Close the idle connection; a running statement's thread closes its own."""
        with self.lock:
            self.closed = True
            raw, self.idle = self.idle, None
        if raw is not None:
            with suppress(Exception):
                raw.close()


class PgDatabase:
    """The connection of one store in a PostgreSQL schema, with its lock, transaction
    depth and clock (the counterpart of :class:`~slr_sql.store.connection.Database`)."""

    dialect = POSTGRES
    checkpointer = None

    def __init__(self, url: str, clock: Any = None, busy_timeout: float = 5.0,
                 adopt: bool = False):
        from .connection import WallClock, check_busy_timeout
        busy_timeout = check_busy_timeout(busy_timeout)
        psycopg = _psycopg()
        conninfo, schema = split_url(url)
        self.url = url
        self.conninfo = conninfo
        self.path = shown_location(url)
        self.schema = schema
        self.clock = clock if clock is not None else WallClock()
        self.lock = ordered_lock("store", reentrant=True)
        self.tx_depth = 0
        self.closed = False
        self.rollback_listeners: list[Callable[[], None]] = []
        # (depth registered at, callback): called once the outermost transaction committed
        # and let go of the lock; dropped with the (nested) transaction that rolls back
        self.commit_callbacks: list[tuple[int, Callable[[], None], bool]] = []
        self.open_streams: weakref.WeakSet = weakref.WeakSet()
        self.deadline: float | None = None
        self.functions: SqlFunctions | None = None  # install_functions
        self.busy_timeout = busy_timeout
        self.notify_channel = f"slr_{schema}"
        # notifications heard of other sessions' changes of the pending rows (others_version)
        self.others_pending = 0
        # whether the store's connection LISTENs to them: from the first look on (a store
        # that never looks, having no event rules, leaves the server's queue alone)
        self.listening = False
        # set to stop the thread that drains the listening connection (_start_draining)
        self.draining = threading.Event()
        self.write_groups: dict[tuple[str, int], int] = {}
        # whether a tBuffer is active, as of the last read of the versions (None: unknown)
        self.tbuffers_active: bool | None = None
        # the settings a written statement may not change (sql_write), read at its first
        self.setting_names: str | None = None
        # a written statement failed in the caller's transaction, which it left aborted: the
        # session advisory locks it may have taken are let go at the transaction's end
        self.session_locks_left = False
        # set by stop_queries, before a close: a query's statement still running (which holds
        # the lock the close waits for) is cancelled, and none starts any more
        self.stopping = False
        # the thread whose query's statement runs on the store's connection now (None: none),
        # and the condition its end is told by
        self.query_thread: int | None = None
        self.query_ended = threading.Condition(threading.Lock())
        # the stop of the query whose statement the server runs now (None: none), while it
        # runs: what stop_query cancels (the statement only, never what comes after it)
        self.query_stop: threading.Event | None = None
        try:
            raw = psycopg.connect(conninfo, autocommit=True)
        except psycopg.Error as exc:
            reason = _first_line(exc)
            secret = password_token(url)
            if secret:
                # libpq quotes a token it cannot decode: the password, when it is one
                reason = reason.replace(secret, "***")
            raise naming_the_store(SLRError(f"{self.path}: cannot connect ({reason})"),
                                   self.path, failure=True) from None
        self.conn = PgConnection(raw, self.path, busy_timeout)
        self.detached = DetachedStatements(conninfo, schema, self.path, busy_timeout)
        try:
            try:
                raw.execute(f"SET lock_timeout = {_lock_timeout_ms(busy_timeout)}")
                raw.execute("SET TIME ZONE 'UTC'")
                _check_client_while_running(raw)
                _migrate_postgres(self, schema, adopt)
                raw.execute(_search_path(schema))

                def reopen() -> Any:
                    again = psycopg.connect(conninfo, autocommit=True)
                    again.execute(f"SET lock_timeout = {_lock_timeout_ms(busy_timeout)}")
                    again.execute("SET TIME ZONE 'UTC'")
                    _check_client_while_running(again)
                    again.execute(_search_path(schema))
                    if self.listening:
                        self._listen_for_pending(again)
                    # (what was notified while no connection listened is unknown)
                    self.others_pending += 1
                    return again
                self.conn.reopen = reopen
                self.conn.in_transaction = lambda: self.tx_depth > 0
            except psycopg.Error as exc:
                raise _error(exc, self.path, busy_timeout, _connected(raw)) from None
        except BaseException:
            self.conn.close()
            raise

    # ------------------------------------------------------------------ lifecycle

    def schema_version(self) -> int:
        return int(self.execute("SELECT coalesce(max(number), 0) FROM slr_migrations")[0][0])

    def data_version(self) -> int:
        """A number that moves when any connection may have committed a change: the next
        transaction id of the server (``pg_snapshot_xmax``), which every writing
        transaction advances and no read does. It moves for other databases' writes too:
        a false alarm costs the caller one cheap re-check, never a missed change."""
        return int(self.execute(
            "SELECT pg_snapshot_xmax(pg_current_snapshot())::text::bigint")[0][0])

    def _listen_for_pending(self, raw: Any) -> None:
        """LISTEN on ``raw`` (the store's connection) to the pending rows' channel: psycopg
        hands what it reads during a statement to :meth:`_heard`, and
        :meth:`others_version` reads what came while the connection was idle."""
        # (the connection's own session, read now: while a dropped connection is replaced,
        # the store's may be the old one, whose pid cannot be read once closed)
        own = raw.info.backend_pid
        raw.add_notify_handler(lambda notify: self._heard(notify, own))
        raw.execute(f"LISTEN {PENDING_CHANNEL}")

    def _heard(self, notify: Any, own: int) -> None:
        if notify.channel == PENDING_CHANNEL and notify.payload == self.schema \
                and notify.pid != own:
            self.others_pending += 1

    def others_version(self) -> int:
        """A number that moves when another session inserted or updated the event rules'
        pending rows (they notify, pg_0011_pending_notify.sql): what the store's
        connection heard, read from its socket without a round trip. A connection lost
        and opened again moves it (what was said meanwhile is unknown).

        The connection LISTENs from the first look made outside a transaction on (a LISTEN
        in one is heard only from its commit); until then every look moves the number, so
        the caller reads what is pending itself. A store that never looks (no event rules)
        never listens: a listener that reads nothing would hold the notifications of every
        other session in the server's queue (docs/postgres.md)."""
        with self.lock:
            self.check_open()
            raw = self.conn.raw
            if raw.closed:
                return self.others_pending + 1
            if not self.listening:
                self.others_pending += 1
                if self.tx_depth == 0:
                    try:
                        self._listen_for_pending(raw)
                    except _psycopg().Error:
                        return self.others_pending   # (the next statement opens it again)
                    self.listening = True
                    self._start_draining()
                return self.others_pending
            try:
                _read_notifications(raw)
            except _psycopg().Error:
                return self.others_pending + 1   # (the next statement opens it again)
            return self.others_pending

    def _start_draining(self) -> None:
        """A daemon thread reads the listening connection's socket every
        :data:`DRAIN_PERIOD` seconds while the store's lock is free. The server sends a
        listening session's notifications to its socket as they come: were nobody to read
        them while the store makes no call, the socket's buffers would fill, the session
        would stop reading the server's queue, and every later notification of every
        session would be kept there for it (a full queue fails the notifying commits).
        It never waits for the lock (a store at work reads its socket itself) and holds a
        weak reference: a store dropped without close() ends it too."""
        stop = self.draining
        store = weakref.ref(self)

        def drain() -> None:
            while not stop.wait(DRAIN_PERIOD):
                db = store()
                if db is None:
                    return
                if db.lock.acquire(blocking=False):
                    try:
                        raw = db.conn.raw
                        if not db.closed and db.tx_depth == 0 and not raw.closed:
                            with suppress(_psycopg().Error):   # (the next statement says it)
                                _read_notifications(raw)
                    finally:
                        db.lock.release()
                del db

        threading.Thread(target=drain, name="slr-pg-drain", daemon=True).start()

    def table_names(self) -> set[str]:
        """Names of the tables of the store's schema (all of the catalog's reads run through
        :meth:`execute`: a closed store says so, and opens no connection again)."""
        return {row[0] for row in self.execute(
            "SELECT tablename FROM pg_tables WHERE schemaname = current_schema()")}

    def set_write_groups(self, groups: Iterable[Iterable[tuple[str, int]]]) -> None:
        """Each type of a group gets the group's advisory lock key: a number derived from
        the schema and the group's least type, so every process computes the same one."""
        keys: dict[tuple[str, int], int] = {}
        for group in groups:
            members = sorted(group)
            if not members:
                continue
            first = f"{self.schema}\x00{members[0][0]}/{members[0][1]}".encode()
            key = zlib.crc32(first) | (zlib.adler32(first) << 32)
            key = key - (1 << 64) if key >= 1 << 63 else key
            for member in members:
                keys[member] = key
        self.write_groups = keys

    def lock_for_write(self, types: Iterable[tuple[str, int]]) -> None:
        """``pg_advisory_xact_lock`` of the groups of ``types``, in key order (no deadlock
        between two writers of several groups); held until the transaction ends."""
        groups = self.write_groups
        if not groups:
            return
        keys = sorted({groups[t] for t in types if t in groups})
        for key in keys:   # (taken with the transaction's next statement, before it)
            self.conn.lock_later(key)

    def open_reader(self) -> PgReadConnection:
        """A read-only connection of its own (a reader that must not queue behind this
        connection's lock, held by a writer for a whole transaction)."""
        self.check_open()
        return PgReadConnection(self.conninfo, self.schema, self.path, self.busy_timeout)

    def listen(self, callback: Callable[[], Any]) -> Callable[[], None]:
        """LISTEN on the store's channel on a connection of its own, in a daemon thread:
        ``callback()`` for every notification (the journals' triggers send one per
        statement). Returns the function that stops the thread. A lost connection is
        opened again after a second (meanwhile the readers' own polling covers)."""
        psycopg = _psycopg()
        stopped = threading.Event()
        channel = quote_identifier(self.notify_channel)
        conninfo = self.conninfo

        def run() -> None:
            while not stopped.is_set():
                try:
                    with psycopg.connect(conninfo, autocommit=True) as conn:
                        conn.execute(f"LISTEN {channel}")
                        while not stopped.is_set():
                            for _ in conn.notifies(timeout=0.5):
                                callback()
                except psycopg.Error:
                    stopped.wait(1.0)

        thread = threading.Thread(target=run, name="slr-listen", daemon=True)
        thread.start()

        def stop() -> None:
            stopped.set()
            thread.join(timeout=5.0)
        return stop

    def lock_named(self, name: str) -> None:
        """Inside a transaction: take the advisory lock ``name`` of this store's schema
        until it ends (writers of the program texts take turns: their ids are the next
        free number)."""
        self.conn.execute("SELECT pg_advisory_xact_lock(hashtext(?))", (f"{self.schema}:{name}",))

    def triggers(self, table: str | None = None) -> set[str]:
        """Names of the triggers of the store's schema (on ``table`` only, when given)."""
        return {row[0] for row in self.execute(
            "SELECT t.tgname FROM pg_trigger t JOIN pg_class c ON c.oid = t.tgrelid "
            "JOIN pg_namespace n ON n.oid = c.relnamespace WHERE NOT t.tgisinternal "
            "AND n.nspname = current_schema() AND (?::text IS NULL OR c.relname = ?)",
            (table, table))}

    def hypothetical_plan(self, sql: str, extra: dict[str, str],
                          without: Iterable[str] = ()) -> list[str] | None:
        """None: PostgreSQL's planner weighs the tables' statistics, so a plan asked of an
        empty copy of the schema would say nothing of the plan on the data (the callers
        build what a statement may use, conservatively)."""
        return None

    def plan_memo(self) -> dict[tuple, Any] | None:
        """None: there is no copy of the schema to ask (:meth:`hypothetical_plan`)."""
        return None

    def index_names(self, table: str) -> set[str]:
        """Names of the indexes of ``table`` in the store's schema."""
        return {row[0] for row in self.execute(
            "SELECT indexname FROM pg_indexes WHERE schemaname = current_schema() "
            "AND tablename = ?", (table,))}

    def qualified(self, name: str) -> str:
        """The store's object ``name`` with its schema, as the store's statements name an
        object that may be missing (a journal another process dropped, a view a user
        dropped). Unqualified, the search path would go on past the schema to ``pg_temp``,
        and ``DROP TABLE IF EXISTS`` would drop, a ``DELETE`` empty, a read answer, a
        temporary object of the same name a written ``kb.sql`` statement made."""
        return qualified_identifier(self.schema, name)

    def object_names(self) -> set[str]:
        """Lower-cased names of the tables, views, indexes and sequences of the schema."""
        return {row[0].lower() for row in self.execute(
            "SELECT c.relname FROM pg_class c JOIN pg_namespace n ON n.oid = c.relnamespace "
            "WHERE n.nspname = current_schema()")}

    def view_statements(self, names: Iterable[str]) -> dict[str, str]:
        """``{view name: the statement that creates it}`` of the named views of the schema."""
        found = dict(self.execute(
            "SELECT viewname, definition FROM pg_views WHERE schemaname = current_schema()"))
        return {name: f"CREATE VIEW {quote_identifier(name)} AS {found[name]}"
                for name in names if name in found}

    max_columns = 1600

    def suspend_streams(self) -> None:
        for stream in list(self.open_streams):
            stream.suspend()

    def stop_queries(self) -> None:
        """(:meth:`Database.stop_queries`) The statement of a compiled query running on the
        store's connection outside a transaction is cancelled (``cancel_safe``: a request of
        its own to the server), again until it has ended -- a cancel that reaches the server
        before the statement is lost -- each sent while the query is known to run, so that
        it never reaches another thread's write after it; one started later is refused; the
        read-only
        ``kb.sql`` statements running on connections of their own end too
        (:meth:`DetachedStatements.stop`). Returns once no query's statement runs on the
        store's connection."""
        psycopg = _psycopg()
        pause = CANCEL_AGAIN
        self.detached.stop()   # (kb.sql's statements on connections of their own)
        with self.query_ended:
            self.stopping = True
            running = self.query_thread
        while running is not None and running != threading.get_ident():
            with self.query_ended:
                # (sent only while the query's statement is known to run, this condition
                # held: its thread clears query_thread under it before it lets go of the
                # store's lock, so no other statement -- another thread's write, which a
                # close never cuts -- can be sent on the connection until the server has
                # the cancel; one that finds the query ended is discarded by the idle
                # backend)
                if self.query_thread is not None:
                    with suppress(psycopg.Error):
                        self.conn.raw.cancel_safe(timeout=STOP_CANCEL_TIMEOUT)
                    self.query_ended.wait(pause)
                running = self.query_thread
            pause = min(pause * 2, 2.0)

    def stop_query(self, stop: threading.Event) -> None:
        """(:meth:`Database.stop_query`) The statement of the query whose ``stop`` it is
        (just set), if the server runs it now, is cancelled (``cancel_safe``) in a thread of
        its own, so that the caller (the service's event loop) never waits: again until it
        has ended -- a cancel that reaches the server before the statement is lost -- each
        sent while the statement is known to run (as :meth:`stop_queries` sends its own), so
        that no other statement of the connection is cut, not even the query's own
        ``ROLLBACK`` after it. A statement of that query starting later is refused (it
        looks at ``stop`` first). It takes no lock it would wait for: a signal handler of
        the statement's own thread may call it (the shell's Ctrl-C)."""
        if self.query_ended.acquire(blocking=False):
            try:
                if self.query_stop is not stop:
                    return
            finally:
                self.query_ended.release()
        # (else its holder is the statement's thread as the statement starts or ends -- this
        # very thread, maybe, in a signal handler: never waited for -- or a cancel under way:
        # a thread of its own looks)
        threading.Thread(target=self._cancel_while_running, args=(stop,),
                         name="slr-sql-stop", daemon=True).start()

    def _cancel_while_running(self, stop: threading.Event) -> None:
        """Cancel the statement of the query whose ``stop`` it is until it has ended (a pause
        of :data:`CANCEL_AGAIN` doubling up to 2 s between two cancels)."""
        pause = CANCEL_AGAIN
        with self.query_ended:
            while self.query_stop is stop:
                # (this condition held: the statement's thread clears query_stop under it
                # as soon as the statement ended, before it sends anything else)
                with suppress(Exception):   # (a thread of its own: nobody to tell)
                    self.conn.raw.cancel_safe(timeout=STOP_CANCEL_TIMEOUT)
                self.query_ended.wait(pause)
                pause = min(pause * 2, 2.0)

    @contextmanager
    def _stoppable(self, stop: threading.Event) -> Iterator[None]:
        """Around the statement of a query given a ``stop`` (the lock held, the statement
        alone: not its BEGIN, SET or ROLLBACK): known to :meth:`stop_query`, which cancels
        it; refused when ``stop`` is set already, and a cancel it met once ``stop`` is set
        said in the words of a stop (:data:`STOPPED_BY_CALLER`). Only for a query's
        statement that may fail without failing the caller's transaction (outside one, or
        in a savepoint: ``may_fall_back``)."""
        with self.query_ended:
            if stop.is_set():
                raise SLRError(STOPPED_BY_CALLER)
            self.query_stop = stop
        try:
            yield
        except SLRCancelled:
            if stop.is_set() and not self.stopping:   # (a close's cancel: said as such)
                raise SLRError(STOPPED_BY_CALLER) from None
            raise
        finally:
            with self.query_ended:
                self.query_stop = None
                self.query_ended.notify_all()

    @contextmanager
    def _query_statement(self) -> Iterator[None]:
        """Around a query's statement on the store's connection (the lock held): known to
        :meth:`stop_queries`, which cancels it; once stopping, refused (and a cancel it met
        said in the words of a close)."""
        with self.query_ended:
            if self.stopping:
                raise SLRError(CLOSED_WHILE_RUNNING)
            self.query_thread = threading.get_ident()
        try:
            yield
        except SLRCancelled:
            if self.stopping:
                raise SLRError(CLOSED_WHILE_RUNNING) from None
            raise
        finally:
            with self.query_ended:
                self.query_thread = None
                self.query_ended.notify_all()

    def close(self) -> None:
        self.stop_queries()
        self.draining.set()
        with self.lock:
            if self.closed:
                return
            self.closed = True
            try:
                if self.tx_depth:
                    self.conn.rollback()
                    self.tx_depth = 0
                self.suspend_streams()
            finally:
                self.detached.close()
                self.conn.close()

    def check_open(self) -> None:
        if self.closed:
            raise SLRError("the event store is closed")

    def read_error(self, exc: BaseException) -> SLRError:
        """The SLRError of a read of this connection that failed with ``exc`` (what the
        store's reading connections say, :class:`PgReadConnection`)."""
        return _read_error(exc, self.path)

    def failure(self, exc: BaseException) -> BaseException:
        """What a statement that failed with ``exc`` raises (see ``Database.failure``):
        ``exc`` itself, as the connection said it -- the server's conditions in words
        already (:func:`_error`), a statement's own error a :class:`PgStatementError`."""
        return exc

    # ------------------------------------------------------------------ transactions

    @contextmanager
    def transaction(self, wait: bool = True, listeners: bool = True,
                    join: bool = False) -> Iterator[PgDatabase]:
        """(:meth:`Database.transaction`) ``wait=False``: a lock another session holds is
        not waited for (SLRBusy at once), nested or not: work a reader may leave for later.
        ``listeners=False``: a rollback does not call the rollback listeners. ``join``: in a
        transaction of this thread, no savepoint of its own (see Database.transaction)."""
        if join and in_own_transaction(self):
            yield self
            return
        committed: list[tuple[int, Callable[[], None], bool]] = []
        try:
            with self.lock:
                self.check_open()
                depth = self.tx_depth
                conn = self.conn
                if depth == 0:
                    self.suspend_streams()
                    conn.begin()
                else:   # (sent with the next statement: a savepoint nothing uses costs nothing)
                    conn.savepoint_later(f"slr_sp{depth}")
                self.tx_depth = depth + 1
                try:
                    outer = None
                    if not wait:
                        if depth:
                            # a SET LOCAL outlives the savepoint's release: the setting the
                            # enclosing transaction had (busy_timeout, 1 ms in one that does
                            # not wait either, its own) is put back before the release
                            outer = conn.execute("SHOW lock_timeout").fetchone()[0]
                        conn.execute("SET LOCAL lock_timeout = 1")
                    yield self
                    if outer is not None:
                        conn.execute("SELECT set_config('lock_timeout', ?, true)", (outer,))
                except BaseException:
                    self.tx_depth = depth
                    committed = drop_commit_callbacks(self.commit_callbacks, depth)
                    try:
                        if depth == 0:
                            conn.rollback()
                        else:
                            conn.roll_back_to(f"slr_sp{depth}")
                    except (SLRError, DatabaseError):
                        # (the connection lost, the server's transaction is gone with it:
                        # the enclosing levels' statements and COMMIT fail; the error that
                        # ends this level is what its caller must hear)
                        pass
                    finally:
                        if depth == 0:
                            self._let_go_of_session_locks()
                        if listeners:
                            self._rolled_back()
                    raise
                self.tx_depth = depth
                try:
                    if depth == 0:
                        conn.execute("COMMIT")
                    else:
                        conn.release_later(f"slr_sp{depth}")
                except BaseException:
                    committed = drop_commit_callbacks(self.commit_callbacks, depth)
                    if depth == 0:
                        conn.rollback()
                    if listeners:
                        self._rolled_back()
                    raise
                finally:
                    if depth == 0:
                        self._let_go_of_session_locks()
                if depth == 0 and self.commit_callbacks:   # (taken under the lock: ours)
                    committed, self.commit_callbacks = self.commit_callbacks, []
                elif depth:   # (released into the enclosing one: its callbacks now)
                    merge_commit_callbacks(self.commit_callbacks, depth)
        except BaseException as exc:
            if committed:   # (rolled back: what a rollback does not take back)
                run_after_rollback(committed, exc)
            raise
        run_commit_callbacks(committed)

    def _let_go_of_session_locks(self) -> None:
        """After a transaction in which a written statement failed: ``pg_advisory_unlock_all``
        (the lock held, outside any transaction; a lost connection's locks went with it)."""
        if self.session_locks_left:
            self.session_locks_left = False
            with suppress(_psycopg().Error):
                self.conn.raw.execute("SELECT pg_advisory_unlock_all()")

    # (the same lock, depth and callbacks as SQLite's Database: one implementation)
    _rolled_back = Database._rolled_back
    after_commit = Database.after_commit

    # ------------------------------------------------------------------ raw SQL

    def sql(self, query: str, params: Iterable[Any] = (), write: bool = False,
            timeout: float | None = None) -> tuple[list[str], list[tuple]]:
        """Run one statement as given (``slr sql``): read-only (a READ ONLY transaction)
        unless ``write``; ``timeout`` seconds as ``statement_timeout``. A read-only statement
        outside a transaction runs on a connection of its own (:class:`DetachedStatements`):
        it never holds the store's lock, and its caller stops waiting at the timeout. A
        transaction-control statement (BEGIN, COMMIT, ...) is refused, written or not; a
        written one may not change a setting of the session (:meth:`sql_write`)."""
        _refuse_transaction_control(query)
        if write:
            columns, rows, _ = self.sql_write(query, params, timeout)
            return columns, rows
        with self.lock:
            self.check_open()
            detached = self.tx_depth == 0
        if detached:
            bound = bound_parameters(params)
            return self.detached.run(
                self.dialect.statement(query) if bound else query, bound or None, timeout)
        with self.lock:
            self.check_open()
            own, raw, deadline = self._raw_statement(timeout)
            try:
                return self._read_only(raw, own, query, params, timeout)
            except _psycopg().Error as exc:
                raise self._raw_statement_error(exc, raw, deadline) from None

    def _raw_statement(self, timeout: float | None) -> tuple[bool, Any, float | None]:
        """For one statement of :meth:`sql` on the store's connection (the lock held):
        whether it is a transaction of its own (else the caller's transaction is begun
        first), the raw connection, and the deadline of ``timeout``."""
        own = self.tx_depth == 0
        if not own:
            self.conn.send_begin()
        return own, self.conn.raw, None if timeout is None else time.monotonic() + timeout

    def _raw_statement_error(self, exc: Exception, raw: Any, deadline: float | None
                             ) -> Exception:
        """The slr_sql error for a statement of :meth:`sql` that failed (past its own
        deadline: its timeout's)."""
        error = _error(exc, self.path, self.busy_timeout, _connected(raw))
        return error if deadline is None else _own_deadline(error, deadline)

    def sql_write(self, query: str, params: Iterable[Any] = (), timeout: float | None = None
                  ) -> tuple[list[str], list[tuple], set[str]]:
        """Run one statement as ``sql(..., write=True)`` does, and say which tables of the
        store's schema it inserted rows into or updated: those whose row counters of the
        transaction (``pg_stat_xact_user_tables``) moved, so rows written by a trigger, a
        rule or a function count, whatever the statement's spelling (all the schema's
        tables when the server keeps no counters, ``track_counts = off``). The deferred
        constraint triggers run before the counters are read (``SET CONSTRAINTS ALL
        IMMEDIATE``: in a transaction of the caller's, its deferrable constraints are
        immediate from then on). The statement is sent alone, by the extended protocol (a
        second statement in the text is refused by the server), and a transaction-control
        statement is refused before anything is sent: the store's connection's transactions
        are the store's. So is a ``SET`` or ``RESET``; a statement that changed a setting of
        the session all the same (``set_config``, in a function or a ``DO`` block), or the
        role, is rolled back (in a transaction of the caller's, to a savepoint before it)
        and refused: the store's connection's settings are the store's. The session advisory
        locks it took are let go after it (in a caller's transaction it failed in, at that
        transaction's end), as after a read-only statement."""
        _refuse_transaction_control(query)
        _refuse_setting(query)
        with self.lock:
            self.check_open()
            psycopg = _psycopg()
            own, raw, deadline = self._raw_statement(timeout)
            try:
                if self.setting_names is None:
                    self.setting_names = raw.execute(_SETTING_NAMES).fetchone()[0] or ""
                state = {"users": None, "names": self.setting_names}
                with raw.pipeline():   # (one round trip)
                    raw.execute("BEGIN" if own else "SAVEPOINT slr_sql_write")
                    # (a SET LOCAL lasts to the caller's transaction's end: put back after)
                    shown = raw.execute("SHOW statement_timeout") \
                        if timeout is not None and not own else None
                    if timeout is not None:
                        raw.execute(f"SET LOCAL statement_timeout = {_timeout_ms(timeout)}")
                    counted = raw.execute(_ROWS_WRITTEN, (self.schema,))
                    marked = raw.execute(_SESSION_STATE, state)
                outer_timeout = None if shown is None else shown.fetchone()[0]
                before = dict(counted.fetchall())
                session = marked.fetchone()
                state["users"] = session[0]
                cursor = raw.cursor()
                # the API's placeholders (`?`, `:name`) in psycopg's style, as on SQLite;
                # without parameters the text goes as written (a `%` stays a `%`)
                bound = bound_parameters(params)
                with raw.pipeline():   # (the extended protocol: this one statement only)
                    if bound:
                        cursor.execute(self.dialect.statement(query), bound, prepare=False)
                    else:
                        cursor.execute(query, None, prepare=False)
                columns = [d.name for d in cursor.description] if cursor.description else []
                rows = [tuple(r) for r in cursor.fetchall()] if cursor.description else []
                with raw.pipeline():
                    # (a deferred constraint trigger would write at the commit, after the
                    # counters are read: it runs now, and its writes count as the statement's)
                    raw.execute("SET CONSTRAINTS ALL IMMEDIATE")
                    counted = raw.execute(_ROWS_WRITTEN, (self.schema,))
                    marked = raw.execute(_SESSION_STATE, state)
                after = dict(counted.fetchall())
                if marked.fetchone() != session:
                    changed = _settings_taken_back(raw, own)
                    raw.execute("SELECT pg_advisory_unlock_all()")
                    raise SLRError(
                        f"sql: the statement changed {changed or 'a setting'} of the session, "
                        f"which is not allowed with write=True: {_SETTING_REFUSAL}; it was "
                        f"rolled back, nothing of it was written")
                written = {table for table, count in after.items()
                           if count is None or count != before.get(table)}
                # a session advisory lock the statement took would be held as long as the
                # store's connection (the store's own are transaction locks): let go, as after
                # a read-only statement
                if own:
                    raw.execute("COMMIT; SELECT pg_advisory_unlock_all()")   # (one round trip)
                else:
                    with raw.pipeline():
                        raw.execute("RELEASE SAVEPOINT slr_sql_write")
                        if outer_timeout is not None:
                            raw.execute("SELECT set_config('statement_timeout', %s, true)",
                                        (outer_timeout,))
                        raw.execute("SELECT pg_advisory_unlock_all()")
                return columns, rows, written
            except psycopg.Error as exc:
                if own:
                    try:
                        _leave_nothing(raw)
                    except psycopg.Error:
                        pass
                else:   # (the caller's transaction is aborted: let go at its end)
                    self.session_locks_left = True
                raise self._raw_statement_error(exc, raw, deadline) from None

    def tables_to_write(self, query: str, params: Iterable[Any] = ()) -> set[str] | None:
        """None: what a statement writes is known only once it ran (its triggers and
        functions are the server's), from :meth:`sql_write`. A transaction-control statement
        and a ``SET`` or ``RESET`` are refused here, before the check's transaction is
        begun."""
        _refuse_transaction_control(query)
        _refuse_setting(query)
        return None

    def _read_only(self, raw: Any, own: bool, query: str, params: Iterable[Any],
                   timeout: float | None) -> tuple[list[str], list[tuple]]:
        """A read-only statement on the store's own connection (inside a transaction: in
        a savepoint made read-only, so it may read the transaction's writes but not write,
        and the rollback to it takes back the settings it changed, its timeout included)."""
        if own:
            raw.execute("BEGIN READ ONLY")
        else:
            raw.execute("SAVEPOINT slr_read_only")
            raw.execute("SET LOCAL transaction_read_only = on")
        try:
            if timeout is not None:
                raw.execute(f"SET LOCAL statement_timeout = {_timeout_ms(timeout)}")
            bound = bound_parameters(params)
            return _one_statement(raw, self.dialect.statement(query) if bound else query,
                                  bound or None)
        finally:
            if _connected(raw):
                if own:
                    _leave_nothing(raw)
                else:
                    raw.execute("ROLLBACK TO SAVEPOINT slr_read_only")
                    raw.execute("RELEASE SAVEPOINT slr_read_only")
                    raw.execute("SELECT pg_advisory_unlock_all()")

    def execute(self, sql: str, params: Iterable[Any] = ()) -> list[tuple]:
        with self.lock:
            self.check_open()
            return self.conn.execute(sql, tuple(params)).fetchall()

    def executemany(self, sql: str, rows: Iterable[Iterable[Any]]) -> None:
        with self.lock:
            self.check_open()
            self.conn.executemany(sql, rows)

    def executescript(self, script: str) -> None:
        from .sqltext import split_sql_script
        with self.transaction():
            for statement in split_sql_script(script):
                self.conn.execute(statement)

    def changes(self) -> int:
        with self.lock:
            self.check_open()
            return max(0, self.conn.last_rowcount)

    def query_plan(self, sql: str) -> list[str]:
        with self.lock:
            self.check_open()
            rows = self.conn.execute("EXPLAIN " + sql, [None] * sql.count("?")).fetchall()
            return [row[0] for row in rows]

    def install_functions(self, functions: SqlFunctions) -> None:
        """Python functions cannot run inside the server: the functions a migration
        installs there (``Native.MIGRATION``) are called by name, and goals that need one
        of the others run in the interpreter on PostgreSQL (the planner asks
        :attr:`python_functions`). Kept only to say what the store was given."""
        self.functions = functions

    python_functions = False

    def run_compiled(self, sql: str, params: dict, limit: int | None = None,
                     deadline: float | None = None, may_fall_back: bool = False,
                     instructions: int | None = None,
                     stop: threading.Event | None = None) -> list[tuple]:
        # (``instructions``: PostgreSQL counts none a client could bound; the deadline,
        # statement_timeout, is its only limit. ``stop``: see _stoppable)
        with self.lock:
            self.check_open()
            if stop is not None and stop.is_set():
                raise SLRError(STOPPED_BY_CALLER)
            # (a query's statement -- one that may fall back -- may be stopped by its caller:
            # outside a transaction or in a savepoint, a cancel fails it alone)
            stoppable = _NOT_STOPPABLE if stop is None or not may_fall_back \
                else self._stoppable(stop)
            if not may_fall_back or self.tx_depth:
                # (inside a transaction it is part of a write -- an event rule's where goal
                # deciding in its add -- which a close waits for)
                return self._run_compiled(sql, params, limit, deadline, may_fall_back,
                                          stoppable)
            with self._query_statement():   # (a query's: a close cancels it)
                return self._run_compiled(sql, params, limit, deadline, may_fall_back,
                                          stoppable)

    def _run_compiled(self, sql: str, params: dict, limit: int | None,
                      deadline: float | None, may_fall_back: bool,
                      stoppable: AbstractContextManager[None]) -> list[tuple]:
        """:meth:`run_compiled`, the lock held; ``stoppable`` around the statement."""
        deadline = self._outer(deadline)
        if deadline is None and (self.tx_depth == 0 or not may_fall_back):
            # (an event rule's statement inside the writer's transaction: a failure
            # fails the add, so no savepoint round trips)
            with stoppable:
                cursor = self.conn.execute(sql, params)
                return cursor.fetchall() if limit is None else cursor.fetchmany(limit)
        if deadline is None:
            # inside a transaction: a statement that fails (the query then goes to the
            # interpreter) must not abort the caller's transaction
            self.conn.execute("SAVEPOINT slr_compiled")
            try:
                with stoppable:
                    cursor = self.conn.execute(sql, params)
                    rows = cursor.fetchall() if limit is None else cursor.fetchmany(limit)
            except BaseException:
                self.conn.execute("ROLLBACK TO slr_compiled")
                self.conn.execute("RELEASE slr_compiled")
                raise
            self.conn.execute("RELEASE slr_compiled")
            return rows
        left = deadline - time.monotonic()
        if left <= 0:
            raise SLRTimeout("query timed out (in its compiled SQL statement)")
        own = self.tx_depth == 0
        outer = None
        if own:
            self.conn.execute("BEGIN")
        else:
            # in the caller's transaction a SET LOCAL outlasts the savepoint's release,
            # to the transaction's end: the setting in force before (an administrator's,
            # the session's, the transaction's) is read here and put back before the
            # release (read in the savepoint's round trip)
            self.conn.savepoint_later("slr_compiled")
            outer = self.conn.execute("SHOW statement_timeout").fetchone()[0]
        try:
            self.conn.execute(f"SET LOCAL statement_timeout = {_timeout_ms(left)}")
            with stoppable:
                cursor = self.conn.execute(sql, params)
                rows = cursor.fetchall() if limit is None else cursor.fetchmany(limit)
            if not own:
                self.conn.execute("SELECT set_config('statement_timeout', ?, true)",
                                  (outer,))
                self.conn.execute("RELEASE slr_compiled")
        except BaseException as exc:
            if own:
                self.conn.rollback()
            else:
                self.conn.execute("ROLLBACK TO slr_compiled")
                self.conn.execute("RELEASE slr_compiled")
            error = _own_deadline(exc, deadline)
            if error is exc:
                raise
            raise error from None
        if own:
            self.conn.execute("COMMIT")
        return rows

    def run_compiled_many(self, sql: str, rows: list) -> None:
        with self.lock:
            self.check_open()
            for row in rows:
                self.conn.execute(sql, row)

    def run_compiled_batch(self, statements: list) -> list[list[tuple]]:
        """``Database.run_compiled_batch``: the statements in one pipeline (one round trip),
        unless a deadline bounds them (then one by one, each under it)."""
        with self.lock:
            self.check_open()
            if self._outer(None) is not None:
                return [self.run_compiled_many(sql, params) or [] if many
                        else self.run_compiled(sql, params) for sql, params, many in statements]
            return self.conn.execute_batch(statements)

    def _outer(self, deadline: float | None) -> float | None:
        outer = self.deadline
        if deadline is None or (outer is not None and outer <= deadline):
            return outer
        return deadline


def _migrate_postgres(db: Any, schema: str, adopt: bool = False) -> None:
    """Create or update the store in PostgreSQL schema ``schema`` through ``db.conn``
    (a :class:`~slr_sql.store.postgres.PgConnection`): the ``pg_NNNN`` scripts not applied
    yet, in one transaction, under an advisory lock (two processes opening a new store at
    once apply them once). A schema holding tables but no store is refused unless
    ``adopt``; a store written by a newer slr_sql is refused."""
    raw = db.conn.raw
    quoted = quote_identifier(schema)
    scripts = postgres_migration_scripts()
    latest = scripts[-1][0] if scripts else 0
    psycopg = _psycopg()
    try:
        raw.execute("BEGIN")
        try:
            raw.execute("SELECT pg_advisory_xact_lock(hashtext(%s))", ("slr_migrate:" + schema,))
            raw.execute(f"CREATE SCHEMA IF NOT EXISTS {quoted}")
            raw.execute(_search_path(schema, local=True))
            tables = {row[0] for row in raw.execute(
                "SELECT tablename FROM pg_tables WHERE schemaname = %s", (schema,))}
            if tables and not _STORE_TABLES.issubset(tables) and not adopt:
                shown = ", ".join(sorted(tables)[:5]) + (", ..." if len(tables) > 5 else "")
                raise SLRError(f"{db.path}: schema {schema} holds tables ({shown}) but no "
                               "slr_sql store; slr_sql.open(url, adopt=True) adds a store to it")
            if "slr_migrations" in tables:
                applied = {row[0] for row in raw.execute("SELECT number FROM slr_migrations")}
            else:
                raw.execute("CREATE TABLE slr_migrations (number INTEGER PRIMARY KEY, "
                            "name TEXT NOT NULL, applied_at TIMESTAMPTZ DEFAULT now())")
                applied = set()
            if applied and max(applied) > latest:
                raise SLRError(f"{db.path}: written by a newer slr_sql (schema version "
                               f"{max(applied)}; this one knows versions up to {latest}): "
                               "upgrade slr_sql")
            for number, filename, text in scripts:
                if number in applied:
                    continue
                try:
                    raw.execute(text)
                except psycopg.Error as exc:
                    raise SLRError(f"{db.path}: migration {filename} failed ({exc}); the "
                                   "schema is left as it was") from None
                raw.execute("INSERT INTO slr_migrations (number, name) VALUES (%s, %s)",
                            (number, filename))
            raw.execute("COMMIT")
        except BaseException:
            db.conn.rollback()
            raise
    except psycopg.Error as exc:
        raise _error(exc, db.path, db.busy_timeout, _connected(raw)) from None
