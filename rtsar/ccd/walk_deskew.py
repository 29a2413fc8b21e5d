"""A squinted beam's range walk taken out before the CCD: the lines written into a turning ring.

(M2) of rtsar.ccd.migration reads aperture row k of column r at r + Δr_k(r) (M1).  A squinted
beam's Δr is almost linear in k, a walk of w bins a pulse (RADARSAT-1: w = 0.0335, 24 cells
across its 716 rows) plus a constant c(r) of each column, with a curvature left over of a
fraction of a cell (RADARSAT-1: at most 0.45 cell, at the aperture's ends, 0.06 cell RMS over
the window's energy).  Fitted by least squares over the rows, weighted by the window's energy,

    Δr_k(r) = w·k + c(r) + ε_k(r),                                                       (W1)

the walk is one shift of each whole pulse: written into a ring of W ≥ bins columns at

    ring_n[j] = line_n(j + s_n),   s_n = w·(n + N - 1) + c_mid   (mod W; zero beyond the swath)
                                                                                         (W2)

every row of line p's aperture (pulse n = p - N + 1 + k) reads ring column
j = r + c(r) - c_mid - w·p, one column for the whole aperture: a plain azimuth correlation of
each ring column (eq. 1), which the nonuniform correlator computes with head blocks from one
line.  Two things turn with the ring.  Line p's column r comes out of ring column
r + c(r) - c_mid - w·p, read with T taps (the unrotation).  And the range-dependent mask: ring
column j holds true column r(j) + w·p, so the correlator's mask is built for the ranges r(j)
(j = r + c(r) - c_mid; the guard's upper half holds the columns below the swath, j - W) and
turned by Q·round(w·m / Q) columns for a block whose lines centre on pulse m
(rtsar.ccd.tiled.mask_shift; Q = MASK_QUANTUM = 1), each line's mask then up to
δ = 1/2 + |w|·B/2 bins from its own.  A mask δ bins off errs by its phase's change with range:

    φ(k, R) = (4π/λ)(sqrt(R² + u_k²) - R) = φ0(R) + ψ(k, R),   φ0(R) = φ(R) at u = u_mid  (W3)

φ0 changes by 0.39 rad a bin at RADARSAT-1's squint (u_mid = 27.5 km): before it was taken out,
every line carried a sawtooth phase error of up to 0.36 rad, and a point whose line met a turn
of the mask moved 0.15 cell with an azimuth PSLR of -27 dB (a cold review).  So the mask holds
exp(-iφ0(R)) · mask(R) and each value read out of the ring gets exp(iφ0) back at its exact
range, r(j + w·p) (``constant_phase_cycles``; phase in float64, reduced mod 2π).  What the turn
leaves is ψ's change with range, linear in k: a shift in azimuth of about 0.02 cell a bin of δ
(walk_block_lines).  The guard of W - bins ≥ |w|·N + T + 2 + max|c - c_mid| columns holds
zeros, so an aperture near one edge never reads the other edge's lines.

What it leaves out is ε, the curvature (the accuracy this costs is measured against the exact
(M2), correlate_migration_reference, in tests/test_walk_deskew.py and on the RADARSAT-1 block);
what it saves is (M2)'s one correlation per bin offset (22 + T for RADARSAT-1) or the fft
correlator's overlap-save blocks (the Doppler-domain read, rtsar.ccd.doppler_migration, needs
blocks of hundreds of lines): lines leave in the nonuniform correlator's head blocks.  Both
interpolations read with the T-tap interpolator w_T of rtsar.ccd.migration
(Processor.range_migration_taps), its weights from a table of PHASES fractional positions.
No secondary range compression in the lens: the rows read each pulse's own compressed line,
as (M2)'s do (rtsar.lens.plan).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from . import tiled
from .base import Correlator, beam_look_back_m, design_mask
from .migration import MOST_CURVATURE_BINS, Walk, fit_walk, interpolation_weights
from .nonuniform import NonUniformCorrelator

MASK_QUANTUM = 1  # columns the mask turns at a time
PHASES = 256  # fractional positions of the interpolation table


def constant_phase_cycles(range_m: np.ndarray, look_back_m: float, wavelength_m: float):
    """φ0(R) / 2π of the module docstring, unreduced (float64): the mask's phase at the beam's
    centre offset u, 2 (sqrt(R² + u²) - R) / λ cycles (rtsar.ccd.base.design_mask's), formed
    as 2u² / (sqrt(R² + u²) + R) / λ, free of cancellation."""
    r = np.asarray(range_m, np.float64)
    u2 = float(look_back_m) ** 2
    return 2.0 * u2 / (np.sqrt(r * r + u2) + r) / wavelength_m


def ring_width(bins: int, walk: Walk, aperture: int, taps: int) -> int:
    """W: bins and the zero guard of the module docstring, widened to the width of the
    correlator's tiles (rtsar.ccd.tiled.tile_columns), so that the mask turns across all of
    them."""
    spread = float(np.abs(walk.offset_bins - walk.offset_mid_bins).max())
    guard = math.ceil(abs(walk.bins_per_pulse) * aperture + taps + 2 + spread)
    width = bins + guard
    while True:
        tile = tiled.tile_columns(width)
        padded = -(-width // tile) * tile
        if padded == width:
            return width
        width = padded


def weight_table(taps: int, real) -> np.ndarray:
    """table[q, j]: w_T's weight of read first + j for a read at first + T/2 - q / PHASES, with
    first = ⌈pos - T/2⌉ (interpolation_weights' layout, as rtsar.ccd.doppler_migration's)."""
    _, table = interpolation_weights(0.5 * taps - np.arange(PHASES) / PHASES, taps)
    return table.astype(real)


@numba.njit(nogil=True, cache=True)
def _first_and_row(pos, taps, phases):  # pragma: no cover - compiled
    # The first read ⌈pos - T/2⌉ and the weight table's row for a read at ``pos``.
    first = math.ceil(pos - 0.5 * taps)
    q = int(round((first + 0.5 * taps - pos) * phases))
    if q == phases:  # pos = first + T/2 - 1 exactly: the same reads from one bin lower
        return first - 1, 0
    return first, q


@numba.njit(nogil=True, cache=True)
def _write_rows(lines, first_pulse, w, s0, table, pad, ring):  # pragma: no cover - compiled
    # ring[i, j] = line_i read at j + s_n (W2), n = first_pulse + i, modulo W; reads at and
    # beyond the swath's bins are zeros.  One fraction a row: its weights once per row, over
    # the row turned into ``pad`` (W + T values) first, so the taps read contiguous values.
    count, bins = lines.shape
    width = ring.shape[1]
    taps, phases = table.shape[1], table.shape[0]
    for i in range(count):
        s = w * (first_pulse + i) + s0
        s -= math.floor(s / width) * width  # s_n mod W in float64: bounded on a stream
        first, q = _first_and_row(s, taps, phases)
        src = lines[i]
        c = first % width  # then counted up, wrapped by a subtraction: no division a sample
        for j in range(width + taps):
            pad[j] = src[c] if c < bins else 0
            c += 1
            if c == width:
                c = 0
        wt = table[q]
        row = ring[i]
        for j in range(width):  # the taps' loop outside: the columns' loop vectorises
            row[j] = pad[j] * wt[0]
        for t in range(1, taps):
            for j in range(width):
                row[j] += pad[j + t] * wt[t]


@numba.njit(nogil=True, cache=True)
def _read_rows(
    ring_out, first_line, w, offset, by_tap, phase, step, mean_step, pad, k0, qs, out
):  # pragma: no cover
    # out[i, r] = ring_out[i] read at r + offset[r] - w·p, p = first_line + i, modulo W: the
    # row turned by ⌊w·p⌋ into ``pad`` first, each value given back its phase φ0 there
    # (``phase``, ``step``: exp(iφ0) and φ0's step to the next column at pad index k, read at
    # the fraction f of the turn: exp(iφ0 + i·f·step), the step's mean (``mean_step``) in one
    # exponential and its departure from it, at most a few mrad, to second order); each
    # column's read its own fraction (offset).  by_tap[t, q]: the weight table by tap; k0, qs:
    # each column's first read and table row, scratch.
    count, bins = out.shape
    width = ring_out.shape[1]
    taps, phases = by_tap.shape[0], by_tap.shape[1]
    span = pad.shape[0]
    lo = (span - bins - taps) // 2  # pad[k] holds the ring column of mask column k - lo
    for i in range(count):
        turn = w * (first_line + i)
        turn -= math.floor(turn / width) * width  # w·p mod W in float64: bounded on a stream
        base = math.floor(turn)
        frac = turn - base
        g = complex(math.cos(frac * mean_step), math.sin(frac * mean_step))
        src = ring_out[i]
        c, k = (-lo - base) % width, 0
        while k < span:  # contiguous runs of the ring (at most two): the loop vectorises
            run = min(span - k, width - c)
            for t in range(run):
                e = frac * (step[k + t] - mean_step)
                pad[k + t] = src[c + t] * (phase[k + t] * g * complex(1.0 - 0.5 * e * e, e))
            k, c = k + run, 0
        row = out[i]
        for r in range(bins):  # each column's first read and weights, then the taps' passes
            first, q = _first_and_row(r + offset[r] - frac, taps, phases)
            k0[r] = first + lo
            qs[r] = q
        for r in range(bins):
            row[r] = pad[k0[r]] * by_tap[0, qs[r]]
        for t in range(1, taps):
            wt = by_tap[t]
            for r in range(bins):
                row[r] += pad[k0[r] + t] * wt[qs[r]]


def walk_block_lines(w: float, head_lines: int, max_block_lines: int) -> int:
    """The longest block the turning mask allows: a block of B lines shares one turn of the mask,
    so its lines' columns drift up to |w|·B/2 bins from it, each bin about 0.02 cell of azimuth
    (module docstring).  RADARSAT-1's points at starts 0-29 pulses apart (2026-11-29): tail
    blocks of 32, up to 0.02 cell off, azimuth PSLR -39.2 to -42.8 dB (the exact (M2): -40 to
    -42.5); of 16, up to 0.011 cell, the correlator alone 20-30 % slower.  The power of two
    nearest 1/|w| (RADARSAT-1: 32), within [head_lines, max_block_lines]."""
    if w == 0:
        return max_block_lines
    nearest = 1 << max(0, round(math.log2(1.0 / abs(w))))
    return max(head_lines, min(max_block_lines, nearest))


class WalkDeskewCorrelator(Correlator):
    """(W1)-(W3): the lines shifted into a turning ring, correlated there by the nonuniform
    correlator (head blocks of ``head_lines``) with the mask less its constant phase, the lines
    read back out of it with that phase given back.

    ``taps`` T: the interpolator of both reads (Processor.range_migration_taps); the others are
    NonUniformCorrelator's.  Output timing is the nonuniform correlator's.
    """

    def __init__(
        self,
        cfg,
        range_m: np.ndarray,
        taps: int,
        head_lines: int = 16,
        max_block_lines: int = 128,
        precision: str = "complex64",
        threaded: bool | None = None,
    ):
        if not (isinstance(taps, int) and taps >= 1):
            raise ValueError(f"taps must be an integer >= 1, got {taps!r}")
        mask = design_mask(cfg, range_m)
        super().__init__(mask, precision)
        n, bins = mask.shape
        self.walk = fit_walk(cfg, range_m)
        if self.walk.curvature_max_bins > MOST_CURVATURE_BINS:
            raise ValueError(
                f"the walk's ring leaves out the aperture's curvature, here "
                f"{self.walk.curvature_max_bins:.2f} bins (at most {MOST_CURVATURE_BINS:g}): "
                "--range-migration-domain time, or --correlator fft with 'doppler'"
            )
        self.ring_columns = ring_width(bins, self.walk, n, taps)
        w = self.walk.bins_per_pulse
        ring_range_m = self._ring_range_m(range_m)
        # The mask without its constant phase φ0(R) (module docstring), given back on read-out.
        look_back_m = beam_look_back_m(cfg)
        phase_range_m = ring_range_m  # the range design_mask's phase takes for each column
        if not cfg.processor.per_bin_mask:  # its one range for every column: nothing turns
            centre_m = cfg.processor.range_centre_m or cfg.geometry.slant_range_m
            phase_range_m = np.full_like(ring_range_m, centre_m)
        cycles = constant_phase_cycles(phase_range_m, look_back_m, cfg.geometry.wavelength_m)
        wide = design_mask(cfg, ring_range_m) * np.exp(-2j * np.pi * np.mod(cycles, 1.0))
        self.inner = NonUniformCorrelator(
            wide,
            head_lines,
            walk_block_lines(w, head_lines, max_block_lines),
            precision,
            threaded,
            mask_rotation=(w, MASK_QUANTUM),
        )
        self.block_lines = self.inner.block_lines
        real = np.float32 if self.dtype == np.complex64 else np.float64
        self.taps = taps
        self._table = weight_table(taps, real)
        self._by_tap = np.ascontiguousarray(self._table.T)  # _read_rows' [tap, row]
        self._k0, self._qs = np.empty(bins, np.int64), np.empty(bins, np.int64)  # its scratch
        self._s0 = w * (n - 1) + self.walk.offset_mid_bins
        self._offset = (self.walk.offset_bins - self.walk.offset_mid_bins).astype(np.float64)
        # _read_rows' pad: the bins and, either side, the taps and the offsets' reach
        margin = taps + math.ceil(np.abs(self._offset).max()) + 2
        span = bins + 2 * margin + taps
        self._pad = np.zeros(span, self.dtype)
        self._write_pad = np.zeros(self.ring_columns + taps, self.dtype)  # _write_rows'
        mask_col = (np.arange(span) - (span - bins - taps) // 2) % self.ring_columns
        nxt = (mask_col + 1) % self.ring_columns
        self._phase = np.exp(2j * np.pi * np.mod(cycles[mask_col], 1.0)).astype(self.dtype)
        # φ0's step to the next column, formed from the cycles in float64 (no mod-2π jump);
        # across the guard's seam (outputs never read) set to the mean's
        step = 2.0 * np.pi * (cycles[nxt] - cycles[mask_col])
        seam = np.abs(step - np.median(step)) > 0.5
        self._step = np.where(seam, np.median(step), step)
        self._mean_step = float(self._step.mean())

    def _ring_range_m(self, range_m: np.ndarray) -> np.ndarray:
        """The range whose mask ring column j holds while the ring is unturned (line 0): the
        true column r with j = r + c(r) - c_mid, c extended linearly over the guard, whose
        upper half holds the columns below the swath (j - W: the near edge's apertures turn
        into it)."""
        bins = len(range_m)
        r = np.arange(bins, dtype=np.float64)
        j = r + self.walk.offset_bins - self.walk.offset_mid_bins
        cols = np.arange(self.ring_columns, dtype=np.float64)
        cols = np.where(cols < 0.5 * (bins + self.ring_columns), cols, cols - self.ring_columns)
        slope = (j[-1] - j[0]) / (bins - 1)
        true = np.interp(cols, j, r, left=np.nan, right=np.nan)
        true = np.where(
            np.isnan(true),
            np.where(cols < j[0], r[0] + (cols - j[0]) / slope, r[-1] + (cols - j[-1]) / slope),
            true,
        )
        step_m = (range_m[-1] - range_m[0]) / (bins - 1)
        return range_m[0] + true * step_m

    def _into_ring(self, lines: np.ndarray) -> np.ndarray:
        ring = np.empty((len(lines), self.ring_columns), self.dtype)
        w = self.walk.bins_per_pulse
        _write_rows(lines, self.pulses_in, w, self._s0, self._table, self._write_pad, ring)
        return ring

    def _out_of_ring(self, ring_out: np.ndarray) -> np.ndarray:
        out = np.empty((len(ring_out), self.range_bins), self.dtype)
        if len(out):
            w = self.walk.bins_per_pulse
            first = self.inner.lines_out - len(out) + self.aperture - 1  # its last pulse's index
            args = (self._offset, self._by_tap, self._phase, self._step, self._mean_step)
            _read_rows(ring_out, first, w, *args, self._pad, self._k0, self._qs, out)
        self.lines_out += len(out)
        return out

    def push(self, lines: np.ndarray) -> np.ndarray:
        lines = self._check(lines)
        ring = self._into_ring(lines)
        self.pulses_in += len(lines)
        return self._out_of_ring(self.inner.push(ring))

    def flush(self) -> np.ndarray:
        return self._out_of_ring(self.inner.flush())

    def close(self) -> None:
        self.inner.close()
