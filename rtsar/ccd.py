"""The shifting CCD with mask: azimuth compression as a time-integrating correlator.

Psaltis & Wagner 1981, "Description of the processor" and eq. 5: every range-compressed pulse is
multiplied by a mask whose transmittance along the shift direction is the azimuth chirp (its rate
k1/y0 depends on range, so the mask is two-dimensional), added into the CCD, and the charge
shifts one row per pulse; the row that reaches the readout register after N pulses is a finished
image line.  Here a circular row index replaces the physical shift:

    g[p, r] = Σ_{k=0}^{N-1} line[p - N + 1 + k, r] · mask[k, r]            (1)

line p is the pulse at aperture position k = N-1 of the line that completes with it.  Output line
j = p - (N - 1) (p ≥ N - 1) is focused at the aperture centre, along-track
x = x_0 + (j + (N - 1)/2) d.  Each output sums exactly N terms from a zeroed row, so nothing can
drift however long the stream runs.

Three implementations of (1) behind one interface (push lines, get finished lines):
DirectCorrelator (the emulation: a numba shift register, O(N) per pixel per pulse, one line per
pulse), FFTCorrelator (overlap-save blocks, O(log N), lines leave in blocks of about N) and
PartitionedCorrelator (uniformly partitioned overlap-save, O(N/L) per pixel per pulse, lines leave
in blocks of L ≪ N).  correlate_reference is the NumPy float64 batch version all are tested
against.

Precision (``Processor.precision``): every correlator takes ``precision="complex64"`` (default:
float32 lines, mask and sums) or ``"complex128"`` (float64 throughout).  Measured relative RMS
error against correlate_reference (tests/test_precision.py: N = 2048, 64 range bins, a
unit-modulus mask / N, complex Gaussian lines; the tested tolerance in brackets): complex64
direct 8.1e-7, fft 1.5e-7, partitioned 1.9e-7 [1e-5]; complex128 direct 0 (the reference's
summation order), fft and partitioned 1.6e-15 [1e-12].  Range-migration correction (a
mask with a third, range-tap axis) lives in rtsar.migration and is built by make_correlator.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from typing import TYPE_CHECKING

import numba
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import fft as sfft

from .lens_plan import next_pow2, precision_dtype
from .params import Config, Processor
from .windows import window

if TYPE_CHECKING:  # rtsar.migration imports this module
    from .migration import MigrationMask

FFT_WORKERS = 2


def aperture_offsets_m(cfg: Config) -> np.ndarray:
    """Along-track offset of each aperture row from the aperture centre, x_k = (k-(N-1)/2)·d."""
    n = cfg.processor.aperture_pulses
    return (np.arange(n) - 0.5 * (n - 1)) * cfg.geometry.along_track_step_m


def design_mask(cfg: Config, range_m: np.ndarray) -> np.ndarray:
    """Mask[k, r] (complex128): conjugate of the expected azimuth phase history, windowed.

    The expected phase of a scatterer at closest-approach range R seen from offset x_k is
    -4π/λ·(sqrt(R² + x_k²) - R) (exact range history; Psaltis eq. 2 is its parabolic limit
    k1/y0·x²).  With ``per_bin_mask`` each range column uses its own R (the k1/y0 dependence);
    otherwise every column uses the range centre.  Scaled by 1/N, so a unit-amplitude history
    compresses to a unit peak with the rectangular window.  Phase formed in float64, reduced
    mod 2π before the exponential.
    """
    proc = cfg.processor
    x = aperture_offsets_m(cfg)[:, None]
    if proc.per_bin_mask:
        r = np.asarray(range_m, dtype=np.float64)[None, :]
    else:
        centre = proc.range_centre_m or cfg.geometry.slant_range_m
        r = np.full((1, len(range_m)), float(centre))
    # sqrt(R² + x²) - R = x² / (sqrt(R² + x²) + R): no cancellation for x ≪ R.
    excess_m = x * x / (np.sqrt(r * r + x * x) + r)
    cycles = np.mod(2.0 * excess_m / cfg.geometry.wavelength_m, 1.0)
    w = window(proc.azimuth_window, proc.aperture_pulses)[:, None]
    return w * np.exp(2j * math.pi * cycles) / proc.aperture_pulses


def correlate_reference(lines: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Float64 batch evaluation of eq. (1): lines[P, Nr] → image[P-N+1, Nr] (complex128)."""
    lines = np.asarray(lines, dtype=np.complex128)
    mask = np.asarray(mask, dtype=np.complex128)
    n = mask.shape[0]
    if lines.ndim != 2 or lines.shape[1] != mask.shape[1]:
        raise ValueError(f"lines must be [pulses, {mask.shape[1]}], got {lines.shape}")
    if lines.shape[0] < n:
        return np.zeros((0, mask.shape[1]), np.complex128)
    windows = sliding_window_view(lines, n, axis=0)  # [P-N+1, Nr, N]
    return np.einsum("prk,kr->pr", windows, mask)


