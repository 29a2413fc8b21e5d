"""PGA in the stream: the block layout and the stitching of block estimates into one phase.

Streaming.  Blocks of P pulses start every H (default P/2).  Each block's estimate is aligned to
the previous one over their P - H common pulses (constant and slope, ``_align``) and commits the
H pulses in its middle, s_b + E … s_b + E + H, E = (P - H)/2 (block 0 from pulse 0): a pulse
leaves (P + H)/2 pulses after arriving.  ``flush`` runs one last block over the final P pulses; a
stream shorter than ``min_pulses`` is passed through ("short_block").  Memory: P + H lines.
``pga_batch`` is the float64 reference of the same layout on a recording; ``estimate_block`` is
Crouch's single-block PGA (batch mode on one recorded block).  Placement: between the AO lens and
the CCD; a per-pulse phase commutes with range compression, so raw shots could take it as well.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .doppler import MAX_EXCESS_COHERENCE, CentroidLags
from .estimator import BlockReport


def align_blocks(delta: np.ndarray) -> tuple[float, float]:
    """Constant a and slope c with δ_i ≈ a + c·i (mod 2π), i = 0, 1, … (a phase difference).

    The slope is first found as the peak of the periodogram of e^{iδ}
    (zero-padded 16×; the maximum-likelihood frequency of a phasor in noise, insensitive to 2π
    steps), then refined with the constant by least squares on the unwrapped remainder.
    """
    delta = np.asarray(delta, np.float64)
    n = delta.size
    if n == 0:
        return 0.0, 0.0
    i = np.arange(n)
    z = np.exp(1j * delta)
    nfft = 16 * (1 << max(0, (n - 1).bit_length()))
    k = int(np.argmax(np.abs(np.fft.fft(z, nfft))))
    c = 2 * math.pi * (k if k < nfft // 2 else k - nfft) / nfft
    a = float(np.angle(np.sum(z * np.exp(-1j * c * i))))
    rest = np.unwrap(np.angle(z * np.exp(-1j * (a + c * i))))
    if n >= 2:
        t = i - 0.5 * (n - 1)
        dc = float(np.dot(t, rest) / np.dot(t, t))
        a += float(rest.mean()) - dc * 0.5 * (n - 1)
        c += dc
    return a, c


class Stitcher:
    """Turns block estimates into one continuous per-pulse phase (the layout of the docstring).

    PGA adds no linear phase of its own: each block's estimate has its constant and slope
    removed (rtsar.focus.pga.estimator), and the stitching only gives it the constant and slope
    that continue the previous block's phase over their common pulses.  The first estimated
    block therefore sets the stream's reference (no slope over it); after a block without an
    estimate (its phase held constant) the next is joined by a constant alone.
    """

    def __init__(self, block: int, hop: int, doppler_gain: float = 0.0,
                 min_doppler_coherence: float = 0.05):  # fmt: skip
        self.block, self.hop = block, hop
        self.doppler_gain, self.min_doppler_coherence = doppler_gain, min_doppler_coherence
        self.doppler_slope_rad = 0.0  # the last anchored block's residual slope (rad/pulse)
        self.doppler_anchored = False  # whether the last block was anchored
        self.prev_anchored = False
        self.margin = (block - hop) // 2
        self.committed = 0  # pulses whose phase is final
        self.last_phase = 0.0  # phase of the last committed pulse (held on failure)
        self.prev_start = None  # previous block's first pulse and its aligned phase
        self.prev_phase = None
        self.prev_estimated = False

    def next_start(self, index: int) -> int:
        return index * self.hop

    def add(
        self,
        start: int,
        phase: np.ndarray,
        report: BlockReport,
        stop: int,
        lags: CentroidLags | None = None,
    ) -> np.ndarray:
        """Align a block's phase to the previous block's; return phases of [committed, stop).

        Over the common pulses δ = previous - phase is fitted by a + c·i (``align_blocks``);
        c is taken only when the previous block had an estimate of its own.  Then the Doppler
        anchor (rtsar.focus.pga.doppler): on an estimated block whose clutter ``lags`` are
        coherent as clutter is (≥ ``min_doppler_coherence`` and half the antenna's ρ(1), at most
        ρ(1) + ``MAX_EXCESS_COHERENCE``), ``doppler_gain`` of
        the residual centroid slope s is added as s·(i - i₀), i₀ the first uncommitted pulse,
        so the committed phase stays continuous and the next block inherits the slope.
        """
        n = phase.size
        if not report.estimated:
            aligned = np.full(n, self.last_phase)
        elif self.prev_start is None:
            aligned = phase.copy()
        elif self.prev_start + self.prev_phase.size <= start:  # no overlap (hop = block)
            aligned = phase - phase[0] + self.last_phase
        else:
            delta = (
                self.prev_phase[start - self.prev_start :]
                - phase[: self.prev_start + self.prev_phase.size - start]
            )
            if self.prev_estimated:
                a, c = align_blocks(delta)
            else:
                a, c = float(np.angle(np.sum(np.exp(1j * delta)))), 0.0
            aligned = phase + a + c * np.arange(n)
        self.prev_anchored = self.doppler_anchored and self.prev_estimated
        self.doppler_anchored = False
        if report.estimated and lags is not None:
            slope, coherence = lags.residual(aligned)
            rho = lags.expected_coherence
            floor = max(self.min_doppler_coherence, 0.5 * rho)
            # Clutter and noise cannot be more coherent than the beam makes them: above ρ(1)
            # the rows hold a point's history (measured 0.95 on psaltis-jpl, ρ(1) = 0.25).
            if rho > 0 and floor <= coherence <= rho + MAX_EXCESS_COHERENCE:
                pivot = max(self.committed - start, 0)
                # The first anchored block (or the first after one without an estimate) takes
                # the whole slope; later ones doppler_gain of it (a first-order tracking loop).
                gain = self.doppler_gain if self.prev_anchored else 1.0
                aligned = aligned + gain * slope * (np.arange(n) - pivot)
                self.doppler_slope_rad, self.doppler_anchored = slope, True
        self.prev_estimated = report.estimated
        self.prev_start, self.prev_phase = start, aligned
        return self.extend(stop)

    def annotate(self, report: BlockReport) -> BlockReport:
        """The block's report with what the Doppler anchor did on it (the last ``add``)."""
        slope = self.doppler_slope_rad if self.doppler_anchored else 0.0
        return replace(report, doppler_anchored=self.doppler_anchored, doppler_slope_rad=slope)

    def extend(self, stop: int) -> np.ndarray:
        """Commit pulses [committed, stop) from the last block's aligned phase."""
        out = self.prev_phase[self.committed - self.prev_start : stop - self.prev_start]
        self.committed = stop
        if out.size:
            self.last_phase = float(out[-1])
        return out
