"""The program a knowledge base runs: built from the program texts stored in the file (every
named program, in load order, whoever loaded them), loaded and unloaded all or nothing, and
never older than the file at the start of a call (:meth:`ProgramLoader.refresh`).

Program building reads clauses and directives (``:- event``, ``max_delay``, buffers,
consumption policies) into a :class:`~slr_sql.program.Program` and its
:class:`~slr_sql.program.Declarations`; event rules (``Head <- Pattern``) are compiled by
:mod:`slr_sql.cep`. The facade (``kb.loader``) calls it; the parts of layer 6 reach it
through their host (:class:`slr_sql.host.Host`): the planner asks for the version its
fact tables were built from, a fleet store refreshes before it writes.

>>> import slr_sql
>>> kb = slr_sql.open(); kb.load(":- event p/1. q(X) :- p(X)^_.")
>>> sorted(kb.loader.declarations.event_types), kb.loader.version > 0
([('p', 1)], True)
"""
from __future__ import annotations

import warnings
from typing import Any, Callable, Iterable

from .clocks import parse_duration
from .errors import SLRError
from .lockorder import ordered_lock
from .host import Host
from .parser import parse_program
from .program import BufferDecl, Declarations, Program, split_event_atom
from .store.checks import shown
from .terms import Atom, Clause, Struct, Var, deref, format_term, list_items

__all__ = ["ProgramLoader"]


