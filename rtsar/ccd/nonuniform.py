"""Non-uniformly partitioned overlap-save: a short block at the head of the mask, long ones behind.

Gardner 1995 ("Efficient convolution without input-output delay") and Garcia 2002 ("Optimal
filter partition for efficient convolution with short input/output delay"): the N taps
h[q] = mask[N-1-q] of eq. (1) (rtsar.ccd.base) are cut into segments; segment s holds the taps
[D_s, D_s + T_s) and is a uniformly partitioned overlap-save correlation (the scheme of
rtsar.ccd.partitioned) with its own block B_s, whose outputs serve the full line D_s pulses
later:

    g[p] = Σ_s g_s[p - D_s],   g_s[p'] = Σ_{q<T_s} h[D_s + q] · line[p' - q]   (pulse index p).

Segment s's output for pulse p - D_s is complete once its block ends, at most B_s - 1 pulses
later, so a segment with D_s ≥ B_s has its part of line p ready before the line's last pulse
arrives, if it is computed at once.  It is not: a tail block's transforms take time (a block
of 64 lines at psaltis-max, 1,200 bins: about 6 ms on one core of the 2-core development
machine, 60 pulses at 10 kHz), and with D_s = B_s the head waited for them on the line that
follows each block (pushes of 4 lines paced at 2,500 pulses/s: p99 6.7 ms, against 1.9 ms).
So every tail segment starts at D_s ≥ TAIL_LEAD · B_s = 2 B_s: its block is computed while
the next B_s pulses arrive (as a real-time partitioned convolution spreads a block's work over
the next block's time), and the head waits only where the machine cannot keep up.  The lead
costs multiply-adds: the segments before each tail block hold twice the taps (psaltis-max,
L = 16: 8 partitions of 16 then 6 of 64, 28 multiply-adds a pixel and line against 22; L = 2:
28 against 18), and a 16-line push's median rose from 0.82 to 1.13 ms as its p99 fell from
6.7 to 2.5 ms (`rtsar bench`, 2026-11-28).  Only the head segment (D_0 = 0, block L) sits
on the latency path: lines leave in blocks of L, as with the uniform correlator of block L,
while the long tail blocks cut the multiply-adds per pixel and line from 2N/L to
2·(number of partitions), at the cost of one more pair of transforms per segment.  The tail
segments run on a worker thread (the kernels release the GIL), fed each chunk of a push that
completes a tail block before the head is computed (a push that completes none leaves it
asleep), the blocks the head's lines of that chunk need first, so the rest overlaps the head's
work and the next pulses' arrival.

All segments run on the kernels of rtsar.ccd.tiled (split real/imaginary arrays over tiles of
range columns, FFTs along azimuth without transposes, one kernel call for all the blocks of a
chunk).  The tail segments add their outputs into one ring of full-output rows in
the order of the pulse that completes each block (then segment); the head's are added last when
the line leaves.  Every stream computes the same blocks in the same order, so the output does
not depend on the push sizes or on the thread's timing (tested bit for bit).

Plan (``plan_segments``): by default the partition of least modelled cost (Garcia 2002;
``transform_cost``), at psaltis-max (N = 512, L = 16) 8 partitions of 16 then 6 of 64;
``rule="doubling"`` gives Gardner's doubling (2 partitions of L, 2L, 4L, …; 4 of L, for the
lead).
"""

from __future__ import annotations

import atexit
import math
import threading
import weakref
from collections import deque

import numpy as np

from . import tiled
from .base import Correlator


def transform_cost(block: int) -> float:
    """A block size's pair of transforms (with the window load and the output) per line, in
    units of one partition's multiply-adds per line: 2.4 + log2(2B), fitted to the kernels of
    rtsar.ccd.tiled on the 2-core development machine (one thread, 1200 range cells: a
    partition ≈ 1.5 µs a line, the transforms of B = 16 / 32 / 64 / 128 / 256 11.3 / 12.0 /
    13.7 / 14.0 / 18.2 µs a line).  Fitted to the kernels' tiles of 32 columns; on one tile
    (rtsar.ccd.tiled.tile_columns, 2026-11-29, 2-core Intel Xeon) a partition costs 1.2-2.1 µs
    a line from B = 16 (0.2-0.7 µs below, where the segment stays in cache) and the transforms
    7.2 / 8.9 / 10.7 / 15.0 / 22.0 µs, not refitted: at psaltis-max, L = 16, the plan this
    model chooses was still the fastest of the eight it weighs (33.5k pulses/s against 28.6k
    or less, pushes of 64); at L = 2 a plan 1.2× faster than its choice exists."""
    return 2.4 + math.log2(2 * block)


