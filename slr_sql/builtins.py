"""Builtin predicates: deterministic ones return a bool, nondeterministic ones are generators
that bind through the machine and ``yield`` once per solution (the machine undoes the
bindings before asking for the next one).

List predicates whose order of solutions users rely on (member/2, append/3, ...) are written
in Prolog (:data:`LIBRARY_SOURCE`) exactly as SWI-Prolog's library defines them, so that the
interpreter enumerates solutions in the same order as SWI-Prolog.
"""
from __future__ import annotations

import functools
import gc
import math
import sys
import unicodedata as _ud
from typing import Any, Callable, Iterator

from .arith import (apply_binary, evaluate, evaluation_error, instantiation_error, iso_error,
                    resource_error, type_error, with_context)
from .unify import bound_args, copy_term, unify, undo, unify_event_row
from .errors import SLRError, SLREvaluationError, SLRSyntaxError
from .program import Program, split_event_atom, event_key
from .terms import (CONS, NODES_BETWEEN_CLOCK_CHECKS, Atom, NIL, String, Struct, Var, check_deadline,
                    deref, from_python, int_text,
                    is_ground, list_items, make_list, same_float, term_vars, to_python)

DET: dict[tuple[str, int], Callable[["Machine", tuple], bool]] = {}
NONDET: dict[tuple[str, int], Callable[["Machine", tuple], Iterator[None]]] = {}


def det(name: str, arity: int):
    """Register the decorated function as the deterministic builtin ``name/arity``: it
    takes the machine and the goal's arguments and returns whether the goal succeeded.

    >>> @det("$always", 0)
    ... def _always(m, a):
    ...     return True
    >>> DET[("$always", 0)] is _always
    True
    >>> del DET[("$always", 0)]
    """
    def deco(f):
        DET[(name, arity)] = f
        return f
    return deco


def nondet(name: str, arity: int):
    """Register the decorated generator as the nondeterministic builtin ``name/arity``:
    each value it yields is one solution (bindings made before the yield), backtracking
    resumes it.

    >>> @nondet("$twice", 0)
    ... def _twice(m, a):
    ...     yield None
    ...     yield None
    >>> NONDET[("$twice", 0)] is _twice
    True
    >>> del NONDET[("$twice", 0)]
    """
    def deco(f):
        NONDET[(name, arity)] = f
        return f
    return deco


# The context SWI-Prolog gives an error a builtin raises: context(system:Name/Arity, _) for
# its C builtins (error_context()); these others name the predicate otherwise, or (None)
# leave the context unbound, as SWI-Prolog's library predicates (must_be/2) do. slr_sql's
# own builtins (robot library, prev/next) leave it unbound too.
def _pi(name: str, arity: int, module: str | None = "system") -> Any:
    pi = Struct("/", (Atom(name), arity))
    return pi if module is None else Struct(":", (Atom(module), pi))


_OTHER_CONTEXTS: dict[tuple[str, int], Any] = {
    ("length", 2): _pi("length", 2, None),
    ("$numbervars", 3): _pi("numbervars", 4),   # (SWI-Prolog's numbervars/3 calls /4)
    ("$text_to_string", 2): _pi("text_to_string", 2),
    ("$sformat", 3): _pi("sformat", 3), ("$sformat", 2): _pi("sformat", 2),
    ("$nl_to", 1): _pi("nl", 1), ("$tab_to", 2): _pi("tab", 2),
    **{(f"${name}_to", 2): _pi(name, 2)
       for name in ("write", "print", "writeq", "write_canonical", "writeln")},
    ("$sub_string", 5): _pi("sub_string", 5),
    ("$char_type", 2): _pi("char_type", 2),
    ("$code_type", 2): _pi("code_type", 2),
    ("$term_variables", 2): _pi("term_variables", 2),
    ("string_to_atom", 2): _pi("atom_string", 2),
    # the library's folds raise the errors of their `is`
    **{key: _pi("is", 2) for key in [("sum_list", 2), ("sumlist", 2), ("max_list", 2),
                                      ("min_list", 2)]},
    **{key: None for key in [
        ("numlist", 3), ("list_to_set", 2), ("max_member", 2), ("min_member", 2),
        ("reverse", 2), ("interpolate", 3), ("extrapolate", 2), ("distance", 3),
        ("pos_multiply", 2), ("tf_lookup", 4), ("tf_lookup", 5), ("prev", 2), ("next", 2),
        ("next", 3), ("origin", 2), ("get_field", 3)]},
}

# SWI-Prolog's C code names some errors' predicate without its module: a conversion's
# first argument that is not of its type, or a text that is no number (syntax_error)
_FIRST_ARGUMENT_TYPES = {("atom_chars", 2): "atom", ("atom_codes", 2): "atom",
                         ("number_codes", 2): "number", ("number_chars", 2): "number",
                         ("name", 2): "atomic",
                         ("number_string", 2): "number"}


def _unbound_element(items: Any) -> bool:
    """Whether the list ``items`` has an unbound element before its end."""
    items = deref(items)
    while type(items) is Struct and items.name == "." and len(items.args) == 2:
        if type(deref(items.args[0])) is Var:
            return True
        items = deref(items.args[1])
    return False


def error_context(key: tuple[str, int], formal: Any = None, args: tuple = ()) -> Any:
    """The predicate indicator SWI-Prolog names in the context of the error ``formal`` that
    the builtin ``key`` (called with ``args``) raises, or None where it leaves the context
    unbound.

    >>> str(error_context(("atom_length", 2)))
    'system:atom_length/2'
    >>> error_context(("numlist", 3)) is None
    True
    """
    kind = formal.name if type(formal) is Struct else formal
    what = deref(formal.args[0]) if type(formal) is Struct and formal.args else None
    name, arity = key
    if key in _FIRST_ARGUMENT_TYPES:
        if kind == "syntax_error" or (kind == "type_error" and what == _FIRST_ARGUMENT_TYPES[key]):
            return _pi(name, arity, None)
    elif key == ("arg", 3):
        # (the term's errors; N's are the module's)
        if kind == "instantiation_error" or (kind == "type_error" and what == "compound"):
            return _pi("arg", 3, None)
    elif key in (("$char_type", 2), ("$code_type", 2)):
        if kind == "instantiation_error" or (kind == "type_error" and what == "char_type"):
            return _pi("char_type", 2, None)
    elif key == ("keysort", 2):
        # an element's errors (a partial list's are the module's)
        if (kind == "type_error" and what == "pair") or (
                kind == "instantiation_error" and args and _unbound_element(args[0])):
            return _pi("keysort", 2, None)
    elif name == "format" and arity >= 2 and (
            kind == "instantiation_error" and type(deref(args[-2])) is Var
            or kind == "type_error" and what == "text"):
        return _pi("format", arity, None)   # the format text unbound or no text
    if kind == "syntax_error":
        return None   # (SWI-Prolog's context of a syntax error is the text and where in it)
    if key in _OTHER_CONTEXTS:
        return _OTHER_CONTEXTS[key]
    if name.startswith("$"):
        return None
    return _pi(name, arity)


def in_builtin(exc: SLREvaluationError, key: tuple[str, int], args: tuple = ()) -> SLREvaluationError:
    """``exc``, raised by the builtin ``key`` called with ``args``, with its context as
    SWI-Prolog gives it (an arithmetic function's own error keeps the function's).

    >>> str(in_builtin(instantiation_error(), ("atom_length", 2)))
    'error(instantiation_error,context(system:atom_length/2,_))'
    >>> str(in_builtin(instantiation_error(), ("numlist", 3)))
    'error(instantiation_error,_)'
    """
    term = exc.term
    if not (type(term) is Struct and term.name == "error" and len(term.args) == 2):
        return exc
    context = deref(term.args[1])
    if type(context) is not Var and not (
            type(context) is Struct and context.name == "context" and len(context.args) == 2
            and type(deref(context.args[0])) is Var):
        return exc
    culprit = error_context(key, deref(term.args[0]), args)
    return exc if culprit is None else with_context(exc, culprit)


def _err_domain(domain: str, culprit: Any) -> SLREvaluationError:
    return iso_error(Struct("domain_error", (Atom(domain), culprit)))


# -- unification and comparison -------------------------------------------------------------

@det("=", 2)
def _eq(m, a):
    return m.unify(a[0], a[1])


@det("\\=", 2)
def _neq(m, a):
    mark = len(m.trail)
    ok = m.unify(a[0], a[1])
    m.undo_to(mark)
    return not ok


@det("==", 2)
def _ident(m, a):
    return compare_terms(a[0], a[1]) == 0


@det("\\==", 2)
def _nident(m, a):
    return compare_terms(a[0], a[1]) != 0


def _type_rank(t: Any) -> int:
    tt = type(t)
    if tt is Var:
        return 0
    if tt is int or tt is float:
        return 1
    if tt is String:  # SWI-Prolog 9 orders strings before atoms: Var < Number < String < Atom
        return 2
    if tt is Atom:
        # SWI-Prolog 7's [] is a reserved symbol, no atom: it sorts after the strings and
        # before every atom ('' included), not as the text '[]' among them
        return 3 if t == "[]" else 4
    return 5


def compare_terms(a: Any, b: Any) -> int:
    """Standard order of terms as SWI-Prolog 9 has it: Var < Number < String < Atom < Compound.

    Iterative (arguments left to right from an explicit stack, so terms nested 100,000
    deep compare), and finite on cyclic terms: a pair of compounds met again inside itself
    adds nothing to the comparison.

    >>> compare_terms(1, Atom("a")), compare_terms(1.0, 1), compare_terms(Atom("b"), Atom("a"))
    (-1, -1, 1)
    """
    stack = None
    seen = None  # pairs of compounds reached through a binding (cycles pass through one)
    while True:
        via = False
        while type(a) is Var and a.ref is not None:
            a = a.ref
            via = True
        while type(b) is Var and b.ref is not None:
            b = b.ref
            via = True
        if a is not b:
            ra, rb = _type_rank(a), _type_rank(b)
            if ra != rb:
                return -1 if ra < rb else 1
            if ra == 1:
                if a == b:
                    if type(a) is not type(b):
                        return -1 if type(a) is float else 1
                    if type(a) is float and not a:
                        # -0.0 before 0.0 (SWI-Prolog): equal numbers, two terms
                        sa, sb = math.copysign(1.0, a), math.copysign(1.0, b)
                        if sa != sb:
                            return -1 if sa < sb else 1
                else:
                    return -1 if a < b else 1
            elif ra == 4 or ra == 2:
                if a != b:
                    return -1 if str(a) < str(b) else 1
            elif ra == 3:
                pass   # [] and [] (the only term of its rank)
            elif ra == 0:
                return -1 if a.age < b.age else 1
            else:
                # compound: arity, name, then arguments left to right
                na, nb = len(a.args), len(b.args)
                if na != nb:
                    return -1 if na < nb else 1
                if a.name != b.name:
                    # a list cell is named '[|]' in SWI-Prolog 7 (functor/3 says so), not
                    # '.': [a] sorts after 'Z'(1, 2) and before a(1, 2)
                    name_a = "[|]" if na == 2 and a.name == "." else str(a.name)
                    name_b = "[|]" if nb == 2 and b.name == "." else str(b.name)
                    return -1 if name_a < name_b else 1
                pair_seen = False
                if via:
                    key = (id(a), id(b))
                    if seen is None:
                        seen = set()
                    pair_seen = key in seen
                    seen.add(key)
                # a compound of no arguments (Struct("f", ()) from Python or JSON, as
                # SWI-Prolog 7's f()) equals one of the same name: nothing to descend into
                if not pair_seen and na:
                    if stack is None:
                        stack = []
                    stack.extend(zip(reversed(a.args[1:]), reversed(b.args[1:])))
                    a, b = a.args[0], b.args[0]
                    continue
        if not stack:
            return 0
        a, b = stack.pop()


_cmp_key = functools.cmp_to_key(compare_terms)

for _op, _test in (("@<", lambda c: c < 0), ("@>", lambda c: c > 0),
                   ("@=<", lambda c: c <= 0), ("@>=", lambda c: c >= 0)):
    DET[(_op, 2)] = (lambda test: lambda m, a: test(compare_terms(a[0], a[1])))(_test)


@det("compare", 3)
def _compare(m, a):
    order = deref(a[0])
    if type(order) is not Var:
        # a bound order is checked first, as SWI-Prolog does (compare(=, a, b) fails)
        if type(order) is not Atom:
            raise type_error("atom", order)
        if order not in ("<", "=", ">"):
            raise _err_domain("order", order)
    c = compare_terms(a[1], a[2])
    return m.unify(a[0], Atom("<" if c < 0 else ">" if c > 0 else "="))


# -- arithmetic -------------------------------------------------------------------------------

@det("is", 2)
def _is(m, a):
    return m.unify(a[0], evaluate(a[1]))


for _op, _test in (("=:=", lambda x, y: x == y), ("=\\=", lambda x, y: x != y),
                   ("<", lambda x, y: x < y), (">", lambda x, y: x > y),
                   ("=<", lambda x, y: x <= y), (">=", lambda x, y: x >= y)):
    DET[(_op, 2)] = (lambda test: lambda m, a: test(evaluate(a[0]), evaluate(a[1])))(_test)


@det("succ", 2)
def _succ(m, a):
    """succ(X, Y): Y = X + 1 over the natural numbers. As SWI-Prolog: each bound argument
    is checked in turn, type_error(integer, V) or domain_error(not_less_than_zero, V)."""
    x, y = deref(a[0]), deref(a[1])
    for v in (x, y):
        if type(v) is not Var:
            if type(v) is not int:
                raise type_error("integer", v)
            if v < 0:
                raise _err_domain("not_less_than_zero", v)
    if type(x) is int:
        return m.unify(y, x + 1)
    if type(y) is int:
        return y > 0 and m.unify(x, y - 1)
    raise instantiation_error()


@det("plus", 3)
def _plus(m, a):
    """plus(X, Y, Z): Z = X + Y over the integers, any two given. As SWI-Prolog: each bound
    argument must be an integer (type_error(integer, V), not evaluated), then two bound."""
    x, y, z = (deref(v) for v in a)
    for v in (x, y, z):
        if type(v) is not Var and type(v) is not int:
            raise type_error("integer", v)
    if type(z) is Var:
        if type(x) is Var or type(y) is Var:
            raise instantiation_error()
        return m.unify(z, x + y)
    if type(y) is Var:
        if type(x) is Var:
            raise instantiation_error()
        return m.unify(y, z - x)
    if type(x) is Var:
        return m.unify(x, z - y)
    return x + y == z


@nondet("between", 3)
def _between(m, a):
    lo = deref(a[0])
    hi = deref(a[1])
    x = deref(a[2])
    # (each bound argument checked in turn, as SWI-Prolog: between(a, H, X) is a type error)
    if type(lo) is Var:
        raise instantiation_error()
    if type(lo) is not int:
        raise type_error("integer", lo)
    if type(hi) is Var:
        raise instantiation_error()
    if hi in ("inf", "infinite") and type(hi) is Atom:
        hi = math.inf
    elif type(hi) is not int:
        raise type_error("integer", hi)
    if type(x) is int:
        if lo <= x <= hi:
            yield None
        return
    if type(x) is not Var:
        raise type_error("integer", x)
    i = lo
    trail = m.trail
    while i <= hi:
        x.ref = i
        trail.append(x)
        yield None
        i += 1



@nondet("$repeat", 0)
def _repeat(m, a):
    # ISO's repeat/0 (the library's repeat calls it): succeeds again on every backtrack. The
    # engine counts each retry as a step, so `repeat, fail` ends at the query's max_steps or
    # timeout like any endless loop.
    while True:
        yield None

# -- type checks -------------------------------------------------------------------------------

def _typecheck(name, test):
    DET[(name, 1)] = lambda m, a: test(deref(a[0]))


_typecheck("var", lambda t: type(t) is Var)
_typecheck("nonvar", lambda t: type(t) is not Var)
_typecheck("atom", lambda t: type(t) is Atom and t != "[]")  # SWI-7: [] is no atom
_typecheck("number", lambda t: type(t) in (int, float))
_typecheck("integer", lambda t: type(t) is int)
_typecheck("float", lambda t: type(t) is float)
_typecheck("atomic", lambda t: type(t) in (Atom, int, float, String))
_typecheck("compound", lambda t: type(t) is Struct)
_typecheck("callable", lambda t: type(t) is Struct or (type(t) is Atom and t != "[]"))  # [] too
_typecheck("is_list", lambda t: list_items(t)[1] == "[]" and type(list_items(t)[1]) is Atom)
_typecheck("string", lambda t: type(t) is String)
_typecheck("ground", is_ground)


# -- term construction ----------------------------------------------------------------------------

@det("functor", 3)
def _functor(m, a):
    t = deref(a[0])
    if type(t) is Struct:
        return m.unify(a[1], _visible_name(t)) and m.unify(a[2], len(t.args))
    if type(t) is not Var:
        return m.unify(a[1], t) and m.unify(a[2], 0)
    name = deref(a[1])
    n = deref(a[2])
    if type(name) is Struct:
        raise type_error("atomic", name)   # (before the arity, as SWI-Prolog checks)
    if type(name) is Var or type(n) is Var:
        raise instantiation_error()
    if type(n) is not int:
        raise type_error("integer", n)
    if n == 0:
        return m.unify(t, name)
    if type(name) is not Atom:
        raise type_error("atomic" if type(name) is Struct else "atom", name)
    if n < 0:
        raise _err_domain("not_less_than_zero", n)
    # the arguments as a (deadline-checked, bounded) list first: functor(F, f, 10**8)
    # is a resource error, not minutes of allocation
    args, _ = list_items(build_list(m, n, lambda _: Var()))
    return m.unify(t, Struct(_internal_name(name, n), tuple(args)))


# SWI-Prolog 7 names the list cell '[|]' (functor/3, =../2 show it, and build a list from
# it); inside, a cell is the compound '.'/2, as the parser and the store encode it.
LIST_CELL = Atom("[|]")


def _visible_name(t: Struct) -> Atom:
    return LIST_CELL if t.name == "." and len(t.args) == 2 else t.name


def _internal_name(name: Atom, arity: int) -> Atom:
    return CONS if arity == 2 and name == "[|]" else name


@nondet("arg", 3)
def _arg(m, a):
    n = deref(a[0])
    t = deref(a[1])
    if type(t) is Var:
        raise instantiation_error()
    if type(t) is not Struct:
        raise type_error("compound", t)
    if type(n) is int:
        if n < 0:   # (0 fails, as SWI-Prolog: no argument, no error)
            raise _err_domain("not_less_than_zero", n)
        if 1 <= n <= len(t.args) and m.unify(a[2], t.args[n - 1]):
            yield None
        return
    if type(n) is not Var:
        raise type_error("integer", n)
    for i, x in enumerate(t.args, 1):
        mark = len(m.trail)
        if m.unify(n, i) and m.unify(a[2], x):
            yield None
        m.undo_to(mark)


@det("=..", 2)
def _univ(m, a):
    t = deref(a[0])
    items, tail = list_items(a[1])
    if type(t) is not Var:
        name = _visible_name(t) if type(t) is Struct else t
        # a given list is a list or a partial one (SWI-Prolog: after its first element is
        # compared with the name, the tail is the culprit)
        if type(tail) is not Var and not (type(tail) is Atom and tail == "[]"):
            if items:
                mark = len(m.trail)
                same = m.unify(items[0], name)
                m.undo_to(mark)
                if not same:
                    return False
            raise type_error("list", tail)
        if type(t) is Struct:
            return m.unify(a[1], make_list((name,) + t.args))
        return m.unify(a[1], make_list([t]))
    if not items and type(tail) is Atom and tail == "[]":
        raise _err_domain("non_empty_list", NIL)
    head = deref(items[0]) if items else None
    # the name is checked before the rest of the list (SWI-Prolog: X =.. [f(x)|_] is
    # type_error(atom, f(x))), then the list: a partial one is an instantiation error, a
    # tail that is no list type_error(list, List)
    if items and len(items) > 1 and type(head) is not Var and \
            (type(head) is not Atom or head == "[]"):
        raise type_error("atom", head)
    if type(tail) is Var:
        if items and type(head) is not Var and type(head) is not Atom:
            raise type_error("atom", head)
        raise instantiation_error()
    if not (type(tail) is Atom and tail == "[]"):
        raise type_error("list", deref(a[1]))
    if len(items) == 1:
        if type(head) is Var:
            raise instantiation_error()
        if type(head) is Struct:
            raise type_error("atomic", head)
        return m.unify(t, head)
    if type(head) is Var:
        raise instantiation_error()
    return m.unify(t, Struct(_internal_name(head, len(items) - 1), tuple(items[1:])))


@det("copy_term", 2)
def _copy_term(m, a):
    return m.unify(a[1], copy_term(a[0], deadline=m.deadline))


@det("$term_variables", 2)
def _term_variables(m, a):
    return m.unify(a[1], make_list(term_vars(a[0], m.deadline)))


@det("$skip_list", 3)
def _skip_list(m, a):
    # SWI-Prolog's '$skip_list'(Length, List, Tail): the cells of List before Tail, the first
    # thing that is no list cell (unbound, [], another term; a cell again on a cyclic list)
    items, tail = list_items(a[1])
    return m.unify(a[0], len(items)) and m.unify(a[2], tail)


def _ord_merge(op: str, xs: list, ys: list, m) -> list:
    """The ordered-set operation ``op`` of two proper lists, as library(ordsets)' clauses
    compute it (the same comparisons in the same order), in one pass."""
    out: list = []
    i = j = 0
    nx, ny = len(xs), len(ys)
    clock = _CELLS_PER_DEADLINE_CHECK
    while i < nx and j < ny:
        clock -= 1
        if not clock:
            clock = _CELLS_PER_DEADLINE_CHECK
            m.check_deadline()
        c = compare_terms(xs[i], ys[j])
        if c < 0:
            if op != "intersection":
                out.append(xs[i])
            i += 1
        elif c > 0:
            if op == "union":
                out.append(ys[j])
            j += 1
        else:
            if op != "subtract":
                out.append(xs[i])
            i += 1
            j += 1
    if op != "intersection":
        out.extend(xs[i:])
    if op == "union":
        out.extend(ys[j:])
    return out


