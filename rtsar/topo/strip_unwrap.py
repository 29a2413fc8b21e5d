"""Unwrapping a stream of wrapped-phase lines strip by strip, continuous across strips.

Used by both height strip stages (rtsar.topo.stream for InSAL, rtsar.topo.sam3d_strips for
spatial amplitude modulation).  Each strip is unwrapped on its lines plus ``overlap`` lines on
each side; its first lines are the previous strip's last ones, already unwrapped, and the new
strip takes the 2π cycle that best matches them (median of the difference on the pixels valid in
both).  A strip without such a pixel (the first one, or after a gap of invalid lines) takes the
absolute rule: rtsar.topo.insar.absolute_cycle_shift at ``percentile`` (the scene's lower part
near the reference plane), and is counted in ``strips_not_aligned`` unless it is the first.
"""

from __future__ import annotations

import math

import numpy as np

from ..phase import TWO_PI
from .insar import absolute_cycle_shift
from .unwrap import unwrap_quality


class StripUnwrapper:
    """``unwrap(wrapped, valid, coherence, shared)`` → (unwrapped, aligned), then ``keep``."""

    def __init__(self, method: str, percentile: float):
        self.method = method
        self.percentile = float(percentile)
        self.prev_unw: np.ndarray | None = None  # unwrapped phase of the last lines kept
        self.prev_valid: np.ndarray | None = None
        self.strips_not_aligned = 0

    def unwrap(self, wrapped, valid, coherence, shared: int) -> tuple[np.ndarray, bool]:
        """Unwrap one strip's domain [lines, range]; its first ``shared`` lines are the last
        ``shared`` lines given to ``keep`` before.  Invalid pixels come out 0."""
        wrapped = np.where(valid, wrapped, 0.0)
        unw = (
            unwrap_quality(wrapped, valid, self.method, coherence) if len(wrapped) > 1 else wrapped
        )
        aligned = False
        if self.prev_unw is not None and shared > 0:
            both = self.prev_valid[-shared:] & valid[:shared]
            if both.any():
                diff = self.prev_unw[-shared:][both] - unw[:shared][both]
                unw = unw + TWO_PI * math.floor(float(np.median(diff)) / TWO_PI + 0.5)
                aligned = True
        if not aligned:
            unw = unw + absolute_cycle_shift(unw, valid, self.percentile)
            if self.prev_unw is not None:
                self.strips_not_aligned += 1
        return np.where(valid, unw, 0.0), aligned

    def keep(self, unwrapped: np.ndarray, valid: np.ndarray) -> None:
        """The lines the next strip will share (its first ``shared`` lines)."""
        self.prev_unw, self.prev_valid = unwrapped, valid
