"""Arithmetic evaluation (``is``, ``=:=`` ...) with SWI-Prolog's integer/float rules.

Integers stay integers where Prolog keeps them (``6/2 =:= 3`` is the integer 3, ``7/2`` is 3.5,
``//`` truncates toward zero, ``mod`` takes the divisor's sign, ``rem`` the dividend's).
"""
from __future__ import annotations

import math
from typing import Any

from .terms import MAX_INTEGER_BITS, Atom, Struct, Var, deref, String
from .errors import SLREvaluationError

__all__ = ["evaluate", "apply_binary", "type_error", "instantiation_error", "evaluation_error", "iso_error",
           "resource_error", "with_context"]


def iso_error(formal: Any, context: Any = None) -> SLREvaluationError:
    """The ISO error ``error(Formal, Context)`` as an exception to raise; the context is left
    unbound unless given.

    >>> from slr_sql.terms import Atom
    >>> str(iso_error(Atom("instantiation_error")))
    'error(instantiation_error,_)'
    """
    term = Struct("error", (formal, context if context is not None else Var("_")))
    from .terms import MESSAGE_TOKENS, format_term

    return SLREvaluationError(term, format_term(term, limit=MESSAGE_TOKENS))


def with_context(exc: SLREvaluationError, culprit: Any) -> SLREvaluationError:
    """``exc`` with its error term's unbound context filled as SWI-Prolog fills it:
    ``context(Culprit, _)``, where Culprit names the predicate (``system:atom_length/2``) or
    the arithmetic function (``(/)/2``) that raised it. An error whose context is already
    bound, or a ball that is no ``error/2`` term, is returned as it is.

    >>> from slr_sql.terms import Atom, Struct
    >>> str(with_context(instantiation_error(), Struct("/", (Atom("succ"), 2))))
    'error(instantiation_error,context(succ/2,_))'
    """
    term = exc.term
    if not (type(term) is Struct and term.name == "error" and len(term.args) == 2):
        return exc
    context = deref(term.args[1])
    message: Any = Var("_")
    if type(context) is Struct and context.name == "context" and len(context.args) == 2 \
            and type(deref(context.args[0])) is Var:
        message = context.args[1]   # context(_, Message): the culprit filled in
    elif type(context) is not Var:
        return exc
    from .terms import MESSAGE_TOKENS, format_term

    new = iso_error(term.args[0], Struct("context", (culprit, message)))
    # the message is the term's text (bounded), and perhaps a hint after it: kept
    message = exc.args[0] if exc.args else ""
    old_text = format_term(term, limit=MESSAGE_TOKENS)
    if isinstance(message, str) and message.startswith(old_text):
        new.args = (new.args[0] + message[len(old_text):],)
    return new


def instantiation_error() -> SLREvaluationError:
    """ISO ``instantiation_error``: an argument is unbound where a value is needed.

    >>> str(instantiation_error())
    'error(instantiation_error,_)'
    """
    return iso_error(Atom("instantiation_error"))


def type_error(kind: str, culprit: Any) -> SLREvaluationError:
    """ISO ``type_error(Kind, Culprit)``: ``culprit`` is not of the expected kind.

    >>> from slr_sql.terms import Atom
    >>> str(type_error("evaluable", Atom("foo")))
    'error(type_error(evaluable,foo),_)'
    """
    return iso_error(Struct("type_error", (Atom(kind), culprit)))


def evaluation_error(what: str) -> SLREvaluationError:
    """ISO ``evaluation_error(What)``: an arithmetic operation is undefined (``zero_divisor``,
    ``undefined`` ...).

    >>> str(evaluation_error("zero_divisor"))
    'error(evaluation_error(zero_divisor),_)'
    """
    return iso_error(Struct("evaluation_error", (Atom(what),)))


