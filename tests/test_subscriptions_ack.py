"""Acknowledged consumption of a subscription: ``next_answers(handled=False)`` takes answers
without marking anything handled, ``acknowledge(count)`` marks them handled in order (what the
network service does for clients that acknowledge). Real store files; a ManualClock where
completeness matters; every wait has a deadline."""
from __future__ import annotations

import asyncio

import pytest

import slr_sql
from slr_sql import ManualClock, SLRError

DEADLINE = 30.0


def xs(answers: list[dict]) -> list:
    return [a["X"] for a in answers]


async def take(sub, limit: int) -> list:
    return await asyncio.wait_for(sub.next_answers(limit, handled=False), DEADLINE)


# Every store here has a ManualClock: events stamped 1, 2 on a wall clock would be "decades
# late" (a LearnedDelayWarning); the subscriptions start at since=0.
def test_answers_not_acknowledged_come_again_after_close_and_reopen(tmp_path):
    path = tmp_path / "acks.db"
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(1, 11)])
        sub = kb.subscribe("p(X)^T", since=0, id="acked")

        async def consume() -> list:
            first = await take(sub, 4)
            second = await take(sub, 4)      # the first batch is not handled by this
            return first + second
        got = asyncio.run(consume())
        assert xs(got) == list(range(1, 9))
        assert sub.unacknowledged == 8 and sub.delivered == 8
        before = sub.position()
        sub.acknowledge(5)
        assert sub.unacknowledged == 3 and sub.position() > before
        sub.close()                          # 6, 7, 8 were never acknowledged
    with slr_sql.open(path, clock=ManualClock(0.0)) as kb:
        again = kb.subscribe("p(X)^T", since=0, id="acked")
        assert [again.get(timeout=DEADLINE)["X"] for _ in range(5)] == [6, 7, 8, 9, 10]
        again.close(forget=True)


def test_the_position_moves_only_with_acknowledgements(tmp_path):
    with slr_sql.open(tmp_path / "pos.db", clock=ManualClock(0.0)) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(1, 4)])
        sub = kb.subscribe("p(X)^T", since=0, id="pos")
        start = sub.position()
        asyncio.run(take(sub, 3))
        assert sub.position() == start
        positions = []
        for _ in range(3):
            sub.acknowledge(1)
            positions.append(sub.position())
        assert start < positions[0] < positions[1] < positions[2]
        sub.close(forget=True)


@pytest.mark.parametrize("count", [-1, 3, 1.0, True, "1"])
def test_acknowledging_what_was_not_taken_is_an_error(count):
    with slr_sql.open(clock=ManualClock(0.0)) as kb:
        kb.add_many(["p(1)^1", "p(2)^2"])
        sub = kb.subscribe("p(X)^T", since=0)
        assert xs(asyncio.run(take(sub, 2))) == [1, 2]
        with pytest.raises(SLRError, match="acknowledge"):
            sub.acknowledge(count)
        assert sub.unacknowledged == 2
        sub.close()


def test_the_end_waits_for_the_acknowledgements_then_is_recorded(tmp_path):
    path = tmp_path / "end.db"
    clock = ManualClock(0.0)
    with slr_sql.open(path, clock=clock) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(1, 4)])
        sub = kb.subscribe("p(X)^T", since=0, until=5, id="ends")
        kb.mark_complete("p/1", 5)

        async def consume() -> list:
            answers = await take(sub, 10)
            assert sub.wait(DEADLINE)                    # the end is queued behind them
            rest = asyncio.ensure_future(sub.next_answers(10, handled=False))
            for _ in range(5):
                await asyncio.sleep(0)                   # let it run: it waits for acks
            assert not rest.done()
            sub.acknowledge(len(answers))
            assert await asyncio.wait_for(rest, DEADLINE) == []
            return answers
        assert xs(asyncio.run(consume())) == [1, 2, 3]
        assert sub.closed
    with slr_sql.open(path, clock=clock) as kb:
        again = kb.subscribe("p(X)^T", since=0, until=5, id="ends")
        assert again.get(timeout=DEADLINE) is None        # finished: ends at once


def test_an_end_not_acknowledged_delivers_again(tmp_path):
    path = tmp_path / "unacked_end.db"
    clock = ManualClock(0.0)
    with slr_sql.open(path, clock=clock) as kb:
        kb.add_many([f"p({i})^{i}" for i in range(1, 4)])
        sub = kb.subscribe("p(X)^T", since=0, until=5, id="ends")
        kb.mark_complete("p/1", 5)
        assert xs(asyncio.run(take(sub, 10))) == [1, 2, 3]
        assert sub.wait(DEADLINE)
        sub.acknowledge(1)
        sub.close()                                       # 2 and 3 unhandled, not finished
    with slr_sql.open(path, clock=clock) as kb:
        again = kb.subscribe("p(X)^T", since=0, until=5, id="ends")
        assert xs(list(again)) == [2, 3]
