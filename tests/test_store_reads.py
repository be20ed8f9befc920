"""Reads that moved behind typed store methods, on both engines: what an event rule's
complex events are made of (``rule_matches``, the demo's provenance notes), the inspection
view of a fact table (``fact_view_select``), and which statements ``slr serve`` lets a
client run (``read_only_refusal``)."""
from __future__ import annotations

import pytest

import slr_sql
from slr_sql.clocks import ManualClock
from slr_sql.store import quote_identifier
from slr_sql.store.read_only import read_only_refusal


def test_rule_matches_name_the_rows_of_each_complex_event(backend):
    with slr_sql.open(backend, clock=ManualClock(100.0)) as kb:
        kb.load("c(X) <- a(X) seq b(X).")
        for event in ["a(1)^1", "a(2)^2", "b(2)^3", "b(1)^4"]:   # one add each: c(2) first
            kb.add(event)
        info = kb.event_rules()[0]
        matches = kb.store.rule_matches(quote_identifier(info["provenance"]), 2)
        # rows by seq: a(1) = 1, a(2) = 2, b(2) = 1, b(1) = 2 (each type numbers its own)
        assert matches == [(2, 1, 2.0, 3.0), (1, 2, 1.0, 4.0)]


def test_the_view_of_facts_reads_them_in_clause_order(backend):
    with slr_sql.open(backend, clock=ManualClock(100.0)) as kb:
        tables = kb.store.replace_fact_tables({("color", 2): [("cup", "red"), ("box", "blue")]})
        select = kb.store.fact_view_select(tables[("color", 2)], 2)
        assert kb.sql(select)[1] == [("cup", "red"), ("box", "blue")]


@pytest.mark.parametrize("statement, dialect, refused", [
    ("SELECT 1", "sqlite", None),
    ("/* why */ -- and\n  with x AS (SELECT 1) SELECT * FROM x", "sqlite", None),
    ("VALUES (1)", "postgresql", None),
    ("EXPLAIN QUERY PLAN SELECT 1", "sqlite", None),
    ("PRAGMA table_info(slr_meta)", "sqlite", None),
    ("pragma main.page_count;", "sqlite", None),
    ("PRAGMA user_version = 99", "sqlite", "this PRAGMA is not allowed"),
    ("PRAGMA writable_schema", "sqlite", "this PRAGMA is not allowed"),
    ("DELETE FROM slr_meta", "sqlite", "DELETE statements are not allowed"),
    ("", "sqlite", "this statements are not allowed"),
    ("SHOW search_path", "postgresql", None),
    ("SHOW search_path", "sqlite", "SHOW statements are not allowed"),
    ("PRAGMA page_count", "postgresql", "PRAGMA statements are not allowed"),
    ("INSERT INTO slr_meta VALUES ('k', 1)", "postgresql", "INSERT statements are not allowed"),
])
def test_only_statements_that_read_are_let_through(statement, dialect, refused):
    refusal = read_only_refusal(statement, dialect)
    assert refusal is None if refused is None else refusal.startswith(refused)


@pytest.mark.parametrize("statement, refused", [
    ("PRAGMA journal_mode;", None),
    ("pragma main.table_info( 'seg' ) ;", None),
    ("PRAGMA table_info(\n'seg'\n)\n", None),
    ("PRAGMA table_info(seg);;", "this PRAGMA is not allowed"),
    ("PRAGMA table_info(seg); DROP TABLE seg", "this PRAGMA is not allowed"),
])
def test_a_pragmas_argument_and_trailing_semicolon(statement, refused):
    assert read_only_refusal(statement) == refused


@pytest.mark.timeout(60)
@pytest.mark.parametrize("statement", [
    "pragma x" + " " * 100_000 + "y",
    "pragma x(" + " " * 100_000 + "y",
    "pragma table_info" + " " * 100_000 + ";" + " " * 100_000 + ";",
    " " * 100_000 + "/*",
    "--\n" * 100_000 + "DELETE FROM seg",
], ids=["spaces-inside-a-pragma", "spaces-in-its-argument", "spaces-between-semicolons",
        "spaces-then-a-comment-left-open", "comment-lines-then-a-delete"])
def test_the_check_reads_a_long_crafted_statement_in_one_pass(statement):
    """A client's statement is checked on the service's threads with the GIL held: layout
    that two quantifiers could share made 4,000 spaces take 99 s of CPU (cubic)."""
    assert read_only_refusal(statement) is not None


def test_every_test_id_is_short_enough_for_a_programs_environment(request):
    """pytest keeps the current test's id in the environment (``PYTEST_CURRENT_TEST``),
    which every program a test or a fixture starts inherits (``pg_ctl`` stopping the
    session's PostgreSQL server in the teardown of the last test, say): an id longer than
    the kernel takes for one string of it (128 KiB) fails every such start with "Argument
    list too long". A parametrized test names its long values with ``ids=``."""
    longest = max(request.session.items, key=lambda item: len(item.nodeid))
    assert len(longest.nodeid) < 1000, longest.nodeid[:200]


def _stored_pages(store, name: str, arity: int, rows: int, max_bytes: int, **where) -> list:
    """Every page of a type, read the way a live view (``after_seq``) or an export
    (``after_key``) reads them."""
    pages, after_seq, after_key = [], 0, None
    while True:
        if "end_from" in where:
            page = store.raw_page(name, arity, rows=rows, max_bytes=max_bytes,
                                  after_key=after_key, **where)
        else:
            page = store.raw_page(name, arity, rows=rows, max_bytes=max_bytes,
                                  after_seq=after_seq)
        pages.append(page)
        if not page.more:
            return pages
        last = page.rows[-1]
        after_seq, after_key = last[-1], (last[arity + 1], last[arity], last[-1])


@pytest.mark.parametrize("where", [{}, {"end_from": 0.0}], ids=["arrival", "end"])
def test_a_page_of_rows_holds_at_most_its_bytes_and_paging_reads_every_row(backend, where):
    sizes = [300, 10, 10, 500, 20, 900, 5, 5, 5, 250]   # characters of each event's text
    with slr_sql.open(backend, clock=ManualClock(100.0)) as kb:
        kb.add_many([f"e('{chr(97 + i) * size}', {i})^{i + 1}" for i, size in enumerate(sizes)])
        pages = _stored_pages(kb.store, "e", 2, rows=4, max_bytes=400, **where)
        read = [row for page in pages for row in page.rows]
        assert [row[0] for row in read] == [chr(97 + i) * size for i, size in enumerate(sizes)]
        for page in pages:
            # one row at least, however large; then only what keeps within the bound
            assert 1 <= len(page.rows) <= 4
            if len(page.rows) > 1:
                assert sum(len(row[0]) + len(str(row[1])) for row in page.rows) <= 400
        # 301 + 11 + 11 bytes, then 501, 21 and 901 alone, then the last four (269)
        assert [len(page.rows) for page in pages] == [3, 1, 1, 1, 4]
        assert [page.more for page in pages] == [True, True, True, True, False]


def test_a_page_says_no_more_when_its_rows_are_the_last(backend):
    with slr_sql.open(backend, clock=ManualClock(100.0)) as kb:
        kb.add_many(["e(1)^1", "e(2)^2"])
        full = kb.store.raw_page("e", 1, rows=2, max_bytes=100, after_seq=0)
        assert ([row[0] for row in full.rows], full.more) == ([1, 2], False)
        assert kb.store.raw_page("e", 1, rows=1, max_bytes=100, after_seq=0).more
        assert kb.store.raw_page("nothing", 1, rows=5, max_bytes=100, after_seq=0).rows == []
