"""slr_sql/library_terms.py is the library's Prolog text (slr_sql.builtins.LIBRARY_SOURCE) as
the parser reads it, written out as Python by slr_sql.library_generate: the same clauses,
and a library text edited without regenerating is parsed, never served stale."""
from __future__ import annotations

from typing import Any

import pytest

from slr_sql import library_terms
from slr_sql.builtins import LIBRARY_SOURCE, library_clauses, library_program
from slr_sql.library_generate import MODULE, library_digest, module_text
from slr_sql.parser import parse_program
from slr_sql.terms import Struct, Var


def shape(term: Any, seen: dict[int, int]) -> Any:
    """``term`` with each variable replaced by its order of first appearance (shared
    variables stay shared), the types of atoms, strings and numbers kept."""
    if type(term) is Var:
        return ("var", seen.setdefault(id(term), len(seen)), term.name)
    if type(term) is Struct:
        return (shape(term.name, seen), tuple(shape(a, seen) for a in term.args))
    return (type(term).__name__, term)


def clause_shape(clause: Any) -> tuple:
    seen: dict[int, int] = {}
    return (shape(clause.head, seen), shape(clause.body, seen), clause.span, clause.text,
            tuple((name, shape(var, seen)) for name, var in clause.varnames))


def test_the_generated_clauses_are_the_parsed_ones():
    parsed = parse_program(LIBRARY_SOURCE, "<library>")
    built = library_terms.clauses(LIBRARY_SOURCE)
    assert len(built) == len(parsed) > 50
    assert [clause_shape(c) for c in built] == [clause_shape(c) for c in parsed]


def test_the_committed_module_is_the_generators_output_for_the_library_as_it_is():
    assert library_terms.SOURCE_SHA256 == library_digest(), (
        "slr_sql.builtins.LIBRARY_SOURCE changed after slr_sql/library_terms.py was generated: "
        "run python -m slr_sql.library_generate")
    assert MODULE.read_text(encoding="utf-8") == module_text()


def test_each_call_builds_new_variables():
    first, second = library_terms.clauses(LIBRARY_SOURCE)[0], library_terms.clauses(LIBRARY_SOURCE)[0]
    assert first.varnames[0][1] is not second.varnames[0][1]


@pytest.mark.parametrize("source", [LIBRARY_SOURCE + "\nextra_library_fact(1).\n",
                                    "only(1).\nonly(2).\n"])
def test_a_library_text_the_module_was_not_made_from_is_parsed(source):
    assert [clause_shape(c) for c in library_clauses(source)] == \
        [clause_shape(c) for c in parse_program(source, "<library>")]


def test_the_library_program_has_every_library_predicate():
    keys = {(str(c.head.name), len(c.head.args)) if type(c.head) is Struct else (str(c.head), 0)
            for c in parse_program(LIBRARY_SOURCE, "<library>")}
    assert keys <= set(library_program().preds)
