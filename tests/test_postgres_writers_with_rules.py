"""Several processes adding to one PostgreSQL store whose rules wait for completeness.

Writer processes each own one input type of a ``recent``, ``chronological`` or negated rule and
add its events out of order, marking their type complete (``kb.mark_complete``) as far as
they know it is, and everything at their end; a decision is made by whichever process moves
completeness far enough (a writer's add or mark, or the test's final marks), whoever stored
the waiting row. Decisions wait for complete histories, so
the complex events cannot depend on how the writers interleave: they must be, once each,
those of the naive reference evaluator of tests/test_cep_differential.py over all events.
"""
from __future__ import annotations

import json
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
import test_cep_differential as cepdiff

import slr_sql
from slr_sql import ManualClock
from writer_processes import start_together

REPO = Path(__file__).resolve().parent.parent

WRITER = r"""
import json, sys
import slr_sql
from slr_sql import ManualClock
url, name, events = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
with slr_sql.open(url, clock=ManualClock(0.0)) as kb:
    print("ready", flush=True)
    sys.stdin.readline()             # the writers start together
    done = 0
    for i, (args, s, e, batch) in enumerate(events):
        if i < done:
            continue
        part = events[i:i + batch]
        kb.add_many([(name, tuple(a), s2, e2) for a, s2, e2, _ in part])
        done = i + len(part)
        rest = [e2 for _, _, e2, _ in events[done:]]
        # complete up to just before the earliest end still to come (all, at the end)
        kb.mark_complete(f"{name}/1", min(rest) - 0.5 if rest else 1000.0)
print("done", flush=True)
"""


def _stream(seed: int, n: int) -> list:
    """``n`` events of each of a/1 and b/1 and ``n // 3`` of c/1: keys 0/1, integer times
    with ties, some intervals."""
    rng = random.Random(seed)
    out = []
    for name, count in (("a", n), ("b", n), ("c", n // 3)):
        for _ in range(count):
            s = float(rng.randint(0, 3 * n))
            out.append((name, (rng.randint(0, 1),), s, s + rng.choice([0.0, 0.0, 1.0])))
    return out


SEQ = ("seq", ("leaf", "a", ("X",)), ("leaf", "b", ("X",)))
SEQ_XY = ("seq", ("leaf", "a", ("X",)), ("leaf", "b", ("Y",)))


@pytest.mark.parametrize("policy, pattern, cnot, where, within", [
    ("recent", SEQ, None, [], None),
    ("unrestricted", SEQ, ("c", ("X",)), [], None),   # negation waits for c's marks
    ("chronological", SEQ_XY, None, [(">=", "X", "Y")], 8),   # a where run in Python
])
def test_writers_of_each_type_decide_each_complex_event_once(postgres_url, tmp_path, policy,
                                                             pattern, cnot, where, within):
    rule = {"pattern": pattern, "head": ["X"], "where": where, "cnot": cnot,
            "within": within, "policy": policy, "interpret": bool(where)}
    types = ["a", "b"] + (["c"] if cnot else [])
    events = [ev for ev in _stream(len(policy) + len(where), 20) if ev[0] in types]
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        kb.load(f":- consumption({policy}).\n" + cepdiff.rule_text(rule)
                + ("\n" + cepdiff.WHERE_PROGRAM if where else ""))
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    rng = random.Random(policy)
    procs = []
    for name in types:   # each writer adds its type out of order, in batches of 1 to 3
        mine = [[list(args), s, e, rng.randint(1, 3)] for n, args, s, e in events if n == name]
        rng.shuffle(mine)
        procs.append(subprocess.Popen(
            [sys.executable, str(script), postgres_url, name, json.dumps(mine)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env, text=True))
    start_together(procs)
    for p in procs:
        assert p.wait(timeout=120) == 0
    with slr_sql.open(postgres_url, clock=ManualClock(0.0)) as kb:
        # (two writers' last marks at once may each miss the other's: a mark of all decides
        # what is left -- here, of rows this process did not store)
        for name in types:
            kb.mark_complete(f"{name}/1", 1000.0)
        assert kb.sql("SELECT count(*) FROM slr_cep_pending")[1] == [(0,)]
        got = sorted(((args[0],), s, e) for args, s, e, _ in kb.store.scan("r", 1))
    expected = sorted(((h[0],), s, e) for h, s, e in cepdiff.reference(rule, events))
    assert expected and got == expected
