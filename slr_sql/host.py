"""The host: what the knowledge base offers the parts it attaches (the planner; synchronized
queries, buffers, event rules, subscriptions, a fleet store's receiving end in layer 6).

Each part gets the facade at construction (``sync.attach(kb)``, ``buffers.attach(kb)``, ...)
and calls back through it, never by importing ``kb``. This Protocol names exactly what they
may use, typed, so that a renamed attribute is a type error in the part that uses it and
not an ``AttributeError`` at run time: the store, the clock, the interpreter, the program
in force and its loader, the plan cache, and the listener lists the parts register on.

>>> import slr_sql
>>> kb = slr_sql.open()
>>> isinstance(kb, Host), isinstance(kb.loader, LoadedProgram)
(True, True)
>>> kb.close()
"""
from __future__ import annotations

from typing import Any, Callable, ContextManager, Protocol, runtime_checkable

from .api import PendingQueryAPI
from .clocks import Clock
from .engine import Engine
from .plans import PlanCache
from .program import Declarations, Program
from .store import EventStore

__all__ = ["Host", "LoadedProgram"]


@runtime_checkable
class LoadedProgram(Protocol):
    """The program in force and what it was built from (:class:`slr_sql.loader.ProgramLoader`)."""

    version: int                    # the stored program version it was built from
    load_lock: ContextManager[Any]  # held by a load (and by a part changing derived state)

    @property
    def program(self) -> Program: ...

    @property
    def declarations(self) -> Declarations: ...

    def refresh(self) -> None:
        """See what other connections wrote since the last call (program, progress)."""

    def ensure_current(self) -> bool:
        """Inside a write transaction: re-read the program if another connection changed
        it; True if it did."""


@runtime_checkable
class Host(Protocol):
    """What a knowledge base offers the parts it attaches."""

    store: EventStore
    clock: Clock
    engine: Engine
    plans: PlanCache
    loader: LoadedProgram
    max_learned_delay: float | None
    # state an attached part keeps per knowledge base, under its name (the planner's SQL side)
    attached_state: dict[str, Any]
    # called inside a load's transaction with the host, after the new program is in force
    load_listeners: list[Callable[[Any], None]]
    # called after an add committed, with its events and the complex events it derived
    add_listeners: list[Callable[[list[Any]], None]]
    # called after the program was re-read from the file (another connection loaded)
    reload_listeners: list[Callable[[Any], None]]
    # called when another connection raised learned delays or completeness marks
    progress_listeners: list[Callable[[], None]]

    @property
    def program(self) -> Program: ...

    @property
    def declarations(self) -> Declarations: ...

    @property
    def sql_enabled(self) -> bool: ...

    @property
    def synchronizer(self) -> Any:
        """The synchronizer of waiting queries (``slr_sql.sync``), or None."""

    @property
    def event_rule_engine(self) -> Any:
        """The event rules in force (``slr_sql.cep``), or None."""

    def query(self, goal: str, at: float | None = None, args: dict[str, Any] | None = None,
              timeout: float | None = None, max_steps: int | None = None,
              limit: int | None = None, wait: bool = False,
              robot: str | None = None) -> list[dict[str, Any]]:
        """Answer ``goal`` now (a subscription's ``where`` condition)."""

    def submit(self, goal: str, at: float | None = None, id: str | None = None,
               args: dict[str, Any] | None = None, timeout: float | None = None,
               callback: Callable[[Any], Any] | None = None) -> PendingQueryAPI:
        """A synchronized query (a subscription waiting for completeness)."""
