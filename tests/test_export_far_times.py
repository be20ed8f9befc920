"""``slr export`` of a store whose times lie beyond MCAP's clock (unsigned 64-bit nanoseconds:
about 1.8e10 s, the year 2554). An event may end at any finite time (SPEC §2): such a store
stopped the export with "OverflowError: cannot convert float infinity to integer (this is
a bug in slr_sql)". Its messages now carry the last time MCAP can say (a negative one the
first, as before) and the event's own times in their data, so the import gives them back."""
from __future__ import annotations

from mcap.reader import make_reader

import slr_sql
from slr_sql import ManualClock

from test_export import everything, slr

LAST_NS = 2 ** 64 - 1


def test_events_and_marks_beyond_mcaps_clock_export_and_come_back(tmp_path):
    with slr_sql.open(tmp_path / "far.db", clock=ManualClock(0.0)) as kb:
        kb.load(":- max_delay(far/1, 0).\n:- max_delay(near/1, 0).")
        kb.add_many([("near", [1], 1.0, 1.0),
                     ("far", [2], -1e300, 1e300),   # start and end beyond both ends
                     ("far", [3], 2e10, 2e10),      # just beyond 2**64 ns
                     ("far", [4], 1e308, 1e308)])
        kb.mark_complete("far/1", 1e308)
        before = everything(kb)
    out = slr("export", str(tmp_path / "far.db"), str(tmp_path / "far.mcap"))
    assert out.returncode == 0, out.stderr
    assert "exported 4 events" in out.stdout and "Traceback" not in out.stderr
    with open(tmp_path / "far.mcap", "rb") as stream:
        times = [(channel.topic, message.log_time)
                 for _, channel, message in make_reader(stream).iter_messages()]
    assert [t for topic, t in times if topic == "/far/1"] == [LAST_NS] * 3
    assert ("/near/1", 1_000_000_000) in times
    back = slr("ros", "import", str(tmp_path / "far.mcap"), str(tmp_path / "back.db"))
    assert back.returncode == 0, back.stderr
    with slr_sql.open(tmp_path / "back.db") as kb:
        assert everything(kb) == before
        assert kb.complete_until("far/1") == 1e308
