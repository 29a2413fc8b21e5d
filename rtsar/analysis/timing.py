"""Throughput of a callable, measured the same way by every benchmark and report."""

from __future__ import annotations

import time


def rate_per_s(fn, items_per_call: int, seconds: float) -> float:
    """Call ``fn`` repeatedly for about ``seconds`` (after one warm-up call, at least three
    calls); return items per second."""
    fn()
    calls, t0 = 0, time.perf_counter()
    while True:
        fn()
        calls += 1
        dt = time.perf_counter() - t0
        if dt >= seconds and calls >= 3:
            return calls * items_per_call / dt
