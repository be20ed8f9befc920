"""The delivery path makes no garbage that only the cyclic collector frees.

``slr serve`` raises the young generation's threshold and freezes its start-up heap so that
collections are rare and short; garbage in reference cycles made per event or per frame
undoes that: at 1,000 events/s and 100 subscribers every such object adds up to a young
collection of tens of thousands of objects every second or two, a pause of every request and
WebSocket subscriber (a tail of the latency). Here the whole path of an event through one
process is run with the collector off: ``kb.add_many`` of event texts, the hub's pass, the
subscriptions' queues, ``next_answers`` on an asyncio loop and the service's frame text.
"""
from __future__ import annotations

import asyncio
import gc

import slr_sql
from slr_sql.service.app import _AnswerTexts


def test_add_many_to_async_subscribers_leaves_no_cyclic_garbage(tmp_path):
    kb = slr_sql.open(tmp_path / "g.db", clock=slr_sql.ManualClock(0))
    try:
        kb.add("e(-1)^0")
        subs = [kb.subscribe("e(I)^T", since=0.5) for _ in range(4)]
        texts = _AnswerTexts()
        got = [[] for _ in subs]

        async def consume(k: int, want: int) -> None:
            seq = len(got[k])
            while len(got[k]) < want:
                answers = await subs[k].next_answers(256, copy=False)
                texts.frame(seq + 1, answers)
                seq += len(answers)
                got[k].extend(a["I"] for a in answers)

        async def rounds() -> list[int]:
            loop = asyncio.get_running_loop()
            found = []
            n = 0
            for _ in range(3):               # the first round warms caches up
                # young collections only: with the collector off, everything a round makes
                # stays in the youngest generation, and its cyclic garbage is found there
                # without traversing the whole heap (in an xdist worker late in the suite a
                # full collection took over a second, six of them most of this test's time)
                gc.collect(0)
                gc.disable()
                try:
                    consumers = [asyncio.ensure_future(consume(k, n + 100))
                                 for k in range(len(subs))]
                    for _ in range(10):
                        batch = [f"e({i})^{i + 1}" for i in range(n, n + 10)]
                        await loop.run_in_executor(None, kb.add_many, batch)
                        n += 10
                    await asyncio.wait_for(asyncio.gather(*consumers), 60)
                    found.append(gc.collect(0))
                finally:
                    gc.enable()
            return found

        found = asyncio.run(rounds())
        assert all(g == list(range(300)) for g in got)   # every event, once, in order
        assert found[1:] == [0, 0], found
        for sub in subs:
            sub.close()
    finally:
        kb.close()
