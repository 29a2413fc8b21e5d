"""The PGA stream stage: blocks of range-compressed pulses corrected as they arrive.

Layout and latency: rtsar.focus.pga.blocks; the estimator: rtsar.focus.pga.estimator (Crouch
eqs. 4.14-4.17); the float64 reference it equals: rtsar.focus.pga.reference.pga_batch.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, field

import numpy as np

from ...lens.plan import range_axis_m
from ...params import Config
from ...phase import phasor
from ...samples import zero_nonfinite_rows
from ..stage import CorrectionStage
from .blocks import Stitcher
from .doppler import antenna_coherence, centroid_lags
from .estimator import REASONS, BlockReport, PGASettings, estimate_block, footprint_pulses


@dataclass
class PGACounters:
    pulses_in: int = 0
    pulses_out: int = 0
    blocks_estimated: int = 0
    blocks_not_estimated: int = 0
    blocks_converged: int = 0
    blocks_doppler_anchored: int = 0  # blocks whose slope the antenna's Doppler centroid set
    nonfinite_pulses: int = 0  # pulses holding NaN/Inf: zeroed, never reach the output
    reasons: dict = field(default_factory=lambda: {r: 0 for r in REASONS})


class PGAStage(CorrectionStage):
    """Streaming PGA between the AO lens and the CCD: ``process(lines)`` → corrected lines.

    Lines leave in pulse order, (P + H)/2 pulses after they arrived (block 0: P); ``flush()``
    returns the rest at the end of a stream.  ``last_phase_rad`` holds the phase removed from the
    lines of the last ``process``/``flush`` call; ``reports`` the last ``keep_reports`` block
    reports; ``counters`` the totals.  Memory: one block of lines.  Output complex64.
    """

    domain = "lines"

    def __init__(
        self,
        config: Config,
        settings: PGASettings | None = None,
        range_m: np.ndarray | None = None,
        keep_reports: int = 64,
    ):
        self.config = config
        self.settings = settings or PGASettings()
        self.range_m = range_axis_m(config) if range_m is None else np.asarray(range_m, np.float64)
        n = config.processor.aperture_pulses
        self.block, self.hop, _ = self.settings.resolved(n, footprint_pulses(config))
        self.bins = self.range_m.size
        # The block being filled plus the hop before it: the last block at flush may start up
        # to H pulses before the next regular block.
        self._buf = np.zeros((self.block + self.hop, self.bins), np.complex128)
        self._buf_start = 0  # stream index of _buf[0]
        self._buf_len = 0
        st = self.settings
        self._stitch = Stitcher(self.block, self.hop, st.doppler_gain, st.min_doppler_coherence)
        self._anchor = st.doppler_anchor and antenna_coherence(config) > 0
        self._next_block = 0
        self.reports: deque[BlockReport] = deque(maxlen=keep_reports)
        self.counters = PGACounters()
        self.last_phase_rad = np.zeros(0)
        self._flushed = False

    @property
    def latency_pulses(self) -> int:
        """Pulses a line waits in this stage in steady state: (P + H)/2."""
        return self.block - self._stitch.margin

    def counter_values(self) -> dict[str, int]:
        """The totals of ``counters``; the reasons as ``reasons.<reason>``."""
        c = asdict(self.counters)
        reasons = c.pop("reasons")
        return {**c, **{f"reasons.{k}": v for k, v in reasons.items()}}

    def _lags(self, block: np.ndarray):
        return centroid_lags(self.config, block) if self._anchor else None

    def _count(self, rep: BlockReport) -> None:
        rep = self._stitch.annotate(rep)
        c = self.counters
        c.blocks_doppler_anchored += rep.doppler_anchored
        c.reasons[rep.reason] += 1
        if rep.estimated:
            c.blocks_estimated += 1
        else:
            c.blocks_not_estimated += 1
        c.blocks_converged += rep.converged
        self.reports.append(rep)

    def _release(self, stop: int, phase: np.ndarray) -> np.ndarray:
        """Correct and drop buffered pulses [committed_before, stop) with ``phase``."""
        lo = stop - phase.size
        rows = self._buf[lo - self._buf_start : stop - self._buf_start]
        out = (rows * phasor(-phase)[:, None]).astype(np.complex64)
        self.counters.pulses_out += len(out)
        return out

    def _trim(self, keep_from: int) -> None:
        drop = keep_from - self._buf_start
        if drop > 0:
            self._buf[: self._buf_len - drop] = self._buf[drop : self._buf_len]
            self._buf_len -= drop
            self._buf_start = keep_from

    def process(self, lines: np.ndarray, aux: dict | None = None) -> np.ndarray:
        """Add range-compressed lines [pulse, bin]; return the lines whose correction is final.

        ``aux`` (auxiliary channels) is accepted for the stage interface and not used.
        """
        if self._flushed:
            raise ValueError("PGAStage was flushed: a new stream needs a new stage")
        x = np.asarray(lines)
        if x.ndim != 2 or x.shape[1] != self.bins:
            raise ValueError(f"lines must be [pulses, {self.bins}], got {x.shape}")
        outs, phases = [], []
        i = 0
        while i < len(x):
            s = self._stitch.next_start(self._next_block)
            need = s + self.block - (self._buf_start + self._buf_len)
            take = min(need, len(x) - i)
            chunk, bad = zero_nonfinite_rows(x[i : i + take].astype(np.complex128))
            self.counters.nonfinite_pulses += int(bad.sum())
            self._buf[self._buf_len : self._buf_len + take] = chunk
            self._buf_len += take
            self.counters.pulses_in += take
            i += take
            if take == need:  # block complete
                block = self._buf[s - self._buf_start : s - self._buf_start + self.block]
                phi, rep = estimate_block(self.config, block, self.range_m, self.settings, s)
                stop = s + self._stitch.margin + self.hop
                ph = self._stitch.add(s, phi, rep, stop, self._lags(block))
                self._count(rep)
                outs.append(self._release(stop, ph))
                phases.append(ph)
                self._next_block += 1
                self._trim(s)  # keep this block: the last one at flush may reach back to it
        return self._finish(outs, phases)

    def flush(self) -> np.ndarray:
        """At the end of a stream: estimate a last block over the final pulses, release all."""
        self._flushed = True
        outs, phases = [], []
        total = self._buf_start + self._buf_len
        if self._stitch.committed < total:
            s = max(0, total - self.block)
            if s == self._stitch.prev_start:  # the last regular block already covers the end
                ph = self._stitch.extend(total)
            else:
                block = self._buf[s - self._buf_start : self._buf_len]
                phi, rep = estimate_block(self.config, block, self.range_m, self.settings, s)
                ph = self._stitch.add(s, phi, rep, total, self._lags(block))
                self._count(rep)
            outs.append(self._release(total, ph))
            phases.append(ph)
        self._buf_len = 0
        self._buf_start = total
        return self._finish(outs, phases)

    def _finish(self, outs, phases) -> np.ndarray:
        self.last_phase_rad = np.concatenate(phases) if phases else np.zeros(0)
        if outs:
            return np.concatenate(outs)
        return np.zeros((0, self.bins), np.complex64)
