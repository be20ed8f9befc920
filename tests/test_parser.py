"""Parser and printer: golden files, properties, the SWI-Prolog cross-check, big inputs.

Golden files live in tests/golden/parse/:
* ``NAME.slr`` -> ``NAME.txt``: every clause as ``line:col-end_line:end_col  text.`` with
  the printed clause (format_term) and its named variables;
* ``err_NAME.slr`` -> ``err_NAME.err``: the exact ``str()`` of the SLRSyntaxError.
Regenerate after an intended change with ``SLR_UPDATE_GOLDEN=1 pytest tests/test_parser.py``
and review the diff.
"""
from __future__ import annotations

import gc
import json
import math
import os
import re
import shutil
import string
import subprocess
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import slr_sql
from slr_sql.errors import SLRSyntaxError
from slr_sql.parser import parse_event_fast, parse_program, parse_term
from slr_sql.terms import INFIX_OPS, PREFIX_OPS, format_atom, format_term
from slr_sql.terms import NIL, TRUE, Atom, String, Struct, Var, make_list

GOLDEN = Path(__file__).parent / "golden" / "parse"
UPDATE = os.environ.get("SLR_UPDATE_GOLDEN") == "1"


# ------------------------------------------------------------------------- helpers

def _require_swipl(why: str) -> None:
    """Fail (not skip, nor pass having asserted nothing) where SWI-Prolog is missing."""
    if shutil.which("swipl") is None:
        pytest.fail(f"swipl (SWI-Prolog) is not installed: {why} (apt-get install "
                    "swi-prolog-nox; .ci/run does)")


def render_clause(c) -> str:
    if c.head is None:
        text = format_term(Struct(":-", (c.body,)))
    elif c.body is TRUE:
        text = format_term(c.head)
    else:
        text = format_term(Struct(":-", (c.head, c.body)))
    s = c.span
    line = f"{s.line}:{s.column}-{s.end_line}:{s.end_column}  {text}."
    if c.varnames:
        line += "  % vars: " + " ".join(name for name, _ in c.varnames)
    return line


def variant(a, b) -> bool:
    """Structural equality with a consistent one-to-one renaming of variables."""
    fwd: dict[int, Var] = {}
    back: dict[int, Var] = {}
    stack = [(a, b)]
    while stack:
        x, y = stack.pop()
        if type(x) is not type(y):
            return False
        if type(x) is Var:
            if fwd.setdefault(id(x), y) is not y or back.setdefault(id(y), x) is not x:
                return False
        elif type(x) is Struct:
            if x.name != y.name or len(x.args) != len(y.args):
                return False
            stack.extend(zip(x.args, y.args))
        elif type(x) is float:
            if not (x == y and math.copysign(1, x) == math.copysign(1, y)):
                return False
        elif x != y:
            return False
    return True


def check_golden(path: Path, actual: str) -> None:
    if UPDATE:
        path.write_text(actual, encoding="utf-8")
    assert path.exists(), f"missing golden file {path.name}; run with SLR_UPDATE_GOLDEN=1"
    assert actual == path.read_text(encoding="utf-8")


# -------------------------------------------------------------------------- golden
@pytest.mark.parametrize("src", sorted(p.name for p in GOLDEN.glob("*.slr")
                                       if not p.name.startswith("err_")))
def test_golden_program(src):
    path = GOLDEN / src
    clauses = parse_program(path.read_text(encoding="utf-8"), filename=src)
    check_golden(path.with_suffix(".txt"), "".join(render_clause(c) + "\n" for c in clauses))
    # The printed program reads back to the same clauses.
    for c in clauses:
        again = parse_program(render_clause(c).split("  ", 1)[1].split("  % vars:")[0])
        assert len(again) == 1
        assert variant(Struct("c", (c.head, c.body)),
                       Struct("c", (again[0].head, again[0].body))), render_clause(c)


@pytest.mark.parametrize("src", sorted(p.name for p in GOLDEN.glob("err_*.slr")))
def test_golden_error(src):
    path = GOLDEN / src
    with pytest.raises(SLRSyntaxError) as ei:
        parse_program(path.read_text(encoding="utf-8"), filename=src)
    e = ei.value
    assert e.line >= 1 and e.column >= 1 and e.filename == src
    check_golden(path.with_suffix(".err"), str(e) + "\n")


def test_error_example_from_the_brief():
    with pytest.raises(SLRSyntaxError) as ei:
        parse_program("a(1).\nb(2) :- .\n")
    e = ei.value
    assert (e.line, e.column) == (2, 9)
    assert str(e) == ("<string>:2:9: unexpected '.' (expected a goal after ':-')\n"
                      "    b(2) :- .\n"
                      "            ^")


# -------------------------------------------------------------------------- API
def test_clause_kinds_spans_and_text():
    src = "p(a).\n  q(X) :-\n    p(X).\n:- event seg/2.\n"
    fact, rule, directive = parse_program(src, filename="f.slr")
    assert fact.body is TRUE and format_term(fact.head) == "p(a)"
    assert format_term(rule.head) == "q(X)" and format_term(rule.body) == "p(X)"
    assert rule.span.filename == "f.slr"
    assert (rule.span.line, rule.span.column, rule.span.end_line, rule.span.end_column) == \
        (2, 3, 3, 10)
    assert rule.text == "q(X) :-\n    p(X)."
    assert directive.head is None and format_term(directive.body) == "event seg/2"
    assert directive.body == Struct("event", (Struct("/", (Atom("seg"), 2)),))


def test_variables_shared_within_a_clause_and_fresh_across_clauses():
    c1, c2 = parse_program("p(X, Y, _, _) :- q(Y, X).  r(X).")
    names = [n for n, _ in c1.varnames]
    assert names == ["X", "Y"]
    x, y, a1, a2 = c1.head.args
    assert c1.body.args[0] is y and c1.body.args[1] is x
    assert a1 is not a2 and a1.name == a2.name == "_"
    assert c2.head.args[0] is not x


def test_varnames_follow_textual_order_not_reduction_order():
    c = parse_program("location(O, L)^T :- prev(seg(O, L)^Z, T).")[0]
    assert [n for n, _ in c.varnames] == ["O", "L", "T", "Z"]
    t, vs = parse_term("f(A)^B, g(h(C), A)")
    assert list(vs) == ["A", "B", "C"] and vs["A"] is t.args[0].args[0].args[0]


def test_parse_term_event_and_optional_dot():
    t, vs = parse_term("seg(cup1, [0.4,0.1,0.9])^12.31")
    assert vs == {}
    assert t == Struct("^", (Struct("seg", (Atom("cup1"), make_list([0.4, 0.1, 0.9]))), 12.31))
    t2, _ = parse_term("seg(cup1, [0.4,0.1,0.9])^12.31.")
    assert t2 == t
    t3, vs3 = parse_term("p(A)^[S, E]")
    assert format_term(t3) == "p(A)^[S,E]" and list(vs3) == ["A", "S", "E"]


def test_all_or_nothing():
    with pytest.raises(SLRSyntaxError) as ei:
        parse_program("p(1).\np(2).\np(3) :- .\np(4).\n")
    assert ei.value.line == 3


