"""The public knowledge-base API (docs/api.md): open, load, add, query, explain.

>>> import slr_sql
>>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
>>> kb.load("color(O,C)^T :- prev(obj(O,_,C)^Z, T).")
>>> kb.add("obj(cup1, cup, red)^2.0")
>>> kb.query("color(cup1, C)^5")
[{'C': Atom('red')}]
>>> kb.close()
"""
from __future__ import annotations

import functools
import inspect
import numbers
import os
import threading
import time
from operator import itemgetter
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from .answers import answer_bindings
from .arguments import (ListenerList, check_callable, check_flag, check_option_names,
                        check_time_option)
from .api import PendingQueryAPI, ProgramInfo, SolutionsAPI, SubscriptionAPI
from .clocks import DEFAULT_MAX_LEARNED_DELAY, Clock, WallClock, parse_duration
from .engine import Engine
from .encoding import NullArgument, event_form_loop
from .errors import (STOPPED_BY_CALLER, BufferNotFound, EventRejected, NotAnEvent, SLRError,
                     SLRUnavailable)
from .parser import parse_event_fast, parse_indicator, parse_program, parse_term
from .loader import ProgramLoader
from .lockorder import held_here
from .plans import PlanCache, argument_term, check_goal, instantiate
from .plans import python_words as _python_words
from .sql_functions import SQL_FUNCTIONS
from .program import BufferDecl, Declarations, Program, split_event_atom, event_key
from .store import CACHE_SIZE_KIB, DEFAULT_BUSY_TIMEOUT, DatabaseError, EventBatch, EventStore, \
    store_error, check_robot_name, null_argument_text
from .store.checks import event_arguments, shorten, shown, text_problem
from .store.connection import ChangedMeanwhile
from .terms import Atom, String, Struct, Var, deref
from .terms import format_atom, format_term

__all__ = ["KnowledgeBase", "open", "Declarations", "BufferDecl", "ProgramInfo", "Solutions",
           "check_time_option", "parse_duration"]


_TUPLE = frozenset({tuple})
_ARGS = frozenset({tuple, list})
_FOUR = {4}
_first, _second, _fourth = itemgetter(0), itemgetter(1), itemgetter(3)


def _event_tuples(events: list) -> str | None:
    """"tuples" if every item is a ``(name, args, start, end)`` tuple whose ``args`` is a
    tuple: such a batch needs no preparing; "lists" if some ``args`` are lists instead (what
    decoded messages and most robot code give): they need only to become tuples; None
    otherwise (checked in one pass of the C loop ``event_form_loop``, or a column at a time
    by :func:`_event_form_by_columns`, which answers the same)."""
    if event_form_loop is not None:
        return event_form_loop(events)
    return _event_form_by_columns(events)


def _event_form_by_columns(events: list) -> str | None:
    """:func:`_event_tuples` without the C loops: a column at a time, at C speed."""
    try:
        if not (_TUPLE.issuperset(map(type, events)) and set(map(len, events)) == _FOUR):
            return None
        kinds = set(map(type, map(_second, events)))
    except TypeError:
        return None
    return "tuples" if _TUPLE.issuperset(kinds) else "lists" if _ARGS.issuperset(kinds) else None


def _is_time_expression(t: Any) -> bool:
    """True if ``t`` may be evaluated as an event time: no string and no list in it."""
    stack = [t]
    while stack:
        x = deref(stack.pop())
        if type(x) is String or (type(x) is Atom and x == "[]"):
            return False
        if type(x) is Struct:
            if x.name == "." and len(x.args) == 2:
                return False
            stack.extend(x.args)
    return True


def check_define(name: Any, arity: Any, fn: Any) -> None:
    """The arguments of ``define``: a predicate's name (a str), its arity (a count) and
    the Python function, else an :class:`SLRError` (the client of ``slr serve`` checks
    them too before it refuses ``define``).

    >>> check_define("double", 2, abs)
    >>> check_define("double", "2", abs)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: define: arity must be a count (an integer >= 0), not '2'
    """
    if not isinstance(name, str):
        raise SLRError(f"define: the predicate's name is a str (an atom), not {shown(name)}")
    # (any integer: a subclass of int, a NumPy integer -- define always took them)
    if isinstance(arity, bool) or not isinstance(arity, numbers.Integral) or arity < 0:
        raise SLRError(f"define: arity must be a count (an integer >= 0), not {shown(arity)}")
    check_callable("define: fn", fn)


def check_open_options(path: Any, clock: Any, adopt: Any) -> None:
    """The ``path``, ``clock`` and ``adopt`` of ``open``, else an :class:`SLRError` (the
    store checks its own options: ``busy_timeout``, ``cache_mib``, ...).

    >>> check_open_options("robot.db", None, False)
    >>> check_open_options(5, None, False)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: open: path must be a file's path (a str or a pathlib.Path), a PostgreSQL URL or None, not 5
    """
    if path is not None and not isinstance(path, (str, os.PathLike)):
        raise SLRError(f"open: path must be a file's path (a str or a pathlib.Path), a "
                       f"PostgreSQL URL or None, not {shown(path)}")
    if clock is not None and not callable(getattr(clock, "now", None)):
        raise SLRError(f"open: clock must be a clock (slr_sql.WallClock, ManualClock or "
                       f"StreamClock: an object with now()), not {shown(clock)}")
    check_flag("open: adopt", adopt)


def check_program_name(name: Any) -> str:
    """``name`` if it can name a program, else an :class:`SLRError` saying why. One of the
    checks of a method's arguments that a local knowledge base and ``slr_sql.connect``'s
    client both run (the client before sending): the same condition, the same words.

    >>> check_program_name("tea")
    'tea'
    >>> check_program_name(5)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: a program name is a non-empty string, not 5
    """
    if not isinstance(name, str) or not name:
        raise SLRError(f"a program name is a non-empty string, not {shown(name)}")
    problem = text_problem(name)
    if problem:
        raise SLRError(f"the program name {shown(name)} cannot be stored: {problem}")
    return name




# why a call that changes the program (or its buffers) is refused inside a transaction
_LOAD_LOCK_FIRST = ("it takes the program's lock, which comes before the store's; call it "
                    "before the transaction or after it (nothing was changed)")