def _ord_memberchk(item: Any, xs: list) -> bool:
    """library(ordsets)' ord_memberchk/2 on a proper list: its comparisons, four at a time."""
    i, n = 0, len(xs)
    while n - i >= 4:
        r4 = compare_terms(item, xs[i + 3])
        if r4 > 0:
            i += 4
            continue
        if r4 == 0:
            return True
        r2 = compare_terms(item, xs[i + 1])
        if r2 > 0:
            return compare_terms(item, xs[i + 2]) == 0
        return r2 == 0 or compare_terms(item, xs[i]) == 0
    if n - i >= 2:
        r2 = compare_terms(item, xs[i + 1])
        if r2 > 0:
            return n - i == 3 and compare_terms(item, xs[i + 2]) == 0
        return r2 == 0 or compare_terms(item, xs[i]) == 0
    return n - i == 1 and compare_terms(item, xs[i]) == 0


def _proper(t: Any) -> list | None:
    items, tail = list_items(t)
    return items if type(tail) is Atom and tail == "[]" else None


@det("$ord_fast", 4)
def _ord_fast(m, a):
    # '$ord_fast'(Op, A, B, Out): the ordered-set operation in one pass where it answers as
    # the library's clauses would: proper lists in, and (union, subtract, intersection) an
    # Out that is unbound and in neither list, so binding it cannot change a comparison.
    # Fails where it does not apply: the library's clauses run then.
    op = str(deref(a[0]))
    if op == "memberchk":
        ys = _proper(a[2])
        return ys is not None and m.unify(a[3], Atom("true" if _ord_memberchk(a[1], ys) else "false"))
    out = deref(a[3])
    if type(out) is not Var:
        return False
    xs, ys = _proper(a[1]), _proper(a[2])
    if xs is None or ys is None or _occurs(out, Struct("-", (a[1], a[2])), m.deadline):
        return False
    return m.unify(out, make_list(_ord_merge(op, xs, ys, m)))


def _occurs(v: Var, t: Any, deadline: float | None) -> bool:
    """Whether the unbound variable ``v`` occurs in ``t`` (each shared compound walked once)."""
    stack = [t]
    seen: set[int] = set()
    clock = NODES_BETWEEN_CLOCK_CHECKS
    while stack:
        x = deref(stack.pop())
        if x is v:
            return True
        if type(x) is Struct and id(x) not in seen:
            seen.add(id(x))
            clock -= 1
            if not clock:
                clock = NODES_BETWEEN_CLOCK_CHECKS
                check_deadline(deadline)
            stack.extend(x.args)
    return False


@det("$unify_with_occurs_check", 2)
def _unify_with_occurs_check(m, a):
    """ISO 8.2.2: unify, failing where a variable would be bound to a term it occurs in."""
    mark = len(m.trail)
    stack = [(a[0], a[1])]
    # pairs of compounds already unified: shared (and cyclic) terms are walked as graphs
    seen: set[tuple[int, int]] = set()
    clock = NODES_BETWEEN_CLOCK_CHECKS
    while stack:
        x, y = stack.pop()
        x, y = deref(x), deref(y)
        if x is y:
            continue
        clock -= 1
        if not clock:
            clock = NODES_BETWEEN_CLOCK_CHECKS
            check_deadline(m.deadline)
        if type(x) is Var or type(y) is Var:
            v, t = (x, y) if type(x) is Var else (y, x)
            if type(t) is not Var and _occurs(v, t, m.deadline):
                m.undo_to(mark)
                return False
            m.unify(v, t)
        elif type(x) is Struct and type(y) is Struct:
            if x.name != y.name or len(x.args) != len(y.args):
                m.undo_to(mark)
                return False
            key = (id(x), id(y))
            if key not in seen:
                seen.add(key)
                stack.extend(zip(reversed(x.args), reversed(y.args)))
        elif not m.unify(x, y):
            m.undo_to(mark)
            return False
    return True


# -- atoms and strings -------------------------------------------------------------------------------

def text_of(t: Any, what: str = "atomic") -> str:
    """The text of an atomic term, or of a list of characters or codes, as the text
    builtins (atom_length/2, sub_atom/5, ...) read their arguments; an unbound term is an
    instantiation error.

    >>> text_of(Atom("cup")), text_of(12), text_of(2.5), text_of(make_list([104, 105]))
    ('cup', '12', '2.5', 'hi')
    """
    t = deref(t)
    tt = type(t)
    if tt is Var:
        raise instantiation_error()
    if tt is Atom or tt is String:
        return str(t)
    if tt is int:
        return int_text(t)
    if tt is float:
        from .terms import format_term

        return format_term(t)
    if tt is Struct:
        items, tail = list_items(t)
        if tail == "[]" and type(tail) is Atom:
            try:
                return "".join(chr(deref(x)) if type(deref(x)) is int else str(deref(x))
                               for x in items)
            except (TypeError, ValueError, OverflowError):  # not a character code
                pass
    raise type_error(what, t)


# -- the classic atom builtins, as SWI-Prolog 7+ has them (its answers and errors are the
# contract, docs/semantics.md): the text of an atom, a string or a number is accepted where
# an atom is read; `[]` is not an atom (SWI-7), compounds are type errors.

def _atom_text(t: Any, compound_error: str = "atomic", nil_error: str = "atom") -> str:
    """The text of an atomic argument read as an atom: an unbound one is an instantiation
    error, ``[]`` a ``type_error(nil_error, [])``, a compound ``type_error(compound_error, _)``."""
    t = deref(t)
    tt = type(t)
    if tt is Var:
        raise instantiation_error()
    if tt is Atom:
        if t == "[]":
            raise type_error(nil_error, t)
        return str(t)
    if tt is String:
        return str(t)
    if tt is int:
        return int_text(t)
    if tt is float:
        from .terms import format_term

        return format_term(t)
    raise type_error(compound_error, t)


def _list_text(t: Any) -> str:
    """The text of a code or character list or a string: a partial list is an
    instantiation error, anything else a type error. As SWI-Prolog 9, the first element
    says which kind of list it is: a code after characters is type_error(character, C), a
    character after codes type_error(character_code, C)."""
    t = deref(t)
    if type(t) is String:
        return str(t)
    items, tail = list_items(t)
    if type(tail) is Var:
        raise instantiation_error()
    if not (type(tail) is Atom and tail == "[]"):
        raise type_error("list", t)
    out = []
    first = deref(items[0]) if items else None
    chars = type(first) is Atom and len(first) == 1
    for x in items:
        x = deref(x)
        if type(x) is Var:
            raise instantiation_error()
        if type(x) is int and not chars:
            if not 0 <= x <= 0x10FFFF or 0xD800 <= x <= 0xDFFF:
                raise type_error("character_code", x)
            out.append(chr(x))
        elif type(x) is Atom and len(x) == 1 and chars:
            out.append(str(x))
        else:
            raise type_error("character" if chars else "character_code", x)
    return "".join(out)


def _code_or_char_list_text(t: Any) -> str:
    """The text of a list as SWI-Prolog's atom_length/2 reads one: its first element makes
    it a character list (a one-character atom) or a code list, and every element must be
    of that kind (``type_error(character, X)`` / ``type_error(character_code, X)``); a
    partial list is an instantiation error, another tail ``type_error(text, List)``.

    >>> _code_or_char_list_text(make_list([104, 105])), _code_or_char_list_text(make_list([Atom("a")]))
    ('hi', 'a')
    """
    items, tail = list_items(t)
    if type(tail) is Var:
        raise instantiation_error()
    if not (type(tail) is Atom and tail == "[]"):
        raise type_error("text", t)
    first = deref(items[0]) if items else None
    chars = type(first) is Atom and len(first) == 1
    out = []
    for x in items:
        x = deref(x)
        if type(x) is Var:
            raise instantiation_error()
        if chars:
            if not (type(x) is Atom and len(x) == 1):
                raise type_error("character", x)
            out.append(str(x))
        else:
            if type(x) is not int or not 0 <= x <= 0x10FFFF or 0xD800 <= x <= 0xDFFF:
                raise type_error("character_code", x)
            out.append(chr(x))
    return "".join(out)


def _number_of_text(s: str, leading_layout: bool, bare_quote_is_zero: bool = True) -> Any:
    r"""The number a text is in Prolog syntax (an optional sign, then a number token: 12,
    -1.5, 0x1A, 0'a, 1.0Inf), or None. ``leading_layout`` allows spaces before it (as
    number_codes/2 does; atom_number/2 and name/2 do not).

    A character code is read as SWI-Prolog's number texts read it, not as its reader does:
    ``0'`` and the one character after it, whatever it is (a space, a newline, a backslash:
    no escape), or a doubled quote; the text ``0'`` alone is 0 (``bare_quote_is_zero``:
    all but atom_number/2, which fails on it).

    >>> _number_of_text("0' ", False), _number_of_text("-0'\\", False), _number_of_text("0'\\n", False)
    (32, -92, None)
    >>> _number_of_text("0'", False), _number_of_text("0'", False, bare_quote_is_zero=False)
    (0, None)
    """
    if s == "0'":
        return 0 if bare_quote_is_zero else None
    if leading_layout:
        s = s.lstrip()
    sign = 1
    if s[:1] in ("-", "+"):
        sign = -1 if s[0] == "-" else 1
        s = s[1:]
    if s.startswith("0'"):
        code = s[2:]
        if code == "''":
            code = "'"
        return sign * ord(code) if len(code) == 1 else None
    if s != s.rstrip():
        return None  # "3 " is no number, in any of the three
    if not s[:1].isdigit():
        return None
    from .parser import parse_term, token_spans

    try:
        t, _ = parse_term(s)
        # the reader takes an end '.' after a term, a number's text has none ("1." and
        # "1.0." are no numbers, as in SWI-Prolog): with one already there, a second fails
        parse_term(s + "\n.")
    except SLRError:
        return None
    # nor a comment after it: the reader skips "1/**/" and "1%c" to 1, but the number token
    # must be the whole text (SWI-Prolog: illegal_number); the text parsed, so it lexes
    spans = token_spans(s)
    if len(spans) != 1 or spans[0][1] != len(s):
        return None
    t = deref(t)
    if type(t) is not int and type(t) is not float:
        return None
    return -t if sign < 0 else t


@nondet("atom_concat", 3)
def _atom_concat(m, a):
    x, y = deref(a[0]), deref(a[1])
    if type(x) is not Var and type(y) is not Var:
        joined = _atom_text(x) + _atom_text(y)
        if type(deref(a[2])) is not Var:
            # a given whole is atomic text, compared as text (atom_concat(a, b, "ab"))
            if _atom_text(a[2]) == joined:
                yield None
            return
        if m.unify(a[2], Atom(joined)):
            yield None
        return
    # a bound part is checked (type errors, before the whole's) and pins the split
    px = _atom_text(x) if type(x) is not Var else None
    py = _atom_text(y) if type(y) is not Var else None
    z = deref(a[2])
    if type(z) is Var:
        raise instantiation_error()
    s = _atom_text(z)
    if px is not None:
        if s.startswith(px) and m.unify(y, Atom(s[len(px):])):
            yield None
        return
    if py is not None:
        if s.endswith(py) and m.unify(x, Atom(s[:len(s) - len(py)])):
            yield None
        return
    for i in range(len(s) + 1):
        mark = len(m.trail)
        if m.unify(x, Atom(s[:i])) and m.unify(y, Atom(s[i:])):
            yield None
        m.undo_to(mark)


def _length_argument(t: Any) -> Any:
    """The length argument of atom_length/2 and sub_atom/5: unbound or an integer."""
    t = deref(t)
    if type(t) is not Var and type(t) is not int:
        raise type_error("integer", t)
    return t


@det("atom_length", 2)
def _atom_length(m, a):
    t = deref(a[0])
    if type(t) is Atom and t == "[]":
        text = ""   # as SWI-Prolog 7: [] has no characters of its own
    elif type(t) is Struct and t.name == "." and len(t.args) == 2:
        text = _code_or_char_list_text(t)   # a code or character list is text too (SWI)
    else:
        text = _atom_text(t, "text")
    # (the text's errors first, then the length's, as SWI-Prolog checks)
    return m.unify(_length_argument(a[1]), len(text))


def text_in(t: Any, mode: str, expected: str = "text", numbers: bool = True) -> str:
    """The text of a builtin's text argument as SWI-Prolog 9 reads it, by ``mode``:

    * ``"any"``: an atom, a string, a number, or a code or character list (its first element
      says which; a bad element is type_error(character_code | character, E), a partial list
      an instantiation error); ``[]`` is the empty text; else type_error(``expected``, T)
      (string_length/2, string_chars/2, ...).
    * ``"no_number"``: "any" but a number (split_string/4, string_code/3).
    * ``"whole"``: "any", but a list that is no text is type_error(``expected``, List) as a
      whole (atom_string/2, string_to_atom/2; without ``numbers``, format/2's format).
    * ``"atomic"``: an atom, a string or a number; ``[]`` is type_error(atom, []), a list or
      compound type_error(atomic, T) (string_concat/3).
    * ``"list"``: a string or a code or character list, as "any"; else type_error(list, T)
      (string_chars/2 and string_codes/2 from the list).

    >>> text_in(make_list([Atom("h"), Atom("i")]), "any"), text_in(NIL, "any"), text_in(12, "any")
    ('hi', '', '12')
    >>> text_in(make_list([Atom("h"), 105]), "any")
    Traceback (most recent call last):
    slr_sql.errors.SLREvaluationError: error(type_error(character,105),_)
    >>> text_in(make_list([Atom("h"), 105]), "whole", "atom")
    Traceback (most recent call last):
    slr_sql.errors.SLREvaluationError: error(type_error(atom,[h,105]),_)
    """
    t = deref(t)
    tt = type(t)
    if tt is Var:
        raise instantiation_error()
    if tt is String:
        return str(t)
    if mode == "list":
        if tt is Struct or (tt is Atom and t == "[]"):
            return _list_text(t)
        raise type_error("list", t)
    if tt is Atom:
        if t != "[]":
            return str(t)
        if mode == "atomic":
            raise type_error("atom", t)
        return ""
    if tt is int or tt is float:
        if mode == "no_number" or not numbers:
            raise type_error(expected, t)
        return text_of(t)
    if mode == "atomic":
        raise type_error("atomic", t)
    if tt is Struct and t.name == "." and len(t.args) == 2:
        if mode != "whole":
            return _code_or_char_list_text(t)
        try:
            return _code_or_char_list_text(t)
        except SLREvaluationError:
            raise type_error(expected, t) from None
    raise type_error(expected, t)


@det("string_length", 2)
def _string_length(m, a):
    text = text_in(a[0], "any")   # (the text's errors first, as SWI-Prolog checks)
    return m.unify(_length_argument(a[1]), len(text))


def _from_text(make: Callable[[str], Any], parse: Callable[[str], Any]):
    """atom_codes/2 and atom_chars/2: from the atom when it is bound, else from the list."""
    def f(m, a):
        x = deref(a[0])
        if type(x) is not Var:
            text = _atom_text(x, "atom")
            if m.unify(a[1], make(text)):
                return True
            if not _is_text_given(a[1]):
                return False
            # as SWI-Prolog's: a given text that is not the list made from the first
            # argument is read as in the other mode (its type errors; a character list for
            # atom_codes, a code list for atom_chars too, a string) and the atom of that text
            # unified with the first argument -- so only an atom is equal to a string there:
            # atom_chars(ab, "ab") is true, atom_chars("", "") and atom_chars(1, "1") false
            return m.unify(x, Atom(_list_text(a[1])))
        return m.unify(x, parse(_list_text(a[1])))
    return f


DET[("atom_codes", 2)] = _from_text(lambda s: make_list([ord(c) for c in s]), Atom)
DET[("atom_chars", 2)] = _from_text(lambda s: make_list([Atom(c) for c in s]), Atom)


@det("name", 2)
def _name(m, a):
    """name(AtomOrNumber, Codes): a text that is a number (no leading layout) gives the
    number, any other text an atom."""
    x = deref(a[0])
    if type(x) is not Var:
        # as SWI-Prolog's: the codes of the first argument's text, else a given text read
        # (name("ab", [97, 98]) and name('12', [0'1, 0'2]) are true, name(1, "01") too)
        if m.unify(a[1], make_list([ord(c) for c in _atom_text(x, "atomic", "atomic")])):
            return True
        if not _is_text_given(a[1]):
            return False
    text = _list_text(a[1])
    n = _number_of_text(text, leading_layout=False)
    return m.unify(x, Atom(text) if n is None else n)


def _is_text_given(t: Any) -> bool:
    """A ground text argument (a string, a list with no variable in it, anything else but a
    variable): number_codes/2 and name/2 read it even when the other argument is given, as
    SWI-Prolog does (number_codes(1, "01") is true, number_codes(1, foo) a type error);
    a partial one is compared with the text of the given term (number_codes(12, [X, Y]))."""
    t = deref(t)
    if type(t) is Var:
        return False
    if type(t) is not Struct:
        return True
    items, tail = list_items(t)
    return type(tail) is not Var and all(type(deref(x)) is not Var for x in items)


def _number_text(m: "Machine", a: tuple, make: Callable[[str], Any]) -> bool:
    """number_codes/2 (``make`` a code list) and number_chars/2 (a character list): from
    the number when it is bound and the text is not, else the text read as a number (a
    code or character list or a string for either, as SWI-Prolog's; leading layout
    allowed) and unified with the first argument."""
    x = deref(a[0])
    if type(x) is not Var:
        if type(x) is not int and type(x) is not float:
            raise type_error("number", x)
        if not _is_text_given(a[1]):
            return m.unify(a[1], make(_atom_text(x)))
    n = _number_of_text(_list_text(a[1]), leading_layout=True)
    if n is None:
        raise iso_error(Struct("syntax_error", (Atom("illegal_number"),)))
    return m.unify(x, n)


DET[("number_codes", 2)] = lambda m, a: _number_text(
    m, a, lambda s: make_list([ord(c) for c in s]))
DET[("number_chars", 2)] = lambda m, a: _number_text(
    m, a, lambda s: make_list([Atom(c) for c in s]))


@det("atom_number", 2)
def _atom_number(m, a):
    """atom_number/2 as SWI-Prolog's library clauses: an atom's (or a string's) text is
    read as a number (no number: false); else a given number makes the atom (any other
    first argument then fails to unify); else a bound second argument must be a number,
    and the first an atom."""
    x = deref(a[0])
    if type(x) is String or type(x) is Atom and x != "[]":
        n = _number_of_text(str(x), leading_layout=False, bare_quote_is_zero=False)
        return n is not None and m.unify(a[1], n)
    n = deref(a[1])
    if type(n) is int or type(n) is float:
        return m.unify(x, Atom(_atom_text(n)))
    if type(n) is not Var:
        raise type_error("number", n)
    if type(x) is Var:
        raise instantiation_error()
    raise type_error("atom", x)


def _term_text(m: "Machine", a: list, make: Callable[[str], Any]) -> bool:
    """term_to_atom/2 (``make``: Atom) and term_string/2 (String)."""
    from .terms import format_term, prolog_var_name

    t = deref(a[0])
    text = deref(a[1])
    if type(text) is not Var:  # as SWI-Prolog: a given text is read, then unified
        # (a code or character list is text too, [] the empty one)
        source = "" if text == NIL else _code_or_char_list_text(text) \
            if type(text) is Struct and text.name == CONS and len(text.args) == 2 \
            else _atom_text(text, "text")
        if not source.strip():
            return m.unify(t, Atom("end_of_file"))
        return m.unify(t, _parse_any(Atom(source)))
    # SWI-Prolog's term_to_atom writes a quote inside quotes doubled and a newline as it
    # is ('it''s'), where writeq writes 'it\'s' and '\n'
    return m.unify(text, make(format_term(t, deadline=m.deadline, char_escapes=False,
                                          var_names=prolog_var_name, cycle_names=False)))


DET[("term_to_atom", 2)] = lambda m, a: _term_text(m, a, Atom)


@det("atom_to_term", 3)
def _atom_to_term(m, a):
    """atom_to_term(Text, Term, Bindings) as SWI-Prolog's: Text (an atom, a string, a number,
    a code or character list) read as term_to_atom/2 reads it, Bindings the list of
    ``'Name' = Var`` of its named variables in the order they first appear (``_`` left
    out); a blank text is ``end_of_file`` with no bindings. Text must be bound, and
    Bindings a list or a partial list (else type_error(list, B), before the text is read)."""
    from .parser import parse_first_term

    text = deref(a[0])
    if type(text) is Var:
        raise instantiation_error()
    bindings = deref(a[2])
    if type(bindings) is not Var and bindings != NIL and not (
            type(bindings) is Struct and bindings.name == CONS and len(bindings.args) == 2):
        raise type_error("list", bindings)
    source = "" if text == NIL else _code_or_char_list_text(text) \
        if type(text) is Struct and text.name == CONS and len(text.args) == 2 \
        else _atom_text(text, "text")
    if not source.strip():
        return m.unify(a[1], Atom("end_of_file")) and m.unify(bindings, NIL)
    try:
        term, names = parse_first_term(source)
    except SLRSyntaxError as exc:
        raise iso_error(Struct("syntax_error", (Atom(exc.message),))) from None
    pairs = make_list([Struct("=", (Atom(name), v)) for name, v in names.items()])
    return m.unify(a[1], term) and m.unify(bindings, pairs)