def resource_error(what: str) -> SLREvaluationError:
    """ISO ``resource_error(What)``: a computation would exceed a limit (memory, integer size).

    >>> str(resource_error("memory"))
    'error(resource_error(memory),_)'
    """
    return iso_error(Struct("resource_error", (Atom(what),)))


def _too_big() -> SLREvaluationError:
    return resource_error("max_integer_size")


def _mul(a, b):
    if type(a) is int and type(b) is int and a.bit_length() + b.bit_length() > MAX_INTEGER_BITS + 1:
        raise _too_big()
    return a * b


def _int_power(a: int, b: int) -> int:
    """a ** b for integers with b >= 0, refused before computing when the result would be
    beyond MAX_INTEGER_BITS (7 ** 100000000 would take hours, uninterruptibly)."""
    if a in (0, 1, -1) or b == 0:
        return a ** b
    if b * (abs(a).bit_length() - 1) > MAX_INTEGER_BITS:
        raise _too_big()
    return a ** b


def _int_required(x: Any) -> int:
    if type(x) is not int:
        if type(x) is float:
            _finite(x)   # SWI-Prolog: an infinite or NaN operand is its error, not a type's
        raise type_error("integer", x)
    return x


def _finite(x: float) -> float:
    """A float operand or result as SWI-Prolog's check_float() with its default flags
    (float_overflow=error, float_undefined=error): an infinity is
    ``evaluation_error(float_overflow)``, a NaN ``evaluation_error(undefined)``."""
    if x - x != 0.0:   # inf - inf and nan - nan are NaN; any finite x - x is 0.0
        raise evaluation_error("undefined" if x != x else "float_overflow")
    return x


def _float_args(f, promote: bool = True, arity: int = 1):
    """A float function of SWI-Prolog's: each float operand is checked (left first) before
    it is applied (sin(inf) is float_overflow, not undefined; exp(-inf) too), and with
    ``promote`` each integer operand is made a float first, as SWI-Prolog does, so one
    beyond the floats overflows (log(2**1100), sqrt(-(2**1100)): Python's math.log would
    take the integer as it is). One wrapper per arity, without a loop: these are called for
    every sqrt, sin, atan2 the interpreter and compiled statements evaluate."""
    if arity == 1:
        def g(a):
            ta = type(a)
            if ta is float:
                if a - a != 0.0:
                    _finite(a)
            elif promote and ta is int:
                a = float(a)   # OverflowError: float_overflow
            return f(a)
        return g

    def g2(a, b):
        ta = type(a)
        if ta is float:
            if a - a != 0.0:
                _finite(a)
        elif promote and ta is int:
            a = float(a)       # (the left operand's overflow first)
        tb = type(b)
        if tb is float:
            if b - b != 0.0:
                _finite(b)
        elif promote and tb is int:
            b = float(b)
        return f(a, b)
    return g2


def _div(a, b):
    if type(a) is int and type(b) is int:
        if b == 0:
            raise evaluation_error("zero_divisor")
        if a % b == 0:
            return a // b
        # as SWI-Prolog (prefer_rationals=false): each integer made a float, then divided;
        # not the exact quotient rounded, which differs beyond 2**53 (-1 / 9007199254740993),
        # and an integer beyond the floats overflows (3 / 10**400)
        return float(a) / float(b)
    if type(b) is float and b - b != 0.0:
        if b == b:
            # over an infinity (SWI-Prolog): an integer is the integer 0, a zero takes the
            # divisor's sign; inf / inf is undefined (the result's check)
            if type(a) is int:
                return 0
            return math.copysign(0.0, b) if a == 0 else a / b
        if type(a) is float:
            _finite(a)   # inf / nan: the infinity's overflow first
        else:
            float(a)     # an integer beyond the floats: its overflow first (OverflowError)
        raise evaluation_error("undefined")
    if b == 0:
        if type(a) is float:
            _finite(a)
        else:
            float(a)     # (2**1100) / 0.0: the integer's overflow first, as SWI-Prolog
        # a zero over zero is no number (SWI-Prolog: undefined), anything else over zero
        # a division by zero
        raise evaluation_error("undefined" if a == 0 else "zero_divisor")
    return a / b