class KnowledgeBase:
    """One SLR knowledge base: program + events + state in one SQLite file.

    Use :func:`slr_sql.open` to get one.
    """

    def __init__(self, path: str | Path | None = None, clock: Clock | None = None, *,
                 synchronous: str = "FULL", busy_timeout: float = DEFAULT_BUSY_TIMEOUT,
                 adopt: bool = False, checkpoint: str = "auto",
                 cache_mib: float = CACHE_SIZE_KIB / 1024, robot: str | None = None,
                 max_learned_delay: float | None = DEFAULT_MAX_LEARNED_DELAY):
        check_open_options(path, clock, adopt)
        if max_learned_delay is not None:
            check_time_option("max_learned_delay", max_learned_delay, minimum=0.0)
            max_learned_delay = float(max_learned_delay)
        # the largest delay a type may learn (clocks.DEFAULT_MAX_LEARNED_DELAY; None: no cap)
        self.max_learned_delay = max_learned_delay
        self.clock = clock if clock is not None else WallClock()
        self.store = EventStore(path, self.clock, synchronous=synchronous,
                                busy_timeout=busy_timeout, adopt=adopt, checkpoint=checkpoint,
                                cache_mib=cache_mib, robot=robot)
        # the Python functions compiled statements call, on every connection of the store
        self.store.install_functions(SQL_FUNCTIONS)
        self.path = self.store.path
        self.engine = Engine(Program(), self.store)
        # the parsed, compiled goals (slr_sql/plans.py); a load or define clears them
        self.plans = PlanCache()
        # state the attached parts keep per knowledge base, under their names (host.Host)
        self.attached_state: dict[str, Any] = {}
        self._cached_plan = self.plans.entries.get
        # the stored (program, progress) versions a bound prev lookup last read with its rows:
        # while they stay the same, no other connection changed what a refresh re-reads
        self._lookup_versions: tuple | None = None
        # extension points for the SQL compiler, buffers and synchronization
        # (each a ListenerList: what is no callable is refused as it is added, not when an
        # add, a load or a refresh calls it and fails there)
        self.load_listeners: list[Callable[["KnowledgeBase"], None]] = \
            ListenerList("kb.load_listeners")
        # outside observers of stored events: the last stage of the event pipeline calls
        # them with each batch (the parts below are stages of the pipeline, not listeners)
        self.add_listeners: list[Callable[[list], None]] = ListenerList("kb.add_listeners")
        # called after the program was re-read from the file (another connection changed
        # it): like load_listeners, but nothing is written (the writer did that)
        self.reload_listeners: list[Callable[["KnowledgeBase"], None]] = \
            ListenerList("kb.reload_listeners")
        # called when another connection raised learned delays or completeness marks
        self.progress_listeners: list[Callable[[], None]] = \
            ListenerList("kb.progress_listeners")
        # the program in force, built from the stored texts and kept current (slr_sql/loader.py)
        self.loader = ProgramLoader(self)
        self._refresh = self.loader.refresh
        self.loader.reload()
        from . import buffers as _buffers  # event-history management
        self._buffers = _buffers.attach(self)
        from . import sync as _sync  # synchronized queries: slr_sql/sync.py
        self._sync = _sync.attach(self)
        self._buffers.follow_clock()   # (after the synchronizer: buffers prune after decisions)
        from . import planner as _planner  # SQL compiler: slr_sql/planner.py
        _planner.attach(self)
        from . import cep as _cep  # event rules: slr_sql/cep/
        self._cep = _cep.attach(self)
        from . import subscriptions as _subscriptions  # subscriptions
        self._subscriptions = _subscriptions.attach(self)
        from .pipeline import EventPipeline  # the stages of adds, marks and progress
        self._pipeline = EventPipeline(self.store, self._sync, self._cep, self._buffers,
                                       self._subscriptions, self.add_listeners)
        self._pipeline.progress()  # decisions that became possible while the file was closed

    @property
    def sql_enabled(self) -> bool:
        """False: every query, and every goal inside one, runs in the interpreter (the
        differential tests compare the two engines this way)."""
        return self.engine.use_sql

    @sql_enabled.setter
    def sql_enabled(self, value: bool) -> None:
        self.engine.use_sql = bool(value)

    @property
    def program(self) -> Program:
        """The program in force (every named program stored in the file, in load order)."""
        return self.loader.program

    @property
    def synchronizer(self) -> Any:
        """The synchronizer of waiting queries (:class:`slr_sql.sync.Synchronizer`; None
        while the knowledge base is being built): a process that waits on what others write
        calls its ``watch_external()``."""
        return getattr(self, "_sync", None)

    @property
    def event_rule_engine(self) -> Any:
        """The event rules in force (:class:`slr_sql.cep.EventRules`; None while the
        knowledge base is being built): a fleet store runs them over shipped events."""
        return getattr(self, "_cep", None)

    @property
    def declarations(self) -> Declarations:
        """What the program in force declares beyond clauses (event types, delays, buffers,
        event rules, consumption policies)."""
        return self.loader.declarations

    # -- lifecycle ----------------------------------------------------------------------
    def close(self) -> None:
        """Close the store. It never waits for another process (the checkpoint of the WAL
        on close is ``PASSIVE``: what a reader still needs stays in the WAL). A query that
        another thread still evaluates ends at its next check (every 2,048 inference
        steps), and a statement of a compiled query at once (interrupted on SQLite,
        cancelled on PostgreSQL), with SLRError "the knowledge base was closed while the
        query ran". A transaction still running is waited for, what it evaluates included
        (an add, and the event rules' ``where`` goals deciding in it).

        Refused inside a transaction of the store this thread holds (``with
        kb.store.transaction():``): closing waits for the synchronizer and the
        subscriptions, whose locks come before the store's, so it could wait for ever on a
        thread that holds one of them and waits for the store. End the transaction first.

        >>> kb = open(); kb.close(); kb.query("true")
        Traceback (most recent call last):
        slr_sql.errors.SLRError: the event store is closed
        """
        if getattr(self, "store", None) is not None:
            self._refuse_inside_transaction(
                "kb.close()", "closing takes the synchronizer's lock, which comes before the "
                "store's; end the transaction first")
        if getattr(self, "engine", None) is not None:   # queries still running end
            self.engine.stopped = True
        if getattr(self, "store", None) is not None:
            # (before the parts close: their closing may wait for the store's lock, which a
            # query's statement holds while it runs)
            self.store.stop_queries()
        if getattr(self, "_subscriptions", None) is not None:  # positions, threads
            self._subscriptions.close()
        if getattr(self, "_cep", None) is not None:
            self._cep.close()
        if getattr(self, "_sync", None) is not None:  # fail waiting queries, stop threads
            self._sync.close()
        self.store.close()

    def __enter__(self) -> "KnowledgeBase":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def _refuse_inside_transaction(self, call: str, why: str, lock: Any = None) -> None:
        """Refuse ``call`` when the calling thread holds a transaction of the store: it
        would take a lock ordered before the store's (docs/architecture.md, "Locks") and
        could wait for ever on a thread taking them in order. Nothing was done yet. A
        thread that holds ``lock`` already (a load listener, inside a load, holds the
        program's) takes it again, re-entrant, out of no order: not refused.

        >>> kb = open()
        >>> with kb.store.transaction():
        ...     kb._refuse_inside_transaction("kb.close()", "end the transaction first")
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: kb.close() inside a transaction of the store: end the transaction first
        >>> kb.close()
        """
        if self.store.in_transaction_here and not (lock is not None and held_here(lock)):
            raise SLRError(f"{call} inside a transaction of the store: {why}")

    # -- the file is the truth ----------------------------------------------------------
    # -- program ------------------------------------------------------------------------
    def load(self, text: str, filename: str = "<string>", *, name: str = "main",
             replace: bool = False) -> None:
        """Add the clauses and declarations of ``text`` to the program ``name`` (persisted);
        with ``replace=True`` the program ``name`` becomes ``text`` alone, in its place.

        All or nothing: a text with any error is rejected whole and the program stays as it
        was. The program a knowledge base runs is every named program stored in the file,
        in load order, whoever loaded them (another process included).

        >>> kb = open(); kb.load("p(1). p(2)."); [a["X"] for a in kb.query("p(X)")]
        [1, 2]
        >>> kb.load("p(3).", name="main", replace=True); [a["X"] for a in kb.query("p(X)")]
        [3]

        Refused inside a transaction of the store (``with kb.store.transaction():``): a
        load takes the program's lock, which comes before the store's. Load before the
        transaction or after it.
        """
        self._refuse_inside_transaction("kb.load()", _LOAD_LOCK_FIRST,
                                       self.loader.load_lock)
        name = check_load(text, filename, name, replace)
        clauses = parse_program(text, filename)   # syntax errors before taking the lock
        if not self.store.dialect.text_holds_nul:
            for what, value in (("program text", text), ("filename", filename),
                                ("program name", name)):
                if "\x00" in value:
                    raise SLRError(
                        f"load: a PostgreSQL store cannot hold the character U+0000 in a "
                        f"{what} (at offset {value.index(chr(0))}); in a quoted atom or "
                        f"string write it as \\x0\\")
        self.loader.load(name, text, filename, clauses, replace)
        self._pipeline.loaded()

    def unload(self, name: str) -> None:
        """Remove the program ``name`` (its clauses, declarations and buffers; the events
        stay). An error if no program has that name.

        >>> kb = open(); kb.load("p(1).", name="tea"); kb.unload("tea"); kb.programs()
        {}

        Refused inside a transaction of the store, as :meth:`load` is.
        """
        self._refuse_inside_transaction("kb.unload()", _LOAD_LOCK_FIRST,
                                       self.loader.load_lock)
        name = check_program_name(name)
        self.loader.unload(name)
        self._pipeline.loaded()

    def programs(self) -> dict[str, ProgramInfo]:
        """The named programs stored in the file, in load order of their first text.

        >>> kb = open(); kb.load("p(1).", name="tea"); kb.programs()["tea"].source
        'p(1).'
        """
        self._refresh()
        out: dict[str, ProgramInfo] = {}
        for text in self.store.program_texts():
            info = out.get(text.name)
            if info is None:
                out[text.name] = ProgramInfo(text.name, text.source, 1,
                                             (text.filename or "<string>",), text.loaded_at)
            else:
                out[text.name] = ProgramInfo(
                    text.name, info.source + "\n" + text.source, info.texts + 1,
                    info.filenames + (text.filename or "<string>",), text.loaded_at)
        return out

    def load_file(self, path: str | Path, *, name: str = "main", replace: bool = False) -> None:
        """Load a program file (see :meth:`load`).

        >>> import pathlib, tempfile
        >>> rules = pathlib.Path(tempfile.mkdtemp()) / "rules.slr"
        >>> _ = rules.write_text("big(X) :- size(X, S)^_, S > 2.")
        >>> from slr_sql import StreamClock
        >>> kb = open(clock=StreamClock()); kb.load_file(rules); kb.add("size(box, 3)^1")
        >>> kb.query("big(X)")
        [{'X': Atom('box')}]
        >>> kb.close()
        """
        self._refuse_inside_transaction("kb.load_file()", _LOAD_LOCK_FIRST,
                                       self.loader.load_lock)
        self.load(read_program_file(path), str(path), name=name, replace=replace)

    def define(self, name: str, arity: int, fn: Callable) -> None:
        """Register a Python predicate ``name/arity``.

        ``fn`` receives the arguments as Python values (unbound ones as :class:`Var`) and
        returns True/False/None, a tuple with one value per argument, or ``{position: value}``.

        >>> kb = open(); kb.define("double", 2, lambda x, y: (x, 2 * x))
        >>> kb.query("double(21, Y)")
        [{'Y': 42}]
        """
        check_define(name, arity, fn)
        self.engine.python_preds[(name, int(arity))] = fn
        self.plans.clear()

    # -- events -------------------------------------------------------------------------
    def _event_from_text(self, text: str) -> tuple:
        fast = parse_event_fast(text)   # the common shape, ~10x faster than the parser
        if fast is not None:
            return fast
        term, _ = parse_term(text, "<event>")
        ev = split_event_atom(term)
        if ev is None:
            raise EventRejected(f"{text.strip()}: an event must be written p(...)^T or "
                                f"p(...)^[Start,End]")
        atom, s, e = ev
        name, _n = event_key(atom)
        args = tuple(atom.args) if type(atom) is Struct else ()
        return (name, args, self._time(s, text), self._time(e, text))

    @staticmethod
    def _time(t: Any, text: str) -> Any:
        from .arith import evaluate

        t = deref(t)
        if type(t) is Var:
            raise EventRejected(f"{text.strip()}: the event time must be bound")
        # An arithmetic expression is evaluated; a string or a list is not a time (evaluated,
        # "1" would be its character code, 49).
        if type(t) not in (int, float) and not _is_time_expression(t):
            raise EventRejected(f"{text.strip()}: the event time must be a number, "
                                f"not {format_term(t)}")
        try:
            return float(t if type(t) in (int, float) else evaluate(t))
        except SLRError:
            raise EventRejected(f"{text.strip()}: the event time must be a number, "
                                f"not {format_term(t)}") from None
        except OverflowError:  # an integer beyond floats: 2**2000
            raise EventRejected(f"{text.strip()}: event times must be finite") from None

    def add(self, text: str) -> None:
        """Add one event written in SLR syntax (``p(..)^T`` or ``p(..)^[S,E]``).

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0))
        >>> kb.add("seg(cup1, [0.4,0.1,0.9])^12.31"); len(kb.query("seg(O,L)^T"))
        1
        """
        if not isinstance(text, str):
            raise not_event_text(text)
        try:
            event = self._event_from_text(text)
        except (ValueError, OverflowError) as exc:  # a number too long for Python to read
            raise EventRejected(f"{shorten(text)}: {_python_words(exc)}") from None
        self._add([event], atomic=True)

    def add_event(self, name: str, args: Iterable[Any], start: float, end: float | None = None) -> None:
        """Add one event from Python values (``str`` is an atom, ``String`` a string).

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0))
        >>> kb.add_event("seg", ["cup1", [0.4, 0.1, 0.9]], start=2.0, end=2.0)
        """
        if end is None:
            end = start
        if not isinstance(name, str):
            raise EventRejected(f"add_event: event name must be an atom (a str), not "
                                f"{shown(name)}")
        self._add([(name, event_arguments(name, args, start, end), start, end)], atomic=True)

    def add_many(self, events: Iterable[Any], atomic: bool = False) -> list[EventRejected]:
        """Add many events in one transaction: strings in SLR syntax or
        ``(name, args, start, end)`` tuples. Returns the rejected events (each with its reason);
        the others are stored; each rejection's ``.index`` and ``.event`` are the position
        and the item in ``events``. With ``atomic=True`` one bad event rejects the whole batch.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.add_many(["p(1)^1", ("p", [2], 2.0, 2.0)])
        []
        """
        check_flag("add_many: atomic", atomic)
        if type(events) is not list:
            try:
                iterator = iter(events)
            except TypeError:
                raise SLRError(f"add_many takes an iterable of events (SLR text or (name, args, "
                               f"start, end) tuples), not {shown(events)}") from None
            events = list(iterator)
        errors: list[EventRejected] = []
        form = _event_tuples(events)
        if form == "tuples":  # the common bulk case: handed to the store as they are
            # (a copy: listeners must not see the caller's list)
            prepared, positions = EventBatch(events), None
        elif form == "lists":
            prepared = EventBatch([(name, args if type(args) is tuple else tuple(args), start, end)
                                   for name, args, start, end in events])
            positions = None
        else:
            prepared, positions = self._prepare_events(events, atomic, errors)
        stored_errors = self._add(prepared, atomic=atomic)
        if stored_errors:
            # the store's and the marks' rejections carry the prepared event: give them the
            # index and the item the caller passed (events rejected while being prepared are
            # not in ``prepared``)
            place: dict[int, list[int]] = {}  # (one tuple object may be given twice)
            for k, event in enumerate(prepared):
                place.setdefault(id(event), []).append(k)
            for err in stored_errors:
                ks = place.get(id(getattr(err, "event", None)))
                k = ks.pop(0) if ks else None
                if k is not None:
                    err.index = k if positions is None else positions[k]
                    err.event = events[err.index]
                errors.append(err)
            errors.sort(key=lambda e: e.index if isinstance(e.index, int) else -1)
        return errors

    def _prepare_events(self, events: list, atomic: bool,
                        errors: list[EventRejected]) -> tuple[list, list[int]]:
        """``(name, args tuple, start, end)`` for each event of ``events`` (text parsed),
        with the index in ``events`` of each; the events that cannot be read go to
        ``errors`` (raised when ``atomic``)."""
        prepared: list = EventBatch()  # (what _add hands to the store)
        positions: list[int] = []
        for i, ev in enumerate(events):
            try:
                if isinstance(ev, str):
                    event = self._event_from_text(ev)
                else:
                    try:
                        name, args, start, end = ev
                    except (TypeError, ValueError):
                        raise EventRejected(f"event #{i} is neither SLR text nor a (name, args, "
                                            f"start, end) tuple: {shown(ev)}") from None
                    event = (name, event_arguments(name, args, start, end), start, end)
            except (SLRError, TypeError, ValueError, OverflowError, RecursionError) as exc:
                if atomic:
                    raise exc if isinstance(exc, SLRError) else \
                        EventRejected(f"{shown(ev)}: {_python_words(exc)}")
                reason = "the term is nested too deeply" if isinstance(exc, RecursionError) \
                    else _python_words(exc)
                err = exc if isinstance(exc, EventRejected) else \
                    EventRejected(f"{shown(ev)}: {reason}")
                err.index = i
                err.event = ev
                errors.append(err)
                continue
            positions.append(i)
            prepared.append(event)
        return prepared, positions

    def _add(self, events: list, atomic: bool) -> list[EventRejected]:
        loader = self.loader
        owed = loader.owe_check()
        if owed is None:   # (checked now: SQLite, memory, a caller's transaction)
            return self._pipeline.add(events, atomic)
        # a server: the change check goes with the add's first statement; when it finds the
        # program changed meanwhile, nothing was stored, and the add is made again on the
        # program read now
        try:
            return self._pipeline.add(events, atomic, lambda: loader.settle_check(owed))
        except ChangedMeanwhile:
            loader.forget_check(owed)
        except BaseException:
            loader.forget_check(owed)   # (the next call checks again)
            raise
        self._refresh()
        return self._pipeline.add(events, atomic)

    # -- queries ------------------------------------------------------------------------
    def query(self, goal: str, at: float | None = None, args: dict | None = None,
              timeout: float | None = None, max_steps: int | None = None,
              limit: int | None = None, wait: bool = False,
              robot: str | None = None) -> list[dict[str, Any]]:
        """Answer ``goal`` now, on the events that have arrived (unsynchronized).

        ``at`` restricts event goals to the stream view (events with end <= at); ``args``
        binds goal variables from Python values (no text splicing; the parsed plan is reused);
        ``timeout`` (seconds) or ``max_steps`` stop an endless computation with SLRTimeout.
        ``wait=True`` makes it synchronized: ``submit(goal, at, timeout=timeout).result()``.
        ``robot`` restricts every event goal, prev and next (in rules too) to the events of
        that robot (their ``robot`` column; see docs/fleet.md).

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.add_many(["pos(a, 1)^1", "pos(a, 4)^5"])
        []
        >>> kb.query("prev(pos(a, X)^T, 4)")
        [{'X': 1, 'T': 1.0}]
        """
        if limit is not None or at is not None or timeout is not None or robot is not None \
                or max_steps is not None or (args is not None and type(args) is not dict) \
                or wait is not False:
            # (the common query gives none of them: no call on its path)
            check_query_options(at=at, timeout=timeout, limit=limit, robot=robot, args=args,
                                max_steps=max_steps, wait=wait)
        if wait:  # synchronized (SLRTimeout names the incomplete types)
            pending = self.submit(goal, at=at, args=args, timeout=timeout, robot=robot)
            try:
                return pending.result()
            except BaseException:
                # (a Ctrl-C in the wait: the query evaluates on a worker thread, whose
                # statement would hold the store's connection on; the query is dropped)
                pending.cancel()
                raise
        if args and limit is None and robot is None:
            key = (goal, tuple(args))
            try:
                plan = self._cached_plan(key)
            except TypeError:   # an unhashable goal (a list): no goal text, said as such
                check_goal(goal)
                raise
            if plan is not None and plan.bound_lookup is not None:
                # the file is the truth: the lookup reads the stored versions with its rows;
                # when they moved (or nothing matched), refresh as every call does, and keep
                # the answers only if the plan survived it (a reloaded program clears it)
                found = plan.bound_lookup.answer(self.store, args)
                if found is not None:
                    answers, versions = found
                    if versions is None or versions != self._lookup_versions:
                        self._refresh()
                        self._lookup_versions = versions
                        if self._cached_plan(key) is not plan:
                            found = None
                    if found is not None:
                        return answers
        return self._answers(goal, at, args, timeout, max_steps, limit, robot)

    def _answers(self, goal: str, at: float | None, args: dict | None,
                 timeout: float | None, max_steps: int | None, limit: int | None,
                 robot: str | None, stop: threading.Event | None = None) -> list[dict[str, Any]]:
        """:meth:`query`'s answers past its fast path (the options checked); ``stop``: the
        query's, of :meth:`solutions` (ends the compiled statement or the interpreter under
        way)."""
        self._refresh()
        plan = self.plans.plan(goal, tuple(args) if args else ())
        if limit == 0:
            return []
        if plan.lookup is not None and limit is None and robot is None:
            frame = [None] * plan.compiled.nslots
            if args:
                for name, value in args.items():
                    frame[plan.bind_slots[name]] = argument_term(name, value)
            answers = plan.lookup.run(self.store, frame, plan.names)
            if answers is not None:
                return answers
        if max_steps is None and self.sql_enabled:  # the compiled SQL plan, if any
            from .planner import try_sql
            deadline = time.monotonic() + timeout if timeout is not None else None
            answers = try_sql(self, plan, args, at, limit, deadline, robot, stop)
            if answers is not None:
                return answers
        term, frame = instantiate(plan, args)
        m = self.engine.machine(at=at, timeout=timeout, max_steps=max_steps)
        m.robot = robot
        m.stop = stop
        answers = []
        names = plan.names
        for _ in m.solve(term):
            answers.append(answer_bindings(names, frame, m.deadline, plan.named))
            if limit is not None and len(answers) >= limit:
                break
        return answers

    def solutions(self, goal: str, at: float | None = None, args: dict | None = None,
                  timeout: float | None = None,
                  robot: str | None = None) -> SolutionsAPI:
        """The answers of ``goal`` one at a time, as they are found (unsynchronized): what
        :meth:`query` returns, lazily. A consumer that stops early (a command line's
        ``--limit``, a shell's "stop") never pays for the rest, so a goal with endless answers
        is usable; past ``timeout`` the iteration raises :class:`SLRTimeout` after the answers
        already yielded. The iterator is a :class:`Solutions`: ``close()`` ends it between
        two answers, ``stop()`` from another thread ends the search for the next one.

        >>> from itertools import islice
        >>> list(islice(open().solutions("between(1, inf, X)"), 3))
        [{'X': 1}, {'X': 2}, {'X': 3}]
        """
        stop = threading.Event()
        return Solutions(self._solutions(goal, at, args, timeout, robot, stop), stop,
                         self.store.stop_query)

    def _solutions(self, goal: str, at: float | None, args: dict | None,
                   timeout: float | None, robot: str | None,
                   stop: threading.Event) -> Iterator[dict[str, Any]]:
        check_query_options(at=at, timeout=timeout, robot=robot, args=args)
        try:
            self._refresh()
            plan = self.plans.plan(goal, tuple(args) if args else ())
        except SLRError:
            raise
        except Exception as exc:  # the facade's promise (see _boundary)
            raise SLRError(f"solutions: {type(exc).__name__}: {exc}") from exc
        from .planner import Fallback, plan_for
        if plan.lookup is not None or (self.sql_enabled
                                       and type(plan_for(self, plan, at is not None))
                                       is not Fallback):
            # A compiled plan answers as one statement: all its answers at once (a stop
            # ends that statement: the store interrupts or cancels it)
            yield from _answers_of_query(self, goal, at, args, timeout, None, None, robot, stop)
            return
        term, frame = instantiate(plan, args)
        m = self.engine.machine(at=at, timeout=timeout)
        m.robot = robot
        m.stop = stop
        solving = m.solve(term)
        while True:
            try:
                next(solving)
            except StopIteration:
                return
            except SLRError:
                raise
            except NullArgument:
                raise not_an_event(self, "solutions") from None
            except RecursionError:
                raise SLRError("solutions: the term is nested too deeply") from None
            except Exception as exc:  # the facade's promise (see _boundary)
                raise SLRError(f"solutions: {type(exc).__name__}: {exc}") from exc
            yield answer_bindings(plan.names, frame, named=plan.named)

    def goal_warnings(self, goal: str) -> list[str]:
        """Warnings about ``goal`` that do not change its answer: an event goal or prev/next
        on a type with no stored events, no rules and no declaration is most likely a typo
        (it simply fails, SPEC §2, since its events may not have arrived yet); each warning
        names the nearest known names.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.load("color(O,C)^T :- prev(obj(O,_,C)^Z, T).")
        >>> kb.goal_warnings("colour(cup2, C)^20")
        ['no events or rules of colour/2; did you mean color/2?']
        """
        import difflib

        from .analysis import goal_refs

        check_goal(goal)
        self._refresh()
        term, _ = parse_term(goal, "<query>")
        program = self.engine.program
        known = set(self.store.event_types()) | set(self.store.declared_types())
        known |= set(program.temporal) | set(program.preds) | set(program.dynamic)
        names = sorted({f"{format_atom(n)}/{a}" for n, a in known
                        if not n.startswith(("slr_", "$"))})
        warnings = []
        for name, arity in sorted(goal_refs(term, program).stored):
            if (name, arity) in known:
                continue
            written = f"{format_atom(name)}/{arity}"
            near = difflib.get_close_matches(written, names, n=3, cutoff=0.6)
            near += [n for n in names if n.rpartition("/")[0] == format_atom(name)
                     and n not in near]  # the same name with another arity
            hint = f"; did you mean {' or '.join(near[:3])}?" if near else ""
            warnings.append(f"no events or rules of {written}{hint}")
        return warnings

    def explain(self, goal: str) -> str:
        """How ``goal`` would be run: which engine, and why.

        >>> open().explain("p(X)").splitlines()[0]
        'goal: p(X)'
        """
        check_goal(goal)
        self._refresh()
        rules = self._cep.explain(goal)  # (is a rule, lines) or None
        if rules is not None and rules[0]:
            return "\n".join(rules[1])
        plan = self.plans.plan(goal, ())
        from .planner import explain as _explain  # SQL or interpreter, and why
        lines = [f"goal: {goal}"] + _explain(self, plan) + (rules[1] if rules else [])
        return "\n".join(lines)

    def event_rules(self) -> list[dict[str, Any]]:
        """The event rules (``Head <- Pattern``) in force, in the order they run: each a
        dict with ``head`` (name/arity), ``rule`` (its text), ``pattern``, ``policy``,
        ``program`` (the named program holding it, whose directives set its policy),
        ``source`` (file:line), ``line``, ``table`` (where its complex events are stored),
        ``provenance`` (the table recording each match's events), and counters:
        ``detections`` (this session), ``pending`` (decisions waiting for completeness),
        ``errors`` (candidates a where goal rejected by an error) with ``last_error``.

        >>> kb = open(); kb.load("c(X) <- a(X) seq b(X)."); [r["head"] for r in kb.event_rules()]
        ['c/1']
        """
        self._refresh()   # (rules another process loaded or unloaded since the last call)
        return self._cep.infos()

    # -- synchronized queries (the work is in slr_sql/sync.py) -----------------
    def submit(self, goal: str, at: float | None = None, id: str | None = None,
               args: dict | None = None, timeout: float | None = None,
               callback: Callable[[Any], Any] | None = None,
               robot: str | None = None) -> PendingQueryAPI:
        """Synchronized query ⟨goal, at⟩: returns a PendingQuery (a concurrent.futures.Future)
        answered with the answer list as soon as every event type the goal depends on is
        complete up to ``at`` (default: now), and every prev/next it evaluates is complete up
        to its own time. ``timeout`` (seconds) fails it with SLRTimeout; ``callback(pending)``
        runs when it is done. ``robot`` restricts the goal's events to that robot's, as in
        :meth:`query`; it waits for the fleet's marks (every robot's), so never early. See
        docs/synchronization.md.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.add("p(a)^0.5")
        >>> p = kb.submit("findall(X, p(X)^_, L)", at=1); p.done()
        False
        >>> kb.mark_complete("p/1", 1); p.result(timeout=5)
        [{'L': [Atom('a')]}]

        Inside a transaction of the store (``with kb.store.transaction():``) the query is
        registered once the transaction ended, committed or rolled back, and answered on
        what was committed; its ``result()`` is waited for after the transaction.
        """
        check_query_options(at=at, timeout=timeout, robot=robot, args=args, id=id,
                            callback=callback)
        self._refresh()
        return self._sync.submit(goal, at=at, id=id, args=args, timeout=timeout,
                                 callback=callback, robot=robot)

    async def ask(self, goal: str, at: float | None = None, id: str | None = None,
                  args: dict | None = None, timeout: float | None = None,
                  robot: str | None = None) -> list[dict[str, Any]]:
        """``await kb.ask(goal, at=z)``: :meth:`submit` for asyncio code.

        >>> import asyncio
        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.add("p(1)^1"); kb.mark_complete("p/1", 1)
        >>> asyncio.run(kb.ask("p(X)^T", at=1))
        [{'X': 1, 'T': 1.0}]
        >>> kb.close()

        Refused inside a transaction of the store: the answer would come only once the
        transaction ended, which the awaiting coroutine holds open (:meth:`submit` there,
        and await it after the transaction).
        """
        import asyncio

        self._refuse_inside_transaction(
            "kb.ask()", "the query is answered once the transaction ended, which waiting "
            "for its answer inside it keeps open; submit() inside, and wait after it")

        from concurrent.futures import Future

        pending = self.submit(goal, at=at, id=id, args=args, timeout=timeout, robot=robot)
        assert isinstance(pending, Future)   # a PendingQueryAPI here is a Future
        return await asyncio.wrap_future(pending)

    def mark_complete(self, event_type: str, t: float) -> None:
        """Declare the history of ``"p/N"`` (or ``"p"``: every arity) complete up to ``t``
        (persisted), like a ``fullyUpdated(p/N)^t`` event.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.mark_complete("p/1", 10)
        >>> kb.complete_until("p/1")
        10.0
        >>> kb.close()
        """
        check_mark(event_type, t)
        self._refresh()
        self._pipeline.mark(event_type, t)

    def complete_until(self, event_type: str) -> float:
        """The time up to which the history of ``"p/N"`` is complete now: the greatest of
        now − max_delay, the latest mark, and (in_order types) the latest end received.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(20)); kb.load(":- max_delay(p/1, 5)."); kb.complete_until("p/1")
        15.0
        >>> kb.close()
        """
        check_event_type("complete_until", event_type)
        self._refresh()
        return self._sync.complete_until(event_type)

    def pending(self) -> list[PendingQueryAPI]:
        """The waiting synchronized queries; each PendingQuery's ``waiting_for`` lists the
        event types and times it waits for.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); waiting = kb.submit("p(X)^T", at=5)
        >>> [p.goal for p in kb.pending()]
        ['p(X)^T']
        >>> kb.mark_complete("p/1", 5); waiting.result(timeout=5), kb.pending()
        ([], [])
        >>> kb.close()
        """
        return self._sync.pending()

    # -- history buffers (the work is in slr_sql/buffers.py) --------------------
    def add_buffer(self, pattern: str, *, keep_last: int | None = None,
                   keep_seconds: float | None = None,
                   keep_between: tuple[float, float] | None = None) -> int:
        """Keep a history of the events matching ``pattern`` (runtime policy, persisted):
        the ``keep_last`` most recent per key, those of the last ``keep_seconds`` (by end
        time), or those whose occurrence lies inside ``keep_between=(T1, T2)``. Returns the
        buffer id.

        >>> kb = open(); kb.add_buffer("face(P, _)", keep_last=1)
        1

        Refused inside a transaction of the store, as :meth:`load` is (the buffers change
        with the program, under its lock).
        """
        self._refuse_inside_transaction("kb.add_buffer()", _LOAD_LOCK_FIRST,
                                       self.loader.load_lock)
        self._refresh()
        return self._buffers.add_runtime(pattern, keep_last=keep_last,
                                         keep_seconds=keep_seconds, keep_between=keep_between)

    def remove_buffer(self, buffer_id: int) -> None:
        """Remove a runtime buffer (the events it kept stay). Refused inside a transaction
        of the store, as :meth:`add_buffer` is.

        >>> kb = open(); buffer = kb.add_buffer("p(_)", keep_last=1); kb.remove_buffer(buffer)
        >>> kb.buffers()
        []
        >>> kb.close()
        """
        if type(buffer_id) is not int:
            raise SLRError(f"remove_buffer: a buffer id is an integer (kb.buffers() lists "
                           f"them), not {shown(buffer_id)}")
        if not -2 ** 63 <= buffer_id < 2 ** 63:
            raise BufferNotFound(f"no active buffer #{shown(buffer_id)}")
        self._refuse_inside_transaction("kb.remove_buffer()", _LOAD_LOCK_FIRST,
                                       self.loader.load_lock)
        self._refresh()
        self._buffers.remove_runtime(buffer_id)

    def buffers(self) -> list:
        """The active buffers (program and runtime) with their counters.

        >>> from slr_sql import StreamClock
        >>> kb = open(clock=StreamClock()); _ = kb.add_buffer("p(_)", keep_last=1)
        >>> kb.add_many(["p(a)^1", "p(b)^2"])
        []
        >>> [(info.pattern, info.pruned) for info in kb.buffers()]
        [('p(_)', 1)]
        >>> kb.close()
        """
        self._refresh()
        return self._buffers.infos()

    # -- SQL access -----------------------------------------------------------------------
    def sql(self, query: str, params: Iterable[Any] = (), write: bool = False,
            timeout: float | None = None) -> tuple[list[str], list[tuple]]:
        """Run one SQL statement on the store's database; returns (column names, rows).
        Read-only unless ``write=True``; every failure is an :class:`SLRError`
        (:class:`SLRTimeout` past ``timeout`` seconds). ``params``: values for ``?``
        placeholders (a sequence) or for ``:name`` ones (a mapping), on either backend. A
        transaction-control statement (BEGIN, COMMIT, ROLLBACK, SAVEPOINT, RELEASE, ...) is
        refused before it runs, written or not: the store begins and ends its own
        transactions (several statements together: ``with kb.store.transaction():``). So is
        a change of the store's connection's settings, which would last for every later
        statement of the store: on SQLite an assignment of a pragma the store sets itself
        (synchronous, busy_timeout, foreign_keys, ...); on PostgreSQL, with ``write=True``,
        a SET or RESET, and a statement that changed a setting or the role all the same
        (set_config) is rolled back and refused.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.add("p(a)^1"); kb.sql("SELECT arg1, t_end FROM p")
        (['arg1', 't_end'], [('a', 1.0)])
        >>> kb.sql("SELECT :x + 1 AS y", {"x": 41})
        (['y'], [(42,)])
        >>> kb.sql("COMMIT", write=True)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: sql: COMMIT is not allowed: the store begins and ends its own transactions (...)
        >>> kb.sql("PRAGMA synchronous = OFF", write=True)
        Traceback (most recent call last):
        ...
        slr_sql.errors.SLRError: sql: PRAGMA synchronous with an argument is not allowed (...)
        """
        from .store import DatabaseError

        check_sql(query, timeout, write)
        try:
            if not write:
                return self.store.sql(query, params, False, timeout)
            return self._sql_write(query, params, timeout)
        except DatabaseError as exc:
            reason = store_error(exc, self.store.path)
            if isinstance(reason, SLRUnavailable):  # a full disk, a lock: may pass
                raise reason from None
            raise SLRError(f"sql: {exc}") from None
        except UnicodeEncodeError:
            raise SLRError("sql: the statement or a parameter is not valid Unicode (a lone "
                           "surrogate such as '\\ud800'); nothing was run") from None
        except (OverflowError, TypeError, ValueError) as exc:  # a parameter SQLite cannot take
            raise unbindable_parameter(exc) from None

    def _sql_write(self, query: str, params: Iterable[Any], timeout: float | None
                   ) -> tuple[list[str], list[tuple]]:
        """``sql(..., write=True)``: a NULL argument is no term (docs/schema.md), so a
        statement that would leave one in a row not so before changes nothing. The store
        says which tables the statement writes (its triggers' and functions' writes
        included, whatever its spelling), and only those are read for such rows: before
        and after it when the store can tell before it runs (SQLite; a statement that
        writes no event table then runs as given, outside a transaction of the check:
        ``VACUUM``); else after it, and when they hold some, the run is taken back, the
        rows there before it are read, and it runs once more."""
        store = self.store
        types = {table.lower(): key for key, table in store.event_types().items()}
        ahead = store.tables_to_write(query, params)
        if ahead is not None:
            named = sorted({types[t.lower()] for t in ahead if t.lower() in types})
            if not named:
                return store.sql(query, params, True, timeout)
            with store.transaction():
                before = set(store.null_arguments(named, every=True))
                columns, rows, _ = store.sql_write(query, params, timeout)
                made = sorted(set(store.null_arguments(named, every=True)) - before)
                if made:
                    raise _no_event_left(made)
            return columns, rows

        def run() -> tuple[tuple[list[str], list[tuple]], list[tuple[str, int, str, int, int]]]:
            columns, rows, written = store.sql_write(query, params, timeout)
            named = sorted({types[t.lower()] for t in written if t.lower() in types})
            left = store.null_arguments(named, every=True) if named else []
            return (columns, rows), left

        with store.transaction():
            try:
                with store.transaction():
                    result, left = run()
                    if left:
                        raise _LeftNoEvent(left)
                return result
            except _LeftNoEvent as first:
                # (taken back: the rows that were no events before it are those left now)
                before = set(store.null_arguments(every=True))
                made = sorted(set(first.left) - before)
                if made:
                    raise _no_event_left(made) from None
                result, left = run()
                made = sorted(set(left) - before)
                if made:
                    raise _no_event_left(made) from None
                return result

    # -- plots ----------------------------------------------------------------------------
    def plot(self, types: Iterable[str] | str | None = None, **options: Any) -> Any:
        """A timeline of the event histories as a matplotlib Figure: one row per event type,
        intervals as bars, points as ticks, ``values=["speed:1"]`` as lines, complex events
        marked. Options: see :func:`slr_sql.plot.timeline` and docs/plots.md.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); kb.add("move(r1)^[2, 8]")
        >>> kb.plot(start=0, end=10, size=(600, 120)).get_size_inches().tolist()
        [6.0, 1.2]
        """
        from .plot import timeline  # deferred: matplotlib is the optional extra slr_sql[plot]
        return timeline(self, types, **options)

    # -- subscriptions (the work is in slr_sql/subscriptions/) ------------------
    def subscribe(self, pattern: str, where: str | None = None, since: Any = "now",
                  until: float | None = None, id: str | None = None,
                  callback: Callable[[dict], Any] | None = None, max_queue: int = 10_000,
                  max_lag: int | None = 1_000_000) -> SubscriptionAPI:
        """Deliver each stored event matching ``pattern`` (``p(..)^T`` or ``p(..)^[S,E]``) and
        the goal ``where`` whose end time lies in [since, until], once, in arrival order, as
        an answer dict: iterate (``for``/``async for``/``sub.get(timeout)``) or give
        ``callback``. ``since``: "now", a time, or earlier (stored events first, then live
        ones); ``until`` ends it once the type is complete up to it; ``id`` makes it durable
        (a restart resumes after the last answer handled). See docs/subscriptions.md.

        >>> from slr_sql import ManualClock
        >>> kb = open(clock=ManualClock(0)); sub = kb.subscribe("p(X)^T", where="X > 1", since=0)
        >>> kb.add_many(["p(1)^1", "p(2)^2"]); sub.get(timeout=5)
        []
        {'X': 2, 'T': 2.0}
        >>> sub.close(); kb.close()
        """
        return self._subscriptions.subscribe(pattern, where=where, since=since, until=until,
                                             id=id, callback=callback, max_queue=max_queue,
                                             max_lag=max_lag)

    def unsubscribe(self, id: str) -> None:
        """Remove the durable subscription ``id`` and its position (closing it if open).

        >>> kb = open(); sub = kb.subscribe("p(X)^T", id="watcher"); kb.unsubscribe("watcher")
        >>> sub.closed
        True
        >>> kb.close()
        """
        self._subscriptions.unsubscribe(id)


