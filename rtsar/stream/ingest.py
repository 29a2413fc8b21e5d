"""Ingest checks: turn what a source delivers into a gap-free, in-order pulse stream.

The azimuth correlator assumes pulse p was taken at x_p = x_0 + p·d (Psaltis & Wagner 1981: the
CCD shifts one row per pulse), so the position of every pulse in the stream must be kept even when
the link loses, repeats or reorders shots.  The instrument's sequence number says where a shot
belongs:

* a gap (sequence jumps ahead by g ≤ ``max_gap_pulses``, by default one aperture N): g zero
  pulses are inserted, flagged (they cost no memory, and the AO lens skips them: a zero pulse
  compresses to a zero line), so zero-filling is bounded whatever number a frame carries;
* a duplicate (a number of the current run seen within the last ``memory_pulses``, on a shot
  no newer than the newest shot accepted) or a late shot (its slot was already zero-filled):
  dropped and counted;
* a number already taken on a shot *newer* than the newest shot accepted, by the instrument's
  clock (``ShotBatch.timestamp_s``): not a repeat but a new shot, so the counter was reset
  (a step back of a few shots is such a reset too); without a clock (times NaN, or not
  advancing) such shots read as duplicates;
* any other jump, forward beyond the bound or backward (an instrument restart, a counter reset):
  the shot is held as a *candidate* until the next shot says what it was.  If the next shot
  continues from it (number + 1), it is a *discontinuity*: N zero pulses are inserted (they
  clear the CCD so no line mixes the two sides), the held shot follows and the count restarts
  from its number (azimuth positions after it are relative to the restart).  Otherwise it was
  a stray shot (a number out of thin air): dropped and counted in ``stray_pulses``, and the
  stream goes on untouched.  At the end of a stream (:meth:`Ingest.flush`) a held candidate is
  taken as a discontinuity, so no shot is lost;
* NaN/Inf samples or the wrong number of samples: the pulse is zeroed and flagged;
* a shot the source marks as standing for no data (``ShotBatch.flagged``: a recording's zero
  pulses, those the live run's ingest inserted or zeroed, or its recorder could not keep):
  zeroed and flagged like one of ingest's own (counted in ``marked_pulses``), so a
  recording's image flags the lines the live image flagged.

A source whose numbers count from the instrument's pulse 0 (``origin_seq``: a GNU Radio stream,
whose item offsets count from the flowgraph's start) anchors the stream: its first shot, number
s0, is pulse s0 - origin_seq of the scan, not pulse 0.  ``start_pulses`` says so (the stream's
owner moves pulse 0's position by that many steps, rtsar.stream.pipeline), and the pulses sent
before the first one received are counted in ``pulses_before_start``: a subscriber that joins a
running flowgraph keeps every position along track and says what it missed.

Every shot received is accounted for: ``pulses_received`` = ``pulses_accepted`` + ``duplicates``
+ ``late_pulses`` + ``stray_pulses`` (+ 1 while a candidate is held).

Auxiliary channels (``ShotBatch.aux``: reference interferometer, HCN cell, second receiver) travel
with their pulse: filled, zeroed and dropped together with it.  Their names and lengths (which may
differ from the main channel's: an HCN channel is sampled faster) are fixed by the first batch.
A shot whose auxiliary channel is bad (NaN/Inf, wrong length, missing) is zeroed in every channel
and counted like a bad main channel.

Nothing is silent: every case has a counter (``Ingest.counters``), reported in strip headers and
stats.  Flagged pulses mark the image lines whose aperture contains them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..samples import nonfinite_shots
from ..sources.base import ShotBatch

COUNTERS = (
    "pulses_received",  # shots delivered by the source
    "pulses_accepted",  # shots that entered the stream with their own samples
    "gap_pulses",  # zero pulses inserted for missing sequence numbers
    "gaps",  # sequence jumps filled
    "discontinuities",  # restarts of the count (jumps beyond max_gap_pulses, confirmed)
    "duplicates",  # shots whose sequence number was already in the stream
    "late_pulses",  # shots arriving after their slot was zero-filled
    "stray_pulses",  # shots whose number fitted neither the run nor a restart, dropped
    "nonfinite_pulses",  # shots holding NaN/Inf, zeroed
    "wrong_length_pulses",  # shots with the wrong sample count (or a missing channel), zeroed
    "pulses_before_start",  # an anchored stream: pulses of the scan before the first received
    "marked_pulses",  # shots the source marks as no data (a recording's zero pulses), flagged
)


@dataclass
class PulseBlock:
    """Consecutive pulses of the stream: pulse index first_pulse .. first_pulse + n - 1.

    ``seq`` and ``time_s``: the instrument's pulse number and clock of each pulse (None where
    the block was made without them); ``inserted``: the zero pulses ingest inserted (a gap's
    fill, a restart's clearing), which carry no shot (seq 0, time NaN)."""

    first_pulse: int
    samples: np.ndarray  # complex64[n, samples_per_shot] (or [n, range_bins] after the lens)
    arrival_s: np.ndarray  # float64[n], perf_counter time the shot arrived (fill: next arrival)
    flagged: np.ndarray  # bool[n], zero-filled or zeroed pulses
    aux: dict = field(default_factory=dict)  # name → complex64[n, samples_per_shot]
    seq: np.ndarray | None = None  # int64[n], the instrument's pulse numbers
    time_s: np.ndarray | None = None  # float64[n], the instrument's clock
    inserted: np.ndarray | None = None  # bool[n], zero pulses inserted by ingest

    def __len__(self) -> int:
        return len(self.samples)

    def with_samples(self, samples: np.ndarray, aux: dict | None = None) -> PulseBlock:
        """The same pulses carrying other samples (the lens's lines; ``[:, :0]``: metadata)."""
        return PulseBlock(self.first_pulse, samples, self.arrival_s, self.flagged, aux or {})

    def slice(self, start: int, stop: int) -> PulseBlock:
        sl = slice(start, stop)
        return PulseBlock(
            self.first_pulse + start,
            self.samples[sl],
            self.arrival_s[sl],
            self.flagged[sl],
            {k: v[sl] for k, v in self.aux.items()},
            *(None if a is None else a[sl] for a in (self.seq, self.time_s, self.inserted)),
        )


def concat_blocks(blocks: list[PulseBlock]) -> PulseBlock:
    """Consecutive pulse blocks as one (raises if they are not consecutive)."""
    if len(blocks) == 1:
        return blocks[0]
    for a, b in zip(blocks, blocks[1:], strict=False):
        if b.first_pulse != a.first_pulse + len(a):  # ingest guarantees this
            raise RuntimeError("pulse blocks are not consecutive")

    def joined(name):  # a field of every block, or None if one lacks it
        parts = [getattr(b, name) for b in blocks]
        return None if any(p is None for p in parts) else np.concatenate(parts)

    return PulseBlock(
        blocks[0].first_pulse,
        np.concatenate([b.samples for b in blocks]),
        np.concatenate([b.arrival_s for b in blocks]),
        np.concatenate([b.flagged for b in blocks]),
        {k: np.concatenate([b.aux[k] for b in blocks]) for k in blocks[0].aux},
        joined("seq"),
        joined("time_s"),
        joined("inserted"),
    )


def regroup_blocks(blocks: list[PulseBlock], most: int):
    """Consecutive pulse blocks regrouped into blocks of at most ``most`` pulses."""
    pending, size = [], 0
    for b in blocks:
        start = 0
        while start < len(b):
            take = min(len(b) - start, most - size)
            pending.append(b.slice(start, start + take))
            size += take
            start += take
            if size == most:
                yield concat_blocks(pending)
                pending, size = [], 0
    if pending:
        yield concat_blocks(pending)


@dataclass
class _Candidate:
    """A shot whose number would restart the count, held until the next shot confirms it."""

    seq: int
    samples: np.ndarray  # [1, samples_per_shot]
    arrival_s: np.ndarray  # [1]
    flagged: np.ndarray  # [1]
    aux: dict
    time_s: np.ndarray  # [1], the instrument's clock

    def block(self, first_pulse: int) -> PulseBlock:
        one = np.array([self.seq], np.int64)
        return PulseBlock(
            first_pulse, self.samples, self.arrival_s, self.flagged, self.aux, one, self.time_s,
            np.zeros(1, bool),
        )  # fmt: skip


class Ingest:
    """Sequence, value and shape checks; call with each ShotBatch, get PulseBlocks back.

    ``max_gap_pulses``: the longest run of missing numbers that is zero-filled (one aperture is
    the usual choice); ``memory_pulses``: how far back duplicates and late shots are recognised
    (default 4 × the larger of the aperture and the gap bound); ``origin_seq``: the number of
    the scan's pulse 0, for a source that numbers from it (module docstring; None: the first
    shot is pulse 0).  Call :meth:`flush` at the end of a stream.
    """

    def __init__(
        self,
        samples_per_shot: int,
        aperture_pulses: int,
        max_gap_pulses: int,
        dtype=np.complex64,
        memory_pulses: int | None = None,
        origin_seq: int | None = None,
    ):
        self.samples_per_shot = int(samples_per_shot)
        self.dtype = np.dtype(dtype)  # the processor's sample type (complex128 stays double)
        self.aperture_pulses = int(aperture_pulses)
        self.max_gap_pulses = max(int(max_gap_pulses), 1)
        self.memory_pulses = int(
            memory_pulses or 4 * max(self.aperture_pulses, self.max_gap_pulses)
        )
        # Zero-filled pulses are read-only views of one zero row: a long gap costs no memory.
        self._zero_row = np.zeros((1, self.samples_per_shot), self.dtype)
        self.counters = dict.fromkeys(COUNTERS, 0)
        self.aux_lengths: dict[str, int] | None = None  # name → samples, fixed by the first batch
        self.next_pulse = 0  # stream index of the next pulse
        self._next_seq: int | None = None  # sequence number expected next
        self._run_start = 0  # first sequence number of the current run (since the last restart)
        self._filled: set[int] = set()  # recently zero-filled sequence numbers (late detection)
        self._recent_low = 0  # sequence numbers below this are forgotten
        self._candidate: _Candidate | None = None
        self.origin_seq = origin_seq
        self.start_pulses = 0  # the scan's pulse number of stream pulse 0 (module docstring)
        self._newest_s: float | None = None  # the newest instrument time of an accepted shot

    def _zeros(self, count: int, arrival: float) -> PulseBlock:
        block = PulseBlock(
            self.next_pulse,
            np.broadcast_to(self._zero_row, (count, self.samples_per_shot)),
            np.full(count, arrival),
            np.ones(count, bool),
            {
                k: np.broadcast_to(np.zeros((1, m), self.dtype), (count, m))
                for k, m in (self.aux_lengths or {}).items()
            },
            np.zeros(count, np.int64),
            np.full(count, np.nan),
            np.ones(count, bool),
        )
        self.next_pulse += count
        return block

    def _forget_old(self) -> None:
        low = self._next_seq - self.memory_pulses
        if low > self._recent_low + self.memory_pulses:  # amortised clean-up
            self._filled = {s for s in self._filled if s >= low}
            self._recent_low = low

    def __call__(self, batch: ShotBatch) -> list[PulseBlock]:
        n = len(batch)
        c = self.counters
        c["pulses_received"] += n
        if n == 0:
            return []
        if self.aux_lengths is None:
            self.aux_lengths = {
                k: int(np.shape(a)[1]) if np.ndim(a) == 2 else self.samples_per_shot
                for k, a in sorted(batch.aux.items())
            }
        lengths = {"": self.samples_per_shot, **self.aux_lengths}
        channels = {k: batch.samples if k == "" else batch.aux.get(k) for k in lengths}
        flagged = np.zeros(n, bool)
        wrong = any(
            a is None or np.ndim(a) != 2 or np.shape(a)[1] != lengths[k]
            for k, a in channels.items()
        )
        if wrong:
            c["wrong_length_pulses"] += n
            channels = {k: np.zeros((n, m), self.dtype) for k, m in lengths.items()}
            flagged[:] = True
        else:
            channels = {k: np.asarray(a, self.dtype) for k, a in channels.items()}
            bad = nonfinite_shots(channels.values())
            if bad.any():
                c["nonfinite_pulses"] += int(bad.sum())
            marked = None if batch.flagged is None else np.asarray(batch.flagged, bool) & ~bad
            if marked is not None and marked.any():
                c["marked_pulses"] += int(marked.sum())
                bad = bad | marked
            if bad.any():
                channels = {k: a.copy() for k, a in channels.items()}
                for a in channels.values():
                    a[bad] = 0
                flagged |= bad
        samples = channels.pop("")
        aux = channels
        seq = np.asarray(batch.seq, np.int64)
        arrival = np.asarray(batch.arrival_s, np.float64)
        times = np.asarray(batch.timestamp_s, np.float64)
        if self._next_seq is None:
            self._next_seq = self._run_start = self._recent_low = int(seq[0])
            if self.origin_seq is not None:
                self.start_pulses = int(seq[0]) - int(self.origin_seq)
                c["pulses_before_start"] += max(self.start_pulses, 0)
        # Fast path: the batch continues the stream exactly (the normal case): numbers that
        # rise strictly and span n - 1 rise by one each (for two, the span alone says so).
        span = int(seq[-1]) - int(seq[0])
        contiguous = n == 1 or (span == n - 1 and (n == 2 or bool(np.all(seq[1:] > seq[:-1]))))
        if self._candidate is None and seq[0] == self._next_seq and contiguous:
            c["pulses_accepted"] += n
            self._next_seq += n
            self._newest(times)
            block = PulseBlock(
                self.next_pulse, samples, arrival, flagged, aux, seq, times, np.zeros(n, bool)
            )
            self.next_pulse += n
            return [block]
        return self._slow(seq, samples, arrival, flagged, aux, times)

    def _is_newer(self, time_s: float) -> bool:
        """A shot taken after the newest shot accepted (by the instrument's clock): under a
        number already taken it is a new shot, not a repeat, so the counter was reset."""
        return self._newest_s is not None and bool(time_s > self._newest_s)

    def _newest(self, times: np.ndarray) -> None:
        """The newest instrument time of an accepted shot (what tells a repeat from a new
        shot under an old number: module docstring): the latest finite time of every shot
        accepted, so where a batch ends does not matter (it read the last shot's time of each
        batch, and a batch ending on a NaN time, or on a clock that stepped back, then left
        a repeat read as a reset, or a reset as a repeat, depending on how shots were
        batched)."""
        t = float(np.max(times, initial=-np.inf, where=np.isfinite(times)))
        if t > -np.inf:  # (none finite: nothing to go by)
            self._newest_s = t if self._newest_s is None else max(self._newest_s, t)

    def _restart(self, cand: _Candidate) -> list[PulseBlock]:
        """A confirmed restart: N zero pulses clear the CCD, then the held shot opens the run."""
        c = self.counters
        c["discontinuities"] += 1
        c["gap_pulses"] += self.aperture_pulses
        c["pulses_accepted"] += 1
        self._filled.clear()
        out = [self._zeros(self.aperture_pulses, float(cand.arrival_s[0]))]
        out.append(cand.block(self.next_pulse))
        self._newest_s = None  # a new run: its own clock (an instrument restart may reset it)
        self._newest(cand.time_s)
        self.next_pulse += 1
        self._next_seq = cand.seq + 1
        self._run_start = self._recent_low = cand.seq
        return out

    def flush(self) -> list[PulseBlock]:
        """At the end of a stream: a held candidate is taken as a restart (nothing is lost)."""
        cand, self._candidate = self._candidate, None
        return self._restart(cand) if cand is not None else []

    def _slow(self, seq, samples, arrival, flagged, aux, times) -> list[PulseBlock]:
        """Shot by shot: gaps, duplicates, late shots, candidates for a restart."""
        c = self.counters
        out: list[PulseBlock] = []
        run_start = None  # start of the current run of in-order shots within this batch

        def close_run(end):
            nonlocal run_start
            if run_start is not None:
                sl = slice(run_start, end)
                out.append(
                    PulseBlock(
                        self.next_pulse,
                        samples[sl],
                        arrival[sl],
                        flagged[sl],
                        {k: a[sl] for k, a in aux.items()},
                        seq[sl],
                        times[sl],
                        np.zeros(end - run_start, bool),
                    )
                )
                self._newest(times[sl])
                self.next_pulse += end - run_start
                c["pulses_accepted"] += end - run_start
                run_start = None

        for i, s in enumerate(seq.tolist()):
            cand = self._candidate
            if cand is not None:
                self._candidate = None
                if s == cand.seq + 1:  # the instrument goes on from the new number: a restart
                    out.extend(self._restart(cand))
                else:  # neither: the held shot was a stray
                    c["stray_pulses"] += 1
            jump = s - self._next_seq
            if jump == 0:
                if run_start is None:
                    run_start = i
                self._next_seq += 1
                continue
            close_run(i)
            known = max(self._run_start, self._next_seq - self.memory_pulses)
            if 0 < jump <= self.max_gap_pulses:
                c["gaps"] += 1
                c["gap_pulses"] += jump
                self._filled.update(range(self._next_seq, s))
                out.append(self._zeros(jump, arrival[i]))
                self._next_seq = s + 1
                run_start = i
            elif jump < 0 and s >= known and not self._is_newer(times[i]):
                if s in self._filled:
                    c["late_pulses"] += 1
                    self._filled.discard(s)
                else:
                    c["duplicates"] += 1
            else:  # beyond the gap bound, back before what is remembered, or a reset: hold it
                sl = slice(i, i + 1)
                self._candidate = _Candidate(
                    s,
                    samples[sl],
                    arrival[sl],
                    flagged[sl],
                    {k: a[sl] for k, a in aux.items()},
                    times[sl],
                )
        close_run(len(seq))
        self._forget_old()
        return out