class Correlator(ABC):
    """Common interface: push range-compressed lines, receive finished image lines.

    ``precision`` ("complex64" or "complex128", see Processor.precision) sets ``dtype``: the type
    lines are cast to by ``_check`` and the type of every line returned.  Subclasses written
    before the knob existed call ``super().__init__(mask)`` and stay complex64.
    """

    def __init__(self, mask: np.ndarray, precision: str = "complex64"):
        mask = np.asarray(mask)
        if mask.ndim != 2 or mask.shape[0] < 2:
            raise ValueError("mask must be [N >= 2, range_bins]")
        self.aperture = mask.shape[0]
        self.range_bins = mask.shape[1]
        self.precision = precision
        self.dtype = precision_dtype(precision)
        self.pulses_in = 0
        self.lines_out = 0

    def _check(self, lines: np.ndarray) -> np.ndarray:
        lines = np.asarray(lines)
        if lines.ndim != 2 or lines.shape[1] != self.range_bins:
            raise ValueError(f"lines must be [pulses, {self.range_bins}], got {lines.shape}")
        return np.ascontiguousarray(lines, dtype=self.dtype)

    def _no_lines(self) -> np.ndarray:
        return np.zeros((0, self.range_bins), self.dtype)

    @abstractmethod
    def push(self, lines: np.ndarray) -> np.ndarray:
        """Add lines[pulse, range_bin]; return the image lines they completed."""

    def flush(self) -> np.ndarray:
        """Emit every line whose pulses have all arrived (nothing is ever held back after this)."""
        return self._no_lines()


@numba.njit(parallel=True, nogil=True, cache=True)
def _shift_register(acc, mask_rev, head, lines, out):  # pragma: no cover - compiled
    # acc[r, slot]: slot (head + j) % N completes after j more pulses;
    # mask_rev[r, j] = mask[N-1-j, r].
    # For each pulse b:  acc[r, (head+j)%N] += line[b, r] * mask[N-1-j, r]  for all j,
    # then acc[r, head] is the finished line, the row is zeroed and head advances (the shift).
    n = acc.shape[1]
    for r in numba.prange(acc.shape[0]):
        h = head
        a = acc[r]
        m = mask_rev[r]
        for b in range(lines.shape[0]):
            v = lines[b, r]
            split = n - h
            for j in range(split):
                a[h + j] += v * m[j]
            for j in range(split, n):
                a[h + j - n] += v * m[j]
            out[b, r] = a[h]
            a[h] = 0
            h += 1
            if h == n:
                h = 0