def test_durations_and_inf():
    t, _ = parse_term("f(60s, 500ms, 2min, 1h, 1.5s, 0.5min, inf)")
    assert t.args == (60, 0.5, 120, 3600, 1.5, 30.0, Atom("inf"))
    assert [type(a) for a in t.args[:4]] == [int, float, int, int]


def test_minus_sign():
    # As SWI-Prolog 9 reads it: only a `-` written against the number makes a literal.
    assert parse_term("-1")[0] == -1
    assert parse_term("- 1")[0] == Struct("-", (1,))
    assert parse_term("-(1)")[0] == Struct("-", (1,))
    assert parse_term("- (1)")[0] == Struct("-", (1,))
    assert parse_term("a- 1")[0] == Struct("-", (Atom("a"), 1))
    assert parse_term("X is 3-1")[0].args[1] == Struct("-", (3, 1))
    assert parse_term("a - -1")[0] == Struct("-", (Atom("a"), -1))
    assert parse_term("-(1, 2)")[0] == Struct("-", (1, 2))
    assert parse_term("- (1, 2)")[0] == Struct("-", (Struct(",", (1, 2)),))
    assert parse_term("a-(1, 2)")[0] == Struct("-", (Atom("a"), Struct(",", (1, 2))))


def test_operators_as_atoms():
    assert parse_term("X = (+)")[0].args[1] == Atom("+")
    assert parse_term("f(+, -)")[0] == Struct("f", (Atom("+"), Atom("-")))
    assert parse_term("- = a")[0] == Struct("=", (Atom("-"), Atom("a")))
    assert parse_term("[-]")[0] == make_list([Atom("-")])
    assert parse_term("- (-)")[0] == Struct("-", (Atom("-"),))


def test_bar_is_semicolon_in_clause_bodies_only():
    c = parse_program("p :- (a | b), X = (c | d).")[0]
    assert format_term(c.body) == "(a;b),X=(c'|'d)".replace("'|'", "|")
    assert parse_term("(a | b)")[0] == Struct("|", (Atom("a"), Atom("b")))


@pytest.mark.parametrize("text", [
    "a :- b :- c", "f(a :- b :- c)", "X = \\+ a", "X = a = b", "a b", "foo (a)",
    "[a|b|c]", "[a|b,c]", "f(,)", "f()", "(a", "a)", "'abc", '"abc', "2 ** 3 ** 4",
    "X = - mod", "p :- .", ":- :- a",
])
def test_rejected_like_swi(text):
    with pytest.raises(SLRSyntaxError):
        parse_term(text)


# ------------------------------------------------------------------- round trip
_WEIRD_ATOMS = [
    "a", "cup1", "hello world", "A", "_x", "[]", "{}", "!", ";", ",", "|", "", "'", '"',
    "\\", "\n", "it's", "a\\b", "ñandú", "É", "/*", ".", "..", "=..", "\\+", "-->", ":-",
    "?-", "-", "+", "*", "^", "mod", "is", "dynamic", "event", "rem", "xor", "->", "*->",
    "\t\x01\x7f", "1a", "a.b", "%", "[a]", "inf", "nan", "1.0Inf", "end_of_file", "e",
]
_OP_NAMES = sorted(set(INFIX_OPS) | set(PREFIX_OPS))

atoms = st.one_of(st.sampled_from(_WEIRD_ATOMS), st.sampled_from(_OP_NAMES),
                  st.text(max_size=6)).map(Atom)
names = st.one_of(atoms, st.sampled_from(_OP_NAMES).map(Atom))
strings = st.text(max_size=8).map(String)
numbers = st.one_of(st.integers(min_value=-10**20, max_value=10**20),
                    st.floats(allow_nan=False, allow_infinity=False))
VARS = [Var(n) for n in ("X", "Y", "_G12", "Long_name", "_Y")]
# Named variables are shared objects (as within a parsed clause); every `_` is a fresh Var,
# as the parser makes them (a Var named "_" prints as `_`, so it cannot be shared).
variables = st.one_of(st.sampled_from(VARS), st.builds(lambda: Var("_")))
leaves = st.one_of(atoms, strings, numbers, variables)


def _extend(children):
    compound = st.builds(lambda n, args: Struct(n, tuple(args)), names,
                         st.lists(children, min_size=1, max_size=3))
    operator = st.one_of(
        st.builds(lambda n, a, b: Struct(n, (a, b)), st.sampled_from(sorted(INFIX_OPS)),
                  children, children),
        st.builds(lambda n, a: Struct(n, (a,)), st.sampled_from(sorted(PREFIX_OPS)),
                  children))
    lists = st.builds(lambda items, tail: make_list(items, tail),
                      st.lists(children, max_size=4),
                      st.one_of(st.just(NIL), variables, atoms, children))
    curly = st.builds(lambda a: Struct("{}", (a,)), children)
    return st.one_of(compound, operator, lists, curly)


terms = st.recursive(leaves, _extend, max_leaves=12)


# Example counts keep the file near 30 s on a CI runner; generation, not parsing, is the
# cost (~20 ms per example).  Raise them locally when changing the printer or the parser.
@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(terms)
def test_round_trip(t):
    text = format_term(t)
    back, _ = parse_term(text)
    assert variant(t, back), f"{text!r} read back as {format_term(back)!r}"


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(terms)
def test_round_trip_as_clause_argument(t):
    # The same text inside a fact, terminated by '.', in a program.
    text = f"p({format_term(t, priority=999)}) ."
    (c,) = parse_program(text)
    assert variant(t, c.head.args[0]), text


@settings(max_examples=200, deadline=None)
@given(atoms)
def test_atom_quoting_round_trip(a):
    back, _ = parse_term(f"f({format_atom(a)})")
    assert back.args[0] == a and type(back.args[0]) is Atom