# (as term_to_atom/2, the text a string: quoted as writeq quotes, where it was the text
# write/1 makes, term_string('A', S) giving "A")
DET[("term_string", 2)] = lambda m, a: _term_text(m, a, String)


def _case_converted(m, a, convert: Callable[[str], str]) -> bool:
    """upcase_atom/2, downcase_atom/2: a bound result (an atom, a string, a number) is
    compared as text; [] or a compound there is type_error(atom, R), as in SWI-Prolog."""
    out = convert(_atom_text(a[0]))
    r = deref(a[1])
    if type(r) is Var:
        return m.unify(r, Atom(out))
    if type(r) is Atom and r != "[]" or type(r) in (String, int, float):
        return text_of(r) == out
    raise type_error("atom", r)


def _simple_upper(ch: str) -> str:
    """One character's simple uppercase mapping (Unicode's one-character mapping, which
    SWI-Prolog's upcase_atom applies): ``str.upper`` where it gives one character; else the
    titlecase where that is one character (U+1F80 'ᾀ' -> U+1F88 'ᾈ'), else the character
    itself ('ß' stays 'ß', where ``str.upper`` gives 'SS').

    >>> _simple_upper("a"), _simple_upper("ß"), _simple_upper("\u1f80") == "\u1f88"
    ('A', 'ß', True)
    """
    u = ch.upper()
    if len(u) == 1:
        return u
    t = ch.title()
    return t if len(t) == 1 else ch


def _simple_lower(ch: str) -> str:
    """One character's simple lowercase mapping ('İ' -> 'i', where ``str.lower`` adds a
    combining dot; the only character whose full lowercase is longer).

    >>> _simple_lower("A"), _simple_lower("\u0130")
    ('a', 'i')
    """
    lo = ch.lower()
    return lo if len(lo) == 1 else lo[0]


def _upcase_text(text: str) -> str:
    """A text upper-cased one character at a time, as SWI-Prolog does (no 'ß' -> 'SS')."""
    return text.upper() if text.isascii() else "".join(map(_simple_upper, text))


def _downcase_text(text: str) -> str:
    """A text lower-cased one character at a time, as SWI-Prolog does: no final sigma
    ('ΑΣ' gives 'ασ', where ``str.lower`` gives 'ας'), 'İ' gives 'i'."""
    return text.lower() if text.isascii() else "".join(map(_simple_lower, text))


@det("upcase_atom", 2)
def _upcase(m, a):
    return _case_converted(m, a, _upcase_text)


def _string_case(m: "Machine", a: tuple, convert: Callable[[str], str]) -> bool:
    """string_upper/2, string_lower/2 as SWI-Prolog's: the text of an atom, a string or a
    number (a list is type_error(atomic, L), [] type_error(atom, [])) converted one
    character at a time, as a string; a given result (a string, an atom, a number) is
    compared as text, anything else there is type_error(string, R)."""
    out = convert(text_in(a[0], "atomic"))
    r = deref(a[1])
    if type(r) is Var:
        return m.unify(r, String(out))
    if type(r) is String or type(r) is Atom and r != "[]" or type(r) in (int, float):
        return text_of(r) == out
    raise type_error("string", r)


DET[("string_upper", 2)] = lambda m, a: _string_case(m, a, _upcase_text)
DET[("string_lower", 2)] = lambda m, a: _string_case(m, a, _downcase_text)


@nondet("sub_atom", 5)
def _sub_atom(m, a):
    return _sub_text(m, a, Atom, "atom")


@nondet("$sub_string", 5)
def _sub_string(m, a):
    """sub_string/5 as SWI-Prolog's: any text (atom, string, number) in, strings out."""
    return _sub_text(m, a, String, "string")


def _sub_text(m, a, make: Callable[[str], Any], what: str):
    s = _atom_text(a[0], what, what)
    bounds = []
    for k in (1, 2, 3):
        v = _length_argument(a[k])
        if type(v) is int and v < 0:
            raise _err_domain("not_less_than_zero", v)
        bounds.append(v)
    sub = deref(a[4])
    n = len(s)
    if type(sub) is not Var:
        t = _atom_text(sub, what, what)
        start = s.find(t)
        while start >= 0:
            mark = len(m.trail)
            if m.unify(a[1], start) and m.unify(a[2], len(t)) and m.unify(a[3], n - start - len(t)):
                yield None
            m.undo_to(mark)
            start = s.find(t, start + 1)
        return
    b0, l0, a0 = bounds
    for b in (range(n + 1) if type(b0) is Var else [b0] if b0 <= n else []):
        if type(l0) is int:
            lengths = [l0] if b + l0 <= n else []
        elif type(a0) is int:
            lengths = [n - b - a0] if n - b - a0 >= 0 else []
        else:
            lengths = range(n - b + 1)
        for length in lengths:
            mark = len(m.trail)
            if m.unify(a[1], b) and m.unify(a[2], length) and m.unify(a[3], n - b - length) \
                    and m.unify(sub, make(s[b:b + length])):
                yield None
            m.undo_to(mark)


# -- char_type/2, code_type/2 ------------------------------------------------------------------
# SWI-Prolog's character classes, in the order it enumerates them for a given character (csymf
# twice, as SWI-Prolog 9 lists it). Each test takes a code and gives None (not of the class),
# True (a class without argument) or the argument: a code ("char": a character for
# char_type/2, a code for code_type/2) or a weight (an integer for both). ASCII is as
# SWI-Prolog's; beyond it the classes come from Unicode's categories (SWI-Prolog asks the C
# library's locale tables, which differ at some characters).

# iswspace() of the C library: the 21 characters SWI-Prolog enumerates for space
_SPACES = (9, 10, 11, 12, 13, 32, 0x1680, 0x2000, 0x2001, 0x2002, 0x2003, 0x2004, 0x2005,
           0x2006, 0x2008, 0x2009, 0x200A, 0x2028, 0x2029, 0x205F, 0x3000)
_SPACE_SET = frozenset(_SPACES)
_PROLOG_SYMBOLS = frozenset(map(ord, "#$&*+-./:<=>?@\\^~"))


def _cat(c: int) -> str:
    return _ud.category(chr(c))


def _is_alnum(c: int) -> bool:
    cat = _cat(c)
    return cat[0] == "L" or cat == "Nd"


def _is_alpha(c: int) -> bool:   # iswalpha: letters, and the digits beyond ASCII's
    cat = _cat(c)
    return cat[0] == "L" or (cat == "Nd" and c > 127)


def _is_cntrl(c: int) -> bool:
    return _cat(c) == "Cc" or c in (0x2028, 0x2029)


def _is_print(c: int) -> bool:
    return not _is_cntrl(c) and _cat(c) not in ("Cn", "Cs", "Co")


def _is_graph(c: int) -> bool:
    return _is_print(c) and c not in _SPACE_SET


def _upper_of(c: int) -> int:
    u = chr(c).upper()
    return ord(u) if len(u) == 1 else c


def _lower_of(c: int) -> int:
    u = chr(c).lower()
    return ord(u) if len(u) == 1 else c


def _xdigit(c: int) -> Any:
    if 48 <= c <= 57:
        return c - 48
    if 97 <= c <= 102 or 65 <= c <= 70:
        return (c | 32) - 87
    return None


_CHAR, _WEIGHT = "char", "weight"
# (name, arity, test, kind of the argument)
_CHAR_TYPES: list[tuple[str, int, Callable[[int], Any], str]] = [
    ("alnum", 0, _is_alnum, ""),
    ("alpha", 0, _is_alpha, ""),
    ("csym", 0, lambda c: _is_alnum(c) or c == 95, ""),
    ("csymf", 0, lambda c: _is_alpha(c) or c == 95, ""),
    ("prolog_var_start", 0, lambda c: _cat(c) in ("Lu", "Lt") or c == 95, ""),
    ("prolog_atom_start", 0, lambda c: _cat(c)[0] == "L" and _cat(c) not in ("Lu", "Lt"), ""),
    ("prolog_identifier_continue", 0, lambda c: _is_alnum(c) or c == 95, ""),
    ("prolog_symbol", 0,
     lambda c: c in _PROLOG_SYMBOLS if c < 128 else _cat(c)[0] == "S", ""),
    ("decimal", 0, lambda c: _cat(c) == "Nd", ""),
    ("decimal", 1, lambda c: _ud.decimal(chr(c)) if _cat(c) == "Nd" else None, _WEIGHT),
    ("csymf", 0, lambda c: _is_alpha(c) or c == 95, ""),
    ("ascii", 0, lambda c: c < 128, ""),
    ("white", 0, lambda c: c in (9, 32), ""),
    ("cntrl", 0, _is_cntrl, ""),
    ("digit", 0, lambda c: 48 <= c <= 57, ""),
    ("print", 0, _is_print, ""),
    ("space", 0, lambda c: c in _SPACE_SET, ""),
    ("end_of_line", 0, lambda c: 10 <= c <= 13, ""),
    ("newline", 0, lambda c: c == 10, ""),
    ("graph", 0, _is_graph, ""),
    ("lower", 0, lambda c: _cat(c) == "Ll", ""),
    ("lower", 1, lambda c: _upper_of(c) if _cat(c) == "Ll" else None, _CHAR),
    ("upper", 0, lambda c: _cat(c) == "Lu", ""),
    ("upper", 1, lambda c: _lower_of(c) if _cat(c) == "Lu" else None, _CHAR),
    ("punct", 0, lambda c: _is_graph(c) and not _is_alnum(c), ""),
    ("period", 0, lambda c: c in (33, 46, 63), ""),
    ("quote", 0, lambda c: c in (34, 39, 96), ""),
    ("to_lower", 1, _upper_of, _CHAR),
    ("to_upper", 1, _lower_of, _CHAR),
    ("paren", 1, lambda c: {40: 41, 91: 93, 123: 125}.get(c), _CHAR),
    ("digit", 1, lambda c: c - 48 if 48 <= c <= 57 else None, _WEIGHT),
    ("xdigit", 1, _xdigit, _WEIGHT),
]
_CHAR_TYPE = {(name, arity): (test, kind) for name, arity, test, kind in _CHAR_TYPES}
# the character of an argument, where the class gives one back (upper(a) is 'A'); a type
# left out here is enumerated over all of Unicode by SWI-Prolog (an instantiation error here)
_CHAR_OF_ARG: dict[tuple[str, int], Callable[[int], Any]] = {
    ("upper", 1): _upper_of, ("lower", 1): _lower_of,
    ("to_lower", 1): _lower_of, ("to_upper", 1): _upper_of,
    ("digit", 1): lambda w: 48 + w if 0 <= w <= 9 else None,
    ("xdigit", 1): lambda w: (48 + w if w <= 9 else 87 + w) if 0 <= w <= 15 else None,
    ("paren", 1): lambda c: {41: 40, 93: 91, 125: 123}.get(c),
}
# classes whose characters SWI-Prolog enumerates from a small set, exactly this one
_CHARS_OF_TYPE: dict[tuple[str, int], Any] = {
    ("digit", 0): range(48, 58), ("digit", 1): range(48, 58), ("white", 0): (9, 32),
    ("end_of_line", 0): range(10, 14), ("newline", 0): (10,), ("space", 0): _SPACES,
    ("ascii", 0): range(128),
}


def _code_of(t: Any) -> Any:
    """The code of a character argument: a one-character atom or string, or a code;
    ``end_of_file`` (or -1) is -1. A text of one character is one too, as SWI-Prolog reads
    it: a list of one character or one code (``[a]``, ``[0'a]``)."""
    tt = type(t)
    if tt is Atom and t == "end_of_file":
        return -1
    if (tt is Atom or tt is String) and len(t) == 1 and t != "[]":
        return ord(t)
    if tt is Struct and t.name == "." and len(t.args) == 2 and _is_nil(deref(t.args[1])):
        x = deref(t.args[0])
        if type(x) is Atom and len(x) == 1 and x != "[]":
            return ord(x)
        if type(x) is int and 0 <= x <= 0x10FFFF:
            return x
        raise type_error("character", t)
    if tt is int:
        # (SWI-Prolog: a code beyond Unicode is no character, one beyond a C int no code)
        if t < -1 or t > 0x7FFFFFFF:
            raise type_error("character", t)
        if t > 0x10FFFF:
            raise _err_domain("character", t)
        return t
    raise type_error("character", t)


def _char_class_value(m, out: Any, kind: str, value: Any, codes: bool) -> bool:
    if kind == _CHAR and not codes:
        return m.unify(out, Atom(chr(value)))
    return m.unify(out, value)


def _arg_code(t: Any) -> int:
    """The code of a class's bound argument (``upper(a)``, ``digit(5)``): end_of_file is
    none."""
    c = _code_of(t)
    if c == -1:
        raise type_error("character", t)
    return c


def _char_type_check(m, c: int, name: str, arity: int, args: tuple, codes: bool) -> bool:
    """Whether the code ``c`` is of the class name/arity (binding its argument)."""
    if c == -1:
        return name == "end_of_file" and arity == 0
    entry = _CHAR_TYPE.get((name, arity))
    if entry is None:
        return False
    test, kind = entry
    value = test(c)
    if value is None or value is False:
        return False
    if arity == 0:
        return True
    arg = deref(args[0])
    if type(arg) is Var:
        return _char_class_value(m, arg, kind, value, codes)
    w = _arg_code(arg)   # a character or a code (a weight too), else SWI-Prolog's error
    if w == value:
        return True
    # to_lower(U) also holds where c is U's lower case (to_lower('A') of 'a', of 'A' itself)
    back = {"to_lower": _lower_of, "to_upper": _upper_of}.get(name)
    return back is not None and back(w) == c


def _char_type(m, a, codes: bool):
    x = deref(a[0])
    t = deref(a[1])
    c = _code_of(x) if type(x) is not Var else None   # as SWI-Prolog: the character first
    if c == -1:
        # end of file (-1, end_of_file) is of the class end_of_file only, before the class
        # is looked at: char_type(-1, foo) fails, as SWI-Prolog's
        if m.unify(t, Atom("end_of_file")):
            yield None
        return
    if type(t) is not Var and not (type(t) is Atom and t != "[]" or type(t) is Struct):
        raise type_error("char_type", t)
    if type(t) is Struct:
        name, arity, args = str(t.name), len(t.args), t.args
    elif type(t) is Atom:
        name, arity, args = str(t), 0, ()
    if type(t) is not Var and (name, arity) not in _CHAR_TYPE and (name, arity) != ("end_of_file", 0):
        raise type_error("char_type", t)
    if c is not None:
        if type(t) is not Var:
            if _char_type_check(m, c, name, arity, args, codes):
                yield None
            return
        for tname, tarity, test, kind in _CHAR_TYPES:
            value = test(c)
            if value is None or value is False:
                continue
            mark = len(m.trail)
            if tarity == 0:
                ok = m.unify(t, Atom(tname))
            else:
                out = Var()
                ok = m.unify(t, Struct(tname, (out,))) and _char_class_value(m, out, kind, value, codes)
            if ok:
                yield None
            m.undo_to(mark)
        return
    if type(t) is Var:
        raise instantiation_error()
    key = (name, arity)
    if key == ("end_of_file", 0):
        if m.unify(x, -1 if codes else Atom("end_of_file")):
            yield None
        return
    arg = deref(args[0]) if arity else None
    if arity and type(arg) is not Var:
        back = _CHAR_OF_ARG.get(key)
        if back is None:
            raise instantiation_error()
        w = _arg_code(arg)
        if key in (("digit", 1), ("xdigit", 1)) and type(arg) is not int:
            return   # a character is no weight
        c = back(w)
        if c is not None and _char_type_check(m, c, name, arity, args, codes):
            if m.unify(x, c if codes else Atom(chr(c))):
                yield None
        return
    chars = _CHARS_OF_TYPE.get(key)
    if chars is None:
        # SWI-Prolog enumerates every Unicode character of the class, from its C library's
        # tables; slr_sql asks for the character instead
        raise instantiation_error()
    for c in chars:
        mark = len(m.trail)
        if _char_type_check(m, c, name, arity, args, codes) \
                and m.unify(x, c if codes else Atom(chr(c))):
            yield None
        m.undo_to(mark)


@nondet("$char_type", 2)
def _char_type2(m, a):
    """char_type(Char, Type) as SWI-Prolog's (docs/language.md: where it asks for Char)."""
    return _char_type(m, a, False)


@nondet("$code_type", 2)
def _code_type2(m, a):
    """code_type(Code, Type): char_type/2 with codes for characters."""
    return _char_type(m, a, True)


@nondet("string_concat", 3)
def _string_concat(m, a):
    """string_concat/3 as SWI-Prolog's: atomic parts (no lists, no []); with either part
    unbound the whole is split, a bound part pinning the split."""
    x, y = deref(a[0]), deref(a[1])
    if type(x) is not Var and type(y) is not Var:
        joined = text_in(x, "atomic") + text_in(y, "atomic")
        if type(deref(a[2])) is not Var:
            # a given whole is atomic text, compared as text (string_concat(a, b, ab))
            if text_in(a[2], "atomic") == joined:
                yield None
            return
        if m.unify(a[2], String(joined)):
            yield None
        return
    px = text_in(x, "atomic") if type(x) is not Var else None
    py = text_in(y, "atomic") if type(y) is not Var else None
    s = text_in(a[2], "atomic")
    if px is not None:
        if s.startswith(px) and m.unify(y, String(s[len(px):])):
            yield None
        return
    if py is not None:
        if s.endswith(py) and m.unify(x, String(s[:len(s) - len(py)])):
            yield None
        return
    for i in range(len(s) + 1):
        mark = len(m.trail)
        if m.unify(x, String(s[:i])) and m.unify(y, String(s[i:])):
            yield None
        m.undo_to(mark)


def _text_conv(name: str, make: Callable[[str], Any], parse: Callable[[Any], Any],
               first: tuple[str, str], second: tuple[str, str], either: bool = False):
    """A conversion Text <-> Other: from the first argument when it is bound (read in the
    text mode ``first``, :func:`text_in`), else from the second (mode ``second``);
    ``either``: from the second too when the first is no text (SWI-Prolog's atom_string/2:
    atom_string(f(x), 1) fails, atom_string(f(x), g) is type_error(string, g))."""
    def f(m, a):
        x = deref(a[0])
        if type(x) is not Var:
            try:
                text = text_in(x, *first)
            except SLREvaluationError as exc:
                # a partial list (and for ``either`` anything that is no text) is made
                # from the second argument when that is given, as SWI-Prolog does
                partial = deref(exc.term.args[0]) == "instantiation_error"
                if not (either or partial) or type(deref(a[1])) is Var:
                    raise
                return m.unify(x, parse(text_in(a[1], *second)))
            if _is_text_given(a[1]):
                # a given second argument is read as text and compared (SWI-Prolog:
                # string_chars(ab, [0'a, 0'b]) is true); one that is no text fails
                try:
                    return text_in(a[1], "any") == text
                except SLREvaluationError:
                    return False
            return m.unify(a[1], make(text))
        return m.unify(x, parse(text_in(a[1], *second)))
    DET[(name, 2)] = f


_text_conv("atom_string", String, Atom, ("whole", "atom"), ("whole", "string"), either=True)
# string_to_atom(S, A) is SWI-Prolog's atom_string(A, S)
DET[("string_to_atom", 2)] = lambda m, a: DET[("atom_string", 2)](m, (a[1], a[0]))
_text_conv("string_chars", lambda s: make_list([Atom(c) for c in s]), String, ("any", "text"),
           ("list", "list"))
_text_conv("string_codes", lambda s: make_list([ord(c) for c in s]), String, ("any", "text"),
           ("list", "list"))


@det("char_code", 2)
def _char_code(m, a):
    """ISO 8.16.6: errors as SWI-Prolog (a one-character atom, or a code)."""
    x = deref(a[0])
    c = deref(a[1])
    if type(x) is not Var:
        if type(x) is not Atom or len(x) != 1:
            raise type_error("character", x)
        if type(c) is not Var and type(c) is not int:
            raise type_error("integer", c)
        return m.unify(c, ord(x))
    if type(c) is Var:
        raise instantiation_error()
    if type(c) is not int:
        raise type_error("integer", c)
    if not -0x80000000 <= c <= 0x7FFFFFFF:   # SWI-Prolog reads the code as a C int first
        raise iso_error(Struct("representation_error", (Atom("int"),)))
    if not 0 <= c <= 0x10FFFF or 0xD800 <= c <= 0xDFFF:  # surrogates too, as SWI-Prolog
        raise type_error("character_code", c)
    return m.unify(x, Atom(chr(c)))


def _parse_any(t):
    """The term a text reads as (its first term: what follows the '.' that ends it is
    ignored, as SWI-Prolog's term_to_atom/2 ignores it); a syntax error is the ISO error
    ``syntax_error(Message)`` (catchable, as in SWI-Prolog), never a raw SLRSyntaxError."""
    from .parser import parse_first_term

    try:
        return parse_first_term(text_of(t))[0]
    except SLRSyntaxError as exc:
        raise iso_error(Struct("syntax_error", (Atom(exc.message),))) from None


@nondet("string_code", 3)
def _string_code(m, a):
    """string_code(Index, Text, Code) as SWI-Prolog's: Text an atom, a string or a code or
    character list (no number); an unbound Index enumerates the text's positions."""
    s = text_in(a[1], "no_number")
    i = deref(a[0])
    if type(i) is Var:
        code = deref(a[2])
        if type(code) is not Var:
            # as SWI-Prolog: a given character (a code, or a one-character atom or string:
            # string_code(I, "ab", a) is I = 1) is looked for; anything else is its error
            # (type_error(character, C), domain_error(character, C) beyond Unicode)
            c = _arg_code(code)
            for k, ch in enumerate(s, 1):
                if ord(ch) == c:
                    mark = len(m.trail)
                    if m.unify(i, k):
                        yield None
                    m.undo_to(mark)
            return
        for k, ch in enumerate(s, 1):
            mark = len(m.trail)
            if m.unify(i, k) and m.unify(a[2], ord(ch)):
                yield None
            m.undo_to(mark)
        return
    if type(i) is not int:
        raise type_error("integer", i)
    if i < 0:
        raise _err_domain("not_less_than_zero", i)
    if 1 <= i <= len(s) and m.unify(a[2], ord(s[i - 1])):
        yield None


