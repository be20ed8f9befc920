"""run_bridge before it runs: what a bridge that cannot start leaves behind."""
from __future__ import annotations

import signal

import pytest

from slr_sql import SLRError
from slr_sql.ros.bridge import run_bridge
from slr_sql.ros.mapping import mapping_from_dict


def test_a_bridge_whose_store_cannot_open_leaves_the_signal_handlers_as_they_were(tmp_path):
    signals = (signal.SIGINT, signal.SIGTERM)
    before = [signal.getsignal(s) for s in signals]
    with pytest.raises(SLRError, match="no such directory"):
        run_bridge(str(tmp_path / "missing" / "robot.db"), mapping_from_dict({"topics": {}}),
                   echo=lambda text: None)
    assert [signal.getsignal(s) for s in signals] == before
