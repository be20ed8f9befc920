r"""Reading text that is no UTF-8 from a SQLite store.

SQLite stores whatever bytes it is given as TEXT: another program (the ``sqlite3`` shell
with ``CAST(x'ff' AS TEXT)``, Python's sqlite3 writing bytes where text was meant) can
leave a value that is no UTF-8. Python's sqlite3 refuses such a value when it reads it
("Could not decode to UTF-8 column ..."), so one bad row made every query, ``sql`` and
``describe`` that read its event type fail. The store reads every row through
:func:`fetch_rows` (or :func:`fetch_row`): sqlite3's own decoding, in C with no call per
text, and only from a row it cannot decode on the connection's ``text_factory`` set to
:data:`read_text` for the rest of that fetch: each bad byte sequence read as U+FFFD, and a
:class:`StoredTextWarning` that gives the bytes and how to find the row
(docs/printed_text.md, "Text that is no UTF-8"). A text factory on every read cost sqlite3
a bytes object and a call per text cell (docs/printed_text.md gives the figures).
PostgreSQL checks the text it is given, so a PostgreSQL store cannot hold such a value.

>>> import sqlite3; conn = sqlite3.connect(":memory:")
>>> with warnings.catch_warnings(record=True) as caught:
...     warnings.simplefilter("always")
...     fetch_rows(conn.execute("SELECT 'café' UNION ALL SELECT CAST(x'677265ff6e' AS TEXT)"))
[('café',), ('gre\ufffdn',)]
>>> [w.category.__name__ for w in caught], conn.text_factory is str
(['StoredTextWarning'], True)
"""
from __future__ import annotations

import codecs
import functools
import sqlite3
import warnings
from itertools import islice
from typing import Any

from ..printable import log_text

ERRORS = "slr-sql-stored-text"
"""The name of the decoding error handler :data:`read_text` decodes with."""

CONTEXT_BYTES = 16
"""Bytes shown on each side of the first bad byte (a long text is not shown whole)."""


class StoredTextWarning(UserWarning):
    """A text read from the store is no UTF-8 (another program wrote it); it was read with
    U+FFFD in place of each bad byte sequence. The message gives its bytes around the first
    bad one, in hex, and a SQL condition that finds its row."""


def not_utf8_message(data: bytes) -> str:
    r"""What :class:`StoredTextWarning` says of the stored text ``data``.

    >>> print(not_utf8_message(b"gre\xffn"))
    the store holds text that is no UTF-8 (another program wrote it): "gre�n", read with U+FFFD in place of the bad bytes; its row is found with the condition instr(CAST(column AS BLOB), x'677265ff6e') > 0
    >>> print(not_utf8_message(b"\x1b]0;owned\x07\n" + b"x" * 40 + b"\xff"))
    the store holds text that is no UTF-8 (another program wrote it): "...xxxxxxxxxxxxxxxx�", read with U+FFFD in place of the bad bytes; its row is found with the condition instr(CAST(column AS BLOB), x'78787878787878787878787878787878ff') > 0
    >>> print(not_utf8_message(b"\x1b]0;owned\x07\n\xff"))
    the store holds text that is no UTF-8 (another program wrote it): "\x1B\]0;owned\a\n�", read with U+FFFD in place of the bad bytes; its row is found with the condition instr(CAST(column AS BLOB), x'1b5d303b6f776e6564070aff') > 0
    """
    try:
        data.decode("utf-8")
        start = 0
    except UnicodeDecodeError as exc:
        start = exc.start
    # (the window may cut a valid character at its edges: "replace" shows that as U+FFFD
    # too, and the bytes in hex are what the condition matches)
    window = data[max(0, start - CONTEXT_BYTES):start + CONTEXT_BYTES]
    # (a stranger's text: its controls escaped, so the warning cannot move a terminal's
    # cursor or start a log line of its own, wherever it is printed)
    shown = log_text(window.decode("utf-8", "replace"))
    cut = ("..." if start > CONTEXT_BYTES else "",
           "..." if len(data) > start + CONTEXT_BYTES else "")
    return (f"the store holds text that is no UTF-8 (another program wrote it): "
            f"\"{cut[0]}{shown}{cut[1]}\", read with U+FFFD in place of the bad bytes; its "
            f"row is found with the condition instr(CAST(column AS BLOB), x'{window.hex()}') > 0")