class DirectCorrelator(Correlator):
    """The CCD emulation: a circular shift register of N rows, one finished line per pulse.

    Each output sums its N products in the register's precision, in aperture order: relative
    RMS error 8.1e-7 in complex64 (N = 2048: sequential rounding grows like sqrt(N)·6e-8) and
    below 1e-15 in complex128 (module docstring; tested to 1e-5 and 1e-12).
    """

    def __init__(self, mask: np.ndarray, precision: str = "complex64"):
        super().__init__(mask, precision)
        self._mask_rev = np.ascontiguousarray(np.asarray(mask)[::-1].T, dtype=self.dtype)
        self._acc = np.zeros((self.range_bins, self.aperture), self.dtype)
        self._head = 0
        # Compile (or load from numba's cache) now, on scratch arrays: the first real push then
        # costs what every push costs.
        scratch = np.zeros((1, 2), self.dtype)
        _shift_register(scratch.copy(), scratch.copy(), 0, scratch[:, :1], scratch[:, :1].copy())

    def push(self, lines: np.ndarray) -> np.ndarray:
        lines = self._check(lines)
        out = np.empty_like(lines)
        if len(lines):
            _shift_register(self._acc, self._mask_rev, self._head, lines, out)
        self._head = (self._head + len(lines)) % self.aperture
        # Lines completing before the N-th pulse saw a partial aperture: not emitted.
        skip = max(0, min(len(lines), self.aperture - 1 - self.pulses_in))
        self.pulses_in += len(lines)
        out = out[skip:]
        self.lines_out += len(out)
        return out


class FFTCorrelator(Correlator):
    """Overlap-save evaluation of eq. (1): lines leave in blocks of ``block_lines``.

    Eq. (1) is the convolution g = line ⊛ h with h[q] = mask[N-1-q]; each block transforms the
    last N-1 lines plus up to B new ones (FFT length M = N - 1 + B, a power of two) along
    azimuth, multiplies by H = DFT(h) per range column and keeps the B fully covered outputs.
    Transforms run in the correlator's precision (H is formed in float64 and cast): relative
    RMS error 1.5e-7 in complex64 and 1.6e-15 in complex128 (N = 2048; tested to 1e-5 and
    1e-12).
    """

    def __init__(
        self, mask: np.ndarray, fft_length: int | None = None, precision: str = "complex64"
    ):
        super().__init__(mask, precision)
        n = self.aperture
        m = fft_length or next_pow2(2 * n)
        if m < n or m & (m - 1):
            raise ValueError(f"fft_length must be a power of two >= N = {n}")
        self.fft_length = m
        self.block_lines = m - n + 1
        h = np.zeros((m, self.range_bins), np.complex128)
        h[:n] = np.asarray(mask, dtype=np.complex128)[::-1]
        self._H = sfft.fft(h, axis=0).astype(self.dtype)
        self._window = np.zeros((m, self.range_bins), self.dtype)  # history + new lines
        self._filled = n - 1  # rows of _window holding data (history starts as zeros)
        self._pending = 0  # new lines in the window not yet emitted

    def _run_block(self) -> np.ndarray:
        n, b = self.aperture, self._pending
        spec = sfft.fft(self._window, axis=0, workers=FFT_WORKERS, overwrite_x=False)
        spec = self._filter(spec)
        y = sfft.ifft(spec, axis=0, workers=FFT_WORKERS, overwrite_x=True)
        out = y[n - 1 : n - 1 + b].astype(self.dtype)
        # Keep the last N-1 lines as history for the next block.
        end = n - 1 + b
        self._window[: n - 1] = self._window[end - (n - 1) : end]
        self._window[n - 1 :] = 0
        self._pending = 0
        # Skip outputs whose aperture is incomplete (pulses before the N-th).
        first_pulse = self.pulses_in - b
        skip = max(0, min(b, n - 1 - first_pulse))
        out = out[skip:]
        self.lines_out += len(out)
        return out

    def _filter(self, spec: np.ndarray) -> np.ndarray:
        """The block's spectrum times H, per range column (a subclass may filter otherwise)."""
        spec *= self._H
        return spec

    def push(self, lines: np.ndarray) -> np.ndarray:
        lines = self._check(lines)
        outs = []
        i = 0
        while i < len(lines):
            take = min(len(lines) - i, self.block_lines - self._pending)
            row = self.aperture - 1 + self._pending
            self._window[row : row + take] = lines[i : i + take]
            self._pending += take
            self.pulses_in += take
            i += take
            if self._pending == self.block_lines:
                outs.append(self._run_block())
        return np.concatenate(outs) if outs else self._no_lines()

    def flush(self) -> np.ndarray:
        # Outputs are causal (line p needs pulses ≤ p), so a partial block is exact: the
        # zero rows after the pending lines only feed outputs that are discarded.
        if self._pending == 0:
            return self._no_lines()
        return self._run_block()


