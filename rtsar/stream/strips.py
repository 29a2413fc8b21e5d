"""Strips: runs of finished image lines, the unit of publication; what sinks are told.

A sink (publisher, image recorder, test collector) receives each :class:`Strip` and the run's
:class:`StreamInfo` (identity, configuration, axes, clock) — never the pipeline itself — through
the four methods of :class:`StripSink`.
"""

from __future__ import annotations

import math
import uuid
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from ..ccd.base import beam_look_back_m, line_azimuth_m
from ..params import Config
from ..sources.formats.timebase import format_utc, from_unix_s


@dataclass
class LineBlock:
    """Finished image lines with the times and flags of the pulses that made them."""

    first_line: int
    lines: np.ndarray  # complex64[n, range_bins]
    first_arrival_s: np.ndarray  # float64[n], arrival of pulse j (first contributing)
    last_arrival_s: np.ndarray  # float64[n], arrival of pulse j + N - 1 (last contributing)
    flagged: np.ndarray  # bool[n], aperture holds a zero-filled / zeroed pulse

    def __len__(self) -> int:
        return len(self.lines)

    def slice(self, start: int, stop: int) -> LineBlock:
        return LineBlock(
            self.first_line + start,
            self.lines[start:stop],
            self.first_arrival_s[start:stop],
            self.last_arrival_s[start:stop],
            self.flagged[start:stop],
        )


@dataclass
class Strip:
    """A run of consecutive image lines, the unit of publication."""

    seq: int
    first_line: int
    lines: np.ndarray  # complex64[n, range_bins]
    azimuth_m: np.ndarray  # float64[n]
    first_arrival_s: float  # perf_counter time, first pulse contributing to the first line
    last_arrival_s: float  # perf_counter time, last pulse contributing to the last line
    flagged_lines: list[tuple[int, int]]  # [(first_line, count)] runs of flagged lines
    counters: dict = field(default_factory=dict)  # every counter of the run when it was sent


@dataclass(frozen=True)
class StreamInfo:
    """What a sink knows of the run: identity, configuration, axes and clock."""

    stream_id: str  # random hex id of this run
    config: Config
    source: str  # the source's description
    lens_backend: str
    range_m: np.ndarray  # slant range of each column
    start_along_track_m: float  # platform position of pulse 0
    clock_offset_s: float  # perf_counter time + this = UNIX time
    heights: bool = False  # height strips (3D) are published beside the image strips
    height_kind: str = ""  # their method: "insal" or "sam"
    config_dict: dict = field(default_factory=dict)  # config.to_dict(), formed once
    corrections: tuple = ()  # names of the correction stages, in the order they run
    correction_specs: tuple = ()  # the --correct values as given (keys and all), in that order
    physical: dict | None = None  # the physical mode's settings (PhysicalSettings.to_dict)
    # ISO 8601 UTC of the stream's pulse 0 (rtsar.sources.formats.timebase): a replayed
    # recording's own, else the processor's clock at the first shot's arrival (set once, by
    # the source stage, before any strip or recorded pulse exists)
    collection_start_utc: str | None = None
    instrument_file: str = ""  # a real instrument's echoes: its file (rtsar.sources.base)

    def __post_init__(self):
        if not self.config_dict:
            object.__setattr__(self, "config_dict", self.config.to_dict())

    def first_shot_at(self, perf_s: float) -> None:
        """Where no collection start is known, the processor's clock (UTC) at the first shot's
        arrival (``perf_s``, perf_counter) becomes it; once (the info is otherwise fixed)."""
        if self.collection_start_utc is None:
            when = utc_text(from_unix_s(self.unix_s(perf_s)))
            object.__setattr__(self, "collection_start_utc", when)

    @property
    def azimuth_step_m(self) -> float:
        return self.config.geometry.along_track_step_m

    @cached_property
    def look_back_m(self) -> float:
        """The squinted beam's offset u_mid (rtsar.ccd.base.beam_look_back_m), formed once."""
        return beam_look_back_m(self.config)

    def azimuth_m(self, first_line: int, count: int) -> np.ndarray:
        """Along-track position of image lines (the centre of each line's aperture)."""
        return line_azimuth_m(
            self.config, self.start_along_track_m, first_line, count, self.look_back_m
        )

    def unix_s(self, perf_s: float) -> float:
        """A perf_counter time as UNIX time."""
        return float(perf_s) + self.clock_offset_s


class StripSink:
    """What the pipeline hands its output to; every method is a no-op unless overridden.

    ``strip``: a strip of image lines; ``height``: a height strip (3D imaging,
    rtsar.topo.stream.HeightStrip, with its own sequence number); ``stats``: the periodic stats
    dictionary (docs/pages/reference/wire.md); ``end``: the final stats, once; ``counters``: the
    sink's own counters, reported with the run's; ``hurry``: the run is being stopped.  A sink
    with ``wants_pulses`` also receives the stream's pulses as ingest made them (``pulses``).
    A sink that ``ends_first`` (a file writer: its end flushes and closes the file) is ended
    before the others, whose end then carries its last counters (a recording's rows).
    """

    wants_pulses = False
    ends_first = False

    def pulses(self, block, info: StreamInfo) -> None:
        """Consecutive pulses of the stream (rtsar.stream.ingest.PulseBlock: the shots with
        every channel, the instrument's numbers and clock, the inserted and zeroed pulses), in
        order, from the lens thread, before any processing: never waits (a recorder queues)."""

    def strip(self, strip: Strip, info: StreamInfo) -> None:
        pass

    def height(self, strip, seq: int, info: StreamInfo) -> None:
        pass

    def stats(self, stats: dict, info: StreamInfo) -> None:
        pass

    def end(self, stats: dict, info: StreamInfo) -> None:
        pass

    def counters(self) -> dict[str, int]:
        """What the sink counts (e.g. a publisher's stalled subscribers), merged into the run's."""
        return {}

    def hurry(self) -> None:
        """The run must end soon (Ctrl-C, a signal, a deadline): stop waiting on anyone."""


