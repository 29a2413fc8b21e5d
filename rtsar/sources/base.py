"""The common currency of all sources: a batch of shots with their sequence numbers and times.

A source is an iterator of :class:`ShotBatch`.  Sequence numbers are the instrument's pulse
counter (they may skip, repeat or go backwards on a bad link: :mod:`rtsar.ingest` sorts that
out); ``timestamp_s`` is the instrument's own clock; ``arrival_s`` is when the shot reached this
host, on the ``time.perf_counter()`` clock, and is what latency is measured from.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np


@dataclass
class ShotBatch:
    """``n`` shots: samples[n, samples_per_shot] (complex64) and per-shot metadata."""

    seq: np.ndarray  # int64[n], instrument pulse counter
    timestamp_s: np.ndarray  # float64[n], instrument clock (s)
    arrival_s: np.ndarray  # float64[n], host time.perf_counter() at arrival (s)
    samples: np.ndarray  # complex64[n, samples_per_shot]
    # Auxiliary receive channels of the same shots (reference interferometer, HCN cell, second
    # receiver, ...): name → complex64[n, samples_per_shot].  Empty for single-channel sources.
    aux: dict = field(default_factory=dict)
    # bool[n] or None: shots the source marks as standing for no data (a recording's zero
    # pulses, rtsar.sinks.raw_record pulse_flags): ingest flags them as it flags its own.
    flagged: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.seq)
        if not (len(self.timestamp_s) == len(self.arrival_s) == len(self.samples) == n):
            raise ValueError("ShotBatch fields must all have one entry per shot")
        if any(len(a) != n for a in self.aux.values()):
            raise ValueError("ShotBatch aux channels must have one entry per shot")
        if self.flagged is not None and len(self.flagged) != n:
            raise ValueError("ShotBatch flagged must have one entry per shot")

    def __len__(self) -> int:
        return len(self.seq)

    def split(self, count: int) -> tuple[ShotBatch, ShotBatch]:
        """The first ``count`` shots and the rest, as two batches (views, nothing copied)."""
        return tuple(
            ShotBatch(
                self.seq[sl],
                self.timestamp_s[sl],
                self.arrival_s[sl],
                self.samples[sl],
                {k: a[sl] for k, a in self.aux.items()},
                None if self.flagged is None else self.flagged[sl],
            )
            for sl in (slice(None, count), slice(count, None))
        )


def _shape(batch: ShotBatch):
    """What must agree for batches to be joined: each channel's width and type (None where a
    channel is not a 2-D array: ingest then judges each batch alone)."""
    channels = [("", batch.samples), *sorted(batch.aux.items())]
    shapes = []
    for name, a in channels:
        if not isinstance(a, np.ndarray) or a.ndim != 2:
            return None
        shapes.append((name, a.shape[1], a.dtype))
    return tuple(shapes)


def join_batches(batches: list[ShotBatch]) -> list[ShotBatch]:
    """Consecutive batches of the same channels (widths and types) as one batch each run.

    A source that releases a shot at a time gives the pipeline's ingest one batch a shot: its
    checks cost the same for one shot as for a block's (psaltis-max, 2-core Intel Xeon: about
    20 µs a call either way), so the batches taken together are checked as one (the same
    shots in the same order: ingest's verdicts and counters do not depend on where a batch
    ends).  A batch that is empty, or whose channels differ, stays alone."""
    out: list[ShotBatch] = []
    run: list[ShotBatch] = []
    shape = None

    def close() -> None:
        if len(run) == 1:
            out.append(run[0])
        elif run:
            flagged = None
            if any(b.flagged is not None for b in run):
                flagged = np.concatenate(
                    [np.zeros(len(b), bool) if b.flagged is None else b.flagged for b in run]
                )
            out.append(
                ShotBatch(  # numbers and times in ingest's own types (int64: no float mixing)
                    np.concatenate([np.asarray(b.seq, np.int64) for b in run]),
                    np.concatenate([np.asarray(b.timestamp_s, np.float64) for b in run]),
                    np.concatenate([np.asarray(b.arrival_s, np.float64) for b in run]),
                    np.concatenate([b.samples for b in run]),
                    {k: np.concatenate([b.aux[k] for b in run]) for k in run[0].aux},
                    flagged,
                )
            )
        run.clear()

    for b in batches:
        this = _shape(b) if len(b) else None
        if this is None or this != shape:
            close()
        if this is None:
            out.append(b)
        else:
            run.append(b)
        shape = this
    close()
    return out


class Source(ABC):
    """Base class of shot sources: iterate to receive :class:`ShotBatch` es.

    ``live`` sources (simulator at its PRF, serial instrument) cannot be paused: when the
    pipeline is full their shots are dropped and counted.  Non-live sources (replay) block.
    ``counters`` holds the source's own tallies (e.g. frames with a bad CRC); ``close`` stops it.
    ``failure`` is None while the source works and after a clean end, else why it ended (a
    link lost for good); ``notify``, when set, receives one-line messages about the link as
    they happen (the application prints them).
    """

    live: bool = True
    paced: bool = True  # shots come at a rate (False: a recording replayed as fast as it goes)
    description: str = "source"

    def __init__(self):
        self.counters: dict[str, int] = {}
        self._stop = False
        self.failure: str | None = None
        self.notify = None
        # The time of the stream's pulse 0 (naive UTC) where the source knows it (a replayed
        # recording's collection start); None: the pipeline takes the first shot's arrival,
        # unless ``clock_is_start`` is False (a replay of a recording that kept none: unknown).
        self.collection_start = None
        self.clock_is_start = True
        # The instrument file of a real instrument whose echoes these are (an imported
        # recording's, run --instrument's): its images are held to the instrument's own beam.
        self.instrument_file = ""

    def _say(self, message: str) -> None:
        if self.notify is not None:
            self.notify(message)

    @abstractmethod
    def __iter__(self) -> Iterator[ShotBatch]:
        """Yield batches until the source ends or ``close()`` is called."""

    def aux_channels(self) -> tuple[str, ...] | None:
        """The auxiliary channels this source delivers with every shot, known before the run
        starts (rtsar.app.live refuses a correction or height stage that reads another one
        before any work); None when only the stream itself can tell.  Here: none (the main
        channel only)."""
        return ()

    def close(self) -> None:
        self._stop = True
