"""Replay of shots from a recording (or an in-memory array) at the real rate, a factor, or max.

``rate="real"`` releases shot n at t0 + n/PRF (absolute schedule: no drift), a number f at
t0 + n/(f·PRF), ``"max"`` as fast as the pipeline takes them.  Replay is not live: when the
pipeline is full it waits (back-pressure) instead of dropping.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np

from .base import ShotBatch, Source
from .formats.timebase import shifted
from .pacing import Pacer, next_release, release_chunk
from .rows import Rows


def parse_rate(text: str | float) -> float | None:
    """'real' → 1.0, 'max' → None (unpaced), '2.5' → 2.5; ValueError otherwise."""
    if isinstance(text, (int, float)):
        value = float(text)
    elif text == "max":
        return None
    elif text == "real":
        return 1.0
    else:
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"rate must be 'real', 'max' or a factor > 0, got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(
            f"rate factor must be a finite number > 0 ('max': as fast as it goes), got {text!r}"
        )
    return value


READ_AHEAD_PULSES = 64  # a replay reads its recording this many pulses at a time


class ReplaySource(Source):
    """Shots from array-likes (an h5py dataset or NumPy arrays) at ``rate`` (see parse_rate).

    ``shots[pulse, sample]``, ``pulse_index`` and ``time_s`` per shot, and ``aux`` (auxiliary
    channel name → [pulse, sample]) travelling with them; ``prf_hz`` is the recorded rate.
    ``flagged`` (bool [pulse], optional): shots that stand for no data (a live recording's
    zero pulses, its ``pulse_flags``): ingest flags them, so the lines they touch are flagged
    as the live run flagged them.  Paced replay: arrival = scheduled time; unpaced: the time
    the shot was read.
    """

    live = False

    def __init__(
        self,
        shots,
        pulse_index,
        time_s,
        prf_hz: float,
        rate: str | float = "real",
        batch: int = 64,
        description: str = "replay",
        live: bool = False,
        aux: dict | None = None,
        flagged=None,
    ):
        super().__init__()
        self.live = live  # True: behave as an instrument (dropped when the pipeline is full)
        self.shots = shots
        self.aux = dict(aux or {})  # auxiliary channel name → array-like [pulse, sample]
        self.pulse_index = np.asarray(pulse_index, np.int64)
        self.time_s = np.asarray(time_s, np.float64)
        self.total = len(self.pulse_index)
        if not (len(shots) == len(self.time_s) == self.total):
            raise ValueError("shots, pulse_index and time_s must have one entry per shot")
        if any(len(a) != self.total for a in self.aux.values()):
            raise ValueError("every auxiliary channel must have one entry per shot")
        self.flagged = None if flagged is None else np.asarray(flagged, bool)
        if self.flagged is not None and len(self.flagged) != self.total:
            raise ValueError("flagged must have one entry per shot")
        self.prf_hz = float(prf_hz)
        self.factor = parse_rate(rate)
        self.paced = self.factor is not None  # "max": as fast as the pipeline takes them
        self.chunk = batch if self.factor is None else release_chunk(self.prf_hz * self.factor)
        self.released = 0
        self.description = description
        # (shots released, perf_counter time) of the first and latest release: achieved rate.
        self.first_release: tuple[int, float] | None = None
        self.last_release: tuple[int, float] | None = None

    @classmethod
    def from_recording(
        cls, recording, rate="real", batch: int = 64, channels=(), first: int = 0, count=None
    ) -> ReplaySource:
        """The recording's shots and its auxiliary ``channels`` (those the processing reads); a
        live recording's zero pulses (``pulse_flags``) are flagged.  ``first``, ``count``: the
        shots first … first + count - 1 only (default: all), read from the file as they go."""
        total = len(recording.pulse_index)
        count = total - first if count is None else count
        if not (0 <= first and 1 <= count and first + count <= total):
            raise ValueError(f"shots {first} … {first + count - 1} of a recording of {total}")
        part = slice(first, first + count)
        flags = getattr(recording, "pulse_flags", None)  # (CPHD, SigMF: none)
        words = _rate_words(rate)
        if count < total:
            words += f"; shots {first:,} … {first + count - 1:,} of {total:,}"
        part_of = (lambda a: a) if count == total else (lambda a: Rows(a, count, first))
        source = cls(
            part_of(recording.shots),
            recording.pulse_index[part],
            recording.time_s[part],
            recording.config.geometry.prf_hz,
            rate,
            batch,
            description=f"replay of {recording.path} ({words})",
            aux={name: part_of(recording.channels[name]) for name in channels},
            flagged=None if flags is None else flags[part] != 0,
        )
        start = getattr(recording, "collection_start", None)  # the UTC of time_s = 0
        if start is not None and first:  # a part: the stream's pulse 0 is shot ``first``
            start = shifted(start, recording.time_s[first] - recording.time_s[0])
        source.collection_start = start
        source.clock_is_start = False  # a replay's processing time is not its collection's
        source.instrument_file = str(getattr(recording, "attrs", {}).get("instrument_file") or "")
        return source

    def aux_channels(self) -> tuple[str, ...]:
        """The auxiliary channels given (``aux``): those it releases with every shot."""
        return tuple(self.aux)

    def __iter__(self) -> Iterator[ShotBatch]:
        pacer = None if self.factor is None else Pacer(self.prf_hz * self.factor)
        ahead = ReadAhead(self.shots, self.aux)
        p = 0
        while p < self.total and not self._stop:
            left = self.total - p
            n = min(self.chunk, left) if pacer is None else next_release(pacer, p, self.chunk, left)
            samples, aux = ahead.take(p, n)
            if pacer is None:
                arrival = np.full(n, time.perf_counter())
            else:
                pacer.wait(p + n - 1, lambda: self._stop)
                arrival = pacer.t0 + np.arange(p, p + n) / pacer.rate_hz
            self.last_release = (p + n, time.perf_counter())
            if self.first_release is None:
                self.first_release = self.last_release
            flagged = None if self.flagged is None else self.flagged[p : p + n]
            yield ShotBatch(
                self.pulse_index[p : p + n], self.time_s[p : p + n], arrival, samples, aux,
                flagged,
            )  # fmt: skip
            p += n
            self.released = p

    def achieved_rate_hz(self) -> float:
        """Shots per second between the first and the latest release (NaN before two)."""
        if self.first_release is None or self.last_release[0] == self.first_release[0]:
            return float("nan")
        (n0, t0), (n1, t1) = self.first_release, self.last_release
        return (n1 - n0) / (t1 - t0)


class ReadAhead:
    """A recording's shots (and auxiliary channels) read ``block`` pulses at a time and
    handed out in the smaller releases of a paced replay: one read of a file (h5py: ~0.1 ms of
    holding the interpreter a call) serves many releases, not one each."""

    def __init__(self, shots, aux: dict, block: int = READ_AHEAD_PULSES):
        self.shots, self.aux, self.block = shots, aux, int(block)
        self.first = self.stop = 0
        self.samples = np.zeros((0, 0), np.complex64)
        self.aux_samples: dict = {}

    def take(self, p: int, n: int) -> tuple[np.ndarray, dict]:
        """Pulses p … p + n - 1: (shots, auxiliary channels), complex64 views."""
        if not (self.first <= p and p + n <= self.stop):
            end = min(len(self.shots), p + max(n, self.block))
            self.samples = np.asarray(self.shots[p:end], np.complex64)
            self.aux_samples = {k: np.asarray(v[p:end], np.complex64) for k, v in self.aux.items()}
            self.first, self.stop = p, end
        a, b = p - self.first, p - self.first + n
        return self.samples[a:b], {k: v[a:b] for k, v in self.aux_samples.items()}


def _rate_words(rate) -> str:
    """A replay rate in words: real, max, or a factor as '5× real rate' (not a bare 5)."""
    factor = parse_rate(rate)  # a ValueError naming the choices for anything else
    if factor is None or rate == "real":
        return "max" if factor is None else "real"
    return f"{factor:g}× real rate"
