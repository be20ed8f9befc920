"""Compile non-recursive SLR goals to one SQL statement (docs/sql.md).

The compiler is an *abstract interpreter*: it walks the goal depth-first exactly like the
top-down interpreter does, but instead of values it binds variables to :class:`Col` objects,
SQL expressions that stand for the value one row of the statement will hold. Every path
through the goal tree (every alternative of a ``;``, every clause of a called rule) becomes
one *branch*: a flat ``SELECT`` with its ``FROM`` aliases, ``WHERE`` conditions and ordering
keys. The branches are glued with ``UNION ALL`` and ordered by their keys, which reproduces
the interpreter's depth-first order of solutions:

* an event goal contributes its store-order columns ``t_end, t_start, seq``;
* prev contributes ``t_start, seq`` (its ties), next ``t_end, seq``; a fact table ``ord``;
* a disjunction, a called rule or an if-then-else contributes the index of the alternative
  taken (a constant) *before* the keys of the goals inside it.

Two solutions of different branches share the goals (and so the key columns) up to the first
alternative where they part, and there their alternative indexes decide; keys are padded
with NULL to a common width.

Values in SQL are always in the store's *top-level encoding* (slr_sql.encoding): atoms TEXT,
integers INTEGER, floats REAL, everything else JSON TEXT. Unification of two values is
``a = b AND typeof(a) = typeof(b)`` (SQLite's ``1 = 1.0`` must not unify), simplified when
the kinds are known (time columns are REAL, counts INTEGER). Arithmetic goes through
application-defined functions that call :func:`slr_sql.arith.evaluate` (Prolog's integer and
float rules, errors included) except ``+``/``-``/``*`` on floats, which SQLite computes with
the same IEEE doubles. A function that meets something the interpreter would reject (a type
error, an integer overflow, a non-ground result) raises, and the query is re-run by the
interpreter, which raises the proper error or answers.

What differs between engines is printed by the store's dialect (its query printers,
:mod:`slr_sql.store.query_printers`): ``typeof`` above, the JSON functions, the Python
functions, answer columns. On PostgreSQL the columns hold typed text, so unification is
text equality there, and a part the engine cannot compute exactly (a Python function)
raises ``Unprintable``, which makes the goal a fallback like any other.

Whatever the compiler does not handle exactly raises :class:`Fallback` with the reason.
Handlers are named ``<kind>_sql``.

The package, one module per part of that walk:

* ``compiler``: :class:`Compiler`, the walk and the dispatch of goals to handlers;
* ``control``: conjunction, disjunction, if-then-else, negation, call/N, forall;
* ``rules``: calls of rules, fact tables and library predicates;
* ``events``: event goals, prev and next;
* ``aggregates``: findall/3 and aggregate_all/3;
* ``builtin_goals``: arithmetic, comparisons, ``=``, ``is`` and det builtins (``slr_det``);
* ``unify``: unification, patterns on stored lists and compounds, encoded values;
* ``guards``: the statements that keep Prolog's error order;
* ``views``: the SELECT of a predicate's inspection view from its compiled branches;
* ``model``: :class:`Col`, :class:`ColRef`, :class:`Part`, :class:`State`, :data:`SITES`,
  :class:`Fallback` and the term walks they share.
"""
from __future__ import annotations

from .builtin_goals import COMPARISONS, EFFECTS, NO_BIND
from .compiler import CONTROL_FALLBACK, CONTROL_SQL, Compiler
from .guards import NUM_ARG, TIME_ARG, guards, unused_checks
from .model import (CYCLIC, NUMERIC, SITES, Col, ColRef, Fallback, Part, Site, State, has_col,
                    has_var, key_columns, quote_ident, resolve, term_free_vars)
from .views import view_select

__all__ = ["Fallback", "Col", "Compiler", "Part", "SITES", "quote_ident",
           # used by the planner and the modules of this package
           "ColRef", "Site", "State", "resolve", "has_var", "has_col", "term_free_vars",
           "guards", "unused_checks", "NUM_ARG", "TIME_ARG", "NUMERIC", "CYCLIC", "NO_BIND", "EFFECTS",
           "COMPARISONS", "CONTROL_FALLBACK", "CONTROL_SQL", "view_select", "key_columns"]