def read_program_file(path: Any) -> str:
    """The text of the program file ``path`` for ``load_file``, else an :class:`SLRError`
    naming it (the client of ``slr serve`` reads the file the same way, where it runs).

    >>> read_program_file("/no/such/rules.slr")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: /no/such/rules.slr: No such file or directory
    """
    if not isinstance(path, (str, os.PathLike)):
        raise SLRError(f"load_file takes a file's path (a str or a pathlib.Path), not "
                       f"{shown(path)}")
    path = Path(path)
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise SLRError(f"{path}: not a program (not UTF-8 text: byte "
                       f"0x{exc.object[exc.start]:02x} at offset {exc.start})") from None
    except OSError as exc:
        raise SLRError(f"{path}: {exc.strerror or exc}") from None
    except ValueError as exc:   # a NUL in the path
        raise SLRError(f"{shown(str(path))}: {exc}") from None


def not_event_text(text: Any) -> SLRError:
    """The error of ``add`` given ``text`` that is no str (the client of ``slr serve``
    raises it too, before sending).

    >>> print(not_event_text(("p", [1], 1.0, 1.0)))
    add takes one event written in SLR syntax (a str), not a tuple; add_event(name, args, start, end) and add_many([...]) take tuples
    """
    return SLRError(f"add takes one event written in SLR syntax (a str), not a "
                    f"{type(text).__name__}; add_event(name, args, start, end) and "
                    f"add_many([...]) take tuples")


