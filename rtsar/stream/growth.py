"""A live run's correlator block, doubled while the run falls behind (issue 38: latency
"degrades gracefully (larger blocks, never drops) as the rate approaches capacity").

The granularity (rtsar.stream.granularity) is chosen from the work timed at the run's start,
blocks back to back.  In a paced run the same work costs 1.3-1.5 times as much (the caches
cold after each idle gap, the other threads on the cores), so near capacity the block chosen
can be too small, and a backlog then grows for the rest of the run (psaltis-max at 50 % of
its PRF, blocks of 8, 2-core Zen 3: median latency 237 ms).  So the run watches its backlog
(``BacklogWatch``): after each correlator push, the pulses waiting in the queues before the
correlator (shots for the lens, lines for the correlator's thread), counted in time at the
run's rate.  Where, over a whole window of GROW_WINDOW_S, it stays above ``backlog_limit_s``
(GROW_BACKLOG_BLOCKS block periods, at least GROW_LEAST_BACKLOG_S) and ends no lower than
it began, the work does not keep up, and the correlator's block doubles: its fixed costs a
block are shared by twice the lines.  A backlog that shrinks is left to drain (a stall of the
machine, a burst after a silence), and so is one that never lasts a window; pulses a line
correction holds (PGA's block) wait in no queue, and are no backlog.

The grown correlator continues the stream exactly (``LineHistory``, ``BlockGrowth``): built
with the larger block, it is first fed the last H lines the old one took (H: the least
multiple of the new block ≥ N - 1; zeros before the run's first pulse), whose outputs, lines
the old correlator gave already, are dropped; the next line it gives is the old one's next.
The swap waits for a push after which the old correlator holds no partial block (the next
one, where the lens aligns its calls to the blocks); the new blocks are counted from there,
and so are the lens's calls (rtsar.stream.pipeline, ``lens_align``, ``lens_align_from``).
The new correlator is built on a thread of its own from the first backlog over the limit
(``Prebuilt``), so the swap costs the push of H lines, about an aperture, once a growth.
The candidates are the granularity's: the head blocks 1, 2, 4, … (each growth doubles),
fft's M - N + 1 for the fast transform lengths M (the next of them).

A grown block shrinks back, one candidate at a time and never below the run's own, once the
room is there (``QuietWatch``): over a window of SHRINK_WINDOW_S the backlog stayed under the
smaller block's limit and the busiest stage's share of the time (its busy seconds over the
window's, rtsar.stream.stats) stayed under SHRINK_BUSY_BELOW over the blocks' ratio.  A
call's work never falls with its size, so at a block r times smaller each stage's work a pulse
is at most r times its present one: under SHRINK_BUSY_BELOW, a margin that FUSE_BELOW's
70 % share keeps too (rtsar.stream.granularity).  The smaller correlator is built on its own
thread from that verdict, and the swap is a growth's, the other way (not if the backlog rose
over the limit again meanwhile; a failed build leaves the block as it is).  Where the block
grows straight after a shrink (within SHRINK_HELD_S of it), the quiet window doubles (up to
SHRINK_WINDOW_MOST_S), so a run at the edge does not swap back and forth; a growth after a
shrink that held that long returns it to SHRINK_WINDOW_S (a load minutes ago does not slow
the shrinks of the hours after it).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import replace

import numpy as np

from ..ccd import make_ccd
from ..params import Config
from .strips import InfoChange

GROW_WINDOW_S = 0.25  # the backlog is judged over windows of this long …
GROW_BACKLOG_BLOCKS = 4  # … behind: over this many block periods of pulses throughout …
GROW_LEAST_BACKLOG_S = 5e-3  # … and over this (a busy machine's jitter stays under it)
SHRINK_WINDOW_S = 1.0  # a grown block shrinks after a window this long …
SHRINK_BUSY_BELOW = 0.7  # … in which the busiest stage's share × the blocks' ratio stayed under
SHRINK_WINDOW_MOST_S = 32.0  # the quiet window doubles at a growth straight after a shrink, to this
SHRINK_HELD_S = 32.0  # a shrink this long before a growth held: the window is SHRINK_WINDOW_S again
HEAD_BLOCK_KINDS = ("partitioned", "nonuniform")  # their block: the head block L
GROWING_KINDS = (*HEAD_BLOCK_KINDS, "fft")  # lines in blocks a config sets (fft: M - N + 1)


def config_with_block(config: Config, block: int) -> Config:
    """``config`` whose correlator releases its lines in blocks of ``block``: partitioned and
    nonuniform with that head block, fft with the transform length M = block + N - 1; the
    others as they are."""
    p = config.processor
    if p.correlator in HEAD_BLOCK_KINDS:
        return config.with_processor(partition_lines=block)
    if p.correlator == "fft":
        return config.with_processor(fft_length=block + p.aperture_pulses - 1)
    return config


def backlog_limit_s(block: int, rate_hz: float) -> float:
    """The backlog (pulses waiting, in seconds at the rate) above which the work is behind,
    with blocks of ``block`` lines at ``rate_hz`` pulses/s: GROW_BACKLOG_BLOCKS block
    periods, at least GROW_LEAST_BACKLOG_S."""
    return max(GROW_LEAST_BACKLOG_S, GROW_BACKLOG_BLOCKS * block / rate_hz)


class BacklogWatch:
    """Whether the work keeps up, from the backlog after each push (module docstring).

    ``observe(now_s, backlog_s, limit_s)`` → True at the end of a window (GROW_WINDOW_S, from
    the first push after the last verdict) in which every backlog exceeded ``limit_s`` and the
    last was no lower than the first less ``slack_s`` (a lens call's pulses: the queues' fill
    moves by that much from one push to the next): the backlog lasted and did not shrink."""

    def __init__(self, window_s: float = GROW_WINDOW_S, slack_s: float = 0.0):
        self.window_s, self.slack_s = float(window_s), float(slack_s)
        self.restart()

    def restart(self) -> None:
        """Forget the window (after a growth: the next is judged on the new block alone)."""
        self._start_s: float | None = None
        self._first_s = self._least_s = 0.0

    def observe(self, now_s: float, backlog_s: float, limit_s: float) -> bool:
        if self._start_s is None:
            self._start_s, self._first_s, self._least_s = now_s, backlog_s, backlog_s
            return False
        self._least_s = min(self._least_s, backlog_s)
        if now_s - self._start_s < self.window_s:
            return False
        behind = self._least_s > limit_s and backlog_s >= self._first_s - self.slack_s
        self._start_s, self._first_s, self._least_s = now_s, backlog_s, backlog_s
        return behind


class QuietWatch:
    """Whether the run has room for a smaller block (module docstring).

    ``observe(now_s, backlog_s, limit_s, busy_s, ratio)`` → the busiest stage's share of the
    window's time at the end of a window (``window_s``, from the first push after the last
    verdict) in which every backlog stayed at or under ``limit_s`` (the smaller block's) and
    that share × ``ratio`` (the block over the smaller one) stayed under SHRINK_BUSY_BELOW;
    else None.  ``busy_s``: each stage's busy seconds so far (rtsar.stream.stats.busy_s)."""

    def __init__(self, window_s: float = SHRINK_WINDOW_S):
        self.window_s = float(window_s)
        self.restart()

    def restart(self) -> None:
        """Forget the window (after a swap: the next is judged on the new block alone)."""
        self._start_s: float | None = None
        self._busy0: dict = {}
        self._quiet = True

    def observe(self, now_s, backlog_s, limit_s, busy_s: dict, ratio: float) -> float | None:
        if self._start_s is None:
            self._start_s, self._busy0, self._quiet = now_s, dict(busy_s), True
            return None
        self._quiet = self._quiet and backlog_s <= limit_s
        elapsed = now_s - self._start_s
        if elapsed < self.window_s:
            return None
        worked = [busy_s[k] - self._busy0.get(k, 0.0) for k in busy_s]
        share = max(worked) / elapsed if worked else math.inf  # no stage measured: no room
        quiet = self._quiet and share * ratio < SHRINK_BUSY_BELOW
        self._start_s, self._busy0, self._quiet = now_s, dict(busy_s), True
        return share if quiet else None

    def back_off(self) -> None:
        """A growth straight after a shrink: the next shrink needs a window twice as long."""
        self.window_s = min(2 * self.window_s, SHRINK_WINDOW_MOST_S)

    def reset(self) -> None:
        """A growth after a shrink that held: the window is the rule's again."""
        self.window_s = SHRINK_WINDOW_S


class LineHistory:
    """The last ``rows`` lines pushed into the correlator (a ring), zeros before the first."""

    def __init__(self, rows: int, range_bins: int, dtype):
        self._ring = np.zeros((rows, range_bins), dtype)
        self.pushed = 0  # lines added so far

    def add(self, lines: np.ndarray) -> None:
        rows, count = len(self._ring), len(lines)
        if count >= rows:  # line k of the stream sits at row k mod rows
            self._ring[(self.pushed + np.arange(count - rows, count)) % rows] = lines[-rows:]
        else:
            at = self.pushed % rows
            first = min(count, rows - at)
            self._ring[at : at + first] = lines[:first]
            self._ring[: count - first] = lines[first:]
        self.pushed += count

    def last(self, count: int) -> np.ndarray:
        """The last ``count`` (≤ rows) lines added, oldest first; zeros before the first."""
        if count > len(self._ring):
            raise ValueError(f"the history holds {len(self._ring)} lines, not {count}")
        index = np.arange(self.pushed - count, self.pushed) % len(self._ring)
        out = self._ring[index]
        out[: max(0, count - self.pushed)] = 0
        return out


def history_lines(aperture: int, block: int) -> int:
    """H: the least multiple of ``block`` that is at least N - 1 (module docstring)."""
    return -(-(aperture - 1) // block) * block


class Prebuilt:
    """The correlator of ``config`` with blocks of ``block`` lines, built on a thread of its
    own from the first backlog over the limit (a shrink: from the quiet window's verdict): by
    the swap it is ready, and the swap only feeds it the history (psaltis-max, nonuniform:
    building 90-400 ms, feeding its 512 lines 28-38 ms, 2-core Zen 3)."""

    def __init__(self, config: Config, range_m: np.ndarray, block: int):
        self.block = int(block)
        self._built, self._error = None, None
        args = (config_with_block(config, block), range_m)
        self._thread = threading.Thread(target=self._build, args=args, daemon=True)
        self._thread.name = f"rtsar-grow-{block}"
        self._thread.start()

    def _build(self, config: Config, range_m: np.ndarray) -> None:
        try:
            self._built = make_ccd(config, range_m)
        except BaseException as exc:  # raised where the swap takes it
            self._error = exc

    def ready(self) -> bool:
        """Built (or failed: ``take`` raises): a swap now would not wait."""
        return not self._thread.is_alive()

    def failed(self) -> bool:
        """The build ended in an error."""
        return self.ready() and self._error is not None

    def take(self, history: np.ndarray):
        """The correlator, built (waited for), fed ``history`` (the last
        history_lines(N, block) lines of the stream) and its outputs of them dropped."""
        self._thread.join()
        if self._error is not None:
            raise self._error
        self._built.push(history)
        return self._built

    def discard(self) -> None:
        """Not needed after all (the block moved the other way): closed once built, on a
        thread of its own, so the stream does not wait for the build."""

        def close() -> None:
            self._thread.join()
            if self._built is not None:
                self._built.close()

        threading.Thread(target=close, daemon=True, name=f"rtsar-discard-{self.block}").start()


class BlockGrowth:
    """The correlator's block, doubled while a live run falls behind and shrunk back once it
    has room (module docstring).

    ``blocks``: the run's block and the larger ones it may grow to, in order; ``rate_hz``: the
    pulse rate the block periods are counted at.  ``after_push(engine, lines, backlog_s,
    now_s, busy_s)`` (after each push of ``lines`` into ``engine.correlator``, an
    rtsar.stream.engine StreamProcessor, ``backlog_s`` of pulses then waiting before it,
    ``busy_s`` each stage's busy seconds so far) → the new block where it changed, else 0."""

    def __init__(
        self, config: Config, blocks, rate_hz: float, range_bins: int, dtype, batch: int = 0
    ):
        self.blocks = [int(b) for b in blocks]
        if len(self.blocks) < 2 or self.blocks != sorted(set(self.blocks)):
            raise ValueError(f"blocks must be the run's and larger ones, got {blocks!r}")
        if not rate_hz > 0:
            raise ValueError(f"rate must be > 0 pulses/s, got {rate_hz!r}")
        self.config = config
        self.rate_hz = float(rate_hz)
        self.block = self.blocks[0]
        n = config.processor.aperture_pulses
        rows = max(history_lines(n, b) for b in self.blocks)
        self.history = LineHistory(rows, range_bins, dtype)
        self.watch = BacklogWatch(slack_s=batch / self.rate_hz)  # a lens call's pulses
        self.quiet = QuietWatch()
        self.due = False  # a growth decided, waiting for a push that ends on a block
        self.growths = self.shrinks = 0
        self.from_pulse = 0  # the stream's pulse from which the blocks are counted
        self.next: Prebuilt | None = None  # the next block's correlator, once a backlog was over
        self.smaller: Prebuilt | None = None  # the smaller block's, once a window was quiet
        self.quiet_share = 0.0  # the busiest stage's share in the window that shrank the block …
        self.quiet_limit_s = 0.0  # … and the backlog it stayed under
        self.last_change = ""  # "growth" or "shrink"
        self.last_change_s = 0.0  # when (the push's time)

    def counters(self) -> dict:
        return {
            "correlator_growths": self.growths,
            "correlator_shrinks": self.shrinks,
            "correlator_block_lines": self.block,
        }

    def close(self) -> None:
        """The run ended: the correlators built for a swap that did not come are closed."""
        self.next, self.smaller = _discarded(self.next), _discarded(self.smaller)

    def step(self, pipe, lines: np.ndarray) -> InfoChange | None:
        """After a push of ``lines`` in ``pipe`` (an rtsar.stream.pipeline.Pipeline), its
        backlog the pulses in its queues before the correlator: where the block changed, the
        lens aligns its calls to the new block (``lens_align`` from ``lens_align_from``,
        ``lens_hold_s``: two blocks' time; not in the overlapped layout, whose lens takes what
        waits), the run's ``notify`` is told why, and the stream's info with the new block in
        its config is returned (the strips after the old block's lines declare it, queued
        after them); else None."""
        was = self.block
        backlog_s = (pipe.q_shots.size + pipe.q_lines.size) / self.rate_hz
        busy_s = dict(pipe.stats.busy_s)
        now = self.after_push(pipe.engine, lines, backlog_s, time.perf_counter(), busy_s)
        if not now:
            return None
        s = pipe.settings
        if s.stages != "overlapped":  # the new blocks counted from the pulse of the swap
            s.lens_align_from, s.lens_hold_s = self.from_pulse, 2 * now / self.rate_hz
            s.lens_align = now
        info = InfoChange(replace(pipe.info, config=pipe.engine.config, config_dict={}))
        if pipe.notify is None:
            return info
        if now > was:
            limit_ms = backlog_limit_s(was, self.rate_hz) * 1e3
            why = (
                f"the work fell behind ({limit_ms:.0f} ms of pulses waiting for "
                f"{self.watch.window_s:g} s)"
            )
        else:
            why = (
                f"the work keeps up with room to spare (its busiest stage "
                f"{self.quiet_share:.0%} busy, the backlog under {self.quiet_limit_s * 1e3:.0f} "
                f"ms, for {self.quiet.window_s:g} s)"
            )
        verb = "grows" if now > was else "shrinks back"
        pipe.notify(f"{why}: the correlator's block {verb} from {was} to {now} lines")
        return info

    def after_push(
        self, engine, lines: np.ndarray, backlog_s: float, now_s: float, busy_s=None
    ) -> int:
        self.history.add(lines)
        at = self.blocks.index(self.block)
        grown = self.blocks[at + 1] if at + 1 < len(self.blocks) else 0
        if grown:
            limit_s = backlog_limit_s(self.block, self.rate_hz)
            if backlog_s > limit_s and self.next is None:  # behind, perhaps: build the next now
                self.next = Prebuilt(self.config, engine.range_m, grown)
            self.due = self.watch.observe(now_s, backlog_s, limit_s) or self.due
        down = self.blocks[at - 1] if at else 0
        if down and backlog_s > backlog_limit_s(down, self.rate_hz) and self.smaller is not None:
            self.smaller = _discarded(self.smaller)  # the room has gone while it was built
            self.quiet.restart()
        if down and not self.due and self.smaller is None and busy_s is not None:
            limit_s = backlog_limit_s(down, self.rate_hz)
            share = self.quiet.observe(now_s, backlog_s, limit_s, busy_s, self.block / down)
            if share is not None:  # room: build the smaller one, swapped once it is ready
                self.quiet_share, self.quiet_limit_s = share, limit_s
                self.smaller = Prebuilt(self.config, engine.range_m, down)
        old = engine.correlator
        n = self.config.processor.aperture_pulses
        if old.pulses_in - old.lines_out != n - 1:
            return 0  # a partial block held: the next push that ends one
        self.due = self.due and bool(grown)  # (the largest block has no larger one)
        if self.due:
            built = self.next or Prebuilt(self.config, engine.range_m, grown)
            self.next, self.smaller = None, _discarded(self.smaller)
            self.growths += 1
            if self.last_change == "shrink" and now_s - self.last_change_s >= SHRINK_HELD_S:
                self.quiet.reset()  # it held: the load that backed the window off is old
            elif self.last_change == "shrink":  # it did not hold: wait longer before the next
                self.quiet.back_off()
            self.last_change, self.last_change_s = "growth", now_s
        elif self.smaller is not None and self.smaller.failed():
            self.smaller = None  # a shrink is optional: the run keeps the block it has
            self.quiet.restart()
            return 0
        elif self.smaller is not None and self.smaller.ready():
            built, self.smaller, self.next = self.smaller, None, _discarded(self.next)
            self.shrinks += 1
            self.last_change, self.last_change_s = "shrink", now_s
        else:
            return 0
        history = self.history.last(history_lines(n, built.block))
        engine.correlator = built.take(history)
        engine.config = config_with_block(engine.config, built.block)
        old.close()
        self.block, self.due, self.from_pulse = built.block, False, self.history.pushed
        self.watch.restart()
        self.quiet.restart()
        return self.block


def _discarded(pending: Prebuilt | None) -> None:
    """None, once ``pending`` (if any) is discarded: what a swap not made leaves."""
    if pending is not None:
        pending.discard()


def why_fixed(p, physical=None, copies: int = 1, swath: bool = False) -> str:
    """Why the correlator of Processor ``p`` cannot grow its block in a live run ("" where it
    can): the correlators whose block a config sets, one receiver (``copies`` > 1: --height's
    receivers keep their own correlators), no swath workers, not --physical, not the
    Doppler-domain range migration, not the walk's ring (rtsar.ccd.walk_deskew: its turn
    counts pulses from the stream's start, which a correlator built mid-stream does not see)."""
    doppler = p.range_migration_taps and p.range_migration_domain == "doppler"
    walk = p.range_migration_taps and p.range_migration_domain == "walk"
    return (
        "swath workers correlate in their own processes" if swath
        else "--physical's CCD has no block" if physical is not None
        else "--height's receivers keep their own correlators" if copies > 1
        else "Doppler-domain migration has no block" if doppler
        else "the walk's ring turns from the stream's first pulse" if walk
        else f"the {p.correlator} correlator has no block" if p.correlator not in GROWING_KINDS
        else ""
    )  # fmt: skip


def growth_words(blocks) -> str:
    """The banner's words for a run whose block may grow (blocks: its own, then the larger)."""
    steps = " → ".join(f"{b:,}" for b in blocks)
    return (
        f"a backlog that lasts {GROW_WINDOW_S:g} s grows the block, {steps} lines at most, "
        f"and room to spare for {SHRINK_WINDOW_S:g} s shrinks it back"
    )


def growth_of(config: Config, settings, engine, physical=None, height=None, batch=0):
    """The BlockGrowth of a pipeline whose ``settings.grow_blocks`` name blocks to grow to
    (None where they name none); an error where its correlator cannot grow (why_fixed).
    ``batch``: the most pulses a lens call takes (0: the config's micro-batch)."""
    blocks = tuple(settings.grow_blocks)
    if len(blocks) < 2:
        return None
    copies = 1 if height is None else 2
    why = why_fixed(config.processor, physical, copies, engine.correlator is None)
    if why:
        raise ValueError(f"the correlator's block cannot grow: {why}")
    batch = batch or settings.max_batch or config.processor.micro_batch
    bins, rate_hz = len(engine.range_m), settings.grow_rate_hz
    return BlockGrowth(config, blocks, rate_hz, bins, engine.dtype, batch)
