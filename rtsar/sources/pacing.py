"""Release shots on an absolute schedule, t0 + n / rate (as GNU Radio's throttle block does).

Sleeping a fixed period per shot accumulates every oversleep; scheduling shot n at t0 + n/rate
does not, so the achieved rate over a long run is the requested one.
"""

from __future__ import annotations

import math
import time


class Pacer:
    """Schedule for shot n: ``t0 + n / rate_hz`` on the perf_counter clock."""

    def __init__(self, rate_hz: float, t0: float | None = None):
        if not rate_hz > 0:
            raise ValueError(f"rate must be > 0, got {rate_hz!r}")
        self.rate_hz = float(rate_hz)
        self.t0 = time.perf_counter() if t0 is None else float(t0)

    def due(self, n: int) -> float:
        """When shot n is due (perf_counter seconds)."""
        return self.t0 + n / self.rate_hz

    def behind(self, n: int, now: float | None = None) -> int:
        """Shots from n on already due at ``now`` (0 when shot n is not yet due)."""
        now = time.perf_counter() if now is None else now
        return max(0, math.floor((now - self.t0) * self.rate_hz) + 1 - n)

    def wait(self, n: int, stop=lambda: False) -> float:
        """Sleep until shot n is due (in short naps so ``stop()`` is honoured); return its time."""
        t = self.due(n)
        while not stop():
            left = t - time.perf_counter()
            if left <= 0:
                break
            time.sleep(min(left, 0.05))
        return t


CATCH_UP_MOST = 64  # shots a late source releases together, at most


def next_release(pacer: Pacer, n: int, chunk: int, left: int, most: int = CATCH_UP_MOST) -> int:
    """Shots to release from shot n on: ``chunk`` while on time; once behind, every shot
    already due (up to ``most``), so a source that fell behind catches up in a few large
    releases instead of paying its per-release cost for each small one late."""
    return max(1, min(left, max(chunk, min(pacer.behind(n), most))))


def release_chunk(rate_hz: float, max_wait_s: float = 0.001, most: int = 8) -> int:
    """Shots released together: those arriving within ``max_wait_s``, 1 to ``most``.

    The AO lens transforms 8 pulses per work-item at once (SIMD lanes): a launch costs about the
    same for 1 or 8 pulses, so releasing fewer than 8 at a time only adds launches.
    """
    return max(1, min(most, int(rate_hz * max_wait_s)))
