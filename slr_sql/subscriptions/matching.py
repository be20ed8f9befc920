"""A subscription's pattern and condition, compiled (:class:`Matcher`), and answers as JSON
(:func:`answer_json`). (``subscribe``'s other arguments are checked by
:func:`~slr_sql.subscriptions.hub.check_subscription`.)"""
from __future__ import annotations

import json
from typing import Any

from ..encoding import encode_json
from ..errors import SLRError, SLRSyntaxError, SLRTimeout
from ..parser import parse_term
from ..program import split_event_atom
from ..terms import Atom, String, Struct, Var, deref, make_list, to_python
from ..unify import undo, unify

__all__ = ["Matcher", "answer_json", "WHERE_TIMEOUT"]

# A condition runs on the hub's one delivery thread, which every subscription of the knowledge
# base shares: without a bound, one condition that never ends (``repeat, fail``, a recursion
# without a base case) stopped the delivery of every subscription for good -- on a server,
# any client's. Its bound is seconds of wall-clock time, which the compiled SQL statement of
# a condition and the interpreter both keep to (a budget of inference steps would send every
# condition to the interpreter: one over a million stored events took 4 s there against
# 0.3 s compiled), about what an event rule's where goal may spend in the interpreter (2,000,000
# steps). A condition that runs out of it ends its subscription with the SLRTimeout, as a
# condition that raises ends it.
WHERE_TIMEOUT = 5.0


def answer_json(answer: dict[str, Any]) -> str:
    """One answer as a JSON object, each value in the store's JSON encoding of terms
    (docs/schema.md): atoms as JSON strings, strings ``{"$string": ..}``, integers and floats
    as JSON numbers (a float always with a ``.`` or an exponent), lists as arrays, compounds
    ``{"f": [..]}``.

    >>> answer_json({"F": Atom("antonio"), "R": 65, "T": 2.0, "S": "hi", "P": [1, 2.5]})
    '{"F":"antonio","R":65,"T":2.0,"S":{"$string":"hi"},"P":[1,2.5]}'
    """
    parts = [json.dumps(str(name)) + ":" + encode_json(_answer_term(value))
             for name, value in answer.items()]
    return "{" + ",".join(parts) + "}"


def _answer_term(value: Any) -> Any:
    """A value of an answer dict back as a term: ``Atom`` stays an atom, a plain ``str`` (how
    answers return strings) is a string."""
    tv = type(value)
    if tv is Atom or tv is int or tv is float:
        return value
    if tv is str or tv is String:
        return String(value)
    if tv is bool:
        return Atom("true" if value else "false")
    if isinstance(value, (list, tuple)):
        return make_list([_answer_term(v) for v in value])
    if tv is Struct:
        return Struct(value.name, tuple(_answer_term(a) for a in value.args))
    if tv is Var:
        raise SLRError("an answer with an unbound variable has no JSON form")
    return value


def _pattern_error(text: str, message: str) -> SLRSyntaxError:
    return SLRSyntaxError(message, line=1, column=1, source_line=text.strip(),
                          filename="<pattern>")


class Matcher:
    """A pattern and condition, compiled: ``match(args, start, end)`` gives the answer dict or
    None. One matcher serves every subscription with the same texts (the hub thread only).
    ``query`` runs the condition (``kb.query``).

    >>> m = Matcher(None, "p(X)^T", None)
    >>> m.key, m.match((Atom("a"),), 1.0, 1.0)
    (('p', 1), {'X': Atom('a'), 'T': 1.0})
    """

    def __init__(self, query: Any, pattern: str, where: str | None):
        self.query = query
        self.pattern = pattern
        self.where = where
        term, varnames = parse_term(pattern, "<pattern>")
        ev = split_event_atom(term)
        if ev is None:
            raise _pattern_error(pattern, "a subscription pattern is an event atom "
                                          "p(...)^T or p(...)^[S,E]")
        atom, s, e = ev
        for stamp in (s, e):
            d = deref(stamp)
            if type(d) is not Var and type(d) not in (int, float):
                raise _pattern_error(pattern, "the time of a subscription pattern must be a "
                                              "variable or a number")
        atom = deref(atom)
        if type(atom) is Struct:
            self.name, self.args = str(atom.name), tuple(atom.args)
        else:
            self.name, self.args = str(atom), ()
        self.arity = len(self.args)
        self.key = (self.name, self.arity)
        self.point = s is e
        self.start, self.end = s, e
        self.vars = [(n, v) for n, v in varnames.items()]
        self.answer_vars = [(n, v) for n, v in self.vars if not n.startswith("_")]
        self.where_bind: list[tuple[str, Var]] = []
        if where is not None:
            _, where_vars = parse_term(where, "<where>")
            pattern_vars = dict(self.vars)
            self.where_bind = [(n, pattern_vars[n]) for n in where_vars if n in pattern_vars]

    def match(self, args: tuple, start: float, end: float) -> dict | None:
        """The answer of the event ``args`` at [start, end], or None if it does not match."""
        trail: list = []
        try:
            for p, v in zip(self.args, args):
                if not unify(p, v, trail):
                    return None
            stamps = ((self.end, end),) if self.point else ((self.start, start), (self.end, end))
            for stamp, value in stamps:
                d = deref(stamp)
                if type(d) is Var:
                    d.ref = value
                    trail.append(d)
                elif type(d) is int or type(d) is float:
                    if d != value:       # times match by value: 5 == 5.0
                        return None
                else:
                    return None
            answer = {name: to_python(var) for name, var in self.answer_vars}
            if self.where is not None:
                bound = {name: deref(var) for name, var in self.where_bind}
                try:
                    rows = self.query(self.where, args=bound or None, limit=1,
                                      timeout=WHERE_TIMEOUT)
                except SLRTimeout as exc:
                    raise SLRTimeout(
                        f"the subscription's where condition did not end within its limit "
                        f"({exc}): a condition runs on the delivery thread every subscription "
                        f"shares, for at most {WHERE_TIMEOUT:g} s") from None
                if not rows:
                    return None
                for name, value in rows[0].items():
                    if name not in answer and not name.startswith("_"):
                        answer[name] = value
            return answer
        finally:
            undo(trail, 0)

    def match_or_error(self, args: tuple, start: float, end: float) -> Any:
        """:meth:`match`, with a failing condition's :class:`SLRError` returned, not raised."""
        try:
            return self.match(args, start, end)
        except SLRError as exc:
            return exc
