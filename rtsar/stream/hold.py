"""The metadata of pulses a line correction holds back, released with their lines.

A line stage (PGA) may return fewer range lines than it was given and the rest later, in pulse
order.  The arrival times and flags of the held pulses wait here, so that the lines the stage
releases leave with their own pulses' metadata: latency and flags stay exact.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from .ingest import PulseBlock, concat_blocks


class HeldPulses:
    """FIFO of pulse blocks whose lines a correction stage still holds."""

    def __init__(self):
        self._held: deque[PulseBlock] = deque()

    def hold(self, block: PulseBlock) -> None:
        self._held.append(block)

    def release(self, lines: np.ndarray) -> PulseBlock | None:
        """The first len(lines) held pulses, their metadata with the ``lines`` released."""
        k = len(lines)
        if k == 0:
            return None
        parts, need = [], k
        while need:
            b = self._held[0]
            if len(b) <= need:
                parts.append(self._held.popleft())
                need -= len(b)
            else:
                parts.append(b.slice(0, need))
                self._held[0] = b.slice(need, len(b))
                need = 0
        meta = concat_blocks(parts)
        return PulseBlock(meta.first_pulse, lines, meta.arrival_s, meta.flagged)
