"""Which pulses made a line: their arrival times and flags, in bounded memory.

Image line j sums pulses j … j + N - 1 (Psaltis & Wagner 1981: a row leaves the CCD after N
shifts).  Its latency is measured from the arrival of pulse j + N - 1, and it is flagged when
any of its N pulses was zero-filled or zeroed by ingest.  Arrival times sit in a ring indexed by
pulse number (the ring spans the CCD plus the queues); flagged pulses are kept while a line can
still contain them.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .ingest import PulseBlock
from .strips import LineBlock


class LineTiming:
    """Records pulses as they enter the CCD; turns finished lines into LineBlocks."""

    def __init__(self, aperture_pulses: int, ring_pulses: int):
        self.aperture = int(aperture_pulses)
        ring = 1 << int(np.ceil(np.log2(max(2, ring_pulses))))
        self._arrival = np.zeros(ring)
        self._flag_pulses: deque[int] = deque()  # indices of flagged pulses still in a window
        self.flagged_lines = 0

    def record(self, block: PulseBlock) -> None:
        """Pulses entering the CCD: keep their arrival times and remember the flagged ones."""
        idx = block.first_pulse + np.arange(len(block))
        self._arrival[idx % len(self._arrival)] = block.arrival_s
        self._flag_pulses.extend(idx[block.flagged].tolist())

    def lines(self, first: int, lines: np.ndarray) -> LineBlock | None:
        """Lines first … first + len - 1 with the arrivals of their first and last pulses and
        their flags (None for no lines)."""
        if not len(lines):
            return None
        j = first + np.arange(len(lines))
        ring = len(self._arrival)
        n = self.aperture
        while self._flag_pulses and self._flag_pulses[0] < first:
            self._flag_pulses.popleft()
        if self._flag_pulses:
            fl = np.fromiter(self._flag_pulses, np.int64)
            k = np.searchsorted(fl, j)
            flagged = (k < len(fl)) & (fl[np.minimum(k, len(fl) - 1)] <= j + n - 1)
        else:
            flagged = np.zeros(len(j), bool)
        self.flagged_lines += int(flagged.sum())
        return LineBlock(
            first, lines, self._arrival[j % ring], self._arrival[(j + n - 1) % ring], flagged
        )