# ------------------------------------------------------------- SWI-Prolog cross-check
# Each text is read by SWI-Prolog 9 (read_term + writeq) and by slr_sql (parse_term +
# format_term); the printed forms must be identical.
SWI_TEXTS = [
    "X = - 1", "X = -(1)", "X = - (1)", "X = -1", "X = - - a", "X = -(-(1))", "X = - - 1",
    "X = (a|b)", "X = (+)", "f(+,-)", "- = a", "- + 1", "X = [-]", "\\+ - a",
    "X = 1.0e10", "X = 1e22", "X = 1.0Inf", "X = 1 - -1", "X = a- 1", "X = 1.0e-10",
    "X = 123.0e100", "X = f((a,b))", "X = (:-)", "X = [a|b]", "X = {a,b}", "X = '{}'(a,b)",
    'X = "a\\"b\\n"', "X = 'it''s'", "X = 'A'", "X = '\\n'", "X = f(;)", "X = (a,b;c->d)",
    "X = -(2)^2", "X = - 2^2", "X = -2^2", "X = -a^2", "X = 2^3^4", ":- dynamic foo/1, bar/2",
    "X = 0x1F+0b101+0o17+0'a", "X = 1-(-(1))", "X = 1-(-1)", "X = a-(-a)", "X = -(-)",
    "p :- a, (b ; c -> d ; e), \\+ f, !", "X = -(a=b)", "X = -(a,b)", "X = - (a,b)",
    "X = a-(b,c)", "X = a-(b:-c)", "X = a*(b+c)", "f(a:-b)", "[a:-b]", "f(a, b|c)",
    "X = 1.5e300 + 5.0e-324 + 0.30000000000000004 + 1.0e15 + 123456789012345.0",
    "X = 'hello world'(x)", "X = f(x)^g(y)^3", "X = '\\x01\\'", "X = f(',', '|', [], {})",
    "X = (a :- b, c ; d)", "X = [1, 2.0, \"s\", 'A b', -3, - 3]", "X = - (dynamic)",
    "X = mod - mod", "X = (- -)", "p :- \\+ \\+ a, !", "X = a mod b", "X = [a|T]",
    "location(O, L)^T :- prev(seg(O, L)^Z, T), T - Z =< 5, !",
    "tf('cam','base',TF)^T :- prev(tf('cam','base',TF1)^T1, T), "
    "next(tf('cam','base',TF2)^T2, [T, inf]), interpolate([TF,T],[TF1,T1],[TF2,T2])",
    "X = \"tab\\there\"", "X = (p *-> q ; r)", "X = (a := b)", "X = ñandú",
    "X = ['\\e', '\\0\\', '\\x7f\\', 'a\\x85\\b', \"\\a\\e\"]", "X = (a, b | c)",
    "X = (a ; b | c)", "p:-(a;b),\\+ (c;d)", "X = a-(b)*c", "X = f(a, (b :- c))",
    # big integers (beyond Python's 4,300-digit str() limit), deep nesting, escapes
    "X = " + "7" * 5000 + " - -" + "9" * 4400, "X = " + "f(" * 600 + "- a" + ")" * 600,
    "X = " + "- " * 600 + "1", "X = " + "^".join(["a"] * 600), "X = 0'\\x41\\ + 0'\\101\\",
    "X = 'it''s\\x41\\\\101\\'", "X = 1.0e308 + 5.0e-324",
]
_SWI_SCRIPT = r"""
:- initialization(main, main).
main :-
    read_line_to_string(user_input, L),
    (   L == end_of_file -> true
    ;   catch(( term_string(T, L, [variable_names(Vs)]),
                maplist([N=V]>>(V='$VAR'(N)), Vs),
                with_output_to(string(S), writeq(T)),
                format("~s~n", [S]) ),
              _, format("<syntax error>~n")),
        main ).
"""


SWI_PRINT_CORPUS = Path(__file__).parent / "golden" / "swi_print.json"


def swi_writeq(texts: list[str], workdir: Path) -> list[str]:
    """What a live SWI-Prolog prints for each text (read_term + writeq), in order."""
    script = workdir / "print.pl"
    script.write_text(_SWI_SCRIPT)
    proc = subprocess.run([shutil.which("swipl"), str(script)], input="\n".join(texts) + "\n",
                          capture_output=True, text=True, timeout=60)
    printed = proc.stdout.splitlines()
    assert len(printed) == len(texts), proc.stderr
    return printed


def test_cross_check_with_swi_prolog(tmp_path):
    """Our printed form of each text is SWI-Prolog's. SWI's answers are committed in
    tests/golden/swi_print.json (written by tests/golden/make_swi_corpus.py), so the test
    runs on machines without SWI-Prolog; where ``swipl`` is installed the live answers must
    equal the committed ones (else the corpus is stale: run the script)."""
    corpus = {x["text"]: x["printed"]
              for x in json.loads(SWI_PRINT_CORPUS.read_text(encoding="utf-8"))["texts"]}
    assert sorted(corpus) == sorted(SWI_TEXTS), "tests/golden/swi_print.json is stale: " \
        "run tests/golden/make_swi_corpus.py"
    if shutil.which("swipl"):
        live = dict(zip(SWI_TEXTS, swi_writeq(SWI_TEXTS, tmp_path)))
        assert live == corpus, "SWI-Prolog prints differently from tests/golden/swi_print.json"
    mismatches = []
    for text in SWI_TEXTS:
        expected = corpus[text]
        assert expected != "<syntax error>", f"SWI-Prolog rejects {text!r}: fix the test list"
        mine = format_term(parse_term(text)[0])
        if mine != expected:
            mismatches.append((text, expected, mine))
    assert not mismatches


@pytest.mark.parametrize("text", SWI_TEXTS, ids=[t if len(t) < 60 else t[:40] + "..."
                                                  for t in SWI_TEXTS])
def test_round_trip_of_cross_check_texts(text):
    t, _ = parse_term(text)
    back, _ = parse_term(format_term(t))
    assert variant(t, back), format_term(t)


# --------------------------------------------------------------------- big inputs
def test_million_element_list():
    n = 1_000_000
    text = "[" + ",".join(map(str, range(n))) + "]"
    term, _ = parse_term(text)   # its speed: benchmarks/bench_big_terms.py
    assert format_term(term) == text


def test_long_list_of_atoms_and_long_program():
    items = [f"a{i}" for i in range(20000)]
    term, _ = parse_term("[" + ", ".join(items) + "|T]")
    assert format_term(term) == "[" + ",".join(items) + "|T]"
    clauses = parse_program("".join(f"p({i}, X) :- q(X, {i}).\n" for i in range(5000)))
    assert len(clauses) == 5000 and clauses[-1].span.line == 5000


def test_deeply_nested_operators_print():
    t = Atom("a")
    for _ in range(300):
        t = Struct("-", (t, Atom("b")))  # left-nested yfx chain: no parentheses needed
    assert format_term(t) == "a" + "-b" * 300
    assert variant(parse_term(format_term(t))[0], t)


# ------------------------------------------------------------------ the fast event reader

# the strings of [a-z][A-Za-z0-9_]{0,6}, built (st.from_regex of that pattern drew the same
# strings at three times the cost: a third of this test's time)
simple_atoms = st.builds(lambda head, tail: head + tail, st.sampled_from(string.ascii_lowercase),
                         st.text(string.ascii_letters + string.digits + "_", max_size=6))
simple_numbers = st.one_of(st.integers(-10**20, 10**20),
                           st.floats(allow_nan=False, allow_infinity=False))
simple_terms = st.recursive(
    st.one_of(simple_atoms.map(Atom), simple_numbers),
    lambda inner: st.one_of(st.lists(inner, max_size=4).map(make_list),
                            st.tuples(simple_atoms, st.lists(inner, min_size=1, max_size=3))
                            .map(lambda t: Struct(t[0], tuple(t[1])))),
    max_leaves=12)


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(simple_atoms, st.lists(simple_terms, max_size=4), simple_numbers, simple_numbers,
       st.sampled_from(["", " "]))
def test_fast_event_reader_agrees_with_the_parser(name, args, s, e, space):
    """kb.add reads the common event shape without lark; whatever it accepts, the parser
    reads the same way (same name, argument terms with their types, times)."""
    atom = Struct(name, tuple(args)) if args else Atom(name)
    stamp = format_term(s) if s == e else f"[{format_term(s)},{space}{format_term(e)}]"
    text = format_term(atom).replace(",", "," + space) + "^" + space + stamp
    fast = parse_event_fast(text)
    if fast is None:  # outside the subset (e.g. a negative time after ^, 1.0e10 spellings)
        return
    term, _ = parse_term(text, "<event>")
    full_args = tuple(term.args[0].args) if args else ()
    full_name = term.args[0].name if args else str(term.args[0])
    assert (fast[0], repr(fast[1])) == (full_name, repr(full_args)), text
    times = term.args[1]
    if s == e:
        assert fast[2] == fast[3] == float(times), text
    else:
        assert (fast[2], fast[3]) == tuple(float(x) for x in (times.args[0], times.args[1].args[0]))


