"""Non-uniformly partitioned overlap-save: a short block at the head of the mask, long ones behind.

Gardner 1995 ("Efficient convolution without input-output delay") and Garcia 2002 ("Optimal
filter partition for efficient convolution with short input/output delay"): the N taps
h[q] = mask[N-1-q] of eq. (1) (rtsar.ccd.base) are cut into segments; segment s holds the taps
[D_s, D_s + T_s) and runs as a uniformly partitioned overlap-save correlator
(rtsar.ccd.partitioned) with its own block B_s.  Since

    g[j] = Σ_s g_s[j + N - D_s - T_s],   g_s = correlation of the lines with mask rows
                                          [N - D_s - T_s, N - D_s),

and segment s's line j + N - D_s - T_s is complete B_s - 1 pulses after pulse j + N - 1 - D_s,
a segment with D_s ≥ B_s has its part of line j ready before the line's last pulse arrives.
Only the head segment (D_0 = 0, block L) sits on the latency path: lines leave in blocks of L,
as with the uniform correlator of block L, while the long tail blocks cut the multiply-adds per
pixel and line from 2N/L to 2·(number of partitions), at the cost of one more pair of transforms
per segment.  The tail segments run on a worker thread (their numba and SciPy kernels release
the GIL), fed each push before the head is computed, so their work overlaps the head's and the
next pulses' arrival instead of delaying the lines of the push that completed a long block.

Plan (Gardner's doubling; ``plan_segments``): the head holds 2 partitions of L, then each block
size 2L, 4L, … up to ``max_block_lines`` holds 2 partitions, and the last segment takes what is
left (also when fewer taps are left than the next size's block).
Sums are formed segment by segment in a fixed order, so the output does not depend on the push
sizes or on the thread's timing (tested bit for bit).
"""

from __future__ import annotations

import atexit
import threading
import weakref
from collections import deque

import numba
import numpy as np

from .base import Correlator
from .partitioned import PartitionedCorrelator


def plan_segments(n: int, head_lines: int, max_block_lines: int) -> list[tuple[int, int, int]]:
    """(first tap D, taps T, block B) of each segment, head first; Σ T = n and D_s ≥ B_s - 1."""
    for name, value in (("head_lines", head_lines), ("max_block_lines", max_block_lines)):
        if not (isinstance(value, int) and value >= 1 and not value & (value - 1)):
            raise ValueError(f"{name} must be a power of two, got {value!r}")
    if head_lines > n:
        raise ValueError(f"head_lines {head_lines} exceeds the aperture N = {n}")
    segments, first, block = [], 0, head_lines
    while first < n:
        remaining = n - first
        taps = remaining if block >= max_block_lines else min(2 * block, remaining)
        following = min(2 * block, max_block_lines)
        if remaining - taps < following:  # too few taps left for a block of the next size
            taps = remaining
        segments.append((first, taps, block))
        first += taps
        block = following
    return segments


