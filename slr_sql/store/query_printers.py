"""The printers of the query compiler (:mod:`slr_sql.sqlcompile`): one method per kind of
node whose SQL differs between engines, mixed into each dialect object.

The compiler decides *what* a goal means (which rows, which conditions, in which order);
these printers decide how a condition on values, a JSON part of a stored term, an
arithmetic function or an answer column is spelled. SQLite's printer gives the text the
compiler always wrote: ``typeof`` carries Prolog's ``1 \\= 1.0``, JSON parts are read with
``json_extract``, arithmetic and det builtins call Python functions registered on the
connection. PostgreSQL's columns hold the typed text of
:meth:`~slr_sql.store.dialect.PostgresDialect.to_column`, so there text equality already is
Prolog's ``==`` on stored values and no ``typeof`` is needed; what would need a Python
function inside the server (``slr_det``, Prolog arithmetic beyond comparisons, the
aggregates, patterns over the parts of stored lists and compounds) raises
:class:`Unprintable`, and the goal is answered by the interpreter there.

Value kinds (the compiler's ``Col.kind``): ``float`` (times), ``int`` (counts),
``num`` (arithmetic), ``text`` (JSON lists built by findall), ``any`` (a stored value).

>>> from slr_sql.store.dialect import POSTGRES, SQLITE
>>> SQLITE.typed_equal("e0.arg1", ":c0", "integer"), POSTGRES.typed_equal("e0.arg1", ":c0", "integer")
("(e0.arg1 = :c0 AND typeof(e0.arg1) = 'integer')", 'e0.arg1 = :c0')
>>> POSTGRES.same_value("e0.arg1", "any", "e1.t_end", "float")
"(slr_typeof(e0.arg1) = 'real' AND slr_number(e0.arg1) = e1.t_end)"
"""
from __future__ import annotations

__all__ = ["PostgresQueryPrinter", "SQLiteQueryPrinter", "Unprintable"]