def test_fast_event_reader_is_used_for_common_events():
    assert parse_event_fast("seg(cup1, [0.4, 0.1, 0.9])^12.31") == (
        "seg", (Atom("cup1"), make_list([0.4, 0.1, 0.9])), 12.31, 12.31)
    assert parse_event_fast("tick^[1, 2.5]") == ("tick", (), 1.0, 2.5)
    for outside in ["p('A')^1", 'p("s")^1', "p(a-b)^1", "p(X)^1", "p(1)^-1", "p(1)^1.", "p(0'a)^1"]:
        assert parse_event_fast(outside) is None, outside


_SPACE = st.sampled_from(["", "", " ", "  ", "\t", "\n"])
_PIECE = st.sampled_from([
    "a", "cup1", "x_Y9", "e", "eB", "A", "_", "'q'", "0", "7", "-3", "007", "12.5", "-0.25",
    "1.5e3", "2.0E-2", "1e5", "1.", ".5", "0x1f", "1_000", "0'a", "-", "+1", "[]", "[", "]",
    ",", "(", ")", "f(", "^", "|", ".", "\"s\""])


@st.composite
def _event_texts(draw):
    """Texts around the fast readers' shapes: well-formed flat events (with lists, spaces,
    both kinds of times) and, mixed in, pieces that make them something else."""
    def item() -> str:
        if draw(st.booleans()):
            return draw(_PIECE)
        inner = draw(st.lists(st.sampled_from(["1", "-2.5", "b", "3.0e1", "[]", "c"]),
                              max_size=3))
        return "[" + ",".join(draw(_SPACE) + x + draw(_SPACE) for x in inner) + "]"
    name = draw(st.sampled_from(["e", "seg", "p_1", "tick", "X", "a b"]))
    args = [draw(_SPACE) + item() + draw(_SPACE) for _ in range(draw(st.integers(0, 4)))]
    head = name + ("(" + ",".join(args) + ")" if args or draw(st.booleans()) else "")
    times = draw(st.sampled_from(["1", "12.31", "-4", "0", "1e3", "[1, 2.5]", "[-1,0]",
                                  "[ 3 ,4 ]", "[1]", "x"]))
    return draw(_SPACE) + head + draw(_SPACE) + "^" + draw(_SPACE) + times + draw(_SPACE)


@settings(max_examples=300, suppress_health_check=[HealthCheck.too_slow])
@given(_event_texts())
def test_the_flat_event_reader_reads_as_the_token_scanner(text):
    """The one-expression reader of the flattest events returns what the token scanner
    returns for the same text: the same name, terms, types and times, or nothing."""
    from slr_sql.parser import _scanned_event
    assert repr(parse_event_fast(text)) == repr(_scanned_event(text)), text


def test_the_flat_event_reader_takes_the_common_shapes():
    from slr_sql.parser import _flat_event
    assert _flat_event("seg(cup1, [0.4,0.1,0.9])^12.31") == (
        "seg", (Atom("cup1"), make_list([0.4, 0.1, 0.9])), 12.31, 12.31)
    assert _flat_event(" pose( r1 , -2 , [ ] )^[10, 10.5] ") == (
        "pose", (Atom("r1"), -2, NIL), 10.0, 10.5)
    assert type(_flat_event("e(7)^1")[1][0]) is int      # an integer stays one
    for nested in ["p(f(a))^1", "p([[1]])^1", "p(1)^-1", "p(1e5)^1", "p('a')^1"]:
        assert _flat_event(nested) is None, nested


@pytest.mark.parametrize("text", ["p(1.5e400)^1", "p(a, [1.0e999])^1", "p(f(-1.0e999))^1"])
def test_an_argument_beyond_the_largest_float_is_the_parsers_overflow(text):
    """Both fast readers leave such a text to the parser, which says why (an event added as
    text is read as a program's term is: not as an infinite argument)."""
    from slr_sql.parser import _flat_event, _scanned_event
    assert _flat_event(text) is None and _scanned_event(text) is None
    with pytest.raises(SLRSyntaxError, match="float overflow"):
        parse_term(text)


def test_fast_event_reader_leaves_no_cyclic_garbage():
    """Every kb.add / add_many of event texts reads them here: garbage that only the cyclic
    collector frees would make a server's young collections big and frequent (pauses)."""
    texts = ["e(12)^13", "seg(cup1, [0.4, [0.1]], f(a, b))^[1, 2.5]", "tick^1", "p('A')^1",
             "p(1)^-1", "p(a, b"]
    # young collections only: with the collector off, what the reader makes stays in the
    # youngest generation, where its cyclic garbage is found without traversing the heap
    gc.collect(0)
    enabled = gc.isenabled()
    gc.disable()
    try:
        for _ in range(20):
            for text in texts:
                parse_event_fast(text)
        assert gc.collect(0) == 0
    finally:
        if enabled:
            gc.enable()


@pytest.mark.parametrize("text,printed", [
    ("[1, e]", "[1,e]"), ("[2, E]", "[2,E]"), ("[1.5, e1, 3]", "[1.5,e1,3]"),
    ("[0.4, 0.1, -0.9]", "[0.4,0.1,-0.9]"), ("[1, 2|T]", "[1,2|T]"), ("[1-2]", "[1-2]"),
])
def test_lists_starting_with_numbers(text, printed):
    """A number list is lexed as one token; lists that only start with numbers are not."""
    assert format_term(parse_term(text, "<t>")[0]) == printed


# --------------------------------------------------------- bad inputs (hardening)
# Every bad text is an SLRSyntaxError at the offending character (line, column, a fragment of
# the message), never a raw Python exception. "\\" below is one backslash in the SLR text.
_BIG_DIGITS = "9" * 400_000  # ~1.3 million bits: beyond terms.MAX_INTEGER_BITS
BAD_INPUTS = [
    # (text, line, column, message fragment)
    ("X = '\\xFFFFFFFFFF\\'", 1, 6, "illegal character code"),
    ("X = '\\x110000\\'", 1, 6, "illegal character code"),
    ("X = '\\xD800\\'", 1, 6, "illegal character code"),           # a surrogate, as SWI
    ('X = "ab\\x110000\\"', 1, 8, "illegal character code"),       # in a string
    ("X = '\\7777777\\'", 1, 6, "illegal character code"),          # octal
    ("X = 0'\\x110000\\", 1, 7, "illegal character code"),          # a character code
    ("X = 'a\\xg'", 1, 7, "\\x escape without hexadecimal digits"),
    ("X = f('\\x')", 1, 8, "\\x escape without hexadecimal digits"),
    ("X = 'it''s\\q'", 1, 11, "undefined escape sequence '\\q'"),  # after a doubled quote
    ("X = 1.0e400", 1, 5, "float overflow"),
    ("X = [1.0, 2.5e999]", 1, 11, "float overflow"),                # a number list token
    ("X = 'a\ud800b'", 1, 7, "illegal character code"),            # a lone surrogate itself
    ("a.\r\np('\udfff').", 2, 4, "illegal character code"),
    ("X = " + _BIG_DIGITS, 1, 5, "integer too large"),
    ("X = 0x" + "f" * 300_000, 1, 5, "integer too large"),
    ("X = " + _BIG_DIGITS + "s", 1, 5, "integer too large"),         # a duration
    ("p :-\n  X = '\\q'.", 2, 8, "undefined escape sequence"),
]