def _intdiv(a, b):
    a, b = _int_required(a), _int_required(b)
    if b == 0:
        raise evaluation_error("zero_divisor")
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b >= 0) else -q


def _mod(a, b):
    a, b = _int_required(a), _int_required(b)
    if b == 0:
        raise evaluation_error("zero_divisor")
    return a % b


def _floordiv(a, b):
    a, b = _int_required(a), _int_required(b)
    if b == 0:
        raise evaluation_error("zero_divisor")
    return a // b


def _rem(a, b):
    a, b = _int_required(a), _int_required(b)
    if b == 0:
        raise evaluation_error("zero_divisor")
    return a - b * _intdiv(a, b)


def _pow_star(a, b):
    # SWI (prefer_rationals=false): int ** int is an int when the result is integral
    if type(a) is int and type(b) is int:
        if b >= 0:
            return _int_power(a, b)
        if a in (1, -1):
            return a ** b and int(a ** b)
        if a == 0:
            raise evaluation_error("zero_divisor")
        return float(a) ** b
    return _pow_float(a, b)


def _pow_float(a, b):
    """a ** b (and a ^ b) when one of them is a float, as SWI-Prolog 9 (prefer_rationals
    false): anything to the power zero and the integer 1 to any power are the integer 1;
    else both operands are checked (left first: inf ** nan is float_overflow) and so is the
    result."""
    if b == 0 or (type(a) is int and a == 1):
        return 1
    if type(a) is int and a == 0 and b == b:
        if b < 0:
            raise evaluation_error("zero_divisor")
        return 0
    # each operand checked, an integer made a float (beyond the floats: float_overflow,
    # before a negative base's fraction is looked at), left first
    fa = _finite(a) if type(a) is float else float(a)
    fb = _finite(b) if type(b) is float else float(b)
    if fa < 0 and fb != int(fb):
        raise evaluation_error("undefined")   # C's pow: a negative number to a fraction
    try:
        return fa ** fb
    except ZeroDivisionError:
        raise evaluation_error("zero_divisor")


def _pow_caret(a, b):
    if type(a) is int and type(b) is int:
        if b < 0:
            if a in (1, -1):
                return int(a ** b)
            if a == 0:
                raise evaluation_error("zero_divisor")
            raise type_error("float", a)
        return _int_power(a, b)
    return _pow_float(a, b)




def _sqrt(a):
    if a < 0:
        raise evaluation_error("undefined")
    return math.sqrt(a)


def _log(a):
    if a < 0:
        raise evaluation_error("undefined")
    if a == 0:
        # SWI-Prolog 9: log(0) is -inf, an overflow (ISO would say undefined)
        raise evaluation_error("float_overflow")
    return math.log(a)


def _to_int(f, x):
    if type(x) is int:
        return x
    if x - x != 0.0:
        return x   # SWI-Prolog: an infinity or NaN stays itself (truncate(inf) is inf)
    return int(f(x))


def _round(x):
    if type(x) is int:
        return x
    if x - x != 0.0:
        return x
    # Prolog rounds half away from zero, Python's round() to even
    return int(math.floor(x + 0.5)) if x >= 0 else -int(math.floor(-x + 0.5))


def _sign(x):
    if type(x) is int:
        return (x > 0) - (x < 0)
    if x != x:
        return x
    return math.copysign(1.0, x) if x != 0 else 0.0


