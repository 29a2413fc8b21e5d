"""Overlap-save blocks along azimuth on tiles of range columns, in split real/imaginary layout.

The kernels of rtsar.ccd.nonuniform: every array is [tile, row, column-in-tile] with the
real and imaginary parts in separate arrays, so every operation runs over C contiguous columns
(one SIMD loop) and no transform needs a transpose.  A block of an overlap-save segment with
block B and P partitions (Gardner 1995; the notation of rtsar.ccd.partitioned):

1. the window of 2B lines [block k-1, block k] is loaded into the delay-line slot k mod P and
   transformed there by a decimation-in-frequency radix-2 FFT (natural order in, bit-reversed
   order out: no reordering pass);
2. Y_k = Σ_p H_p · X_{k-p} over the delay line, with H_p stored in the same bit-reversed order
   (the multiply is elementwise, so the order does not matter) and 1/2B folded in;
3. a decimation-in-time inverse FFT (bit-reversed in, natural out) whose last stage computes
   only the second half, the B outputs of block k, which are added (tail segments) into an
   accumulation ring or stored (the head segment) at the rows of the full output they serve.

Twiddles come from one float64-formed table of the largest size, cast to the precision.
"""

from __future__ import annotations

import numba
import numpy as np

LANES = 16  # float32 values in one AVX-512 register: a tile's width is a multiple of it
MOST_TILE_COLUMNS = 2048  # the widest tile (tile_columns)