@pytest.mark.parametrize("text,line,column,fragment", BAD_INPUTS,
                         ids=[f"bad{i}" for i in range(len(BAD_INPUTS))])
def test_bad_input_is_a_syntax_error_at_its_place(text, line, column, fragment):
    with pytest.raises(SLRSyntaxError) as ei:
        parse_program(text if text.endswith(".") else text + ".")
    e = ei.value
    assert fragment in e.message, str(e)
    assert (e.line, e.column) == (line, column), str(e)
    assert "\r" not in e.source_line
    str(e).encode("utf-8")  # printable as it is: no lone surrogate in the message


def test_big_integers_read_and_print_beyond_pythons_digit_limit():
    # Python refuses int(text) beyond 4,300 digits by default; SLR reads them, as SWI does.
    digits = "7" * 5000
    t, _ = parse_term(f"X = {digits}")
    assert t.args[1] == 7 * (10**5000 - 1) // 9
    assert format_term(t) == f"X={digits}"
    assert format_term(parse_term(f"f(-{digits})")[0]) == f"f(-{digits})"


def test_characters_up_to_the_last_code_point_are_fine():
    t, _ = parse_term("X = '\\x10FFFF\\\\x0\\'")
    assert t.args[1] == "\U0010ffff\x00"


# ------------------------------------------------- deep inputs: no recursion limit
DEEP = 100_000  # the shapes that used to recurse once per level; the others share their code
SOME = 20_000
# shape -> (text, its printed form; None when that is the text without spaces)
DEEP_SHAPES = {
    "compound": ("f(" * DEEP + "a" + ")" * DEEP, None),
    "nested lists": ("[" * DEEP + "a" + "]" * DEEP, None),
    "prefix chain": ("- " * DEEP + "a", "- " * (DEEP - 1) + "-a"),
    "xfy chain": ("^".join(["a"] * DEEP), None),
    "yfx chain": ("+".join(["a"] * SOME), None),
    "parentheses": ("(" * SOME + "a" + ")" * SOME, "a"),
    "curly": ("{" * SOME + "a" + "}" * SOME, None),
    "conjunction": (", ".join(["a"] * SOME), ",".join(["a"] * SOME)),
    "if-then-else": ("(a -> b ; " * SOME + "c" + ")" * SOME, "a->b;" * SOME + "c"),
    "mixed": ("f(- [" * SOME + "a" + "])" * SOME, "f(-[" * SOME + "a" + "])" * SOME),
    # an infix operator before a bracket whose commas are operators (re-read as one term)
    "infix bracket": ("a-(b:-c, " * SOME + "d" + ")" * SOME, None),
}


@pytest.mark.parametrize("shape", sorted(DEEP_SHAPES))
def test_deep_terms_parse_and_print(shape):
    text, printed = DEEP_SHAPES[shape]
    term, _ = parse_term(text)
    assert format_term(term) == (text.replace(" ", "") if printed is None else printed)


def test_a_body_of_many_goals_parses():
    n = DEEP // 2
    (c,) = parse_program("p :- " + ", ".join(f"q({i})" for i in range(n)) + ".")
    goals, body = [], c.body
    while type(body) is Struct and body.name == ",":
        goals.append(body.args[0])
        body = body.args[1]
    assert len(goals) + 1 == n
    (d,) = parse_program("p :- " + " | ".join(["a"] * n) + ".")  # `|` read as `;`
    assert d.body.name == ";" and d.body.args[1].name == ";"


def test_deep_event_text_falls_back_to_the_parser():
    text = "p(" + "f(" * 5000 + "a" + ")" * 5000 + ")^1"
    assert parse_event_fast(text) is None
    term, _ = parse_term(text)
    assert term.name == "^"


def test_cyclic_terms_print_as_swi_does():
    x = Var("X")
    x.ref = Struct("f", (x,))
    assert format_term(x) == "@(S_1,[S_1=f(S_1)])"
    y = Var("Y")
    y.ref = make_list([Atom("a")], y)
    assert format_term(Struct("g", (y, y))) == "@(g(S_1,S_1),[S_1=[a|S_1]])"