class ProgramLoader:
    """The program in force for one knowledge base (``host``) and what it was built from.

    ``program`` and ``declarations`` are replaced whole by a load (never changed in place:
    a reader holding the old objects keeps a consistent pair); ``version`` is the stored
    program version they were built from; ``load_lock`` serializes loads in this process
    (the store's write lock serializes them between processes).
    """

    def __init__(self, host: Host) -> None:
        self.host = host
        self.store = host.store
        self.program = Program()
        self.declarations = Declarations()
        self.load_lock = ordered_lock("kb.load", reentrant=True)
        # the stored program version self.program was built from, the parsed stored texts
        # (by id), and the store's data_version when the file was last checked for changes
        self.version = -1
        self._parsed: dict[int, tuple[str, list]] = {}
        self.seen_data_version: int | None = None
        # the stored progress version (learned delays, completeness marks) last seen
        self.progress_version = self.store.versions()[1]

    # -- the file is the truth ----------------------------------------------------------
    def refresh(self) -> None:
        """See what other connections (processes, knowledge bases) wrote since the last
        call: a cheap ``PRAGMA data_version`` first; when it moved, the program and progress
        versions; the program is re-read when its version moved, and the synchronizer
        re-reads delays and marks when theirs did."""
        store = self.store
        if store.path is None:  # in memory: no other connection can write it
            return
        data_version = store.data_version()
        if data_version == self.seen_data_version:
            return
        if store.in_transaction_here:
            # (a call inside a transaction this thread holds, ``kb.store.transaction()``:
            # the program and progress stay as last read until the next call after it --
            # their re-read takes locks ordered before the store's, which it holds)
            return
        program_version, progress_version = store.versions()
        if program_version != self.version:
            with self.load_lock:
                if store.program_version() != self.version:
                    self.reload()
        if progress_version != self.progress_version:
            self.progress_version = progress_version
            for listener in self.host.progress_listeners:
                listener()
        self.seen_data_version = data_version   # (not before: a failed re-read is retried)

    def owe_check(self) -> Any:
        """Before an add: on a server, the change check :meth:`refresh` makes, owed until
        the add's first statement (which carries it: docs/postgres.md, "Concurrency");
        returns what :meth:`settle_check` takes. Elsewhere (SQLite, memory, inside a
        transaction), :meth:`refresh` now and None.

        >>> import slr_sql
        >>> slr_sql.open().loader.owe_check() is None   # (in memory: nobody else writes)
        True
        """
        owed = None
        if self.store.path is not None and not self.store.in_transaction_here:
            owed = self.store.owe_change_check(self.version)
        if owed is None:
            self.refresh()
        return owed

    def settle_check(self, owed: Any) -> None:
        """The add that owed the check stored its events (and committed): what the check
        read is taken as :meth:`refresh` takes it (the progress listeners are told of
        marks and delays another connection raised); a check the add never sent (it
        stored nothing) is made now."""
        read = self.store.settle_change_check(owed)
        if read is None:
            self.refresh()
            return
        counter, _, progress_version = read   # (the program: the add's own, or it failed)
        if progress_version != self.progress_version:
            self.progress_version = progress_version
            for listener in self.host.progress_listeners:
                listener()
        self.seen_data_version = counter

    def forget_check(self, owed: Any) -> None:
        """The add that owed the check failed or is made again: nothing of what it read
        is taken (the next call checks again)."""
        self.store.settle_change_check(owed)
        self.seen_data_version = None

    def reload(self) -> None:
        """Build the program from the texts stored now (the union of every named program,
        in load order) and tell the reload listeners. The version is read before the texts:
        a change committed in between is seen again at the next call."""
        version = self.store.program_version()
        texts = self.store.program_texts()
        self.store.event_types()   # re-read the event types too: declared arities may be new
        program, decls = self._build(self._named(texts))
        self.program, self.declarations = program, decls
        self.host.engine.program = program
        self.version = version
        _warn_policies_of_no_rule(decls)
        self.host.plans.clear()
        for listener in self.host.reload_listeners:
            listener(self.host)

    def ensure_current(self) -> bool:
        """Inside a write transaction: make sure the program is the stored one (re-read it
        if another connection changed it); True if it had to be re-read. (Without taking
        the load lock: a thread holding it may be waiting for the store lock we hold, and
        no load can be between its write and its commit while we hold that.)"""
        if self.store.program_version() == self.version:
            return False
        self.reload()
        return True

    def _parse_texts(self, texts: list) -> list[list[Clause]]:
        """The clauses of each stored text, parsed once per text id."""
        parsed = {}
        out = []
        for text in texts:
            cached = self._parsed.get(text.id)
            if cached is None or cached[0] is not text.source and cached[0] != text.source:
                cached = (text.source, parse_program(text.source, text.filename or "<stored>"))
            parsed[text.id] = cached
            out.append(cached[1])
        self._parsed = parsed
        return out

    def _named(self, texts: list) -> list[tuple[str, list[Clause]]]:
        """The clauses of each stored text with the name of its program."""
        return list(zip((t.name for t in texts), self._parse_texts(texts)))

    def _build(self, texts: Iterable[tuple[str, list[Clause]]]) -> tuple[Program, Declarations]:
        program, decls = Program(), Declarations()
        for name, clauses in texts:
            self._add_clauses(clauses, program, decls, name)
        return program, decls

    # -- program building ---------------------------------------------------------------
    def _add_clauses(self, clauses: list[Clause], program: Program, decls: Declarations,
                     name: str) -> None:
        """Add the clauses of one text of the program ``name``."""
        from . import cep as _cep  # event rules Head <- Pattern
        for clause in clauses:
            if clause.head is None:
                self._directive(clause, program, decls, name)
                continue
            head = deref(clause.head)
            if _cep.is_event_rule(head):
                # (the size of a new rule is checked by load: a rule the store holds
                # already, loaded by an earlier version beyond today's maximum, still
                # loads, so that its file opens and the program can be unloaded)
                rule = _cep.compile_rule(clause, sized=False)
                rule.program = name   # (its policy: its own program's directives)
                decls.read_rules.append(rule)
                continue
            if _cep.is_ignored_fact(head):
                continue   # ETALIS-only facts such as print_trigger/1 (docs/events.md)
            self._check_head(head, clause)
            if type(head) is Struct and head.name in ("tBuffer", "cBuffer") and len(head.args) == 2:
                decls.buffers.append(self._buffer_decl(head, clause))
            program.add_clause(clause)
        if decls.read_rules:  # policies, dependency order, no cycles
            # (from every rule as read: a text of a program may set the policy of rules
            # that an earlier text of it holds, and that another program holds too)
            decls.event_rules = _cep.prepare(decls.read_rules, decls.consumption, program)

    def _buffer_decl(self, head: Struct, clause: Clause) -> BufferDecl:
        pattern, amount = deref(head.args[0]), deref(head.args[1])
        if type(pattern) not in (Struct, Atom):
            raise SLRError(f"{_where(clause)}{head.name}: the pattern must be an event "
                           f"term, not {format_term(pattern)}")
        if head.name == "tBuffer":
            value = parse_duration(amount)
        else:
            if type(amount) is not int or amount < 0:
                raise SLRError(f"{_where(clause)}cBuffer: the count must be a non-negative "
                               f"integer, not {format_term(amount)}")
            value = amount
        return BufferDecl(str(head.name), pattern, value, clause)

    def _check_head(self, head: Any, clause: Clause) -> None:
        from .builtins import BUILTIN_NAMES
        from .engine import CONTROL

        if type(head) is Var:
            raise SLRError(f"{_where(clause)}a clause head cannot be a variable")
        if type(head) not in (Struct, Atom):
            raise SLRError(f"{_where(clause)}a clause head must be callable, not "
                           f"{format_term(head)}")
        if split_event_atom(head) is not None:
            return
        key = (str(head.name), len(head.args)) if type(head) is Struct else (str(head), 0)
        if key in CONTROL or key in BUILTIN_NAMES or key in (("prev", 2), ("next", 2), ("next", 3)):
            raise SLRError(f"{_where(clause)}cannot redefine the builtin {key[0]}/{key[1]}")

    def _directive(self, clause: Clause, program: Program, decls: Declarations,
                   program_name: str) -> None:
        goal = deref(clause.body)
        name = str(goal.name) if type(goal) is Struct else str(goal)
        args = goal.args if type(goal) is Struct else ()
        try:
            if name == "event" and len(args) == 1:
                decls.event_types.update(_indicators(args[0]))
            elif name == "max_delay" and len(args) == 2:
                ind = _indicator(args[0])
                value = deref(args[1])
                decls.max_delay[ind] = "learn" if value == "learn" and type(value) is Atom \
                    else parse_duration(value)
            elif name == "in_order" and len(args) == 1:
                decls.in_order.update(_indicators(args[0]))
            elif name == "dynamic" and len(args) == 1:
                program.dynamic.update(_indicators(args[0]))
                program.analysis_cache = None      # (what it said of the program changed)
            elif name in ("discontiguous", "use_module", "ensure_loaded", "set_prolog_flag",
                          "module"):
                pass  # accepted for compatibility with Prolog sources; nothing to do here
            elif name in ("tBuffer", "cBuffer") and len(args) == 2:
                decls.buffers.append(self._buffer_decl(goal, clause))
            elif name == "consumption" and len(args) in (1, 2):
                from .cep import consumption_directive
                target, policy = consumption_directive(goal)
                # (its own program's rules only: a program loaded later must not change
                # how the rules of the programs loaded before pair events)
                decls.consumption.setdefault(program_name, {})[target] = policy
            else:
                raise SLRError(f"unknown directive :- {format_term(goal)}")
        except SLRError as exc:
            msg = str(exc)
            if not msg.startswith(_where(clause)) or not _where(clause):
                msg = _where(clause) + msg
            raise SLRError(msg) from None

    # -- loading ------------------------------------------------------------------------
    def load(self, name: str, text: str, filename: str, clauses: list[Clause],
             replace: bool) -> None:
        """Add the parsed ``clauses`` of ``text`` to the program ``name`` (or, with
        ``replace``, make them the whole of it), in one transaction: stored, built, the event
        types declared and the load listeners run, or nothing changed."""
        from . import cep as _cep
        for clause in clauses:
            if clause.head is not None and _cep.is_event_rule(clause.head):
                _cep.check_size(clause)
        with self.load_lock, self.store.transaction():
            # the write lock is ours: the texts stored now are the latest
            stale = self.store.program_version() != self.version
            if replace or stale:
                texts = [t for t in self.store.program_texts() if not (replace and t.name == name)]
                parsed = self._named(texts)
                if replace:
                    first = self._first_text_of(name)
                    at = len([t for t in texts if first is not None and t.id < first])
                    parsed = parsed[:at] + [(name, clauses)] + parsed[at:] if first is not None \
                        else parsed + [(name, clauses)]
                else:
                    parsed = parsed + [(name, clauses)]
                program, decls = self._build(parsed)
            else:
                program, decls = self.program.copy(), self.declarations.copy()
                self._add_clauses(clauses, program, decls, name)
            self._check_event_arities(decls, filename)
            self._check_consumption_heads(decls, name, filename, clauses)
            self._install(program, decls, lambda: self.store.replace_named_program(
                name, text, filename) if replace else self.store.append_program(
                text, filename, name), (text, clauses))
        _warn_policies_of_no_rule(decls, name)

    def unload(self, name: str) -> None:
        """Remove the program ``name`` in one transaction (an :class:`SLRError` when no
        program has that name)."""
        with self.load_lock, self.store.transaction():
            stored = self.store.program_texts()
            texts = [t for t in stored if t.name != name]
            if len(texts) == len(stored):
                names = list(dict.fromkeys(t.name for t in stored))
                raise SLRError(f"no program named {shown(name)} (loaded: "
                               f"{', '.join(repr(n) for n in names) or 'none'})")
            program, decls = self._build(self._named(texts))
            self._install(program, decls, lambda: self.store.delete_program(name))

    def _first_text_of(self, name: str) -> int | None:
        ids = [t.id for t in self.store.program_texts() if t.name == name]
        return min(ids) if ids else None

    @staticmethod
    def _check_consumption_heads(decls: Declarations, name: str, filename: str,
                                 clauses: list[Clause]) -> None:
        """Refuse ``:- consumption(Head/N, Policy)`` in ``clauses``, the text loaded into the
        program ``name``, when Head/N is the head of event rules of other programs and of
        none of its own: a directive governs its own program's rules, so it would change
        nothing while its writer meant to change how those other rules pair events (which
        a program must not do to another). A head no program defines yet is accepted: the
        directive waits for rules of its own program (a shell's ``user`` program gets them
        text by text). A directive of an earlier text is not looked at again: another
        program may have defined its head since, which must not refuse every later text of
        this one."""
        from .cep import consumption_directive
        asked = set()
        for clause in clauses:
            if clause.head is None:
                try:
                    directive = consumption_directive(clause.body)
                except SLRError:
                    continue
                if directive is not None and directive[0] is not None:
                    asked.add(directive[0])
        own = {rule.head_key for rule in decls.read_rules if rule.program == name}
        for head, policy in sorted(((h, p) for h, p in decls.consumption.get(name, {}).items()
                                    if h in asked), key=repr):
            if head in own:
                continue
            others = sorted({rule.program for rule in decls.read_rules
                             if rule.head_key == head and rule.program != name})
            if others:
                ind = f"{format_term(Atom(head[0]))}/{head[1]}"
                raise SLRError(
                    f"{filename}: :- consumption({ind}, {policy}): the event rules of {ind} "
                    f"are in the program{'s' if len(others) > 1 else ''} "
                    f"{', '.join(shown(o) for o in others)}, none in the program "
                    f"{shown(name)} loaded here; a consumption directive sets the policy of "
                    f"its own program's rules only, so that loading a program never changes "
                    f"how another program's rules pair events (put the directive in "
                    f"the text of {shown(others[0])})")

    def _check_event_arities(self, decls: Declarations, filename: str) -> None:
        """Refuse ``:- event p/N`` when the store already has events of p with another
        arity M that nobody declared: p/N would silently become a second type (its own
        table) beside them -- most often a changed mind about p's arguments. Declaring p/M
        too (``:- event p/M, p/N.``) says both are meant."""
        new = decls.event_types - self.declarations.event_types
        if not new:
            return
        stored = self.store.event_types()
        declared = decls.event_types | self.store.declared_types()
        for name, arity in sorted(new):
            others = sorted(a for (n, a) in stored if n == name and a != arity
                            and (n, a) not in declared)
            if others:
                other = others[0]
                p = format_term(Atom(name))
                raise SLRError(
                    f"{filename}: :- event {p}/{arity}: the store already holds events of "
                    f"{p}/{other} (table {stored[(name, other)]}), which no program "
                    f"declares; an event type is name/arity, so {p}/{arity} would be a "
                    f"second type beside it, with a table of its own. If both are meant, "
                    f"declare both (:- event {p}/{other}, {p}/{arity}.)")

    def _install(self, program: Program, decls: Declarations, write: Callable[[], Any],
                 parsed: tuple[str, list] | None = None) -> None:
        """Inside the load transaction: store the change (``write``, returning the new
        text's id), declare the event types, make ``program`` the one in force and let the load
        listeners build what is derived from it (fact tables, views, buffers); on any error
        everything is as before."""
        old = (self.program, self.declarations, self.version, dict(self._parsed))
        try:
            # the tables declared here and by the listeners (event rules' complex types):
            # the views are made again once more at the end if one of them is read
            with self.store.table_batch():
                text_id = write()
                if parsed is not None:
                    self._parsed[text_id] = parsed
                declared = self.store.declared_types()
                for type_name, arity in sorted(decls.event_types - declared):
                    self.store.declare_type(type_name, arity)
                self.program, self.declarations = program, decls
                self.version = self.store.program_version()
                for listener in self.host.load_listeners:
                    listener(self.host)
        except BaseException:
            self.program, self.declarations, self.version, self._parsed = old
            raise
        self.host.engine.program = program
        self.host.plans.clear()