def unbindable_parameter(exc: BaseException) -> SLRError:
    """The error of ``sql`` whose ``params`` cannot be bound (``exc``: why), raised by the
    client of ``slr serve`` too for parameters it cannot go through.

    >>> print(unbindable_parameter(TypeError("'int' object is not iterable")))
    sql: a parameter cannot be bound: 'int' object is not iterable (parameters are None, int of 64 bits, float, str or bytes)
    """
    return SLRError(f"sql: a parameter cannot be bound: {_python_words(exc)} "
                    f"(parameters are None, int of 64 bits, float, str or bytes)")


def check_sql(query: Any, timeout: Any, write: Any = False) -> None:
    """The statement, the ``timeout`` and the ``write`` flag of ``sql``, else an
    :class:`SLRError` (run by the client of ``slr serve`` too, before sending).

    >>> check_sql("SELECT 1", 2.0)
    >>> check_sql("SELECT 1", "soon")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: sql: timeout must be a number of seconds, not 'soon'
    """
    if not isinstance(query, str):
        raise SLRError(f"sql: the statement is text (a str), not a {type(query).__name__}")
    check_time_option("sql: timeout", timeout, minimum=0.0)
    check_flag("sql: write", write)


def check_load(text: Any, filename: Any, name: Any, replace: Any = False) -> str:
    """The arguments of ``load``: program text, the file name its messages show, the
    program's name (returned) and ``replace`` (True or False), else an :class:`SLRError`
    (run by the client of ``slr serve`` too, before sending).

    >>> check_load("p(1).", "<string>", "main")
    'main'
    >>> check_load(b"p(1).", "<string>", "main")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: load takes program text (a str), not a bytes; load_file(path) reads a file
    """
    name = check_program_name(name)
    if not isinstance(text, str):
        raise SLRError(f"load takes program text (a str), not a {type(text).__name__}; "
                       f"load_file(path) reads a file")
    if not isinstance(filename, str) or text_problem(filename):
        raise SLRError(f"load: filename is the text shown in messages (a str without lone "
                       f"surrogates), not {shown(filename)}")
    check_flag("load: replace", replace)
    return name