class Unprintable(Exception):
    """A node this engine's SQL cannot express exactly; ``reason`` says why (the query
    compiler turns it into a fallback to the interpreter, shown by explain)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class SQLiteQueryPrinter:
    """SQLite: the compiler's text as it always was.

    >>> from slr_sql.store.dialect import SQLITE
    >>> SQLITE.answer("t0.t_end", "float"), SQLITE.inner_json("e0.arg1", "any")
    ('t0.t_end', 'slr_j(e0.arg1)')
    """

    # an engine whose statements may call Python functions (slr_det, slr_ar1, ...)
    query_functions = True
    # the alias a subquery in FROM needs (none on SQLite)
    subquery_alias = ""

    def key_padding(self, kinds: frozenset[str]) -> str:
        """The NULL that pads a branch's missing order key in a UNION ALL, at a place where
        the branches' keys are of ``kinds`` ("text": a robot's name, "number": the others);
        any mix is fine here (a column takes any value, and keys of different kinds only
        meet after an alternative's index has decided).

        >>> SQLiteQueryPrinter().key_padding(frozenset({"text", "number"}))
        'NULL'
        """
        return "NULL"

    def view_column(self, expr: str) -> str:
        """An answer column of an inspection view: without the affinity of the column it
        reads (a view's UNION takes its first branch's affinity, and REAL, a time's, would
        turn another branch's stored integer into a float when the view is read). Unary
        plus is a no-op on every value.

        >>> SQLiteQueryPrinter().view_column("t0.t_start")
        '+(t0.t_start)'
        """
        return f"+({expr})"

    def may_raise(self, sql: str) -> bool:
        """Whether evaluating ``sql`` may raise an error Prolog raises too (arithmetic,
        builtins: every function slr_sql registers but slr_sign_bit)."""
        return self.raising_calls(sql) > 0

    def raising_calls(self, sql: str) -> int:
        """How many calls in ``sql`` may raise."""
        return sql.count("slr_") - sql.count("slr_sign_bit(")

    def typed_equal(self, value: str, const: str, sql_type: str) -> str:
        """A stored value equals a constant number of SQL type ``integer`` or ``real``."""
        return f"({value} = {const} AND typeof({value}) = '{sql_type}')"

    def same_value(self, a: str, kind_a: str, b: str, kind_b: str) -> str:
        """Two run-time values are the same term (``1`` is not ``1.0``)."""
        return f"({a} = {b} AND typeof({a}) = typeof({b}))"

    # -0.0 and 0.0 are two terms, but one value to SQLite's = and grouping, and no built-in
    # shows a zero's sign (without the optional math functions): slr_sign_bit does, called
    # for zeros only; a lookup run without it tells them apart in Python
    zero_signs_in_sql = False

    def zero_sign(self, value: str, negative: bool) -> str | None:
        """The condition that ``value``, equal to a float zero, has the sign of ``-0.0``
        (``negative``) or of ``0.0``; None where ``=`` on stored values tells them apart.

        >>> SQLiteQueryPrinter().zero_sign("t0.arg1", True)
        'slr_sign_bit(t0.arg1) = 1'
        """
        return f"slr_sign_bit({value}) = {1 if negative else 0}"

    def same_zero_sign(self, a: str, b: str) -> str | None:
        """The condition that two equal values, when zeros, have one sign (added to
        :meth:`same_value`); None where ``=`` tells -0.0 from 0.0 already.

        >>> SQLiteQueryPrinter().same_zero_sign("t0.arg1", "t1.arg1")
        '(t0.arg1 <> 0 OR slr_sign_bit(t0.arg1) = slr_sign_bit(t1.arg1))'
        """
        return f"({a} <> 0 OR slr_sign_bit({a}) = slr_sign_bit({b}))"

    def time_equal(self, value: str, time: str) -> str:
        """A stored value or argument is a number equal to a stored time."""
        return f"({value} = {time} AND typeof({value}) IN ('integer', 'real'))"

    def prolog_number(self, value: str) -> str:
        """A stored value as a number in arithmetic (raises on anything else)."""
        return f"slr_num({value})"

    def value_order(self, value: str) -> list[str]:
        """The ORDER BY keys that put stored values in SQLite's order (the order that
        breaks an event rule's ties between events of the same times): numbers first, by
        value (an integer and a real compared exactly), then text byte by byte, then the
        SQL type (1 before 1.0), then -0.0 before 0.0 (Prolog's standard order: to SQL's
        order the two are one value, and the tie went to the arrival order).

        >>> SQLiteQueryPrinter().value_order("e0.arg1")[:2]
        ['e0.arg1', 'typeof(e0.arg1)']
        """
        # (slr_sign_bit is called for the zeros alone)
        return [value, f"typeof({value})",
                f"(CASE WHEN {value} = 0 AND typeof({value}) = 'real' "
                f"THEN 1 - slr_sign_bit({value}) END)"]

    def comparison(self, op: str, a: str, kind_a: str, b: str, kind_b: str) -> str:
        """``a op b`` for an arithmetic comparison of two numbers of the kinds ``float``
        (a double), ``small`` (an integer constant of at most 2**53), ``int`` (another
        integer within 64 bits), ``bignum`` (a larger integer constant) or ``num`` (a stored
        value, :meth:`prolog_number`), exact as Python's comparison of an integer and a
        float is: SQLite compares an INTEGER and a REAL exactly already.

        >>> SQLiteQueryPrinter().comparison("<", "t0.t_end", "float", ":c0", "int")
        't0.t_end < :c0'
        """
        return f"{a} {op} {b}"

    def arith1(self, op: str, a: str) -> str:
        return f"slr_ar1({op}, {a})"

    def arith2(self, op: str, a: str, b: str) -> str:
        return f"slr_ar2({op}, {a}, {b})"

    def finite_float(self, value: str) -> str:
        """A float computed by SQL's own ``+ - *`` of finite floats, failing the statement
        where Prolog raises float_overflow (the interpreter then answers, and raises it):
        SQLite's arithmetic overflows to an infinity (or a NaN, which it reads as NULL), so
        any other value takes ``abs`` of the smallest integer, SQLite's own integer overflow
        error. A built-in rather than an ``slr_`` function: no Python call, and no guard
        statement (docs/semantics.md, "Values", says what that leaves).

        >>> SQLiteQueryPrinter().finite_float("(t0.t_start * :c0)")
        'CASE WHEN abs((t0.t_start * :c0)) <= 1.7976931348623157e308 THEN (t0.t_start * :c0) ELSE abs(-9223372036854775807 - 1) END'
        """
        return (f"CASE WHEN abs({value}) <= 1.7976931348623157e308 THEN {value} "
                f"ELSE abs(-9223372036854775807 - 1) END")

    def det_call(self, site: int, output: int, inputs: str) -> str:
        """Output ``output`` (-1: success) of the det builtin or Python predicate ``site``."""
        return f"slr_det({site}, {output}{inputs})"

    def inner_json(self, value: str, kind: str) -> str:
        """A value's encoding inside JSON (a list element, a compound argument)."""
        return f"slr_j({value})"

    def answer(self, value: str, kind: str) -> str:
        """A value as an answer column of the statement."""
        return value

    def json_guard(self, value: str) -> str:
        """The value when it is a stored list or compound (JSON text), else NULL."""
        return f"(CASE WHEN substr({value}, 1, 1) IN ('[', '{{') THEN {value} END)"

    def json_part(self, text: str, path: str) -> str:
        """The SQL value at ``path`` of JSON ``text`` (a JSON string as its text)."""
        return f"json_extract({text}, {path})"

    def json_text(self, text: str, path: str) -> str:
        """The JSON text at ``path``."""
        return f"{text} -> {path}"

    def json_kind(self, text: str, path: str) -> str:
        """``'array'``, ``'object'``, ``'text'``, ``'integer'``, ``'real'``... at ``path``."""
        return f"json_type({text}, {path})"

    def json_length(self, text: str, path: str) -> str:
        return f"json_array_length({text}, {path})"

    def json_drop(self, text: str, path: str, removes: str) -> str:
        """The array at ``path`` without the elements at the paths ``removes``."""
        return f"json_remove(json_extract({text}, {path}), {removes})"

    def list_of(self, union: str, keys: list[str]) -> str:
        """The JSON list of the ``v0`` of the rows of ``union``, in the order of ``keys``."""
        order = (" ORDER BY " + ", ".join(keys)) if keys else ""
        return f"(SELECT '[' || coalesce(group_concat(v0, ','), '') || ']' FROM ({union}{order}))"

    def aggregate(self, fn: str, union: str) -> str:
        """``slr_sum``/``slr_max``/``slr_min``/``slr_setof`` over ``v0`` of the ordered rows."""
        return f"(SELECT {fn}(v0) FROM ({union}))"


def _exact(value: str) -> str:
    """A double ``value`` as a NUMERIC that compares with integers (and other doubles so
    written) as the double's exact value does: its integral part exactly (a bigint), plus
    the shortest decimal of its fraction (the fraction's decimal has the fraction's sign
    and stays within (-1, 1), and the shortest decimals of doubles are in their order).
    Beyond 2**63 a double is an integer: a bigint of its 61 to 63 leading bits (the division
    by a power of two is exact) times that power of two, exactly (its shortest decimal is
    not its value: 2.0**70 is 1180591620717411303424, not 1180591620717411300000). The
    infinities as their text.

    >>> _exact("t0.t_end")[:60]
    'CASE WHEN abs(t0.t_end) < 9223372036854775807 THEN CAST(CAST'
    """
    # (floor(log(2, |v|)) may be one off at a power of two: the leading part stays an
    # integer below 2**63 either way)
    shift = f"floor(log(2, CAST(abs({value}) AS numeric))) - 61"
    return (f"CASE WHEN abs({value}) < 9223372036854775807 "
            f"THEN CAST(CAST(trunc({value}) AS bigint) AS numeric) "
            f"+ CAST(CAST({value} - trunc({value}) AS text) AS numeric) "
            f"WHEN abs({value}) < CAST('Infinity' AS double precision) "
            f"THEN CAST(CAST({value} / power(CAST(2 AS double precision), {shift}) AS bigint) "
            f"AS numeric) * power(CAST(2 AS numeric), {shift}) "
            f"ELSE CAST(CAST({value} AS text) AS numeric) END")


class PostgresQueryPrinter:
    """PostgreSQL: typed text values, plpgsql functions of migration ``pg_0009``.

    >>> from slr_sql.store.dialect import POSTGRES
    >>> POSTGRES.answer("t0.t_end", "float"), POSTGRES.inner_json("t0.t_end", "float")
    ('slr_float_text(t0.t_end)', 'slr_float_json(t0.t_end)')
    >>> POSTGRES.det_call(1, -1, "")
    Traceback (most recent call last):
    ...
    slr_sql.store.query_printers.Unprintable: a det builtin or a kb.define'd predicate (a Python function) runs in the interpreter on PostgreSQL
    """

    query_functions = False
    subquery_alias = " AS s"

    def key_padding(self, kinds: frozenset[str]) -> str:
        # a UNION column has one type: an untyped NULL in the first branches resolves as
        # text, which does not meet a later branch's number; a NULL typed as a number does
        # not meet a robot's name
        if len(kinds) > 1:
            raise Unprintable("branches ordered by a robot's name and by a number at one "
                              "place (origin/2 beside other goals) run in the interpreter "
                              "on PostgreSQL")
        return "CAST(NULL AS text)" if "text" in kinds else "CAST(NULL AS double precision)"

    def view_column(self, expr: str) -> str:
        # a column is typed: the server refuses a view whose branches disagree (not made)
        return expr

    def may_raise(self, sql: str) -> bool:
        # slr_typeof, slr_number, slr_j and the float printers never raise; slr_num does
        return "slr_num(" in sql

    def raising_calls(self, sql: str) -> int:
        return sql.count("slr_num(")

    def typed_equal(self, value: str, const: str, sql_type: str) -> str:
        # the constant is bound as its column text: the spelling carries the type
        return f"{value} = {const}"

    def same_value(self, a: str, kind_a: str, b: str, kind_b: str) -> str:
        if kind_a in ("any", "text") and kind_b in ("any", "text"):
            return f"{a} = {b}"
        if kind_a == "num" or kind_b == "num":
            raise Unprintable("unifying a computed number with another value runs in the "
                              "interpreter on PostgreSQL")
        if kind_a in ("float", "int"):
            a, kind_a, b, kind_b = b, kind_b, a, kind_a
        if kind_b == "float":
            return f"(slr_typeof({a}) = 'real' AND slr_number({a}) = {b})"
        return f"{a} = ({b})::text"

    def time_equal(self, value: str, time: str) -> str:
        # an integer meets the double as a NUMERIC, by their exact values: slr_number
        # rounds it to a double, and 2**53 + 1 would be the time 2.0**53 (SQLite compares
        # an integer with a double exactly). The rounded equality stays first (an index
        # over the time serves it), and so does the type test (sqlcompile.TIME_ARG finds
        # an argument from Python matched with a time by it)
        integer = f"CAST(CASE WHEN slr_typeof({value}) = 'integer' THEN {value} END AS numeric)"
        return (f"(slr_number({value}) = {time} AND slr_typeof({value}) IN ('integer', 'real') "
                f"AND (slr_typeof({value}) = 'real' OR {integer} = {_exact(time)}))")

    zero_signs_in_sql = True   # a stored value's text carries the sign ('-0.0' is not '0.0')

    def zero_sign(self, value: str, negative: bool) -> str | None:
        return None

    def same_zero_sign(self, a: str, b: str) -> str | None:
        return None

    def prolog_number(self, value: str) -> str:
        # slr_num reads a float's text as a NUMERIC, the shortest decimal that reads back
        # as the float, which is not its value beyond 2**53 (2.0**60 is 1152921504606847000
        # there): a float's exact value instead, as Python compares it with an integer
        # (an integer's text read here, not in the plpgsql slr_num: no call for a number)
        return (f"(CASE slr_typeof({value}) WHEN 'integer' THEN CAST({value} AS numeric) "
                f"WHEN 'real' THEN {_exact(f'CAST({value} AS double precision)')} "
                f"ELSE slr_num({value}) END)")

    def value_order(self, value: str) -> list[str]:
        # SQLite's order of the values (a column of text here would put 12 before 9, and
        # an atom that reads as a number, stored tagged as {"$atom":"9"}, after every
        # letter): numbers by their exact value (text has none: NULL, after the numbers
        # in ascending order), then the text SQLite stores, byte by byte (an atom that
        # SQLite keeps untagged is read out of its tag; one holding U+0000 stays tagged,
        # PostgreSQL text cannot hold the character), then the SQL type
        number = (f"CASE slr_typeof({value}) WHEN 'integer' THEN CAST({value} AS numeric) "
                  f"WHEN 'real' THEN {_exact(f'CAST({value} AS double precision)')} END")
        text = (f"(CASE WHEN slr_typeof({value}) = 'text' THEN "
                f"CASE WHEN left({value}, 10) = '{{\"$atom\":\"' "
                f"AND substr({value}, 11, 1) NOT IN ('[', '{{', '\\') "
                f"AND strpos({value}, '\\u0000') = 0 "
                f"THEN CAST({value} AS json) ->> '$atom' ELSE {value} END END) COLLATE \"C\"")
        # (-0.0 before 0.0: the number key takes them for one value; false sorts first)
        return [number, text, f"slr_typeof({value})", f"({value} <> '-0.0')"]

    def comparison(self, op: str, a: str, kind_a: str, b: str, kind_b: str) -> str:
        # a double meets an integer or a stored value as a NUMERIC (the server would turn
        # the NUMERIC into a double: 2**53 + 1 =:= 2.0**53); two doubles compare as doubles
        kinds = (kind_a, kind_b)
        if "bignum" in kinds and ("float" in kinds or "num" in kinds):
            # (_exact gives a double beyond 2**63 as its shortest decimal)
            raise Unprintable("comparing a float with an integer beyond 64 bits runs in the "
                              "interpreter on PostgreSQL")
        # (an integer constant of at most 2**53 is a double exactly: ``T > 5`` stays a
        # comparison of doubles, as fast as before)
        if kind_a == "float" and kind_b not in ("float", "small"):
            a = _exact(a)
        elif kind_b == "float" and kind_a not in ("float", "small"):
            b = _exact(b)
        return f"{a} {op} {b}"

    def arith1(self, op: str, a: str) -> str:
        raise Unprintable("Prolog arithmetic on stored values (beyond comparisons and float "
                          "+ - *) runs in the interpreter on PostgreSQL")

    def arith2(self, op: str, a: str, b: str) -> str:
        return self.arith1(op, a)

    def finite_float(self, value: str) -> str:
        # double precision arithmetic raises its own overflow error (the interpreter then
        # answers); its operands here are finite (times, finite constants)
        return value

    def det_call(self, site: int, output: int, inputs: str) -> str:
        raise Unprintable("a det builtin or a kb.define'd predicate (a Python function) runs "
                          "in the interpreter on PostgreSQL")

    def inner_json(self, value: str, kind: str) -> str:
        if kind == "float":
            return f"slr_float_json({value})"
        if kind == "int":
            return f"({value})::text"
        if kind == "text":
            return value
        if kind == "num":
            raise Unprintable("a computed number inside a list runs in the interpreter on "
                              "PostgreSQL")
        return f"slr_j({value})"

    def answer(self, value: str, kind: str) -> str:
        # every answer column is the column text (branches of a UNION agree on the type);
        # the planner reads it back with from_column
        if kind == "float":
            return f"slr_float_text({value})"
        if kind == "int":
            return f"({value})::text"
        if kind == "num":
            raise Unprintable("a computed number as an answer runs in the interpreter on "
                              "PostgreSQL")
        return value

    def json_guard(self, value: str) -> str:
        raise Unprintable("matching the parts of a stored list or compound runs in the "
                          "interpreter on PostgreSQL")

    json_part = json_text = json_kind = json_length = json_guard

    def json_drop(self, text: str, path: str, removes: str) -> str:
        return self.json_guard(text)

    def list_of(self, union: str, keys: list[str]) -> str:
        # the order of an aggregate's input is the aggregate's own ORDER BY
        order = (" ORDER BY " + ", ".join(keys)) if keys else ""
        return (f"(SELECT '[' || coalesce(string_agg(v0, ','{order}), '') || ']' "
                f"FROM ({union}) AS s)")

    def aggregate(self, fn: str, union: str) -> str:
        raise Unprintable("aggregate_all sum/max/min/set (Python aggregates) run in the "
                          "interpreter on PostgreSQL")