# ------------------------------------------------------------------ big quoted text
@pytest.mark.parametrize("quote", ["'", '"'])
def test_a_large_quoted_atom_costs_memory_proportional_to_its_size(quote):
    import tracemalloc

    n = 500_000
    text = "X = " + quote + "ab\\n" * (n // 4) + "x" * (n // 2) + quote
    tracemalloc.start()
    try:
        term, _ = parse_term(text)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert len(term.args[1]) == 3 * (n // 4) + n // 2
    assert peak < 40 * n, f"peak {peak / 1e6:.0f} MB for a {n / 1e6:.0f} MB atom"


# ------------------------------------------------------------------ layout characters
# Python's `\s`, str.isspace and float() take every one of these for whitespace; SWI-Prolog 9
# reads U+001C..U+001F and U+0085 as illegal characters, the rest as layout.
WHITESPACE = [c for c in map(chr, range(0x3001)) if c.isspace()]   # (U+3000 is the last)
SWI_ILLEGAL = {"\x1c", "\x1d", "\x1e", "\x1f", "\x85"}


def _laid_out(char: str) -> dict[str, str]:
    """Texts with ``char`` where layout may stand, for each reader."""
    return {"flat event": f"{char}p({char}-3{char},{char}[1.5{char},{char}a{char}]{char}){char}^"
                          f"{char}[{char}1{char},{char}2{char}]{char}",
            "nested event": f"p({char}f({char}a{char}){char}){char}^{char}1{char}",
            "program": f"{char}p(-3{char}).{char}q([1.5{char}, 2]).{char}r(1){char}:-{char}true.",
            "query": f"{char}p(X){char},{char}q(Y){char}"}


@pytest.mark.parametrize("char", WHITESPACE, ids=lambda c: f"U+{ord(c):04X}")
def test_layout_is_what_swi_prolog_reads_as_layout(char):
    """Every reader (both fast event readers, the parser of events, programs and queries)
    takes a whitespace character as layout exactly where SWI-Prolog does, and refuses the
    others with a syntax error at the character, as the parser refuses any stray character."""
    texts = _laid_out(char)
    kb = slr_sql.open(clock=slr_sql.ManualClock(100))
    try:
        if char in SWI_ILLEGAL:
            for reader, text in texts.items():
                if reader.endswith("event"):
                    assert parse_event_fast(text) is None, reader
                    call = kb.add
                else:
                    call = kb.load if reader == "program" else kb.query
                with pytest.raises(SLRSyntaxError, match=re.escape(f"unexpected character {char!r}")):
                    call(text)
            assert kb.query("p(X)^[S, E]") == kb.query("p(X, Y)^[S, E]") == []   # none stored
            with pytest.raises(slr_sql.SLRError, match="existence_error"):
                kb.query("q(X)")                                                # none loaded
            return
        spaced = _laid_out(" ")
        for reader in ("flat event", "nested event"):
            assert parse_event_fast(texts[reader]) == parse_event_fast(spaced[reader]) \
                is not None, reader
            kb.add(texts[reader])
        kb.load(texts["program"])
        assert kb.query(texts["query"]) == [{"X": -3, "Y": [1.5, 2]}]
        assert kb.query("p(X, Y)^[S, E]") == [{"X": -3, "Y": [1.5, slr_sql.Atom("a")], "S": 1.0,
                                                 "E": 2.0}]
        assert kb.query("p(X)^T") == [{"X": slr_sql.Struct("f", (slr_sql.Atom("a"),)), "T": 1.0}]
    finally:
        kb.close()


def test_swi_prolog_refuses_those_characters_and_no_other_whitespace(tmp_path):
    """The table above is SWI-Prolog's (where ``swipl`` is installed it is asked), and the
    parser's layout characters are the same whitespace less those."""
    from slr_sql.parser import _LAYOUT_CHARS
    assert set(_LAYOUT_CHARS) == set(WHITESPACE) - SWI_ILLEGAL
    assert all(not chr(c).isspace() for c in range(0x3001, 0x110000))
    if shutil.which("swipl"):
        codes = ",".join(str(ord(c)) for c in WHITESPACE)
        goal = (f"forall(member(C,[{codes}]), (atom_codes(A, [0'p, 0'(, 0'1, C, 0')]), "
                "catch((term_string(_, A), R = ok), _, R = illegal), "
                "format('~w ~w~n', [C, R]))), halt")
        out = subprocess.run([shutil.which("swipl"), "-g", goal], capture_output=True,
                             text=True, timeout=60).stdout.split()
        verdicts = dict(zip(out[::2], out[1::2]))
        assert {chr(int(c)) for c, v in verdicts.items() if v == "illegal"} == SWI_ILLEGAL
        assert len(verdicts) == len(WHITESPACE)


# ------------------------------------------------------------- non-ASCII capitals
# What SWI-Prolog 9 reads for `X = <text>`: a name that begins with a capital letter of any
# script is a variable (and cannot stand before `(`), a titlecase letter (U+01C5) or a small
# one begins an atom.
CAPITALS = {"Émile": "var", "Ωmega": "var", "ℕat": "var", "Ⅻ": "var", "Ø": "var",
            "émile": "atom", "ωmega": "atom", "ǅa": "atom", "x٣": "atom", "ⅻ": "atom",
            "Émile(a)": "syntax", "Foo(a)": "syntax", "émile(a)": "compound"}


def _kind(term: object) -> str:
    return {Var: "var", Atom: "atom", Struct: "compound"}[type(term)]


def _swi_kinds(texts: list[str], tmp_path: Path) -> list[str]:
    """What X is to SWI-Prolog in each ``X = <text>``: var, atom, compound, or syntax (each
    text sent as a quoted atom, so that any character gets there)."""
    script = tmp_path / "kinds.pl"
    script.write_text(
        ":- initialization(main, main).\n"
        "main :- read_term(user_input, L, []), ( L == end_of_file -> true ;\n"
        "  catch(( term_string(T, L), T = (_ = V),\n"
        "    ( var(V) -> K = var ; atom(V) -> K = atom ; K = compound ) ),\n"
        "    _, K = syntax),\n"
        "  format('~w~n', [K]), main ).\n", encoding="utf-8")
    proc = subprocess.run([shutil.which("swipl"), str(script)],
                          input="".join(format_atom(f"X = {t}") + ".\n" for t in texts),
                          capture_output=True, text=True, encoding="utf-8", timeout=60)
    return proc.stdout.split()


@pytest.mark.parametrize("text", CAPITALS)
def test_a_name_with_a_capital_of_any_script_is_a_variable(text):
    if CAPITALS[text] == "syntax":
        with pytest.raises(SLRSyntaxError, match="operator expected"):
            parse_term(f"X = {text}")
        return
    term, names = parse_term(f"X = f({text}, {text})")
    first, second = term.args[1].args
    assert _kind(first) == CAPITALS[text]
    if CAPITALS[text] == "var":
        assert first is second and text in names     # one variable, named as written
        # an atom of that name is written quoted, so that it reads back as the atom
        assert parse_term(format_atom(text))[0] == Atom(text)


def test_the_capitals_table_is_swi_prologs(tmp_path):
    """The parser reads each text of the table as the table says, and so does SWI-Prolog
    where ``swipl`` is installed (CI installs it)."""
    def ours(text: str) -> str:
        try:
            return _kind(parse_term(f"X = {text}")[0].args[1])
        except SLRSyntaxError:
            return "syntax"
    assert {text: ours(text) for text in CAPITALS} == CAPITALS
    if not shutil.which("swipl"):
        return
    assert dict(zip(CAPITALS, _swi_kinds(list(CAPITALS), tmp_path))) == CAPITALS


# ---------------------------------------------------------------- digit groups, scripts
# What SWI-Prolog 9 reads for `X = <text>` (writeq of X, or a syntax error): integers in
# digit groups, and digits of any one script.
NUMBERS = {"1_000_000": "1000000", "1 000 000": "1000000", "1_ 000": "1000",
           "1_\n000": "1000", "1_%c\n000": "1000", "1_/*c*/000": "1000", "0x1_F": "31",
           "0o7 7": "63", "0b1 0": "2", "[1 000, 2]": "[1000,2]", "-1 000": "-1000",
           "f(1 2)": "f(12)", "٣٤": "34", "١ ٢": "12", "١٢.٥": "12.5", "٣.٥e٢": "350.0",
           "1  000": "syntax", "1__000": "syntax", "1_000_": "syntax", "1 _000": "syntax",
           "1\t000": "syntax", "0x1 F": "syntax", "1 000e3": "syntax", "1٣": "syntax",
           "1 ٣": "syntax", "٣e2": "syntax", "١٢.٥e3": "syntax", "1.5e٣": "syntax",
           "1_/* a */ 2": "12", "1_/* a */ b */2": "syntax", "1_/*/*/**/2": "syntax"}


def _swi_reads(texts: list[str], tmp_path: Path) -> list[str]:
    """What SWI-Prolog writes (writeq) for X read from each ``X = <text>``, or "syntax"."""
    script = tmp_path / "reads.pl"
    script.write_text(
        ":- initialization(main, main).\n"
        "main :- read_term(user_input, L, []), ( L == end_of_file -> true ;\n"
        "  catch(( term_string(T, L), T = (_ = V), with_output_to(string(S), writeq(V)) ),\n"
        "    _, S = syntax),\n"
        "  format('~w~n', [S]), main ).\n", encoding="utf-8")
    # each text as a quoted atom term, so that any character and newline gets there
    lines = "".join(format_atom(f"X = {t}") + ".\n" for t in texts)
    proc = subprocess.run([shutil.which("swipl"), str(script)], input=lines,
                          capture_output=True, text=True, encoding="utf-8", timeout=60)
    return proc.stdout.splitlines()


def _read_as_written(text: str) -> str:
    """What the parser reads for ``X = <text>``, written (format_term), or "syntax": the form
    of the tables' answers below."""
    try:
        return format_term(parse_term(f"X = {text}")[0].args[1])
    except SLRSyntaxError:
        return "syntax"


@pytest.mark.parametrize("text", NUMBERS)
def test_numbers_read_as_swi_prolog_reads_them(text):
    assert _read_as_written(text) == NUMBERS[text]


def test_the_numbers_table_is_swi_prologs(tmp_path):
    """Where ``swipl`` is installed (CI installs it) it reads the table's texts as the table
    says; the events' fast readers leave digit groups and other scripts to the parser."""
    assert parse_event_fast("p(1_000)^1") is None and parse_event_fast("p(1 000)^1") is None
    assert parse_event_fast("p(٣)^1") is None and parse_event_fast("p(1٣)^1") is None
    kb = slr_sql.open(clock=slr_sql.ManualClock(0))
    kb.add_many(["p(1_000, 2 000)^1 500", "p(٣, ١٢.٥)^2"])
    assert kb.query("p(X, Y)^T") == [{"X": 3, "Y": 12.5, "T": 2.0},
                                     {"X": 1000, "Y": 2000, "T": 1500.0}]
    with pytest.raises(SLRSyntaxError, match="two scripts"):
        kb.add("p(1٣)^1")
    with pytest.raises(SLRSyntaxError, match="two scripts"):     # a duration too
        kb.load(":- max_delay(p/2, 1٣ms).")
    assert parse_term("X = ٣ms")[0].args[1] == 0.003
    kb.close()
    if shutil.which("swipl"):
        assert dict(zip(NUMBERS, _swi_reads(list(NUMBERS), tmp_path))) == NUMBERS


# ------------------------------------------------------------------ name characters
# What SWI-Prolog 9 reads for `X = <text>` (slr_sql/unichars.py): a name goes on with Unicode
# ID_Continue characters -- marks (`é` written `e` + U+0301), connector punctuation -- and not
# with `²`; non-ASCII symbols glue into symbol atoms; `²` and `½` are atoms alone, as `!` is.
NAME_CHARS = {"x²": "syntax", "a²b": "syntax", "½a": "syntax", "X²": "syntax", "_²": "syntax",
              "²": "atom", "½": "atom", "x\u0301": "atom", "e\u0301cole": "atom",
              "a\u0903b": "atom", "a‿b": "atom", "x℘": "atom", "℘": "atom", "Ω\u0301": "var",
              "→": "atom", "+→": "atom", "≤≥": "atom", "a→b": "syntax", "a·b": "syntax",
              "f(≤, ≥)": "compound", "²(a)": "compound", "∀x": "syntax", "x\U0001d7d8": "atom",
              "\U00010400x": "var", "\U00010428x": "atom", "\U0001f600": "atom"}


@pytest.mark.parametrize("text", NAME_CHARS)
def test_names_and_symbols_of_any_script_read_as_swi_prolog_reads_them(text):
    if NAME_CHARS[text] == "syntax":
        with pytest.raises(SLRSyntaxError):
            parse_term(f"X = {text}")
        return
    value = parse_term(f"X = {text}")[0].args[1]
    assert _kind(value) == NAME_CHARS[text]
    if NAME_CHARS[text] == "atom":
        assert value == Atom(text)                # one token, all of the text
        assert parse_term(format_atom(text))[0] == Atom(text)


def test_the_name_chars_table_is_swi_prologs(tmp_path):
    """The grammar's character classes are unichars.py's: a name goes on with every character
    of ID_CONTINUE, a symbol atom with every one of SYMBOL, each SOLO one is an atom alone (the
    first and last character of each range of each class); SWI-Prolog reads the table as it
    says where ``swipl`` is installed."""
    from slr_sql import unichars

    def ends(cls: str) -> list[str]:
        return [c for k, c in enumerate(cls) if c != "-" and "-" not in cls[k - 1:k]] + \
            [cls[k + 1] for k, c in enumerate(cls) if c == "-"]

    for c in ends(unichars.ID_CONTINUE):
        assert parse_term(f"x{c}")[0] == Atom(f"x{c}"), hex(ord(c))
    for c in ends(unichars.ID_START):
        assert type(parse_term(f"{c}x")[0]) is (Var if c.isupper() else Atom), hex(ord(c))
    for c in ends(unichars.SYMBOL):
        assert parse_term(f"+{c}")[0] == Atom(f"+{c}"), hex(ord(c))
    for c in ends(unichars.SOLO):
        assert parse_term(c)[0] == Atom(c), hex(ord(c))
        with pytest.raises(SLRSyntaxError):
            parse_term(c + c)
    if not shutil.which("swipl"):
        return
    assert dict(zip(NAME_CHARS, _swi_kinds(list(NAME_CHARS), tmp_path))) == NAME_CHARS


# ------------------------------------------------------------------ writeq of atoms
# How SWI-Prolog 9's writeq writes an atom: unquoted when it reads back as the same atom -- a
# name of any script that does not begin with a capital, a run of symbol characters, a solo
# character of Latin-1 -- and with control, format and separator characters escaped.
WRITEQ = {"ǅa": "ǅa", "ᾈ1": "ᾈ1", "中1": "中1", "ア_": "ア_", "é": "é", "x\u0301": "x\u0301",
          "²": "²", "½": "½", "→": "→", "+→": "+→", "≤≥": "≤≥", "Émile": "'Émile'",
          "Ⅻ": "'Ⅻ'", "a²": "'a²'", "௰": "'௰'", "\U0001f600": "\U0001f600",
          "a\u2028b": "'a\\x2028\\b'", "a\ufeff": "'a\\xFEFF\\'", "a\xadb": "'a\\xAD\\b'",
          "a\xa0b": "'a\\xA0\\b'", "\x85": "'\\x85\\'", "\x7f": "'\\x7F\\'", "a\u200db": "'a\\x200D\\b'"}


@pytest.mark.parametrize("atom", WRITEQ)
def test_atoms_are_written_as_swi_prologs_writeq_writes_them(atom):
    assert format_atom(atom) == WRITEQ[atom]
    assert parse_term(WRITEQ[atom])[0] == Atom(atom)


def test_the_writeq_table_is_swi_prologs():
    """SWI-Prolog writes each atom of the table as the table says."""
    _require_swipl("this test checks the table against it")
    codes = ",".join("[" + ",".join(str(ord(c)) for c in a) + "]" for a in WRITEQ)
    goal = (f"forall(member(C, [{codes}]), (atom_codes(A, C), writeq(A), nl)), halt")
    out = subprocess.run([shutil.which("swipl"), "-g", goal], capture_output=True,
                         text=True, encoding="utf-8", timeout=60).stdout
    assert dict(zip(WRITEQ, out.splitlines())) == WRITEQ


# --------------------------------------------------------- \u \U \c escapes, Inf and NaN
# What SWI-Prolog 9 reads for `X = <text>` (writeq of X, or a syntax error): the escapes
# \uXXXX, \UXXXXXXXX and \c (which skips the layout after it); 1.0Inf and 1.5NaN take no
# exponent, and a NaN's mantissa lies strictly between 1 and 2.
ESCAPES_AND_FLOATS = {
    "'\\u00e9t\\u00E9'": "été", "\"\\U0001F600\"": '"\U0001f600"', "0'\\u00e9": "233",
    "'a\\c   b'": "ab", "\"a\\c\\tb\"": '"a\\tb"', "'a\\c'": "a", "'\\u00e'": "syntax",
    "'\\U1F600'": "syntax", "'\\uD800'": "syntax", "'\\U00110000'": "syntax",
    "1.0Inf": "1.0Inf", "2.0Inf": "1.0Inf", "0.0Inf": "1.0Inf", "1.5NaN": "1.5NaN",
    "1.25NaN": "1.5NaN", "1.0e10Inf": "syntax", "1.5e0NaN": "syntax", "2.5NaN": "syntax",
    "0.5NaN": "syntax", "1.0NaN": "syntax", "22.2NaN": "syntax", "1.0e10": "10000000000.0"}


@pytest.mark.parametrize("text", ESCAPES_AND_FLOATS)
def test_escapes_and_special_floats_read_as_swi_prolog_reads_them(text):
    assert _read_as_written(text) == ESCAPES_AND_FLOATS[text]


def test_the_escapes_and_floats_table_is_swi_prologs(tmp_path):
    """Where ``swipl`` is installed (CI installs it) it reads the table as it says."""
    if shutil.which("swipl"):
        got = _swi_reads(list(ESCAPES_AND_FLOATS), tmp_path)
        assert dict(zip(ESCAPES_AND_FLOATS, got)) == ESCAPES_AND_FLOATS


# ------------------------------------------------------------------ operator priorities
# Texts SWI-Prolog 9 reads as the same term as the bracketed text beside them (its operator
# table: xor is 400 yfx, := 800 xfx, =@= and \=@= 700 xfx).
SAME_TERMS = {"1 + 2 xor 3": "1 + (2 xor 3)", "2 xor 3 * 4": "(2 xor 3) * 4",
              "a := b = c": "a := (b = c)", "a =@= b + 1": "=@=(a, b + 1)",
              "a \\=@= f(x)": "\\=@=(a, f(x))", "(=@=)": "'=@='", "\\+ a =@= b": "\\+ (a =@= b)"}


@pytest.mark.parametrize("text", SAME_TERMS)
def test_operators_have_swi_prologs_priorities(text):
    assert parse_term(text)[0] == parse_term(SAME_TERMS[text])[0]
    term = parse_term(text)[0]
    assert parse_term(format_term(term))[0] == term


def test_the_operator_table_is_swi_prologs():
    """SWI-Prolog reads each pair of the table as one term."""
    _require_swipl("this test checks the table against it")
    pairs = ",".join(f"{format_atom(a)}-{format_atom(b)}" for a, b in SAME_TERMS.items())
    goal = (f"forall(member(A-B, [{pairs}]), (term_to_atom(T, A), term_to_atom(U, B), "
            "(T == U -> writeln(same) ; writeln(differ)))), halt")
    out = subprocess.run([shutil.which("swipl"), "-g", goal], capture_output=True,
                         text=True, encoding="utf-8", timeout=60).stdout.split()
    assert out == ["same"] * len(SAME_TERMS)


# ------------------------------------------------------- prefix operators before braces
# What SWI-Prolog 9 reads and writes (writeq) for `X = <text>`: a prefix operator is written
# apart from a brace (`-{a}` is a dict to SWI, a syntax error), and a backslash-newline in
# quoted text also skips the layout that follows on the next line.
WRITTEN_BACK = {"- {a}": "- {a}", "f(\\+ {})": "f(\\+ {})", "- {}": "- {}",
                "[- {a, b}]": "[- {a,b}]", "'a\\\n   b'": "ab", "\"a\\\n\tb\"": '"ab"'}


@pytest.mark.parametrize("text", WRITTEN_BACK)
def test_terms_are_written_so_that_swi_prolog_reads_them_back(text):
    term = parse_term(f"X = {text}")[0].args[1]
    assert format_term(term) == WRITTEN_BACK[text]
    assert parse_term(WRITTEN_BACK[text])[0] == term


def test_the_written_back_table_is_swi_prologs(tmp_path):
    """Where ``swipl`` is installed it reads and writes the table's texts as it says, and
    reads the written texts back as the same terms."""
    if shutil.which("swipl"):
        got = _swi_reads(list(WRITTEN_BACK) + list(WRITTEN_BACK.values()), tmp_path)
        assert got == list(WRITTEN_BACK.values()) + list(WRITTEN_BACK.values())


def test_a_query_that_goes_on_after_its_full_stop_says_so():
    """The parser's name of the end of the text ($END) is not shown to a user."""
    for text in ("X = 0. 3", "p(a). q(b)"):
        with pytest.raises(SLRSyntaxError, match=r"expected the end of the text after '\.'"):
            parse_term(text)


# ------------------------------------------------- a prefix operator before an operator atom
# What SWI-Prolog 9 reads for `X = <text>` (writeq, or a syntax error): a prefix operator
# followed by an infix operator that ends the term takes it as its operand when it fits.
PREFIX_BEFORE_OP = {"(- ^)": "- (^)", "[- ^]": "[- (^)]", "f(- ^, a)": "f(- (^),a)",
                    "(\\+ is)": "\\+ (is)", "[\\+ is, a]": "[\\+ (is),a]", "- ^": "- (^)",
                    "(- =)": "syntax", "(- mod)": "syntax"}


@pytest.mark.parametrize("text", PREFIX_BEFORE_OP)
def test_a_prefix_operator_takes_a_final_operator_atom_as_swi_prolog_does(text):
    if PREFIX_BEFORE_OP[text] == "syntax":
        with pytest.raises(SLRSyntaxError):
            parse_term(f"X = {text}")
    else:
        term = parse_term(f"X = {text}")[0].args[1]
        assert format_term(term) == PREFIX_BEFORE_OP[text]
        assert parse_term(PREFIX_BEFORE_OP[text])[0] == term


def test_the_prefix_before_op_table_is_swi_prologs(tmp_path):
    """Where ``swipl`` is installed it reads the table's texts as it says."""
    if shutil.which("swipl"):
        got = _swi_reads(list(PREFIX_BEFORE_OP), tmp_path)
        assert dict(zip(PREFIX_BEFORE_OP, got)) == PREFIX_BEFORE_OP


# ------------------------------------------------------------------------ radix integers
# What SWI-Prolog 9 reads for `X = <text>` (writeq, or a syntax error): R'digits is an integer
# in radix R (2 to 36), in digit groups too.
RADIX = {"16'FF": "255", "16'ff": "255", "2'101": "5", "36'zz": "1295", "02'11": "3",
         "10'12": "12", "16'FF_FF": "65535", "[16'ff, 8'17]": "[255,15]", "37'1": "syntax",
         "1'1": "syntax", "2'102": "syntax", "16'1g": "syntax", "2'": "syntax"}


@pytest.mark.parametrize("text", RADIX)
def test_radix_integers_read_as_swi_prolog_reads_them(text):
    assert _read_as_written(text) == RADIX[text]
    assert parse_event_fast(f"p({text})^1") is None        # left to the parser


def test_the_radix_table_is_swi_prologs(tmp_path):
    """Where ``swipl`` is installed it reads the table's texts as it says."""
    if shutil.which("swipl"):
        assert dict(zip(RADIX, _swi_reads(list(RADIX), tmp_path))) == RADIX


@pytest.mark.parametrize("text", ["X is 1r3", "X = f(2r7)", "p(10r4)."])
def test_a_rational_number_is_refused_as_such(text):
    """SWI-Prolog 9 reads 1r3 as the rational number 1/3; slr_sql has no rationals, and says
    so rather than "operator expected"."""
    with pytest.raises(SLRSyntaxError, match="rational numbers such as 1r3 are not supported"):
        parse_program(text) if text.endswith(".") else parse_term(text)