def check_event_type(method: str, spec: Any) -> None:
    """An event type argument of ``method``: text ``"p/N"`` or ``"p"`` (or a ``(name,
    arity)`` pair) that can be stored, with an arity an event may have; else an
    :class:`SLRError` (run by the client of ``slr serve`` too, before sending).

    >>> check_event_type("complete_until", "p/1"), check_event_type("mark_complete", "'x/seen'/2")
    (None, None)
    >>> check_event_type("mark_complete", "'x/seen/2")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: mark_complete: "'x/seen/2" is not an indicator Name/Arity or Name: it does not read as a quoted name, alone or followed by /Arity (unterminated quoted atom)
    >>> check_event_type("complete_until", 5)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: complete_until: the event type is text such as "p/2" or "p", not 5
    """
    if isinstance(spec, tuple) and len(spec) == 2 and isinstance(spec[0], str) and \
            (spec[1] is None or (type(spec[1]) is int and 0 <= spec[1] <= 100_000)):
        text = spec[0]
    elif isinstance(spec, str):
        text = spec
        if spec.startswith("'"):   # a name quoted as Prolog writes it: read as Prolog does
            try:
                _, quoted_arity = parse_indicator(spec)
            except SLRError as exc:
                raise SLRError(f"{method}: {exc}") from None
            if quoted_arity is not None and quoted_arity > 999_999:
                raise SLRError(f"{method}: the arity of {shown(spec)} is out of range (an "
                               f"event has at most a few thousand arguments)")
        name, sep, arity = spec.rpartition("/")
        if sep and name and arity.isdigit() and len(arity) > 6:
            raise SLRError(f"{method}: the arity of {shown(spec)} is out of range (an event "
                           f"has at most a few thousand arguments)")
    else:
        raise SLRError(f"{method}: the event type is text such as \"p/2\" or \"p\", not "
                       f"{shown(spec)}")
    problem = text_problem(text)
    if problem:
        raise SLRError(f"{method}: the event type {shown(spec)} cannot be stored: {problem}")


