"""Differential test: the interpreter against SWI-Prolog (the correctness contract:
docs/semantics.md).

Hypothesis generates small random programs -- facts over a few constants, stratified rules with
joins, cut (also inside if-then-else conditions, ``\\+``, ``findall`` and ``call/1``), negation,
``findall/3``, ``aggregate_all/3``, ``forall/2``, arithmetic with ``is`` and comparisons over
ints and floats (``/``, ``//``, ``mod``), if-then-else, ``*->``, ``;``, member/append/between,
nested ``call/1``, and stored events with a temporal rule -- plus a few queries. Every query
runs through slr_sql (``kb.load`` + ``kb.query(goal, max_steps=...)``) and through SWI-Prolog
(the events written as facts ``ev(A, B, Start, End)`` in store order, before the temporal
rules, as docs/semantics.md says). The answer lists must be equal, in order; an error must be the same
ISO formal term, after the same answers (checked with ``limit=``).

SWI-Prolog runs as one long-lived process that consults each example's program from its own
file, runs its queries, prints the answers in a simple JSON encoding, and unloads the file
(its predicates are abolished afterwards, so existence errors stay exact).

SWI-Prolog's answers to 200 generated examples are committed in ``tests/golden/swi_differential.json``
(written by ``tests/golden/make_swi_corpus.py``). ``test_corpus_answers`` replays them on
every machine; where ``swipl`` is installed (CI installs it) it first checks that SWI-Prolog
still gives exactly the committed answers. ``test_same_answers_as_swipl`` asks a live
SWI-Prolog about fresh examples; on a machine without ``swipl`` it runs on the committed
examples and answers instead, so nothing is skipped.
"""
from __future__ import annotations

import contextlib
import json
import re
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import pytest
from hypothesis import HealthCheck, assume, given, settings, strategies as st
from strategy_helpers import BOOLEANS, integers, sampled

import slr_sql
from slr_sql import Atom, SLREvaluationError, SLRTimeout, Struct, Var
from slr_sql.planner import plan_for
from slr_sql.terms import int_from_text

HAVE_SWIPL = shutil.which("swipl") is not None
CORPUS_PATH = Path(__file__).parent / "golden" / "swi_differential.json"

SLR_MAX_STEPS = 60_000
SWI_INFERENCE_LIMIT = 3_000_000
# SWI-Prolog's stacks (its default is 1 GB). A query that recurses without end fills them
# before it reaches the inference limit, and near 1 GB each garbage collection scans the whole
# stack: one such generated example took 5 s to run out of inferences (and its occurs-check
# run another second), under 1 s with this limit, where it runs out of stack instead. Either
# way slr_sql runs out of SLR_MAX_STEPS on it and the example is discarded; a query slr_sql
# answers within SLR_MAX_STEPS recurses at most that deep, a few MB of SWI-Prolog's stacks,
# so no comparison that is made depends on this limit (one that did would fail: SWI-Prolog's
# resource error is not slr_sql's answer).
SWI_STACK_LIMIT = "64m"
SLR_TIMEOUT = 5.0  # seconds; a query that runs out of steps or time is discarded
MAX_ANSWERS = 200  # a query with more answers is discarded (both sides stop after one more)

# ---------------------------------------------------------------------------------------------
# The SWI-Prolog side
# ---------------------------------------------------------------------------------------------

DRIVER = r"""
:- set_prolog_flag(verbose, silent).
:- style_check(-singleton).
:- style_check(-discontiguous).
% slr_sql, like most Prologs, has no occurs check and does not support cyclic terms (it may
% loop on them): each query is run a second time with occurs_check=error, and a query that
% would create a cyclic term is reported (C); the test discards it before slr_sql runs it.
:- use_module(library(time)).
:- use_module(library(solution_sequences)).

serve :-
    prompt(_, ''),
    repeat,
      read_term(user_input, Cmd, []),
      (   Cmd == end_of_file -> halt
      ;   Cmd = run(File) -> run_file(File), fail
      ;   halt(2)
      ).

run_file(File) :-
    catch(run_file_(File), E, (write('X '), print_error(E))),
    % unload_file/1 alone can leave clauses of predicates that were called: abolish them
    forall(source_file(M:H, File), (functor(H, N, A), abolish(M:N/A))),
    unload_file(File),
    write('END'), nl, flush_output.

run_file_(File) :-
    load_files(File, [silent(true)]),
    forall(catch(query(Id, G, Names, Vs), _, fail), run_query(Id, G, Names, Vs)).

run_query(Id, G, _Names, Vs) :-
    format("Q ~w~n", [Id]),
    copy_term(G, G2),
    catch(call_with_time_limit(20,
            ( call_with_inference_limit(forall(limit(MAX_ANSWERS1, G), print_answer(Vs)),
                                        SWI_LIMIT, R),
              ( R == inference_limit_exceeded -> write('L'), nl ; true ) )),
          E, print_error(E)),
    occurs_check_pass(G2),
    write('D'), nl.

occurs_check_pass(G) :-
    set_prolog_flag(occurs_check, error),
    catch(call_with_time_limit(1, call_with_inference_limit(forall(limit(MAX_ANSWERS1, G), true),
                                                   SWI_LIMIT, _)),
          E, true),
    set_prolog_flag(occurs_check, false),
    (   nonvar(E), ( E = error(occurs_check(_, _), _) ; E == time_limit_exceeded )
    ->  write('C'), nl
    ;   true
    ).

print_answer(Vs) :- \+ acyclic_term(Vs), !, write('C'), nl.
print_answer(Vs) :-   % a whole line or nothing, should a limit strike while it is built
    copy_term(Vs, Vs1),   % variables numbered by first occurrence: '$VAR'(I) (linear time)
    numbervars(Vs1, 0, _, [singletons(false)]),
    with_output_to(string(S), (write('A ['), ser_args(Vs1, numbered), write(']'))),
    write(S), nl.

print_error(time_limit_exceeded) :- !, write('L'), nl.
print_error(E) :- \+ acyclic_term(E), !, write('C'), nl.
print_error(error(F, _)) :- !, write('E '), strip_module_pi(F, F1),
    term_variables(F1, All), ser(F1, All), nl.
print_error(Ball) :- write('E '), term_variables(Ball, All), ser(Ball, All), nl.

strip_module_pi(existence_error(procedure, _:PI), existence_error(procedure, PI)) :- !.
strip_module_pi(F, F).

ser(T, Vs) :- var(T), !, ( var_index(Vs, T, 0, I) -> true ; I = -1 ), format('{"v":~d}', [I]).
ser('$VAR'(I), numbered) :- integer(I), !, format('{"v":~d}', [I]).
ser(T, _) :- integer(T), !, format('{"i":"~d"}', [T]).
ser(T, _) :- float(T), !, float_class(T, C),
    (   C == nan -> write('{"f":"nan"}')
    ;   C == infinite -> ( T > 0 -> write('{"f":"inf"}') ; write('{"f":"-inf"}') )
    ;   format('{"f":"~w"}', [T])
    ).
ser(T, _) :- T == [], !, write('{"l":[]}').
ser(T, Vs) :- is_list(T), !, write('{"l":['), ser_args(T, Vs), write(']}').
ser(T, Vs) :- T = [_|_], !, spine(T, Items, Tail),     % a partial list, flat
    write('{"pl":['), ser_args(Items, Vs), write('],"tail":'), ser(Tail, Vs), write('}').

ser(T, _) :- atom(T), !, atom_codes(T, Cs), format('{"a":~w}', [Cs]).
ser(T, _) :- string(T), !, string_codes(T, Cs), format('{"s":~w}', [Cs]).
ser(T, Vs) :- compound(T), !, compound_name_arguments(T, N, As),
    ( N == '[|]', As = [_, _] -> N1 = '.' ; N1 = N ), atom_codes(N1, Cs),
    format('{"c":~w,"args":[', [Cs]), ser_args(As, Vs), write(']}').
ser(T, _) :- format('{"a":"unknown ~q"}', [T]).

spine(T, [X|Xs], Tail) :- nonvar(T), T = [X|T1], !, spine(T1, Xs, Tail).
spine(T, [], T).

ser_args([], _).
ser_args([X], Vs) :- !, ser(X, Vs).
ser_args([X|Xs], Vs) :- ser(X, Vs), write(','), ser_args(Xs, Vs).

var_index([V|_], T, I, I) :- V == T, !.
var_index([_|Vs], T, I0, I) :- I1 is I0 + 1, var_index(Vs, T, I1, I).

:- initialization(serve, main).
""".replace("SWI_LIMIT", str(SWI_INFERENCE_LIMIT)).replace("MAX_ANSWERS1", str(MAX_ANSWERS + 1))


class Swipl:
    """One SWI-Prolog process that runs example files on request."""

    def __init__(self, workdir: Path):
        exe = shutil.which("swipl")
        if exe is None:
            pytest.fail("swipl (SWI-Prolog) is not installed: the differential test needs it "
                        "(apt-get install swi-prolog-nox)")
        self.exe = exe
        self.workdir = workdir
        self.driver = workdir / "driver.pl"
        self.driver.write_text(DRIVER)
        self.counter = 0
        self.proc: subprocess.Popen | None = None

    def _start(self) -> None:
        self.stderr = open(self.workdir / "swipl.stderr", "ab")
        self.proc = subprocess.Popen([self.exe, f"--stack-limit={SWI_STACK_LIMIT}", "-q",
                                      str(self.driver)],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=self.stderr, text=True, cwd=str(self.workdir))

    def run(self, program: str) -> dict[int, dict]:
        """Consult ``program`` (which defines query/4) and return {id: {answers, error, limit}}."""
        if self.proc is None or self.proc.poll() is not None:
            self._start()
        self.counter += 1
        path = self.workdir / f"ex{self.counter}.pl"
        path.write_text(program)
        assert self.proc and self.proc.stdin and self.proc.stdout
        self.proc.stdin.write(f"run({json.dumps(str(path))}).\n".replace('"', "'"))
        self.proc.stdin.flush()
        try:
            results = self._read(path, program)
        except BaseException:
            # never leave the protocol out of step: start a new process for the next example
            self.proc.kill()
            self.proc.wait()
            self.proc = None
            raise
        path.unlink()
        return results

    def _read(self, path: Path, program: str) -> dict[int, dict]:
        results: dict[int, dict] = {}
        current = None
        while True:
            line = self.proc.stdout.readline()
            if not line:
                raise AssertionError(f"swipl died on {path}:\n{program}")
            line = line.rstrip("\n")
            if line == "END":
                return results
            tag, _, rest = line.partition(" ")
            if tag in ("A", "E"):
                try:
                    value = json.loads(rest)
                except ValueError:
                    raise AssertionError(f"bad output from swipl: {line!r}\n{program}") from None
            if tag == "Q":
                current = results[int(rest)] = {"answers": [], "error": None, "limit": False,
                                                 "cyclic": False}
            elif tag == "A":
                current["answers"].append(value)
            elif tag == "E":
                current["error"] = value
            elif tag == "L":
                current["limit"] = True
            elif tag == "C":
                current["cyclic"] = True
            elif tag == "D":
                current = None
            elif tag == "X":
                raise AssertionError(f"swipl could not run the program: {rest}\n{program}")
            else:
                raise AssertionError(f"unexpected output from swipl: {line!r}\n{program}")

    def close(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.stdin.close()
            self.proc.wait(timeout=10)
        if self.proc is not None:
            self.stderr.close()


class CorpusOracle:
    """Stands in for :class:`Swipl` on a machine without SWI-Prolog: the committed answers
    of the corpus examples, looked up by program text."""

    def __init__(self, corpus: list[dict]):
        self.results = {e["swi_program"]: e["swi"] for e in corpus}

    def run(self, program: str) -> dict[int, dict]:
        return self.results[program]


def load_corpus() -> list[dict]:
    """The committed examples: dicts with program, events, swi_program, queries and swi
    (SWI-Prolog's results per query number). Empty while the file is being generated
    (test_the_corpus_is_a_real_sample fails then)."""
    if not CORPUS_PATH.exists():
        return []
    data = json.loads(CORPUS_PATH.read_text(encoding="utf-8"))
    for entry in data["examples"]:
        entry["events"] = [tuple(e) for e in entry["events"]]
        entry["queries"] = [tuple(q) for q in entry["queries"]]
        entry["swi"] = {int(k): v for k, v in entry["swi"].items()}
    return data["examples"]


CORPUS = load_corpus()


def corpus_example(entry: dict) -> tuple:
    return entry["program"], entry["events"], entry["swi_program"], entry["queries"]


@contextlib.contextmanager
def live_swipl():
    """A live SWI-Prolog for a module's tests: a failure that says how to install it where
    it is not (the modules that need a live one have no committed answers to fall back on)."""
    if not HAVE_SWIPL:
        pytest.fail("swipl (SWI-Prolog) is not installed: this differential test needs it "
                    "(apt-get install swi-prolog-nox)")
    with tempfile.TemporaryDirectory(prefix="slr_swi_") as d:
        s = Swipl(Path(d))
        try:
            yield s
        finally:
            s.close()


@pytest.fixture(scope="module")
def swipl():
    """A live SWI-Prolog, or the committed answers where it is not installed."""
    if not HAVE_SWIPL:
        yield CorpusOracle(CORPUS)
        return
    with live_swipl() as s:
        yield s


# ---------------------------------------------------------------------------------------------
# Canonical answers: both sides become nested tuples with variables numbered by first occurrence
# ---------------------------------------------------------------------------------------------

def _codes(cs: list) -> str:
    return "".join(map(chr, cs))


def from_swi(j: dict, varmap: dict) -> tuple:
    """The JSON that the driver prints -> canonical tuple (variables renumbered via varmap)."""
    if "v" in j:
        return ("v", varmap.setdefault(("swi", j["v"]), len(varmap)))
    if "i" in j:
        return ("i", int_from_text(j["i"]))   # (int() stops at 4,300 digits)
    if "f" in j:
        return ("f", repr(float(j["f"])))
    if "l" in j:
        return ("l", tuple(from_swi(x, varmap) for x in j["l"]))
    if "pl" in j:
        return ("pl", tuple(from_swi(x, varmap) for x in j["pl"]), from_swi(j["tail"], varmap))
    if "a" in j:
        return ("a", written_vars(_codes(j["a"]), "swi", varmap))
    if "s" in j:
        return ("s", written_vars(_codes(j["s"]), "swi", varmap))
    return ("c", _codes(j["c"]), tuple(from_swi(x, varmap) for x in j["args"]))


# a variable written by write/1, format/2, term_to_atom/2: '_' and a number of its own
WRITTEN_VAR = re.compile(r"(?<![A-Za-z0-9_])_[0-9]+(?![A-Za-z0-9_])")


def written_vars(text: str, side: str, varmap: dict) -> str:
    """``text`` with each written variable (``_123``) numbered by its first occurrence in
    the answer, shared with the answer's variables' numbering (``varmap``): the numbers
    SWI-Prolog and slr_sql give a variable are their own."""
    return WRITTEN_VAR.sub(
        lambda m: f"_V{varmap.setdefault((side, 'written', m.group()), len(varmap))}", text)


def from_slr(v, varmap: dict) -> tuple:
    """A value as kb.query returns it (docs/api.md) -> canonical tuple."""
    if type(v) is Var:
        return ("v", varmap.setdefault(("slr", id(v)), len(varmap)))
    if type(v) is bool:
        raise AssertionError(f"bool in an answer: {v!r}")
    if type(v) is int:
        return ("i", v)
    if type(v) is float:
        return ("f", repr(v))
    if type(v) is list:
        return ("l", tuple(from_slr(x, varmap) for x in v))
    if type(v) is Atom:
        # (the empty list comes back as [], never as an atom)
        return ("a", written_vars(str(v), "slr", varmap))
    if type(v) is str:
        return ("s", written_vars(v, "slr", varmap))
    if type(v) is Struct:
        if v.name == "." and len(v.args) == 2:  # a partial list, flat
            items = []
            while type(v) is Struct and v.name == "." and len(v.args) == 2:
                items.append(from_slr(v.args[0], varmap))
                v = v.args[1]
            return ("pl", tuple(items), from_slr(v, varmap))
        return ("c", str(v.name), tuple(from_slr(x, varmap) for x in v.args))
    raise AssertionError(f"unexpected value in an answer: {v!r} ({type(v).__name__})")


def swi_answer(values: list, names: list[str]) -> dict:
    """Named bindings as SLR's answers show them: a variable left unbound is omitted unless
    it is shared with another named variable (SWI's toplevel rule, answers.answer_bindings)."""
    top = [v["v"] for v in values if "v" in v]
    kept = [(n, v) for n, v in zip(names, values) if not ("v" in v and top.count(v["v"]) < 2)]
    varmap: dict = {}
    return {n: from_swi(v, varmap) for n, v in kept}


def slr_answer(answer: dict, names: list[str]) -> dict:
    varmap: dict = {}
    return {n: from_slr(answer[n], varmap) for n in names if n in answer}


def canonical_error(term) -> tuple:
    """The formal part of an ISO error term (or the whole ball of a non-error throw)."""
    if type(term) is Struct and term.name == "error" and len(term.args) == 2:
        term = term.args[0]
    return from_slr(slr_sql.terms.to_python(term), {})


# ---------------------------------------------------------------------------------------------
# Program generator
# ---------------------------------------------------------------------------------------------

ATOMS = ["a", "b", "c"]
INTS = [0, 1, 2, 3]
FLOATS = [0.5, 1.5, 2.0, 0.0, -0.0]  # -0.0 and 0.0: equal numbers, two terms
STRINGS = ['"s"']
TIMES = [1.0, 2.0, 3.0]
# times written in goals: floats, and integers, which match the stored float times by value
TIME_TEXTS = ["1.0", "2.0", "3.0", "1", "2", "3"]
CMP_OPS = ["=:=", "=\\=", "<", ">", "=<", ">="]
ARITH_OPS = ["+", "-", "*", "/", "//", "mod", "max", "min"]
TERM_TESTS = ["==", "\\==", "@<", "@>=", "=", "\\="]
TYPE_TESTS = ["number", "integer", "float", "var", "nonvar", "atomic", "compound", "is_list"]


class Gen:
    """Draws the pieces of one program; ``clause_vars`` are the variables of the clause being
    built (the head's first, so that bodies join on them)."""

    def __init__(self, draw):
        self.draw = draw
        self.vars = ["X", "Y", "Z", "W"]
        self.preds: list[tuple[str, int]] = []  # callable user predicates (name, arity)
        self.counter = 0

    def fresh(self, prefix: str) -> str:
        self.counter += 1
        return f"{prefix}{self.counter}"

    def pick(self, xs):
        return self.draw(sampled(xs))

    def chance(self, p: float) -> bool:
        return self.draw(integers(0, 99)) < int(p * 100)

    def constant(self) -> str:
        kind = self.draw(integers(0, 9))
        if kind < 4:
            return self.pick(ATOMS)
        if kind < 8:
            return str(self.pick(INTS))
        if kind < 9:
            return repr(self.pick(FLOATS))
        return self.pick(STRINGS)

    def var(self) -> str:
        return self.pick(self.vars)

    def term(self, depth: int = 0) -> str:
        kind = self.draw(integers(0, 9))
        if kind < 5:
            return self.var()
        if kind < 8 or depth > 0:
            return self.constant()
        if kind < 9:
            return f"f({self.term(depth + 1)}, {self.term(depth + 1)})"
        return self.list_term(depth + 1)

    def list_term(self, depth: int = 1) -> str:
        items = [self.term(depth) for _ in range(self.draw(integers(0, 3)))]
        if items and self.chance(0.15):
            return f"[{', '.join(items)}|{self.var()}]"
        return f"[{', '.join(items)}]"

    def expr(self, depth: int = 0) -> str:
        kind = self.draw(integers(0, 9))
        if depth >= 2 or kind < 3:
            return str(self.pick(INTS + [5, 7]))
        if kind < 4:
            return repr(self.pick(FLOATS))
        if kind < 6:
            return self.var()
        op = self.pick(ARITH_OPS)
        a, b = self.expr(depth + 1), self.expr(depth + 1)
        if op in ("max", "min"):
            return f"{op}({a}, {b})"
        return f"({a} {op} {b})"

    def call_pred(self) -> tuple:
        name, arity = self.pick(self.preds)
        if name == "ev":
            stamp = self.draw(integers(0, 3))
            if stamp == 0:
                t = f"[{self.var()}, {self.var()}]"
            elif stamp == 1:
                t = self.var()
            elif stamp == 2:
                t = f"[{self.pick(TIME_TEXTS)}, {self.var()}]"
            else:
                t = self.pick(TIME_TEXTS)
            return ("ev", (self.term(), self.term()), t)
        return ("lit", name, tuple(self.term() for _ in range(arity)))

    def leaf(self) -> tuple:
        kind = self.draw(integers(0, 19))
        if kind < 7 and self.preds:
            return self.call_pred()
        if kind < 8:
            return ("raw", "!")
        if kind < 9:
            return ("raw", self.pick(["true", "fail"]))
        if kind < 11:
            op = self.pick(TERM_TESTS)
            if op.startswith("@"):
                # the standard order of two unbound variables is implementation-defined (SWI:
                # by age): one side atomic keeps var-to-var comparisons out
                return ("raw", f"{self.term()} {op} {self.constant()}")
            return ("raw", f"{self.term()} {op} {self.term()}")
        if kind < 13:
            return ("raw", f"{self.var()} is {self.expr()}")
        if kind < 14:
            return ("raw", f"{self.expr()} {self.pick(CMP_OPS)} {self.expr()}")
        if kind < 15:
            return ("raw", f"{self.pick(TYPE_TESTS)}({self.term()})")
        if kind < 16:
            return ("raw", f"member({self.term()}, {self.list_term()})")
        if kind < 17:
            return ("raw", f"append({self.pick([self.var(), self.list_term()])}, "
                           f"{self.pick([self.var(), self.list_term()])}, "
                           f"{self.pick([self.var(), self.list_term()])})")
        if kind < 18:
            lo = self.pick(["0", "1", self.var()])
            return ("raw", f"between({lo}, {self.pick(['2', '3'])}, {self.var()})")
        if kind < 19:
            return ("raw", f"length({self.list_term()}, {self.var()})")
        return ("lit", "undefined_pred", (self.var(),))

    def goal(self, depth: int = 0) -> tuple:
        if depth >= 3:
            return self.leaf()
        kind = self.draw(integers(0, 24))
        if kind < 11:
            return self.leaf()
        if kind < 14:
            return ("conj", [self.goal(depth + 1) for _ in range(self.draw(integers(2, 3)))])
        if kind < 15:
            return ("not", self.goal(depth + 1))
        if kind < 17:
            return ("ite", self.goal(depth + 1), self.goal(depth + 1), self.goal(depth + 1))
        if kind < 18:
            return ("ift", self.goal(depth + 1), self.goal(depth + 1))
        if kind < 19:
            return ("soft", self.goal(depth + 1), self.goal(depth + 1), self.goal(depth + 1))
        if kind < 20:
            return ("or", self.goal(depth + 1), self.goal(depth + 1))
        if kind < 22:
            return ("findall", self.term(), self.goal(depth + 1), self.var())
        if kind < 23:
            return ("call", self.goal(depth + 1)) if self.chance(0.6) else \
                ("vcall", self.goal(depth + 1), self.fresh("G"))
        if kind < 24:
            return ("count", self.goal(depth + 1), self.var())
        return ("forall", self.goal(depth + 1), self.goal(depth + 1))

    def body(self) -> tuple:
        return ("conj", [self.goal() for _ in range(self.draw(integers(1, 3)))])


def render(g: tuple, swi: bool) -> str:
    """Goal AST -> text; ``swi`` writes event atoms as ev(A, B, Start, End)."""
    k = g[0]
    if k == "raw":
        return g[1]
    if k == "lit":
        return f"{g[1]}({', '.join(g[2])})" if g[2] else g[1]
    if k == "ev":
        a, b = g[1]
        if not swi:
            return f"ev({a}, {b})^{g[2]}"
        t = g[2]
        if t.startswith("["):
            s, e = t[1:-1].split(", ")
        else:
            s = e = t
        return f"ev({a}, {b}, {s}, {e})"
    if k == "conj":
        return "(" + ", ".join(render(x, swi) for x in g[1]) + ")"
    if k == "not":
        return f"\\+ {render(g[1], swi)}"
    if k == "ite":
        return f"({render(g[1], swi)} -> {render(g[2], swi)} ; {render(g[3], swi)})"
    if k == "ift":
        return f"({render(g[1], swi)} -> {render(g[2], swi)})"
    if k == "soft":
        return f"({render(g[1], swi)} *-> {render(g[2], swi)} ; {render(g[3], swi)})"
    if k == "or":
        return f"({render(g[1], swi)} ; {render(g[2], swi)})"
    if k == "findall":
        return f"findall({g[1]}, {render(g[2], swi)}, {g[3]})"
    if k == "call":
        return f"call({render(g[1], swi)})"
    if k == "vcall":  # a variable goal is call/1: a cut inside is local
        return f"({g[2]} = ({render(g[1], swi)}), {g[2]})"
    if k == "count":
        return f"aggregate_all(count, {render(g[1], swi)}, {g[2]})"
    if k == "forall":
        return f"forall({render(g[1], swi)}, {render(g[2], swi)})"
    raise AssertionError(g)


def query_of(goal: tuple) -> tuple[str, str, list[str]]:
    """A query's text for slr_sql and for SWI-Prolog, and the variables whose bindings are
    compared: all but those :func:`goals_written_apart` gives."""
    q_slr, q_swi = render(goal, False), render(goal, True)
    return q_slr, q_swi, [n for n in var_names(q_slr) if n not in goals_written_apart(goal)]


def goals_written_apart(g: tuple) -> set[str]:
    """The variables of ``g`` bound to a goal (``G = (Goal), G``) whose goal holds an event
    goal: the goal is a term in the answer, and the two programs write an event goal apart
    (``ev(A, B)^T``, ``ev(A, B, T, T)``), so the binding is not compared; its goal's
    answers are."""
    found: set[str] = set()
    todo = [g]
    while todo:
        node = todo.pop()
        if node[0] == "vcall" and render(node[1], False) != render(node[1], True):
            found.add(node[2])
        todo.extend(node[1] if node[0] == "conj" else
                    [node[k] for k in _SUBGOALS.get(node[0], ())])
    return found


# where a goal of the AST holds its sub-goals (conj: the list in node[1])
_SUBGOALS = {"not": (1,), "call": (1,), "vcall": (1,), "count": (1,), "ite": (1, 2, 3),
             "soft": (1, 2, 3), "ift": (1, 2), "or": (1, 2), "forall": (1, 2), "findall": (2,)}


VAR_RE = re.compile(r"\b[A-Z][A-Za-z0-9_]*")


def var_names(text: str) -> list[str]:
    """Named variables of generated text, in order of first occurrence (no quoted atoms
    with capitals are generated, strings are lower case)."""
    out: list[str] = []
    for v in VAR_RE.findall(text):
        if v not in out:
            out.append(v)
    return out


@st.composite
def examples(draw):
    g = Gen(draw)
    slr: list[str] = []
    swi: list[str] = []
    # facts
    for name, arity in (("fa", 1), ("fb", 2)):
        n = draw(integers(1, 4))
        for _ in range(n):
            fact = f"{name}({', '.join(g.constant() for _ in range(arity))})."
            slr.append(fact)
            swi.append(fact)
        g.preds.append((name, arity))
    # events, as SWI facts in store order (end, start, arrival) before the temporal rules.
    # SLR matches a stored event's times by value (SPEC §2, "Times match by value": the
    # goal ev(..)^2 finds an event stored at 2.0), where SWI would not unify 2 with 2.0; the
    # SPEC wins, so the oracle models it: the facts are ev_stored/4 with float times, and
    # the first clause of ev/4 matches a goal's times against them by value ('$tm'/2: an
    # unbound time is bound to the stored float, a number compares with =:=, anything else
    # fails) after unifying the data arguments, as slr_sql does. The temporal rules follow
    # as further clauses of ev/4, unified as Prolog clauses (only stored times go by value).
    events = []
    for _ in range(draw(integers(0, 4))):
        s = g.pick(TIMES)
        e = g.pick([t for t in TIMES if t >= s])
        events.append((g.constant(), g.constant(), s, e))
    order = sorted(range(len(events)), key=lambda i: (events[i][3], events[i][2], i))
    swi.append(":- dynamic(ev_stored/4).")  # no events and no rules: an event goal fails
    for i in order:
        a, b, s, e = events[i]
        swi.append(f"ev_stored({a}, {b}, {s!r}, {e!r}).")
    swi.append("'$tm'(T, T0) :- var(T), !, T = T0.")
    swi.append("'$tm'(T, T0) :- number(T), T =:= T0.")
    swi.append("ev(A, B, S, E) :- ev_stored(A, B, S0, E0), '$tm'(S, S0), '$tm'(E, E0).")
    g.preds.append(("ev", 2))
    if draw(BOOLEANS):
        # a temporal rule: answers after the stored events
        head_args = (g.var(), g.var())
        stamp = g.pick(["T", "[S, T]"])
        body = g.body()
        text_slr = f"ev({head_args[0]}, {head_args[1]})^{stamp} :- {render(body, False)}."
        s_, e_ = ("T", "T") if stamp == "T" else ("S", "T")
        text_swi = f"ev({head_args[0]}, {head_args[1]}, {s_}, {e_}) :- {render(body, True)}."
        slr.append(text_slr)
        swi.append(text_swi)
    # stratified rules r1, r2, r3: each calls only earlier predicates
    for i in range(1, draw(integers(1, 3)) + 1):
        arity = draw(integers(1, 2))
        for _ in range(draw(integers(1, 3))):
            head = f"r{i}({', '.join(g.term() if g.chance(0.3) else g.var() for _ in range(arity))})"
            body = g.body()
            slr.append(f"{head} :- {render(body, False)}.")
            swi.append(f"{head} :- {render(body, True)}.")
        g.preds.append((f"r{i}", arity))
    # queries
    queries = []
    for qi in range(draw(integers(1, 3))):
        if draw(integers(0, 2)) == 0:
            goal = ("conj", [g.goal(1) for _ in range(draw(integers(1, 2)))])
        else:
            goal = g.call_pred() if draw(integers(0, 3)) else g.goal(0)
        q_slr, q_swi, names = query_of(goal)
        queries.append((q_slr, q_swi, names))
        swi.append(f"query({qi}, {q_swi}, [{', '.join(repr(n) for n in names)}], "
                   f"[{', '.join(names)}]).")
    return "\n".join(slr) + "\n", events, "\n".join(swi) + "\n", queries


# The classic atom builtins and SWI-7's lists, every mode and error, one query each (in the
# corpus as one example each). Left out, with the reason: atom('[]') (slr_sql reads '[]' as
# the empty list, which SWI-7 tells apart), term_to_atom/2 of a term with variables (the
# names SWI makes up, _123), and the wording inside syntax_error(...).
BUILTIN_GOALS = [
    'atom_concat(a, b, X)', 'atom_concat(X, b, ab)', 'atom_concat(a, X, ab)',
    'atom_concat(X, Y, ab)', 'atom_concat(a, b, ab)', 'atom_concat(a, b, ba)',
    'atom_concat(1, 2, X)', 'atom_concat(a, 1.5, X)', 'atom_concat("s", b, X)',
    'atom_concat([a], b, X)', 'atom_concat(a, [b], a1)', 'atom_concat(X, [b], ab)',
    'atom_concat([], a, X)', 'atom_concat(X, Y, [a])', 'atom_concat(f(x), b, X)',
    'atom_concat(X, b, f(x))', 'atom_concat(X, Y, Z)', 'atom_concat(a, Y, Z)',
    'atom_concat(X, Y, 12)', 'atom([])', 'atomic([])', 'atom(a)', 'atom("s")', 'atom(1)',
    '[a] =.. L', '[a, b] =.. L', "X =.. ['[|]', a, []]", 'functor([a], N, A)',
    "functor(X, '[|]', 2)", 'X =.. [foo, a]', 'f(a, b) =.. L', 'a =.. L', 'X =.. [1]',
    'X =.. [f(a), b]', 'name(X, "12")', 'name(X, "ab")', 'name(ab, X)', 'name(12, X)',
    'name(1.5, X)', 'name(X, [])', 'name(X, Y)', 'name(f(x), Y)', 'name(X, "-12")',
    'name(X, " 12")', "name(X, [0'a|_])", 'name("s", X)', 'atom_codes(ab, X)',
    'atom_codes(X, "ab")', "atom_codes(X, [0'a, 0'b])", 'atom_codes(12, X)', 'atom_codes(X, Y)',
    'atom_codes(f(x), Y)', 'atom_codes(X, [a|_])', "atom_codes(ab, [0'a|T])", 'atom_codes([], C)',
    'atom_codes(X, [-1])', 'atom_codes(X, foo)', 'atom_chars(ab, X)', 'atom_chars(X, [a, b])',
    'atom_chars(12, X)', 'atom_chars(X, Y)', 'atom_chars(X, [a|_])', 'atom_chars(ab, [a|T])',
    'atom_chars(X, [ab])', 'atom_chars(X, [1])', 'atom_chars(1.5, L)', "atom_chars(X, ['1', '2'])",
    'char_code(a, X)', 'char_code(X, 98)', 'char_code(X, Y)', 'char_code(ab, X)', 'char_code(X, a)',
    'char_code(1, X)', 'char_code(a, 97)', 'char_code(X, -1)', 'atom_length(abc, L)',
    'atom_length(12, L)', "atom_length('', L)", 'atom_length(X, L)', 'atom_length(abc, foo)',
    'atom_length(abc, -1)', 'atom_length(f(x), L)', 'atom_length("str", L)', 'atom_length([], L)',
    'atom_length(abc, 3)', 'atom_length(1.5, L)', 'sub_atom(abc, B, 2, A, S)',
    'sub_atom(abc, B, L, A, S)', 'sub_atom(abc, 1, L, A, S)', 'sub_atom(abcab, B, L, A, ab)',
    'sub_atom(abc, B, L, 0, S)', 'sub_atom(abc, 4, L, A, S)', 'sub_atom(X, B, L, A, S)',
    'sub_atom(f(x), B, L, A, S)', 'sub_atom(abc, a, L, A, S)', 'sub_atom(abc, B, L, A, f(x))',
    'sub_atom(abc, 0, 1, A, S)', 'sub_atom(12, B, 1, A, S)', 'sub_atom(abc, B, -1, A, S)',
    'number_codes(12, X)', 'number_codes(X, "12")', 'number_codes(X, "1.5")',
    'number_codes(X, "a")', 'number_codes(X, Y)', 'number_codes(a, X)', 'number_codes(X, " 12")',
    'number_codes(X, "0x1A")', 'number_codes(X, "-3")', "number_codes(X, [0'1|_])",
    "atom_number('12', X)", "atom_number('1.5', X)", 'atom_number(abc, X)', 'atom_number(X, 12)',
    'atom_number(X, Y)', "atom_number('12', 12)", 'atom_number(12, X)', "atom_number('-7', X)",
    "atom_number(' 3', X)", "atom_number('0b101', X)", 'atom_number(X, a)', "atom_number('3 ', X)",
    'upcase_atom(abc, X)', "upcase_atom('aB1', X)", "upcase_atom(X, 'ABC')", 'upcase_atom(12, X)',
    'upcase_atom(f(x), X)', "upcase_atom(abc, 'ABC')", 'upcase_atom("s", X)',
    "term_to_atom(T, 'foo(a, [1,2])')", "term_to_atom(f(a), 'f(a)')", 'term_to_atom(1+2*3, A)',
    "term_to_atom(T, '- 1')", 'term_to_atom(- (1), A)', 'term_to_atom(a- -1, A)',
    'term_to_atom(T, 12)', 'term_to_atom([a|b], A)', 'number_codes(X, "12 ")',
    'number_codes(X, "\\n12")', 'name(X, "12 ")', 'atom_number(X, "12")', 'atom_number("12", X)',
    "downcase_atom('AbC', X)", 'downcase_atom(X, y)', 'atom_concat(a, [], X)',
    'atom_concat(X, Y, [])', 'name([], X)', 'atom_chars([], X)', 'upcase_atom([], X)',
    'sub_atom([], B, L, A, S)', 'atom_number([], X)', 'number_codes(X, [])', 'atom_codes(X, [])',
    'atom_chars(X, [])', 'char_code([], X)', 'atom_length(X, 3)', "atom_codes(X, [0'a|foo])",
    'atom_chars(X, [a|foo])', 'atom_codes(X, [a])', 'atom_codes(X, ["a"])', "atom_chars(X, [0'a])",
    'atom_codes(X, [f(x)])', 'name(X, [a])', 'name(X, foo)', 'number_codes(X, foo)',
    'atom_number(a, 3)', 'atom_number(A, 1.5)', 'atom_number(f(x), Y)', 'upcase_atom(abc, f(x))',
    'upcase_atom(abc, "ABC")', 'sub_atom(abc, B, L, A, "b")', 'sub_atom("abc", B, 1, 0, S)',
    'atom_length(abc, 1.5)', 'char_code(X, 1114112)', 'atom_codes(X, [1114112])',
    'number_codes(X, "1e10")', 'number_codes(X, "12a")', "atom_number('1e10', X)",
    'atom_number(inf, X)', "atom_number('0''a', X)", 'name(X, "1.0e3")', 'number_codes(X, "- 3")',
    'number_codes(X, "+3")', "atom_number('+3', X)", "atom_number('-', X)", 'name(X, "0x1A")',
    'name(X, "+3")', 'term_to_atom(f(x), "f(x)")', 'term_to_atom(T, "f(x)")',
    'term_to_atom(T, f(x))', "atom_chars(X, ['1'|T])", 'sub_atom(abc, B, L, A, abcd)',
    'sub_atom(abc, 1, 1, 1, S)', 'sub_atom(abc, B, 1, 1, S)', 'sub_atom(abc, B, 4, A, S)',
    'sub_atom(abc, B, L, 1, S)', 'sub_atom(abc, 1, L, 1, S)', "upcase_atom('äb', X)",
    "atom_length('äb', L)", 'atom_codes(X, "äb")', "T = '[|]'(a, []), is_list(T)",
    'X = [a|b], X =.. [F|Args]', "functor(T, '[|]', 2), T = [a]", "functor(T, '[|]', 3)",
    "X =.. ['[|]', a]",
]
_QUOTED = re.compile(r"'[^']*'|\"[^\"]*\"|0'.")


def builtin_example(goal: str) -> tuple:
    """One BUILTIN_GOALS query as an example (no program, no events)."""
    names = var_names(_QUOTED.sub("", goal))
    swi = (f"query(0, ({goal}), [{', '.join(repr(n) for n in names)}], "
           f"[{', '.join(names)}]).\n")
    return "", [], swi, [(goal, goal, names)]


class Hang(BaseException):
    """Not an Exception: a broad ``except Exception`` in the code under test must not swallow
    it, and hypothesis reports it at once instead of shrinking through more hangs."""


@contextlib.contextmanager
def watchdog(seconds: float, what: str):
    """Turn a hang (a loop that max_steps cannot stop, e.g. in the loader) into a failure."""
    def fire(signum, frame):
        if frame is not None and frame.f_code.co_name == "gc_callback":
            # an exception raised in a gc callback would be swallowed: try again soon
            signal.setitimer(signal.ITIMER_REAL, 0.01)
            return
        raise Hang(f"slr_sql did not return within {seconds} s: {what}")
    old = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def a_(text: str):
    """A generated constant as the Python value add_many takes."""
    if text.startswith('"'):
        return slr_sql.String(text[1:-1])
    if text[0].isdigit() or (text[0] == "-" and text[1:2].isdigit()):
        return float(text) if "." in text else int(text)
    return text


DISCARDED = "discarded"


def check_example(example: tuple, swi: dict[int, dict], where: str | None = None,
                  plans: list | None = None) -> str | None:
    """Run one example through slr_sql (a store at ``where``) and compare with SWI-Prolog's
    results ``swi``; ``plans`` gets each query's plan (a compiled one or the fallback).

    Returns DISCARDED for an example outside the comparison (a cyclic term, too many
    answers, no termination within the limits), else None; a difference fails.
    """
    program, events, swi_program, queries = example
    if any(r["cyclic"] for r in swi.values()):
        return DISCARDED
    # the events' times are small numbers, not the wall clock's: a ManualClock (the queries
    # are unsynchronized, so where it stands changes no answer)
    with slr_sql.open(where, clock=slr_sql.ManualClock(0.0)) as kb, watchdog(30, f"program:\n{program}queries: {queries}"):
        kb.load(program)
        if events:
            assert kb.add_many([("ev", [a_(a), a_(b)], s, e) for a, b, s, e in events]) == []
        for qi, (q, _, names) in enumerate(queries):
            theirs = swi[qi]
            if plans is not None:
                try:
                    plans.append(plan_for(kb, kb.plans.plan(q, ()), False))
                except slr_sql.errors.SLRError:
                    pass
            if len(theirs["answers"]) > MAX_ANSWERS:
                return DISCARDED
            try:
                ours = [slr_answer(a, names) for a in
                        kb.query(q, max_steps=SLR_MAX_STEPS, timeout=SLR_TIMEOUT,
                                 limit=MAX_ANSWERS + 1)]
                error = None
            except SLRTimeout:
                return DISCARDED  # does not terminate within the step limit
            except SLREvaluationError as exc:
                error = canonical_error(exc.term)
                ours = None
            context = f"\nprogram:\n{program}events: {events}\nquery: {q}\nswi program:\n{swi_program}"
            assert not theirs["limit"], f"SWI-Prolog ran out of inferences, slr_sql did not{context}"
            expected = [swi_answer(a, names) for a in theirs["answers"]]
            if theirs["error"] is not None:
                assert error == from_swi(theirs["error"], {}), \
                    f"errors differ: slr_sql {error}, SWI {theirs['error']}{context}"
                # the answers before the error are the same
                if expected:
                    prefix = [slr_answer(a, names) for a in
                              kb.query(q, max_steps=SLR_MAX_STEPS, limit=len(expected))]
                    assert prefix == expected, context
                with pytest.raises(SLREvaluationError):  # and no answer more before it
                    kb.query(q, max_steps=SLR_MAX_STEPS, limit=len(expected) + 1)
                # the compiled SQL plan (run without a step limit) raises the same error
                try:
                    fast = [slr_answer(a, names) for a in
                            kb.query(q, timeout=SLR_TIMEOUT, limit=MAX_ANSWERS + 1)]
                except SLREvaluationError as exc:
                    fast = canonical_error(exc.term)
                assert fast == error, f"compiled path differs: {fast}{context}\n{kb.explain(q)}"
            else:
                assert error is None, f"slr_sql raised {error}, SWI did not{context}"
                assert ours == expected, context
                # without a step limit kb.query runs the compiled SQL plan when the goal has
                # one, else the interpreter with compiled sub-goals: the same answers again
                fast = [slr_answer(a, names) for a in
                        kb.query(q, timeout=SLR_TIMEOUT, limit=MAX_ANSWERS + 1)]
                assert fast == expected, f"compiled path differs{context}\n{kb.explain(q)}"
    return None


# Fresh examples need a live SWI-Prolog; without one the committed examples stand in.
_EXAMPLES = examples() if HAVE_SWIPL else st.sampled_from([corpus_example(e) for e in CORPUS])


@settings(max_examples=200 if HAVE_SWIPL else 50, derandomize=True, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                 HealthCheck.data_too_large])
@given(_EXAMPLES)
def test_same_answers_as_swipl(swipl, example):
    assume(check_example(example, swipl.run(example[2])) is not DISCARDED)


def test_a_goal_held_in_a_variable_is_compared_where_both_programs_write_it_alike():
    """``G1 = (findall(X, ev(X, X)^[X, X], X)), G1``: SWI-Prolog's program holds
    ``ev(X, X, X, X)`` there, so G1's binding differs in text only and is not compared
    (X's is); a goal without an event goal is compared."""
    event_goal = ("findall", "X", ("ev", ("X", "X"), "[X, X]"), "X")
    assert query_of(("vcall", event_goal, "G1"))[2] == ["X"]
    assert query_of(("conj", [("not", ("vcall", ("lit", "fa", ["Y"]), "G2")),
                              ("call", ("vcall", event_goal, "G3"))]))[2] == ["G2", "Y", "X"]


CHUNK = 25  # corpus examples per test case: failures stay readable, the overhead small


@pytest.mark.parametrize("start", range(0, len(CORPUS), CHUNK))
def test_corpus_answers(swipl, start):
    """slr_sql gives SWI-Prolog's committed answers; a live SWI-Prolog (where installed)
    still gives exactly those answers, else the corpus is stale: regenerate it with
    ``python tests/golden/make_swi_corpus.py``."""
    entries = CORPUS[start:start + CHUNK]
    for entry in entries:
        if HAVE_SWIPL:
            assert swipl.run(entry["swi_program"]) == entry["swi"], (
                "SWI-Prolog no longer gives the committed answers (tests/golden/"
                f"swi_differential.json is stale: run tests/golden/make_swi_corpus.py):\n"
                f"{entry['swi_program']}")
        assert check_example(corpus_example(entry), entry["swi"]) is not DISCARDED, \
            "a committed example must be comparable"


def test_the_corpus_is_a_real_sample():
    """The committed examples exercise what the generator exercises: answers, errors and
    events (a corpus of trivial examples would replay nothing)."""
    assert len(CORPUS) >= 150 + len(BUILTIN_GOALS)
    replayed = {e["queries"][0][0] for e in CORPUS if not e["program"]}
    assert [g for g in BUILTIN_GOALS if g not in replayed] == []
    results = [r for e in CORPUS for r in e["swi"].values()]
    assert sum(bool(r["answers"]) for r in results) >= 100
    assert sum(r["error"] is not None for r in results) >= 10
    assert sum(bool(e["events"]) for e in CORPUS) >= 50