def tile_columns(bins: int) -> int:
    """Range columns a tile for ``bins`` columns: all of them in one tile where they are at
    most MOST_TILE_COLUMNS (else equal tiles), rounded up to a multiple of LANES.

    The kernels' inner loops run along a tile's row, so their fixed costs (a row view, the
    vectorised loop's set-up and alias checks, a radix-2 butterfly's bookkeeping) fall on
    every row of every tile: with rows of 32 columns (the width before 2026-11-29) they took
    about a third of the time.  The nonuniform correlator alone, tiles of 32 against one
    tile, in separate processes alternated three times (2-core Intel Xeon, 2026-11-29),
    pulses/s: psaltis-max pushes of 64 lines 17.9-19.5k against 28.3-30.5k, of 16
    16.2-17.4k against 23.4-28.9k, of 4 13.8-17.3k against 19.0-21.8k; psaltis-jpl pushes of
    64 60.7-77.0k against 80.0-102.1k, of 1 20.2-31.1k against 27.2-32.4k; crouch-sal
    25.6-30.2k against 32.9-41.9k; tiny 308-373k against 396-422k.  Wider swaths (random
    masks, N = 512, two rounds): 2,048 bins, blocks of 16 and 128, pushes of 64, 10.0-11.6k
    against 16.7-17.2k; 4,096 bins (two tiles) 5.1-5.4k against 7.8-9.0k; 2,048 bins, blocks
    of 4, pushes of 4, 5.6-5.7k against 8.3-8.8k.  MOST_TILE_COLUMNS bounds a tile's rows for
    wider swaths; no width between 2,048 and 4,096 was compared."""
    if bins < 1:
        raise ValueError(f"bins must be >= 1, got {bins}")
    tiles = -(-bins // MOST_TILE_COLUMNS)
    per_tile = -(-bins // tiles)
    return -(-per_tile // LANES) * LANES


def twiddles(size: int, dtype) -> tuple[np.ndarray, np.ndarray]:
    """exp(-2πi j/size), j < size/2, formed in float64: (real, imaginary) in ``dtype``."""
    w = np.exp(-2j * np.pi * np.arange(max(1, size // 2)) / size)
    return w.real.astype(dtype), w.imag.astype(dtype)


def bit_reversed(n: int) -> np.ndarray:
    """The bit-reversal permutation of range(n), n a power of two."""
    bits = n.bit_length() - 1
    idx = np.arange(n)
    rev = np.zeros(n, np.int64)
    for b in range(bits):
        rev |= ((idx >> b) & 1) << (bits - 1 - b)
    return rev


def tile_spectra(taps: np.ndarray, block: int, tile: int, dtype) -> tuple[np.ndarray, np.ndarray]:
    """H[t, f, p, c] = DFT_2B([h_p, 0_B])[bitrev f] / 2B of range column t·C + c (split parts):
    for each frequency, the P partitions' values side by side (what the multiply-adds stream).

    ``taps`` [T, range]: the taps h[q] of the segment (float64 formed), P = ceil(T/B).
    """
    count, bins = taps.shape
    parts, width = -(-count // block), 2 * block
    tiles = -(-bins // tile)
    h = np.zeros((parts * block, tiles * tile), np.complex128)
    h[:count, :bins] = taps
    padded = np.zeros((parts, width, tiles * tile), np.complex128)
    padded[:, :block] = h.reshape(parts, block, tiles * tile)
    spec = np.fft.fft(padded, axis=1)[:, bit_reversed(width)] / width
    spec = spec.reshape(parts, width, tiles, tile).transpose(2, 1, 0, 3)
    return (
        np.ascontiguousarray(spec.real, dtype=dtype),
        np.ascontiguousarray(spec.imag, dtype=dtype),
    )


@numba.njit(nogil=True, cache=True)
def store_lines(lines, hist_re, hist_im, first_row):  # pragma: no cover - compiled
    # hist[t, (first_row + i) mod rows, c] = lines[i, t·C + c] (zero beyond the last column).
    tiles, rows, tile = hist_re.shape
    bins = lines.shape[1]
    for t in range(tiles):
        for i in range(lines.shape[0]):
            r = (first_row + i) % rows
            line = lines[i]
            for c in range(tile):
                col = t * tile + c
                if col < bins:
                    v = line[col]
                    hist_re[t, r, c] = v.real
                    hist_im[t, r, c] = v.imag


@numba.njit(nogil=True, fastmath=True, cache=True)
def _dif(re, im, twr, twi, stride):  # pragma: no cover - compiled
    # In place: natural order in, bit-reversed out; twiddle j of size n at tw[j·stride].  The
    # 2-point stage and j = 0 (twiddle 1) skip the multiply.
    n, cols = re.shape
    m = n
    while m > 2:
        half = m // 2
        for k in range(0, n, m):
            for j in range(half):
                wr, wi = twr[j * stride], twi[j * stride]
                ar, ai, br, bi = re[k + j], im[k + j], re[k + j + half], im[k + j + half]
                if j == 0:
                    for c in range(cols):
                        dr = ar[c] - br[c]
                        di = ai[c] - bi[c]
                        ar[c] += br[c]
                        ai[c] += bi[c]
                        br[c] = dr
                        bi[c] = di
                else:
                    for c in range(cols):
                        dr = ar[c] - br[c]
                        di = ai[c] - bi[c]
                        ar[c] += br[c]
                        ai[c] += bi[c]
                        br[c] = dr * wr - di * wi
                        bi[c] = dr * wi + di * wr
        m = half
        stride *= 2
    if m == 2:
        for k in range(0, n, 2):
            ar, ai, br, bi = re[k], im[k], re[k + 1], im[k + 1]
            for c in range(cols):
                dr = ar[c] - br[c]
                di = ai[c] - bi[c]
                ar[c] += br[c]
                ai[c] += bi[c]
                br[c] = dr
                bi[c] = di


@numba.njit(nogil=True, fastmath=True, cache=True)
def _dit_second_half(re, im, twr, twi, stride, out_re, out_im):  # pragma: no cover - compiled
    # Inverse DFT (conjugate twiddles), bit-reversed in, natural out, in place but for the last
    # stage, which writes only outputs n/2 .. n-1 into out[0 .. n/2).
    n, cols = re.shape
    if n == 2:
        for c in range(cols):
            out_re[0, c] = re[0, c] - re[1, c]
            out_im[0, c] = im[0, c] - im[1, c]
        return
    for k in range(0, n, 2):  # the 2-point stage: twiddle 1
        ar, ai, br, bi = re[k], im[k], re[k + 1], im[k + 1]
        for c in range(cols):
            dr = ar[c] - br[c]
            di = ai[c] - bi[c]
            ar[c] += br[c]
            ai[c] += bi[c]
            br[c] = dr
            bi[c] = di
    step = stride * (n // 4)  # twiddle stride of the 4-point stage
    m = 4
    while m < n:
        half = m // 2
        for k in range(0, n, m):
            for j in range(half):
                wr, wi = twr[j * step], -twi[j * step]
                ar, ai, br, bi = re[k + j], im[k + j], re[k + j + half], im[k + j + half]
                for c in range(cols):
                    tr = br[c] * wr - bi[c] * wi
                    ti = br[c] * wi + bi[c] * wr
                    br[c] = ar[c] - tr
                    bi[c] = ai[c] - ti
                    ar[c] += tr
                    ai[c] += ti
        m *= 2
        step //= 2
    half = n // 2
    for j in range(half):
        wr, wi = twr[j * step], -twi[j * step]
        ar, ai, br, bi = re[j], im[j], re[j + half], im[j + half]
        yr, yi = out_re[j], out_im[j]
        for c in range(cols):
            yr[c] = ar[c] - (br[c] * wr - bi[c] * wi)
            yi[c] = ai[c] - (br[c] * wi + bi[c] * wr)


@numba.njit(nogil=True, fastmath=True, cache=True)
def _mac_run(x_re, x_im, h_re, h_im, h0, d_re, d_im, slot, c0, run, y_re, y_im):  # pragma: no cover
    # Columns c0 .. c0+run-1 of the block, multiplied by the spectra's columns h0 ..: X_k = x
    # enters the delay line at slot k mod P, then y = Σ_p H_p · X_{k-p}; h[f, p] = H_p and
    # d[f, s] = X_s at frequency f.  (Indexed, not sliced: a row view per partition cost 1.7×
    # the time.  Unsigned column indices: no negative-index wraparound, so the loops vectorise.)
    n, parts = h_re.shape[0], h_re.shape[1]
    a0, b0, m = np.uint64(c0), np.uint64(h0), np.uint64(run)
    for f in range(n):
        for c in range(m):  # p = 0: X_k itself, entering the delay line
            a, b = a0 + c, b0 + c
            hr, hi, xr, xi = h_re[f, 0, b], h_im[f, 0, b], x_re[f, a], x_im[f, a]
            d_re[f, slot, a] = xr
            d_im[f, slot, a] = xi
            y_re[f, a] = hr * xr - hi * xi
            y_im[f, a] = hr * xi + hi * xr
        s = slot
        for p in range(1, parts):
            s = s - 1 if s > 0 else parts - 1
            for c in range(m):
                a, b = a0 + c, b0 + c
                hr, hi, xr, xi = h_re[f, p, b], h_im[f, p, b], d_re[f, s, a], d_im[f, s, a]
                y_re[f, a] += hr * xr - hi * xi
                y_im[f, a] += hr * xi + hi * xr


@numba.njit(nogil=True, cache=True)
def _enter_and_mac(x_re, x_im, h_re, h_im, t, shift, d_re, d_im, k, y_re, y_im):  # pragma: no cover
    # Tile t's block through the spectra h[tile, f, p, c] of mask column (t·C + c + shift) mod
    # (tiles·C): the mask turned ``shift`` columns against the lines (rtsar.ccd.walk_deskew);
    # shift 0 reads tile t's own.  At most three contiguous runs of columns.
    tiles, cols = h_re.shape[0], h_re.shape[3]
    total = tiles * cols
    slot = k % h_re.shape[2]
    c = 0
    while c < cols:
        g = (t * cols + c + shift) % total
        t2 = g // cols
        c2 = g - t2 * cols
        run = min(cols - c, cols - c2)
        _mac_run(x_re, x_im, h_re[t2], h_im[t2], c2, d_re[t], d_im[t], slot, c, run, y_re, y_im)
        c += run


@numba.njit(nogil=True, cache=True)
def mask_shift(rotation, line) -> int:  # pragma: no cover - compiled
    """The columns the mask is turned for the block whose lines centre on ``line`` (a pulse
    index, float): Q·round(w·line / Q) with rotation = (w columns a pulse, quantum Q); 0 where
    Q is 0."""
    q = rotation[1]
    if q == 0:
        return 0
    return np.int64(q * np.round(rotation[0] * line / q))


@numba.njit(nogil=True, cache=True)
def _block(
    t,
    k,
    valid_end,
    seg,
    ring_re,
    ring_im,
    h_re,
    h_im,
    d_re,
    d_im,
    tw_re,
    tw_im,
    x_re,
    x_im,
    y_re,
    y_im,
    out_re,
    out_im,
    assign,
    rotation,
):  # pragma: no cover - compiled
    # Block k of the segment seg = (offset, 2B, P, delay) for tile t; pulses ≥ valid_end read
    # as zeros.  Its outputs (pulses kB .. kB+B-1 of the segment) go to the full output's
    # pulse + delay.  h/d: the flat arrays of all segments' spectra and delay lines; rotation:
    # mask_shift's, taken at the middle of the block's output lines.
    offset, n, parts, delay = seg[0], seg[1], seg[2], seg[3]
    tiles, rows, width = ring_re.shape
    size = tiles * n * parts * width
    shape = (tiles, n, parts, width)
    hr = h_re[offset : offset + size].reshape(shape)
    hi = h_im[offset : offset + size].reshape(shape)
    dr = d_re[offset : offset + size].reshape(shape)
    di = d_im[offset : offset + size].reshape(shape)
    block = n // 2
    xr, xi, yr, yi = x_re[t, :n], x_im[t, :n], y_re[t, :n], y_im[t, :n]
    for i in range(n):
        pulse = (k - 1) * block + i
        if pulse < 0 or pulse >= valid_end:
            for c in range(width):
                xr[i, c] = 0
                xi[i, c] = 0
        else:
            r = pulse % rows
            for c in range(width):
                xr[i, c] = ring_re[t, r, c]
                xi[i, c] = ring_im[t, r, c]
    stride = (tw_re.shape[0] * 2) // n
    _dif(xr, xi, tw_re, tw_im, stride)
    shift = mask_shift(rotation, k * block + delay + 0.5 * (block - 1))
    _enter_and_mac(xr, xi, hr, hi, t, shift, dr, di, k, yr, yi)
    ob_r, ob_i = xr[:block], xi[:block]  # the window is no longer needed
    _dit_second_half(yr, yi, tw_re, tw_im, stride, ob_r, ob_i)
    ring_rows = out_re.shape[1]
    for i in range(block):
        r = (k * block + i + delay) % ring_rows
        if assign:
            for c in range(width):
                out_re[t, r, c] = ob_r[i, c]
                out_im[t, r, c] = ob_i[i, c]
        else:
            for c in range(width):
                out_re[t, r, c] += ob_r[i, c]
                out_im[t, r, c] += ob_i[i, c]


@numba.njit(nogil=True, cache=True)
def run_blocks(
    events,
    valid_end,
    segs,
    ring_re,
    ring_im,
    h_re,
    h_im,
    d_re,
    d_im,
    tw_re,
    tw_im,
    x_re,
    x_im,
    y_re,
    y_im,
    out_re,
    out_im,
    assign,
    rotation,
):  # pragma: no cover - compiled
    """The blocks ``events`` [(segment, block k), ...] in this order on every tile, one tile
    after another on the calling thread.  segs[s] = (offset in h and d, 2B, P, delay); ring:
    the input lines; h, d: all segments' spectra (tile_spectra) and delay lines, flat; tw:
    twiddles; x, y: per-tile work rows; out: the rows the outputs are added to (``assign``:
    stored) at pulse + delay; rotation: float64 (w, Q) of mask_shift ((0, 0): none).

    Not a parallel kernel: the head's and the tail's threads (rtsar.ccd.nonuniform) already
    keep two cores busy, and OpenMP's team for the tiles only added its hand-offs and its
    spinning threads to a pipeline's.  On 2 cores (issue 38, Zen 3, three runs each): a push
    of one line into psaltis-jpl's correlator 138-150 against 187-204 µs parallel, psaltis-max
    alone 10.6-15.7k against 11.8-12.2k pulses/s, its pipeline at max rate 9.8-11.0k against
    8.6-10.2k."""
    for t in range(ring_re.shape[0]):
        for e in range(events.shape[0]):
            _block(
                np.int64(t),  # one _block signature (a prange index was unsigned)
                events[e, 1],
                valid_end,
                segs[events[e, 0]],
                ring_re,
                ring_im,
                h_re,
                h_im,
                d_re,
                d_im,
                tw_re,
                tw_im,
                x_re,
                x_im,
                y_re,
                y_im,
                out_re,
                out_im,
                assign,
                rotation,
            )


@numba.njit(nogil=True, cache=True)
def emit_lines(acc_re, acc_im, head_re, head_im, first, count, skip, out):  # pragma: no cover
    """out[j - skip] = acc + head at pulse first + j for skip ≤ j < count (``out``: the output
    lines viewed as floats, real and imaginary interleaved); those rows of acc are zeroed (one
    thread, as run_blocks)."""
    tiles, ring, tile = acc_re.shape
    head_ring = head_re.shape[1]
    bins = out.shape[1] // 2
    for t in range(tiles):
        width = min(tile, bins - t * tile)
        for j in range(count):
            r, h = (first + j) % ring, (first + j) % head_ring
            if j >= skip:
                line = out[j - skip]
                for c in range(width):
                    line[2 * (t * tile + c)] = acc_re[t, r, c] + head_re[t, h, c]
                    line[2 * (t * tile + c) + 1] = acc_im[t, r, c] + head_im[t, h, c]
            acc_re[t, r, :] = 0
            acc_im[t, r, :] = 0
