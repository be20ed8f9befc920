"""One open SQLite database: connection settings, transactions, deadlines and raw SQL.

:class:`Database` is the object every part of an :class:`~slr_sql.store.EventStore` shares:
the connection, the lock that serializes it, the transaction depth and the clock. The parts
run their statements through :meth:`Database.execute` (and ``executemany``), inside
:meth:`Database.transaction` when they write, so that a condition of the file or its disk is
an SLRError in words (:meth:`Database.failure`) on every path, a background thread's too; a
stream that reads its rows as they come (an event scan) hands what it meets to
:meth:`Database.failure` itself.

Durability: file databases use ``journal_mode=WAL`` with ``synchronous=FULL``: when a
transaction commits it is in the WAL *and* fsynced, so it survives a process kill and a
power loss. (``synchronous=NORMAL`` would survive a kill but may lose the last transactions
on power loss.)

Sharing: any number of processes may open the file. Readers never wait (WAL); a writer waits
for another's write transaction at most ``busy_timeout`` seconds (default
:data:`DEFAULT_BUSY_TIMEOUT`), then gets :class:`~slr_sql.errors.SLRBusy` naming the file.
Opening a store that is up to date only reads it, and closing never waits for anyone (the
checkpoint on close is ``PASSIVE``). Threads share the one connection: every statement runs
and is read holding :attr:`Database.lock`, a transaction holds it to the end, and the
statements other threads left open (event scans read in batches) are *suspended* when a
transaction begins and resumed after it from where they were (so a rollback or a dropped
table in one thread never aborts another thread's scan).
"""
from __future__ import annotations

import os
import random
import re
import sqlite3
import stat
import threading
import time
import weakref
from contextlib import contextmanager
from typing import Any, Callable, Generator, Iterable, Iterator
from urllib.parse import unquote

from ..errors import CLOSED_WHILE_RUNNING, STOPPED_BY_CALLER, SLRError, SLRStoreGone, SLRTimeout, \
    naming_the_store
from ..encoding import signal_safe_loop
from ..lockorder import ordered_lock
from .authorizer import READ_ONLY_RESULT_BYTES, READ_ONLY_VALUE_BYTES, READ_ONLY_VALUE_COST, \
    SqlGuard, harden_connection
from .bounded_builtins import bounded_builtins
from .checkpointer import CHECKPOINT_INTERVAL, CHECKPOINT_MODES, WalCheckpointer
from .dialect import SQLITE
from .functions import SqlFunctions
from .schema import migrate, migrate_new_memory_store, migration_scripts
from .sqltext import bound_parameters, busy_error, quote_identifier, split_sql_script, store_error
from .sqltext import file_identity as _file_identity, file_uri as _file_uri
from .stored_text import fetch_row, fetch_rows

__all__ = ["Database", "DatabaseError", "ReadConnection", "CACHE_SIZE_KIB", "DEFAULT_BUSY_TIMEOUT",
           "run_sql_file", "check_file", "refuse_no_store", "check_busy_timeout", "is_postgres_url"]

# The base class of the errors the database raises while running a statement (a missing
# table, a syntax error, a constraint, an interrupted statement...; a condition of the file
# or disk is an SLRError instead: Database.failure). Callers outside the store catch this
# name, never sqlite3's.
# (the PostgreSQL backend's PgStatementError derives from it)
DatabaseError = sqlite3.Error

CACHE_SIZE_KIB = 65536  # PRAGMA cache_size of the store's connection (64 MiB)

# plans of the planning copy kept for statements asked again (Database.hypothetical_plan):
# beyond this many they are forgotten together (statements whose text has its constants
# in it are all new)
PLANS_REMEMBERED = 1024

# Seconds a write waits for another connection's write transaction before SLRBusy: long
# enough for any ordinary transaction of another writer (milliseconds) and a checkpoint,
# short enough that a process stuck holding the lock is reported rather than waited for.
DEFAULT_BUSY_TIMEOUT = 5.0
# How often (virtual machine instructions) the progress handler of a statement with a
# deadline, or of a query's statement, looks at the clock and at stop_queries: ~0.3 ms of
# work at SQLite's ~70 million instructions a second
STOP_CHECK_INSTRUCTIONS = 20000

# How often (virtual machine instructions) an instruction budget's progress handler counts:
# ~15 us between calls at SQLite's ~70 million instructions a second, so the Python call
# costs ~1 % of a statement's time
INSTRUCTIONS_PER_CHECK = 1000