def _minmax(pick_first):
    # as SWI-Prolog: a NaN gives way to the other number (max(1, nan) is 1), -0.0 is below
    # the zeros (max(0, -0.0) is 0), and of two equal numbers the float wins
    # (max(1, 1.0) is 1.0, in either order): max_list/2 and aggregate_all fold with these
    def f(a, b):
        if a != a:
            return b
        if b != b:
            return a
        if a == b:
            # SWI-Prolog makes floats of the two (checked: max(inf, inf) is float_overflow)
            if type(a) is float:
                _finite(a)
            if type(b) is float:
                _finite(b)
            sa = math.copysign(1.0, a) if type(a) is float else 1.0
            sb = math.copysign(1.0, b) if type(b) is float else 1.0
            if sa != sb:   # -0.0 and a zero: the sign decides
                return a if pick_first(sa, sb) else b
            return b if type(b) is float else a
        return a if pick_first(a, b) else b
    return f


def _copysign(a, b):
    # SWI-Prolog: an integer magnitude stays an integer (copysign(1, -0.0) is -1), and an
    # integer sign is only its sign (no float of it: copysign(1, -(2**1100)) is -1)
    negative = b < 0 if type(b) is int else math.copysign(1.0, b) < 0
    if type(a) is int:
        return -abs(a) if negative else abs(a)
    return math.copysign(a, -1.0 if negative else 1.0)


def _fractional_part(a):
    if type(a) is float and a - a != 0.0:
        if a != a:
            raise evaluation_error("undefined")
        return math.copysign(0.0, a)   # SWI-Prolog: the fraction of an infinity is 0.0
    if type(a) is float:
        return math.modf(a)[0]   # the fraction keeps the sign (-1.0e308's is -0.0)
    return a - math.trunc(a)


def _shift_l(a, b):
    a, b = _int_required(a), _int_required(b)
    if b < 0:
        return a >> -b   # SWI-Prolog: a negative shift goes the other way
    if a and a.bit_length() + b > MAX_INTEGER_BITS:
        raise _too_big()
    return a << b


def _shift_r(a, b):
    a, b = _int_required(a), _int_required(b)
    return _shift_l(a, -b) if b < 0 else a >> b


def _msb(a):
    a = _int_required(a)
    if a < 1:
        raise iso_error(Struct("domain_error", (Atom("not_less_than_one"), a)))
    return a.bit_length() - 1


def _lsb(a):
    a = _int_required(a)
    if a < 1:
        raise iso_error(Struct("domain_error", (Atom("not_less_than_one"), a)))
    return (a & -a).bit_length() - 1


def _natural(a):
    """An integer operand that must not be negative (popcount/1, getbit/2)."""
    a = _int_required(a)
    if a < 0:
        raise iso_error(Struct("domain_error", (Atom("not_less_than_zero"), a)))
    return a


def _getbit(a, b):
    _int_required(a), _int_required(b)    # (both types first, as SWI-Prolog)
    # then, as SWI-Prolog, the index's sign, and an index beyond 64 bits is bit 0 of any
    # value (getbit(-2, 2**63) is 0); only then the value's sign
    b = _natural(b)
    if b >= 1 << 63:
        return 0
    return (_natural(a) >> b) & 1


def _atanh(a):
    if a == 1 or a == -1:   # SWI-Prolog: an infinity, so float_overflow (Python: undefined)
        return math.copysign(math.inf, a)
    return math.atanh(a)


BINARY = {
    "+": lambda a, b: a + b,
    "-": lambda a, b: a - b,
    "*": _mul,
    "/": _div,
    "//": _intdiv,
    "mod": _mod,
    "rem": _rem,
    "div": _floordiv,
    "min": _minmax(lambda a, b: a < b),
    "max": _minmax(lambda a, b: a > b),
    "**": _pow_star,
    "^": _pow_caret,
    "atan2": _float_args(math.atan2, arity=2),
    "atan": _float_args(math.atan2, arity=2),
    "copysign": _copysign,
    ">>": _shift_r,
    "<<": _shift_l,
    "/\\": lambda a, b: _int_required(a) & _int_required(b),
    "\\/": lambda a, b: _int_required(a) | _int_required(b),
    "xor": lambda a, b: _int_required(a) ^ _int_required(b),
    "gcd": lambda a, b: math.gcd(_int_required(a), _int_required(b)),
    "getbit": _getbit,
    "nexttoward": _float_args(math.nextafter, arity=2),
}

