"""The percentile the latency benchmarks report (bench_sync, bench_subscriptions).

>>> pct([4.0, 1.0, 3.0, 2.0], 50), pct([], 99)
(3.0, nan)
"""
from __future__ import annotations


def pct(xs: list[float], p: float) -> float:
    """The ``p``-th percentile of ``xs`` (nearest rank over ``len(xs) - 1`` steps); NaN for
    no samples."""
    xs = sorted(xs)
    if not xs:
        return float("nan")
    k = min(len(xs) - 1, max(0, int(round(p / 100.0 * (len(xs) - 1)))))
    return xs[k]
