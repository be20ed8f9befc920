r"""Reading text that is no UTF-8 from a SQLite store.

SQLite stores whatever bytes it is given as TEXT: another program (the ``sqlite3`` shell
with ``CAST(x'ff' AS TEXT)``, Python's sqlite3 writing bytes where text was meant) can
leave a value that is no UTF-8. Python's sqlite3 refuses such a value when it reads it
("Could not decode to UTF-8 column ..."), so one bad row made every query, ``sql`` and
``describe`` that read its event type fail. Every connection of the store reads text with
:data:`read_text` instead: valid UTF-8 decoded in C (sqlite3 makes a bytes object of each
text first: docs/printed_text.md gives the cost), each bad byte sequence as U+FFFD, and a
:class:`StoredTextWarning` that gives the bytes and how to find the row
(docs/printed_text.md, "Text that is no UTF-8"). PostgreSQL checks the text it is given,
so a PostgreSQL store cannot hold such a value.

>>> import sqlite3; conn = sqlite3.connect(":memory:"); conn.text_factory = read_text
>>> with warnings.catch_warnings(record=True) as caught:
...     warnings.simplefilter("always")
...     conn.execute("SELECT 'café', CAST(x'677265ff6e' AS TEXT)").fetchone()
('café', 'gre\ufffdn')
>>> [w.category.__name__ for w in caught]
['StoredTextWarning']
"""
from __future__ import annotations

import codecs
import functools
import warnings

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
r"""A SQLite connection's ``text_factory``: ``str(data, "utf-8")`` in C, the handler in
Python only for a text that is no UTF-8 (the module's example)."""
