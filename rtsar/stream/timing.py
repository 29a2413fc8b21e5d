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
from .strips import LineBlock, flag_runs, join_run


class RecordedFlags:
    """The flagged lines of an image focused from a recording at once (``rtsar process``):
    line j sums pulses j … j + N - 1, and is flagged when one of them is (as
    :meth:`LineTiming.lines` decides it while streaming).  ``pulse_flagged``: bool [pulse], 1
    byte a pulse (a recording's own flags; None: none yet), which ``mark`` may add to as the
    shots are read (those zeroed for NaN/Inf), before the lines that hold them are added.
    ``add(first_line, count)`` for each block of lines written, in order; ``runs``: the flagged
    lines as [first_line, count] runs (adjacent blocks' runs merged), ``lines`` their number."""

    def __init__(self, pulse_flagged: np.ndarray | None, aperture_pulses: int, pulses: int):
        self.aperture = int(aperture_pulses)
        self.flagged = np.zeros(int(pulses), bool)
        if pulse_flagged is not None:
            self.flagged[:] = np.asarray(pulse_flagged, bool)
        self.runs: list[list[int]] = []
        self.lines = 0

    def mark(self, first_pulse: int, flagged: np.ndarray) -> None:
        """Pulses first_pulse … (``flagged``: bool, one a pulse) flagged besides the recording's."""
        self.flagged[first_pulse : first_pulse + len(flagged)] |= flagged

    def add(self, first_line: int, count: int) -> None:
        first, count = int(first_line), int(count)
        if not count:
            return
        # flagged pulses before each pulse of the lines' apertures (first … first + count + N)
        window = self.flagged[max(first, 0) : max(first + count + self.aperture - 1, 0)]
        if not window.any():
            return
        before = np.concatenate([[0], np.cumsum(window, dtype=np.int64)])
        j = np.arange(count) + first - max(first, 0)
        low = np.clip(j, 0, len(window))
        high = np.clip(j + self.aperture, 0, len(window))
        flagged = before[high] > before[low]
        self.lines += int(flagged.sum())
        for run_first, n in flag_runs(first, flagged):
            join_run(self.runs, run_first, n)


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
        idx = np.arange(block.first_pulse, block.first_pulse + len(block))
        self._arrival[idx % len(self._arrival)] = block.arrival_s
        self._flag_pulses.extend(idx[block.flagged].tolist())

    def lines(self, first: int, lines: np.ndarray) -> LineBlock | None:
        """Lines first … first + len - 1 with the arrivals of their first and last pulses and
        their flags (None for no lines)."""
        if not len(lines):
            return None
        j = np.arange(first, first + len(lines))
        ring = len(self._arrival)
        n = self.aperture
        while self._flag_pulses and self._flag_pulses[0] < first:
            self._flag_pulses.popleft()
        if self._flag_pulses:
            fl = np.fromiter(self._flag_pulses, np.int64)
            k = np.searchsorted(fl, j)
            flagged = (k < len(fl)) & (fl[np.minimum(k, len(fl) - 1)] <= j + n - 1)
            self.flagged_lines += int(flagged.sum())
        else:  # no flagged pulse in any window: the common case, no count to make
            flagged = np.zeros(len(j), bool)
        return LineBlock(
            first, lines, self._arrival[j % ring], self._arrival[(j + n - 1) % ring], flagged
        )