@numba.njit(nogil=True, cache=True)
def _mac_group(h, d, newest, y):  # pragma: no cover - compiled
    # One group of range columns:  y = Σ_{p<P} H_p · X_{newest-p},  h[p, :] = H_p and
    # d[k mod P, :] = X_k (the delay line), the G columns' 2L frequencies side by side.
    # Partitions go in pairs: half the loads and stores of y.
    parts = h.shape[0]
    y[:] = 0
    s = newest % parts
    p = 0
    while p + 1 < parts:
        s1 = s - 1 if s > 0 else parts - 1
        h0, h1, x0, x1 = h[p], h[p + 1], d[s], d[s1]
        for f in range(y.shape[0]):
            y[f] += h0[f] * x0[f] + h1[f] * x1[f]
        s = s1 - 1 if s1 > 0 else parts - 1
        p += 2
    if p < parts:
        h0, x0 = h[p], d[s]
        for f in range(y.shape[0]):
            y[f] += h0[f] * x0[f]


@numba.njit(parallel=True, nogil=True, cache=True)
def _enter_and_correlate(H, fdl, spec, first, acc):  # pragma: no cover - compiled
    # For new block k = first + b: X_k = spec[b] enters the delay line at slot k mod P (over
    # X_{k-P}, which no output needs any more), then acc[b] = Y_k = Σ_{p<P} H_p · X_{k-p}.
    # H[g, p, :] and fdl[g, slot, :] hold group g of G range columns (G·2L values per
    # partition): each thread streams its own groups, whose data serve all the blocks of a call
    # from cache, and the inner loop runs over G·2L values, not 2L.
    parts = H.shape[1]
    for g in numba.prange(H.shape[0]):
        for b in range(spec.shape[0]):
            k = first + b
            fdl[g, k % parts] = spec[b, g]
            _mac_group(H[g], fdl[g], k, acc[b, g])


@numba.njit(parallel=True, nogil=True, cache=True)
def _gather_lines(acc, first, out):  # pragma: no cover - compiled
    # out[j, :] = output line first + j of the blocks: acc[b, r, L:2L] holds the L outputs of
    # block b (the last half of its inverse transform).  One output line per iteration: the
    # writes are contiguous.
    step = acc.shape[2] // 2
    for j in numba.prange(out.shape[0]):
        b, i = divmod(first + j, step)
        y = acc[b]
        line = out[j]
        for r in range(line.shape[0]):
            line[r] = y[r, step + i]