@det("number_string", 2)
def _number_string(m, a):
    n, s = deref(a[0]), deref(a[1])
    # as SWI-Prolog: a bound first argument must be a number, and the text a string or a
    # code or character list (an atom or a number there is type_error(list, ..))
    if type(n) is not Var and type(n) is not int and type(n) is not float:
        raise type_error("number", n)
    if type(s) is not Var:
        # a text that is no number fails (SWI-Prolog's number_string, unlike ISO's
        # number_codes, raises no syntax error), and so does one with layout around it
        n = _number_of_text(_list_text(s), leading_layout=False)
        return n is not None and m.unify(a[0], n)
    return m.unify(s, String(text_of(a[0])))


@det("downcase_atom", 2)
def _downcase(m, a):
    return _case_converted(m, a, _downcase_text)


def _concat_items(items_term: Any) -> list[str] | None:
    """The texts of atomic_list_concat's list, as SWI-Prolog reads them for joining: an
    atom, a string or a number each (``[]`` or a compound is type_error(text, E)); None
    when the list is partial or has an unbound element (before any bad one); a tail that
    is no list is type_error(list, Tail)."""
    items, tail = list_items(items_term)
    if type(tail) is not Var and not (type(tail) is Atom and tail == "[]"):
        raise type_error("list", tail)
    out = []
    for x in items:
        x = deref(x)
        if type(x) is Var:
            return None
        out.append(_join_text(x))
    return None if type(tail) is Var else out


def _join_text(t: Any) -> str:
    """An atomic text to join (atomic_list_concat's parts and separator)."""
    t = deref(t)
    if type(t) is Var:
        raise instantiation_error()
    if type(t) is String or type(t) is Atom and t != "[]":
        return str(t)
    if type(t) is int or type(t) is float:
        return text_of(t)
    raise type_error("text", t)


@det("atomic_list_concat", 2)
def _alc2(m, a):
    parts = _concat_items(a[0])
    if parts is None:
        raise instantiation_error()
    return m.unify(a[1], Atom("".join(parts)))


@det("atomic_list_concat", 3)
def _alc3(m, a):
    """atomic_list_concat(Parts, Sep, Atom) as SWI-Prolog's: the separator first, then the
    parts joined; with a part or the list's tail unbound, Atom split at each separator."""
    sep = _join_text(a[1])
    parts = _concat_items(a[0])
    if parts is not None:
        if len(sep) * (len(parts) - 1) > MAX_BUILT_TEXT:   # (the separator repeated)
            raise resource_error("memory")
        return m.unify(a[2], Atom(sep.join(parts)))
    if not sep:
        raise _err_domain("non_empty_atom", deref(a[1]))
    whole = text_in(a[2], "atomic")
    return m.unify(a[0], make_list([Atom(p) for p in whole.split(sep)]))


@det("split_string", 4)
def _split_string(m, a):
    s, seps, pad = (text_in(a[0], "no_number"), text_in(a[1], "no_number"),
                    text_in(a[2], "no_number"))
    out = deref(a[3])
    if type(out) is not Var and not (type(out) is Atom and out == "[]") \
            and not (type(out) is Struct and out.name == "." and len(out.args) == 2):
        raise type_error("list", out)
    return m.unify(a[3], make_list([String(p) for p in _split_any(s, seps, pad)]))


def _split_any(s: str, seps: str, pad: str) -> list[str]:
    """split_string/4's fields as SWI-Prolog makes them: the whole text stripped of ``pad``
    at both ends, then each field from its start, where ``pad`` is skipped first (so pad
    characters that are separators too join adjacent separators), to the next separator,
    stripped of ``pad`` at its end.

    >>> _split_any("//a//b//", "/", "/"), _split_any("/home//jan", "/", "")
    (['a', 'b'], ['', 'home', '', 'jan'])
    """
    start, end = 0, len(s)
    while start < end and s[start] in pad:
        start += 1
    while end > start and s[end - 1] in pad:
        end -= 1
    out = []
    while True:
        while start < end and s[start] in pad:
            start += 1
        stop = start
        while stop < end and s[stop] not in seps:
            stop += 1
        last = stop
        while last > start and s[last - 1] in pad:
            last -= 1
        out.append(s[start:last])
        if stop >= end:
            return out
        start = stop + 1


# -- lists -----------------------------------------------------------------------------------------

def proper_list(t: Any) -> list:
    """The items of a proper list; a partial list is an instantiation error, anything
    else a type error (``list``).

    >>> proper_list(make_list([1, 2]))
    [1, 2]
    >>> proper_list(Atom("a"))
    Traceback (most recent call last):
    slr_sql.errors.SLREvaluationError: error(type_error(list,a),_)
    """
    items, tail = list_items(t)
    if type(tail) is Var:
        raise instantiation_error()
    if not (type(tail) is Atom and tail == "[]"):
        raise type_error("list", t)
    return items


# The longest list one builtin call builds from a number (numlist/3, length/2): about
# 150 bytes a cell, so 1.5 GB. Longer is resource_error(memory) at once, instead of a
# MemoryError after minutes (SWI-Prolog's 1 GB stacks stop at a similar size).
MAX_BUILT_LIST = 10_000_000
# The longest text one builtin call makes by repeating (format/2's counts and columns: ~Nc,
# ~Nn, ~Nd, ~*c; tab/1; atomic_list_concat/3's separator): 64 Mi characters, the most a
# read-only SQL statement may make too. Longer is resource_error(memory) at once: a query's
# format(atom(A), "~1000000000n", []) built a 1 GB atom in one Python step, 5 GB of the
# server's memory and 20 s, past the query's timeout (which is looked at between steps).
MAX_BUILT_TEXT = 64 << 20
# Cells built between two looks at the query's deadline.
_CELLS_PER_DEADLINE_CHECK = 1 << 16


def build_list(m: "Machine", n: int, item: Callable[[int], Any], tail: Any = NIL) -> Any:
    """The list ``[item(0), ..., item(n-1) | tail]`` built back to front, in chunks between
    which the query's deadline is checked (SLRTimeout); longer than MAX_BUILT_LIST is
    resource_error(memory). The cyclic garbage collector is paused while building a long
    list: it would otherwise re-scan the growing list again and again (3-4x slower).

    >>> from slr_sql.engine import Engine; from slr_sql.program import Program
    >>> str(build_list(Engine(Program()).machine(), 3, lambda i: i + 1))
    '[1,2,3]'
    """
    if n > MAX_BUILT_LIST:
        raise resource_error("memory")
    out = tail
    paused = n > _CELLS_PER_DEADLINE_CHECK and gc.isenabled()
    if paused:
        gc.disable()
    try:
        stop = n
        while stop > 0:
            start = max(0, stop - _CELLS_PER_DEADLINE_CHECK)
            for i in range(stop - 1, start - 1, -1):
                out = Struct(CONS, (item(i), out))
            stop = start
            if stop:
                m.check_deadline()
    finally:
        if paused:
            gc.enable()
    return out


@nondet("length", 2)
def _length(m, a):
    items, tail = list_items(a[0])
    n = deref(a[1])
    # as SWI-Prolog: the length is checked before the list
    if type(n) is not Var:
        if type(n) is not int:
            raise type_error("integer", n)
        if n < 0:
            raise _err_domain("not_less_than_zero", n)
    if type(tail) is not Var and not (type(tail) is Atom and tail == "[]"):
        raise type_error("list", a[0])
    if type(tail) is Atom and tail == "[]":
        if m.unify(n, len(items)):
            yield None
        return
    if type(tail) is not Var:
        return
    if type(n) is int:
        if n < len(items):
            return
        if m.unify(tail, build_list(m, n - len(items), lambda _: Var())):
            yield None
        return
    if type(n) is not Var:
        raise type_error("integer", n)
    if n is tail:  # length([a|T], T): no list is its own length (fails, as in SWI-Prolog)
        return
    # Lists of 0, 1, 2, ... fresh variables. Each one is the previous one with a fresh
    # variable in front (all are unbound again after backtracking), so each solution costs
    # one cell, not a whole new list.
    k = 0
    fresh = NIL
    while True:
        if k > MAX_BUILT_LIST:
            raise resource_error("memory")
        mark = len(m.trail)
        if m.unify(tail, fresh) and m.unify(n, len(items) + k):
            yield None
        m.undo_to(mark)
        k += 1
        fresh = Struct(CONS, (Var(), fresh))


@det("msort", 2)
def _msort(m, a):
    return m.unify(a[1], make_list(sorted(proper_list(a[0]), key=_cmp_key)))


def _dedup(items: list) -> list:
    out = []
    for x in items:
        if not out or compare_terms(out[-1], x) != 0:
            out.append(x)
    return out


def sorted_unique(items: list) -> list:
    """``items`` in the standard order of terms without duplicates (what ``sort/2`` and
    ``setof/3`` give).

    >>> sorted_unique([Atom("b"), 1, Atom("a"), 1])
    [1, Atom('a'), Atom('b')]
    """
    return _dedup(sorted(items, key=_cmp_key))


@det("sort", 2)
def _sort(m, a):
    return m.unify(a[1], make_list(_dedup(sorted(proper_list(a[0]), key=_cmp_key))))


_SORT_ORDERS = {"<": Atom("@<"), ">": Atom("@>"), "=<": Atom("@=<"), ">=": Atom("@>=")}


def _sort_key(key: Any) -> list | None:
    """sort/4's key as SWI-Prolog checks it first, as the path of keys its sort follows into
    each element: an argument position (a non-negative integer; 0 the element itself), a
    dict key (an atom, ``[]`` too) or a list of such keys (the positions there positive);
    another key is type_error(sort_key, Key). None where SWI-Prolog's sort/4 fails: a path
    holding a key that is neither (a variable, a float, a compound) -- checked in order,
    after the positions before it.

    >>> _sort_key(0), _sort_key(2), _sort_key(make_list([1, Atom("a")])), _sort_key(make_list([1.5]))
    ([], [2], [1, Atom('a')], None)
    """
    key = deref(key)
    if type(key) is Var:
        raise instantiation_error()
    if type(key) is int:
        if key < 0:
            raise _err_domain("not_less_than_one", key)    # (SWI-Prolog's, though 0 is one)
        return [key] if key else []
    if type(key) is Atom:
        return [key]
    if type(key) is Struct and key.name == "." and len(key.args) == 2:
        items, tail = list_items(key)
        if type(tail) is Atom and tail == "[]":
            path: list = []
            for x in items:
                x = deref(x)
                if type(x) is int:
                    if x < 1:
                        raise _err_domain("not_less_than_one", x)
                elif type(x) is not Atom:
                    return None
                path.append(x)
            return path
    raise type_error("sort_key", key)


def _sort_key_of(path: list, t: Any) -> Any:
    """The part of the element ``t`` sort/4's key ``path`` names, with SWI-Prolog's errors:
    a variable on the way is an instantiation error, a term that is no compound
    type_error(compound, T); a dict key reaches into no term (slr_sql has no dicts:
    type_error(dict, T), as SWI-Prolog's for a compound), a position past the compound's
    arguments is ISO's type_error(compound, T) (SWI-Prolog's own existence_error(argument,
    N, T) has three arguments)."""
    for step in path:
        t = deref(t)
        if type(t) is Var:
            raise instantiation_error()
        if type(t) is not Struct:
            raise type_error("compound", t)
        if type(step) is not int:
            raise type_error("dict", t)
        if len(t.args) < step:
            raise type_error("compound", t)
        t = t.args[step - 1]
    return t


@det("sort", 4)
def _sort4(m, a):
    path = _sort_key(a[0])
    if path is None:
        return False
    order = deref(a[1])
    if type(order) is Var:
        raise instantiation_error()
    if type(order) is not Atom:
        raise type_error("atom", order)
    # SWI-Prolog takes < > =< >= for @< @> @=< @>= (the standard order all the same)
    order = _SORT_ORDERS.get(str(order), order)
    if str(order) not in ("@<", "@>", "@=<", "@>="):
        raise _err_domain("order", order)
    items = proper_list(a[2])
    # every element's key first, in the list's order (the first bad element's error)
    keys = [_sort_key_of(path, t) for t in items]
    ranked = sorted(range(len(items)), key=lambda j: _cmp_key(keys[j]),
                    reverse=order in ("@>", "@>="))
    if order in ("@<", "@>"):
        kept: list[int] = []
        for j in ranked:
            if not kept or compare_terms(keys[kept[-1]], keys[j]) != 0:
                kept.append(j)
        ranked = kept
    return m.unify(a[3], make_list([items[j] for j in ranked]))


@det("keysort", 2)
def _keysort(m, a):
    items = proper_list(a[0])
    for x in items:
        x = deref(x)
        if type(x) is Var:
            raise instantiation_error()
        if type(x) is not Struct or x.name != "-" or len(x.args) != 2:
            raise type_error("pair", x)
    return m.unify(a[1], make_list(sorted(items, key=lambda t: _cmp_key(deref(t).args[0]))))


def _numbers(t: Any) -> list:
    return [evaluate(x) for x in proper_list(t)]


def _no_matching_rule(name: str, args: tuple, arity: int | None = None) -> SLREvaluationError:
    """SWI-Prolog 9's error when no rule of its library(lists) predicate ``name`` (a `=>`
    rule) matches the call ``name(args)``: existence_error(matching_rule, lists:Goal) in
    ``context(lists:name/arity, _)``."""
    goal = Struct(name, args)
    return iso_error(Struct("existence_error", (Atom("matching_rule"),
                                                Struct(":", (Atom("lists"), goal)))),
                     Struct("context", (_pi(name, arity or len(args), "lists"), Var("_"))))


def _is_nil(t: Any) -> bool:
    return type(t) is Atom and t == "[]"


@det("sum_list", 2)
def _sum_list(m, a):
    """sum_list/2 as SWI-Prolog's library: each element added as it comes (Y is Y0 + X);
    a tail that is no list (unbound too: `=>` rules do not bind) is no matching rule."""
    items, tail = list_items(a[0])
    total: Any = 0
    for x in items:
        total = apply_binary("+", total, evaluate(x))   # Y is Y0 + X: inf + 1 is float_overflow
    if not _is_nil(tail):
        raise _no_matching_rule("sum_list", (tail, total, a[1]))
    return m.unify(a[1], total)


DET[("sumlist", 2)] = _sum_list


def _extreme(items: list, better: Callable[[Any, Any], bool]) -> Any:
    """The first item no other item is ``better`` than (None for an empty list)."""
    if not items:
        return None
    best = items[0]
    for x in items[1:]:
        if better(x, best):
            best = x
    return best


def _unify_extreme(m, out, t, better, name: str) -> bool:
    """max_member/2, min_member/2 (``name``) as SWI-Prolog's library: [] fails, a term that
    is no list, or a tail that is none (unbound too), is no matching rule."""
    t = deref(t)
    if _is_nil(t):
        return False
    if not (type(t) is Struct and t.name == "." and len(t.args) == 2):
        raise _no_matching_rule(name, (out, t))
    items, tail = list_items(t)
    best = _extreme(items, better)
    if not _is_nil(tail):
        raise _no_matching_rule(name + "_", (tail, best, out))
    return m.unify(out, best)


def _fold_arith(name: str, items: list) -> Any:
    """The arithmetic max/min of the items, folded left as SWI-Prolog's max_list/2 and
    aggregate_all(max(X), ..) do (``max(1, 1.0)`` is 1.0, in either order); None if empty."""
    if not items:
        return None
    value = items[0]
    for x in items[1:]:
        value = apply_binary(name, value, x)
    return value


def _unify_fold(m, out, name: str, t: Any) -> bool:
    """max_list/2, min_list/2 (``name`` max or min) as SWI-Prolog's library folds: [] fails,
    a term that is no list, or a tail that is none (unbound too), is no matching rule."""
    t = deref(t)
    if _is_nil(t):
        return False
    what = name + "_list"
    if not (type(t) is Struct and t.name == "." and len(t.args) == 2):
        raise _no_matching_rule(what, (t, out))
    items, tail = list_items(t)
    value = _fold_arith(name, [evaluate(x) for x in items])
    if not _is_nil(tail):
        # (the library's fold starts from the first element as it is)
        raise _no_matching_rule(what, (tail, items[0] if len(items) == 1 else value, out))
    return m.unify(out, value)


DET[("max_list", 2)] = lambda m, a: _unify_fold(m, a[1], "max", a[0])
DET[("min_list", 2)] = lambda m, a: _unify_fold(m, a[1], "min", a[0])
DET[("max_member", 2)] = lambda m, a: _unify_extreme(
    m, a[0], a[1], lambda x, y: compare_terms(x, y) > 0, "max_member")
DET[("min_member", 2)] = lambda m, a: _unify_extreme(
    m, a[0], a[1], lambda x, y: compare_terms(x, y) < 0, "min_member")


@det("numlist", 3)
def _numlist(m, a):
    lo, hi = deref(a[0]), deref(a[1])
    for bound in (lo, hi):   # must_be(integer, L), then must_be(integer, H)
        if type(bound) is Var:
            raise instantiation_error()
        if type(bound) is not int:
            raise type_error("integer", bound)
    if lo > hi:
        return False
    return m.unify(a[2], build_list(m, hi - lo + 1, lambda i: lo + i))


@det("$must_be_list", 1)
def _must_be_list(m, a):
    """must_be(list, L): a partial list is an instantiation error, another term that is no
    list type_error(list, L) (the context unbound, as the library's)."""
    proper_list(a[0])
    return True


@det("$reverse_list", 2)
def _reverse_list(m, a):
    """reverse/2 of a list that is no partial one (the compiled path calls it where the
    list's end is known): its reverse, or failure when its tail is no list."""
    items, tail = list_items(a[0])
    if not _is_nil(tail):
        return False   # (the library's clauses are for [] and [X|Xs] only)
    return m.unify(a[1], make_list(items[::-1]))


@nondet("reverse", 2)
def _reverse(m, a):
    """reverse(Xs, Ys) as SWI-Prolog's library clauses, which walk Ys's cells beside Xs's
    (``reverse([X|Xs], [_|Bound], Rs, Ys)``): a partial Xs is completed to one length after
    another, as far as Ys has cells for it (with no end when Ys is partial too):
    ``reverse(L, [1, 2])`` answers L = [2, 1] and ends, ``reverse([1|T], R)`` has no end."""
    items, tail = list_items(a[0])
    if type(tail) is not Var:
        if _reverse_list(m, a):
            yield None
        return
    ys = a[1]
    ys_items, ys_tail = list_items(ys)
    if type(ys_tail) is not Var:
        # Ys's cells end: the walk reaches only their number of elements, and only a proper
        # Ys ends it there (its cell after the last is [])
        if _is_nil(ys_tail) and m.unify(a[0], make_list(ys_items[::-1])):
            yield None
        return
    trail = m.trail
    extra = 0
    while True:
        # the list with `extra` more elements: its solution, if Ys is its reverse
        fresh = [Var() for _ in range(extra)]
        mark = len(trail)
        if m.unify(tail, make_list(fresh)) and m.unify(ys, make_list((items + fresh)[::-1])):
            yield None
        m.undo_to(mark)
        # one element more only where Ys has a cell for it too (the clauses' walk fails
        # there, and with it every longer list)
        longer = m.unify(tail, make_list([Var() for _ in range(extra + 1)], Var())) and \
            m.unify(ys, make_list([Var() for _ in range(len(items) + extra + 1)], Var()))
        m.undo_to(mark)
        if not longer:
            return
        extra += 1
        # (each length is a walk of its own: counted by its cells, a walk that finds no
        # solution is ended by the query's limits)
        m.count_steps(extra)


@det("memberchk", 2)
def _memberchk(m, a):
    items, tail = list_items(a[1])
    trail = m.trail
    for x in items:
        mark = len(trail)
        if unify(a[0], x, trail):
            return True
        undo(trail, mark)
    if type(tail) is Var:
        return m.unify(tail, Struct(".", (a[0], Var())))
    if not _is_nil(tail):
        raise iso_error(Struct("type_error", (Atom("list"), tail)),
                        Struct("context", (_pi("$memberchk", 3), Var("_"))))
    return False


@det("list_to_set", 2)
def _list_to_set(m, a):
    out = []
    for x in proper_list(a[0]):
        if not any(compare_terms(x, y) == 0 for y in out):
            out.append(x)
    return m.unify(a[1], make_list(out))


# -- output ------------------------------------------------------------------------------------------

def _out(m: "Machine"):
    """Where write/1 & co. write: the innermost live with_output_to/2 capture, else the
    engine's output (None: the process's standard output)."""
    captures = m.captures
    while captures:
        height, cp = captures[-1]
        cps = m.cps
        if height < len(cps) and cps[height] is cp:
            return cp[3]
        captures.pop()   # its goal ended (succeeded, failed or threw): the capture is over
    return m.engine.out or sys.stdout


class DiscardedOutput:
    """An output that drops what is written: where a served knowledge base's queries write
    (``slr serve``, docs/service.md), so no client writes into the operator's logs.

    >>> import slr_sql
    >>> kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    >>> kb.engine.out = kb.engine.err = DiscardedOutput()
    >>> kb.query("write(hi), print_message(error, format('~w', [x]))"); kb.close()
    [{}]
    """

    position = 0   # (format/2's column stops count from the start of a line)

    def write(self, text: str) -> None:
        pass

    def flush(self) -> None:
        pass