UNARY = {
    "-": lambda a: -a,
    "+": lambda a: a,
    "abs": abs,
    "sign": _sign,
    "sqrt": _float_args(_sqrt),
    "sin": _float_args(math.sin),
    "cos": _float_args(math.cos),
    "tan": _float_args(math.tan),
    "asin": _float_args(math.asin),
    "acos": _float_args(math.acos),
    "atan": _float_args(math.atan),
    "sinh": _float_args(math.sinh),
    "cosh": _float_args(math.cosh),
    "tanh": _float_args(math.tanh),
    "asinh": _float_args(math.asinh),
    "acosh": _float_args(math.acosh),
    "atanh": _float_args(_atanh),
    "exp": _float_args(math.exp),
    "log": _float_args(_log),
    "floor": lambda a: _to_int(math.floor, a),
    "ceiling": lambda a: _to_int(math.ceil, a),
    "round": _round,
    "truncate": lambda a: _to_int(math.trunc, a),
    "integer": _round,
    "float": _float_args(float),
    "float_integer_part": _float_args(
        lambda a: a if type(a) is int else math.copysign(float(math.trunc(a)), a), promote=False),
    "float_fractional_part": _fractional_part,
    "\\": lambda a: ~_int_required(a),
    "msb": _msb,
    "lsb": _lsb,
    "popcount": lambda a: bin(_natural(a)).count("1"),
    "random": lambda a: _random_below(a),
}


def _random_below(a):
    """random(N): a random integer 0 =< R < N (SWI-Prolog's; N an integer, or an integral
    float, at least 1)."""
    import random

    if type(a) is float and a - a == 0.0 and a == int(a):
        a = int(a)   # (SWI-Prolog takes an integral float as its integer: random(2.0))
    a = _int_required(a)
    if a < 1:
        raise iso_error(Struct("domain_error", (Atom("not_less_than_one"), a)))
    return random.randrange(a)

CONSTANTS = {
    "pi": math.pi,
    "e": math.e,
    "inf": math.inf,
    "nan": math.nan,
    "epsilon": 2.220446049250313e-16,
    # (SWI-Prolog 9.0 has no infinite, max_tagged_integer, realtime nor random/0 function:
    # type_error(evaluable, Name/0) there, and here)
    "random_float": None,
    "cputime": None,
}


# Expressions nested deeper than this are evaluated from an explicit stack (1+1+...+1 with
# 100,000 terms), below Python's recursion limit, which the caller's frames share.
_MAX_RECURSIVE_DEPTH = 200


def evaluate(t: Any, _depth: int = 0) -> int | float:
    """Evaluate an arithmetic expression term.

    >>> from slr_sql.terms import Struct
    >>> evaluate(Struct("+", (1, Struct("*", (2, 3)))))
    7
    """
    t = deref(t)
    tt = type(t)
    if tt is int or tt is float:
        return t
    if tt is Var:
        raise instantiation_error()
    if tt is Struct:
        if _depth > _MAX_RECURSIVE_DEPTH:
            return _evaluate_deep(t)
        name = t.name
        args = t.args
        n = len(args)
        try:
            if n == 2:
                f = BINARY.get(name)
                if f is not None:
                    # right argument first, as SWI-Prolog: it decides which error is
                    # raised when both arguments are faulty ((1/0) + Y: instantiation_error)
                    b = evaluate(args[1], _depth + 1)
                    return _checked(f(evaluate(args[0], _depth + 1), b), name, 2)
            elif n == 1:
                f = UNARY.get(name)
                if f is not None:
                    return _checked(f(evaluate(args[0], _depth + 1)), name, 1)
        except (OverflowError,) as exc:
            raise evaluation_error("float_overflow") from exc
        except (ValueError, ZeroDivisionError) as exc:
            raise evaluation_error("undefined") from exc
        except SLREvaluationError as exc:
            raise _in_function(exc, name, n)
        return _other_compound(t, _depth)
    return _atomic_value(t, tt)


