"""Release shots on an absolute schedule, t0 + n / rate (as GNU Radio's throttle block does).

Sleeping a fixed period per shot accumulates every oversleep; scheduling shot n at t0 + n/rate
does not, so the achieved rate over a long run is the requested one.

A shot released late is latency for every line it completes (its arrival is its due time).
Linux lets a sleep end up to the thread's "timer slack" late, 50 µs by default, so that wake-ups
can be merged: a pacing thread asks for TIMER_SLACK_NS instead (``tight_sleeps``, prctl
PR_SET_TIMERSLACK, its own thread only).  Pacing at 1,600 shots/s on a quiet 2-core Zen 3
(2026-11-29): releases 79 µs late at the median (p90 112) with the default, 22 µs (p90 31-38)
with 1 µs.  Only where a shot comes every TIGHT_FROM_S or more: a late wake-up releases the
shots then due together, and near a machine's capacity that merging is what keeps up
(psaltis-max at its 10 kHz on 2 cores, alternating 3 s replays: tight sleeps released one shot
at a time, dropped 502 shots and doubled the latency; at 2.5 and 5 kHz they lowered the median
in 5 and 4 of 6 rounds, at 1.6 kHz in 7 of 8: tools/ab_latency.py).  Elsewhere the sleeps
are the system's.
"""

from __future__ import annotations

import ctypes
import math
import sys
import threading
import time

TIMER_SLACK_NS = 1000  # a pacing thread's sleeps end at most this late, where the system allows
TIGHT_FROM_S = 200e-6  # … where a shot comes every this many seconds or more (module docstring)
_PR_SET_TIMERSLACK = 29  # linux/prctl.h
_paced = threading.local()  # threads whose slack is set


def tight_sleeps(slack_ns: int = TIMER_SLACK_NS) -> bool:
    """The calling thread's sleeps end at most ``slack_ns`` late (Linux; module docstring):
    True where set, False where the system has no such setting or refused it."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        return (
            ctypes.CDLL(None, use_errno=True).prctl(
                _PR_SET_TIMERSLACK, ctypes.c_ulong(slack_ns), 0, 0, 0
            )
            == 0
        )
    except (OSError, AttributeError):  # no C library to call, or no prctl in it
        return False


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
        """Sleep until shot n is due (in short naps so ``stop()`` is honoured); return its time.
        The calling thread's first wait sets its sleeps tight (``tight_sleeps``) where a shot
        comes every TIGHT_FROM_S or more (the thread's first pacer decides)."""
        if not getattr(_paced, "decided", False):
            _paced.decided = True
            if 1.0 / self.rate_hz >= TIGHT_FROM_S:
                tight_sleeps()
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
