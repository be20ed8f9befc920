"""What a statement on a store connection may do: SQLite's authorizer and its own switches.

Every connection the store opens gets :func:`harden_connection`: the SQLite functions in
:data:`DENIED_FUNCTIONS` and the pragmas in :data:`DENIED_PRAGMAS` are refused in every
statement (the store's own SQL never calls them; a user's ``kb.sql(..., write=True)`` may not
either). A statement a user hands the store, written or read-only, may not begin or end a
transaction (:meth:`SqlGuard.hand_written`: the store's connection's transactions are the
store's), nor create a temporary table, view, trigger or index (it would outlast the
statement on the store's connection, where an unqualified name is read in ``temp`` first),
nor assign a pragma of :data:`STORE_SETTING_PRAGMAS` (those the store sets on its
connection itself: ``synchronous``, ``busy_timeout``, ``foreign_keys``, ...). SQLite's
``SQLITE_DBCONFIG_ENABLE_FTS3_TOKENIZER`` switch is turned off where Python lets it be
reached safely (:func:`fts3_tokenizer_switch_off`). A *read-only* statement (``kb.sql``
without ``write``, ``slr sql``, the service's ``/sql``) runs under the stricter
:meth:`SqlGuard.read_only`: no ``ATTACH``/``DETACH`` (also what ``VACUUM INTO`` asks for), no
pragma that changes a setting or acts (:data:`ACTING_PRAGMAS`), and each string or blob it
makes at most :data:`READ_ONLY_VALUE_BYTES` long (``randomblob``, ``zeroblob``, ``printf``
widths, ``replace``/``group_concat`` growth: a memory bomb is an error, not an allocation),
and all its rows' strings and blobs, with :data:`READ_ONLY_VALUE_COST` bytes for each value,
at most :data:`READ_ONLY_RESULT_BYTES`.

The authorizer cannot carry a message: :class:`SqlGuard` remembers why it refused, and
:class:`~slr_sql.store.connection.Database` raises that reason in words.

>>> import sqlite3
>>> conn = sqlite3.connect(":memory:"); guard = harden_connection(conn)
>>> conn.execute("SELECT fts3_tokenizer('simple')")
Traceback (most recent call last):
...
sqlite3.OperationalError: not authorized to use function: fts3_tokenizer
>>> guard.denied
"fts3_tokenizer() is not allowed (it reads and re-points SQLite's full-text tokenizers, which are addresses in the process's memory)"
"""
from __future__ import annotations

import ctypes
import sqlite3
import sys
from typing import Any

from .stored_text import fetch_row

__all__ = ["SqlGuard", "harden_connection", "fts3_tokenizer_switch_off", "DENIED_FUNCTIONS",
           "DENIED_PRAGMAS", "READING_PRAGMAS", "ACTING_PRAGMAS", "STORE_SETTING_PRAGMAS",
           "READ_ONLY_VALUE_BYTES", "READ_ONLY_RESULT_BYTES", "READ_ONLY_VALUE_COST", "transaction_control_refusal",
           "TEMPORARY_OBJECT_REFUSAL"]

# Functions no statement on a store connection may call, with the reason given.
DENIED_FUNCTIONS = {
    "fts3_tokenizer": "it reads and re-points SQLite's full-text tokenizers, which are "
                      "addresses in the process's memory",
    "load_extension": "it loads native code into the process",
    "rtreenode": "a debugging function that decodes any blob as an R*Tree node",
    "rtreedepth": "a debugging function that decodes any blob as an R*Tree node",
}

# Pragmas no statement on a store connection may run, with the reason given.
DENIED_PRAGMAS = {
    "case_sensitive_like": "it registers SQLite's own LIKE on the connection again, over "
                           "the store's bounded one, and one call of that cannot be stopped "
                           "by a statement's timeout; for a case-sensitive match use GLOB",
}