def _check_plan(n: int, head_lines: int, max_block_lines: int) -> None:
    for name, value in (("head_lines", head_lines), ("max_block_lines", max_block_lines)):
        if not (isinstance(value, int) and value >= 1 and not value & (value - 1)):
            raise ValueError(f"{name} must be a power of two, got {value!r}")
    if head_lines > n:
        raise ValueError(f"head_lines {head_lines} exceeds the aperture N = {n}")


TAIL_LEAD = 2  # a tail segment of block B starts at D ≥ TAIL_LEAD · B (module docstring)


def _segments_for(n: int, blocks: list[int]) -> list[tuple[int, int, int]] | None:
    """The segments with these block sizes, each but the last holding the fewest partitions
    that let the next block start late enough (D ≥ TAIL_LEAD · B); None where the taps run
    out first."""
    segments, first = [], 0
    for s, block in enumerate(blocks):
        if s + 1 == len(blocks):
            return [*segments, (first, n - first, block)]
        parts = max(1, -(-(TAIL_LEAD * blocks[s + 1] - first) // block))
        if first + parts * block >= n:
            return None
        segments.append((first, parts * block, block))
        first += parts * block
    return None


def plan_segments(
    n: int, head_lines: int, max_block_lines: int, rule: str = "optimal"
) -> list[tuple[int, int, int]]:
    """(first tap D, taps T, block B) of each segment, head first; Σ T = n and D_s ≥ 2 B_s
    (TAIL_LEAD) for every tail segment.

    ``rule="optimal"`` (Garcia 2002): of every increasing sequence of block sizes L < B_1 < …
    ≤ ``max_block_lines`` (powers of two), each segment holding the fewest partitions that
    let the next one start, the one with the least cost per line, Σ_s transform_cost(B_s) +
    partitions_s (fewer segments on a tie).  ``rule="doubling"`` (Gardner 1995, with the lead):
    4 partitions of L, then 2 of each size 2L, 4L, … up to ``max_block_lines``, the last
    taking the rest.
    """
    _check_plan(n, head_lines, max_block_lines)
    if rule == "doubling":
        return _doubling(n, head_lines, max_block_lines)
    if rule != "optimal":
        raise ValueError(f"rule must be 'optimal' or 'doubling', got {rule!r}")
    sizes = []
    while head_lines << (len(sizes) + 1) <= min(max_block_lines, n):
        sizes.append(head_lines << (len(sizes) + 1))
    best, best_key = [(0, n, head_lines)], None
    for chosen in range(1 << len(sizes)):
        blocks = [head_lines] + [b for i, b in enumerate(sizes) if chosen >> i & 1]
        segments = _segments_for(n, blocks)
        if segments is None:
            continue
        cost = sum(transform_cost(b) + -(-t // b) for _, t, b in segments)
        key = (round(cost, 9), len(segments))
        if best_key is None or key < best_key:
            best, best_key = segments, key
    return best


def _doubling(n: int, head_lines: int, max_block_lines: int) -> list[tuple[int, int, int]]:
    segments, first, block = [], 0, head_lines
    while first < n:
        remaining = n - first
        parts = 2 * TAIL_LEAD if first == 0 else 2  # D of the next = 2 B (TAIL_LEAD) after
        taps = remaining if block >= max_block_lines else min(parts * block, remaining)
        following = min(2 * block, max_block_lines)
        if remaining - taps < following:  # too few taps left for a block of the next size
            taps = remaining
        segments.append((first, taps, block))
        first += taps
        block = following
    return segments


class _Group:
    """Segments computed together (the head, or the tail): their spectra, delay lines, scratch."""

    def __init__(self, h: np.ndarray, segments, tiles: int, tile: int, real, tw, rotation):
        self.rotation = rotation  # float64 (w, Q) of tiled.mask_shift
        spectra, segs, offset = [], [], 0
        for d, t, b in segments:
            hr, hi = tiled.tile_spectra(h[d : d + t], b, tile, real)
            spectra.append((hr.ravel(), hi.ravel()))
            segs.append((offset, 2 * b, hr.shape[2], d))
            offset += hr.size
        self.blocks = [b for _, _, b in segments]
        h_re, h_im = (np.concatenate([sp[i] for sp in spectra]) for i in (0, 1))
        width = 2 * max(self.blocks)
        self.arrays = (
            np.array(segs, np.int64),
            h_re,
            h_im,
            np.zeros_like(h_re),  # the delay lines, same layout
            np.zeros_like(h_im),
            *tw,
            *(np.zeros((tiles, width, tile), real) for _ in range(4)),
        )
        self.done = [0] * len(segments)  # blocks computed per segment

    def run(self, events, valid_end: int, ring, out, assign: bool) -> None:
        """tiled.run_blocks on these segments' blocks ``events``."""
        segs, *arrays = self.arrays  # spectra, delay lines, twiddles, work rows (re, im each)
        tiled.run_blocks(events, valid_end, segs, *ring, *arrays, *out, assign, self.rotation)

    def events(self, end: int, limit: int | None = None) -> np.ndarray:
        """(segment, block) of the blocks complete at ``end`` pulses (and, with ``limit``,
        completing at most at pulse ``limit``), ordered by the pulse that completes them, then
        segment: every stream computes the same blocks in the same order (bit-exact sums)."""
        found = []
        for s, b in enumerate(self.blocks):
            last = min(end, end if limit is None else limit) // b
            found += [((k + 1) * b, s, k) for k in range(self.done[s], last)]
            self.done[s] = max(self.done[s], last)
        found.sort()
        return np.array([(s, k) for _, s, k in found], np.int64).reshape(-1, 2)


class _Tail(threading.Thread):
    """The tail segments, computed chunk by chunk in order on their own thread: ``progress``
    is the pulse count up to which every tail block is in the accumulation ring."""

    def __init__(self, run, threaded: bool):
        super().__init__(name="rtsar-ccd-tail", daemon=True)
        self._run = run  # run(events): the blocks into the accumulation ring
        self.group: _Group | None = None
        self.progress = 0
        self.error: BaseException | None = None
        self._submitted = 0  # the end of the last job given to the thread
        self._jobs: deque = deque()
        self._cond = threading.Condition()
        self._threaded = threaded
        if threaded:
            self.start()
            _LIVE.add(self)

    def due(self, end: int) -> bool:
        """Whether a tail block ends after the last job's end and by ``end`` pulses.  Not on
        most pushes of a head block or a few (every tail block is at least two head blocks
        long, four or more in most plans): those give the thread no job and do not wake it, a
        wake-up at every push having cost more than the small tail's work (psaltis-jpl's 320
        bins, N = 512, a line a push: 94-95 µs a push when every push woke it, 64-67 µs now,
        51 µs with the tail on the caller's thread; 2-core Intel Xeon, 2026-11-29).
        ``wait_for`` knows those pulses as done once the last job is."""
        return any(end // b != self._submitted // b for b in self.group.blocks)

    def submit(self, end: int, urgent: int) -> None:
        """Compute the blocks complete at ``end`` pulses (``due``), those completing by
        ``urgent`` first."""
        self._submitted = end
        if not self._threaded:
            self._work((end, urgent))
            return
        if not self.is_alive() and self.error is None:
            raise RuntimeError("the nonuniform correlator was closed: no more lines")
        with self._cond:
            self._jobs.append((end, urgent))
            self._cond.notify_all()

    def _work(self, job) -> None:
        end, urgent = job
        for limit in (urgent, end):
            events = self.group.events(end, limit)
            if len(events):
                self._run(events)
            with self._cond:
                self.progress = max(self.progress, limit)
                self._cond.notify_all()

    def run(self) -> None:  # pragma: no cover - runs on the worker thread (covered via push)
        while True:
            with self._cond:
                while not self._jobs:
                    self._cond.wait()
                job = self._jobs[0]
            if job is _STOP:
                return
            try:
                self._work(job)
            except BaseException as exc:  # reported to the caller of push/flush
                with self._cond:
                    self.error = exc
                    self._cond.notify_all()
                return
            with self._cond:
                self._jobs.popleft()
                self._cond.notify_all()

    def wait_for(self, pulses: int) -> None:
        """Block until every tail block completing by pulse count ``pulses`` is in the ring
        (those after the last job's end come with a later job: ``due``)."""
        pulses = min(pulses, self._submitted)
        if self.progress >= pulses and self.error is None:
            return
        with self._cond:
            while self.error is None and self.progress < pulses:
                self._cond.wait()
            if self.error is not None:
                raise RuntimeError(f"the CCD's tail thread failed: {self.error}") from self.error

    def stop(self, join_s: float = 0.0) -> None:
        """End the thread after the jobs before; wait up to ``join_s`` for it to exit."""
        if self._threaded and self.is_alive():
            with self._cond:
                self._jobs.append(_STOP)
                self._cond.notify_all()
            if join_s:
                self.join(join_s)


_STOP = object()
_LIVE: weakref.WeakSet = weakref.WeakSet()  # tail threads not yet stopped


@atexit.register
def _stop_all() -> None:
    # A tail thread still alive when the interpreter finalises dies inside the OpenMP runtime
    # its kernels used ("terminate called without an active exception", SIGABRT): end them here.
    for tail in list(_LIVE):
        tail.stop(join_s=5.0)


class NonUniformCorrelator(Correlator):
    """Eq. (1) by non-uniformly partitioned overlap-save (module docstring): lines in blocks of
    ``head_lines`` L, the tail of the mask in blocks up to ``max_block_lines``.

    ``threaded`` (default True) runs the tail segments on their own thread; ``rule``:
    plan_segments' "optimal" (default) or "doubling".  ``mask_rotation`` (w, Q): a block whose
    lines centre on pulse m reads mask column (c + Q·round(w·m / Q)) mod bins for column c, the
    mask turning against the lines (rtsar.ccd.walk_deskew; tiled.mask_shift); None: column
    c's own.  Relative RMS error against correlate_reference 1.8e-7 in complex64, 1.6e-15 in
    complex128 (N = 2048, 64 bins; tested to 1e-5 and 1e-12).
    """

    CHUNK = 128  # pushes are computed up to this many lines at a time

    def __init__(
        self,
        mask: np.ndarray,
        head_lines: int = 16,
        max_block_lines: int = 128,
        precision: str = "complex64",
        threaded: bool | None = None,
        rule: str = "optimal",
        mask_rotation: tuple[float, int] | None = None,
    ):
        super().__init__(mask, precision)
        rotation = np.zeros(2, np.float64)
        if mask_rotation is not None:
            w, q = mask_rotation
            if not (math.isfinite(w) and isinstance(q, int) and q >= 1):
                raise ValueError(
                    f"mask_rotation must be (finite w, int Q >= 1), got {mask_rotation}"
                )
            rotation[:] = w, q
        n, bins = self.aperture, self.range_bins
        self.block_lines = head_lines
        largest = 1 << (n.bit_length() - 1)  # the largest power of two <= N
        self.segments = plan_segments(n, head_lines, min(max_block_lines, largest), rule)
        self.partitions = sum(-(-t // b) for _, t, b in self.segments)
        real = np.float64 if self.dtype == np.complex128 else np.float32
        tile = tiled.tile_columns(bins)
        tiles = -(-bins // tile)
        if mask_rotation is not None and tiles * tile != bins:
            raise ValueError(
                f"a turning mask needs the tiles' width: {bins} bins are {tiles} × {tile} "
                "columns (rtsar.ccd.walk_deskew.ring_width)"
            )
        widest = max(b for _, _, b in self.segments)
        self._window_rows = 2 * widest  # rows the widest segment's transform reads
        tw = tiled.twiddles(2 * widest, real)
        h = np.asarray(mask, dtype=np.complex128)[::-1]  # h[q] = mask[N-1-q], float64 formed
        self._head = _Group(h, self.segments[:1], tiles, tile, real, tw, rotation)
        tail = (
            _Group(h, self.segments[1:], tiles, tile, real, tw, rotation)
            if self.segments[1:]
            else None
        )
        # Rings indexed by pulse (powers of two): the input lines (2 × the widest block and a
        # chunk behind the newest pulse), the tail's sums of the full output (rows up to N
        # ahead of it, a chunk behind) and the head's outputs (the chunk's blocks).
        chunk = self.CHUNK + 2 * head_lines
        self._hist = self._ring(tiles, 2 * max(widest, head_lines) + chunk, tile, real)
        self._acc = self._ring(tiles, n + chunk, tile, real)
        self._head_out = self._ring(tiles, chunk, tile, real)
        if threaded is None:
            threaded = True
        self.threaded = bool(threaded) and tail is not None
        self._tail = _Tail(self._run_tail, self.threaded)
        self._tail.group = tail
        self._flushed = 0  # lines of the pending head block that flush() has emitted
        self._closed = False
        # Compile (or load from numba's cache) the kernels and touch every buffer now.
        self._warm()

    @staticmethod
    def _ring(tiles: int, rows: int, tile: int, real) -> tuple[np.ndarray, np.ndarray]:
        """Real and imaginary parts of a ring of at least ``rows`` rows on every tile."""
        shape = (tiles, 1 << (rows - 1).bit_length(), tile)
        return np.zeros(shape, real), np.zeros(shape, real)

    def _warm(self) -> None:
        none = np.zeros((0, 2), np.int64)
        self._head.run(none, 0, self._hist, self._head_out, True)
        tiled.store_lines(self._no_lines(), *self._hist, 0)

    def _run_tail(self, events: np.ndarray) -> None:
        self._tail.group.run(events, 1 << 62, self._hist, self._acc, False)

    def _needed(self, last_pulse: int) -> int:
        """Pulse count by which every tail block that serves lines ≤ ``last_pulse`` is done."""
        need = 0
        for d, _, b in self.segments[1:]:
            if last_pulse >= d:
                need = max(need, ((last_pulse - d) // b + 1) * b)
        return need

    def _lines_out(self, first: int, count: int, skip: int) -> np.ndarray:
        """Full lines for pulses first+skip .. first+count-1 (acc + head); their rows freed."""
        # Lines completing before the N-th pulse saw a partial aperture: not emitted.
        skip = min(count, max(skip, self.aperture - 1 - first))
        self._tail.wait_for(self._needed(first + count - 1))
        out = np.empty((count - skip, self.range_bins), self.dtype)
        tiled.emit_lines(*self._acc, *self._head_out, first, count, skip, out.view(out.real.dtype))
        self.lines_out += len(out)
        return out

    def push(self, lines: np.ndarray) -> np.ndarray:
        if self._closed:
            raise RuntimeError("the nonuniform correlator was closed: no more lines")
        lines = self._check(lines)
        lb, rows = self.block_lines, self._hist[0].shape[1]
        outs = []
        for i in range(0, len(lines), self.CHUNK):
            chunk = lines[i : i + self.CHUNK]
            start, end = self.pulses_in, self.pulses_in + len(chunk)
            if self._tail.group is not None:
                # The tail may still read the rows this chunk overwrites: wait (rarely).
                self._tail.wait_for(end - rows + self._window_rows)
            tiled.store_lines(chunk, *self._hist, start % rows)
            self.pulses_in = end
            done, blocks = start // lb, end // lb
            if self._tail.group is not None and self._tail.due(end):
                self._tail.submit(end, self._needed(blocks * lb - 1))
            if blocks > done:
                events = self._head.events(end)
                self._head.run(events, end, self._hist, self._head_out, True)
                outs.append(self._lines_out(done * lb, (blocks - done) * lb, self._flushed))
                self._flushed = 0
        if len(outs) == 1:
            return outs[0]
        return np.concatenate(outs) if outs else self._no_lines()

    def flush(self) -> np.ndarray:
        # The filter is causal (line p needs pulses ≤ p), so the head's partial block,
        # zero-padded, gives its lines exactly; the tail's parts of them are complete already
        # (each tail block ends before the lines it serves).  Nothing is committed: the head's
        # spectrum lands in the delay-line slot that the complete block will overwrite.
        lb = self.block_lines
        first = self.pulses_in // lb * lb
        pending = self.pulses_in - first
        if pending == self._flushed:
            return self._no_lines()
        events = np.array([[0, first // lb]], np.int64)
        self._head.run(events, self.pulses_in, self._hist, self._head_out, True)
        out = self._lines_out(first, pending, self._flushed)
        self._flushed = pending
        return out

    def close(self) -> None:
        """End the tail thread and wait for it (also done, without the wait, when the correlator
        is garbage collected, and at interpreter exit)."""
        self._closed = True
        self._tail.stop(join_s=5.0)

    def __del__(self):
        try:
            self._tail.stop()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass
