"""Answers as callers see them: the bindings of a query's named variables, in Python values,
and their text as the Prolog top level prints it (``slr query``, ``slr shell``, ``slr demo``).

>>> from slr_sql.terms import Var
>>> X = Var("X"); X.ref = 1; answer_bindings([("X", 0)], [X])
{'X': 1}
"""
from __future__ import annotations

import math
import re
from typing import Any, Callable

from .terms import INFIX_OPS, PREFIX_OPS, Atom, Struct, Var, deref, format_term, int_text, \
    quoted_text, to_python

__all__ = ["answer_bindings", "AnswerVariables", "query_variable_names", "value_text", "binding_text", "answer_text",
           "rebuilt"]


def answer_bindings(names: list, frame: list, deadline: float | None = None,
                    named: list | None = None) -> dict[str, Any]:
    """Bindings of the named variables, as SWI-Prolog's toplevel shows them: a variable left
    unbound is omitted unless it is shared with another named variable (``X = Y``).
    ``deadline`` (the query's, ``time.monotonic()``) also bounds converting a huge answer.

    The unbound variables the values hold are named as SWI-Prolog's top level names them,
    by what they are, not by the name the engine gave them: one that variables of the query
    hold is named by the last of them in the query's order (``named``: the query's variables,
    ``_X`` ones too, as ``(name, slot)``; ``names`` by default), one not starting with
    ``_`` before one that does (only those are shown); any other (a clause's variable, an
    ``_``, one a builtin made) is a new variable the engine names (``_G`` and a number),
    which no query names. The answer's variables are new, not the engine's own.

    >>> from slr_sql.terms import Var
    >>> X, Y, Z = Var("X"), Var("Y"), Var("Z"); X.ref = 1; Y.ref = Z
    >>> answer_bindings([("X", 0), ("Y", 1), ("Z", 2), ("W", 3)], [X, Y, Z, Var("W")])
    {'X': 1, 'Y': Var('Z'), 'Z': Var('Z')}
    >>> from slr_sql.terms import Struct
    >>> X, Y, clauses = Var("X"), Var("Y"), Var("Y")   # (a clause's variable named Y)
    >>> X.ref = Struct("f", (clauses, Y)); Y.ref = Var()
    >>> shown = answer_bindings([("X", 0)], [X, Y], named=[("X", 0), ("Y", 1)])["X"]
    >>> shown.args[0].name.startswith("_G"), shown.args[1]
    (True, Var('Y'))
    """
    values = [(name, deref(frame[slot])) for name, slot in names]
    free = [id(v) for _, v in values if type(v) is Var]
    answer = {}
    variables = None
    for name, v in values:
        tv = type(v)
        if tv is Var or tv is Struct:
            if tv is Var and free.count(id(v)) < 2:
                continue
            if variables is None:   # (a value that may hold a variable: most hold none)
                variables = AnswerVariables(names if named is None else named, frame)
            answer[name] = to_python(v, deadline, variables)
        else:
            answer[name] = to_python(v, deadline)
    return answer


class AnswerVariables:
    """The variable an answer holds for each unbound variable of the engine's (see
    :func:`answer_bindings`), made when first asked for: most answers hold none. The
    compiled plans name their answers' variables with it too (planner.compile_goal).

    >>> from slr_sql.terms import Var
    >>> Y, fresh = Var("Y"), Var("Y")          # the query's Y, and a clause's Y
    >>> names = AnswerVariables([("Y", 0)], [Y])
    >>> names(Y), names(fresh).name.startswith("_G"), names(fresh) is names(fresh)
    (Var('Y'), True, True)
    """

    __slots__ = ("named", "frame", "given", "taken")

    def __init__(self, named: list, frame: list):
        self.named = named
        self.frame = frame
        self.given: dict[int, Var] | None = None
        self.taken: frozenset[str] = frozenset()

    def __call__(self, var: Var) -> Var:
        given = self.given
        if given is None:
            given = self.given = {key: Var(name) for key, name
                                  in query_variable_names(self.named, self.frame).items()}
            self.taken = frozenset(name for name, _ in self.named if name.startswith("_G"))
        new = given.get(id(var))
        if new is None:
            new = Var()
            taken = self.taken
            if taken:
                while new.name in taken:   # (a query's own _G2000)
                    new = Var()
            given[id(var)] = new
        return new