# Pragmas the store sets on its connection itself (at open, around its transactions, in its
# migrations), or whose assignment changes how its transactions work or can damage its file
# or its rows' guarantees: an assignment in a
# hand-written statement is refused even with ``write=True`` (it would last for every later
# statement of the store), with the reason given. Reading them is allowed.
STORE_SETTING_PRAGMAS = {
    "query_only": "every later write of the store would fail",
    "locking_mode": "in EXCLUSIVE mode the store's connection would keep the file locked "
                    "after each of its transactions, shutting out every other process",
    "journal_mode": "the store's transactions are journaled in its WAL, which its readers in "
                    "other processes and its checkpointer rely on",
    "synchronous": "the store sets it as it opens (slr_sql.open(..., synchronous=...), FULL "
                   "by default: an add that returned is on disk, which a lower setting would "
                   "quietly undo for every later add)",
    "busy_timeout": "the store sets it as it opens (slr_sql.open(..., busy_timeout=...)) and "
                    "around each of its transactions' BEGIN",
    "foreign_keys": "the store turns it on as it opens: its tables' references are checked "
                    "on every write",
    "cache_size": "the store sets it as it opens (slr_sql.open(..., cache_mib=...))",
    "wal_autocheckpoint": "the store sets it as it opens (slr_sql.open(..., checkpoint=...)): "
                          "checkpoints are either SQLite's, inside a commit, or the store's "
                          "background thread's",
    "auto_vacuum": "the store's file is made with auto_vacuum=INCREMENTAL, which its "
                   "reclaiming of free pages relies on",
    "user_version": "it is the number of the store's last migration, which the store's "
                    "opening reads to know which migrations to apply",
    "legacy_alter_table": "the store's migrations set it themselves",
    # (and those whose assignment can damage the store's file or the rows' guarantees)
    "writable_schema": "it lets a statement rewrite the schema table itself, which can leave "
                       "the store's file damaged so that no connection opens it again",
    "schema_version": "SQLite keeps it itself; an assignment can damage the store's file "
                      "(other connections go on with a schema they no longer read)",
    "ignore_check_constraints": "the store's tables' CHECK constraints keep its rows "
                                "well-formed (its event rules' state, its buffers)",
}

# Pragmas that take an argument and only read (also table-valued: pragma_table_info('t')).
READING_PRAGMAS = frozenset({
    "table_info", "table_xinfo", "table_list", "index_list", "index_info", "index_xinfo",
    "foreign_key_list", "foreign_key_check", "integrity_check", "quick_check",
    "function_list", "module_list", "pragma_list", "collation_list", "database_list",
    "compile_options"})

# Pragmas that act even without an argument (a read-only statement may not run them).
ACTING_PRAGMAS = frozenset({"optimize", "wal_checkpoint", "incremental_vacuum",
                            "shrink_memory"})

# The longest string or blob a read-only statement may make or read (SQLITE_LIMIT_LENGTH).
READ_ONLY_VALUE_BYTES = 64 << 20
# The most bytes a read-only statement's rows may hold together: their text and blobs, and
# READ_ONLY_VALUE_COST for each value (a number or a NULL holds no text, but its place in the
# row's tuple and its Python object cost memory all the same: 2,000 columns of NULL over
# 20,000 rows, no text at all, took 1.5 GB of a server answering them).
READ_ONLY_RESULT_BYTES = 128 << 20
# What each value of a read-only statement's rows counts beside its text: the 8 bytes of its
# place in the row and at least as much again of its object or its JSON (a low estimate).
READ_ONLY_VALUE_COST = 16

_OK, _DENY = sqlite3.SQLITE_OK, sqlite3.SQLITE_DENY
_FUNCTION = sqlite3.SQLITE_FUNCTION
_PRAGMA = sqlite3.SQLITE_PRAGMA
_ATTACHING = frozenset({sqlite3.SQLITE_ATTACH, sqlite3.SQLITE_DETACH})
_TRANSACTION, _SAVEPOINT = sqlite3.SQLITE_TRANSACTION, sqlite3.SQLITE_SAVEPOINT
# the statement SQLite's authorizer means by (action, its first argument)
_TRANSACTION_STATEMENTS = {
    (_TRANSACTION, "BEGIN"): "BEGIN", (_TRANSACTION, "COMMIT"): "COMMIT",
    (_TRANSACTION, "ROLLBACK"): "ROLLBACK", (_SAVEPOINT, "BEGIN"): "SAVEPOINT",
    (_SAVEPOINT, "RELEASE"): "RELEASE", (_SAVEPOINT, "ROLLBACK"): "ROLLBACK TO"}
