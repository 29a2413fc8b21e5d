"""Uniformly partitioned overlap-save: the correlation in blocks of L ≪ N lines (low latency)."""

from __future__ import annotations

import numba
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import fft as sfft

from .base import Correlator
from .fft import FFT_WORKERS

# Multiply-adds of one block (2·N·range bins, padded) from which the groups are shared among
# numba's threads: below, one thread keeps up (psaltis-jpl, 0.33 M: a push of 64 pulses in
# 1.1 ms here), and the threaded kernel would cost a first run more than it saves (2.6-3.2 s
# of CPU to compile against 1.2-1.7 s for one thread's).  psaltis-max (1.2 M) uses threads.
PARALLEL_MACS = 1 << 20


# _mac_group and _enter_group are inlined into the kernels that call them (numba's IR): one
# compilation a kernel, 2/3 of the CPU time of compiling the three apart on a first run.
@numba.njit(nogil=True, cache=True, inline="always")
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


@numba.njit(nogil=True, cache=True, inline="always")
def _enter_group(H, fdl, spec, first, acc, g):  # pragma: no cover - compiled
    # For new block k = first + b: X_k = spec[b] enters the delay line at slot k mod P (over
    # X_{k-P}, which no output needs any more), then acc[b] = Y_k = Σ_{p<P} H_p · X_{k-p}.
    # H[g, p, :] and fdl[g, slot, :] hold group g of G range columns (G·2L values per
    # partition): the group's data serve all the blocks of a call from cache, and the inner
    # loop runs over G·2L values, not 2L.
    parts = H.shape[1]
    for b in range(spec.shape[0]):
        k = first + b
        slot, x = fdl[g, k % parts], spec[b, g]
        for f in range(x.shape[0]):  # a loop: a slice copy would compile a shape-error message
            slot[f] = x[f]
        _mac_group(H[g], fdl[g], k, acc[b, g])


@numba.njit(nogil=True, cache=True)
def _enter_and_correlate(H, fdl, spec, first, acc):  # pragma: no cover - compiled
    # _enter_group over the groups on this thread (small plans: see PARALLEL_MACS).
    for g in range(H.shape[0]):
        _enter_group(H, fdl, spec, first, acc, g)


@numba.njit(parallel=True, nogil=True, cache=True)
def _enter_and_correlate_threads(H, fdl, spec, first, acc):  # pragma: no cover - compiled
    # The same, each thread streaming its own groups.
    for g in numba.prange(H.shape[0]):
        _enter_group(H, fdl, spec, first, acc, g)


@numba.njit(nogil=True, cache=True)
def _gather_lines(acc, first, out):  # pragma: no cover - compiled
    # out[j, :] = output line first + j of the blocks: acc[b, r, L:2L] holds the L outputs of
    # block b (the last half of its inverse transform).  One output line per iteration: the
    # writes are contiguous.  (A copy: one thread keeps up, and compiles and loads faster.)
    step = acc.shape[2] // 2
    for j in range(out.shape[0]):
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
        self.threaded = self._H.size >= PARALLEL_MACS
        self._kernel = _enter_and_correlate_threads if self.threaded else _enter_and_correlate
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
        self._kernel(self._H, self._fdl, spec.reshape(grouped), self._blocks, acc.reshape(grouped))
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