# SWI-Prolog's names for functions in an error's context (0 ^ -1 is raised by its power)
_CONTEXT_NAMES = {"^": "**", "getbit": "bit"}


def _in_function(exc: SLREvaluationError, name: str, n: int) -> SLREvaluationError:
    """An error raised while applying the function name/n, as SWI-Prolog's: one the function
    raises itself (a zero divisor, an operand of the wrong type or domain) names it in its
    context (``context((/)/2, _)``); an undefined or overflowing float, an unbound or unknown
    operand (raised by an operand nested inside the call too), is left for the predicate that evaluates (``context(system:(is)/2, _)``)."""
    term = exc.term
    if type(term) is not Struct or term.name != "error" or len(term.args) != 2:
        return exc
    formal = deref(term.args[0])
    if type(formal) is not Struct or len(formal.args) == 0:
        return exc
    kind = formal.name
    what = deref(formal.args[0])
    if (kind == "evaluation_error" and what == "zero_divisor") or kind == "domain_error" \
            or (kind == "type_error" and what in ("integer", "float")):
        return with_context(exc, Struct("/", (Atom(_CONTEXT_NAMES.get(name, name)), n)))
    return exc


# The functions whose float result SWI-Prolog passes on unchecked: they make no new
# infinity or NaN of finite operands, so -inf, abs(nan), max(inf, 1), truncate(inf) are
# answers, while inf + 1, sqrt(inf), float(inf) raise their errors.
UNCHECKED = frozenset([("-", 1), ("+", 1), ("abs", 1), ("sign", 1), ("floor", 1),
                       ("ceiling", 1), ("round", 1), ("truncate", 1), ("integer", 1),
                       ("float_fractional_part", 1), ("min", 2), ("max", 2), ("copysign", 2)])


def _checked(r: Any, name: str, n: int) -> Any:
    """An operation's result: an infinity is float_overflow and a NaN undefined (but for
    the UNCHECKED functions); an integer beyond MAX_INTEGER_BITS (one that grew slowly, by
    + or -) is a resource error."""
    tr = type(r)
    if tr is float:
        if r - r != 0.0 and (name, n) not in UNCHECKED:
            _finite(r)
        return r
    if tr is int:
        if r.bit_length() > MAX_INTEGER_BITS:
            raise _too_big()
        return r
    if tr is complex:   # a negative number to a fractional power
        raise evaluation_error("undefined")
    return r


def apply_binary(name: str, a: int | float, b: int | float) -> int | float:
    """The binary function ``name`` of two numbers as ``is`` applies it, its result checked
    (the folds of sum_list/2 and aggregate_all/3: ``S is S0 + X``, ``M is max(M0, X)``).

    >>> apply_binary("max", 1, 1.0)
    1.0
    >>> apply_binary("+", 1.0e308, 1.0e308)
    Traceback (most recent call last):
    slr_sql.errors.SLREvaluationError: error(evaluation_error(float_overflow),_)
    """
    try:
        return _checked(BINARY[name](a, b), name, 2)
    except OverflowError as exc:
        raise evaluation_error("float_overflow") from exc