class _Tail(threading.Thread):
    """The tail segments, fed pushes in order on their own thread; outputs kept per segment."""

    def __init__(self, correlators: list[PartitionedCorrelator], threaded: bool):
        super().__init__(name="rtsar-ccd-tail", daemon=True)
        self.correlators = correlators
        self.outputs = [deque() for _ in correlators]  # per segment: arrays of lines, in order
        self.lines_ready = [0] * len(correlators)  # lines each segment has produced
        self.error: BaseException | None = None
        self._jobs: deque = deque()
        self._cond = threading.Condition()
        self._threaded = threaded
        if threaded:
            self.start()
            _LIVE.add(self)

    def submit(self, lines: np.ndarray | None) -> None:
        """Push ``lines`` into every tail segment (None: flush them)."""
        if not self._threaded:
            self._work(lines)
            return
        if not self.is_alive() and self.error is None:
            raise RuntimeError("the nonuniform correlator was closed: no more lines")
        with self._cond:
            self._jobs.append(lines)
            self._cond.notify_all()

    def _work(self, lines) -> None:
        for s, corr in enumerate(self.correlators):
            out = corr.flush() if lines is None else corr.push(lines)
            if len(out):
                with self._cond:
                    self.outputs[s].append(out)
                    self.lines_ready[s] += len(out)
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

    def wait_for(self, needed: list[int]) -> None:
        """Block until segment s has produced ``needed[s]`` lines (or the thread failed)."""
        with self._cond:
            while self.error is None and any(
                r < w for r, w in zip(self.lines_ready, needed, strict=True)
            ):
                self._cond.wait()
            if self.error is not None:
                raise RuntimeError(f"the CCD's tail thread failed: {self.error}") from self.error

    def take(self, s: int, skip: int, count: int) -> np.ndarray:
        """Drop ``skip`` lines of segment s, then remove and return the next ``count``."""
        with self._cond:
            queue = self.outputs[s]
            parts, need = [], skip + count
            while need:
                head = queue[0]
                if len(head) <= need:
                    parts.append(queue.popleft())
                    need -= len(head)
                else:
                    parts.append(head[:need])
                    queue[0] = head[need:]
                    need = 0
        lines = parts[0] if len(parts) == 1 else np.concatenate(parts)
        return lines[skip:]

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

    ``threaded`` (default: True where numba's threading layer allows concurrent parallel
    kernels, i.e. not "workqueue") runs the tail segments on their own thread.
    """

    def __init__(
        self,
        mask: np.ndarray,
        head_lines: int = 16,
        max_block_lines: int = 128,
        precision: str = "complex64",
        threaded: bool | None = None,
    ):
        super().__init__(mask, precision)
        n = self.aperture
        self.block_lines = head_lines
        largest = 1 << (n.bit_length() - 1)  # the largest power of two <= N
        self.segments = plan_segments(n, head_lines, min(max_block_lines, largest))
        mask = np.asarray(mask)
        parts = [
            PartitionedCorrelator(mask[n - d - t : n - d], b, precision)
            for d, t, b in self.segments
        ]
        self.partitions = sum(c.partitions for c in parts)
        self._head = parts[0]
        # Full line j takes segment s's line j + skip_s, skip_s = N - D_s - T_s: each segment's
        # first skip_s lines are dropped.
        self._skip = [n - d - t for d, t, _ in self.segments]
        if threaded is None:
            try:  # known once a parallel kernel ran (the segments' constructors ran theirs)
                threaded = numba.threading_layer() != "workqueue"
            except ValueError:  # pragma: no cover - no parallel kernel has run
                threaded = False
        self.threaded = bool(threaded) and len(parts) > 1
        self._tail = _Tail(parts[1:], self.threaded)
        self._tail_skipped = [0] * (len(parts) - 1)
        self._head_skipped = 0

    def _combine(self, head: np.ndarray) -> np.ndarray:
        """The full lines for the head segment's new lines ``head`` (segment-0 line numbers)."""
        if len(head) == 0:
            return self._no_lines()
        # Full lines first..first+len-1, first = head lines given so far less the skipped ones.
        skip0 = self._skip[0] - self._head_skipped
        if skip0 >= len(head):
            self._head_skipped += len(head)
            return self._no_lines()
        if skip0 > 0:
            self._head_skipped += skip0
            head = head[skip0:]
        first = self.lines_out
        count = len(head)
        needed = [first + count + k for k in self._skip[1:]]
        self._tail.wait_for(needed)
        out = np.array(head, dtype=self.dtype, copy=True)
        for s in range(len(self._skip) - 1):  # a fixed order: the same sums whatever the timing
            skip = self._skip[s + 1] - self._tail_skipped[s]  # nonzero on the first lines only
            out += self._tail.take(s, skip, count)
            self._tail_skipped[s] += skip
        self.lines_out += count
        return out

    def push(self, lines: np.ndarray) -> np.ndarray:
        lines = self._check(lines)
        self.pulses_in += len(lines)
        # The tail works while the head is computed; on its thread it reads a copy (the caller
        # may reuse its buffer once push returns).
        self._tail.submit(lines.copy() if self.threaded else lines)
        return self._combine(self._head.push(lines))

    def flush(self) -> np.ndarray:
        self._tail.submit(None)
        return self._combine(self._head.flush())

    def close(self) -> None:
        """End the tail thread and wait for it (also done, without the wait, when the correlator
        is garbage collected, and at interpreter exit)."""
        self._tail.stop(join_s=5.0)

    def __del__(self):
        try:
            self._tail.stop()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass
