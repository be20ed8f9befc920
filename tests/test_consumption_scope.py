"""A consumption directive governs the event rules of its own program (docs/events.md,
"Consumption policies"): ``:- consumption(Policy).`` in one named program never changes how
another program's rules pair events, whichever was loaded first, across unload, replace and
reopening the store; ``:- consumption(Head/N, Policy).`` naming a head that only other
programs define is refused, changing nothing. On a SQLite file and on PostgreSQL.
"""
from __future__ import annotations

import pytest
from test_cli import slr

import slr_sql
from slr_sql import ManualClock

DELAYS = ":- max_delay(a/1, 0).\n:- max_delay(b/1, 0).\n"
# two programs over the same events: 'pairs' has no directive (unrestricted), 'latest'
# pairs each b with the most recent a
PAIRS = DELAYS + "c(X) <- a(X) seq b(X).\n"
LATEST = ":- consumption(recent).\nd(X) <- a(X) seq b(X).\n"


def _intervals(kb, head: str) -> list[tuple[float, float]]:
    return sorted((a["S"], a["E"]) for a in kb.query(f"{head}(_)^[S, E]"))


def _policies(kb) -> dict[tuple[str, str], str]:
    return {(r["program"], r["head"]): r["policy"] for r in kb.event_rules()}


@pytest.mark.parametrize("latest_first", [False, True], ids=["pairs-first", "latest-first"])
def test_a_programs_default_policy_leaves_the_other_programs_rules_alone(backend, latest_first):
    clock = ManualClock(0.0)
    loads = [("pairs", PAIRS), ("latest", LATEST)]
    with slr_sql.open(backend, clock=clock) as kb:
        for name, text in (reversed(loads) if latest_first else loads):
            kb.load(text, name=name)
        assert _policies(kb) == {("pairs", "c/1"): "unrestricted",
                                 ("latest", "d/1"): "recent"}
        kb.add_many(["a(1)^1", "a(1)^2", "b(1)^3"])
        clock.set(10.0)
        assert _intervals(kb, "c") == [(1.0, 3.0), (2.0, 3.0)]
        assert _intervals(kb, "d") == [(2.0, 3.0)]
        assert "consumption policy unrestricted" in kb.explain("c(X) <- a(X) seq b(X)")
    # reopened: the rules are built again from the stored texts, each with its policy
    clock = ManualClock(10.0)
    with slr_sql.open(backend, clock=clock) as kb:
        assert _policies(kb) == {("pairs", "c/1"): "unrestricted",
                                 ("latest", "d/1"): "recent"}
        kb.add_many(["a(1)^11", "b(1)^12"])
        clock.set(20.0)
        assert _intervals(kb, "c") == [(1.0, 3.0), (1.0, 12.0), (2.0, 3.0), (2.0, 12.0),
                                       (11.0, 12.0)]
        assert _intervals(kb, "d") == [(2.0, 3.0), (11.0, 12.0)]


def test_replacing_and_unloading_a_program_keep_the_others_policies(backend):
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        kb.load(PAIRS, name="pairs")
        kb.load(LATEST, name="latest")
        kb.load(":- consumption(chronological).\nd(X) <- a(X) seq b(X).\n", name="latest",
                replace=True)
        assert _policies(kb) == {("pairs", "c/1"): "unrestricted",
                                 ("latest", "d/1"): "chronological"}
        kb.unload("pairs")
        kb.load(PAIRS, name="pairs")     # loaded again, after the program with a directive
        assert _policies(kb) == {("pairs", "c/1"): "unrestricted",
                                 ("latest", "d/1"): "chronological"}
        kb.unload("latest")
        assert _policies(kb) == {("pairs", "c/1"): "unrestricted"}


def test_a_directive_in_a_later_text_of_the_same_program_sets_its_earlier_rules(backend):
    # texts added to one name are one program (the shell's 'user' program is made so); the
    # same rule in another program keeps that program's policy, and is a rule of its own
    rule = "c(X) <- a(X) seq b(X).\n"
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        kb.load(DELAYS + rule, name="pairs")
        kb.load(rule, name="user")
        kb.load(":- consumption(recent).", name="user")
        assert sorted((r["program"], r["policy"]) for r in kb.event_rules()) == \
            [("pairs", "unrestricted"), ("user", "recent")]


@pytest.mark.parametrize("directives, r_policy, q_policy", [
    (":- consumption(r/0, recent).\n:- consumption(chronological).\n", "recent", "chronological"),
    (":- consumption(chronological).\n:- consumption(r/0, recent).\n", "recent", "chronological"),
    (":- consumption(recent).\n:- consumption(chronological).\n", "chronological",
     "chronological"),
    (":- consumption(r/0, recent).\n:- consumption(r/0, chronological).\n", "chronological",
     "unrestricted"),
], ids=["head-then-default", "default-then-head", "two-defaults", "two-heads"])
def test_a_head_directive_wins_over_the_programs_default_in_either_order(
        directives, r_policy, q_policy):
    """(docs/events.md) Of two directives of one kind the last is in force; a rule's own
    `Head/N` directive wins over the program's default wherever the two are written."""
    with slr_sql.open(clock=ManualClock(0.0)) as kb:
        kb.load(directives + "r <- a seq b.\nq <- a seq b.\n")
        assert _policies(kb) == {("main", "r/0"): r_policy, ("main", "q/0"): q_policy}


def test_a_head_directive_for_rules_only_another_program_has_is_refused(backend):
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        kb.load(PAIRS, name="pairs")
        before = (kb.programs(), _policies(kb))
        with pytest.raises(slr_sql.SLRError, match=r"consumption\(c/1, recent\): the event "
                                                   r"rules of c/1 are in the program 'pairs'"):
            kb.load(":- consumption(c/1, recent).\nd(X) <- a(X) seq b(X).\n", name="other")
        assert (kb.programs(), _policies(kb)) == before    # nothing changed
        # a program that defines the head too sets its own rules' policy only
        kb.load(":- consumption(c/1, recent).\nc(X) <- a(X) seq b(X) within 5.\n",
                name="other")
        assert {r["policy"] for r in kb.event_rules() if r["program"] == "pairs"} == \
            {"unrestricted"}
        assert {r["policy"] for r in kb.event_rules() if r["program"] == "other"} == \
            {"recent"}
        # a head no program defines yet waits for rules of its own program
        kb.load(":- consumption(e/1, chronological).", name="later")
        kb.load("e(X) <- a(X) seq b(X).", name="later")
        assert _policies(kb)[("later", "e/1")] == "chronological"
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:   # reopened: the same
        assert _policies(kb)[("later", "e/1")] == "chronological"
        assert {r["policy"] for r in kb.event_rules() if r["program"] == "pairs"} == \
            {"unrestricted"}


def test_a_waiting_head_directive_never_blocks_a_later_load_of_its_program(backend):
    """A head directive waiting for rules of its own program while another program then
    defined the head: every later load into the directive's program was refused, whatever
    its text (``p(1).`` here), for a directive written long before -- as in a store written
    before directives were scoped to their program. A text that gives such a directive
    itself is still refused."""
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        kb.load(":- consumption(c/1, recent).")          # no rules of c/1 yet: it waits
        kb.load(PAIRS, name="pairs")                      # another program defines c/1
        kb.load("p(1).")
        assert kb.query("p(X)") == [{"X": 1}]
        assert _policies(kb) == {("pairs", "c/1"): "unrestricted"}
        before = kb.programs()
        with pytest.raises(slr_sql.SLRError, match=r"consumption\(c/1, chronological\): "
                                                   r"the event rules of c/1 are in the "
                                                   r"program 'pairs'"):
            kb.load(":- consumption(c/1, chronological).")
        assert kb.programs() == before


def _scope_warnings(caught) -> list[str]:
    return [str(w.message) for w in caught
            if issubclass(w.category, slr_sql.loader.ConsumptionScopeWarning)]


def test_a_policy_that_sets_no_rule_is_warned_of_at_its_load_and_at_each_open(backend):
    """A program whose ``:- consumption(Policy).`` has no event rule of its own to set, while
    other programs hold rules, is warned of when it is loaded and when the store is opened
    (a store loaded before a directive governed its own program only holds such programs:
    the rules its directive set before pair events by their own policy now); a directive
    beside its program's rules, or waiting for rules while no program has any, is not."""
    with slr_sql.open(backend, clock=ManualClock(0.0)) as kb:
        with pytest.warns(slr_sql.loader.ConsumptionScopeWarning) as caught:
            kb.load(":- consumption(chronological).", name="early")   # no rule anywhere yet
            kb.load(LATEST, name="latest")
            kb.load(PAIRS, name="pairs")
            kb.load(":- consumption(recent).", name="policy")
        assert _scope_warnings(caught) == [
            ":- consumption(recent) in the program 'policy' sets the policy of no event rule: "
            "'policy' holds none, and a consumption directive sets the rules of its own "
            "program only (the event rules of 'latest', 'pairs' keep their own policy; put "
            "the directive in the text of the program whose rules it is for)"]
        assert _policies(kb)[("pairs", "c/1")] == "unrestricted"
    with pytest.warns(slr_sql.loader.ConsumptionScopeWarning) as caught:
        slr_sql.open(backend, clock=ManualClock(0.0)).close()
    assert [m.split(" sets ")[0] for m in _scope_warnings(caught)] == [
        ":- consumption(chronological) in the program 'early'",
        ":- consumption(recent) in the program 'policy'"]


def test_slr_load_says_a_policy_that_sets_no_rule_in_one_line(tmp_path):
    db, rules, policy = tmp_path / "s.db", tmp_path / "rules.pl", tmp_path / "policy.pl"
    rules.write_text(PAIRS)
    policy.write_text(":- consumption(recent).\n")
    assert slr("load", str(db), str(rules)).returncode == 0
    done = slr("load", str(db), str(policy), "--name", "policy")
    assert done.returncode == 0 and "Traceback" not in done.stderr
    assert done.stderr.startswith("warning: :- consumption(recent) in the program 'policy' "
                                  "sets the policy of no event rule:"), done.stderr
    assert len(done.stderr.splitlines()) == 1
