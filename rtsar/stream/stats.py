"""What a run did: counters, the latency distribution in bounded memory, stage busy time.

Latency of an image line: from the arrival of the last pulse that contributes to it (pulse
j + N - 1 for line j, Psaltis & Wagner 1981: the row leaves the CCD after N shifts) to the
publication of the strip holding it.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np


class LatencyStats:
    """Latency distribution in bounded memory: a log-spaced histogram (0.5 % wide bins)."""

    BINS_PER_DECADE = 460
    LOW_S = 1e-6

    def __init__(self):
        self.counts = np.zeros(9 * self.BINS_PER_DECADE + 2, np.int64)  # 1 µs … 1e3 s
        self.recent: deque[float] = deque(maxlen=4000)
        self.total = 0
        self.max_s = 0.0

    SMALL = 16  # at most this many values a call: binned one by one (below)

    def add(self, latency_s: np.ndarray) -> None:
        latency_s = np.asarray(latency_s, np.float64).ravel()
        if not latency_s.size:
            return
        values = latency_s.tolist()
        if len(values) <= self.SMALL:
            self._add_few(values)
        else:
            # Called for every strip on the publishing thread, holding the GIL: bincount, not
            # add.at (and no floor: the decades are >= 0; infinity capped before the cast,
            # which would make it the lowest integer).
            decades = np.log10(np.fmax(latency_s, self.LOW_S) / self.LOW_S)
            k = np.minimum(decades * self.BINS_PER_DECADE, len(self.counts)).astype(np.int64) + 1
            np.clip(k, 0, len(self.counts) - 1, out=k)
            self.counts += np.bincount(k, minlength=len(self.counts))
        self.recent.extend(values[-self.recent.maxlen :])
        self.total += len(values)
        self.max_s = max(self.max_s, max(values))

    def _add_few(self, values: list[float]) -> None:
        """The bins of a few values one by one: a strip of 1-16 lines, the low-latency case.
        The histogram-wide bincount and sum cost 20-60 µs a strip on a busy 2-core machine
        (its 33 kB through the caches the other stages use), a tenth of a line's time at
        1,600 pulses/s; the same bins as ``add``'s (NaN and values under LOW_S in bin 1)."""
        counts, top = self.counts, len(self.counts) - 1
        for v in values:
            v = v / self.LOW_S if v > self.LOW_S else 1.0  # NaN too, as np.fmax does
            k = int(math.log10(v) * self.BINS_PER_DECADE) + 1 if v < 1e300 else top
            counts[min(k, top)] += 1

    def percentile(self, q: float) -> float:
        """q-th percentile (s), to the histogram's 0.5 %; NaN when empty."""
        if self.total == 0:
            return float("nan")
        k = int(np.searchsorted(np.cumsum(self.counts), q / 100 * self.total, "left"))
        return self.LOW_S * 10 ** ((k - 0.5) / self.BINS_PER_DECADE)

    def recent_percentile(self, q: float) -> float:
        """q-th percentile (s) of the last ``recent.maxlen`` lines, by the rank rule of
        ``percentile`` (the smallest value with q % at or under it), so the two agree, to the
        histogram's 0.5 %, where they hold the same lines; NaN when empty."""
        if not self.recent:
            return float("nan")
        return float(np.percentile(self.recent, q, method="inverted_cdf"))


@dataclass
class PipelineStats:
    """What a run did: counters, latency, timing.  ``as_dict`` is what the stats topic carries."""

    counters: dict = field(default_factory=dict)
    latency: LatencyStats = field(default_factory=LatencyStats)
    started_s: float = 0.0
    elapsed_s: float = 0.0
    busy_s: dict = field(default_factory=dict)  # seconds of work per stage
    stopped_by: str = ""  # the signal that stopped the source ("SIGINT", …), else ""

    def as_dict(self) -> dict:
        d = {k: int(v) for k, v in self.counters.items()}
        lat = self.latency
        return {
            "counters": d,
            "elapsed_s": self.elapsed_s,
            "pulse_rate_hz": d.get("pulses_processed", 0) / max(self.elapsed_s, 1e-9),
            "latency_median_ms": lat.percentile(50) * 1e3,
            "latency_p99_ms": lat.percentile(99) * 1e3,
            "latency_max_ms": lat.max_s * 1e3,
            "stage_busy_s": dict(self.busy_s),
            "stopped_by": self.stopped_by,
        }
