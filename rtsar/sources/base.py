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
        # recording's collection start); None: the pipeline takes the first shot's arrival.
        self.collection_start = None

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