class ConsumptionScopeWarning(UserWarning):
    """A program's ``:- consumption(Policy).`` sets the policy of no event rule: the program
    holds no event rule of its own while other programs hold some, and a directive sets its
    own program's rules only (docs/events.md, "Whose rules a directive sets"). A store loaded
    by a version of slr_sql before that rule may hold such a program: its directive set the
    other programs' rules then, and no longer does."""


def policies_of_no_rule(decls: Declarations) -> list[tuple[str, str, list[str]]]:
    """``(program, policy, programs with event rules)`` of each program whose
    ``:- consumption(Policy).`` sets no rule's policy (:class:`ConsumptionScopeWarning`).

    >>> import slr_sql
    >>> kb = slr_sql.open()
    >>> kb.load("c(X) <- a(X) seq b(X).")
    >>> with warnings.catch_warnings(record=True) as caught:
    ...     warnings.simplefilter("always")
    ...     kb.load(":- consumption(recent).", name="policy")
    >>> policies_of_no_rule(kb.loader.declarations), [w.category.__name__ for w in caught]
    ([('policy', 'recent', ['main'])], ['ConsumptionScopeWarning'])
    """
    owners = sorted({str(rule.program) for rule in decls.read_rules})
    if not owners:
        return []   # (no rule anywhere yet: the directive waits for its program's rules)
    return [(program, policies[None], owners) for program, policies in
            sorted(decls.consumption.items()) if None in policies and program not in owners]


