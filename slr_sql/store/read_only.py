"""Which statements only read a store: what ``slr serve`` lets a client run with ``/sql``
(the store then runs it read-only as well, ``sql()`` without ``write``: this check gives
the client a clear refusal before the database gives an obscure one).

A statement may start with ``SELECT``, ``WITH``, ``VALUES`` or ``EXPLAIN``; on SQLite also a
``PRAGMA`` from a list of those that only report, on PostgreSQL also ``SHOW`` and ``TABLE``.

>>> read_only_refusal("  -- a comment\\nSELECT 1") is None
True
>>> read_only_refusal("DELETE FROM slr_meta")
'DELETE statements are not allowed (SELECT, WITH, VALUES, EXPLAIN)'
>>> read_only_refusal("PRAGMA journal_mode") is None, read_only_refusal("PRAGMA journal_mode = DELETE")
(True, 'this PRAGMA is not allowed')

On PostgreSQL a function whose effect a read-only transaction does not stop is refused
(ending other sessions, reading the server's files, its configuration, session locks):

>>> read_only_refusal("SELECT pg_terminate_backend(pid) FROM pg_stat_activity", "postgresql")
'pg_terminate_backend() acts beyond reading the store (on other sessions, the server or its files) and is not allowed'
"""
from __future__ import annotations

import re

__all__ = ["read_only_refusal"]

_READ_KEYWORDS = {"select", "with", "values", "explain"}
_READ_KEYWORDS_POSTGRES = _READ_KEYWORDS | {"show", "table"}
_READ_PRAGMAS = {"table_info", "table_xinfo", "table_list", "index_list", "index_info",
                 "index_xinfo", "foreign_key_list", "database_list", "page_count", "page_size",
                 "freelist_count", "user_version", "schema_version", "compile_options",
                 "function_list", "pragma_list", "collation_list", "integrity_check",
                 "quick_check", "journal_mode", "encoding"}
_COMMENTS = re.compile(r"\A(?:\s+|--[^\n]*(?:\n|\Z)|/\*.*?\*/)*", re.S)
# a PRAGMA that reads: its name, optionally one argument in parentheses, nothing after (the
# text comes with its trailing layout and one `;` taken off). No two quantifiers here can
# take the same characters one after the other: the match is linear in the text's length
# (with `\s*` around a class that also takes spaces, a client's 4,000 spaces took 99 s of
# CPU with the GIL held, and 16,000 hours)
_PRAGMA = re.compile(r"pragma\s+(?:main\.)?(\w+)\s*(?:\([\w\"'`\[\].\s]*\))?\Z", re.I)


# PostgreSQL functions whose effect a READ ONLY transaction does not stop, by name: on other
# sessions (ending or cancelling them: every other `slr serve` on the store, any other
# application), on the server (its configuration, logs, WAL, replication, statistics),
# on its files (reading them, listing folders: a superuser role's, or pg_read_server_files'),
# session-level locks and notifications, and text run as a statement (query_to_xml, dblink,
# ts_stat, ts_rewrite),
# which a check of names cannot see into. A client of /sql reads the store; none of these is
# needed for that. Matched as an identifier (any case, quoted or schema-qualified) before
# its opening parenthesis, comments between them included; a name inside a string literal
# is refused too (a refusal too many, never a call let through)
_SERVER_FUNCTIONS = re.compile(
    r"(?<![\w$])(pg_terminate_backend|pg_cancel_backend|pg_reload_conf|pg_rotate_logfile\w*"
    r"|pg_read_file|pg_read_binary_file|pg_ls_\w+|pg_stat_file|pg_file_\w+"
    r"|pg_(?:try_)?advisory\w*|pg_notify|set_config|pg_log_backend_memory_contexts"
    r"|pg_switch_wal|pg_switch_xlog|pg_promote|pg_create_restore_point|pg_backup_\w+"
    r"|pg_start_backup|pg_stop_backup|pg_wal_replay_\w+|pg_xlog_replay_\w+"
    r"|pg_\w*replication_\w+|pg_logical_\w+|pg_replication_origin_\w+"
    r"|pg_stat_reset\w*|pg_import_system_collations|pg_drop_\w+|pg_create_\w+"
    r"|pg_stat_statements_reset|brin_\w+|gin_clean_pending_list"
    r"|query_to_xml\w*|cursor_to_xml\w*|dblink\w*|ts_stat|ts_rewrite|lo_\w+)(?![\w$])\"?",
    re.I)
_SPACES = re.compile(r"\s*")


def _server_function_called(text: str) -> str | None:
    """The first name of :data:`_SERVER_FUNCTIONS` in ``text`` followed by ``(``, with
    layout and comments between them; None if none is. Linear in the text's length: each
    name's scan stops at the first character that is no layout, and the end of a comment
    is looked up once for all the names before it (a client's text of many names each
    opening a comment would otherwise be scanned to its end once per name). A comment that
    never ends after a name, or holds another one (PostgreSQL nests them), is taken as a
    call.

    >>> _server_function_called("SELECT pg_notify /* a */ ('c', 'x')")
    'pg_notify'
    >>> _server_function_called("SELECT pg_notify /* /* */ x */ ('c', 'x')")
    'pg_notify'
    >>> _server_function_called("SELECT 1 AS pg_notify") is None
    True
    """
    comment_end = line_end = -1
    for found in _SERVER_FUNCTIONS.finditer(text):
        at = found.end()
        while True:
            at = _SPACES.match(text, at).end()   # type: ignore[union-attr]
            if text.startswith("/*", at):
                if comment_end < at + 2:
                    comment_end = text.find("*/", at + 2)
                if comment_end < 0 or text.find("/*", at + 2, comment_end) >= 0:
                    return found.group(1)   # (unended, or nested: PostgreSQL nests them)
                at = comment_end + 2
            elif text.startswith("--", at):
                if line_end < at + 2:
                    line_end = text.find("\n", at + 2)
                if line_end < 0:
                    return found.group(1)
                at = line_end + 1
            else:
                break
        if text.startswith("(", at):
            return found.group(1)
    return None


def read_only_refusal(statement: str, dialect: str = "sqlite") -> str | None:
    """None when ``statement`` only reads (judged by its first keyword, comments skipped),
    else why it is refused, in words. ``dialect``: the store's (``"sqlite"`` or
    ``"postgresql"``, :mod:`slr_sql.store.dialect`).

    >>> read_only_refusal("SHOW search_path", "postgresql") is None
    True
    """
    text = statement[_COMMENTS.match(statement).end():]   # type: ignore[union-attr]
    keyword = re.match(r"\w*", text).group(0).lower()     # type: ignore[union-attr]
    if keyword == "pragma" and dialect == "sqlite":
        body = text.rstrip()
        if body.endswith(";"):
            body = body[:-1].rstrip()
        m = _PRAGMA.match(body)
        if m is None or m.group(1).lower() not in _READ_PRAGMAS:
            return "this PRAGMA is not allowed"
        return None
    allowed = _READ_KEYWORDS_POSTGRES if dialect == "postgresql" else _READ_KEYWORDS
    if keyword not in allowed:
        return (f"{keyword.upper() or 'this'} statements are not allowed "
                f"(SELECT, WITH, VALUES, EXPLAIN)")
    if dialect == "postgresql":
        if re.search(r"\bu&['\"]", text, re.I):   # (a name spelled by Unicode escapes)
            return "Unicode-escaped names and strings (U&'...') are not allowed"
        called = _server_function_called(text)
        if called is not None:
            return (f"{called}() acts beyond reading the store (on other sessions, "
                    f"the server or its files) and is not allowed")
    return None
