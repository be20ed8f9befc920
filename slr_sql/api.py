"""One interface for a knowledge base, local or remote: :class:`KnowledgeBaseAPI`.

``slr_sql.open(path)`` gives a :class:`~slr_sql.KnowledgeBase` (the store in this process);
``slr_sql.connect(url)`` gives a client of ``slr serve`` (the store in the server's process).
Both implement :class:`KnowledgeBaseAPI`: the same methods, with the same parameters and
defaults, returning the same Python values and raising the same :class:`~slr_sql.SLRError`
classes, so that code written against the protocol runs on either::

    def colors(kb: slr_sql.KnowledgeBaseAPI) -> list:
        return kb.query("color(O, C)^T")

What only a local knowledge base can do is said by the method: ``define`` (a Python
predicate runs in the process that holds the store) raises an ``SLRError`` on a remote one;
``sql(write=True)`` is refused by the service (it runs read-only SQL only).
tests/test_api_parity.py checks every public method of both against this protocol.

>>> import slr_sql
>>> with slr_sql.open() as kb:
...     isinstance(kb, KnowledgeBaseAPI)
True
"""
from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Protocol, runtime_checkable

from .errors import EventRejected

__all__ = ["KnowledgeBaseAPI", "PendingQueryAPI", "SolutionsAPI", "SubscriptionAPI",
           "ProgramInfo"]


@dataclass(frozen=True)
class ProgramInfo:
    """One named program, as :meth:`KnowledgeBaseAPI.programs` describes it.

    >>> ProgramInfo("tea", "p(1).", 1, ("<string>",), 2.0).filenames
    ('<string>',)
    """

    name: str
    source: str             # its texts, in load order, joined by newlines
    texts: int              # how many texts were loaded under the name
    filenames: tuple        # the file (or "<string>") of each text
    loaded_at: float | None  # store clock time of its latest text


@runtime_checkable
class PendingQueryAPI(Protocol):
    """A synchronized query (``kb.submit``): a ``concurrent.futures.Future`` of the answer
    list. ``result(timeout)`` raises :class:`~slr_sql.SLRTimeout` (in words: what it waits
    for) when the time runs out; ``waiting_for`` lists the conditions it waits for now."""

    id: str | None
    goal: str
    waiting_for: list

    def result(self, timeout: float | None = None) -> list[dict[str, Any]]: ...

    def done(self) -> bool: ...

    def cancel(self) -> bool: ...

    def explain(self) -> str: ...

    def add_done_callback(self, fn: Callable[[Any], Any]) -> None: ...


@runtime_checkable
class SubscriptionAPI(Protocol):
    """A subscription (``kb.subscribe``): ``for answer in sub``, ``sub.get(timeout)``,
    ``sub.close()``; a context manager."""

    id: str | None
    pattern: str

    def get(self, timeout: float | None = None) -> dict | None: ...

    def __iter__(self) -> Iterator[dict[str, Any]]: ...

    def __next__(self) -> dict[str, Any]: ...

    def close(self) -> None: ...

    def __enter__(self) -> Any: ...

    def __exit__(self, exc_type: Any, *rest: Any) -> None: ...


@runtime_checkable
class SolutionsAPI(Protocol):
    """The answers of ``kb.solutions``, one at a time: ``for answer in answers``;
    ``close()`` ends them between two answers, ``stop()`` (from another thread) the search
    for the next one, which then raises an SLRError."""

    def __iter__(self) -> Iterator[dict[str, Any]]: ...

    def __next__(self) -> dict[str, Any]: ...

    def close(self) -> None: ...

    def stop(self) -> None: ...


@runtime_checkable
class KnowledgeBaseAPI(Protocol):
    """What every knowledge base offers, local (``slr_sql.open``) or remote
    (``slr_sql.connect``). See ``docs/api.md`` for each method."""

    # -- lifecycle
    def close(self) -> None: ...

    def __enter__(self) -> Any: ...

    def __exit__(self, *exc: Any) -> None: ...

    # -- programs
    def load(self, text: str, filename: str = "<string>", *, name: str = "main",
             replace: bool = False) -> None: ...

    def load_file(self, path: str | Path, *, name: str = "main",
                  replace: bool = False) -> None: ...

    def unload(self, name: str) -> None: ...

    def programs(self) -> dict[str, ProgramInfo]: ...

    def define(self, name: str, arity: int, fn: Callable) -> None: ...

    def event_rules(self) -> list[dict[str, Any]]: ...

    # -- events
    def add(self, text: str) -> None: ...

    def add_event(self, name: str, args: Iterable[Any], start: float,
                  end: float | None = None) -> None: ...

    def add_many(self, events: Iterable[Any], atomic: bool = False) -> list[EventRejected]: ...

    # -- queries
    def query(self, goal: str, at: float | None = None, args: dict | None = None,
              timeout: float | None = None, max_steps: int | None = None,
              limit: int | None = None, wait: bool = False,
              robot: str | None = None) -> list[dict[str, Any]]: ...

    def solutions(self, goal: str, at: float | None = None, args: dict | None = None,
                  timeout: float | None = None,
                  robot: str | None = None) -> SolutionsAPI: ...

    def goal_warnings(self, goal: str) -> list[str]: ...

    def explain(self, goal: str) -> str: ...

    def submit(self, goal: str, at: float | None = None, id: str | None = None,
               args: dict | None = None, timeout: float | None = None,
               callback: Callable[[Any], Any] | None = None,
               robot: str | None = None) -> PendingQueryAPI: ...

    async def ask(self, goal: str, at: float | None = None, id: str | None = None,
                  args: dict | None = None, timeout: float | None = None,
                  robot: str | None = None) -> list[dict[str, Any]]: ...

    def pending(self) -> list[PendingQueryAPI]: ...

    def mark_complete(self, event_type: str, t: float) -> None: ...

    def complete_until(self, event_type: str) -> float: ...

    # -- histories, SQL, plots
    def add_buffer(self, pattern: str, *, keep_last: int | None = None,
                   keep_seconds: float | None = None,
                   keep_between: tuple[float, float] | None = None) -> int: ...

    def remove_buffer(self, buffer_id: int) -> None: ...

    def buffers(self) -> list: ...

    def sql(self, query: str, params: Iterable[Any] = (), write: bool = False,
            timeout: float | None = None) -> tuple[list[str], list[tuple]]: ...

    def plot(self, types: Iterable[str] | str | None = None, **options: Any) -> Any: ...

    # -- subscriptions
    def subscribe(self, pattern: str, where: str | None = None, since: Any = "now",
                  until: float | None = None, id: str | None = None,
                  callback: Callable[[dict], Any] | None = None, max_queue: int = 10_000,
                  max_lag: int | None = 1_000_000) -> SubscriptionAPI: ...

    def unsubscribe(self, id: str) -> None: ...