class _Capture:
    """with_output_to/2's text so far (bounded as format/2's output is), or a stream alias
    its goal's output goes to (``with_output_to(user_error, G)``)."""

    __slots__ = ("parts", "size", "stream", "position")

    def __init__(self, stream: Any = None):
        self.parts: list[str] = []
        self.size = 0
        self.stream = stream
        # where the text's last line ends, as SWI-Prolog's stream counts it: format/2's
        # column stops count from there (write(a), format("~t~w~10|", [b]) pads to 10)
        self.position = 0

    def write(self, text: str) -> None:
        if self.stream is not None:
            self.stream.write(text)
            return
        self.size += len(text)
        if self.size > MAX_BUILT_TEXT:
            raise resource_error("memory")
        self.parts.append(text)
        self.position = _line_position(text, self.position)


# the text sinks of with_output_to/2 and format/3 (SWI-Prolog's)
_TEXT_SINKS = frozenset((("atom", 1), ("string", 1), ("codes", 1), ("codes", 2), ("chars", 1),
                         ("chars", 2)))


def _stream_alias(m: "Machine", t: Any, sink: bool) -> Any:
    """The output stream an alias names, as SWI-Prolog's: ``user_output`` (the query's
    output, past any with_output_to/2 capture, as SWI-Prolog's alias is its standard output)
    and ``user_error``; ``user_input`` is no output; slr_sql has no other streams. ``sink``:
    where a text sink was possible too (with_output_to/2, format/3: what is no alias nor sink
    is type_error(output, T); write/2 & co.: domain_error(stream_or_alias, T))."""
    t = deref(t)
    if type(t) is Var:
        raise instantiation_error()
    if type(t) is Atom and t != NIL:
        if t == "user_output":
            return m.engine.out or sys.stdout
        if t == "user_error":
            return m.engine.err or sys.stderr
        if t == "user_input":
            raise iso_error(Struct("permission_error", (Atom("output"), Atom("stream"), t)))
        raise iso_error(Struct("existence_error", (Atom("stream"), t)))
    if sink:
        raise type_error("output", t)
    raise _err_domain("stream_or_alias", t)


def _output_sink(m: "Machine", t: Any) -> Any:
    """A text sink term (``atom(A)``, ``string(S)``, ``codes(C)``, ``codes(C, T)``,
    ``chars(C)``, ``chars(C, T)``) as it is, or the stream an alias names."""
    t = deref(t)
    if type(t) is Struct and (t.name, len(t.args)) in _TEXT_SINKS:
        return t
    return _stream_alias(m, t, sink=True)


def _unify_sink(m: "Machine", sink: Struct, text: str) -> bool:
    """Unify a text sink's argument(s) with ``text``: an atom, a string, a code or
    character list (with ``codes(C, T)``/``chars(C, T)`` a difference list ending in T)."""
    kind = sink.name
    if kind == "atom":
        return m.unify(sink.args[0], Atom(text))
    if kind == "string":
        return m.unify(sink.args[0], String(text))
    tail = sink.args[1] if len(sink.args) == 2 else NIL
    if kind == "codes":
        return m.unify(sink.args[0], make_list([ord(c) for c in text], tail))
    return m.unify(sink.args[0], make_list([Atom(c) for c in text], tail))


_WITH_OUTPUT_TO = _pi("with_output_to", 2)


def capture_sink(m: "Machine", args: tuple) -> Any:
    """with_output_to(Sink, Goal)'s checks, as SWI-Prolog's, the sink's first: the text sink
    term (``string(S)``, ...) or the stream an alias names (what the goal's output goes to);
    the engine then runs the goal as once/1 with its output captured.

    >>> from slr_sql.engine import Engine
    >>> capture_sink(Engine(Program()).machine(), (Struct("string", (Var("S"),)), Atom("true"))).name
    Atom('string')
    """
    try:
        sink = _output_sink(m, args[0])
        goal = deref(args[1])
        if type(goal) is Var:
            raise instantiation_error()
        if type(goal) not in (Atom, Struct):
            raise type_error("callable", goal)
        m.check_body(goal)
    except SLREvaluationError as exc:
        raise with_context(exc, _WITH_OUTPUT_TO)
    # SWI-Prolog calls the goal from C: an undefined procedure names '$c_call_prolog'/0
    m.meta_check(goal, _pi("$c_call_prolog", 0))
    return sink


def output_capture(sink: Any) -> _Capture:
    """The capture of with_output_to/2's goal: its text, for a text sink; for a stream alias
    the stream it passes the text on to.

    >>> c = output_capture(Struct("atom", (Var("A"),))); c.write("ab"); "".join(c.parts)
    'ab'
    """
    return _Capture(None if type(sink) is Struct else sink)


def unify_sink(m: "Machine", sink: Any, capture: _Capture) -> bool:
    """with_output_to/2's goal succeeded: the text sink unified with what it wrote (true for
    a stream alias, which has had its text).

    >>> from slr_sql.engine import Engine
    >>> m = Engine(Program()).machine(); s = Var("S"); c = output_capture(Struct("string", (s,)))
    >>> c.write("hi"); unify_sink(m, Struct("string", (s,)), c), s.ref
    (True, String('hi'))
    """
    if type(sink) is not Struct:
        return True
    return _unify_sink(m, sink, "".join(capture.parts))


def _write_text(t: Any, quoted: bool = False, deadline: float | None = None,
                numbervars: bool = True) -> str:
    """A term as write/1 (``quoted``: writeq/1, print/1) writes it: ``'$VAR'(1)`` as ``B``
    (SWI-Prolog's numbervars(true)) unless ``numbervars`` is false (write_canonical/1); an
    unbound variable as ``_`` and its number (``_123``), as SWI-Prolog writes one."""
    from .terms import format_term, prolog_var_name

    t = deref(t)
    if not quoted and type(t) in (Atom, String):
        return str(t)
    return format_term(t, quoted=quoted, deadline=deadline, numbervars=numbervars,
                       var_names=prolog_var_name)


