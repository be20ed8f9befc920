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
    return None