def _replace_and_warn(exc: UnicodeError) -> tuple[str, int]:
    if not isinstance(exc, UnicodeDecodeError):
        raise exc
    # one message per text (not per bad sequence in it): warnings shows it once per process
    warnings.warn(StoredTextWarning(not_utf8_message(bytes(exc.object))), stacklevel=2)
    return "\ufffd", exc.end


codecs.register_error(ERRORS, _replace_and_warn)

read_text = functools.partial(str, encoding="utf-8", errors=ERRORS)
r"""The ``text_factory`` :func:`fetch_rows` reads on with once a row held text that is no
UTF-8: ``str(data, "utf-8")`` in C, the handler in Python only for a text that is no UTF-8
(the module's example)."""

NOT_UTF8_ERROR = "Could not decode to UTF-8"
"""How sqlite3's error for a text that is no UTF-8 begins (``OperationalError``)."""


def fetch_rows(cursor: sqlite3.Cursor, limit: int | None = None) -> list[Any]:
    r"""The rows of ``cursor`` still to be read (at most ``limit``), as ``fetchall()`` (or
    ``fetchmany(limit)``) gives them, but a text that is no UTF-8 read with U+FFFD and a
    :class:`StoredTextWarning`: every read of a store connection goes through here (or
    :func:`fetch_row`; tests/test_architecture.py). The statement runs once: nothing is
    run again, so a statement that wrote (``RETURNING``) is not written twice.

    sqlite3 decodes text in C unless the connection has a ``text_factory``, which costs a
    bytes object and a call for every text cell read; so the rows are read without one.
    sqlite3 builds a row before it steps its statement to the next one, so a row it cannot
    decode is still the current one when the error is raised, and the rows before it are
    in ``rows`` (``list.extend`` keeps what it appended when its iterator fails, where
    ``fetchall`` loses them): the rest is read on from that row with :data:`read_text`,
    which is set for that only (the connection's next reads pay nothing).

    >>> import sqlite3; conn = sqlite3.connect(":memory:")
    >>> cursor = conn.execute("SELECT 'a' UNION ALL SELECT CAST(x'ff' AS TEXT) "
    ...                       "UNION ALL SELECT 'c'")
    >>> with warnings.catch_warnings(record=True):
    ...     fetch_rows(cursor, 1), fetch_rows(cursor, 1), fetch_rows(cursor)
    ([('a',)], [('\ufffd',)], [('c',)])
    """
    rows: list[Any] = []
    try:
        rows.extend(cursor if limit is None else islice(cursor, limit))
    except sqlite3.OperationalError as exc:
        if not str(exc).startswith(NOT_UTF8_ERROR):
            raise
        connection = cursor.connection
        factory = connection.text_factory
        connection.text_factory = read_text
        try:
            rows.extend(cursor if limit is None else islice(cursor, limit - len(rows)))
        finally:
            # (the one it had: a fetch nested in this one, by a Python function the
            # statement calls, leaves this one's in force)
            connection.text_factory = factory
    return rows


def fetch_row(cursor: sqlite3.Cursor) -> Any:
    r"""The next row of ``cursor`` (None when there is none), as ``fetchone()`` gives it,
    a text that is no UTF-8 read as :func:`fetch_rows` reads it.

    >>> import sqlite3; conn = sqlite3.connect(":memory:")
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     fetch_row(conn.execute("SELECT 1, CAST(x'61ff' AS TEXT)")), len(caught)
    ((1, 'a\ufffd'), 1)
    >>> fetch_row(conn.execute("SELECT 1 WHERE 0")) is None
    True
    """
    rows = fetch_rows(cursor, 1)
    return rows[0] if rows else None