def query_variable_names(named: list, frame: list) -> dict[int, str]:
    """``id()`` of each unbound variable that variables of a query hold -> the name an
    answer gives it, as SWI-Prolog's top level names it: the last of those variables in the
    query's order (``named``, ``(name, slot)`` in ``frame``), one whose name does not start
    with ``_`` before one that does (an answer shows only those).

    >>> from slr_sql.terms import Var
    >>> Z, Y, U = Var("Z"), Var("Y"), Var("_U"); Z.ref = U; Y.ref = U
    >>> query_variable_names([("Z", 0), ("Y", 1), ("_U", 2)], [Z, Y, U]) == {id(U): "Y"}
    True
    """
    given: dict[int, str] = {}
    for name, slot in named:
        v = deref(frame[slot])
        if type(v) is Var and (not name.startswith("_")
                               or given.get(id(v), "_").startswith("_")):
            given[id(v)] = name
    return given


_SOLO_ATOMS = {"[]", "{}", "!", ";", ","}
_PLAIN_ATOM = re.compile(r"[a-z][A-Za-z0-9_]*\Z")
_SYMBOL_ATOM = re.compile(r"[+\-*/\\^<>=~:.?@#&$]+\Z")


def _atom_text(name: str) -> str:
    if _PLAIN_ATOM.match(name) or _SYMBOL_ATOM.match(name) or name in _SOLO_ATOMS:
        return name
    # (escaped as writeq escapes: a control or bidi character never reaches the terminal)
    return quoted_text(name, "'")


def _string_text(text: str) -> str:
    return quoted_text(text, '"')


def _number_text(x: float | int, digits: int | None = None) -> str:
    if isinstance(x, float):
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        if math.isnan(x):
            return "nan"
        if digits is not None:
            return repr(round(x, digits) + 0.0)  # + 0.0 turns -0.0 into 0.0
        return repr(x)
    return int_text(x)   # (repr refuses an integer of more than 4,300 digits)


def rebuilt(value: Any, split: Callable[[Any], tuple[Any, Any]]) -> Any:
    """``value`` rebuilt from the leaves up, without recursion (an answer may be nested
    deeper than Python's recursion): ``split(item)`` gives ``(None, new_leaf)`` for a leaf,
    ``(children, make)`` for a node, ``make`` putting the rebuilt children together.

    >>> rebuilt([1, [2, 3]], lambda x: (x, sum) if isinstance(x, list) else (None, x * 10))
    60
    """
    done: list = []
    todo: list = [(value, None)]
    while todo:
        item, node = todo.pop()
        if node is not None:   # its children are the last results: put them together
            n, make = node
            children = done[len(done) - n:]
            del done[len(done) - n:]
            done.append(make(children))
            continue
        children, result = split(item)
        if children is None:
            done.append(result)
        else:
            todo.append((None, (len(children), result)))
            todo.extend((c, None) for c in reversed(children))
    return done[0]


def value_text(value: Any, digits: int | None = None, priority: int = 1200) -> str:
    """Prolog text of one answer value: atoms quoted when needed, strings in double quotes.
    ``digits`` rounds floats for display (the demo); by default they print exactly, as
    SWI-Prolog's ``writeq`` (``1.0e+22``, ``1.0Inf``). ``priority``: the highest operator
    priority written without brackets (an operand of ``=`` is 699).

    >>> from slr_sql.terms import Atom
    >>> value_text(Atom("cup1")), value_text("never-observed"), value_text([1, 2.5])
    ('cup1', '"never-observed"', '[1,2.5]')
    """
    if digits is None:
        kind = type(value)
        if kind is Atom and _PLAIN_ATOM.match(value):
            return str(value)        # (the common values, as the printer writes them)
        if kind is int:
            return int_text(value)
        if kind is float:
            return format_term(value)
        # the engine's printer (writeq's): operators, the brackets a list element or an
        # operand needs (`[(a:-b)]`), quoting (`','`), floats as SWI-Prolog writes them
        # (the printer takes a value as returned: lists as Python lists, strings as str)
        return format_term(value, priority=priority)
    if isinstance(value, bool):  # bool is an int subclass; never produced, but be exact
        return "true" if value else "false"
    if isinstance(value, Atom):
        return _atom_text(str(value))
    if isinstance(value, str):
        return _string_text(value)
    if isinstance(value, (int, float)):
        return _number_text(value, digits)
    if isinstance(value, (list, tuple)):
        return "[" + ",".join(value_text(v, digits) for v in value) + "]"
    if isinstance(value, Var):
        return str(value)
    if isinstance(value, Struct):
        args = ",".join(value_text(a, digits) for a in value.args)
        if str(value.name) == "-" and len(value.args) == 2:
            return value_text(value.args[0], digits) + "-" + value_text(value.args[1], digits)
        return f"{_atom_text(str(value.name))}({args})"
    return str(value)