@dataclass(frozen=True)
class InfoChange:
    """The stream's info from here on, in the queue of image lines (the correlator's block
    changed, rtsar.stream.growth): an item of no lines."""

    info: StreamInfo

    def __len__(self) -> int:
        return 0


class StripAssembler:
    """Collects line blocks in order and cuts them into strips of any length; knows when the
    oldest line held came (``due``: the strip deadline)."""

    def __init__(self, info: StreamInfo):
        self.info = info  # the stream's, as the strips published next declare it
        self._pending: list[LineBlock] = []
        self._came_s: list[float] = []  # when each pending block came (the strip stage's clock)
        self.held = 0  # lines pending
        self.seq = 0  # the next strip's number
        self._switches: list[tuple[int, StreamInfo]] = []  # (lines held before it, new info)

    def add(self, block: LineBlock | InfoChange, now_s: float = 0.0) -> None:
        """A block of lines, come at ``now_s`` (seconds on the caller's clock); or the stream's
        info as it is from here (the correlator's block changed, rtsar.stream.growth): the
        lines held before it go out first, as strips of the old info (``due``)."""
        self._switch()
        if isinstance(block, InfoChange):
            if self.held:
                self._switches.append((self.held, block.info))
            else:
                self.info = block.info
            return
        self._pending.append(block)
        self._came_s.append(float(now_s))
        self.held += len(block)

    def _switch(self) -> None:
        """The lines before a new info all taken (by the last ``take``): the new info's turn."""
        while self._switches and self._switches[0][0] <= 0:
            self.info = self._switches.pop(0)[1]

    def due(self, now_s: float, lines: int, most: int, deadline_s: float | None) -> int:
        """Lines to publish now as one strip (0: none yet).  ``lines`` or more held: all of
        them, at most max(lines, ``most``) (``most`` <= ``lines``: strips of exactly ``lines``);
        fewer: all of them once the oldest has waited ``deadline_s`` (None: never).  A new
        info waiting (``add``): the lines before it, at once."""
        self._switch()
        if self._switches:
            return min(self._switches[0][0], max(lines, most))
        if self.held >= lines:
            return min(self.held, max(lines, most))
        if self.held and deadline_s is not None and now_s - self._came_s[0] >= deadline_s:
            return self.held
        return 0

    def wait_s(self, now_s: float, deadline_s: float | None) -> float:
        """Seconds until the oldest line held reaches ``deadline_s`` (inf: no line held, or no
        deadline)."""
        if not self.held or deadline_s is None:
            return math.inf
        return max(0.0, self._came_s[0] + deadline_s - now_s)

    def take(self, count: int, counters: dict) -> tuple[Strip, np.ndarray]:
        """The first ``count`` pending lines as one strip, and the arrival of the last pulse of
        each of its lines (the latency reference); ``info`` is the strip's until the next
        call."""
        self._switch()
        parts, rest, came, need = [], [], [], count
        for b, came_s in zip(self._pending, self._came_s, strict=True):
            if need == 0:
                rest.append(b)
                came.append(came_s)
            elif len(b) <= need:
                parts.append(b)
                need -= len(b)
            else:
                parts.append(b.slice(0, need))
                rest.append(b.slice(need, len(b)))
                came.append(came_s)
                need = 0
        self._pending, self._came_s = rest, came
        self.held -= count
        if self._switches:  # (a block change waiting: rare)
            self._switches = [(at - count, info) for at, info in self._switches]
        first = parts[0].first_line
        one = len(parts) == 1  # the low-latency case: no copies
        lines = parts[0].lines if one else np.concatenate([p.lines for p in parts])
        flagged = parts[0].flagged if one else np.concatenate([p.flagged for p in parts])
        strip = Strip(
            seq=self.seq,
            first_line=first,
            lines=lines,
            azimuth_m=self.info.azimuth_m(first, len(lines)),
            first_arrival_s=float(parts[0].first_arrival_s[0]),
            last_arrival_s=float(parts[-1].last_arrival_s[-1]),
            flagged_lines=flag_runs(first, flagged),
            counters=counters,
        )
        self.seq += 1
        last = parts[0].last_arrival_s if one else np.concatenate([p.last_arrival_s for p in parts])
        return strip, last


def flag_runs(first: int, flagged: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in ``flagged`` as (first_line, count) pairs."""
    if not flagged.any():
        return []
    f = np.concatenate([[False], flagged, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(f))
    return [(first + int(a), int(b - a)) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def join_run(runs: list[list[int]], first: int, count: int) -> None:
    """[first, count] onto ``runs``: joined to the last run where it follows it, else a new
    run (the flagged lines of an image, strip after strip)."""
    if runs and sum(runs[-1]) == first:
        runs[-1][1] += count
    else:
        runs.append([first, count])


def new_stream_id() -> str:
    """A random hex id for a run (a new id tells subscribers the publisher restarted)."""
    return uuid.uuid4().hex[:16]


def utc_text(when) -> str | None:
    """A naive UTC datetime as ISO 8601 (rtsar.sources.formats.timebase), None as None."""
    return None if when is None else format_utc(when)
