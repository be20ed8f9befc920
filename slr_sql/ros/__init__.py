"""ROS for slr_sql (the ``slr_sql[ros]`` extra): recorded and live robot data in.

* :func:`slr_sql.ros.bag_import.import_bag` — rosbag1, rosbag2 (sqlite3, MCAP) and MCAP files
  into a knowledge base, through ``rosbags`` (no ROS installation needed);
* :mod:`slr_sql.ros.mapping` — MAP files: topics -> events (YAML, or a ``pub_sub.xml``);
* :mod:`slr_sql.ros.bridge` — a live ROS 2 node (rclpy) storing mapped topics as events;
* :mod:`slr_sql.ros.requests` — queries and runtime control of the bridge over ROS topics
  (:mod:`slr_sql.ros.protocol`: the JSON on the wire; :mod:`slr_sql.ros.control`: the
  control state, kept in the store);
* :mod:`slr_sql.ros.cli` — ``slr ros import`` and ``slr ros bridge``.

This package sits above the knowledge-base facade: it uses only the public API
(``slr_sql.open``, ``kb.add_many``, ``kb.mark_complete``, ``kb.query``, ``kb.submit``,
``kb.load``, ``kb.add_buffer``, ``kb.subscribe``, ``kb.close``), and the network service's
JSON encoding of terms and errors (:mod:`slr_sql.service.encoding`), so that the request
topics and ``slr serve`` speak the same payloads.
Importing it is cheap and needs none of the extra's packages; the submodules import
``rosbags``, ``yaml`` and ``rclpy`` themselves. See docs/ros.md.

>>> from slr_sql.ros import EXTRA_HINT
>>> "slr_sql[ros]" in EXTRA_HINT
True
"""
from __future__ import annotations

__all__ = ["EXTRA_HINT"]

EXTRA_HINT = "pip install 'slr_sql[ros]'"