def _warn_policies_of_no_rule(decls: Declarations, program: str | None = None) -> None:
    """Warn (:class:`ConsumptionScopeWarning`) of each program's (or ``program``'s)
    ``:- consumption(Policy).`` that sets no rule's policy: at a load, and when a store's
    program is read (a store loaded before a directive governed its own program only)."""
    for name, policy, owners in policies_of_no_rule(decls):
        if program is not None and name != program:
            continue
        warnings.warn(ConsumptionScopeWarning(
            f":- consumption({policy}) in the program {shown(name)} sets the policy of no "
            f"event rule: {shown(name)} holds none, and a consumption directive sets the "
            f"rules of its own program only (the event rules of "
            f"{', '.join(shown(o) for o in owners)} keep their own policy; put the directive "
            f"in the text of the program whose rules it is for)"), stacklevel=2)


def _indicator(t: Any) -> tuple[str, int]:
    t = deref(t)
    if type(t) is Struct and t.name == "/" and len(t.args) == 2:
        name, arity = deref(t.args[0]), deref(t.args[1])
        if type(name) is Atom and type(arity) is int and arity >= 0:
            return str(name), arity
    raise SLRError(f"expected a predicate indicator name/arity, not {format_term(t)}")


def _indicators(t: Any) -> list[tuple[str, int]]:
    t = deref(t)
    if type(t) is Struct and t.name == "," and len(t.args) == 2:
        return _indicators(t.args[0]) + _indicators(t.args[1])
    if type(t) is Struct and t.name == "." and len(t.args) == 2:
        items, _ = list_items(t)
        return [ind for x in items for ind in _indicators(x)]
    return [_indicator(t)]


def _where(clause: Clause | None) -> str:
    if clause is None or clause.span is None:
        return ""
    return f"{clause.span.filename}:{clause.span.line}: "