def binding_text(value: Any) -> str:
    """A binding's value as SWI-Prolog's top level writes it after ``X = ``: as an operand
    of ``=`` (priority 699: the conjunction ``(a, b)`` is written ``(a,b)``), an atom that is
    an operator in brackets (``X = (table)``, ``X = (-)``: bare, ``X = table, Y = 1`` is a
    syntax error), so that the answer reads back as its bindings.

    >>> from slr_sql.terms import Atom, Struct
    >>> binding_text(Struct(",", (Atom("a"), Atom("b")))), binding_text(Atom(","))
    ('(a,b)', "(',')")
    >>> binding_text([Struct(":-", (Atom("a"), Atom("b")))]), binding_text(1e22)
    ('[(a:-b)]', '1.0e+22')
    """
    if type(value) is Atom and (value in INFIX_OPS or value in PREFIX_OPS):
        return "(" + format_term(value) + ")"
    return value_text(value, priority=699)


def answer_text(answer: dict[str, Any]) -> str:
    """One answer as the Prolog top level prints it, on one line: ``X = a, Y = [1,2]``.

    An answer without variables (a goal that just succeeds) is ``true``. Variables the
    query did not name (an answer names them as the engine names its own, ``_G`` and a
    number: :func:`answer_bindings`) are printed as SWI-Prolog's top level prints them:
    ``_`` where the answer holds one only once, ``_A``, ``_B``, ... where it holds one more
    than once; every other variable by its name, the query's.

    >>> answer_text({"X": 1, "L": [1, 2]}), answer_text({})
    ('X = 1, L = [1,2]', 'true')
    >>> from slr_sql.terms import Struct, Var
    >>> shared, other = Var(), Var()
    >>> answer_text({"X": Struct("f", (shared, shared, other)), "L": [other, Var()]})
    'X = f(_A,_A,_B), L = [_B,_]'
    """
    # X = Y answers {'X': Var('Y'), 'Y': Var('Y')}; like Prolog, do not print "Y = Y".
    shown = [(name, value) for name, value in answer.items()
             if not (isinstance(value, Var) and str(value) == name)]
    if not shown:
        return "true"
    shown = _fresh_variables_named(shown, taken=set(answer))
    return ", ".join(f"{name} = {binding_text(value)}" for name, value in shown)


def unnamed_variables_named(answer: dict[str, Any]) -> dict[str, Any]:
    """``answer`` with the variables the query did not name renamed as :func:`answer_text`
    names them, counted over the whole answer: for a caller that cuts the values before
    printing them (the shell's ``[...|...]``), as SWI-Prolog's top level counts them -- a
    variable held twice is ``_A`` also where the cut leaves it once.

    >>> from slr_sql.terms import Var
    >>> shared = Var()
    >>> answer_text({"L": [shared, Var()], "M": [shared]})
    'L = [_A,_], M = [_A]'
    >>> answer_text({"M": unnamed_variables_named({"L": [shared, Var()], "M": [shared]})["M"]})
    'M = [_A]'
    """
    return dict(_fresh_variables_named(list(answer.items()), taken=set(answer)))


# the name the engine gives a variable no clause or query named (terms.Var); an answer names
# so every variable that no variable of the query holds (answer_bindings), and the text
# also comes from the names alone when the answer came over the service as JSON
_FRESH_NAME = re.compile(r"_G\d+\Z")


def _fresh_variables_named(shown: list[tuple[str, Any]],
                           taken: set[str]) -> list[tuple[str, Any]]:
    """``shown`` with each unnamed variable renamed as SWI-Prolog's top level names it, in
    the order they are printed: ``_`` for one that occurs once, else the next of ``_A``,
    ``_B``, ... (``_A1`` after ``_Z``) that no variable of the answer is named already."""
    order: list[str] = []
    counts: dict[str, int] = {}
    todo: list[Any] = [value for _, value in reversed(shown)]
    while todo:               # (iterative: an answer may be nested deeper than recursion)
        item = todo.pop()
        if isinstance(item, Var):
            name = item.name
            if _FRESH_NAME.match(name):
                if name not in counts:
                    counts[name] = 0
                    order.append(name)
                counts[name] += 1
            else:
                taken.add(name)
        elif isinstance(item, Struct):
            todo.extend(reversed(item.args))
        elif isinstance(item, (list, tuple)):
            todo.extend(reversed(item))
    if not order:
        return shown
    renamed: dict[str, Var] = {}
    letters = (f"_{chr(65 + n % 26)}{n // 26 or ''}" for n in range(1 << 30))
    for name in order:
        if counts[name] == 1:
            renamed[name] = Var("_")
            continue
        new = next(letters)
        while new in taken:
            new = next(letters)
        renamed[name] = Var(new)

    def split(item: Any) -> tuple[Any, Any]:
        if isinstance(item, Var):
            return None, renamed.get(item.name, item)
        if isinstance(item, Struct):
            return item.args, lambda args, name=item.name: Struct(name, tuple(args))
        if isinstance(item, list):
            return item, list
        if isinstance(item, tuple):
            return item, tuple
        return None, item

    return [(name, rebuilt(value, split)) for name, value in shown]
