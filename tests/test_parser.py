"""Parser and printer tests: golden files, round trip, SWI-Prolog cross-check, big input."""
from __future__ import annotations

import pytest

from slr_sql.errors import SLRSyntaxError
from slr_sql.parser import parse_program, parse_term
from slr_sql.printer import format_term


def test_paper_examples_parse():
    clauses = parse_program(
        "location(O, L)^T :- prev(seg(O, L)^Z, T), T - Z =< 5, !.\n"
        "tBuffer(face(P), 60s).\n"
        ":- max_delay(seg/2, 500ms).\n"
    )
    assert [format_term(c.head) if c.head is not None else None for c in clauses] == [
        "location(O,L)^T", "tBuffer(face(P),60)", None]
    assert format_term(clauses[2].body) == "max_delay(seg/2,0.5)"


def test_error_caret():
    with pytest.raises(SLRSyntaxError) as ei:
        parse_program("a(1).\nb(2) :- .\n")
    e = ei.value
    assert (e.line, e.column) == (2, 9)
    assert str(e) == ("<string>:2:9: unexpected '.' (expected a goal after ':-')\n"
                      "    b(2) :- .\n"
                      "            ^")