def check_busy_timeout(value: Any) -> float:
    """``value`` as a ``busy_timeout`` (seconds, a number >= 0 and finite), else an
    :class:`SLRError` naming it; the same words for every backend.

    >>> check_busy_timeout(2)
    2.0
    >>> check_busy_timeout(float("inf"))
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: busy_timeout must be a number of seconds >= 0, not inf
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not 0 <= value < float("inf"):
        raise SLRError(f"busy_timeout must be a number of seconds >= 0, not {value!r}")
    return float(value)


def check_file_options(synchronous: Any, checkpoint: Any, cache_mib: Any) -> None:
    """``synchronous``, ``checkpoint`` and ``cache_mib`` of ``open``, else an
    :class:`SLRError` naming the option (open's boundary would word any other error as
    ``open: ValueError: ...``). They tune an SQLite file; a PostgreSQL store checks them
    the same way, then has no use for them (the server keeps its own durability,
    checkpoints and cache), so a value is refused or taken alike on both engines.

    >>> check_file_options("NORMAL", "background", 16)
    >>> check_file_options("FAST", "auto", 64)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: synchronous must be OFF, NORMAL, FULL or EXTRA, not 'FAST'
    """
    if isinstance(cache_mib, bool) or not isinstance(cache_mib, (int, float)) \
            or not 0.0625 <= cache_mib <= 1 << 20:
        raise SLRError(f"cache_mib must be a number of MiB from 0.0625 to 1048576, "
                       f"not {cache_mib!r}")
    if not isinstance(synchronous, str) or \
            synchronous.upper() not in ("OFF", "NORMAL", "FULL", "EXTRA"):
        raise SLRError(f"synchronous must be OFF, NORMAL, FULL or EXTRA, not {synchronous!r}")
    if not isinstance(checkpoint, str) or checkpoint not in CHECKPOINT_MODES:
        raise SLRError(f"checkpoint must be 'auto' or 'background', not {checkpoint!r}")


class ChangedMeanwhile(SLRError):
    """Another connection changed what an add's decisions rest on (the program, or a tBuffer
    made active) since the add began, as its change check found: nothing of the add was
    stored. The knowledge base reads the program again and adds once more; it never reaches
    a caller of the API. (Raised by the PostgreSQL backend; here, beside ``DatabaseError``,
    so that the facade catches it without importing that backend.)"""

class WallClock:
    def now(self) -> float:
        return time.time()


_SQLITE_MAGIC = b"SQLite format 3\x00"
# The files SQLite keeps beside a database, named after it, and what each is: opening the
# database takes a file of that name for its own and truncates, rewrites or deletes it
_SIDE_FILES = (("-wal", "write-ahead log"), ("-shm", "shared-memory index"),
               ("-journal", "rollback journal"))
# The store files, by (device, inode), this process has open through SQLite connections
# (Database, ReadConnection), with how many. POSIX drops every lock a process holds on a file
# when the process closes any descriptor of that file, and SQLite cannot know of descriptors
# it did not open: check_file reading the header of a store that another knowledge base of
# this process had open dropped that connection's locks, so the next other process to close
# the store took itself for its last user, checkpointed and deleted the -wal and -shm, and
# the knowledge bases of this process (`slr serve --foxglove` after any `slr query` of the
# file) refused every later write: their log had been deleted. A file held here is read only
# through SQLite.
_HELD: dict[tuple[int, int], int] = {}
_HELD_LOCK = threading.Lock()   # (a leaf: held only around a stat, a count or a raw read)


def _hold(path: str) -> tuple[int, int] | None:
    """Count the file at ``path`` as open here through SQLite (call once connected, before
    the connection's first statement takes a lock); its identity, to :func:`_release`."""
    with _HELD_LOCK:
        identity = _file_identity(path)
        if identity is not None:
            _HELD[identity] = _HELD.get(identity, 0) + 1
        return identity


def _release(identity: tuple[int, int] | None) -> None:
    if identity is None:
        return
    with _HELD_LOCK:
        left = _HELD.get(identity, 0) - 1
        if left > 0:
            _HELD[identity] = left
        else:
            _HELD.pop(identity, None)


def _held_here(path: str) -> bool:
    with _HELD_LOCK:
        identity = _file_identity(path)
        return identity is not None and identity in _HELD


def _read_head(path: str, size: int) -> bytes | None:
    """The first ``size`` bytes of the file ``path``; None, reading nothing, when this
    process has the file open through SQLite (closing a descriptor of it would drop the
    locks of those connections). OSError as open() raises it."""
    with _HELD_LOCK:
        identity = _file_identity(path)
        if identity is not None and identity in _HELD:
            return None
        with open(path, "rb") as handle:
            return handle.read(size)


# Tables every store has (the first migration creates them).
_STORE_TABLES = frozenset({"slr_meta", "slr_program", "slr_event_types"})


def _store_gone(path: Any, what: str, outcome: str) -> SLRStoreGone:
    return SLRStoreGone(f"{path}: {what} while open (by another program?); {outcome}. "
                        f"Restore the file, or close this knowledge base and open the path "
                        f"again")


def _read_error(exc: sqlite3.Error, path: Any, busy_timeout: float, moved: bool) -> SLRError:
    """The SLRError of a failed read: :class:`SLRStoreGone` when the store's file is no
    longer the one at the path (``moved``: what the error says is about that), else
    :func:`store_error`'s words (busy, full, damaged, a table dropped)."""
    if moved:
        return _store_gone(path, "the store file was deleted or replaced",
                           f"nothing was read ({exc})")
    return store_error(exc, path, busy_timeout, "nothing was read")


# SQLite's primary result codes that are about the store's file or its disk, not about the
# statement: what a statement of the store's connection meets is said in words
# (Database.failure); any other code is the statement's own (a missing table, a constraint,
# a Python function that raised) and stays a DatabaseError for the callers that answer it
# (the planner hands such a statement over to the interpreter)
_FILE_CONDITIONS = frozenset({sqlite3.SQLITE_BUSY, sqlite3.SQLITE_READONLY, sqlite3.SQLITE_PERM,
                              sqlite3.SQLITE_IOERR, sqlite3.SQLITE_CORRUPT, sqlite3.SQLITE_FULL,
                              sqlite3.SQLITE_CANTOPEN, sqlite3.SQLITE_PROTOCOL,
                              sqlite3.SQLITE_NOLFS, sqlite3.SQLITE_NOTADB})


def check_file(path: str, adopt: bool = False) -> bool:
    """Refuse, before anything is written, a ``path`` that is not (and may not become) a
    store: an :class:`SLRError` naming the path and the reason. Returns True when the store
    is new (no file yet, an empty file, or an SQLite file with nothing in it), False for an
    existing store (or, with ``adopt``, a foreign SQLite file to take over).

    Refused: an empty path (SQLite would make it a temporary file, gone on close), a
    directory, a path in a missing directory, a file that is not SQLite, a truncated or
    damaged file, a store written by a newer slr_sql, and an SQLite file with tables that is
    not a store (unless ``adopt``). The file is read only through its header
    and a read-only connection, so a refused file keeps every byte and its mtime.

    >>> import tempfile; folder = tempfile.mkdtemp()
    >>> check_file(os.path.join(folder, "robot.db"))
    True
    >>> check_file(folder)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: ...: is a directory, not a store file
    """
    if path == "":   # (SQLite makes "" a private temporary file, deleted on close)
        raise SLRError("a store's path is empty: give a file name (or no path for a store "
                       "in memory)")
    _refuse_url_shaped(path)
    if os.path.isdir(path):
        raise SLRError(f"{path}: is a directory, not a store file")
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise SLRError(f"{path}: no such directory: {folder}")
    if not _held_here(path):  # (a store open here passed when it was opened)
        _refuse_side_files(path)
    try:
        info = os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            raise SLRError(f"{path}: a symbolic link to a missing file") from None
        return True
    except OSError as exc:
        raise SLRError(f"{path}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise SLRError(f"{path}: not a regular file, so not a store")
    if info.st_size == 0:
        return True
    try:
        read = _read_head(path, 100)
    except OSError as exc:
        raise SLRError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    if read is None:   # a store this process has open: SQLite reads it (migrate checks it)
        return False
    header = read
    if not header.startswith(_SQLITE_MAGIC[:len(header)]) or len(header) < 16:
        raise SLRError(f"{path}: not an SQLite database (so not an slr_sql store)")
    if len(header) < 100:
        raise SLRError(f"{path}: the file is truncated ({len(header)} bytes, less than an "
                       "SQLite header)")
    _check_length(path, header, info.st_size)
    objects, version = _read_schema(path, header)
    tables = sorted(name for kind, name in objects if kind == "table")
    if _STORE_TABLES.issubset(tables) and version >= 1:
        latest = migration_scripts()[-1][0]
        if version > latest:
            raise SLRError(f"{path}: written by a newer slr_sql (schema version {version}; "
                           f"this one knows versions up to {latest}): upgrade slr_sql")
        return False
    if not objects and version == 0:
        return True  # an SQLite file with nothing in it: it becomes a store
    shown = ", ".join(tables[:5]) + (", ..." if len(tables) > 5 else "")
    what = f"an SQLite file with tables {shown}" if tables else "an SQLite file"
    if not adopt:
        raise SLRError(f"{path}: not an slr_sql store ({what}); slr_sql.open(path, "
                       "adopt=True) adds a store to it")
    if version != 0:
        raise SLRError(f"{path}: cannot adopt {what}: it uses PRAGMA user_version "
                       f"({version}) for its own schema, as slr_sql does")
    return False


def _file_kind(path: str) -> str | None:
    """What is at ``path``: None for nothing (or a link to nothing), "file" for a regular
    file, else its kind in words."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return None
    if stat.S_ISREG(mode):
        return "file"
    return "a directory" if stat.S_ISDIR(mode) else "a named pipe" if stat.S_ISFIFO(mode) \
        else "a socket" if stat.S_ISSOCK(mode) else "a device"


def _is_sqlite_file(path: str) -> bool:
    if _file_kind(path) != "file":   # (a named pipe's open would wait for a writer)
        return False
    try:
        head = _read_head(path, len(_SQLITE_MAGIC))
    except OSError:   # (no such file, or not readable: not one to be destroyed by a store)
        return False
    return head is None or head == _SQLITE_MAGIC   # (None: SQLite has it open here)


def _refuse_side_files(path: str) -> None:
    """Refuse a store at ``path`` that SQLite would destroy, or that would destroy one: a
    path named as the ``-wal``, ``-shm`` or ``-journal`` of an SQLite database beside it
    (opening that database truncates or deletes its side files: a store there was gone
    after the next ``slr query`` of the database, a fleet store ``robot.db-wal`` as soon
    as the push closed ``robot.db``); and a store whose -wal or -journal is an SQLite
    database (which opening the store would destroy), or whose side file is no file. SQLite names the side files after the
    database's real path, so a link's target is checked too.

    >>> import tempfile, slr_sql; folder = tempfile.mkdtemp()
    >>> slr_sql.open(os.path.join(folder, "robot.db")).close()
    >>> check_file(os.path.join(folder, "robot.db-wal"))
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: ...robot.db-wal: the name of the write-ahead log of the SQLite database ...robot.db beside it ...
    """
    for spelled in dict.fromkeys((path, os.path.realpath(path))):
        for suffix, what in _SIDE_FILES:
            if spelled.endswith(suffix) and _is_sqlite_file(spelled[:-len(suffix)]):
                raise SLRError(
                    f"{path}: the name of the {what} of the SQLite database "
                    f"{spelled[:-len(suffix)]} beside it (SQLite's own file, which opening "
                    f"that database truncates or deletes): a store there would be lost; "
                    f"give it another name")
            side = spelled + suffix
            kind = _file_kind(side)
            if kind not in (None, "file"):
                raise SLRError(f"{path}: {side} beside it is {kind}, where SQLite keeps the "
                               f"{what} of {path}: remove or rename it")
            # (never the -shm's bytes: SQLite locks that file, and a descriptor of ours
            # closed would drop the locks of any connection of this process to the store)
            if suffix != "-shm" and _is_sqlite_file(side):
                raise SLRError(
                    f"{path}: {side} beside it is an SQLite database (a store?), where "
                    f"SQLite keeps the {what} of {path}: opening {path} would destroy "
                    f"it; move that file to another name first")


def _read_schema(path: str, header: bytes) -> tuple[list[tuple[str, str]], int]:
    """``(type, name)`` of every object of ``sqlite_master``, and ``PRAGMA user_version``,
    read without creating or changing a file.

    A read-only connection to a database in WAL mode creates its ``-wal`` and ``-shm`` files
    when they are missing, and cannot remove them when it closes. So a WAL database with no
    ``-wal`` file (no connection has it open: the file holds everything committed) is read
    as ``immutable`` (no side files, no locks). Should a writer open and checkpoint it while
    it is being read, the read may see a torn page: it is retried, with locks once the
    writer's ``-wal`` exists, before the file is called damaged.
    """
    wal_mode = header[18:20] == b"\x02\x02"
    error: Exception | None = None
    for _attempt in range(3):
        immutable = wal_mode and not os.path.exists(path + "-wal")
        uri = _file_uri(path) + ("&immutable=1" if immutable else "")
        try:
            conn = sqlite3.connect(uri, uri=True, isolation_level=None, timeout=30.0)
            try:
                harden(conn)
                objects = fetch_rows(conn.execute("SELECT type, name FROM sqlite_master"))
                version = fetch_row(conn.execute("PRAGMA user_version"))[0]
                return objects, version
            finally:
                conn.close()
        except sqlite3.DatabaseError as exc:
            error = exc
            if not immutable:
                break
        except sqlite3.Error as exc:
            raise SLRError(f"{path}: cannot read it ({exc})") from None
    if "not a database" in str(error):
        raise SLRError(f"{path}: not an SQLite database, or its header is damaged "
                       f"({error})")
    code = getattr(error, "sqlite_errorcode", None)
    if code is not None and code & 0xFF != sqlite3.SQLITE_CORRUPT:
        # the file could not be read (a full disk refusing the -shm file, permissions...):
        # that says nothing about its pages
        reason = store_error(error, path, outcome="it was not opened")  # type: ignore[arg-type]
        if type(reason) is not SLRError:
            raise reason
        raise SLRError(f"{path}: cannot read it ({error})")
    raise SLRError(f"{path}: the file is damaged ({error})")


def is_postgres_url(where: Any) -> bool:
    """True for ``postgresql://...`` and ``postgres://...``.

    >>> is_postgres_url("postgres://u@h/db"), is_postgres_url("robot.db")
    (True, False)
    """
    return isinstance(where, str) and where.startswith(("postgresql://", "postgres://"))


def shown_location(where: Any) -> str:
    """A store's path or URL as messages show it: a PostgreSQL URL without its password,
    given before the host or as a parameter.

    >>> shown_location("postgresql://robot:s3cret@db/fleet?sslpassword=k3y&schema=a")
    'postgresql://robot:***@db/fleet?sslpassword=***&schema=a'
    >>> shown_location("postgresql://robot:p@ss@db/fleet")     # an '@' left unescaped
    'postgresql://robot:***@db/fleet'
    >>> shown_location("robot.db"), shown_location("POSTGRESQL://robot:s3cret@db/fleet")
    ('robot.db', 'POSTGRESQL://robot:***@db/fleet')
    """
    text = str(where)
    if not _URL_SHAPED.match(text):   # (any scheme: a mistyped one names a password too)
        return text
    # (an '@' further on, in a parameter, hides the host too: better than a password)
    span = _password_span(text)
    if span is not None:
        text = text[:span[0]] + "***" + text[span[1]:]
    # a parameter's name is decoded as its value is, by libpq and by split_url (pass%77ord is
    # password): the name is compared decoded; a value runs on over a '#' (written
    # unescaped in a password, what follows it is the password's too)
    return re.sub(r"([?&])([^=&#]*)=([^&]*)",
                  lambda m: f"{m[1]}{m[2]}=***" if unquote(m[2]).lower() in _PASSWORD_KEYS
                  else m[0], text)


_PASSWORD_KEYS = ("password", "sslpassword")
_URL_SHAPED = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*://")


def _password_span(url: str) -> tuple[int, int] | None:
    """Where the password of a URL's user part is, ``(start, end)``; None without one. The
    user's part ends at the last '@' (a host has none; a password written without escaping
    may), the password begins after the first ':' before the first '@'."""
    scheme_end = url.find("://") + 3
    first_at = url.find("@", scheme_end)
    if first_at < 0:
        return None
    colon = url.find(":", scheme_end, first_at)   # (none: a user without a password)
    return None if colon < 0 else (colon + 1, url.rfind("@"))


def _refuse_url_shaped(path: str) -> None:
    """A store name that is a URL but no PostgreSQL one (``POSTGRESQL://``, ``mysql://``)
    is no store (a file path would make it a folder ``POSTGRESQL:``); said without its
    password."""
    if _URL_SHAPED.match(path) and not is_postgres_url(path):
        if path[:8].lower().startswith(("http://", "https://")):
            # (the URL of `slr serve`, which most commands take for DB: say who takes it)
            raise SLRError(f"{shown_location(path)}: the URL of a server (slr serve), not a "
                           f"store: this needs the store itself, its file or a PostgreSQL "
                           f"URL (postgresql://...); a server's store is asked through "
                           f"slr_sql.connect(URL) or the slr commands that take its URL "
                           f"(query, add, sql, ...)")
        raise SLRError(f"{shown_location(path)}: not a store: a URL names a PostgreSQL store "
                       f"and begins postgresql:// or postgres:// (in lower case)")


def password_token(where: str) -> str:
    """The password of a PostgreSQL URL's user part as written ('' if none): libpq quotes
    it in some of its messages (a bad %-escape), which say so with it hidden.

    >>> password_token("postgresql://robot:s3%zz@db/fleet"), password_token("postgresql://db")
    ('s3%zz', '')
    """
    span = _password_span(where) if is_postgres_url(where) else None
    return "" if span is None else where[span[0]:span[1]]


def on_read_only_file_system(path: str) -> bool:
    """Whether the file system holding ``path`` is mounted read-only (a store there can be
    read only; SQLite cannot make the ``-shm`` file of a store in WAL mode beside it).

    >>> import tempfile; on_read_only_file_system(tempfile.gettempdir() + "/robot.db")
    False
    """
    try:
        flags = os.statvfs(os.path.dirname(os.path.abspath(path)) or ".").f_flag
    except OSError:
        return False
    return bool(flags & os.ST_RDONLY)


def read_only_uri(path: str) -> str:
    """The URI that reads the store ``path`` on a file system mounted read-only: no process
    writes to it there, so without a ``-wal`` (every commit in the file) it is read as
    ``immutable`` (SQLite needs no ``-shm`` then); with one, as a read-only WAL database
    (SQLite reads the ``-wal`` and ``-shm`` that exist).

    >>> read_only_uri("/media/ro/robot.db")
    'file:///media/ro/robot.db?mode=ro&immutable=1'
    """
    return _file_uri(path, "ro") + ("" if os.path.exists(path + "-wal") else "&immutable=1")


def refuse_no_store(path: str) -> None:
    """Refuse, before a command that only reads opens it (which would create it), a store
    path that holds no store: a missing path, or an empty file (SQLite would make it a
    database on the first write). A PostgreSQL URL is left to opening it.

    >>> refuse_no_store("postgresql://u@h/db")
    >>> refuse_no_store("nowhere.db")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: no such store: nowhere.db
    """
    if is_postgres_url(path):
        return
    _refuse_url_shaped(path)
    if path == ":memory:" and not os.path.lexists(path):
        raise SLRError("no such store: ':memory:' is a store in memory, which a command of its "
                       "own would open empty; give the store's file (or the URL of the slr "
                       "serve that holds a store in memory)")
    if not os.path.lexists(path):
        raise SLRError(f"no such store: {path}")
    if os.path.isfile(path) and os.path.getsize(path) == 0:
        raise SLRError(f"no such store: {path} is an empty file (only load, add, ingest, run, "
                       "demo and serve create a store)")


def _check_length(path: str, header: bytes, size: int) -> None:
    """Refuse a file shorter than the page count its header records (a truncated copy).
    Skipped while a write-ahead log holds pages not yet copied into the file."""
    page_size = int.from_bytes(header[16:18], "big")
    page_size = 65536 if page_size == 1 else page_size
    pages = int.from_bytes(header[28:32], "big")
    header_is_current = header[24:28] == header[92:96]  # "version-valid-for" = change counter
    try:
        wal_bytes = os.path.getsize(path + "-wal")
    except OSError:
        wal_bytes = 0
    if header_is_current and pages and not wal_bytes and size < pages * page_size:
        raise SLRError(f"{path}: the file is truncated ({size} bytes; its header records "
                       f"{pages} pages of {page_size} bytes)")


class Database:
    """The connection of one store, with its lock, transaction depth and clock.

    ``path`` None or ``":memory:"`` gives an in-memory database. Opening applies the
    migrations the file has not seen yet. A file that is not a store is refused
    (:func:`check_file`) unless ``adopt`` (then a foreign SQLite file gets a store added).

    >>> db = Database(None); db.execute("SELECT ? + 1", (1,))
    [(2,)]
    >>> db.close()
    """

    dialect = SQLITE
    python_functions = True  # create_function's Python functions run inside statements

    def __init__(self, path: str | os.PathLike | None = None, clock: Any = None,
                 synchronous: str = "FULL", busy_timeout: float = DEFAULT_BUSY_TIMEOUT,
                 adopt: bool = False, checkpoint: str = "auto",
                 checkpoint_interval: float = CHECKPOINT_INTERVAL,
                 cache_mib: float = CACHE_SIZE_KIB / 1024):
        busy_timeout = check_busy_timeout(busy_timeout)
        check_file_options(synchronous, checkpoint, cache_mib)
        self.checkpointer: WalCheckpointer | None = None
        self.path = None if path in (None, ":memory:") else os.fspath(path)
        new = True if self.path is None else check_file(self.path, adopt)
        self.clock = clock if clock is not None else WallClock()
        self.lock = ordered_lock("store", reentrant=True)
        self.tx_depth = 0
        # what ended the open transaction before its end (SQLite rolled it back itself, a
        # rollback to a savepoint failed; None when unknown): _transaction_ended
        self.ended: list[BaseException | None] = []
        self.closed = False
        # called, lock held, after a transaction rolled back (the event-type cache reloads)
        self.rollback_listeners: list[Callable[[], None]] = []
        # (depth registered at, callback): called once the outermost transaction committed
        # and let go of the lock; dropped with the (nested) transaction that rolls back
        self.commit_callbacks: list[tuple[int, Callable[[], None], bool]] = []
        # streams (event scans read in batches) whose statement may still be open: suspended
        # when a transaction begins (see suspend_streams)
        self.open_streams: weakref.WeakSet = weakref.WeakSet()
        self.deadline: float | None = None  # of the compiled statement running now
        # (handler, every n instructions, whether it ends the statement once stopping) of the
        # statement running now: what _deadline puts back when an inner statement's own
        # limit ends
        self.progress: tuple[Callable[[], int], int, bool] | None = None
        # the progress handler SQLite calls now (_signal_safe's, of self.progress[0]): put
        # back as it is once an inner statement ends, its generator mid-run perhaps
        self.progress_call: Callable[[], int] | None = None
        # set by stop_queries, before a close: a query's statement still running (which
        # holds the lock the close waits for) ends at its next progress check
        self.stopping = False
        # what a signal handler raised while SQLite ran a statement (a Ctrl-C's
        # KeyboardInterrupt), kept by the progress handler that met it (_signal_safe): sqlite3
        # would clear it; raised once the statement ended (_deadline). And whether one of
        # our progress handlers asked SQLite to end a statement (a deadline, a budget, a
        # stop, a close): an "interrupted" statement without it was ended by an exception
        # that escaped the handler
        self.escaped: list[BaseException] = []
        self.ended_by_handler = False
        # the Python functions statements may call (install_functions), on every connection
        self.functions: SqlFunctions | None = None
        # (schema version, in-memory copy of the schema, extra indexes made in it, the
        # catalog's indexes, the plans it gave: (statement, its extra indexes) -> steps):
        # hypothetical_plan asks its planner
        self._planning: tuple[int, sqlite3.Connection, dict[str, str], set[str],
                              dict[tuple, Any]] | None = None
        self.busy_timeout = busy_timeout
        self._absolute: str | None = None  # set once open (check_identity)
        self._identity: tuple = (None, None, None)
        # the files this open creates: removed again should it fail (a store it could not
        # create leaves no empty file, -wal or -shm behind)
        created = [] if self.path is None or os.path.lexists(self.path) else \
            [name for name in (self.path, self.path + "-wal", self.path + "-shm",
                               self.path + "-journal") if not os.path.lexists(name)]
        try:
            # (a URI of the path, as every other connection of the store opens it: SQLite,
            # built to read URIs, took a plain 'file:other.db' for the file other.db, which
            # check_file had not looked at and the store's readers did not open)
            # (a store on a file system mounted read-only is opened to be read: SQLite
            # could not make its -shm beside it, so reading failed too)
            self.read_only = self.path is not None and not new and \
                on_read_only_file_system(self.path)
            self.conn = sqlite3.connect(":memory:" if self.path is None else
                                        read_only_uri(self.path) if self.read_only else
                                        _file_uri(self.path, "rwc"), uri=True,
                                        check_same_thread=False, isolation_level=None,
                                        timeout=busy_timeout, cached_statements=512)
        except sqlite3.Error as exc:
            raise SLRError(f"{self.path}: cannot open it ({exc})") from None
        # (before the first statement takes a lock: see _HELD)
        self._held = None if self.path is None else _hold(self.path)
        conn = self.conn
        try:
            self.guard = harden(conn, self)
            # the bound parameters one statement may hold (999 in SQLite before 3.32)
            self.max_parameters = conn.getlimit(sqlite3.SQLITE_LIMIT_VARIABLE_NUMBER)
            # auto_vacuum must be chosen before the first table exists (a no-op afterwards,
            # but one that wants the write lock: only a new file gets it)
            if fetch_row(conn.execute("PRAGMA page_count"))[0] == 0:
                conn.execute("PRAGMA auto_vacuum=INCREMENTAL")
            if self.path is not None and new:
                conn.execute("PRAGMA journal_mode=WAL")
            conn.execute(f"PRAGMA synchronous={synchronous.upper()}")
            conn.execute("PRAGMA foreign_keys=ON")
            # Every event type has four indexes; SQLite's default 2 MiB page cache makes large
            # ingests spill and re-read index pages constantly. The cache grows only as used.
            conn.execute(f"PRAGMA cache_size=-{int(cache_mib * 1024)}")
            if self.path is None:
                migrate_new_memory_store(conn)
            else:
                migrate(conn, self.path)
            # an existing store is in WAL already (switching again would want a lock); an
            # adopted file is switched only once its migrations succeeded
            if self.path is not None and not new and not self.read_only and \
                    fetch_row(conn.execute("PRAGMA journal_mode"))[0].lower() != "wal":
                conn.execute("PRAGMA journal_mode=WAL")
            background = checkpoint == "background" and self.path is not None \
                and not self.read_only
            if background:
                # see store/checkpointer.py: no commit waits for a checkpoint's fsync
                conn.execute("PRAGMA wal_autocheckpoint=0")
        except BaseException as exc:
            conn.close()
            _release(self._held)
            self._held = None
            for name in created:
                try:
                    os.remove(name)
                except OSError:
                    pass  # not created after all, or already gone
            if isinstance(exc, sqlite3.Error):
                outcome = "it was not created, and nothing was left behind" if created else \
                    "it was not opened"
                reason = store_error(exc, self.path, busy_timeout, outcome)
                if type(reason) is not SLRError:  # busy, full: a condition that may pass
                    raise reason from None
                folder = os.path.dirname(os.path.abspath(self.path or ".")) or "."
                if self.path is not None and not new and not getattr(self, "read_only", False) \
                        and not os.access(folder, os.W_OK) and not os.access(self.path, os.W_OK):
                    # (SQLite reads a store in WAL mode through a -shm file beside it, which it
                    # makes when missing; a read-only file system is read without one)
                    raise SLRError(
                        f"{self.path}: cannot open the store: it is read-only to this process, "
                        f"and so is its folder, where SQLite makes the -shm file it reads a "
                        f"store through ({exc}); make the folder writable for this process, or "
                        f"read a copy of the store") from None
                raise SLRError(f"{self.path or ':memory:'}: cannot open the store "
                               f"({exc})") from None
            raise
        # which file is open (device, inode), to notice it deleted or replaced before a
        # commit is acknowledged; the path made absolute now (a later chdir changes nothing)
        self._absolute = None if self.path is None else os.path.abspath(self.path)
        self._identity = (None, None, None) if self.path is None else self._identities()
        if background:   # (it checkpoints this file, and no other one put at the path)
            self.checkpointer = WalCheckpointer(self.path, checkpoint_interval,
                                                identity=self._identity[0])

    # ------------------------------------------------------------------ lifecycle

    def schema_version(self) -> int:
        """The number of the last migration applied (``PRAGMA user_version``).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).schema_version() >= 1
        True
        """
        return self.execute("PRAGMA user_version")[0][0]

    def data_version(self) -> int:
        """``PRAGMA data_version``: a number that changes when another connection (another
        process, or another store object on the same file) commits — the cheap first check
        of "did anyone else change the file?".

        >>> db = Database(None); db.data_version() == db.data_version()
        True
        """
        return self.execute("PRAGMA data_version")[0][0]

    def others_version(self) -> int:
        """A number that moves when another connection may have changed the event rules'
        pending rows, read without I/O: on SQLite :meth:`data_version` (any commit of
        another connection moves it).

        >>> db = Database(None); db.others_version() == db.others_version()
        True
        """
        return self.data_version()

    def table_names(self) -> set[str]:
        """Names of the tables of the database.

        >>> "slr_meta" in Database(None).table_names()
        True
        """
        return {row[0] for row in self.execute(
            "SELECT name FROM sqlite_master WHERE type = 'table'")}

    def set_write_groups(self, groups: Iterable[Iterable[tuple[str, int]]]) -> None:
        """Writers take turns on SQLite already (``BEGIN IMMEDIATE``): nothing to keep."""

    def lock_for_write(self, types: Iterable[tuple[str, int]]) -> None:
        """Nothing to wait for: this connection holds the database's one write lock."""

    def lock_named(self, name: str) -> None:
        """Nothing to wait for (see :meth:`lock_for_write`)."""

    def triggers(self, table: str | None = None) -> set[str]:
        """Names of the triggers (on ``table`` only, when given), temporary ones included.

        >>> Database(None).triggers("slr_clock")
        {'slr_clock_back'}
        """
        return {row[0] for row in self.execute(
            "SELECT name FROM sqlite_master WHERE type = 'trigger' AND "
            "(? IS NULL OR tbl_name = ?) UNION ALL SELECT name FROM sqlite_temp_master "
            "WHERE type = 'trigger' AND (? IS NULL OR tbl_name = ?)",
            (table, table, table, table))}

    def index_names(self, table: str) -> set[str]:
        """Names of the indexes of ``table`` (as created, not lower-cased).

        >>> db = Database(None); _ = db.execute("CREATE TABLE t (x)")
        >>> _ = db.execute("CREATE INDEX t_x ON t (x)"); db.index_names("t")
        {'t_x'}
        """
        return {row[0] for row in self.execute(
            "SELECT name FROM sqlite_master WHERE type = 'index' AND tbl_name = ?", (table,))}

    def hypothetical_plan(self, sql: str, extra: dict[str, str],
                          without: Iterable[str] = ()) -> list[str] | None:
        """The steps of SQLite's plan for ``sql`` (``EXPLAIN QUERY PLAN``'s lines) as if the
        indexes ``extra`` (name -> its ``CREATE INDEX``) existed too, but not those of them
        named in ``without``; None if the plan cannot be asked.

        Asked of an empty in-memory copy of the schema (its tables and indexes, with this
        connection's SQL functions): the copy is all the planner reads, as no statistics
        are gathered (``ANALYZE`` is never run), so an index is judged without being built.
        The copy is made again when the schema changed, and after a rollback (which takes
        the schema's version back); the extra indexes stay in it until then, or until left
        out. Its answers are kept with it: a statement asked again with the same extra
        indexes (a compiled query of another constant, whose text is the same) is answered
        without the planner, as the copy's schema is all its plan depends on.

        >>> db = Database(None); _ = db.execute("CREATE TABLE t (x, y)")
        >>> sql, x = "SELECT * FROM t WHERE x = :v", {"t_x": "CREATE INDEX t_x ON t (x)"}
        >>> db.hypothetical_plan(sql, {}), db.hypothetical_plan(sql, x)
        (['SCAN t'], ['SEARCH t USING INDEX t_x (x=?)'])
        >>> db.hypothetical_plan(sql, x, without=["t_x"])
        ['SCAN t']
        """
        with self.lock:
            self.check_open()
            try:
                copy, made, catalog, answers = self._planning_copy()
            except (sqlite3.Error, ValueError, TypeError):
                return None
            left_out = set(without)
            asked = {name for name in extra if name not in catalog}
            # (the indexes the copy has beyond the catalog's once this call's are made or
            # dropped: with the statement, all its answer depends on)
            key = (sql, frozenset((made.keys() - (asked & left_out)) | (asked - left_out)))
            if key in answers:
                known = answers[key]
                return None if known is None else list(known)
            try:
                for name, statement in extra.items():
                    if name in catalog:
                        continue
                    if name in left_out:
                        if made.pop(name, None) is not None:
                            copy.execute(f"DROP INDEX {quote_identifier(name)}")
                    elif name not in made:
                        copy.execute(statement)
                        made[name] = statement
                plan = fetch_rows(copy.execute("EXPLAIN QUERY PLAN " + sql, _AnyParameters()))
            except (sqlite3.Error, ValueError, TypeError):
                steps = None
            else:
                steps = [str(row[-1]) for row in plan]
            if len(answers) >= PLANS_REMEMBERED:
                answers.clear()
            answers[key] = steps
        return None if steps is None else list(steps)

    def plan_memo(self) -> dict[tuple, Any] | None:
        """What :meth:`hypothetical_plan`'s answers are kept in, for what a caller derives
        from them: emptied when the copy is made again (the schema changed, a rollback);
        None if there is no copy to ask.

        >>> db = Database(None); memo = db.plan_memo(); memo[("judged", "x")] = 1
        >>> db.plan_memo() is memo, db.execute("CREATE TABLE t (x)") is not None
        (True, True)
        >>> ("judged", "x") in db.plan_memo()
        False
        """
        with self.lock:
            self.check_open()
            try:
                memo = self._planning_copy()[3]
            except (sqlite3.Error, ValueError, TypeError):
                return None
            if len(memo) >= PLANS_REMEMBERED:
                memo.clear()
            return memo

    def _forget_planning_copy(self) -> None:
        """Before a rollback: the schema's version goes back with it, and the next changes
        may bring it to a number a copy made inside had, of another schema (lock held)."""
        if self._planning is not None:
            self._planning[1].close()
            self._planning = None

    def _planning_copy(self) -> tuple[sqlite3.Connection, dict[str, str], set[str],
                                      dict[tuple, Any]]:
        """The in-memory copy of the schema :meth:`hypothetical_plan` asks, the extra
        indexes made in it since (name -> statement), the catalog's index names, and the
        plans it gave (lock held)."""
        version = fetch_row(self.conn.execute("PRAGMA schema_version"))[0]
        if self._planning is not None and self._planning[0] == version:
            return self._planning[1], self._planning[2], self._planning[3], self._planning[4]
        self._forget_planning_copy()
        # (no statement cache: an EXPLAIN's rows are made when it is prepared, so a cached
        # one would answer for the indexes there were then)
        copy = sqlite3.connect(":memory:", check_same_thread=False, isolation_level=None,
                               cached_statements=0)
        harden(copy)
        if self.functions is not None:
            register_functions(copy, self.functions)
        rows = fetch_rows(self.conn.execute(
            "SELECT type, name, sql FROM sqlite_master WHERE sql IS NOT NULL AND type IN "
            "('table', 'index') UNION ALL SELECT type, name, sql FROM sqlite_temp_master "
            "WHERE sql IS NOT NULL AND type IN ('table', 'index') "
            "ORDER BY 1 DESC"))   # tables before their indexes
        catalog = set()
        for kind, name, statement in rows:
            if not name.lower().startswith("sqlite_"):
                try:
                    copy.execute(statement)
                except sqlite3.Error:
                    # (one that cannot be made again as it stands: a virtual table's shadow
                    # tables, made with it already; a module or collation not here) -- left
                    # out: only a statement reading it cannot be planned
                    continue
                if kind == "index":
                    catalog.add(name)
        made: dict[str, str] = {}
        answers: dict[tuple, Any] = {}
        self._planning = (version, copy, made, catalog, answers)
        return copy, made, catalog, answers

    def qualified(self, name: str) -> str:
        """The store's object ``name`` as its statements name it where it may be missing
        (dropped by another process or a user): quoted. A temporary object cannot be made on
        the store's connection (the authorizer), so none can answer for it.

        >>> Database(None).qualified("slr_subj_p")
        '"slr_subj_p"'
        """
        return quote_identifier(name)

    def object_names(self) -> set[str]:
        """Lower-cased names of every table, index, view and trigger of the database.

        >>> "slr_meta" in Database(None).object_names()
        True
        """
        return {row[0].lower() for row in self.execute("SELECT name FROM sqlite_master")}

    def view_statements(self, names: Iterable[str]) -> dict[str, str]:
        """``{view name: the statement that creates it}`` of the named views that exist.

        >>> db = Database(None); _ = db.execute("CREATE VIEW answer AS SELECT 42 AS x")
        >>> db.view_statements(["answer", "nothing"])
        {'answer': 'CREATE VIEW answer AS SELECT 42 AS x'}
        """
        found = dict(self.execute("SELECT name, sql FROM sqlite_master WHERE type = 'view'"))
        return {name: found[name] for name in names if name in found}

    @property
    def max_columns(self) -> int:
        """The most columns a table may have (SQLite's compile-time limit)."""
        return self.conn.getlimit(sqlite3.SQLITE_LIMIT_COLUMN)

    def suspend_streams(self) -> None:
        """Close the statements of the streams still reading (lock held): each resumes
        after its last row with a statement of its own when next read. Called when a
        transaction begins, so that no statement of another thread stays open across it."""
        for stream in list(self.open_streams):
            stream.suspend()

    def stop_queries(self) -> None:
        """End the queries' statements (compiled queries, read-only SQL) that run on this
        connection now or start later with SLRError "the knowledge base was closed while
        the query ran", at the next check of their progress handler (every
        :data:`STOP_CHECK_INSTRUCTIONS` virtual machine instructions): a close is coming,
        which would otherwise wait for them to end. A transaction is left to end, the
        statements inside it included (a close never cuts a write, nor an event rule's
        ``where`` goal deciding in its add). Called without the lock, from any thread;
        :meth:`close` calls it first.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.stop_queries(); s.run_compiled("SELECT 1", {})
        [(1,)]
        >>> s.run_compiled("SELECT 1", {}, may_fall_back=True)
        Traceback (most recent call last):
        slr_sql.errors.SLRError: the knowledge base was closed while the query ran
        """
        self.stopping = True

    def stop_query(self, stop: threading.Event) -> None:
        """(``stop`` was just set) End the statement of the query whose ``stop`` it is, if
        one runs now: on SQLite there is nothing to do here -- the statement's progress
        handler looks at ``stop`` every :data:`STOP_CHECK_INSTRUCTIONS` instructions
        (:meth:`run_compiled`), so no other statement of the connection can be cut.
        Called without the lock, from any thread; it never waits.

        >>> import threading
        >>> from slr_sql.store import EventStore
        >>> s, stop = EventStore(None), threading.Event()
        >>> stop.set(); s.stop_query(stop)
        >>> s.run_compiled("SELECT 1", {}, may_fall_back=True, stop=stop)
        Traceback (most recent call last):
        slr_sql.errors.SLRError: the query was stopped while it looked for its next answer
        """

    def close(self) -> None:
        """Checkpoint what the WAL holds, as far as no reader needs it (``PASSIVE``: never
        waits for another connection), and close. Idempotent. A query's statement still
        running ends first (:meth:`stop_queries`).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.close(); s.close()
        """
        self.stop_queries()
        with self.lock:
            if self.closed:
                return
            self.closed = True
            if self.checkpointer is not None:
                self.checkpointer.stop()
            self._forget_planning_copy()
            if self._absolute is not None:
                now = self._identities()
                if now[0] != self._identity[0]:  # replaced: leave the new file's side alone
                    self._remove_own_side_files(now)
            try:
                if self.tx_depth:
                    self.tx_depth = 0
                    self.ended = []
                    if self.conn.in_transaction:
                        try:
                            self.conn.execute("ROLLBACK")
                        except sqlite3.Error:
                            pass   # (closing rolls back what is left anyway)
                self.suspend_streams()  # iterators still open: they fail when read again
                if self.path is not None:
                    try:
                        fetch_rows(self.conn.execute("PRAGMA wal_checkpoint(PASSIVE)"))
                    except sqlite3.OperationalError:
                        pass  # best effort: the WAL is checkpointed on the next open anyway
            finally:
                self.conn.close()
                _release(self._held)
                self._held = None

    def open_reader(self) -> "ReadConnection | None":
        """A :class:`ReadConnection` to this store's file (None in memory: no other
        connection can reach an in-memory database)."""
        self.check_open()
        return None if self.path is None else \
            ReadConnection(self._absolute or self.path, self.busy_timeout,
                           functions=self.functions, identity=self._identity[0])

    def check_open(self) -> None:
        if self.closed:
            raise SLRError("the event store is closed")

    def _identities(self, shm: bool = True) -> tuple:
        """``(device, inode)`` of the file, its write-ahead log and (unless not ``shm``) its
        shared-memory file (None where missing)."""
        names = (str(self._absolute), f"{self._absolute}-wal", f"{self._absolute}-shm")
        return tuple(_file_identity(name) for name in (names if shm else names[:2]))

    def check_identity(self) -> None:
        """Raise :class:`SLRStoreGone` naming the path if the file open is no longer the one
        at the path (deleted, moved, replaced), or its write-ahead log was deleted (another
        process would start a second one): what is written now would be lost. A file
        database only; a few microseconds (``stat`` calls).

        When the file was replaced, this connection's ``-wal`` and ``-shm`` still at the path
        are removed at once: left there, SQLite would apply the old store's log to the new
        file when it is next opened.

        >>> import os, tempfile
        >>> path = os.path.join(tempfile.mkdtemp(), "robot.db"); db = Database(path)
        >>> db.check_identity(); os.remove(path); db.check_identity()
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRStoreGone: ...robot.db: the store file was deleted or replaced while open ...
        """
        if self._absolute is None:
            return
        now = self._identities(shm=False)
        main, wal, shm = self._identity
        if now[0] == main and now[1] == wal:
            return
        if now[0] != main:
            self._remove_own_side_files(self._identities())
            what = "the store file was deleted or replaced"
        elif wal is not None and now[1] != wal:
            what = "the store's write-ahead log (-wal) was deleted or replaced"
        else:  # a log that appeared since the open: that is its identity from now on
            self._identity = (main, now[1], shm if shm is not None else self._identities()[2])
            return
        raise _store_gone(self.path, what, "nothing of this call was stored")

    def read_error(self, exc: sqlite3.Error) -> SLRError:
        """The SLRError of a read of this connection that failed with ``exc`` (what the
        store's own reading connections say, :class:`ReadConnection`).

        >>> db = Database(None)
        >>> db.read_error(sqlite3.OperationalError("no such table: p"))
        SLRError(':memory:: the store failed (no such table: p)')
        """
        moved = self._absolute is not None and \
            _file_identity(self._absolute) != self._identity[0]
        return _read_error(exc, self.path, self.busy_timeout, moved)

    def failure(self, exc: sqlite3.Error) -> Exception:
        """What a statement of this connection that failed with ``exc`` raises: for an error
        about the file or its disk, an :class:`SLRError` in words -- :class:`SLRStoreGone`
        when the file open is no longer the one at the path (:meth:`check_identity`), else
        :func:`store_error`'s (SLRBusy, SLRStoreFull, a damaged file, an I/O error, a
        read-only file); else ``exc`` itself, the statement's own error, which callers
        catch as :data:`DatabaseError` (a compiled statement handed over to the
        interpreter, a view that cannot be made).

        >>> db = Database(None)
        >>> db.failure(sqlite3.OperationalError("no such table: p"))
        OperationalError('no such table: p')
        >>> db.failure(sqlite3.OperationalError("database or disk is full"))
        SLRStoreFull(':memory:: the disk is full (or the store reached its size limit; database or disk is full); nothing of this call was written: free space and retry')
        """
        if self.tx_depth and not self.conn.in_transaction:
            self._transaction_ended(exc)   # (SQLite rolled it all back: a full disk, I/O)
        code = getattr(exc, "sqlite_errorcode", None)
        if code is None:   # (a driver that does not say: by the words)
            return store_error(exc, self.path, self.busy_timeout) if \
                "database is locked" in str(exc) or "disk is full" in str(exc) else exc
        if code & 0xFF not in _FILE_CONDITIONS:
            return exc
        try:
            self.check_identity()
        except SLRStoreGone as gone:
            return gone
        return store_error(exc, self.path, self.busy_timeout)

    def _remove_own_side_files(self, now: tuple) -> None:
        """Remove the ``-wal`` and ``-shm`` at the path that are this connection's own (same
        inode as when opened) once the file beside them is another one."""
        for suffix, mine, there in (("-wal", self._identity[1], now[1]),
                                    ("-shm", self._identity[2], now[2])):
            if mine is not None and there == mine:
                try:
                    os.remove(f"{self._absolute}{suffix}")
                except OSError:
                    pass  # gone already
        self._identity = (self._identity[0], None, None)

    # ------------------------------------------------------------------ transactions

    @contextmanager
    def transaction(self, wait: bool = True, listeners: bool = True,
                    join: bool = False) -> Iterator["Database"]:
        """Run several statements as one atomic unit (BEGIN IMMEDIATE ... COMMIT).

        Re-entrant: nested uses become savepoints, so an inner failure undoes only the inner
        part. The lock is held for the whole transaction. ``wait=False``: another
        connection's write transaction is not waited for (SLRBusy at once), for work a
        reader may leave for later (a nested one holds the lock already).
        ``listeners=False``: a rollback of this one does not call the rollback listeners,
        for a block that changes nothing they know of (a build of indexes that may fail):
        it takes back only itself. ``join=True``: inside a transaction of this thread, the
        block joins it with no savepoint of its own, for a caller that lets every error
        through to the enclosing level, which takes the whole back (a savepoint makes SQLite
        keep the pages the block changes, for a rollback to it that would never come).

        A level that ends with an error raises that error, whatever its rollback meets. A
        transaction SQLite rolls back itself while levels are open (a statement met a full
        disk, an I/O error), or that a statement ends, goes on as one begun again, and each
        of its levels that ends normally raises an SLRError saying it was rolled back:
        nothing of it is kept, nothing after it commits on its own.

        >>> db = Database(None)
        >>> with db.transaction():
        ...     db.execute("INSERT INTO slr_meta VALUES ('a', '1')")
        []
        >>> db.execute("SELECT value FROM slr_meta WHERE key = 'a'")
        [('1',)]
        """
        if join and in_own_transaction(self):
            yield self
            return
        committed: list[tuple[int, Callable[[], None], bool]] = []
        try:
            with self.lock:
                self.check_open()
                depth = self.tx_depth
                conn = self.conn
                try:
                    if depth == 0:
                        self.suspend_streams()
                        self._begin(self.busy_timeout if wait else 0.0)
                    else:
                        if not conn.in_transaction:   # (ended unseen: see _transaction_ended)
                            self._transaction_ended(None)
                        conn.execute(f"SAVEPOINT slr_sp{depth}")
                except sqlite3.Error as exc:
                    raise self.failure(exc) from None
                self.tx_depth = depth + 1
                try:
                    yield self
                except BaseException:
                    self.tx_depth = depth
                    committed = drop_commit_callbacks(self.commit_callbacks, depth)
                    try:
                        self._forget_planning_copy()
                        self._roll_back(depth)
                    finally:
                        if listeners:
                            self._rolled_back()
                    raise
                self.tx_depth = depth
                try:
                    if not conn.in_transaction:   # (ended unseen: a statement ended it)
                        self._transaction_ended(None)
                    if self.ended:
                        raise self._ended_error(depth)
                    if depth == 0:
                        self.check_identity()  # before anything is acknowledged
                    conn.execute("COMMIT" if depth == 0 else f"RELEASE slr_sp{depth}")
                except BaseException as exc:
                    committed = drop_commit_callbacks(self.commit_callbacks, depth)
                    self._forget_planning_copy()
                    if depth == 0 or self.ended:
                        self._roll_back(depth)
                    if listeners:
                        self._rolled_back()
                    if isinstance(exc, sqlite3.Error):   # (a full disk meets the commit)
                        raise self.failure(exc) from None
                    raise
                if depth == 0 and self.commit_callbacks:   # (taken under the lock: ours)
                    committed, self.commit_callbacks = self.commit_callbacks, []
                elif depth:   # (released into the enclosing one: its callbacks now)
                    merge_commit_callbacks(self.commit_callbacks, depth)
        except BaseException as exc:
            if committed:   # (rolled back: what a rollback does not take back)
                run_after_rollback(committed, exc)
            raise
        run_commit_callbacks(committed)

    def _roll_back(self, depth: int) -> None:
        """Take back the transaction level ``depth`` that is ending with an error (lock
        held): ``ROLLBACK`` of the whole at depth 0, else ``ROLLBACK TO`` its savepoint. It
        never raises: the error that ends the level is what its caller must hear. A
        transaction SQLite already rolled back itself (a full disk, an I/O error) is not
        rolled back again; a savepoint that cannot be rolled back to ends the whole
        transaction (:meth:`_transaction_ended`: what it changed must not be committed with
        the rest)."""
        conn = self.conn
        try:
            if depth == 0:
                self.ended = []
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                return
            if not conn.in_transaction:   # (ended unseen: nothing of this level is left)
                self._transaction_ended(None)
                return
            conn.execute(f"ROLLBACK TO slr_sp{depth}")
            conn.execute(f"RELEASE slr_sp{depth}")
        except sqlite3.Error as exc:
            if depth:
                self._transaction_ended(exc)
            # (at depth 0 a ROLLBACK that fails leaves nothing to keep: SQLite rolls back
            # what it cannot commit, and the next BEGIN starts afresh)

    def _transaction_ended(self, reason: BaseException | None) -> None:
        """The open transaction ended before its levels did (lock held): SQLite rolls a
        transaction back itself when a statement meets a full disk, an I/O error or an
        interrupt, a hand-written statement may end it, and a rollback to a savepoint
        that failed leaves that part in it. The statements its levels still run must not
        commit one by one, nor the part be kept with the rest: the whole is rolled back
        and a transaction begun again, with the savepoints of the open levels, so that
        their statements and rollbacks go on inside it; each level that ends without an
        error raises :meth:`_ended_error` instead (nothing of the transaction is kept),
        and the outermost level's end forgets ``reason``."""
        if not self.ended:
            self.ended = [reason]
        conn = self.conn
        try:
            if conn.in_transaction:
                conn.execute("ROLLBACK")
            conn.execute("BEGIN")
            for level in range(1, self.tx_depth):
                conn.execute(f"SAVEPOINT slr_sp{level}")
        except sqlite3.Error:
            pass   # (each level's end then finds no transaction, and says so)

    def _ended_error(self, depth: int) -> SLRError:
        """What a level of a transaction that ended before it (:meth:`_transaction_ended`)
        raises as it ends without an error of its own."""
        reason = self.ended[0] if self.ended else None
        outcome = "the transaction was rolled back, nothing of it was written" if depth == 0 \
            else "the transaction is rolled back, nothing of it will be written"
        if isinstance(reason, sqlite3.Error):
            error = store_error(reason, self.path, self.busy_timeout, outcome)
            if outcome in str(error):
                return error
            longer = type(error)(f"{error}; {outcome}")
            if error.store_location is None:
                return longer
            return naming_the_store(longer, error.store_location, error.store_failure)
        where = self.path or ":memory:"
        return naming_the_store(SLRError(f"{where}: the transaction ended before its end (a "
                                         f"statement ended it); {outcome}"), where)

    def _begin(self, timeout: float) -> None:
        """``BEGIN IMMEDIATE``, waiting at most ``timeout`` seconds for another
        connection's write transaction. SQLite's own busy handler sleeps longer and longer
        between tries (up to 100 ms), so a process committing back to back keeps the lock
        from the others for seconds; here the lock is tried again every 0.1 to 2 ms (a try
        is a few microseconds), so writers take turns."""
        conn = self.conn
        if self.path is None:  # in memory: no other connection to wait for
            conn.execute("BEGIN IMMEDIATE")
            return
        conn.execute("PRAGMA busy_timeout = 0")
        try:
            deadline = None
            pause = 1e-4
            while True:
                try:
                    conn.execute("BEGIN IMMEDIATE")
                    return
                except sqlite3.OperationalError as exc:
                    busy = busy_error(exc, self.path, self.busy_timeout)
                    if busy is None:
                        raise
                    now = time.monotonic()
                    if deadline is None:
                        deadline = now + timeout
                    if now >= deadline:
                        raise busy from None
                    time.sleep(min(pause * (0.5 + random.random()), deadline - now))
                    pause = min(pause * 2, 2e-3)
        finally:
            conn.execute(f"PRAGMA busy_timeout = {int(self.busy_timeout * 1000)}")

    def _rolled_back(self) -> None:
        """Call the rollback listeners (lock held), as a transaction level ends with an
        error, which its caller must hear: a listener that reads the store again and meets
        the store's own condition (the file damaged, the server gone: that error's cause,
        most likely) does not hide it, and the next listener still runs."""
        for listener in self.rollback_listeners:
            try:
                listener()
            except (SLRError, DatabaseError):
                continue

    def after_commit(self, callback: Callable[[], None], always: bool = False) -> None:
        """Call ``callback()`` once the outermost transaction this thread is in has
        committed and let go of the store's lock; never, should the transaction (or the
        nested one it was asked for in) roll back. Outside a transaction: at once.

        >>> db = Database(None); heard = []
        >>> with db.transaction():
        ...     db.after_commit(lambda: heard.append("committed"))
        ...     heard.append("inside")
        >>> heard
        ['inside', 'committed']
        """
        with self.lock:
            if self.tx_depth:
                self.commit_callbacks.append((self.tx_depth, callback, always))
                return
        callback()

    # ------------------------------------------------------------------ raw SQL

    def sql(self, query: str, params: Iterable[Any] = (), write: bool = False,
            timeout: float | None = None) -> tuple[list[str], list[tuple]]:
        """Run one SQL statement as given (for ``slr sql``) and return ``(column names,
        rows)``. Read-only unless ``write``: a statement that would change the store (an
        INSERT, a DROP, a pragma assignment, an ATTACH) raises an :class:`SLRError` starting
        with ``read-only``; written or not, a transaction-control statement (BEGIN, COMMIT,
        SAVEPOINT, ...: the connection's transactions are the store's) and an assignment of
        a pragma the store sets itself (synchronous, busy_timeout, ...) raise an SLRError saying so
        (:meth:`SqlGuard.hand_written`, :meth:`SqlGuard.writing`); a condition of the file or its disk :meth:`failure`'s SLRError;
        the statement's own errors raise :data:`DatabaseError`. The connection's SQL
        functions are there, so compiled statements (``kb.explain``) run as printed.
        ``timeout`` (seconds): a longer statement is interrupted with :class:`SLRTimeout`.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).sql("SELECT 1 AS one")
        (['one'], [(1,)])
        >>> EventStore(None).sql("DROP TABLE slr_meta")
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: read-only: the statement would change the store (attempt to write a readonly database); pass write=True to allow it
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        with self.lock:
            self.check_open()
            conn = self.conn
            guard = self.guard
            guard.begin_statement()
            if write:
                columns, rows, _ = self._write(query, params, deadline)
                return columns, rows
            # query_only refuses every write to a database file; the authorizer refuses what
            # it lets through (pragma assignments such as journal_mode, ATTACH, DETACH) and
            # the functions no statement may call; the length limit turns a memory bomb
            # (randomblob(2e9), printf('%.*c', 2e9, 'x')) into an error
            conn.execute("PRAGMA query_only = 1")
            conn.set_authorizer(guard.read_only)
            longest = conn.setlimit(sqlite3.SQLITE_LIMIT_LENGTH, READ_ONLY_VALUE_BYTES)
            try:
                with self._deadline(deadline, "the SQL statement", stops=not self.tx_depth):
                    cursor = conn.execute(query, bound_parameters(params))
                    columns = [d[0] for d in cursor.description] if cursor.description else []
                    return columns, _bounded_rows(cursor)
            except sqlite3.DatabaseError as exc:
                reason = _read_only_error(exc, guard)
                raise (self.failure(exc) if reason is exc else reason) from None
            finally:
                conn.setlimit(sqlite3.SQLITE_LIMIT_LENGTH, longest)
                conn.set_authorizer(guard.always)
                conn.execute("PRAGMA query_only = 0")

    def sql_write(self, query: str, params: Iterable[Any] = (), timeout: float | None = None
                  ) -> tuple[list[str], list[tuple], set[str]]:
        """Run one statement as ``sql(..., write=True)`` does, and say which tables of the
        store it inserted rows into or updated, those its triggers wrote included (SQLite's
        authorizer names them while it compiles the statement, whatever the spelling).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.declare_type("p", 1)
        'p'
        >>> s.sql_write('INSERT INTO "P" (arg1, t_start, t_end, arrival) VALUES (1, 1, 1, 1)')
        ([], [], {'p'})
        """
        with self.lock:
            self.check_open()
            return self._write(query, params,
                               None if timeout is None else time.monotonic() + timeout)

    def tables_to_write(self, query: str, params: Iterable[Any] = ()) -> set[str] | None:
        """The tables of the store a statement would insert rows into or update, those its
        triggers would write included, told by compiling it (``EXPLAIN``: nothing runs);
        None when it cannot be compiled so (its own run says why). A statement the store
        refuses (:meth:`SqlGuard.writing`: a BEGIN, a COMMIT, ...) raises its SLRError here,
        before any transaction of the check is begun.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.declare_type("p", 1)
        'p'
        >>> s.tables_to_write("UPDATE [P] SET arg1 = ?", (1,)), s.tables_to_write("VACUUM")
        ({'p'}, set())
        """
        with self.lock:
            self.check_open()
            conn, guard = self.conn, self.guard
            guard.begin_statement()
            conn.set_authorizer(guard.writing)
            try:
                conn.execute(f"EXPLAIN {query}", bound_parameters(params)).close()
                return guard.written
            except sqlite3.Error as exc:
                if _refused(str(exc), guard):
                    raise SLRError(f"sql: {guard.denied}") from None
                return None
            except (OverflowError, TypeError, ValueError):
                return None
            finally:
                guard.denied = None
                conn.set_authorizer(guard.always)

    def _write(self, query: str, params: Iterable[Any], deadline: float | None
               ) -> tuple[list[str], list[tuple], set[str]]:
        if not self.tx_depth:   # (autocommit: no COMMIT of ours checks the file)
            self.check_identity()
        conn, guard = self.conn, self.guard
        guard.begin_statement()
        # (setting an authorizer expires the connection's prepared statements: a statement
        # run before is compiled again, so the authorizer sees it and its triggers)
        conn.set_authorizer(guard.writing)
        try:
            with self._deadline(deadline, "the SQL statement"):
                cursor = conn.execute(query, bound_parameters(params))
                columns = [d[0] for d in cursor.description] if cursor.description else []
                return columns, fetch_rows(cursor), guard.written
        except sqlite3.DatabaseError as exc:
            if _refused(str(exc), guard):
                raise SLRError(f"sql: {guard.denied}") from None
            if _FUNCTION_FAILED in str(exc):
                raise SLRError(f"sql: {_NOT_UTF8}") from None
            raise self.failure(exc) from None
        finally:
            conn.set_authorizer(guard.always)

    def execute(self, sql: str, params: Iterable[Any] = ()) -> list[tuple]:
        """Execute one statement for another slr_sql module (triggers, buffer pruning, ...)
        and return its rows. Inside :meth:`transaction` it is part of the transaction. A
        condition of the file or its disk raises :meth:`failure`'s SLRError, a statement's own
        error a :data:`DatabaseError`: the one path of this class's reads of the catalog
        (:meth:`table_names`, :meth:`data_version`, ...) too.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).execute("SELECT ? + 1", (1,))
        [(2,)]
        """
        with self.lock:
            self.check_open()
            try:
                return fetch_rows(self.conn.execute(
                    sql, params if type(params) is tuple else tuple(params)))
            except sqlite3.Error as exc:
                raise self.failure(exc) from None

    def executemany(self, sql: str, rows: Iterable[Iterable[Any]]) -> None:
        """``executemany`` for other slr_sql modules.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.executemany("INSERT INTO slr_meta VALUES (?, ?)", [("a", "1")])
        """
        with self.lock:
            self.check_open()
            try:
                self.conn.executemany(sql, rows)
            except sqlite3.Error as exc:
                raise self.failure(exc) from None

    def executescript(self, script: str) -> None:
        """Run several statements (e.g. ``CREATE TRIGGER`` ... ``END;``) in one transaction.
        (Unlike ``sqlite3``'s ``executescript`` it does not commit an enclosing transaction.)

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.executescript("CREATE TABLE slr_x(a); CREATE TABLE slr_y(b);")
        """
        with self.transaction():
            for statement in split_sql_script(script):
                try:
                    self.conn.execute(statement)
                except sqlite3.Error as exc:
                    raise self.failure(exc) from None

    def changes(self) -> int:
        """Rows changed by the last statement (``changes()``).

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.executemany("INSERT INTO slr_meta VALUES (?, ?)", [("a", "1")])
        >>> s.changes()
        1
        """
        return self.execute("SELECT changes()")[0][0]

    def query_plan(self, sql: str) -> list[str]:
        """SQLite's ``EXPLAIN QUERY PLAN`` lines for a statement (parameters bound to NULL).

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).query_plan("SELECT * FROM slr_meta WHERE key = ?")
        ['SEARCH slr_meta USING INDEX sqlite_autoindex_slr_meta_1 (key=?)']
        """
        return [row[3] for row in self.execute("EXPLAIN QUERY PLAN " + sql,
                                                [None] * sql.count("?"))]

    # ------------------------------------------------------------------ compiled queries
    # Execution helpers for slr_sql.planner / slr_sql.sqlcompile: application-defined
    # functions and running compiled statements (parameters always bound).

    def install_functions(self, functions: SqlFunctions) -> None:
        """Register the Python functions statements may call (the one list of them is
        :data:`slr_sql.sql_functions.SQL_FUNCTIONS`) on the store's connection, and on
        every reading connection opened from now on.

        >>> from slr_sql.store.functions import Native, SqlFunction, SqlFunctions
        >>> db = Database(None)
        >>> db.install_functions(SqlFunctions(
        ...     (SqlFunction("twice", 1, lambda x: 2 * x, Native.INTERPRETER_ONLY),), ()))
        >>> db.execute("SELECT twice(21)")
        [(42,)]
        """
        with self.lock:
            self.check_open()
            self.functions = functions
            register_functions(self.conn, functions, self)

    def run_compiled(self, sql: str, params: dict, limit: int | None = None,
                     deadline: float | None = None, may_fall_back: bool = False,
                     instructions: int | None = None,
                     stop: threading.Event | None = None) -> list[tuple]:
        """Run a compiled SELECT with named parameters; all rows, or the first ``limit``.
        ``deadline`` (``time.monotonic()``): past it the statement is interrupted and
        :class:`SLRTimeout` raised, as the interpreter does for ``timeout=``.
        ``instructions``: a budget of SQLite virtual machine instructions, counted by the
        progress handler every :data:`INSTRUCTIONS_PER_CHECK`; past it the statement is
        interrupted with :class:`SLRTimeout` too. The count depends on the statement and
        the data, never on the machine's speed (what ``max_steps`` is to the interpreter),
        exact to within one :data:`INSTRUCTIONS_PER_CHECK` (SQLite counts a cached
        statement's intervals on from where its previous run left off).
        ``may_fall_back``: the caller answers with the interpreter when the statement
        fails, so a failure must leave the caller's transaction usable (SQLite's does); it
        is a query's statement, which :meth:`stop_queries` ends outside a transaction.
        ``stop``: the query's stop (``Solutions.stop()`` sets it, from another thread, and
        calls :meth:`stop_query`); once set, the statement is interrupted at its progress
        handler's next check with SLRError :data:`~slr_sql.errors.STOPPED_BY_CALLER`.

        >>> from slr_sql.store import EventStore
        >>> EventStore(None).run_compiled("SELECT :a + 1", {"a": 1})
        [(2,)]
        >>> EventStore(None).run_compiled("WITH RECURSIVE r(n) AS (SELECT 1 UNION ALL "
        ...                               "SELECT n + 1 FROM r) SELECT count(*) FROM r", {},
        ...                               instructions=100_000)   # endless: stopped by count
        Traceback (most recent call last):
        slr_sql.errors.SLRTimeout: query ran out of its budget of 100000 SQLite instructions (in its compiled SQL statement)
        """
        with self.lock:
            self.check_open()
            # (inside a transaction it is part of a write -- an event rule's where goal
            # deciding in its add -- which a close waits for)
            stops = may_fall_back and not self.tx_depth
            if stops and self.stopping:
                raise SLRError(CLOSED_WHILE_RUNNING)
            if stop is not None and stop.is_set():
                raise SLRError(STOPPED_BY_CALLER)
            try:
                with self._deadline(deadline, "its compiled SQL statement", instructions,
                                    stops=stops, stop=stop):
                    cursor = self.conn.execute(sql, params)
                    try:
                        return fetch_rows(cursor, limit)
                    finally:
                        cursor.close()
            except sqlite3.Error as exc:
                raise self.failure(exc) from None

    def run_compiled_many(self, sql: str, rows: list) -> None:
        """Run a compiled writing statement once per row of parameters (dicts for named
        parameters, tuples for ``?``), in the current transaction.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.run_compiled("CREATE TABLE t (x)", {})
        []
        >>> s.run_compiled_many("INSERT INTO t VALUES (:x)", [{"x": 1}, {"x": 2}])
        >>> s.run_compiled("SELECT sum(x) FROM t", {})
        [(3,)]
        """
        with self.lock:
            self.check_open()
            try:
                self.conn.executemany(sql, rows)
            except sqlite3.Error as exc:
                raise self.failure(exc) from None

    def run_compiled_batch(self, statements: list) -> list[list[tuple]]:
        """Run compiled statements in order, in the current transaction: each a ``(sql,
        params, many)``, ``many`` meaning ``params`` is a list of rows for
        :meth:`run_compiled_many`. Returns each one's rows ([] for ``many``). On a server
        they go in one round trip.

        >>> from slr_sql.store import EventStore
        >>> s = EventStore(None); s.run_compiled("CREATE TABLE t (x)", {})
        []
        >>> s.run_compiled_batch([("INSERT INTO t VALUES (:x)", [{"x": 1}, {"x": 2}], True),
        ...                       ("SELECT sum(x) FROM t", {}, False)])
        [[], [(3,)]]
        """
        return [self.run_compiled_many(sql, params) or [] if many
                else self.run_compiled(sql, params) for sql, params, many in statements]

    @contextmanager
    def _deadline(self, deadline: float | None, what: str,
                  instructions: int | None = None, stops: bool = False,
                  stop: threading.Event | None = None) -> Iterator[None]:
        """Interrupt the statements run inside past ``deadline`` (``time.monotonic()``), or
        past ``instructions`` virtual machine instructions, with :class:`SLRTimeout`; with
        ``stops`` (a query's statement), once :meth:`stop_queries` was called, with SLRError
        :data:`CLOSED_WHILE_RUNNING`; once ``stop`` (the query's) is set, with SLRError
        :data:`STOPPED_BY_CALLER`. A statement run from inside another (a ``kb.define``
        predicate querying the kb from SQL) keeps the outer deadline, and without a budget
        of its own its instructions count against the outer budget: the handler is per
        connection (one with its own budget or an earlier deadline has its own handler while
        it runs, and the outer's is put back). Call with the lock held."""
        conn = self.conn
        outer, outer_handler = self.deadline, self.progress
        if deadline is None or (outer is not None and outer <= deadline):
            deadline = outer
        # (an inner statement of a query's statement ends with it)
        stops = stops or (outer_handler is not None and outer_handler[2])
        checks = [0]
        allowed = -1 if instructions is None else max(1, instructions // INSTRUCTIONS_PER_CHECK)
        handler: tuple[Callable[[], int], int, bool] | None = outer_handler
        if instructions is not None:
            def out_of_budget() -> int:
                checks[0] += 1
                if checks[0] > allowed or (stops and self.stopping) or (
                        stop is not None and stop.is_set()):
                    return 1
                return 1 if deadline is not None and time.monotonic() > deadline else 0

            handler = (out_of_budget, INSTRUCTIONS_PER_CHECK, stops)
        elif deadline is not outer:
            handler = (lambda: 1 if (stops and self.stopping) or (
                stop is not None and stop.is_set()) or time.monotonic() > deadline else 0,
                STOP_CHECK_INSTRUCTIONS, stops)
        elif stop is not None or (stops and (outer_handler is None or not outer_handler[2])):
            # (no limit of its own: the outer's, if any, still counts)
            limit = None if outer_handler is None else outer_handler[0]
            handler = (lambda: 1 if (stops and self.stopping) or (
                stop is not None and stop.is_set()) or (limit is not None and limit()) else 0,
                STOP_CHECK_INSTRUCTIONS if outer_handler is None else outer_handler[1],
                stops)
        outer_call = self.progress_call
        if handler is not None:
            # (a handler of its own even where the outer's holds: an inner statement may run
            # inside the outer's progress handler -- a signal's handler that queries the
            # store -- whose generator cannot be resumed while it runs)
            self.deadline, self.progress = deadline, handler
            self.progress_call = _signal_safe(handler[0], self)
            conn.set_progress_handler(self.progress_call, handler[1])
        if outer_handler is None:
            self.escaped.clear()
            self.ended_by_handler = False
        try:
            yield
        except sqlite3.OperationalError as exc:
            if self.tx_depth and not conn.in_transaction:
                self._transaction_ended(exc)   # (an interrupted write rolls it all back)
            if self.escaped:
                # a signal handler's exception (Ctrl-C) ended the statement: the caller's,
                # not a failure of the statement (its query would go on in the interpreter);
                # kept for an outer statement, ended by its failing function call
                raise self.escaped[0] from None
            if "interrupt" in str(exc):
                if checks[0] > allowed >= 0:
                    raise SLRTimeout(f"query ran out of its budget of {instructions} SQLite "
                                     f"instructions (in {what})") from None
                if deadline is not None and time.monotonic() > deadline:
                    raise SLRTimeout(f"query timed out (in {what})") from None
                if stops and self.stopping:
                    raise SLRError(CLOSED_WHILE_RUNNING) from None
                if stop is not None and stop.is_set():
                    raise SLRError(STOPPED_BY_CALLER) from None
                if handler is not None and not self.ended_by_handler:
                    # no handler of ours asked, nothing kept: an exception escaped the
                    # handler (a signal's, met outside _signal_safe's try): as a Ctrl-C's
                    raise KeyboardInterrupt from None
            raise busy_error(exc, self.path, self.busy_timeout) or exc from None
        else:
            if self.escaped and outer_handler is None:
                # (kept by a step's wrapper whose call went on, and no progress handler
                # ended the statement: it ran to its end, and the Ctrl-C is still the caller's)
                raise self.escaped[0] from None
        finally:
            if outer_handler is None:
                self.escaped.clear()
                self.ended_by_handler = False
            if handler is not None:
                self.deadline, self.progress = outer, outer_handler
                self.progress_call = outer_call
                if outer_handler is None or outer_call is None:
                    conn.set_progress_handler(None, 0)
                else:
                    # (the outer's own object: replaced by a new one, the one that may be
                    # running now -- the signal's handler above it returns into it -- would
                    # lose its last owner)
                    conn.set_progress_handler(outer_call, outer_handler[1])


def _signal_safe(check: Callable[[], int], db: Database) -> Callable[[], int]:
    """``check`` as a progress handler that keeps an exception a signal handler raises in it
    (a Ctrl-C's KeyboardInterrupt, a handler's SystemExit) in ``db.escaped`` and ends the
    statement, instead of letting it escape into sqlite3, which clears it and ends the
    statement "interrupted" as if the handler had asked. Python runs pending signal handlers
    at the first instruction of the Python code sqlite3 calls, before any ``try`` of a
    plain function; resumed generator code starts inside its ``try``. When ``check`` asks
    to end the statement, ``db.ended_by_handler`` says so.

    >>> db = Database(None)
    >>> def raising() -> int:
    ...     raise KeyboardInterrupt
    >>> _signal_safe(lambda: 0, db)(), _signal_safe(raising, db)(), db.escaped
    (0, 1, [KeyboardInterrupt()])
    """
    def checks() -> Iterator[int]:
        answer = 0
        while True:
            try:
                while True:
                    yield answer
                    # (kept by a function's or a step's wrapper whose call went on: end now)
                    answer = 1 if db.escaped else check()
                    if answer:
                        db.ended_by_handler = True
            except GeneratorExit:
                return
            except BaseException as exc:   # noqa: BLE001 - kept, raised once it ended
                if not db.escaped:
                    db.escaped.append(exc)
                answer = 1

    handler = checks()
    next(handler)
    return handler.__next__


class _NoValue:
    """What a function called from SQL returns instead of raising (sqlite3 cannot store
    it: the call fails as it would for an exception, "user-defined function raised
    exception")."""


_NO_VALUE = _NoValue()


def _signal_safe_function(fn: Callable[[Any], Any], db: Database) -> Callable[[Any], Any]:
    """``fn`` (of one argument) as a function SQL calls, which keeps an exception a signal
    handler raises as it is called in ``db.escaped`` (as :func:`_signal_safe` does for a
    progress handler); the call then fails, as it does when ``fn`` raises an
    :class:`Exception` of its own.

    >>> db = Database(None)
    >>> def halve(x: int) -> float:
    ...     if x == 3:
    ...         raise KeyboardInterrupt   # (as a signal's handler would, inside fn)
    ...     return 1 / x
    >>> halve_safely = _signal_safe_function(halve, db)
    >>> halve_safely(2), halve_safely(0) is _NO_VALUE, db.escaped
    (0.5, True, [])
    >>> halve_safely(3) is _NO_VALUE, db.escaped, halve_safely(4)
    (True, [KeyboardInterrupt()], 0.25)
    """
    def calls() -> Generator[Any, Any, None]:
        result = None
        while True:
            try:
                while True:
                    argument = yield result
                    try:
                        result = fn(argument)
                    except Exception:   # noqa: BLE001 - fn's own: the call fails
                        result = _NO_VALUE
            except GeneratorExit:
                return
            except BaseException as exc:   # noqa: BLE001 - kept, raised once it ended
                if not db.escaped:
                    db.escaped.append(exc)
                result = _NO_VALUE

    call = calls()
    next(call)
    return call.send


def _signal_safe_step(step: Callable[[Any], Any], db: Database) -> Callable[[Any], Any]:
    """An aggregate's ``step`` of one argument, as :func:`_signal_safe_function` wraps a
    function, for a run without the C speedups: what a signal handler raises as it is called
    is kept in ``db.escaped`` and the call returns (the statement's progress handler then
    ends the statement, :func:`_signal_safe`); what ``step`` raises of its own fails the
    call, as it would unwrapped.

    >>> db = Database(None)
    >>> def step(x: int) -> None:
    ...     if x == 0:
    ...         raise ValueError("zero")
    ...     if x == 3:
    ...         raise KeyboardInterrupt   # (as a signal's handler would, inside step)
    >>> safe_step = _signal_safe_step(step, db)
    >>> safe_step(1), safe_step(3), db.escaped
    (None, None, [KeyboardInterrupt()])
    >>> safe_step(0)
    Traceback (most recent call last):
    ...
    ValueError: zero
    """
    def calls() -> Generator[None, Any, None]:
        while True:
            try:
                while True:
                    step((yield))
            except GeneratorExit:
                return
            except Exception:   # step's own: the call fails (and the statement with it)
                raise
            except BaseException as exc:   # noqa: BLE001 - kept, raised once it ended
                if not db.escaped:
                    db.escaped.append(exc)

    call = calls()
    next(call)
    return call.send


CommitCallbacks = list[tuple[int, Callable[[], None], bool]]


def in_own_transaction(db: Any) -> bool:
    """Whether the calling thread is inside a transaction of ``db`` (a Database or a
    PgDatabase): the lock is held for a whole transaction, so once this thread holds it, one
    open is this thread's (another thread's would have kept it from the lock until done).
    What ``transaction(join=True)`` asks before joining instead of opening a savepoint.

    >>> db = Database(None)
    >>> with db.transaction():
    ...     in_own_transaction(db)
    True
    >>> in_own_transaction(db)
    False
    """
    with db.lock:
        return bool(db.tx_depth)


def merge_commit_callbacks(callbacks: CommitCallbacks, depth: int) -> None:
    """Hand, in ``callbacks``, those asked for inside the nested transaction released into
    the one at ``depth`` (>= 1) over to that one: a later nested transaction at the same
    depth that rolls back must not take them back with its own.

    >>> callbacks = [(1, print, False), (2, print, False)]
    >>> merge_commit_callbacks(callbacks, 1); callbacks
    [(1, <built-in function print>, False), (1, <built-in function print>, False)]
    """
    callbacks[:] = [(min(d, depth), callback, always) for d, callback, always in callbacks]


def drop_commit_callbacks(callbacks: CommitCallbacks, depth: int) -> CommitCallbacks:
    """Forget, in ``callbacks``, those asked for inside the (nested) transaction at ``depth``
    that rolled back, but those asked for ``always``: they move to the enclosing one, and
    are returned to be run once the outermost one rolled back (depth 0).

    >>> callbacks = [(1, print, False), (2, print, False), (2, print, True)]
    >>> drop_commit_callbacks(callbacks, 1), callbacks
    ([], [(1, <built-in function print>, False), (1, <built-in function print>, True)])
    >>> drop_commit_callbacks(callbacks, 0), callbacks
    ([(1, <built-in function print>, True)], [])
    """
    kept: CommitCallbacks = []
    due: CommitCallbacks = []
    for d, callback, always in callbacks:
        if d <= depth:
            kept.append((d, callback, always))
        elif always:
            (due if depth == 0 else kept).append((max(depth, 1), callback, always))
    callbacks[:] = kept
    return due


def run_after_rollback(callbacks: CommitCallbacks, error: BaseException) -> None:
    """Call the ``always`` callbacks of a transaction that rolled back because of ``error``
    (which goes on being raised: theirs are noted on it).

    >>> def fails(): raise ValueError("cache gone")
    >>> error = KeyError("the rollback's cause")
    >>> run_after_rollback([(1, lambda: print("undone"), True), (1, fails, True)], error)
    undone
    >>> error.__notes__
    ['and after the rollback: ValueError: cache gone']
    """
    for _depth, callback, _always in callbacks:
        try:
            callback()
        except BaseException as exc:   # (the rollback's cause is what the caller hears)
            error.add_note(f"and after the rollback: {type(exc).__name__}: {exc}")


def run_commit_callbacks(callbacks: CommitCallbacks) -> None:
    """Call each of ``callbacks`` (``(depth, callback, always)``, asked for with ``after_commit``)
    once their transaction committed: every one, even after one raised (each is the rest of
    an add, mark or clock move of its own: the later ones are still observed, decided and
    heard), then the first error raised.

    >>> heard = []
    >>> def fails(): raise KeyError("first")
    >>> run_commit_callbacks([(1, fails, False), (1, lambda: heard.append("second"), False)])
    Traceback (most recent call last):
    ...
    KeyError: 'first'
    >>> heard
    ['second']
    """
    first: BaseException | None = None
    for _depth, callback, _always in callbacks:
        try:
            callback()
        except BaseException as exc:   # (raised once the others ran)
            if first is None:
                first = exc
    if first is not None:
        raise first


def harden(conn: sqlite3.Connection, db: Database | None = None) -> SqlGuard:
    """:func:`~slr_sql.store.authorizer.harden_connection` and the wrapped built-ins of
    :mod:`~slr_sql.store.bounded_builtins`: what every connection of the store gets. (Its
    rows are read with :func:`~slr_sql.store.stored_text.fetch_rows`, which reads a text
    that is no UTF-8 with U+FFFD and a warning, not an error for its whole table.) ``db``:
    the store whose connection it is (:func:`register_functions`).

    >>> conn = sqlite3.connect(":memory:"); guard = harden(conn)
    >>> conn.execute("SELECT printf('%.*c', 2000000000, 'x')").fetchall()  # at once, not in 9 s
    [(None,)]
    >>> conn.execute("SELECT load_extension('evil.so')")
    Traceback (most recent call last):
        ...
    sqlite3.OperationalError: not authorized to use function: load_extension
    """
    guard = harden_connection(conn)
    register_functions(conn, bounded_builtins(conn, guard), db)
    return guard


def register_functions(conn: sqlite3.Connection, functions: SqlFunctions,
                       db: Database | None = None) -> None:
    """Register every function and aggregate of ``functions`` on one SQLite connection:
    the only place slr_sql registers Python functions (tests/test_sql_functions.py).
    ``db``: the store whose connection it is; there each function keeps what a signal
    handler raises as it is called in ``db.escaped`` (Python runs a Ctrl-C's handler in the
    first Python code that runs, most often a function called row by row, where sqlite3
    would clear it): wrapped by the C speedups' ``signal_safe`` when built, else the
    functions and the aggregates' steps of one argument only (:func:`_signal_safe_function`;
    a step's call goes on, and the statement's progress handler ends it).

    >>> from slr_sql.store.functions import Native, SqlFunction
    >>> twice = SqlFunction("twice", 1, lambda x: 2 * x, on_postgres=Native.INTERPRETER_ONLY)
    >>> conn = sqlite3.connect(":memory:"); register_functions(conn, SqlFunctions((twice,), ()))
    >>> conn.execute("SELECT twice(21)").fetchall()
    [(42,)]
    """
    for f in functions.functions:
        fn = f.fn
        if db is not None:
            if signal_safe_loop is not None:
                fn = signal_safe_loop(fn, db.escaped)
            elif f.arity == 1:
                fn = _signal_safe_function(fn, db)
        conn.create_function(f.name, f.arity, fn, deterministic=f.deterministic)
    for a in functions.aggregates:
        cls = a.cls if db is None else _signal_safe_aggregate(a.cls, a.arity, db)
        conn.create_aggregate(a.name, a.arity, cls)


class _SignalSafeAggregate:
    """One group's aggregate as SQLite calls it: the ``step`` and ``finalize`` of the
    aggregate's own instance, wrapped to keep what a signal handler raises in them."""

    __slots__ = ("step", "finalize")


def _signal_safe_aggregate(cls: type, arity: int, db: Database) -> Callable[[], Any]:
    """The aggregate ``cls`` as :func:`register_functions` registers it on ``db``'s
    connection: a factory of one :class:`_SignalSafeAggregate` per group, whose calls keep a
    signal handler's exception (a Ctrl-C's) in ``db.escaped`` -- as the functions' do: an
    aggregate's step is called row by row, where Python most often runs the handler, and
    sqlite3 clears what it raises there ("'step' method raised error"), so the statement
    failed and the goal went on in the interpreter.

    >>> class Total:
    ...     def __init__(self): self.v = 0
    ...     def step(self, x): self.v += x
    ...     def finalize(self): return self.v
    >>> db = Database(None); total = _signal_safe_aggregate(Total, 1, db)()
    >>> total.step(2), total.step(3), total.finalize(), db.escaped
    (None, None, 5, [])
    """
    if signal_safe_loop is not None:
        safe = signal_safe_loop

        def make() -> _SignalSafeAggregate:
            inner = cls()
            aggregate = _SignalSafeAggregate()
            aggregate.step = safe(inner.step, db.escaped)
            aggregate.finalize = safe(inner.finalize, db.escaped)
            return aggregate
        return safe(make, db.escaped)

    def make_in_python() -> _SignalSafeAggregate:
        inner = cls()
        aggregate = _SignalSafeAggregate()
        aggregate.step = _signal_safe_step(inner.step, db) if arity == 1 else inner.step
        aggregate.finalize = inner.finalize
        return aggregate
    return make_in_python


def _bounded_rows(cursor: sqlite3.Cursor) -> list[tuple]:
    """Every row of a read-only statement, or an SLRError once its strings and blobs, with
    :data:`READ_ONLY_VALUE_COST` bytes for each value, add up to more than
    :data:`READ_ONLY_RESULT_BYTES` (a statement repeating a large value over many rows, or
    many values over many rows, would otherwise fill the memory before its time limit)."""
    rows: list[tuple] = []
    size = 0
    while True:
        batch = fetch_rows(cursor, 256)
        if not batch:
            return rows
        for row in batch:
            size += READ_ONLY_VALUE_COST * len(row)
            for value in row:
                if type(value) is str or type(value) is bytes:
                    size += len(value)
        if size > READ_ONLY_RESULT_BYTES:
            cursor.close()
            raise SLRError(f"sql: the result of a read-only statement is larger than "
                           f"{READ_ONLY_RESULT_BYTES >> 20} MiB of text and blobs (each value "
                           f"counted as {READ_ONLY_VALUE_COST} bytes besides its text): ask "
                           f"for fewer rows (LIMIT) or columns")
        rows.extend(batch)


def _refused(text: str, guard: SqlGuard) -> bool:
    """Whether a statement's error ``text`` is a refusal whose reason ``guard`` holds: the
    authorizer's, or a wrapped built-in's (:mod:`~slr_sql.store.bounded_builtins`)."""
    return guard.denied is not None and (
        "authoriz" in text or "user-defined function raised exception" in text or
        "vtable constructor failed" in text)   # (refused in a virtual table's own statements)


# A Python function's call fails before it starts when an argument is text that is not
# valid UTF-8 (Python reads it as str): SQLite then says only "user-defined function raised
# exception", of a LIKE or trim the user never knew was a Python function.
_FUNCTION_FAILED = "user-defined function raised exception"

class _AnyParameters(dict):
    """Named parameters for a statement that is only planned: each one NULL."""

    def __missing__(self, key: str) -> None:
        return None
_NOT_UTF8 = (
    "a function call failed, most likely on text that is not valid UTF-8: LIKE, GLOB, "
    "instr, replace, printf, format, trim, ltrim, rtrim, json_patch and slr_sql's own "
    "functions run through Python on a store connection (their size is checked first: "
    "slr_sql/store/bounded_builtins.py), which reads text as UTF-8; CAST(x AS BLOB) passes "
    "the bytes as they are")


def _function_failed(text: str) -> str:
    """The words for an error ``text`` of SQLite: a failed Python function's explained."""
    return _NOT_UTF8 if _FUNCTION_FAILED in text else text


def _read_only_error(exc: sqlite3.DatabaseError, guard: SqlGuard) -> Exception:
    """The error to raise for ``exc``, raised by a read-only statement: the authorizer's
    reason, the read-only refusal, the value limit in words, else ``exc`` itself."""
    text = str(exc)
    if _refused(text, guard):
        assert guard.denied is not None
        if guard.denied.startswith("read-only"):
            return SLRError(f"{guard.denied}; pass write=True to allow it")
        if "too big" not in guard.denied:
            return SLRError(f"sql: {guard.denied}")
        text = guard.denied   # a wrapped built-in's value over the limit: said below
    if "readonly" in text or "authoriz" in text:
        return SLRError(f"read-only: the statement would change the store ({text}); pass "
                        f"write=True to allow it")
    if "too big" in text:
        return SLRError(f"sql: a read-only statement may make or read strings and blobs of at "
                        f"most {READ_ONLY_VALUE_BYTES >> 20} MiB ({text})")
    if _FUNCTION_FAILED in text:
        return SLRError(f"sql: {_NOT_UTF8}")
    return exc


class ReadConnection:
    """A connection of its own to a store's file, for a reader that must not queue behind the
    store's connection: its statements never wait for the store's lock, which a writer holds
    for a whole transaction, fsync included (WAL lets a reader and the writer work at the same
    time; each statement sees what was committed when it started). ``query_only``: it cannot
    write. Opened with :meth:`Database.open_reader`; an in-memory store has none.

    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "r.db"); db = Database(path)
    >>> reader = db.open_reader(); reader.execute("SELECT count(*) FROM slr_program")
    [(0,)]
    >>> reader.close(); db.close()
    """

    def __init__(self, path: str, busy_timeout: float = DEFAULT_BUSY_TIMEOUT,
                 cache_kib: int = 2048, functions: SqlFunctions | None = None,
                 identity: tuple[int, int] | None = None):
        self.path = path
        self.busy_timeout = busy_timeout
        self.lock = ordered_lock("store.reader")
        self.closed = False
        # (device, inode) of the store's file: another file at the path is not the store
        self._identity = identity or _file_identity(path)
        try:
            # mode=rw: a store file deleted meanwhile is not made again, empty, at its path
            self.conn = sqlite3.connect(read_only_uri(path) if on_read_only_file_system(path)
                                        else _file_uri(path, "rw"), uri=True,
                                        check_same_thread=False, isolation_level=None,
                                        timeout=busy_timeout, cached_statements=64)
        except sqlite3.Error as exc:
            raise self._error(exc) from None
        self._held = _hold(path)   # (before the first statement takes a lock: see _HELD)
        try:
            harden(self.conn)
            self.conn.execute("PRAGMA query_only=ON")
            self.conn.execute(f"PRAGMA cache_size=-{int(cache_kib)}")
            if functions is not None:
                register_functions(self.conn, functions)
        except sqlite3.Error as exc:
            self._close_connection()
            raise self._error(exc) from None
        if _file_identity(path) != self._identity:
            self._close_connection()
            raise _store_gone(path, "the store file was deleted or replaced", "nothing was read")

    def _close_connection(self) -> None:
        self.conn.close()
        _release(self._held)
        self._held = None

    def _error(self, exc: sqlite3.Error) -> SLRError:
        now = _file_identity(self.path)
        return _read_error(exc, self.path, self.busy_timeout,
                           now is None or (self._identity is not None and now != self._identity))

    def execute(self, sql: str, params: Iterable[Any] = ()) -> list[tuple]:
        """Run one reading statement and return its rows. Every failure of the database
        is an :class:`SLRError` named after it (:func:`store_error`): SLRBusy,
        SLRStoreFull, SLRStoreGone, a damaged file, a table another connection dropped."""
        with self.lock:
            if self.closed:
                raise SLRError("the event store is closed")
            try:
                return fetch_rows(self.conn.execute(sql, tuple(params)))
            except sqlite3.Error as exc:
                raise self._error(exc) from None

    def close(self) -> None:
        """Close the connection (idempotent)."""
        with self.lock:
            if not self.closed:
                self.closed = True
                self._close_connection()



def run_sql_file(path: str | os.PathLike, query: str,
                 write: bool = False) -> tuple[list[str], list[tuple]]:
    """Run one SQL statement on the store file ``path`` through a connection of its own,
    read-only unless ``write``; returns ``(column names, rows)``. Every failure (no such
    file, an SQL error, a write to a read-only connection) is an :class:`SLRError`.

    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "robot.db"); Database(path).close()
    >>> run_sql_file(path, "SELECT count(*) AS n FROM slr_program")
    (['n'], [(0,)])
    """
    path = os.fspath(path)
    if not os.path.exists(path):
        raise SLRError(f"no such store: {path}")
    uri = _file_uri(path, "rw" if write else "ro")
    try:
        conn = sqlite3.connect(uri, uri=True, isolation_level=None)
    except sqlite3.Error as exc:
        raise SLRError(f"sql: {exc}") from None
    guard = harden(conn)
    try:
        if not write:
            conn.set_authorizer(guard.read_only)
            conn.setlimit(sqlite3.SQLITE_LIMIT_LENGTH, READ_ONLY_VALUE_BYTES)
        cursor = conn.execute(query)
        columns = [d[0] for d in cursor.description or ()]
        return columns, (fetch_rows(cursor) if write else _bounded_rows(cursor))
    except sqlite3.Error as exc:
        text = str(exc)
        if _refused(text, guard) and guard.denied is not None:
            text = guard.denied
        else:
            text = _function_failed(text)
        if not write and "too big" in text:
            text = f"{text} (a read-only statement's values are at most " \
                   f"{READ_ONLY_VALUE_BYTES >> 20} MiB)"
        raise SLRError(f"sql: {text}") from None
    finally:
        conn.close()