_WRITING_ROWS = frozenset({sqlite3.SQLITE_INSERT, sqlite3.SQLITE_UPDATE})
_INSERT = sqlite3.SQLITE_INSERT
# creating a temporary object: announced as such, as the plain action in database "temp"
# (``CREATE TABLE temp.t``), or only by the row it writes into the temp schema's table
# (``CREATE TRIGGER temp.t ON main_table`` is announced as a trigger of "main")
_CREATING_TEMP = frozenset({sqlite3.SQLITE_CREATE_TEMP_TABLE, sqlite3.SQLITE_CREATE_TEMP_VIEW,
                            sqlite3.SQLITE_CREATE_TEMP_TRIGGER, sqlite3.SQLITE_CREATE_TEMP_INDEX})
_CREATING = frozenset({sqlite3.SQLITE_CREATE_TABLE, sqlite3.SQLITE_CREATE_VIEW,
                       sqlite3.SQLITE_CREATE_TRIGGER, sqlite3.SQLITE_CREATE_INDEX})
_TEMP_SCHEMA_TABLES = frozenset({"sqlite_temp_master", "sqlite_temp_schema"})
_FTS3_TOKENIZER_SWITCH = 1004  # SQLITE_DBCONFIG_ENABLE_FTS3_TOKENIZER


def transaction_control_refusal(statement: str) -> str:
    """Why a hand-written transaction-control statement (``statement``: its keyword) is
    refused, on either backend.

    >>> transaction_control_refusal("COMMIT")
    'COMMIT is not allowed: the store begins and ends its own transactions (several statements stored together or not at all: with kb.store.transaction(): ...)'
    """
    return (f"{statement} is not allowed: the store begins and ends its own transactions "
            f"(several statements stored together or not at all: with kb.store.transaction(): "
            f"...)")


# why a hand-written statement may not create a temporary object on a SQLite store
TEMPORARY_OBJECT_REFUSAL = (
    "a temporary table, view, trigger or index is not allowed: it would outlast the statement "
    "on the store's own connection, where SQLite reads an unqualified name in the temp schema "
    "first (a temporary table named as an event table would take that type's reads and adds, "
    "lost at close; a temporary trigger would run inside the store's own writes). Create a "
    "table in the store's file instead (write=True), or use a WITH clause")