def check_mark(event_type: Any, t: Any) -> None:
    """The arguments of ``mark_complete``: an event type and a number of seconds, else an
    :class:`SLRError` (run by the client of ``slr serve`` too, before sending).

    >>> check_mark("p/1", 10)
    >>> check_mark("p/1", "later")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: mark_complete: t must be a number of seconds, not 'later'
    """
    check_event_type("mark_complete", event_type)
    check_time_option("mark_complete: t", t, required=True)


def check_query_options(at: Any = None, timeout: Any = None, limit: Any = None,
                        robot: Any = None, args: Any = None, max_steps: Any = None, *,
                        wait: Any = False, id: Any = None, callback: Any = None) -> None:
    """The options of ``query``, ``solutions``, ``submit`` and ``ask``: ``at`` and
    ``timeout`` numbers of seconds (``timeout`` >= 0), ``limit`` and ``max_steps``
    counts, ``robot`` a robot's name, ``args`` a dict, ``wait`` True or False, ``id`` a
    non-empty string, ``callback`` a callable (None: not given), else an
    :class:`SLRError` (run by the client of ``slr serve`` too, before sending).

    >>> check_query_options(at=5, timeout=1.5, limit=3, args={"X": 1})
    >>> check_query_options(limit="x")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: limit must be a count (an integer >= 0), not 'x'
    >>> check_query_options(callback="print")
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: callback must be callable (a function), not 'print'
    """
    if limit is not None and (type(limit) is not int or limit < 0):
        raise SLRError(f"limit must be a count (an integer >= 0), not {shown(limit)}")
    if max_steps is not None and (type(max_steps) is not int or max_steps < 0):
        raise SLRError(f"max_steps must be a count (an integer >= 0), not {shown(max_steps)}")
    check_time_option("at", at)
    check_time_option("timeout", timeout, minimum=0.0)
    if robot is not None:
        check_robot_name(robot)
    if args is not None and not isinstance(args, dict):
        raise SLRError(f"args must be a dict of variable name -> value, not {shown(args)}")
    check_flag("wait", wait)
    if id is not None and (not isinstance(id, str) or not id):
        raise SLRError(f"id must be a non-empty string (or None: one is made), not {shown(id)}")
    if callback is not None:
        check_callable("callback", callback)


