"""Exceptions, named after the condition they report."""
from __future__ import annotations

import logging
from typing import Any

__all__ = ["SLRError", "SLRSyntaxError", "SLREvaluationError", "SLRTimeout", "SLRUnavailable",
           "SLRBusy", "SLRStoreFull", "SLRStoreGone", "SLRServerUnreachable", "SLRCancelled",
           "SLRStatementTimeout", "EventRejected", "NotAnEvent", "BufferNotFound", "log_failure",
           "naming_the_store", "CLOSED_WHILE_RUNNING", "STOPPED_BY_CALLER"]

# The words of the SLRError a query still running when its knowledge base closes ends with:
# the interpreter's at its next check, a compiled statement's interrupted (SQLite) or
# cancelled (PostgreSQL) by the close
CLOSED_WHILE_RUNNING = "the knowledge base was closed while the query ran"
# ... and the words of one whose consumer stopped it from another thread (Solutions.stop: a
# served query whose client asked to stop or left), at the interpreter's next check
STOPPED_BY_CALLER = "the query was stopped while it looked for its next answer"


class SLRError(Exception):
    """Base class of every error slr_sql raises on purpose.

    ``store_location``: the store's location (its file path, a PostgreSQL URL without its
    password) when the message starts with it, ``store_failure``: True when the store itself
    failed rather than the call (:func:`naming_the_store`).
    """

    store_location: str | None = None
    store_failure = False


def naming_the_store(exc: Any, where: Any, failure: bool = False) -> Any:
    """``exc``, whose message starts with ``where: `` (the store's location: a file path, a
    PostgreSQL URL's host and database), marked so; ``failure``: the store itself failed,
    not the call that met it (its file damaged or unreadable, its database server refusing
    the connection). A client of ``slr serve`` is not told where the server keeps its
    store: the service answers the message without that start, or a failure (and every
    condition that may pass, :class:`SLRUnavailable`) as a 5xx in general words with a
    request id, the message in the server's log.

    >>> e = naming_the_store(SLRError("/srv/robot.db: the file is damaged"), "/srv/robot.db",
    ...                      failure=True)
    >>> e.store_location, e.store_failure
    ('/srv/robot.db', True)
    """
    exc.store_location = str(where)
    exc.store_failure = failure
    return exc


class SLRSyntaxError(SLRError):
    """Program or goal text that does not parse.

    ``str()`` is ``file:line:col: message`` followed by the source line and a caret.

    >>> e = SLRSyntaxError("operator expected", line=1, column=6, source_line="a(1) b.")
    >>> print(e)
    <string>:1:6: operator expected
        a(1) b.
             ^
    """

    def __init__(self, message: str, line: int = 0, column: int = 0,
                 source_line: str = "", filename: str = "<string>"):
        self.message = message
        self.line = line
        self.column = column
        self.source_line = source_line
        self.filename = filename
        super().__init__(self._render())

    def _render(self) -> str:
        head = f"{self.filename}:{self.line}:{self.column}: {self.message}"
        if not self.source_line:
            return head
        caret = " " * (max(self.column, 1) - 1) + "^"
        return f"{head}\n    {self.source_line}\n    {caret}"

    def __str__(self) -> str:
        return self._render()


class SLREvaluationError(SLRError):
    """An ISO error raised while running a goal; ``term`` is the error term (``error(F, C)``)."""

    def __init__(self, term: Any, message: str | None = None):
        self.term = term
        super().__init__(message or f"{term}")


class SLRTimeout(SLRError, TimeoutError):
    """A query ran out of its ``timeout=`` (seconds) or step limit, or a wait for a
    synchronized query's answer (``PendingQuery.result(timeout=)``) ran out. It is also a
    ``TimeoutError`` (so ``concurrent.futures.TimeoutError``), what a Future's ``result``
    raises."""


class SLRUnavailable(SLRError):
    """A condition that may pass: nothing of the failed call was written, and the same call
    may succeed later (the service answers it with 503 and ``Retry-After``).
    ``retry_after`` is a suggested wait in seconds.

    >>> issubclass(SLRBusy, SLRUnavailable), issubclass(SLRStoreFull, SLRUnavailable)
    (True, True)
    """

    retry_after: float = 1


class SLRBusy(SLRUnavailable):
    """The store file stayed locked by another connection (another process, or another
    knowledge base on the same file) for longer than the ``busy_timeout`` given to
    :func:`slr_sql.open`; the message names the file. Nothing of the failed call was
    written: retrying it later is safe.

    >>> issubclass(SLRBusy, SLRError)
    True
    """


class SLRStoreFull(SLRUnavailable):
    """The store could not grow: the disk (or file system quota) is full, or SQLite's size
    limit of the file was reached. Nothing of the failed call was written; the message
    names the file. Retry once space is freed.

    >>> issubclass(SLRStoreFull, SLRError)
    True
    """

    retry_after = 10


class SLRStoreGone(SLRUnavailable):
    """The store's file was deleted, moved or replaced by another file while it was open:
    what this knowledge base would write could never be read by anyone opening the path.
    Raised before a write is acknowledged (nothing of the failed call counts as stored);
    the message names the path. Restore the file, or close and reopen to start a new store.

    >>> issubclass(SLRStoreGone, SLRError)
    True
    """

    retry_after = 10


