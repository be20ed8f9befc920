"""`slr ros import` of a recording: the store's clock follows the bag's record times, and the
import learns no delays. It opened the store with the wall clock: every imported type "arrived"
months after its stamps, printed a LearnedDelayWarning and learned the cap (3600 s), so a
synchronized query on the store, later and live, waited an hour for each of them; the events'
arrival times were the import's, not the recording's.

Real bags written with rosbags (examples/ros/make_bag.py) and `slr` as a real process."""
from __future__ import annotations

import time

import slr_sql
from slr_sql import ManualClock

from test_export import robot_store
from test_ros_import import make_bag, recorded, slr, tf_items

EPOCH = make_bag.EPOCH   # the recordings' stamps: wall-clock times of the past


def battery_items(fmt: str, n: int) -> list:
    """``n`` Float64 messages (no header: the event time is the record time)."""
    return [("/battery", "std_msgs/msg/Float64", EPOCH + 0.5 + i, {"data": 24.0 - i})
            for i in range(n)]


def test_an_imported_bag_arrives_in_its_own_time_and_teaches_no_delays(tmp_path):
    items = tf_items("mcap", 40, start=EPOCH) + battery_items("mcap", 8)
    bag = make_bag.write_bag(tmp_path / "rec", "mcap", items)
    map_file = tmp_path / "robot.yaml"
    map_file.write_text("topics:\n  /battery:\n    args: [data]\n")
    db = tmp_path / "robot.db"
    # batches of 16 events: the clock moves between them
    run = slr("ros", "import", str(bag), str(db), "--map", str(map_file), "--batch", "16")
    assert run.returncode == 0, run.stderr
    assert "imported 88 events from 48 messages" in run.stdout
    assert "warning" not in run.stderr.lower() and "LearnedDelay" not in run.stderr, run.stderr
    last_record = max(recorded(at) for _, _, at, _ in items)
    with slr_sql.open(db) as kb:   # later, on the wall clock, as a live process would
        now = time.time()
        horizons = {t: kb.complete_until(t) for t in ("tf/3", "battery/1", "slr_import/3")}
        arrivals = kb.sql("SELECT min(arrival - t_end) AS early, max(arrival) AS last, "
                          "count(DISTINCT arrival) AS batches FROM tf")[1][0]
        learned = kb.sql("SELECT count(*) FROM slr_meta WHERE key LIKE 'sync/learned/%'")[1][0][0]
    # no type learned a delay from the import: each is complete up to the wall clock's now
    assert all(h >= now - 60 for h in horizons.values()), horizons
    assert learned == 0
    # each batch arrived at the record time of its last message: in the recording's time
    early, last, batches = arrivals
    assert early >= 0.0 and last == last_record and batches > 1


def test_importing_an_export_of_old_events_says_no_warning(tmp_path):
    with robot_store(tmp_path / "r.db", clock=ManualClock(100.0)):
        pass
    assert slr("export", str(tmp_path / "r.db"), str(tmp_path / "out.mcap")).returncode == 0
    run = slr("ros", "import", str(tmp_path / "out.mcap"), str(tmp_path / "back.db"))
    assert run.returncode == 0, run.stderr
    assert "warning" not in run.stderr.lower(), run.stderr
    with slr_sql.open(tmp_path / "back.db", clock=ManualClock(10.0)) as kb:
        arrivals = {row[0] for table in ("seg", "tf", "goal", "said")
                    for row in kb.sql(f"SELECT DISTINCT arrival FROM {table}")[1]}
        learned = kb.sql("SELECT count(*) FROM slr_meta WHERE key LIKE 'sync/learned/%'")[1][0][0]
    assert learned == 0
    assert arrivals == {3.0}   # the greatest end time of its batch (one batch), not the wall's