class _LeftNoEvent(Exception):
    """A hand-written statement's run left rows that are no events in the tables it wrote
    (raised to take that run back)."""

    def __init__(self, left: list[tuple[str, int, str, int, int]]) -> None:
        super().__init__()
        self.left = left


def _no_event_left(made: list[tuple[str, int, str, int, int]]) -> NotAnEvent:
    name, arity, _, argument, seq = made[0]
    more = f" (and {len(made) - 1} more)" if len(made) > 1 else ""
    return NotAnEvent(f"sql: the statement would leave a row that is no event: arg{argument} "
                      f"of {name}/{arity}'s row of seq {seq}{more} would be NULL, which is no "
                      f"term; nothing was changed")


def not_an_event(kb: KnowledgeBase | None, where: str) -> NotAnEvent:
    """The error of a goal that read a stored argument that is NULL, naming the first such
    row of each type (whichever path met it: compiled SQL, the interpreter, prev/next, a
    buffer's pattern), so every path says the same.

    >>> from slr_sql import ManualClock
    >>> kb = open(clock=ManualClock(2)); kb.add("p(a)^1")
    >>> kb.store.execute("UPDATE p SET arg1 = NULL")   # (as another client: below the door)
    []
    >>> print(not_an_event(kb, "query"))  # doctest: +ELLIPSIS
    query: p/1: the stored row of seq 1 is not an event: its arg1 is NULL, ...
    """
    rows = []
    if kb is not None:
        try:
            rows = kb.store.null_arguments()
        except Exception:  # noqa: BLE001 - the message without the rows is still the answer
            rows = []
    if not rows:
        return NotAnEvent(f"{where}: a stored event argument is NULL, which is no term (a row "
                          f"written by hand, by another client of the database); "
                          f"fix or delete that row")
    said = "; ".join(null_argument_text(*row) for row in rows)
    return NotAnEvent(f"{where}: {said}")