def _other_compound(t: Struct, depth: int) -> int | float:
    """A compound that is not a known operation: ``[X]`` (a character code) or an error."""
    name, args = t.name, t.args
    n = len(args)
    if name == "." and n == 2:
        # [X] is the character code X, as in SWI-Prolog: a code or a one-char atom
        # (SWI-Prolog: the element first, then that it is the only one)
        tail = deref(args[1])
        x = deref(args[0])
        if type(x) is Var:
            raise instantiation_error()
        if not (type(x) is int and x >= 0 or type(x) is Atom and len(x) == 1 and x != "[]"):
            raise type_error("character", x)
        if not (tail == "[]" and type(tail) is Atom):
            raise _not_one_character(t)
        return x if type(x) is int else ord(x)
    # as SWI-Prolog: the arguments are evaluated (right first) before the functor is
    # found unknown, so f(Y) with Y unbound is an instantiation error
    for a in reversed(args):
        evaluate(a, depth + 1)
    raise type_error("evaluable", Struct("/", (name, n)))


def _atomic_value(t: Any, tt: type) -> int | float:
    if tt is Atom:
        if t in CONSTANTS:
            v = CONSTANTS[t]
            if v is None:
                import random
                import time

                return {"random_float": random.random, "cputime": time.process_time}[t]()
            return v
        if t == "[]":
            raise type_error("evaluable", t)
        raise type_error("evaluable", Struct("/", (t, 0)))
    if tt is String:
        if len(t) == 1:
            return ord(t)
        raise _not_one_character(t)
    raise type_error("evaluable", t)


def _not_one_character(t: Any) -> SLREvaluationError:
    """SWI-Prolog's error for a list or string of other than one character as an
    expression (its own term: type_error([], T), with a message as its context)."""
    # (the evaluating predicate fills the context's first argument)
    return iso_error(Struct("type_error", (Atom("[]"), t)),
                     Struct("context", (Var("_"), Atom('"x" must hold one character'))))


class _Apply:
    """_evaluate_deep's marker: apply ``f`` to the last ``n`` values (in argument order)."""

    __slots__ = ("f", "n", "term")

    def __init__(self, f: Any, n: int, term: Struct):
        self.f = f
        self.n = n
        self.term = term


def _evaluate_deep(t: Any) -> int | float:
    """evaluate() from an explicit stack, in the same order (right argument first)."""
    values: list = []
    todo: list = [t]
    while todo:
        x = todo.pop()
        if type(x) is _Apply:
            try:
                if x.n == 2:
                    b = values.pop()
                    a = values.pop()
                    values.append(_checked(x.f(a, b), x.term.name, 2))
                else:
                    values.append(_checked(x.f(values.pop()), x.term.name, 1))
            except OverflowError as exc:
                raise evaluation_error("float_overflow") from exc
            except (ValueError, ZeroDivisionError) as exc:
                raise evaluation_error("undefined") from exc
            except SLREvaluationError as exc:
                raise _in_function(exc, x.term.name, x.n)
            continue
        x = deref(x)
        tx = type(x)
        if tx is int or tx is float:
            values.append(x)
        elif tx is Var:
            raise instantiation_error()
        elif tx is Struct:
            n = len(x.args)
            f = BINARY.get(x.name) if n == 2 else UNARY.get(x.name) if n == 1 else None
            if f is None:
                values.append(_other_compound(x, 0))
                continue
            todo.append(_Apply(f, n, x))
            if n == 2:
                # the right argument is evaluated first (as evaluate() does), so its value
                # lands first: _Swap puts the two back in argument order for _Apply
                todo.append(_SWAP)
                todo.append(x.args[0])
                todo.append(x.args[1])
            else:
                todo.append(x.args[0])
        elif type(x) is _Swap:
            values[-1], values[-2] = values[-2], values[-1]
        else:
            values.append(_atomic_value(x, tx))
    return values[0]


class _Swap:
    """_evaluate_deep's marker: the right operand's value was pushed first: swap the two."""

    __slots__ = ()


_SWAP = _Swap()


def compare_num(a: int | float, b: int | float) -> int:
    """Standard order of two numbers as -1, 0 or 1 (by value: ``1`` and ``1.0`` compare equal).

    >>> compare_num(1, 2.5), compare_num(3, 3.0), compare_num(2, -1)
    (-1, 0, 1)
    """
    return (a > b) - (a < b)
