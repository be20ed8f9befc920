r"""Text a stranger controls, made safe to print on a terminal or to write in a log.

Names come from places the user does not control: event type names and argument atoms of a
store, channel and topic names of a bag or an MCAP file, program names, file paths, a
request's fields. A character in them that a terminal does not draw as itself (ESC starting
an escape sequence, CR returning to the start of the line, the C1 controls, a bidi override
such as U+202E reversing what follows) could rewrite the screen or a log line.

The one rule (docs/printed_text.md): a character that
SWI-Prolog's ``writeq`` escapes -- C0 and C1 controls, DEL, format characters (bidi
overrides and isolates, zero-width characters), line and paragraph separators, private-use
and unassigned code points -- is never printed as itself but as writeq's escape (``\x1B\``,
``\r``, ``\x202E\``).

* :func:`printable_name`: a name holding such a character is printed as writeq prints the
  atom, quoted (``'ev\x1B\[31m'``), so that it reads back as the same atom; any other name is
  printed as it is.
* :func:`printable_text`: a message or a program's text gets the escapes in place, its
  line breaks and tabs kept (they move the cursor only where a reader expects).
* :func:`log_text`: one log line: line breaks escaped too, and cut to :data:`LOG_TEXT_LIMIT`
  characters.

>>> printable_name("cup1"), printable_name("ev\x1b[31mil"), printable_name("r1\u202eevil")
('cup1', "'ev\\x1B\\[31mil'", "'r1\\x202E\\evil'")
>>> print(printable_text("no such file: a\rb\nnext line"))
no such file: a\rb
next line
"""
from __future__ import annotations

import math
from typing import Any

from .errors import SLRSyntaxError
from .terms import char_escape, quoted_text, undrawn_character

__all__ = ["printable_name", "printable_text", "printable_syntax_error", "log_text",
           "LOG_TEXT_LIMIT", "shorten", "shown"]

LOG_TEXT_LIMIT = 200   # characters of stranger-supplied text in one log line


def _has_undrawn(text: str) -> bool:
    if text.isascii() and text.isprintable():   # (the common case, without the large regex)
        return False
    return undrawn_character().search(text) is not None


def _escape_undrawn(text: str, keep: str = "") -> str:
    if not _has_undrawn(text):
        return text
    undrawn = undrawn_character()
    return "".join(ch if ch in keep or not undrawn.match(ch) else char_escape(ch) for ch in text)


def printable_name(name: Any) -> str:
    r"""``name`` as it is when a terminal draws each of its characters, else quoted and
    escaped as SWI-Prolog's ``writeq`` prints the atom.

    >>> printable_name("/camera/image"), printable_name("a\nb"), printable_name("caf\u00e9")
    ('/camera/image', "'a\\nb'", 'café')
    """
    name = str(name)
    return quoted_text(name, "'") if _has_undrawn(name) else name


def printable_text(text: Any) -> str:
    r"""``text`` with each character a terminal does not draw as itself written as writeq's
    escape, its line breaks and tabs kept: for messages and program text.

    >>> printable_text("unknown event type: x\x1b]0;owned\x07")
    'unknown event type: x\\x1B\\]0;owned\\a'
    """
    return _escape_undrawn(str(text), keep="\n\t")


def printable_syntax_error(exc: SLRSyntaxError) -> str:
    r"""A syntax error as the CLI prints it (``file:line:col: message``, the line, a caret),
    the line's characters escaped as :func:`printable_text` does (a tab too: the caret
    counts characters) and the caret still under the column it points at.

    >>> print(printable_syntax_error(SLRSyntaxError("operator expected", 1, 4, "a\rb c")))
    <string>:1:4: operator expected
        a\rb c
            ^
    """
    head = printable_text(f"{exc.filename}:{exc.line}:{exc.column}: {exc.message}")
    if not exc.source_line:
        return head
    before = _escape_undrawn(exc.source_line[:max(exc.column, 1) - 1])
    return (f"{head}\n    {_escape_undrawn(exc.source_line)}\n"
            f"    {' ' * len(before)}^")


def log_text(value: Any, limit: int = LOG_TEXT_LIMIT) -> str:
    r"""``value`` (its ``str``; an exception: its type and message) on one log line: every
    character a terminal does not draw escaped as in :func:`printable_text`, line breaks
    included, and cut after ``limit`` characters, the count of those left out said.

    >>> log_text("bad\ninput")
    'bad\\ninput'
    >>> log_text(ValueError("x" * 300), limit=20)
    'ValueError: xxxxxxxx... (292 more characters)'
    """
    if isinstance(value, BaseException):
        message = str(value)
        value = type(value).__name__ + (f": {message}" if message else "")
    text = _escape_undrawn(str(value))
    if len(text) > limit:
        return f"{text[:limit]}... ({len(text) - limit} more characters)"
    return text


def shorten(text: str, limit: int = 80) -> str:
    """``text`` cut to about ``limit`` characters for a message (a 10 MB argument must not
    make a 10 MB error).

    >>> shorten("x" * 100, 10)
    'xxxxxxxxxx... (100 characters)'
    """
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def shown(value: Any, limit: int = 80) -> str:
    """``repr(value)`` for a message, cut to about ``limit`` characters, and never an error:
    an integer of more digits than Python prints (10**5000) is described by its size.

    >>> shown(10 ** 5000), shown(("p", 10 ** 5000))
    ('an integer of about 5001 digits', 'a tuple holding an integer too long to print')
    """
    if type(value) is int and value.bit_length() > 14000:
        return f"an integer of about {int(value.bit_length() * math.log10(2)) + 1} digits"
    try:
        return shorten(repr(value), limit)
    except ValueError:  # an integer inside with more digits than Python converts
        return f"a {type(value).__name__} holding an integer too long to print"
    except Exception:  # noqa: BLE001 - a value whose repr fails says only its type
        return f"a {type(value).__name__}"
