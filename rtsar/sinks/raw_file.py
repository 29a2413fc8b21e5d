"""The raw shots' file of ``rtsar run --record`` (written by the recorder process,
rtsar.sinks.raw_writer; what it holds: rtsar.sinks.raw_record).

:class:`RawFile` makes the file with the first shots (their channels fix its datasets), appends
rows in stream order, flushes every ``flush_every_s`` (crash-safe, rtsar.sinks.live_file) and
closes it with the final attributes.  A write the disk refuses raises WriteFailed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..params import config_from_dict
from ..stream.strips import join_run
from .io import RECORDING_FORMAT, RECORDING_VERSION, describe_channels
from .live_file import LiveFile
from .name_claim import NameClaim

MAX_RUNS_LISTED = 10_000
INSERTED, ZEROED, NOT_RECORDED = 1, 2, 4  # /pulse_flags bits
FLAGS_MEANING = (
    "1: a zero pulse ingest inserted (a gap, a restart: no shot); 2: a shot ingest zeroed "
    "(NaN/Inf, wrong length); 4: not recorded (the recorder's queue was full: record_dropped)"
)
_META = (  # the per-pulse datasets, pulse_index last: a row is whole once it has its index
    ("time_s", np.float64),
    ("along_track_m", np.float64),
    ("instrument_seq", np.int64),
    ("instrument_time_s", np.float64),
    ("pulse_flags", np.uint8),
    ("pulse_index", np.int64),
)


@dataclass
class Shots:
    """A block of the stream as the recorder process receives it (rtsar.stream.ingest
    .PulseBlock's recorded fields); ``samples`` and ``aux`` None for inserted zero pulses."""

    first_pulse: int
    count: int
    samples: np.ndarray | None
    aux: dict
    seq: np.ndarray | None
    time_s: np.ndarray | None
    flagged: np.ndarray
    inserted: np.ndarray | None
    nbytes: int  # the bytes it holds (none for inserted zero pulses)
    widths: dict  # auxiliary channel → samples (what a file made from this block holds)
    collection_start_utc: str | None = None  # the stream's pulse 0 (StreamInfo), for the file

    def __len__(self) -> int:
        return self.count

    @classmethod
    def of(cls, block, collection_start_utc: str | None = None) -> Shots:
        """A PulseBlock's recorded fields, its arrays contiguous (they travel out of band)."""
        n = len(block)
        zeros = block.inserted is not None and bool(block.inserted.all())
        c = np.ascontiguousarray
        samples = None if zeros else c(block.samples)
        aux = {} if zeros else {k: c(a) for k, a in block.aux.items()}
        nbytes = 0 if zeros else samples.nbytes + sum(a.nbytes for a in aux.values())
        return cls(
            int(block.first_pulse), n, samples, aux,
            None if block.seq is None else c(block.seq),
            None if block.time_s is None else c(block.time_s),
            c(block.flagged),
            None if block.inserted is None else c(block.inserted),
            nbytes,
            {k: int(a.shape[1]) for k, a in block.aux.items()},
            collection_start_utc,
        )  # fmt: skip


@dataclass
class _Dropped:
    """Pulses first … first + count - 1 not recorded (consecutive drops merge into one)."""

    first: int
    count: int
    nbytes: int = 0


def add_run(runs: list[list[int]], first: int, count: int) -> None:
    """Pulses ``first`` … ``first + count - 1`` into ``runs`` ([first, count] each): joined to
    the last run where they follow it, else a new run while fewer than MAX_RUNS_LISTED."""
    if len(runs) < MAX_RUNS_LISTED or (runs and sum(runs[-1]) == first):
        join_run(runs, first, count)


class RawFile:
    """The recording being written (module docstring).  ``claim_mark``/``claim_fd``: the run's
    claim on the name (rtsar.sinks.name_claim), held by the file's writer from its creation."""

    def __init__(
        self,
        path: str,
        config: dict,
        scene: dict,
        source: str,
        start_along_track_m: float,
        flush_every_s: float,
        claim_mark: str | None = None,
        claim_fd: int | None = None,
    ):
        self.path = Path(path)
        self.config = config_from_dict(config)
        self.config_dict = config
        self.scene = scene
        self.source = source
        self.start_along_track_m = float(start_along_track_m)
        self.flush_every_s = float(flush_every_s)
        self._claim = None if claim_fd is None else NameClaim.adopted(claim_mark, claim_fd)
        self._file: LiveFile | None = None
        self._datasets: dict = {}
        self.written = 0  # pulses whose rows are in the file (shots, inserted zeros)
        self.collection_start_utc: str | None = None  # from the first block of shots
        self.dropped = 0  # pulses not recorded (as marked in the file)
        self.dropped_runs: list[list[int]] = []
        self.saved = (0, 0)  # (written, dropped) of the rows sure to be on disk (note_saved)

    def release(self) -> None:
        """The claim on the name goes (a file never made; the file's writer releases its own)."""
        if self._claim is not None:
            self._claim.release()
            self._claim = None

    def due(self) -> bool:
        return self._file is not None and self._file.dirty and self._file.due()

    def flush_if_due(self) -> None:
        if self.due():
            self._file.flush()
            self.note_saved()

    def note_saved(self) -> None:
        """``saved`` becomes the counts of now when every row written is on disk (after a flush,
        the close, or a failure whose one close went through: rtsar.sinks.live_file), so that
        what the run is told never exceeds what a reader of the file finds."""
        if self._file is not None and self._file.saved_rows == self._file.rows:
            self.saved = (self.written, self.dropped)

    def append(self, items: list) -> None:
        """Rows for the items (Shots and _Dropped, in stream order); WriteFailed from the disk."""
        if self._file is None:
            first = next((x for x in items if not isinstance(x, _Dropped)), None)
            widths = {} if first is None else first.widths
            self.collection_start_utc = None if first is None else first.collection_start_utc
            self._create(widths)
        self._append(items)
        for x in items:
            if isinstance(x, _Dropped):
                self._count_drop(x.first, x.count)
            else:
                self.written += len(x)
        self.note_saved()  # (the first rows are flushed at once)

    def _count_drop(self, first: int, count: int) -> None:
        self.dropped += count
        add_run(self.dropped_runs, first, count)

    def _create(self, widths: dict[str, int]) -> None:
        claim, self._claim = self._claim, None  # the file's writer holds it from here
        self._file = LiveFile(
            self.path,
            lambda f: self._make(f, widths),
            claim=claim,
            flush_every_s=self.flush_every_s,
            unit="shots",
            tidy=self._trim,
        )

    def _make(self, f, widths: dict[str, int]) -> None:
        s = self.config.waveform.samples_per_shot
        rows = lambda width: max(16, min(1024, (1 << 20) // (8 * width)))  # noqa: E731 (~1 MiB)
        ds = self._datasets
        ds["shots"] = f.create_dataset(
            "shots", (0, s), np.complex64, maxshape=(None, s), chunks=(rows(s), s)
        )
        group = f.create_group("channels")
        for name, width in sorted(widths.items()):
            ds[f"channels/{name}"] = group.create_dataset(
                name, (0, width), np.complex64, maxshape=(None, width), chunks=(rows(width), width)
            )
        for name, dtype in _META:
            ds[name] = f.create_dataset(name, (0,), dtype, maxshape=(None,), chunks=(4096,))
        a = f.attrs
        a["format"] = RECORDING_FORMAT
        a["format_version"] = RECORDING_VERSION
        a["config"] = json.dumps(self.config_dict)
        a["scene"] = json.dumps(self.scene)
        a["channels"] = describe_channels(self.config, widths)
        a["rtsar_version"] = __version__
        a["source"] = self.source
        a["recorded_live"] = True
        a["pulse_flags_meaning"] = FLAGS_MEANING
        a["complete"] = False
        if self.collection_start_utc:  # the time of pulse 0 (time_s = 0)
            a["collection_start_utc"] = self.collection_start_utc

    def _trim(self, rows: int) -> None:
        """After a failed write: every dataset back to the rows written whole."""
        for d in self._datasets.values():
            if d.shape[0] > rows:
                d.resize(rows, axis=0)

    def _append(self, items: list) -> None:
        """Rows for the items: shots and channels where recorded (inserted and dropped pulses
        are left unwritten, reading as zeros), then the per-pulse data, pulse_index last."""
        start = self._file.rows
        end = start + sum(len(x) if not isinstance(x, _Dropped) else x.count for x in items)
        ds = self._datasets
        with self._file.writing():
            for name, d in ds.items():
                if name == "shots" or name.startswith("channels/"):
                    d.resize(end, axis=0)
            for row, group in _runs_of_shots(items, start):  # one write per run of shots
                ds["shots"][row : row + sum(len(x) for x in group)] = _joined(group, None)
                for name in group[0].aux:
                    values = _joined(group, name)
                    ds[f"channels/{name}"][row : row + len(values)] = values
            p = np.arange(start, end)
            g = self.config.geometry
            meta = {
                "time_s": p / g.prf_hz,
                "along_track_m": self.start_along_track_m + p * g.along_track_step_m,
                "instrument_seq": np.concatenate([_seq(x) for x in items]),
                "instrument_time_s": np.concatenate([_time(x) for x in items]),
                "pulse_flags": np.concatenate([_flags(x) for x in items]),
                "pulse_index": p,
            }
            for name, _ in _META:
                ds[name].resize(end, axis=0)
                ds[name][start:end] = meta[name]
        self._file.stored(end)

    def close(self, counters: dict, complete: bool) -> None:
        """Close with the final attributes (nothing when no shot ever came).  The run's
        ``counters`` were taken before this file was finished: their ``record_*`` entries are
        this file's own.  ``complete``: the run's end came (``complete``) and every pulse it
        handed over has its row here (none dropped)."""
        if self._file is None:
            return
        own = {"record_written": self.written, "record_dropped": self.dropped}
        counters = {k: v for k, v in counters.items() if not k.startswith("record_")}
        attrs = {
            "counters": json.dumps({**counters, **own}),
            **own,
            "record_dropped_runs": json.dumps(self.dropped_runs),
            "complete": bool(complete) and not self.dropped,
        }
        try:
            self._file.close(attrs)
        finally:
            self.note_saved()


def _runs_of_shots(items: list, start: int):
    """(first row, [blocks]) of each run of consecutive blocks that hold shots (inserted zero
    pulses and dropped pulses break a run: their rows are not written)."""
    row, group, first = start, [], start
    for x in items:
        if isinstance(x, _Dropped) or not x.nbytes:
            if group:
                yield first, group
            group = []
        else:
            if not group:
                first = row
            group.append(x)
        row += x.count
    if group:
        yield first, group


def _joined(group: list, channel: str | None) -> np.ndarray:
    """The main channel (None) or an auxiliary one of consecutive blocks, as one array."""
    parts = [x.samples if channel is None else x.aux[channel] for x in group]
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def _seq(x) -> np.ndarray:
    if isinstance(x, _Dropped) or x.seq is None:
        return np.zeros(x.count, np.int64)
    return np.where(_inserted(x), 0, x.seq)


def _time(x) -> np.ndarray:
    if isinstance(x, _Dropped) or x.time_s is None:
        return np.full(x.count, np.nan)
    return np.where(_inserted(x), np.nan, x.time_s)


def _inserted(x) -> np.ndarray:
    return np.zeros(len(x), bool) if x.inserted is None else x.inserted


def _flags(x) -> np.ndarray:
    if isinstance(x, _Dropped):
        return np.full(x.count, NOT_RECORDED, np.uint8)
    inserted = _inserted(x)
    zeroed = x.flagged & ~inserted
    return (inserted * INSERTED + zeroed * ZEROED).astype(np.uint8)
