"""What a rule's per-column memory of stored texts may hold.

``pos_multiply`` on stored values remembers the readings of the last texts of each input
column (a camera pose stored again and again is read once). The memory is bounded by the
number of texts, so each text it keeps must be small too: a column that holds large
values (a long list, a message) would otherwise keep dozens of them alive for as long as
the rule is installed. A long text is read each time instead, as before the memory.
"""
from __future__ import annotations

from slr_sql.cep.where import remembering


def test_a_long_text_is_read_each_time_and_not_kept():
    calls: list = []
    read = remembering(lambda text: calls.append(len(text)) or None)
    long_text = "[" + ",".join(["0.25"] * 50_000) + "]"
    assert read(long_text) is None and read(long_text) is None
    assert calls == [len(long_text)] * 2
    pose = '{"pose":[[0.1,0.0,1.2],[0.0,0.0,0.258819045,0.965925826]]}'
    read(pose)
    read(pose)
    assert calls[2:] == [len(pose)]   # (a pose's text is remembered)