class PartitionedCorrelator(Correlator):
    """Uniformly partitioned overlap-save evaluation of eq. (1): lines leave in blocks of L.

    The low-latency convolution of long audio filters (overlap-save with the filter cut into
    equal partitions and a frequency-domain delay line; Gardner 1995, "Efficient convolution
    without input-output delay", uniform case): the N taps of h[q] = mask[N-1-q] form
    P = ceil(N/L) partitions h_p[q] = h[pL + q] of L taps (the last one zero-padded).  Per block
    k of L new lines, X_k = DFT_2L([block k-1, block k]) along azimuth per range column joins a
    ring of the last P input spectra, and

        Y_k = Σ_{p=0}^{P-1} H_p · X_{k-p},     H_p = DFT_2L([h_p, 0_L]),

    whose inverse transform holds the L outputs of block k in its last L samples.  A line leaves
    at most L - 1 pulses after its last pulse arrives, plus the block's compute time; the cost is
    2N/L complex multiply-adds per pixel per line (N for DirectCorrelator) and two 2L-point
    transforms per pixel per L lines.  ``block_lines`` = L: a power of two in [1, N].
    Relative RMS error 1.9e-7 in complex64 and 1.6e-15 in complex128 (N = 2048, L = 16; tested
    to 1e-5 and 1e-12).
    """

    def __init__(self, mask: np.ndarray, block_lines: int = 16, precision: str = "complex64"):
        super().__init__(mask, precision)
        n, bins, lb = self.aperture, self.range_bins, block_lines
        if not (isinstance(lb, int) and 1 <= lb <= n and not lb & (lb - 1)):
            raise ValueError(f"block_lines must be a power of two in [1, N = {n}], got {lb!r}")
        self.block_lines = lb
        self.partitions = parts = -(-n // lb)
        width = 2 * lb
        # Range columns go in groups of G (the last one zero-padded) for the multiply-adds.
        group = min(max(16, 256 // lb), 64, bins)
        groups = -(-bins // group)
        taps = np.zeros((parts * lb, groups * group), np.complex128)
        taps[:n, :bins] = np.asarray(mask, dtype=np.complex128)[::-1]
        h = np.zeros((groups, group, parts, width), np.complex128)
        h[..., :lb] = taps.reshape(parts, lb, groups, group).transpose(2, 3, 0, 1)
        # 1/2L folded into H: the inverse transforms then run unnormalised (norm="forward").
        h = sfft.fft(h, axis=-1) / width
        # H[g, p, i·2L + f] = H_p[f] of range column g·G + i.
        self._H = np.ascontiguousarray(h.transpose(0, 2, 1, 3), dtype=self.dtype)
        self._H = self._H.reshape(groups, parts, group * width)
        self._fdl = np.zeros_like(self._H)  # ring of the last P input spectra, same layout
        # Pushes are correlated up to 128 lines at a time: each group's H and delay line then
        # serve several blocks from cache.
        max_blocks = max(1, 128 // lb)
        self._lines = np.zeros(((max_blocks + 1) * lb, bins), self.dtype)
        # _windows[b, r, :] = _lines[b·L : b·L + 2L, r]: block b's overlap-save input (a view).
        self._windows = sliding_window_view(self._lines, width, axis=0)[::lb]
        # Transforms and sums: [block, range column (padded), frequency].
        self._spec = np.zeros((max_blocks, groups * group, width), self.dtype)
        self._acc = np.zeros_like(self._spec)
        self._group_shape = (groups, group * width)
        # Many short transforms (1200 of 32 points: 70 µs) run faster on one thread than on two,
        # which would also meet numba's worker still spinning after the previous kernel.
        self._workers = FFT_WORKERS if width >= 256 else 1
        self._pending = 0  # new lines in _lines after the previous block (rows lb...)
        self._flushed = 0  # of the pending lines, those flush() has emitted already
        self._blocks = 0  # blocks entered into the delay line
        # Compile (or load from numba's cache) the kernels, plan the transforms and touch every
        # buffer now: the first real push then costs what every push costs.  (Blocks of zeros
        # leave all state zero.)
        self._correlate(max_blocks)
        _gather_lines(self._acc[:1], 0, np.zeros((1, bins), self.dtype))

    def _correlate(self, count: int) -> np.ndarray:
        """Enter the ``count`` blocks after _lines[0:L]; return their Y (outputs: [:, :, L:])."""
        spec, acc = self._spec[:count], self._acc[:count]
        np.copyto(spec[:, : self.range_bins], self._windows[:count])
        sfft.fft(spec, axis=-1, workers=self._workers, overwrite_x=True)  # X_k, in place
        grouped = (count, *self._group_shape)
        _enter_and_correlate(
            self._H, self._fdl, spec.reshape(grouped), self._blocks, acc.reshape(grouped)
        )
        return sfft.ifft(acc, axis=-1, norm="forward", workers=self._workers, overwrite_x=True)

    def _emit(self, acc: np.ndarray, stop: int) -> np.ndarray:
        """Lines 0 .. stop-1 of the blocks in ``acc`` less those given before or incomplete."""
        # Lines completing before the N-th pulse saw a partial aperture: not emitted.
        start = max(self._flushed, self.aperture - 1 - self._blocks * self.block_lines)
        out = np.empty((max(0, stop - start), self.range_bins), self.dtype)
        if len(out):
            _gather_lines(acc, start, out)
        self.lines_out += len(out)
        return out

    def push(self, lines: np.ndarray) -> np.ndarray:
        lines = self._check(lines)
        lb = self.block_lines
        room = len(self._lines) - lb
        outs = []
        i = 0
        while i < len(lines):
            take = min(len(lines) - i, room - self._pending)
            row = lb + self._pending
            self._lines[row : row + take] = lines[i : i + take]
            self._pending += take
            self.pulses_in += take
            i += take
            blocks = self._pending // lb
            if blocks and (self._pending == room or i == len(lines)):
                outs.append(self._emit(self._correlate(blocks), blocks * lb))
                self._blocks += blocks
                # The last complete block becomes the previous one; a partial block follows.
                keep = self._pending - blocks * lb
                self._lines[: lb + keep] = self._lines[blocks * lb : (blocks + 1) * lb + keep]
                self._pending, self._flushed = keep, 0
        if len(outs) == 1:
            return outs[0]
        return np.concatenate(outs) if outs else self._no_lines()

    def flush(self) -> np.ndarray:
        # The filter is causal (line p needs pulses ≤ p), so the partial block, zero-padded, gives
        # its lines exactly (zeros, not stale rows: through the transforms those would add their
        # rounding, or a NaN, to every line).  Nothing is committed: its X_k lands in the
        # delay-line slot that the complete block will overwrite, so a later push continues the
        # stream unchanged.
        lb, pending = self.block_lines, self._pending
        if pending == self._flushed:
            return self._no_lines()
        self._lines[lb + pending : 2 * lb] = 0
        out = self._emit(self._correlate(1), pending)
        self._flushed = pending
        return out


CORRELATORS = Processor.CORRELATORS


def make_correlator(
    kind: str,
    mask: np.ndarray | MigrationMask,
    fft_length: int | None = None,
    *,
    partition_lines: int = 16,
    precision: str = "complex64",
) -> Correlator:
    """The correlator named by ``Processor.correlator`` (one of CORRELATORS).

    ``mask`` is a 2-D mask[k, r] (design_mask) or a rtsar.migration.MigrationMask (from
    design_migration_mask, ``Processor.range_migration_taps`` > 0): then, for "fft", one
    overlap-save correlator that filters each block with every range tap
    (rtsar.migration.FFTMigrationCorrelator), and for the other kinds one correlator per range
    tap, summed (rtsar.migration.MigrationCorrelator).
    """
    if kind not in CORRELATORS:
        raise ValueError(f"correlator must be one of {CORRELATORS}, got {kind!r}")
    from .migration import (  # it imports this module
        FFTMigrationCorrelator,
        MigrationCorrelator,
        MigrationMask,
    )

    if isinstance(mask, MigrationMask):
        if kind == "fft":
            return FFTMigrationCorrelator(mask, fft_length, precision)
        taps = [
            make_correlator(
                kind, m, fft_length, partition_lines=partition_lines, precision=precision
            )
            for m in mask.tap_masks()
        ]
        return MigrationCorrelator(mask, taps)
    if kind == "direct":
        return DirectCorrelator(mask, precision)
    if kind == "fft":
        return FFTCorrelator(mask, fft_length, precision)
    return PartitionedCorrelator(mask, partition_lines, precision)
