"""A knowledge base closed by another thread while adds run: an add either stored its
events and returned, or stored nothing and raised. An add that raised after its commit
would be retried by its caller and store its events twice."""

import threading

import pytest

import slr_sql

PROGRAM = """
alarm(X) <- p(X) seq q(X).
"""


@pytest.mark.parametrize("trial", range(30))
def test_an_add_that_raised_stored_nothing_and_one_that_returned_stored_all(tmp_path, trial):
    path = tmp_path / "race.db"
    kb = slr_sql.open(path, clock=slr_sql.ManualClock(0.0))
    kb.load(PROGRAM)
    kb.add_buffer("p(_)", keep_last=5)
    kb.subscribe("p(X)^T", since=0)
    started = threading.Event()
    returned: list[int] = []
    raised: list[int] = []

    def adds() -> None:
        for i in range(100_000):
            if i == 3 + trial:
                started.set()
            try:
                kb.add_many([("p", [i], float(i), float(i)), ("q", [i], float(i), float(i))])
            except slr_sql.SLRError:
                raised.append(i)
                return
            returned.append(i)
        started.set()

    adder = threading.Thread(target=adds)
    adder.start()
    assert started.wait(60)
    kb.close()
    adder.join(60)
    assert not adder.is_alive()
    with slr_sql.open(path, clock=slr_sql.ManualClock(0.0)) as again:
        stored = {a["X"] for a in again.query("q(X)^_")}
    assert set(returned) <= stored
    assert not set(raised) & stored, "an add raised after its events were stored"