class SqlGuard:
    """The authorizer callbacks of one connection; ``denied`` is the reason of the last
    refusal (None before any)."""

    def __init__(self) -> None:
        self.denied: str | None = None
        # the tables a statement inserts into or updates, but temporary ones (``writing``)
        self.written: set[str] = set()
        # whether the statement attached a database (``hand_written``)
        self.attached = False

    def begin_statement(self) -> None:
        """Forget what the previous hand-written statement was refused or wrote."""
        self.denied = None
        self.written = set()
        self.attached = False

    def always(self, action: int, arg1: Any, arg2: Any, _db: Any, _trigger: Any) -> int:
        """Every statement: no function of :data:`DENIED_FUNCTIONS`, no pragma of
        :data:`DENIED_PRAGMAS` (refused before SQLite acts on it)."""
        if action == _FUNCTION and isinstance(arg2, str):
            reason = DENIED_FUNCTIONS.get(arg2.lower())
            if reason is not None:
                self.denied = f"{arg2.lower()}() is not allowed ({reason})"
                return _DENY
        elif action == _PRAGMA and isinstance(arg1, str):
            reason = DENIED_PRAGMAS.get(arg1.lower())
            if reason is not None:
                self.denied = f"PRAGMA {arg1.lower()} is not allowed ({reason})"
                return _DENY
        return _OK

    def hand_written(self, action: int, arg1: Any, arg2: Any, db: Any, trigger: Any) -> int:
        """Any statement a user hands the store: :meth:`always`, and no transaction control
        (BEGIN, COMMIT, END, ROLLBACK, SAVEPOINT, RELEASE): it runs on the store's own
        connection, whose transactions the store begins and ends (a BEGIN would leave the
        connection in a transaction the store knows nothing of, a COMMIT or RELEASE would end
        the store's own transaction or level halfway). A VACUUM is no transaction
        control: it compiles to nothing the authorizer hears, and as it runs it attaches
        its target and then begins and ends a transaction of its own, which is let be (a
        statement that attaches is never one that begins a transaction: a BEGIN compiles
        to its transaction action alone)."""
        if action in _ATTACHING:
            self.attached = True
        elif action in _CREATING_TEMP or db == "temp" and (
                action in _CREATING or action == _INSERT and arg1 in _TEMP_SCHEMA_TABLES):
            self.denied = TEMPORARY_OBJECT_REFUSAL
            return _DENY
        elif (action == _TRANSACTION or action == _SAVEPOINT) and not self.attached:
            self.denied = transaction_control_refusal(
                _TRANSACTION_STATEMENTS.get((action, str(arg1).upper()),
                                            "a transaction-control statement"))
            return _DENY
        return self.always(action, arg1, arg2, db, trigger)

    def writing(self, action: int, arg1: Any, arg2: Any, db: Any, trigger: Any) -> int:
        """A hand-written statement that may write: :meth:`hand_written`, no assignment of a
        pragma of :data:`STORE_SETTING_PRAGMAS`, and the tables it inserts
        rows into or updates noted in ``written`` -- by name, whatever database holds them
        but ``temp``: another name ATTACHed to the store's own file writes its tables. SQLite asks
        while it compiles the statement, its triggers' statements included (SQLite codes
        them into it), so what is noted does not depend on how the statement spells a name."""
        if action in _WRITING_ROWS and db != "temp" and isinstance(arg1, str):
            self.written.add(arg1)   # (an attached alias of the store's own file included)
        elif action == _PRAGMA and arg2 is not None and self._store_setting(str(arg1)):
            return _DENY
        return self.hand_written(action, arg1, arg2, db, trigger)

    def _store_setting(self, pragma: str) -> bool:
        """Whether ``pragma``, given an argument, is one of :data:`STORE_SETTING_PRAGMAS`
        (then ``denied`` says why it is refused)."""
        name = pragma.lower()
        reason = STORE_SETTING_PRAGMAS.get(name)
        if reason is None:
            return False
        self.denied = f"PRAGMA {name} with an argument is not allowed ({reason})"
        return True

    def read_only(self, action: int, arg1: Any, arg2: Any, db: Any, trigger: Any) -> int:
        """A read-only statement: :meth:`hand_written`, and no ATTACH, DETACH (nor ``VACUUM
        INTO``, which attaches its target), no pragma assignment, no acting pragma."""
        if action in _ATTACHING:
            self.denied = "read-only: the statement would write a database file (ATTACH, " \
                          "DETACH, VACUUM, VACUUM INTO)"
            return _DENY
        if action == _PRAGMA:
            name = str(arg1).lower()
            if name in DENIED_PRAGMAS:
                return self.always(action, arg1, arg2, db, trigger)
            if arg2 is not None and self._store_setting(name):
                return _DENY   # (not even with write=True: said so)
            if name in ACTING_PRAGMAS or (arg2 is not None and name not in READING_PRAGMAS):
                self.denied = f"read-only: PRAGMA {name} with an argument, or one that acts, " \
                              "would change the store or its settings"
                return _DENY
            return _OK
        return self.hand_written(action, arg1, arg2, db, trigger)


def harden_connection(conn: sqlite3.Connection) -> SqlGuard:
    """Install the store's authorizer on ``conn`` and turn the FTS3 tokenizer switch off;
    returns the guard (whose ``denied`` says why a statement was refused).

    >>> conn = sqlite3.connect(":memory:"); guard = harden_connection(conn)
    >>> conn.execute("SELECT load_extension('evil.so')")
    Traceback (most recent call last):
        ...
    sqlite3.OperationalError: not authorized to use function: load_extension
    >>> guard.denied
    'load_extension() is not allowed (it loads native code into the process)'
    >>> conn.execute("SELECT 1 + 1").fetchall()
    [(2,)]
    """
    guard = SqlGuard()
    conn.set_authorizer(guard.always)
    fts3_tokenizer_switch_off(conn)
    return guard