class Solutions:
    """The answers of one goal, one at a time (what :meth:`KnowledgeBase.solutions` returns):
    an iterator of answer dicts, computed as they are asked for.

    ``close()`` ends it between two answers (what the goal still holds is let go);
    ``stop()``, from any thread, ends the search for an answer under way with
    :class:`SLRError` (``STOPPED_BY_CALLER``), and a later ``next()`` raises it at once: the
    interpreter at its next check of limits (every few thousand inference steps), a goal
    compiled to one SQL statement (or a compiled sub-goal the interpreter runs) at once --
    SQLite's progress handler of that statement interrupts it (it looks every 20,000
    instructions), PostgreSQL's server is sent a cancel of that statement, again until it
    ended. Only that query's statement ends: the store is unchanged, and its connection
    answers the next query. ``slr serve`` stops a query so when its client asks to stop or
    leaves (docs/service.md, "Answers one at a time").

    >>> kb = open()
    >>> answers = kb.solutions("between(1, inf, X)")
    >>> next(answers)
    {'X': 1}
    >>> answers.stop(); next(answers)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: the query was stopped while it looked for its next answer
    >>> kb.close()
    """

    def __init__(self, answers: Iterator[dict[str, Any]], stop: threading.Event,
                 stop_statement: Callable[[threading.Event], None]):
        self._answers = answers
        self._stop = stop
        # (the store's stop_query: ends the statement of this query the server runs now)
        self._stop_statement = stop_statement
        self._closed = False

    def __iter__(self) -> "Solutions":
        return self

    def __next__(self) -> dict[str, Any]:
        if self._closed:
            raise StopIteration
        if self._stop.is_set():
            raise SLRError(STOPPED_BY_CALLER)
        return next(self._answers)

    def stop(self) -> None:
        """End the search for the next answer (see the class's text); thread-safe, and it
        never waits (the service calls it on its event loop)."""
        self._stop.set()
        self._stop_statement(self._stop)

    def close(self) -> None:
        """End the iteration: later ``next()`` calls raise StopIteration. From another thread
        while a ``next()`` looks for an answer, that search ends as :meth:`stop` ends it."""
        self._closed = True
        self.stop()    # (what a next() under way in another thread checks)
        try:
            self._answers.close()
        except ValueError:
            pass   # (that next() is running the generator: the stop ends it there)


def _boundary(method: Callable, where: str | None = None) -> Callable:
    """The facade's promise, kept at its edge: whatever goes wrong below (a check a layer
    lacks, a Python error inside a user's ``define``d predicate, a damaged file), the caller
    gets an :class:`SLRError` in words, never a raw Python or SQLite exception. ``where``:
    the name its messages start with (default: the method's)."""
    if where is None:
        where = "open" if method.__name__ == "__init__" else method.__name__

    @functools.wraps(method)
    def guarded(*args: Any, **kwargs: Any) -> Any:
        try:
            return method(*args, **kwargs)
        except SLRError:
            raise
        except NullArgument:
            kb = args[0] if args and isinstance(args[0], KnowledgeBase) else None
            raise not_an_event(kb, where) from None
        except RecursionError:
            raise SLRError(f"{where}: the term is nested too deeply") from None
        except MemoryError:
            raise SLRError(f"{where}: out of memory") from None
        except DatabaseError as exc:
            kb = args[0] if args and isinstance(args[0], KnowledgeBase) else None
            path = getattr(getattr(kb, "store", None), "path", None) or (
                args[1] if where == "open" and len(args) > 1 else kwargs.get("path"))
            raise store_error(exc, path) from None
        except Exception as exc:  # noqa: BLE001 - the boundary: every kind becomes words
            raise unforeseen_failure(where, exc) from exc
    return guarded


def unforeseen_failure(where: str, exc: BaseException) -> SLRError:
    """The facade's last resort (:func:`_boundary`): a Python error no check foresaw,
    raised by the method ``where``, as an :class:`SLRError` (the client of ``slr serve``
    words what it runs on the caller's side, ``plot``, so too).

    >>> print(unforeseen_failure("plot", TypeError("'int' object is not iterable")))
    plot: TypeError: 'int' object is not iterable
    """
    return SLRError(f"{where}: {type(exc).__name__}: {exc}")


# the keyword options of open(): those of KnowledgeBase after its path and clock
OPEN_OPTIONS = tuple(name for name, parameter in
                     inspect.signature(KnowledgeBase.__init__).parameters.items()
                     if parameter.kind is inspect.Parameter.KEYWORD_ONLY)

# Every public method of the facade goes through the boundary (one list, kept next to it).
for _name in ("__init__", "close", "load", "unload", "programs", "load_file", "define", "add",
              "goal_warnings",
              "add_event", "add_many", "query", "explain", "submit", "mark_complete",
              "complete_until", "pending", "add_buffer", "remove_buffer", "buffers", "sql",
              "plot", "subscribe", "unsubscribe", "event_rules"):
    if hasattr(KnowledgeBase, _name):
        setattr(KnowledgeBase, _name, _boundary(getattr(KnowledgeBase, _name)))
del _name
# the answers of a compiled plan that solutions() gives, in query()'s words
_answers_of_query = _boundary(KnowledgeBase._answers, "query")


def open(path: str | Path | None = None, clock: Clock | None = None, **options: Any) -> KnowledgeBase:
    """Open (or create) a knowledge base; ``path=None`` gives an in-memory one.

    Options: ``synchronous`` (``"FULL"``: an event is on disk when its add returns),
    ``busy_timeout`` (seconds a write waits for another process's write transaction before
    :class:`~slr_sql.errors.SLRBusy`; default 5), ``checkpoint`` (``"auto"``: SQLite copies
    the write-ahead log into the file during the commit that fills it; ``"background"``: a
    thread of the store does it, so no ``add`` waits for it -- for long-running writers with
    a latency budget, such as ``slr serve`` and ``slr ros bridge``), ``cache_mib`` (SQLite's
    page cache, default 64 MiB: it fills as the store is used, then the process's memory stays
    flat; a smaller one makes it flat sooner and makes large ingests and scans re-read pages),
    ``max_learned_delay`` (seconds a learned delay may reach, default 3600; ``None``: no cap;
    an event arriving later than that after its end warns with
    :class:`~slr_sql.sync.LearnedDelayWarning`: its times are probably not the clock's).
    A file that is not a store (not SQLite, damaged, a store of a newer slr_sql, or an SQLite
    file of another application) is refused with an :class:`SLRError` and left untouched;
    ``adopt=True`` adds a store to another application's SQLite file on purpose.
    ``robot`` names the robot the store belongs to (kept in the store; a store has one name
    for life): its events are stored with that name in their ``robot`` column, for
    ``origin/2`` and fleets (docs/fleet.md).

    An option of another name is an :class:`SLRError` naming the options.

    >>> kb = open(); kb.close()
    >>> open(bogus=1)
    Traceback (most recent call last):
    ...
    slr_sql.errors.SLRError: open has no option 'bogus' (its options: synchronous, busy_timeout, adopt, checkpoint, cache_mib, robot, max_learned_delay)
    """
    check_option_names("open", options, OPEN_OPTIONS)
    return KnowledgeBase(path, clock, **options)