class SLRServerUnreachable(SLRUnavailable):
    """The database server of a ``postgresql://`` store could not be reached, or dropped the
    connection (a restart, a network outage, an administrator ending the session). The next
    call connects again. A call that failed before its commit wrote nothing; one whose
    connection was lost *during* the commit has an outcome only the server knows, so a
    writer that retries it may store that add twice, never lose it (PostgreSQL's own
    guarantee for a commit without an answer).

    >>> issubclass(SLRServerUnreachable, SLRUnavailable)
    True
    """

    retry_after = 5


class SLRStatementTimeout(SLRTimeout):
    """The database server of a ``postgresql://`` store cancelled a statement at its own
    ``statement_timeout`` setting (one an administrator set for the server, the database
    or the role, or a ``SET`` of the session), not at the call's ``timeout=``: the same
    call would run as long again and meet it again, so it is no condition to retry
    (unlike :class:`SLRCancelled`). A call's own ``timeout=`` replaces the setting for
    that call; otherwise the setting must be raised. The message names the setting and
    quotes the server's words. Nothing of the failed call was written.

    >>> issubclass(SLRStatementTimeout, SLRTimeout), issubclass(SLRStatementTimeout,
    ...                                                         SLRUnavailable)
    (True, False)
    """

    reason = ""   # the server's words (``canceling statement due to statement timeout``)


class SLRCancelled(SLRUnavailable):
    """The database server of a ``postgresql://`` store cancelled a statement for another
    reason than a timeout (the call's own ``timeout=`` is :class:`SLRTimeout`, the server's
    ``statement_timeout`` :class:`SLRStatementTimeout`): another session's
    ``pg_cancel_backend``, an administrator's cancel. The message quotes the server's
    reason. Nothing of the failed call was written (its transaction is rolled back); the
    same call may succeed when retried. (A server that speaks another language than
    English gives its reasons in that language: a cancel at its ``statement_timeout`` is
    then told from another only by the words, and is an SLRCancelled too.)

    >>> issubclass(SLRCancelled, SLRUnavailable), issubclass(SLRCancelled, SLRTimeout)
    (True, False)
    """

    reason = ""   # the server's words (``canceling statement due to user request``)


class SLRSubscriptionInUse(SLRUnavailable):
    """A durable subscription's id is delivered elsewhere now: open in this process, or held
    by another process (whose lease has not run out). It may be opened once that one closes,
    or once a process that died has its lease run out.

    >>> issubclass(SLRSubscriptionInUse, SLRUnavailable)
    True
    """


class NotAnEvent(SLRError):
    """A goal read a stored row that is no event: an argument holds SQL NULL, which no term
    is stored as (a row written by hand, by another client of the database), or a
    hand-written statement (``kb.sql(..., write=True)``) would leave one. The message names
    the type, the row's ``seq`` and the column; the goal gives no answers rather than
    answers without that row, the statement changes nothing.

    >>> issubclass(NotAnEvent, SLRError)
    True
    """


class BufferNotFound(SLRError):
    """No active buffer has the id given to ``remove_buffer``: removed already, or never
    made (``kb.buffers()`` lists the active ones). The same class locally and from
    ``slr_sql.connect``'s client; the service answers it with 404.

    >>> issubclass(BufferNotFound, SLRError), str(BufferNotFound("no active buffer #7"))
    (True, 'no active buffer #7')
    """


class EventRejected(SLRError):
    """An event that cannot be stored (non-ground, NaN, start > end, wrong arity, ...)."""

    # set by whoever rejects an event of a batch: its position in the batch, and the
    # event as (name, args, start, end) (absent otherwise: read them with getattr)
    index: int | None
    event: tuple[Any, ...] | None


def log_failure(logger: logging.Logger, what: str, exc: BaseException, then: str = "") -> None:
    """Log that ``what`` failed with ``exc`` (``then``: what happens next, e.g. "retrying").

    An :class:`SLRError` is an expected failure (the store busy past ``busy_timeout``, its
    disk full, a statement timeout, the store closing or gone): any client can bring it
    about (a long transaction, a flood of events, a dropped connection), and its message
    says what happened, so it is one WARNING line without a traceback, which would only
    bury the lines around it. Anything else is a bug of this package: an ERROR with its
    traceback, which is what whoever fixes it needs.

    >>> import io
    >>> out = io.StringIO(); log = logging.getLogger("slr_sql.example")
    >>> handler = logging.StreamHandler(out); log.addHandler(handler)
    >>> log_failure(log, "a delivery pass", SLRBusy("the store is busy"), "retrying")
    >>> try:
    ...     {}["a bug"]
    ... except KeyError as exc:
    ...     log_failure(log, "housekeeping", exc)
    >>> log.removeHandler(handler); print(out.getvalue())
    a delivery pass failed (SLRBusy: the store is busy); retrying
    housekeeping failed (KeyError: 'a bug')
    Traceback (most recent call last):
    ...
    KeyError: 'a bug'
    """
    tail = f"; {then}" if then else ""
    if isinstance(exc, SLRError):
        logger.warning("%s failed (%s: %s)%s", what, type(exc).__name__, exc, tail)
    else:
        logger.error("%s failed (%s: %s)%s", what, type(exc).__name__, exc, tail,
                     exc_info=exc)