def fts3_tokenizer_switch_off(conn: sqlite3.Connection) -> bool:
    """Turn ``SQLITE_DBCONFIG_ENABLE_FTS3_TOKENIZER`` off on ``conn`` (the two-argument
    ``fts3_tokenizer()`` then refuses an address written into the statement); True when it
    is off. Python 3.12 has ``Connection.setconfig``; on CPython 3.11 the connection's
    ``sqlite3*`` is read from the object (the first field after the object header) and used
    only after two checks that it is one: its first field is SQLite's default VFS and it
    names the file the connection opened. Elsewhere (or if a check fails) False: the
    authorizer alone refuses the function.

    (SQLite still accepts an address passed as a bound parameter with the switch off, so
    the authorizer is the defence; the switch is the second line.)

    >>> conn = sqlite3.connect(":memory:")
    >>> fts3_tokenizer_switch_off(conn)
    True
    >>> conn.execute("SELECT fts3_tokenizer('simple', zeroblob(8))")
    Traceback (most recent call last):
        ...
    sqlite3.OperationalError: fts3tokenize disabled
    """
    setconfig = getattr(conn, "setconfig", None)
    if setconfig is not None:  # Python >= 3.12
        try:
            setconfig(_FTS3_TOKENIZER_SWITCH, False)
            return not conn.getconfig(_FTS3_TOKENIZER_SWITCH)  # type: ignore[attr-defined]
        except sqlite3.Error:
            return False
    library = _library()
    handle = _connection_handle(conn, library)
    if library is None or handle is None:
        return False
    state = ctypes.c_int(-1)
    rc = library.sqlite3_db_config(ctypes.c_void_p(handle), _FTS3_TOKENIZER_SWITCH,
                                   ctypes.c_int(0), ctypes.byref(state))
    return rc == sqlite3.SQLITE_OK and state.value == 0


_LIBRARY: Any = False  # not looked up yet


def _library() -> Any:
    """The SQLite library the ``_sqlite3`` module uses (its symbols, through the module's
    own handle), or None."""
    global _LIBRARY
    if _LIBRARY is False:
        _LIBRARY = None
        try:
            import _sqlite3

            library = ctypes.CDLL(_sqlite3.__file__)
            library.sqlite3_vfs_find.restype = ctypes.c_void_p
            library.sqlite3_vfs_find.argtypes = [ctypes.c_char_p]
            library.sqlite3_db_filename.restype = ctypes.c_char_p
            library.sqlite3_db_filename.argtypes = [ctypes.c_void_p, ctypes.c_char_p]
            library.sqlite3_db_config.restype = ctypes.c_int
            library.sqlite3_libversion_number.restype = ctypes.c_int
            if library.sqlite3_libversion_number() == sqlite3.sqlite_version_info[0] * 1000000 \
                    + sqlite3.sqlite_version_info[1] * 1000 + sqlite3.sqlite_version_info[2]:
                _LIBRARY = library
        except (ImportError, OSError, AttributeError):
            pass
    return _LIBRARY


def _connection_handle(conn: sqlite3.Connection, library: Any) -> int | None:
    """The ``sqlite3*`` of ``conn`` on CPython 3.11 (release build), checked, or None."""
    if library is None or sys.implementation.name != "cpython" \
            or sys.version_info[:2] != (3, 11) or hasattr(sys, "getobjects") \
            or not isinstance(conn, sqlite3.Connection):
        return None
    pointer = ctypes.sizeof(ctypes.c_void_p)
    handle = ctypes.c_void_p.from_address(id(conn) + 2 * pointer).value  # after ob_refcnt, ob_type
    if not handle or handle % pointer:
        return None
    if ctypes.c_void_p.from_address(handle).value != library.sqlite3_vfs_find(None):
        return None  # not an sqlite3 struct (whose first field is its VFS)
    try:
        # (the name's bytes: a file name need not be UTF-8, and its text would be no
        # stored text to read tolerantly and warn of)
        opened = fetch_row(conn.execute(
            "SELECT CAST(file AS BLOB) FROM pragma_database_list WHERE name = 'main'"))[0]
    except (sqlite3.Error, TypeError):
        return None
    named = library.sqlite3_db_filename(handle, b"main")
    if (named or b"") != (opened or b""):
        return None
    return handle