def canonical_text(t: Any, deadline: float | None = None) -> str:
    """A term as write_canonical/1 writes it, as SWI-Prolog's: quoted, every compound but a
    list as ``name(arg, ...)`` (no operators), ``'$VAR'(N)`` as it is, and the variables
    named by their first occurrence, ``A``, ``B``, ... for those met more than once and
    ``_`` for those met once.

    >>> x, y = Var("X"), Var("Y")
    >>> canonical_text(Struct("f", (x, y, x, Struct("-", (1,)), Struct("$VAR", (1,)))))
    "f(A,_,A,-(1),'$VAR'(1))"
    """
    from .terms import format_term

    seen: dict[int, int] = {}
    order: list[int] = []

    def count(v: Var) -> str:
        if id(v) not in seen:
            order.append(id(v))
        seen[id(v)] = seen.get(id(v), 0) + 1
        return "_"

    format_term(t, quoted=True, deadline=deadline, var_names=count, cycle_names=False,
                ignore_ops=True)
    names: dict[int, str] = {}
    for key in order:
        if seen[key] > 1:
            n = len(names)   # A, ..., Z, A1, ... as numbervars/3 and write/1 name them
            names[key] = chr(ord("A") + n % 26) + (str(n // 26) if n >= 26 else "")
    return format_term(t, quoted=True, deadline=deadline, var_names=lambda v: names.get(id(v), "_"),
                       cycle_names=False, ignore_ops=True)


# write/1 & co.: (the text of the term, then what follows it); each also with a stream
# alias first (write/2, ...), as SWI-Prolog's
_WRITERS: dict[str, Callable[["Machine", Any], str]] = {
    "write": lambda m, t: _write_text(t, deadline=m.deadline),
    "print": lambda m, t: _write_text(t, True, m.deadline),
    "writeq": lambda m, t: _write_text(t, True, m.deadline),
    "write_canonical": lambda m, t: canonical_text(t, m.deadline),
    "writeln": lambda m, t: _write_text(t, deadline=m.deadline) + "\n",
}


def _writer(name: str, with_stream: bool) -> Callable[["Machine", list], bool]:
    text_of = _WRITERS[name]
    if with_stream:
        def write_to(m: "Machine", a: list) -> bool:
            stream = _stream_alias(m, a[0], sink=False)
            stream.write(text_of(m, a[1]))
            return True
        return write_to

    def write(m: "Machine", a: list) -> bool:
        _out(m).write(text_of(m, a[0]))
        return True
    return write


# (the ones with a stream are the library's write/2, ... : a program written before slr_sql
# had them keeps its own, as for the library's other predicates)
for _name in _WRITERS:
    DET[(_name, 1)] = _writer(_name, False)
    DET[(f"${_name}_to", 2)] = _writer(_name, True)
DET[("nl", 0)] = lambda m, a: (_out(m).write("\n"), True)[1]
DET[("$nl_to", 1)] = lambda m, a: (_stream_alias(m, a[0], sink=False).write("\n"), True)[1]


def _spaces(n: Any) -> str:
    """tab/1's spaces: N an integer expression (none for N < 0); as SWI-Prolog, a float is
    type_error(integer_expression) and a count beyond 64 bits evaluation_error(int_overflow)."""
    n = evaluate(n)
    if type(n) is not int:
        raise type_error("integer_expression", n)
    if n > sys.maxsize:
        raise evaluation_error("int_overflow")
    if n > MAX_BUILT_TEXT:
        raise resource_error("memory")
    return " " * n


def _tab(m: "Machine", a: list) -> bool:
    """tab(N): N spaces (:func:`_spaces`)."""
    _out(m).write(_spaces(a[0]))
    return True


DET[("tab", 1)] = _tab
DET[("$tab_to", 2)] = lambda m, a: (_stream_alias(m, a[0], sink=False).write(_spaces(a[1])), True)[1]


def _text_to_string(m: "Machine", a: list) -> bool:
    """text_to_string(Text, S): an atom, a string or a code or character list (no number)
    as a string, as SWI-Prolog's: a string Text is unified with S as it is; else a given S
    is compared as text (an atom, a string, a number, a code or character list, ``[]`` the
    empty text; what is none of these is no match)."""
    text = text_in(a[0], "no_number")
    if type(deref(a[0])) is String:
        return m.unify(a[1], a[0])
    result = deref(a[1])
    if type(result) is Var:
        return m.unify(result, String(text))
    if type(result) is Struct and not (result.name == CONS and len(result.args) == 2):
        return False
    try:
        return text_in(result, "any") == text
    except SLREvaluationError:
        return False


DET[("$text_to_string", 2)] = _text_to_string


_MESSAGE_PREFIXES = {"error": "ERROR: ", "warning": "Warning: ", "informational": "% "}


def message_text(kind: Any, message: Any, deadline: float | None = None) -> str | None:
    """The line print_message/2 writes to the standard error for a message of ``kind``
    (None: nothing, for ``silent``): ``format(Format, Args)`` formatted, any other term as
    SWI-Prolog writes a message it has no text for, after the kind's prefix.

    >>> message_text(Atom("warning"), Struct("format", (String("~w late"), make_list([Atom("cup1")]))))
    'Warning: cup1 late\\n'
    >>> message_text(Atom("error"), Atom("oops")), message_text(Atom("silent"), Atom("x"))
    ('ERROR: Unknown message: oops\\n', None)
    """
    kind = deref(kind)
    if type(kind) is Var:
        raise instantiation_error()
    if type(kind) is Atom and kind == "silent":
        return None
    message = deref(message)
    text = None
    if type(message) is Struct and message.name == "format" and len(message.args) == 2:
        try:
            text = format_text(text_in(message.args[0], "whole", numbers=False),
                               _format_args(message.args[1]), deadline)
        except SLREvaluationError:
            text = None
    if text is None:
        text = "Unknown message: " + _write_text(message, True, deadline)
    prefix = _MESSAGE_PREFIXES.get(str(kind), "") if type(kind) is Atom else ""
    return prefix + text + "\n"


def _print_message(m: "Machine", a: list) -> bool:
    """print_message(Kind, Message): its line to the standard error (never into a
    with_output_to/2 capture), as SWI-Prolog's (:func:`message_text`)."""
    text = message_text(a[0], a[1], m.deadline)
    if text is not None:
        (m.engine.err or sys.stderr).write(text)
    return True


DET[("$print_message", 2)] = _print_message


def _numbervars(m: "Machine", a: list) -> bool:
    """numbervars(T, Start, End): each unbound variable of T, depth-first left to right,
    bound to ``'$VAR'(N)`` from N = Start (which write/1, print/1 and format/2 write as
    ``A``, ``B``, ...); End the next number, as SWI-Prolog's."""
    from .terms import term_vars

    start = deref(a[1])
    if type(start) is Var:
        raise instantiation_error()
    if type(start) is not int:
        raise type_error("integer", start)
    n = start
    for v in term_vars(a[0], m.deadline):
        m.unify(v, Struct("$VAR", (n,)))
        n += 1
    return m.unify(a[2], n)


DET[("$numbervars", 3)] = _numbervars


def format_text(fmt: str, args: list, deadline: float | None = None, start: int = 0) -> str:
    """SWI-style ``format/2`` directives: ~w ~p ~q ~a ~d ~D ~s ~e ~E ~f ~g ~G ~n ~c ~r ~R ~8| ~t
    ~~ ~i ~*c; ``start``: the column the output goes on from (its column stops count from it).

    >>> format_text("~w has ~d items~n", [Atom("cup"), 3])
    'cup has 3 items\\n'
    """
    out = _BoundedText()
    args = list(args)
    i = 0
    n = len(fmt)
    columns = _ColumnStops(out)
    columns.column = columns.position = start

    def take():
        if not args:
            raise iso_error(Struct("format", (Atom("not enough arguments"),)))
        return args.pop(0)

    while i < n:
        ch = fmt[i]
        if ch != "~":
            out.append(ch)
            i += 1
            continue
        i += 1
        # the numeric argument: ~`c (a fill character), ~* (the next argument) or digits;
        # then an optional ':' (SWI-Prolog's locale modifier: its default locale, as here,
        # groups no digits) and the directive, NUL where the text ends (SWI-Prolog's
        # existence_error(format_character, '\x0\'), or the last digit of a count)
        num = ""
        digits_end = False                # a count's digits ran to the end of the text
        if i < n and fmt[i] == "`":
            if i + 1 < n:
                num = str(ord(fmt[i + 1]))
            i += 2
        elif i < n and fmt[i] == "*":   # a count as it is, not evaluated (SWI-Prolog's error)
            count = deref(take())
            # (SWI-Prolog takes a C int: a count beyond 2**31 - 1 is no count either)
            if type(count) is not int or not 0 <= count <= 0x7FFFFFFF:
                raise iso_error(Struct("format", (
                    Atom("no or negative integer for `*' argument"),)))
            num = int_text(count)
            i += 1
        else:
            while i < n and "0" <= fmt[i] <= "9":
                num += fmt[i]
                i += 1
            digits_end = i >= n and num != ""
        if i < n and fmt[i] == ":":
            i += 1
        d = fmt[i] if i < n else num[-1] if digits_end else "\0"
        i += 1
        if d == "w":
            columns.term(_write_text(take(), deadline=deadline))
        elif d in "pq":
            columns.term(_write_text(take(), True, deadline))
        elif d == "a":
            # atomic only, and not [] (text_of takes a code list and [])
            arg = deref(take())
            if type(arg) is Var or type(arg) is Struct or arg == NIL:
                raise _format_argument_type(d, arg)
            out.append(text_of(arg))
        elif d in "dD":
            v = _format_integer(take(), d)
            k = _count(num, 0)
            digits = int_text(abs(v))
            if d == "D":  # groups of three digits left of the point
                whole = digits[:-k] if k else digits
                whole = whole or "0"
                lead = len(whole) % 3 or 3
                whole = ",".join([whole[:lead]] + [whole[j:j + 3]
                                                    for j in range(lead, len(whole), 3)])
                digits = whole + (digits[-k:] if k else "")
            if k > 0:  # ~2d: the last k digits after a decimal point
                digits = digits.rjust(k + 1, "0")
                digits = digits[:-k] + "." + digits[-k:]
            out.append(("-" if v < 0 else "") + digits)
        elif d in "feEgG":
            v = evaluate(take())
            prec = min(_count(num, 6), 1000)
            out.append(_float_directive_text(v, prec, d))
        elif d == "s":
            out.append(_format_codes(take()))
        elif d == "n":
            out.append("\n" * _count(num, 1))
        elif d == "c":
            out.append(_format_char(take()) * _count(num, 1))
        elif d == "r" or d == "R":     # ~R: the digits beyond 9 as capitals
            v = _format_integer(take(), d)
            base = _count(num, 8)
            if not 2 <= base <= 36:
                raise _err_domain("radix", base)
            digits = "0123456789abcdefghijklmnopqrstuvwxyz"
            if d == "R":
                digits = digits.upper()
            s, x = "", abs(v)
            while True:
                s = digits[x % base] + s
                x //= base
                if not x:
                    break
            out.append(("-" if v < 0 else "") + s)
        elif d == "~":
            out.append("~")
        elif d == "i":
            take()
        elif d == "t":
            columns.fill(_char(_count(num, 32)))
        elif d == "|":
            columns.stop(None if not num else _count(num, 0), relative=False)
        elif d == "+":
            columns.stop(_count(num, 8), relative=True)
        else:
            raise iso_error(Struct("existence_error", (Atom("format_character"), Atom(d))))
    if args:  # an argument no directive took (SWI-Prolog's error)
        raise iso_error(Struct("format", (Atom("too many arguments"),)))
    return "".join(out)


def _float_directive_text(v: int | float, prec: int, d: str) -> str:
    """``~Nf``, ``~Ne``, ``~Ng`` (``~E``, ``~G``) of a number, as SWI-Prolog writes it: a
    float or an integer of 64 bits as C's printf writes the double, an integer beyond 64
    bits with all its digits (SWI-Prolog formats it with GMP: ``~e`` of ``10**400`` is
    ``1.000000e+400``, where a double overflows).

    >>> _float_directive_text(2.5, 2, "f"), _float_directive_text(10**400, 6, "e")
    ('2.50', '1.000000e+400')
    >>> _float_directive_text(-(10**30) - 7, 1, "f")
    '-1000000000000000000000000000007.0'
    """
    if type(v) is int and not -(2**63) <= v < 2**63:
        if d == "f":
            return int_text(v) + ("." + "0" * prec if prec else "")
        import decimal

        with decimal.localcontext() as context:
            context.rounding = decimal.ROUND_HALF_UP     # (GMP's, as SWI-Prolog's shows)
            text = format(decimal.Decimal(v), f".{prec}{d}")
        if d in "gG":  # as C's %g: no trailing zeros (a Decimal keeps them)
            mantissa, e, exponent = text.partition("e" if d == "g" else "E")
            if "." in mantissa:
                mantissa = mantissa.rstrip("0").rstrip(".")
            text = mantissa + e + exponent
        return text
    return f"{float(v):.{prec}{d}}"


def _count(num: str, default: int) -> int:
    """The numeric argument of a format directive (``~3d``, ``~*c``), or ``default``; a
    count beyond :data:`MAX_BUILT_TEXT` is resource_error(memory)."""
    if not num:
        return default
    if len(num) > 12:  # ~99999999999999999d: no column or count is that large
        raise resource_error("memory")
    count = int(num)
    if count > MAX_BUILT_TEXT:
        raise resource_error("memory")
    return count


class _ColumnStops:
    """format/2's column stops, as SWI-Prolog's: ``~t`` marks a fill point (``~Ct``,
    ``~`ct``: filled with character C or c, else spaces) in the text since the last stop;
    ``~N|`` (column N; bare: here) and ``~N+`` (N past the last stop, 8 by default) pad that
    text to the column at its fill points -- evenly, the rest spread from the middle one
    (``_fill_sizes``) -- or on its right when it has none. Text already past the column is
    left as it is, and the count goes on from the column all the same.

    The column is counted as SWI-Prolog 9 counts it: format's own text (its literal
    characters, ``~a``, ``~s``, ``~c``, numbers, ``~n``) one character at a time, a line
    break or carriage return back to 0, a tab to ``(column + 1) | 7``, a backspace one back;
    a term written by ``~w``, ``~p``, ``~q`` adds the column its text ends at when written
    on a line of its own (the output stream's count: a tab to ``(position | 7) + 1``) --
    unless no fill point is pending and the output so far ends at the column, where the
    term goes straight to the output and the column is where the output then ends. So
    ``format("ab~t~w~10|", ['\\nc'])`` pads 'ab' to 'ab' and 7 spaces: 'c' counts from
    column 2.

    >>> format_text("~w~t~10|~w", [Atom("abc"), Atom("def")])
    'abc       def'
    >>> format_text("~t~w~t~10|", [Atom("abc")]), format_text("~`-t~5|", [])
    ('   abc    ', '-----')
    >>> format_text("ab~t~w~10|", [Atom("\\nc")]), format_text("ab~t~a~10|", [Atom("\\nc")])
    ('ab       \\nc', 'ab         \\nc')
    """

    def __init__(self, out: "_BoundedText"):
        self.out = out
        self.start = 0            # the piece where the text since the last stop begins
        self.column = 0           # the column it begins at (format's count)
        self.position = 0         # where the output ends on its line there (the stream's)
        # the last stop, where ~N+ counts from: the line's start before the first (even when
        # format/2 goes on from a column of the stream's)
        self.last_stop = 0
        self.fills: list[tuple[int, str]] = []   # (piece, fill character) of each ~t
        self.terms: set[int] = set()             # the pieces ~w, ~p, ~q wrote

    def fill(self, char: str) -> None:
        self.fills.append((len(self.out), char))
        self.out.append("")

    def term(self, text: str) -> None:
        """Append the text of a term written by ~w, ~p or ~q."""
        self.terms.add(len(self.out))
        self.out.append(text)

    def _column_here(self) -> int:
        """The column at the end of the output, as SWI-Prolog counts it (the class's
        docstring)."""
        out = self.out
        column, position = self.column, self.position
        fills = {piece for piece, _ in self.fills}
        pending = False
        for index in range(self.start, len(out)):
            if index in fills:
                pending = True
                continue
            piece = out[index]
            if index not in self.terms:
                column = _format_column(piece, column)
            elif pending or position != column:
                column += _line_position(piece, 0)
            else:
                column = _line_position(piece, position)
            if not pending:          # (output goes straight to the stream until a ~t)
                position = _line_position(piece, position)
        return column

    def stop(self, count: int | None, relative: bool) -> None:
        out = self.out
        here = self._column_here()
        if count is None:
            target = here
        else:
            target = self.last_stop + count if relative else count
        pad = target - here
        if pad > 0:
            if self.fills:
                for (piece, char), size in zip(self.fills, _fill_sizes(pad, len(self.fills))):
                    out.put(piece, char * size)
            else:
                out.append(" " * pad)
        self.position = _line_position("".join(out[self.start:]), self.position)
        # the column is the stop's even where the text went past it (SWI-Prolog counts on
        # from the stop: "abcdef~3|~t~a~10|" pads 'x' from column 3)
        self.start, self.column, self.fills = len(out), target, []
        self.last_stop = target
        self.terms.clear()


def _fill_sizes(pad: int, fills: int) -> list[int]:
    """How many fill characters each of ``fills`` fill points gets of ``pad``, as
    SWI-Prolog's format/2 spreads them: each the same share, then the rest one at a time
    from the middle fill point outwards, alternately right and left at growing distances
    (``m``, ``m + 1``, ``m - 2``, ``m + 3``, ...; ``m = fills // 2``), where a distance
    past either end gives nothing (SWI-Prolog 9's pl-fmt.c: such a column comes out short).

    >>> _fill_sizes(7, 3), _fill_sizes(3, 4), _fill_sizes(9, 5)
    ([2, 3, 2], [1, 0, 1, 1], [2, 1, 2, 2, 1])
    """
    each, rest = divmod(pad, fills)
    sizes = [each] * fills
    middle = fills // 2
    for k in range(rest):
        index = middle + (k if k % 2 else -k)
        if 0 <= index < fills:
            sizes[index] += 1
    return sizes


def _format_column(text: str, column: int) -> int:
    """The column after format/2 output ``text`` from ``column``, as SWI-Prolog's format
    counts its own output (update_column(): a tab to ``(column + 1) | 7``).

    >>> _format_column("a\\tb", 0), _format_column("ab\\nc", 5), _format_column("\\b", 0)
    (8, 1, 0)
    """
    return _column_after(text, column, lambda c: (c + 1) | 7)


def _line_position(text: str, position: int) -> int:
    """Where an output stream's line ends after ``text`` written from ``position``, as
    SWI-Prolog's streams count it (a tab to ``(position | 7) + 1``).

    >>> _line_position("a\\tb", 0), _line_position("ab\\nc", 5), _line_position("\\b", 0)
    (9, 1, 0)
    """
    return _column_after(text, position, lambda c: (c | 7) + 1)


def _column_after(text: str, column: int, tab: Callable[[int], int]) -> int:
    """The column after ``text`` from ``column``: a new line or return goes to 0, a
    backspace back one, a tab where ``tab`` says (format and streams differ there)."""
    cut = max(text.rfind("\n"), text.rfind("\r"))
    if cut >= 0:
        column, text = 0, text[cut + 1:]
    if "\t" not in text and "\b" not in text:
        return column + len(text)
    for c in text:
        if c == "\t":
            column = tab(column)
        elif c == "\b":
            column = max(column - 1, 0)
        else:
            column += 1
    return column


class _BoundedText(list):
    """format/2's output so far: resource_error(memory) once it passes MAX_BUILT_TEXT
    characters (many directives, each within the bound)."""

    size = 0

    def _grow(self, piece: str) -> None:
        self.size += len(piece)
        if self.size > MAX_BUILT_TEXT:
            raise resource_error("memory")

    def append(self, piece: str) -> None:
        self._grow(piece)
        super().append(piece)

    def put(self, index: int, piece: str) -> None:
        """Put ``piece`` in place of the empty piece at ``index`` (a fill point)."""
        self._grow(piece)
        self[index] = piece


def _char(code: Any) -> str:
    """The character of a code (``~c``); as SWI-Prolog, representation_error(code_point)
    when the code is no Unicode character."""
    if type(code) is not int:
        raise type_error("integer", code)
    if not 0 <= code <= 0x10FFFF or 0xD800 <= code <= 0xDFFF:
        raise iso_error(Struct("representation_error", (Atom("code_point"),)))
    return chr(code)


def _format_argument_type(directive: str, culprit: Any) -> SLREvaluationError:
    """SWI-Prolog's error for an argument a format/2 directive does not take."""
    return iso_error(Struct("format_argument_type", (Atom(directive), culprit)))


def _format_integer(arg: Any, directive: str) -> int:
    """The integer of ``~d``, ``~D``, ``~r``, ``~R``: the argument evaluated, as SWI-Prolog;
    a value that is no integer is ``format_argument_type(D, Arg)`` (the argument as given),
    an infinity or a NaN the evaluation error SWI-Prolog raises for it.

    >>> _format_integer(Struct("+", (1, 2)), "d")
    3
    """
    v = evaluate(arg)
    if type(v) is not int:
        if v != v:
            raise evaluation_error("undefined")
        if v in (math.inf, -math.inf):
            raise evaluation_error("float_overflow")
        raise _format_argument_type(directive, deref(arg))
    return v


def _format_codes(arg: Any) -> str:
    """The text of ``~s``: a code or character list, a string or an atom, as SWI-Prolog
    takes it; anything else (a number, a partial or mixed list, a compound, a variable) is
    ``format_argument_type(s, Arg)``.

    >>> _format_codes(make_list([104, 105])), _format_codes(String("hi"))
    ('hi', 'hi')
    """
    arg = deref(arg)
    if type(arg) is String or type(arg) is Atom:
        return "" if arg == NIL else str(arg)
    if type(arg) is Struct and arg.name == CONS and len(arg.args) == 2:
        try:
            return _code_or_char_list_text(arg)
        except SLREvaluationError:
            pass
    raise _format_argument_type("s", arg)


def _format_char(arg: Any) -> str:
    """``~c``'s character: its argument a code as it is (not evaluated), as SWI-Prolog's; what
    is no code (an atom, a variable, a float, an expression, a negative integer) is SWI-Prolog's
    ``format_argument_type(c, Culprit)``.

    >>> _format_char(97)
    'a'
    """
    arg = deref(arg)
    if type(arg) is not int or arg < 0 or arg > 0x7FFFFFFF:   # (no C int: no code either)
        raise _format_argument_type("c", arg)
    return _char(arg)


def _format_args(t: Any) -> list:
    t = deref(t)
    items, tail = list_items(t)
    if type(tail) is Atom and tail == "[]" and (items or t == "[]"):
        return items
    return [t]


@det("format", 1)
def _format1(m, a):
    out = _out(m)
    out.write(format_text(text_in(a[0], "whole", numbers=False), [], m.deadline,
                          getattr(out, "position", 0)))
    return True


@det("format", 2)
def _format2(m, a):
    out = _out(m)
    out.write(format_text(text_in(a[0], "whole", numbers=False), _format_args(a[1]),
                          m.deadline, getattr(out, "position", 0)))
    return True


@det("format", 3)
def _format3(m, a):
    sink = _output_sink(m, a[0])
    text = format_text(text_in(a[1], "whole", numbers=False), _format_args(a[2]), m.deadline)
    if type(sink) is Struct:
        return _unify_sink(m, sink, text)
    sink.write(text)
    return True


def _sformat(m: "Machine", a: list) -> bool:
    """sformat(S, Format[, Args]): format/3 into a string, SWI-Prolog's old spelling of
    ``format(string(S), Format, Args)``."""
    args = _format_args(a[2]) if len(a) == 3 else []
    text = format_text(text_in(a[1], "whole", numbers=False), args, m.deadline)
    return m.unify(a[0], String(text))


DET[("$sformat", 3)] = _sformat
DET[("$sformat", 2)] = _sformat


DET[("halt", 0)] = lambda m, a: (_ for _ in ()).throw(
    iso_error(Struct("permission_error", (Atom("halt"), Atom("system"), Atom("halt")))))


# -- collecting: findall, aggregate_all, bagof, setof, forall --------------------------------------

def _strip_carets(goal: Any) -> tuple[Any, list]:
    """``V^W^G`` -> (G, [V, W]). ``p(..)^T`` (an event atom: a time or ``[S,E]`` on the right)
    is a goal, not a quantification."""
    quantified = []
    goal = deref(goal)
    while type(goal) is Struct and goal.name == "^" and len(goal.args) == 2:
        left, right = deref(goal.args[0]), deref(goal.args[1])
        right_is_goal = (type(right) is Atom) or (type(right) is Struct and right.name != ".")
        if type(left) is not Var and not right_is_goal:
            break
        quantified.append(left)
        goal = right
    return goal, quantified


# the library predicates SWI-Prolog names in the context of their goal's errors: findall/3
# (and bagof/3, setof/3, aggregate_all's bag and set) run it in '$bags':findall_loop/4
_FINDALL_LOOP = _pi("findall_loop", 4, "$bags")
_AGGREGATE_ALL = _pi("aggregate_all", 3, "aggregate")


def collector(m: "Machine", key, args, nxt):
    """Start the all-solutions builtin ``key`` (findall/3,4, forall/2, aggregate_all/3,
    bagof/3, setof/3) on the machine ``m``; ``nxt`` is the continuation after it.

    >>> from slr_sql.engine import Engine
    >>> m = Engine(Program()).machine(); x, found = Var("X"), Var("L")
    >>> goal = Struct("findall", (x, Struct("member", (x, make_list([1, 2]))), found))
    >>> [str(found) for _ in m.solve(goal)]
    ['[1,2]']
    """
    name, arity = key
    if name in ("findall", "findAll") and arity == 3:
        def finish(m, results, nxt, out=args[2]):
            return nxt if m.unify(out, make_list(results)) else False
        return m.push_collect(args[0], args[1], finish, nxt, caller=_FINDALL_LOOP)
    if name == "findall" and arity == 4:
        def finish(m, results, nxt, out=args[2], tail=args[3]):
            return nxt if m.unify(out, make_list(results, tail)) else False
        return m.push_collect(args[0], args[1], finish, nxt, caller=_FINDALL_LOOP)
    if name == "forall":
        m.meta_check(args[0], _pi("forall", 2, "$apply"))
        goal = Struct("\\+", (Struct(",", (Struct("call", (args[0],)),
                                           Struct("\\+", (Struct("call", (args[1],)),)))),))
        return (goal, len(m.cps), nxt)
    if name == "aggregate_all":
        return _aggregate_all(m, args, nxt)
    if name in ("bagof", "setof"):
        return _bagof(m, args, nxt, name == "setof")
    raise AssertionError(key)


def _aggregate_all(m: "Machine", args, nxt):
    spec = deref(args[0])
    goal = args[1]
    out = args[2]
    if type(spec) is Atom and spec == "count":
        return m.push_collect(NIL, goal, lambda m, r, nxt: nxt if m.unify(out, len(r)) else False, nxt,
                              caller=_AGGREGATE_ALL)
    if type(spec) is Struct and spec.name in ("max", "min") and len(spec.args) == 2:
        return _aggregate_witness(m, spec, goal, out, nxt)
    if type(spec) is not Struct or len(spec.args) != 1:
        if type(spec) is Var:
            raise instantiation_error()
        raise _err_domain("aggregate_template", spec)
    kind = spec.name
    template = spec.args[0]
    if kind in ("sum", "max", "min"):
        return _aggregate_arith(m, kind, template, goal, out, nxt)

    def finish(m, results, nxt):
        if kind == "count":
            value = len(results)
        elif kind == "bag":
            value = make_list(results)
        elif kind == "set":
            value = make_list(_dedup(sorted(results, key=_cmp_key)))
        else:
            raise _err_domain("aggregate_template", spec)
        return nxt if m.unify(out, value) else False

    return m.push_collect(template, goal, finish, nxt, caller=_FINDALL_LOOP)


def _raising_in(each: Callable[[Any], None], culprit: Any) -> Callable[[Any], None]:
    """``each`` whose errors name ``culprit`` in their context, as the library's errors
    name the comparison or ``is`` that raised them (an arithmetic function's own error
    keeps the function's)."""
    def checked(found: Any) -> None:
        try:
            each(found)
        except SLREvaluationError as exc:
            raise with_context(exc, culprit)
    return checked


def _better(kind: str, x: Any, best: Any) -> bool:
    """``X > Best`` (max) or ``X < Best`` (min), as the library compares a witness form's
    solutions: its errors are the comparison's."""
    try:
        a, b = evaluate(x), evaluate(best)
    except SLREvaluationError as exc:
        raise with_context(exc, _pi(">" if kind == "max" else "<", 2))
    return a > b if kind == "max" else a < b


def _aggregate_arith(m: "Machine", kind: str, template, goal, out, nxt):
    """``aggregate_all(sum(X) | max(X) | min(X), ..)`` as SWI-Prolog's library(aggregate):
    each solution is evaluated as it comes (``S is S0 + X``, ``M is max(M0, X)``), so a
    solution that is no number raises its error there, before any error a later solution
    of the goal would throw. ``max(X-W)``/``min(X-W)``: the witness form (docs/sql.md),
    answered as ``max(X, W)`` is (:func:`_aggregate_witness`): the first X must be a number,
    then the first solution whose X is strictly better, X compared as it comes."""
    t0 = deref(template)
    witness = kind != "sum" and type(t0) is Struct and t0.name == "-" and len(t0.args) == 2
    state: list = [0] if kind == "sum" else []   # the sum; or the best so far

    def each(found) -> None:
        if kind == "sum":
            state[0] = apply_binary("+", state[0], evaluate(found))
        elif witness:
            if not state:
                first = deref(deref(found).args[0])
                if type(first) is Var:
                    raise instantiation_error()
                if type(first) not in (int, float):
                    raise type_error("number", first)
                state.append(found)
                return
            if _better(kind, deref(found).args[0], deref(state[0]).args[0]):
                state[0] = found
        else:
            value = evaluate(found)
            # the first solution is max(X, X), as SWI-Prolog's State = state(X) starts:
            # max(inf, inf) is float_overflow, so a lone inf is too
            state[:] = [apply_binary(kind, state[0] if state else value, value)]

    if not witness:
        each = _raising_in(each, _pi("is", 2))

    def finish(m, results, nxt):
        if not state:
            return False
        if witness:
            best = deref(state[0])
            value = Struct(kind, (best.args[0], best.args[1]))
        else:
            value = state[0]
        return nxt if m.unify(out, value) else False

    return m.push_collect(template, goal, finish, nxt, each, caller=_AGGREGATE_ALL)


def _aggregate_witness(m: "Machine", spec: Struct, goal, out, nxt):
    """``aggregate_all(max(X, W), Goal, max(Max, Witness))`` (and min) as SWI-Prolog's
    library(aggregate): the first solution whose X is strictly better than every earlier
    one, X kept as it was found; the first X must be a number. Each solution is compared as
    it comes, so its error comes before any a later solution of the goal would throw."""
    kind = spec.name
    best: list = []
    # the library's clause head is aggregate_all(max(X, W), Goal, max(Max, Witness)): the
    # result is max(Max, Witness) before the goal runs (a goal sharing it sees that); a
    # result that is none goes to the library's general clause, which evaluates each
    # solution's X (X1 is X) and then fails
    result = Struct(kind, (Var("_Max"), Var("_Witness")))
    if not m.unify(out, result):
        return m.push_collect(spec.args[0], goal, lambda m, r, nxt: False, nxt,
                              _raising_in(evaluate, _pi("is", 2)), caller=_AGGREGATE_ALL)

    def each(found) -> None:
        found = deref(found)
        if not best:
            first = deref(found.args[0])
            if type(first) is Var:
                raise instantiation_error()
            if type(first) not in (int, float):
                raise type_error("number", first)
            best.append(found)
            return
        if _better(kind, found.args[0], best[0].args[0]):
            best[0] = found


    def finish(m, results, nxt):
        if not best:
            return False
        return nxt if m.unify(result, Struct(kind, (best[0].args[0], best[0].args[1]))) else False

    return m.push_collect(Struct("w", (spec.args[0], spec.args[1])), goal, finish, nxt, each,
                          caller=_AGGREGATE_ALL)


def _bagof(m: "Machine", args, nxt, is_set: bool):
    template, goal, out = args
    inner, quantified = _strip_carets(goal)
    excluded = {id(v) for v in term_vars(Struct("t", (template, *quantified)))}
    witness_vars = [v for v in term_vars(inner) if id(v) not in excluded]
    witness = make_list(witness_vars)
    pair = Struct("-", (witness, template))

    def finish(m, results, nxt):
        if not results:
            return False
        groups: list[tuple[Any, list]] = []
        if not witness_vars:
            groups = [(witness, [deref(r).args[1] for r in results])]
        else:
            ordered = sorted(results, key=lambda r: _cmp_key(deref(r).args[0]))
            for r in ordered:
                w, t = deref(r).args
                for g in groups:
                    if _variant(g[0], w):
                        # one witness for the group, as SWI-Prolog's pick_same/4 (V = Vars):
                        # the variables of its solutions' copies become the same ones
                        m.unify(g[0], w)
                        g[1].append(t)
                        break
                else:
                    groups.append((w, [t]))
        if is_set:
            groups = [(w, _dedup(sorted(items, key=_cmp_key))) for w, items in groups]
        return m.push_solutions(_bag_solutions(m, witness, out, groups), nxt)

    return m.push_collect(pair, inner, finish, nxt, caller=_FINDALL_LOOP)


def _bag_solutions(m: "Machine", witness, out, groups) -> Iterator[None]:
    for w, items in groups:
        mark = len(m.trail)
        if m.unify(witness, w) and m.unify(out, make_list(items)):
            yield None
        m.undo_to(mark)


def _variant(a: Any, b: Any, deadline: float | None = None) -> bool:
    mapping: dict = {}
    back: dict = {}
    stack = [(a, b)]
    # pairs of compounds already compared (or being compared further down the stack):
    # comparing one again adds nothing, so cyclic and shared terms take finite, linear time
    seen: set[tuple[int, int]] = set()
    clock = NODES_BETWEEN_CLOCK_CHECKS
    while stack:
        clock -= 1
        if not clock:
            clock = NODES_BETWEEN_CLOCK_CHECKS
            check_deadline(deadline)
        x, y = stack.pop()
        x, y = deref(x), deref(y)
        if type(x) is Var and type(y) is Var:
            if mapping.setdefault(id(x), id(y)) != id(y) or back.setdefault(id(y), id(x)) != id(x):
                return False
        elif type(x) is Struct and type(y) is Struct:
            if x.name != y.name or len(x.args) != len(y.args):
                return False
            key = (id(x), id(y))
            if key in seen:
                continue
            seen.add(key)
            stack.extend(zip(x.args, y.args))
        elif type(x) is not type(y):
            return False
        elif type(x) is float:
            if not same_float(x, y):
                return False
        elif x != y:
            return False
    return True


# -- prev / next -----------------------------------------------------------------------------------

def _time_value(t: Any) -> float:
    t = deref(t)
    if type(t) is Var:
        raise instantiation_error()
    v = evaluate(t)
    try:
        return float(v)
    except OverflowError:
        # an integer beyond the largest float compares beyond every stored (float) time
        return math.inf if v > 0 else -math.inf


def _interval(t: Any) -> tuple[float, float] | None:
    t = deref(t)
    if type(t) is Struct and t.name == "." and len(t.args) == 2:
        items, tail = list_items(t)
        if len(items) == 2 and tail == "[]":
            return _time_value(items[0]), _time_value(items[1])
        raise type_error("interval", t)
    return None


def _event_pattern(t: Any, op: str):
    ev = split_event_atom(t)
    if ev is None:
        t = deref(t)
        if type(t) is Var:
            raise instantiation_error()
        raise type_error("event_atom", t)
    atom, s, e = ev
    name, n = event_key(atom)
    args = tuple(atom.args) if type(atom) is Struct else ()
    return name, n, args, s, e


def matching_rows(m: "Machine", pattern: tuple, rows) -> Iterator[tuple]:
    """Rows of ``rows`` that match ``pattern`` (data arguments + (start, end); the stored
    times by value, see :func:`slr_sql.unify.match_time`), tested, bindings undone.

    >>> from slr_sql.engine import Engine
    >>> m = BuiltinMachine(Engine(Program(), None))
    >>> rows = [((Atom("a"),), 1.0, 1.0), ((Atom("b"),), 2.0, 2.0)]
    >>> [row[0] for row in matching_rows(m, (Atom("b"), Var("S"), Var("E")), rows)]
    [(Atom('b'),)]
    """
    trail = m.trail
    args, s, e = pattern[:-2], pattern[-2], pattern[-1]
    for row in rows:
        mark = len(trail)
        ok = unify_event_row(args, s, e, row[0], row[1], row[2], trail)
        undo(trail, mark)
        if ok:
            yield row


def _yield_rows(m: "Machine", pattern: tuple, rows) -> Iterator[None]:
    """Bind ``pattern`` to each row it matches in turn (as :func:`matching_rows`)."""
    trail = m.trail
    args, s, e = pattern[:-2], pattern[-2], pattern[-1]
    for row in rows:
        mark = len(trail)
        if unify_event_row(args, s, e, row[0], row[1], row[2], trail):
            yield None
        undo(trail, mark)


@nondet("prev", 2)
def _prev(m, a):
    """prev(E^Z, T): the matching event(s) with the greatest end <= T (ties: all, store order);
    prev(E^Z, [A,B]): the latest matching event with A =< start and end =< B."""
    name, n, args, s, e = _event_pattern(a[0], "prev")
    iv = _interval(a[1])
    if iv is None:
        start_ge, t = None, _time_value(a[1])
    else:
        start_ge, t = iv
    if t != t or start_ge != start_ge:
        return   # NaN: no time is at, before or after it (no history to wait for either)
    if m.on_prev is not None:
        m.on_prev(name, n, t)
    store = m.engine.events
    if store is None:
        return

    bound = bound_args(args)
    pattern = args + (s, e)
    if m.robot is not None:  # one robot's events (a fleet store asked per robot)
        first = next(matching_rows(m, pattern, store.prev_candidates(
            name, n, bound, t, start_ge, robot=m.robot)), None)
        if first is not None:
            yield from _yield_rows(m, pattern, store.rows_at_end(
                name, n, bound, first[2], start_ge=start_ge, robot=m.robot))
        return
    first = next(matching_rows(m, pattern, store.prev_candidates(name, n, bound, t, start_ge)), None)
    if first is None:
        return
    yield from _yield_rows(m, pattern, store.rows_at_end(name, n, bound, first[2], start_ge=start_ge))


def _next(m, event, lo_t, hi_t):
    name, n, args, s, e = _event_pattern(event, "next")
    lo, hi = _time_value(lo_t), _time_value(hi_t)
    if lo != lo or hi != hi:
        return   # NaN: no time is at, before or after it (no history to wait for either)
    if m.on_next is not None:
        m.on_next(name, n, lo, hi, args, s, e)  # sync: the full pattern, for in_order
    store = m.engine.events
    if store is None:
        return

    bound = bound_args(args)
    pattern = args + (s, e)
    if m.robot is not None:  # one robot's events (a fleet store asked per robot)
        first = next(matching_rows(m, pattern, store.next_candidates(
            name, n, bound, lo, hi, robot=m.robot)), None)
        if first is not None:
            yield from _yield_rows(m, pattern, store.rows_at_start(
                name, n, bound, first[1], hi, robot=m.robot))
        return
    first = next(matching_rows(m, pattern, store.next_candidates(name, n, bound, lo, hi)), None)
    if first is None:
        return
    yield from _yield_rows(m, pattern, store.rows_at_start(name, n, bound, first[1], hi))


@nondet("next", 2)
def _next2(m, a):
    iv = _interval(a[1])
    if iv is None:
        t = deref(a[1])
        if type(t) is Var:
            raise instantiation_error()
        raise type_error("interval", t)
    yield from _next(m, a[0], iv[0], iv[1])


@nondet("next", 3)
def _next3(m, a):
    yield from _next(m, a[0], a[1], a[2])


# -- origin/2: whose events ---------------------------------------------------------------------------

def origin_goal(goal: Any) -> Any:
    """The goal of ``origin(R, Goal)`` if it is an event goal, prev/2, next/2 or next/3;
    raises the ISO error otherwise.

    >>> str(origin_goal(Struct("prev", (Struct("^", (Struct("seen", (Var("X"),)), Var("T"))), 5))))
    'prev(seen(X)^T,5)'
    >>> origin_goal(Atom("true"))
    Traceback (most recent call last):
    slr_sql.errors.SLREvaluationError: error(type_error(event_goal,true),_)
    """
    g = deref(goal)
    if type(g) is Var:
        raise instantiation_error()
    if type(g) is Struct and ((g.name == "^" and len(g.args) == 2 and split_event_atom(g))
                              or (g.name, len(g.args)) in (("prev", 2), ("next", 2),
                                                           ("next", 3))):
        return g
    raise type_error("event_goal", g)


@nondet("origin", 2)
def _origin(m, a):
    """origin(R, Goal): Goal (an event goal, prev or next) over robot R's events only; with R
    unbound, robot by robot in name order, binding R. Inside a query restricted to one robot
    (``kb.query(goal, robot=...)``) only that robot is seen."""
    goal = origin_goal(a[1])
    r = deref(a[0])
    if type(r) is Var:
        store = m.engine.events
        robots = store.robots() if store is not None else []
    elif type(r) is Atom:
        robots = [str(r)]
    else:
        raise type_error("atom", r)
    if m.robot is not None:
        robots = [name for name in robots if name == m.robot]
    for name in robots:
        # the goal runs in a machine of its own reading only this robot's events; its
        # answers (event rows: ground) are copied out and bound here one by one
        sub = m.engine.machine(at=m.at)
        sub.deadline, sub.max_steps, sub.timeout = m.deadline, m.max_steps, m.timeout
        sub.on_prev, sub.on_next = m.on_prev, m.on_next
        sub.robot = name
        answers = []
        solving = sub.solve(goal)
        try:
            for _ in solving:
                answers.append(copy_term(goal))
        finally:
            sub.abandon(solving)
            undo(sub.trail, 0)
        robot = Atom(name)
        for answer in answers:
            mark = len(m.trail)
            if m.unify(a[0], robot) and m.unify(goal, answer):
                yield None
            m.undo_to(mark)


# -- robot library -----------------------------------------------------------------------------------

def _pair(t: Any) -> tuple[Any, Any]:
    items = proper_list(t)
    if len(items) != 2:
        raise type_error("value_time_pair", t)
    return items[0], items[1]


def _robot_call(f, *args):
    from .robotlib import RobotValueError

    try:
        return f(*args)
    except RobotValueError as exc:
        raise iso_error(Struct("domain_error", (Atom("robot_value"), String(str(exc)))))


@det("interpolate", 3)
def _interpolate(m, a):
    from . import robotlib

    v, t = _pair(a[0])
    v1, t1 = _pair(a[1])
    v2, t2 = _pair(a[2])
    value = _robot_call(robotlib.interpolate, float(evaluate(t)), to_python(v1),
                        float(evaluate(t1)), to_python(v2), float(evaluate(t2)))
    return m.unify(v, from_python(value))


@det("extrapolate", 2)
def _extrapolate(m, a):
    from . import robotlib

    v, _t = _pair(a[0])
    v1, _t1 = _pair(a[1])
    return m.unify(v, from_python(_robot_call(robotlib.extrapolate, to_python(v1))))


@det("pos_multiply", 2)
def _pos_multiply(m, a):
    from . import robotlib

    items = proper_list(a[0])
    if not items:
        raise _err_domain("non_empty_list", NIL)
    fast = _pos_multiply_terms(items)
    if fast is not None:
        return m.unify(a[1], fast)
    p = to_python(items[0])
    transforms = [to_python(x) for x in items[1:]]
    return m.unify(a[1], from_python(_robot_call(robotlib.pos_multiply, p, transforms)))


def _number_tuple(t: Any, n: int) -> tuple | None:
    """The numbers of a proper list of exactly ``n`` ints/floats, else None."""
    items, tail = list_items(t)
    if len(items) != n or not (type(tail) is Atom and tail == "[]"):
        return None
    out = []
    for x in items:
        if type(x) is Var:
            x = deref(x)
        if type(x) is not float and type(x) is not int:
            return None
        out.append(x)
    return tuple(out)


def _plain_value(t: Any) -> Any:
    """A point ``[X,Y,Z]`` or ``pose([X,Y,Z],[QX,QY,QZ,QW])`` of numbers as tuples (what
    robotlib.pos_multiply_fast reads), else None."""
    t = deref(t)
    if type(t) is Struct and t.name == "pose" and len(t.args) == 2:
        tr = _number_tuple(t.args[0], 3)
        q = _number_tuple(t.args[1], 4)
        return None if tr is None or q is None else Struct("pose", (tr, q))
    return _number_tuple(t, 3)


def _pos_multiply_terms(items: list) -> Any:
    """pos_multiply of plain points and poses straight from the terms (no to_python /
    from_python round trip; the same floats), or None for the general path."""
    from . import robotlib

    values = []
    for x in items:
        v = _plain_value(x)
        if v is None:
            return None
        values.append(v)
    out = robotlib.pos_multiply_fast(values[0], values[1:])
    if out is None:
        return None
    if type(out) is list:
        return make_list(out)
    return Struct("pose", (make_list(out.args[0]), make_list(out.args[1])))


@det("distance", 3)
def _distance(m, a):
    from . import robotlib

    return m.unify(a[2], from_python(_robot_call(robotlib.distance, to_python(a[0]), to_python(a[1]))))


# -- get_field/3: message terms read by field name ------------------------------------------

def _message_fields(t: Any) -> list | None:
    """[(name, value)] of a message term ``Type(Name: Value, ...)``; else None."""
    t = deref(t)
    if type(t) is not Struct or not t.args or (t.name == "." and len(t.args) == 2):
        return None
    out = []
    for arg in t.args:
        arg = deref(arg)
        if type(arg) is not Struct or arg.name != ":" or len(arg.args) != 2:
            return None
        key = deref(arg.args[0])
        if type(key) is not Atom:
            return None
        out.append((key, arg.args[1]))
    return out


def _field_steps(path: Any) -> list:
    """The steps of a field path: an atom ``'pose.position.x'`` / ``'poses[0].position'``, or a
    list of field names (atoms) and list indexes (integers, from 0)."""
    path = deref(path)
    if type(path) is Atom:
        steps: list = []
        for segment in str(path).split("."):
            name, _, rest = segment.partition("[")
            if not name:
                raise _err_domain("field_path", path)
            steps.append(Atom(name))
            while rest:
                index, close, rest = rest.partition("]")
                if not close or not index.lstrip("-").isdigit() or (rest and rest[0] != "["):
                    raise _err_domain("field_path", path)
                steps.append(int(index))
                rest = rest[1:]
        return steps
    if type(path) is int:
        return [path]
    items = proper_list(path)
    out = []
    for item in items:
        item = deref(item)
        if type(item) is Var:
            raise instantiation_error()
        if type(item) is not Atom and type(item) is not int:
            raise _err_domain("field_path", path)
        out.append(item)
    return out


@nondet("get_field", 3)
def _get_field(m, a):
    """get_field(Message, Path, Value): the field of a message term (how ROS messages reach
    SLR: ``'geometry_msgs/msg/Point'(x: 1.0, y: 2.0, z: 0.5)``) at Path -- an atom naming a
    field or a dotted path with list indexes (``'poses[0].position.x'``), or a list of names
    and indexes. Fails when there is no such field. With Path unbound: each field of the
    message in turn, Path bound to its name."""
    msg = deref(a[0])
    if type(msg) is Var:
        raise instantiation_error()
    fields = _message_fields(msg)
    if fields is None:
        raise type_error("message", msg)
    path = deref(a[1])
    if type(path) is Var:
        trail = m.trail
        for key, value in fields:
            mark = len(trail)
            if m.unify(path, key) and m.unify(a[2], value):
                yield None
            undo(trail, mark)
        return
    value: Any = msg
    for step in _field_steps(path):
        if type(step) is int:
            items, tail = list_items(deref(value))
            if not (type(tail) is Atom and tail == "[]") or not -len(items) <= step < len(items):
                return
            value = items[step]
            continue
        fields = _message_fields(value)
        if fields is None:
            return
        for key, v in fields:
            if key == step:
                value = v
                break
        else:
            return
    if m.unify(a[2], value):
        yield None


# -- tf_lookup: tf2's lookupTransform over the stored tf / tf_static events (slr_sql.frames) --

def _frame(t: Any) -> Any:
    t = deref(t)
    if type(t) is Var:
        raise instantiation_error()
    if not is_ground(t):
        raise instantiation_error()
    return t


def _tf_hooks(m: "Machine") -> Any:
    if m.on_prev is None and m.on_next is None and m.on_arrival is None:
        return None
    from .frames import TfHooks

    def prev(key, t):
        if m.on_prev is not None:
            m.on_prev(key[0], key[1], t)

    def next_(key, lo, hi, args):
        if m.on_next is not None:
            m.on_next(key[0], key[1], lo, hi, tuple(args) + (Var(),), Var(), Var())

    def arrival(key, t, args):
        if m.on_arrival is not None:
            m.on_arrival(key[0], key[1], t, tuple(args) + (Var(),))
    return TfHooks(prev, next_, arrival)


def _tf_lookup(m: "Machine", a: tuple, extrapolate: bool) -> bool:
    from .frames import FrameTree, PoseOverflow, lookup

    target, source = _frame(a[0]), _frame(a[1])
    t = _time_value(a[2])
    store = m.engine.events
    if store is None:
        return False
    tree = m.engine.frames
    if tree is None:
        tree = m.engine.frames = FrameTree()
    try:
        pose = lookup(store, tree, target, source, t, extrapolate, _tf_hooks(m),
                      getattr(m, "check_deadline", None))
    except PoseOverflow:
        raise evaluation_error("float_overflow") from None
    if pose is None:
        return False
    return m.unify(a[3], Struct("pose", (make_list(list(pose[0])), make_list(list(pose[1])))))


@det("tf_lookup", 4)
def _tf_lookup4(m, a):
    """tf_lookup(Target, Source, T, Pose): the pose of frame Source in frame Target at T,
    chained through the stored frame tree; fails outside an edge's observations."""
    return _tf_lookup(m, a, False)


@det("tf_lookup", 5)
def _tf_lookup5(m, a):
    """tf_lookup(Target, Source, T, Pose, Mode): Mode ``interpolate`` is tf_lookup/4;
    ``extrapolate`` holds an edge's nearest observation outside its observations."""
    mode = deref(a[4])
    if type(mode) is Var:
        raise instantiation_error()
    if type(mode) is not Atom:
        raise type_error("atom", mode)
    if mode not in ("interpolate", "extrapolate"):
        raise _err_domain("tf_lookup_mode", mode)
    return _tf_lookup(m, a, mode == "extrapolate")


# -- Python-defined predicates ---------------------------------------------------------------------

class BuiltinMachine:
    """What a deterministic builtin needs of a machine when it runs outside one (called
    from SQL, or for the builtin goals of an event rule's ``where``): a trail to bind on,
    a time ``at`` (set by the caller), no hooks (such a goal reads no history), and the
    ``deadline`` (``time.monotonic()``, None: none) of the statement or query it runs for.

    >>> from slr_sql.engine import Engine
    >>> from slr_sql.program import Program
    >>> m = BuiltinMachine(Engine(Program(), None))
    >>> y = Var("Y"); DET[("copy_term", 2)](m, (Struct("f", (Var("X"),)), y)), deref(y)
    (True, Struct('f', (Var('_G...'),)))
    """

    __slots__ = ("engine", "trail", "at", "on_prev", "on_next", "cps", "deadline")

    def __init__(self, engine: Any):
        self.engine = engine
        self.trail: list = []
        self.at = None
        self.on_prev = None
        self.on_next = None
        self.cps: list = []
        self.deadline = None

    def unify(self, a: Any, b: Any) -> bool:
        return unify(a, b, self.trail)

    def undo_to(self, mark: int) -> None:
        undo(self.trail, mark)

    def check_deadline(self) -> None:
        check_deadline(self.deadline)



def call_python_pred(m: "Machine", fn: Callable, args: tuple) -> bool:
    """Call a predicate registered with ``kb.define``.

    ``fn`` gets the arguments as Python values (unbound ones as :class:`Var`) and returns
    ``True``/``False``/``None`` (succeed/fail/fail), a tuple/list with one value per argument
    (unified with the arguments), or a dict ``{position: value}`` (0-based positions).

    >>> from slr_sql.engine import Engine
    >>> m = BuiltinMachine(Engine(Program(), None)); total = Var("T")
    >>> call_python_pred(m, lambda a, b, _: {2: a + b}, (1, 2, total)), deref(total)
    (True, 3)
    """
    values = [to_python(x) for x in args]
    try:
        result = fn(*values)
    except (SLRError, MemoryError, RecursionError):
        raise  # ours, or resource errors the machine turns into ISO ones
    except Exception as exc:
        # a bug in the user's function reaches the caller as an SLR error naming it
        name = getattr(fn, "__name__", "a defined predicate")
        raise iso_error(Struct("python_error", (String(
            f"{name} raised {type(exc).__name__}: {exc}"),))) from exc
    if result is None or result is False:
        return False
    if result is True:
        return True
    if isinstance(result, dict):
        return all(m.unify(args[i], from_python(v)) for i, v in result.items())
    if isinstance(result, (tuple, list)):
        if len(result) != len(args):
            raise iso_error(Struct("python_error", (String(
                f"defined predicate returned {len(result)} values for {len(args)} arguments"),)))
        return all(m.unify(x, from_python(v)) for x, v in zip(args, result))
    raise iso_error(Struct("python_error", (String(f"defined predicate returned {result!r}"),)))


# -- the Prolog-defined library ---------------------------------------------------------------------

LIBRARY_SOURCE = r"""
member(X, [Y|Ys]) :- member_(Ys, X, Y).
member_(_, X, X).
member_([Y|Ys], X, _) :- member_(Ys, X, Y).
append([], L, L).
append([H|T], L, [H|R]) :- append(T, L, R).
append(ListOfLists, List) :- '$must_be_list'(ListOfLists), '$append_all'(ListOfLists, List).
'$append_all'([], []).
'$append_all'([L|Ls], As) :- append(L, Ws, As), '$append_all'(Ls, Ws).
nth0(I, L, E) :- integer(I), !, I >= 0, '$nth_det'(I, L, E).
nth0(I, L, E) :- var(I), !, '$nth_gen'(L, E, 0, I).
nth0(I, _, _) :- throw(error(type_error(integer, I), _)).
nth1(I, L, E) :- integer(I), !, I >= 1, I0 is I-1, '$nth_det'(I0, L, E).
nth1(I, L, E) :- var(I), !, '$nth_gen'(L, E, 1, I).
nth1(I, _, _) :- throw(error(type_error(integer, I), _)).
'$nth_det'(0, [E|_], E) :- !.
'$nth_det'(I, [_|T], E) :- I1 is I-1, '$nth_det'(I1, T, E).
'$nth_gen'([E|_], E, B, B).
'$nth_gen'([_|T], E, B0, B) :- B1 is B0+1, '$nth_gen'(T, E, B1, B).
nth0(I, L, E, R) :- var(I), !, '$nth_gen'(L, E, R, 0, I).
nth0(I, L, E, R) :- '$nth_index'(I, nonneg, 0), '$nth_del'(I, L, E, R).
nth1(I, L, E, R) :- var(I), !, '$nth_gen'(L, E, R, 1, I).
nth1(I, L, E, R) :- '$nth_index'(I, positive_integer, 1), I0 is I-1, '$nth_del'(I0, L, E, R).
'$nth_index'(I, Type, Min) :- ( integer(I), I >= Min -> true ; throw(error(type_error(Type, I), _)) ).
'$nth_gen'([E|R], E, R, B, B).
'$nth_gen'([H|T], E, [H|R], B0, B) :- B1 is B0+1, '$nth_gen'(T, E, R, B1, B).
'$nth_del'(0, [E|R], E, R) :- !.
'$nth_del'(I, [H|T], E, [H|R]) :- I1 is I-1, '$nth_del'(I1, T, E, R).
last([X|Xs], Last) :- '$last'(Xs, X, Last).
'$last'([], Last, Last).
'$last'([X|Xs], _, Last) :- '$last'(Xs, X, Last).
select(X, [Head|Tail], Rest) :- '$select3'(Tail, Head, X, Rest).
'$select3'(Tail, Head, Head, Tail).
'$select3'([Head2|Tail], Head, X, [Head|Rest]) :- '$select3'(Tail, Head2, X, Rest).
selectchk(Elem, List, Rest) :- select(Elem, List, Rest0), !, Rest = Rest0.
exclude(_, [], []).
exclude(P, [H|T], R) :- ( call(P, H) -> R = R1 ; R = [H|R1] ), exclude(P, T, R1).
include(_, [], []).
include(P, [H|T], R) :- ( call(P, H) -> R = [H|R1] ; R = R1 ), include(P, T, R1).
partition(_, [], [], []).
partition(P, [H|T], I, E) :- ( call(P, H) -> I = [H|I1], E = E1 ; I = I1, E = [H|E1] ), partition(P, T, I1, E1).
maplist(_, []).
maplist(G, [A|As]) :- call(G, A), maplist(G, As).
maplist(_, [], []).
maplist(G, [A|As], [B|Bs]) :- call(G, A, B), maplist(G, As, Bs).
maplist(_, [], [], []).
maplist(G, [A|As], [B|Bs], [C|Cs]) :- call(G, A, B, C), maplist(G, As, Bs, Cs).
maplist(_, [], [], [], []).
maplist(G, [A|As], [B|Bs], [C|Cs], [D|Ds]) :- call(G, A, B, C, D), maplist(G, As, Bs, Cs, Ds).
foldl(G, L, V0, V) :- '$foldl'(L, G, V0, V).
'$foldl'([], _, V, V).
'$foldl'([X|Xs], G, V0, V) :- call(G, X, V0, V1), '$foldl'(Xs, G, V1, V).
foldl(G, L1, L2, V0, V) :- '$foldl'(L1, L2, G, V0, V).
'$foldl'([], [], _, V, V).
'$foldl'([X|Xs], [Y|Ys], G, V0, V) :- call(G, X, Y, V0, V1), '$foldl'(Xs, Ys, G, V1, V).
foldl(G, L1, L2, L3, V0, V) :- '$foldl'(L1, L2, L3, G, V0, V).
'$foldl'([], [], [], _, V, V).
'$foldl'([X|Xs], [Y|Ys], [Z|Zs], G, V0, V) :- call(G, X, Y, Z, V0, V1), '$foldl'(Xs, Ys, Zs, G, V1, V).
foldl(G, L1, L2, L3, L4, V0, V) :- '$foldl'(L1, L2, L3, L4, G, V0, V).
'$foldl'([], [], [], [], _, V, V).
'$foldl'([X|Xs], [Y|Ys], [Z|Zs], [W|Ws], G, V0, V) :- call(G, X, Y, Z, W, V0, V1), '$foldl'(Xs, Ys, Zs, Ws, G, V1, V).
partition(P, L, Less, Equal, Greater) :- '$partition'(L, P, Less, Equal, Greater).
'$partition'([], _, [], [], []).
'$partition'([H|T], P, L, E, G) :- call(P, H, Diff), '$partition'(Diff, H, P, T, L, E, G).
'$partition'(<, H, P, T, L, E, G) :- !, L = [H|Rest], '$partition'(T, P, Rest, E, G).
'$partition'(=, H, P, T, L, E, G) :- !, E = [H|Rest], '$partition'(T, P, L, Rest, G).
'$partition'(>, H, P, T, L, E, G) :- !, G = [H|Rest], '$partition'(T, P, L, E, Rest).
'$partition'(Diff, _, _, _, _, _, _) :- ( ground(Diff) -> throw(error(type_error(oneof([<, =, >]), Diff), _)) ; throw(error(instantiation_error, _)) ).
convlist(G, ListIn, ListOut) :- '$convlist'(ListIn, ListOut, G).
'$convlist'([], [], _).
'$convlist'([H0|T0], ListOut, G) :- ( call(G, H0, H) -> ListOut = [H|T], '$convlist'(T0, T, G) ; '$convlist'(T0, ListOut, G) ).
select(X, XList, Y, YList) :- '$select4'(XList, X, Y, YList).
'$select4'([X|List], X, Y, [Y|List]).
'$select4'([X0|XList], X, Y, [X0|YList]) :- '$select4'(XList, X, Y, YList).
selectchk(X, XList, Y, YList) :- select(X, XList, Y, YList), !.
nextto(X, Y, [X, Y|_]).
nextto(X, Y, [_|Zs]) :- nextto(X, Y, Zs).
prefix([], _).
prefix([E|T0], [E|T]) :- prefix(T0, T).
same_length([], []).
same_length([_|T1], [_|T2]) :- same_length(T1, T2).
proper_length(List, Length) :- '$skip_list'(Length0, List, Tail), Tail == [], Length = Length0.
is_set(Set) :- '$skip_list'(Len, Set, Tail), Tail == [], sort(Set, Sorted), length(Sorted, Len).
subset(L, S) :- var(L), !, throw(error(existence_error(matching_rule, lists:subset(L, S)), context(lists:subset/2, _))).
subset([], _) :- !.
subset([E|R], Set) :- !, memberchk(E, Set), subset(R, Set).
subset(L, S) :- throw(error(existence_error(matching_rule, lists:subset(L, S)), context(lists:subset/2, _))).
delete([], _, []).
delete([H|T], X, R) :- ( H \= X -> R = [H|R1] ; R = R1 ), delete(T, X, R1).
subtract(L, D, R) :- var(L), !, throw(error(existence_error(matching_rule, lists:subtract(L, D, R)), context(lists:subtract/3, _))).
subtract([], _, R) :- !, R = [].
subtract([E|T], D, R) :- !, ( memberchk(E, D) -> R = R1 ; R = [E|R1] ), subtract(T, D, R1).
subtract(L, D, R) :- throw(error(existence_error(matching_rule, lists:subtract(L, D, R)), context(lists:subtract/3, _))).
intersection([], _, []).
intersection([X|T], L, I) :- ( memberchk(X, L) -> I = [X|R] ; I = R ), intersection(T, L, R).
union([], L, L).
union([H|T], L, R) :- ( memberchk(H, L) -> R = R1 ; R = [H|R1] ), union(T, L, R1).
permutation(Xs, Ys) :- '$skip_list'(Xlen, Xs, XTail), '$skip_list'(Ylen, Ys, YTail), ( XTail == [], YTail == [] -> Xlen == Ylen ; var(XTail), YTail == [] -> length(Xs, Ylen) ; XTail == [], var(YTail) -> length(Ys, Xlen) ; var(XTail), var(YTail) -> length(Xs, Len), length(Ys, Len) ; '$must_be_list'(Xs), '$must_be_list'(Ys) ), '$perm'(Xs, Ys).
'$perm'([], []).
'$perm'(List, [First|Perm]) :- select(First, List, Rest), '$perm'(Rest, Perm).
once(G) :- call(G), !.
ignore(G) :- ( call(G) -> true ; true ).
pairs_keys_values([], [], []).
pairs_keys_values([K-V|T], [K|Ks], [V|Vs]) :- pairs_keys_values(T, Ks, Vs).
pairs_keys([], []).
pairs_keys([K-_|T], [K|Ks]) :- pairs_keys(T, Ks).
pairs_values([], []).
pairs_values([_-V|T], [V|Vs]) :- pairs_values(T, Vs).
flatten(List, Flat) :- '$flatten'(List, [], Flat0), !, Flat = Flat0.
'$flatten'(Var, Tl, [Var|Tl]) :- var(Var), !.
'$flatten'([], Tl, Tl) :- !.
'$flatten'([Hd|Tl], Tail, List) :- !, '$flatten'(Hd, FlatHeadTail, List), '$flatten'(Tl, Tail, FlatHeadTail).
'$flatten'(NonList, Tl, [NonList|Tl]).
repeat :- '$repeat'.
term_variables(Term, Vars) :- '$term_variables'(Term, Vars).
predsort(P, L, Sorted) :- '$skip_list'(N, L, Tail), ( Tail == [] -> '$predsort'(P, N, L, _, Sorted1), Sorted = Sorted1 ; var(Tail) -> throw(error(instantiation_error, _)) ; throw(error(type_error(list, L), _)) ).
'$predsort'(P, 2, [X1, X2|L], L, R) :- !, call(P, Delta, X1, X2), '$predsort2'(Delta, X1, X2, R).
'$predsort'(_, 1, [X|L], L, [X]) :- !.
'$predsort'(_, 0, L, L, []) :- !.
'$predsort'(P, N, L1, L3, R) :- N1 is N // 2, plus(N1, N2, N), '$predsort'(P, N1, L1, L2, R1), '$predsort'(P, N2, L2, L3, R2), '$predmerge'(P, R1, R2, R).
'$predsort2'('<', X1, X2, [X1, X2]).
'$predsort2'('=', X1, _, [X1]).
'$predsort2'('>', X1, X2, [X2, X1]).
'$predmerge'(_, [], R, R) :- !.
'$predmerge'(_, R, [], R) :- !.
'$predmerge'(P, [H1|T1], [H2|T2], Result) :- call(P, Delta, H1, H2), !, '$predmerge_'(Delta, P, H1, H2, T1, T2, Result).
'$predmerge_'('>', P, H1, H2, T1, T2, [H2|R]) :- '$predmerge'(P, [H1|T1], T2, R).
'$predmerge_'('=', P, H1, _, T1, T2, [H1|R]) :- '$predmerge'(P, T1, T2, R).
'$predmerge_'('<', P, H1, H2, T1, T2, [H1|R]) :- '$predmerge'(P, T1, [H2|T2], R).
sub_string(String, Before, Length, After, Sub) :- '$sub_string'(String, Before, Length, After, Sub).
char_type(Char, Type) :- '$char_type'(Char, Type).
code_type(Code, Type) :- '$code_type'(Code, Type).
unify_with_occurs_check(X, Y) :- '$unify_with_occurs_check'(X, Y).
list_to_ord_set(List, Set) :- sort(List, Set).
ord_union(Sets, Union) :- ( Sets == [] -> Union = [] ; nonvar(Sets), Sets = [_|_] -> length(Sets, N), '$ord_union_all'(N, Sets, Union, []) ; throw(error(existence_error(matching_rule, ordsets:ord_union(Sets, Union)), context(ordsets:ord_union/2, _))) ).
'$ord_union_all'(N, Sets0, Union, Sets) :- ( N =:= 1 -> Sets0 = [Union|Sets] ; N =:= 2 -> Sets0 = [Set1, Set2|Sets], '$ord_union_f'(Set1, Set2, Union) ; A is N >> 1, Z is N - A, '$ord_union_all'(A, Sets0, X, Sets1), '$ord_union_all'(Z, Sets1, Y, Sets), '$ord_union_f'(X, Y, Union) ).
ord_union(Set1, Set2, Union) :- '$ord_union_f'(Set1, Set2, Union).
'$ord_union_f'(Set1, Set2, Union) :- ( '$ord_fast'(union, Set1, Set2, Union) -> true ; '$ord_union'(Set1, Set2, Union) ).
'$ord_union'(Set1, Set2, Union) :- ( Set1 == [] -> Union = Set2 ; nonvar(Set1), Set1 = [H1|T1] -> '$ord_union2'(Set2, H1, T1, Union) ; throw(error(existence_error(matching_rule, ordsets:ord_union(Set1, Set2, Union)), context(ordsets:ord_union/3, _))) ).
'$ord_union2'(L2, H1, T1, Union) :- ( L2 == [] -> Union = [H1|T1] ; nonvar(L2), L2 = [H2|T2] -> compare(Order, H1, H2), '$ord_union3'(Order, H1, T1, H2, T2, Union) ; throw(error(existence_error(matching_rule, ordsets:union2(L2, H1, T1, Union)), context(ordsets:union2/4, _))) ).
'$ord_union3'('<', H1, T1, H2, T2, Union) :- Union = [H1|Union0], '$ord_union2'(T1, H2, T2, Union0).
'$ord_union3'('=', H1, T1, _, T2, Union) :- Union = [H1|Union0], '$ord_union'(T1, T2, Union0).
'$ord_union3'('>', H1, T1, H2, T2, Union) :- Union = [H2|Union0], '$ord_union2'(T2, H1, T1, Union0).
ord_subtract(Set, Delete, Remaining) :- ( '$ord_fast'(subtract, Set, Delete, Remaining) -> true ; '$ord_subtract'(Set, Delete, Remaining) ).
'$ord_subtract'(L1, L2, Diff) :- ( L1 == [] -> Diff = [] ; L2 == [] -> Diff = L1 ; nonvar(L1), L1 = [H1|T1] -> '$ord_diff21'(L2, H1, T1, Diff) ; throw(error(existence_error(matching_rule, ordsets:ord_subtract(L1, L2, Diff)), context(ordsets:ord_subtract/3, _))) ).
'$ord_diff21'([], H1, T1, [H1|T1]).
'$ord_diff21'([H2|T2], H1, T1, Diff) :- compare(Order, H1, H2), '$ord_diff3'(Order, H1, T1, H2, T2, Diff).
'$ord_diff12'([], _, _, []).
'$ord_diff12'([H1|T1], H2, T2, Diff) :- compare(Order, H1, H2), '$ord_diff3'(Order, H1, T1, H2, T2, Diff).
'$ord_diff3'('<', H1, T1, H2, T2, [H1|Diff]) :- '$ord_diff12'(T1, H2, T2, Diff).
'$ord_diff3'('=', _, T1, _, T2, Diff) :- '$ord_subtract'(T1, T2, Diff).
'$ord_diff3'('>', H1, T1, _, T2, Diff) :- '$ord_diff21'(T2, H1, T1, Diff).
ord_memberchk(Item, Set) :- ( '$ord_fast'(memberchk, Item, Set, In) -> In == true ; '$ord_memberchk'(Item, Set) ).
'$ord_memberchk'(Item, [X1, X2, X3, X4|Xs]) :- !, compare(R4, Item, X4), ( R4 = '>' -> '$ord_memberchk'(Item, Xs) ; R4 = '<' -> compare(R2, Item, X2), ( R2 = '>' -> Item == X3 ; R2 = '<' -> Item == X1 ; true ) ; true ).
'$ord_memberchk'(Item, [X1, X2|Xs]) :- !, compare(R2, Item, X2), ( R2 = '>' -> '$ord_memberchk'(Item, Xs) ; R2 = '<' -> Item == X1 ; true ).
'$ord_memberchk'(Item, [X1]) :- Item == X1.
ord_intersection(Set1, Set2, Intersection) :- ( Intersection == [] -> \+ '$ord_intersect'(Set1, Set2) ; '$ord_fast'(intersection, Set1, Set2, Intersection) -> true ; '$ord_intersection'(Set1, Set2, Intersection) ).
'$ord_intersect'([H1|T1], L2) :- '$ord_intersect_'(L2, H1, T1).
'$ord_intersect_'([H2|T2], H1, T1) :- compare(Order, H1, H2), '$ord_intersect__'(Order, H1, T1, H2, T2).
'$ord_intersect__'('<', _, T1, H2, T2) :- '$ord_intersect_'(T1, H2, T2).
'$ord_intersect__'('=', _, _, _, _).
'$ord_intersect__'('>', H1, T1, _, T2) :- '$ord_intersect_'(T2, H1, T1).
'$ord_intersection'([], _, []).
'$ord_intersection'([H1|T1], L2, Int) :- '$ord_isect2'(L2, H1, T1, Int).
'$ord_isect2'([], _, _, []).
'$ord_isect2'([H2|T2], H1, T1, Int) :- compare(Order, H1, H2), '$ord_isect3'(Order, H1, T1, H2, T2, Int).
'$ord_isect3'('<', _, T1, H2, T2, Int) :- '$ord_isect2'(T1, H2, T2, Int).
'$ord_isect3'('=', H1, T1, _, T2, [H1|Int]) :- '$ord_intersection'(T1, T2, Int).
'$ord_isect3'('>', H1, T1, _, T2, Int) :- '$ord_isect2'(T2, H1, T1, Int).
ord_subset(Sub, Super) :- '$ord_subset'(Sub, Super).
'$ord_subset'([], _).
'$ord_subset'([H1|T1], [H2|T2]) :- compare(Order, H1, H2), '$ord_subset_'(Order, H1, T1, T2).
'$ord_subset_'('>', H1, T1, [H2|T2]) :- compare(Order, H1, H2), '$ord_subset_'(Order, H1, T1, T2).
'$ord_subset_'('=', _, T1, T2) :- '$ord_subset'(T1, T2).
ord_add_element(Set, El, Add) :- '$ord_add_element'(Set, El, Add).
'$ord_add_element'([], El, [El]).
'$ord_add_element'([H|T], El, Add) :- compare(Order, H, El), '$ord_addel'(Order, H, T, El, Add).
'$ord_addel'('<', H, T, El, [H|Add]) :- '$ord_add_element'(T, El, Add).
'$ord_addel'('=', H, T, _, [H|T]).
'$ord_addel'('>', H, T, El, [El, H|T]).
'>>'(Ps, L) :- '$lambda'(Ps, [], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'>>'(Ps, L, A1) :- '$lambda'(Ps, [A1], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'>>'(Ps, L, A1, A2) :- '$lambda'(Ps, [A1, A2], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'>>'(Ps, L, A1, A2, A3) :- '$lambda'(Ps, [A1, A2, A3], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'>>'(Ps, L, A1, A2, A3, A4) :- '$lambda'(Ps, [A1, A2, A3, A4], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'>>'(Ps, L, A1, A2, A3, A4, A5) :- '$lambda'(Ps, [A1, A2, A3, A4, A5], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'>>'(Ps, L, A1, A2, A3, A4, A5, A6) :- '$lambda'(Ps, [A1, A2, A3, A4, A5, A6], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'>>'(Ps, L, A1, A2, A3, A4, A5, A6, A7) :- '$lambda'(Ps, [A1, A2, A3, A4, A5, A6, A7], Extra, L, LC), G =.. [call, LC|Extra], call(G).
'/'(Free, L) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC).
'/'(Free, L, A1) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC, A1).
'/'(Free, L, A1, A2) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC, A1, A2).
'/'(Free, L, A1, A2, A3) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC, A1, A2, A3).
'/'(Free, L, A1, A2, A3, A4) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC, A1, A2, A3, A4).
'/'(Free, L, A1, A2, A3, A4, A5) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC, A1, A2, A3, A4, A5).
'/'(Free, L, A1, A2, A3, A4, A5, A6) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC, A1, A2, A3, A4, A5, A6).
'/'(Free, L, A1, A2, A3, A4, A5, A6, A7) :- '$lambda_free'(Free), copy_term(Free+L, Free+LC), call(LC, A1, A2, A3, A4, A5, A6, A7).
'$lambda'(Ps, _, _, _, _) :- var(Ps), !, throw(error(instantiation_error, _)).
'$lambda'(Free/Ps, Args, Extra, L, LC) :- !, '$lambda_free'(Free), '$must_be_list'(Ps), copy_term(Free/Ps>>L, Free/PsC>>LC), '$lambda_params'(PsC, Args, Extra, Free/Ps>>(user:L)).
'$lambda'(Ps, Args, Extra, L, LC) :- '$must_be_list'(Ps), copy_term(Ps>>L, PsC>>LC), '$lambda_params'(PsC, Args, Extra, Ps>>(user:L)).
'$lambda_params'([], Extra, Extra, _) :- !.
'$lambda_params'([P|Ps], [A|As], Extra, C) :- !, P = A, '$lambda_params'(Ps, As, Extra, C).
'$lambda_params'(_, _, _, C) :- throw(error(domain_error(lambda_parameters, C), _)).
'$lambda_free'(F) :- var(F), !, throw(error(instantiation_error, _)).
'$lambda_free'({_}) :- !.
'$lambda_free'({}) :- !.
'$lambda_free'(F) :- throw(error(type_error(lambda_free, F), _)).
max_member(P, M, L) :- var(L), !, throw(error(existence_error(matching_rule, lists:max_member(user:P, M, L)), context(lists:max_member/3, _))).
max_member(P, M, [H|T]) :- !, '$max_member3'(T, P, H, M).
max_member(_, _, []) :- !, fail.
max_member(P, M, L) :- throw(error(existence_error(matching_rule, lists:max_member(user:P, M, L)), context(lists:max_member/3, _))).
'$max_member3'(L, P, M0, M) :- var(L), !, throw(error(existence_error(matching_rule, lists:max_member_(L, user:P, M0, M)), context(lists:max_member_/4, _))).
'$max_member3'([], _, M0, M) :- !, M = M0.
'$max_member3'([H|T], P, M0, M) :- !, ( call(P, H, M0) -> '$max_member3'(T, P, M0, M) ; '$max_member3'(T, P, H, M) ).
'$max_member3'(L, P, M0, M) :- throw(error(existence_error(matching_rule, lists:max_member_(L, user:P, M0, M)), context(lists:max_member_/4, _))).
min_member(P, M, L) :- var(L), !, throw(error(existence_error(matching_rule, lists:min_member(user:P, M, L)), context(lists:min_member/3, _))).
min_member(P, M, [H|T]) :- !, '$min_member3'(T, P, H, M).
min_member(_, _, []) :- !, fail.
min_member(P, M, L) :- throw(error(existence_error(matching_rule, lists:min_member(user:P, M, L)), context(lists:min_member/3, _))).
'$min_member3'(L, P, M0, M) :- var(L), !, throw(error(existence_error(matching_rule, lists:min_member_(L, user:P, M0, M)), context(lists:min_member_/4, _))).
'$min_member3'([], _, M0, M) :- !, M = M0.
'$min_member3'([H|T], P, M0, M) :- !, ( call(P, M0, H) -> '$min_member3'(T, P, M0, M) ; '$min_member3'(T, P, H, M) ).
'$min_member3'(L, P, M0, M) :- throw(error(existence_error(matching_rule, lists:min_member_(L, user:P, M0, M)), context(lists:min_member_/4, _))).
with_output_to(Sink, Goal) :- '$with_output_to'(Sink, Goal).
write(S, T) :- '$write_to'(S, T).
print(S, T) :- '$print_to'(S, T).
writeq(S, T) :- '$writeq_to'(S, T).
write_canonical(S, T) :- '$write_canonical_to'(S, T).
writeln(S, T) :- '$writeln_to'(S, T).
nl(S) :- '$nl_to'(S).
tab(S, N) :- '$tab_to'(S, N).
sformat(S, F, A) :- '$sformat'(S, F, A).
sformat(S, F) :- '$sformat'(S, F).
numbervars(T, S, E) :- '$numbervars'(T, S, E).
text_to_string(T, S) :- '$text_to_string'(T, S).
print_message(Kind, Message) :- '$print_message'(Kind, Message).
ord_del_element(Set, El, Del) :- '$ord_del_element'(Set, El, Del).
'$ord_del_element'([], _, []).
'$ord_del_element'([H|T], El, Del) :- compare(Order, H, El), '$ord_delel'(Order, H, T, El, Del).
'$ord_delel'('<', H, T, El, [H|Del]) :- '$ord_del_element'(T, El, Del).
'$ord_delel'('=', _, T, _, T).
'$ord_delel'('>', H, T, _, [H|T]).
"""

_LIBRARY: Program | None = None


def library_program() -> Program:
    """The Prolog-defined part of the builtins, built once per process.

    >>> ("member", 2) in library_program().preds
    True
    """
    global _LIBRARY
    if _LIBRARY is None:
        prog = Program()
        for clause in library_clauses():
            prog.add_clause(clause)
        _LIBRARY = prog
    return _LIBRARY


def library_clauses(source: str = LIBRARY_SOURCE) -> list:
    """The clauses of the library's Prolog ``source``: built by the generated
    :mod:`slr_sql.library_terms` when it was made from this very text (parsing it is ~20-35 ms
    of every process that opens a store), else parsed.

    >>> str(library_clauses()[0].head), len(library_clauses("p(1).")) == 1
    ('member(X,[Y|Ys])', True)
    """
    import hashlib

    from . import library_terms

    if hashlib.sha256(source.encode("utf-8")).hexdigest() == library_terms.SOURCE_SHA256:
        return library_terms.clauses(source)
    from .parser import parse_program

    return parse_program(source, "<library>")


BUILTIN_NAMES = set(DET) | set(NONDET)
