"""The raw shots of a live run, kept while it images (``rtsar run --record RAW.h5``).

A live scan could only be focused once, live; its recording lets it be focused again (another
correction, PGA, window, correlator) with ``rtsar process RAW.h5`` or ``rtsar replay RAW.h5``,
which give the live run's image.  What is recorded is the stream as ingest made it (rtsar.stream
.ingest): one row per pulse of the stream, in order, every channel the source delivers, the
zero pulses ingest inserted (gaps, restarts) and the shots it zeroed (NaN/Inf, wrong length)
where the live run had them; so the file is an ordinary recording
(docs/pages/reference/files.md) whose ``pulse_index`` counts the stream's pulses, and the
instrument's own numbers and clock are kept beside it:

* ``/instrument_seq`` int64 [pulse]: the instrument's pulse counter (u64 bits; 0 where none);
* ``/instrument_time_s`` float64 [pulse]: the instrument's clock (NaN where none);
* ``/pulse_flags`` uint8 [pulse]: 1 a zero pulse ingest inserted (no shot), 2 a shot ingest
  zeroed, 4 not recorded: the recorder's queue was full (``record_dropped``; its rows read as
  zeros, nothing of them was written).

The file is written by a thread of its own behind a queue bounded in bytes (``queue_bytes``;
default :func:`record_queue_bytes`): the pipeline hands each block over without waiting, so a
slow disk never stalls the imaging; a block that does not fit is not recorded, counted
(``record_dropped``) and marked.  A failed write (a full disk) ends the recording, not the run:
said at once through ``notify``, the rest counted as dropped.  The file is crash-safe like the
live image (rtsar.sinks.live_file): a SIGKILL leaves a readable file with every shot up to its
last flush (every ``flush_every_s``).  Final attributes: ``complete``, ``counters`` (JSON, the
run's), ``record_written``, ``record_dropped``, ``record_dropped_runs`` (JSON [[first pulse,
count], ...], the first :data:`MAX_RUNS_LISTED`).
"""

from __future__ import annotations

import json
import threading
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import __version__
from ..params import Config
from ..stream.strips import StreamInfo, StripSink
from .h5_output import WriteFailed
from .io import RECORDING_FORMAT, RECORDING_VERSION, describe_channels
from .live_file import LiveFile
from .name_claim import NameClaim

QUEUE_S = 2.0  # seconds of the stream's main-channel shots the recorder's queue holds …
QUEUE_BYTES = (16 << 20, 256 << 20)  # … within these bounds
TAKE_BYTES = 32 << 20  # the most the writer takes from the queue for one round of writes
ROUND_S, ROUND_BYTES = 0.1, 4 << 20  # a round waits this long for this much (fewer HDF5 calls)
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


def record_queue_bytes(config: Config) -> int:
    """The recorder's queue: :data:`QUEUE_S` seconds of main-channel shots at the PRF, within
    :data:`QUEUE_BYTES` (at psaltis-max, 10 kHz × 1800 samples: 256 MiB, 1.9 s)."""
    per_s = config.geometry.prf_hz * config.waveform.samples_per_shot * 8
    low, high = QUEUE_BYTES
    return int(min(high, max(low, QUEUE_S * per_s)))


@dataclass
class _Dropped:
    """Pulses first … first + count - 1 not recorded (consecutive drops merge into one)."""

    first: int
    count: int


def _nbytes(block) -> int:
    """Bytes a block holds in the queue (a block of inserted zero pulses: none)."""
    if block.inserted is not None and block.inserted.all():
        return 0
    return block.samples.nbytes + sum(a.nbytes for a in block.aux.values())


class ShotRecorder(StripSink):
    """Pipeline sink that records the pulse stream to ``path`` (module docstring).

    The name is claimed now (a second live writer of it is refused before any work); the file
    is made with the first pulses (their channels fix its datasets).  ``notify``: one-line
    messages (a failed write).  ``close()`` ends it if the run's ``end`` never came."""

    wants_pulses = True

    def __init__(
        self,
        path: str | Path,
        config: Config,
        scene: dict | None = None,
        source: str = "",
        start_along_track_m: float = 0.0,
        queue_bytes: int | None = None,
        flush_every_s: float = 0.5,
        notify=None,
    ):
        self.path = Path(path)
        self.config = config
        self.scene = scene or {}
        self.source = source
        self.start_along_track_m = float(start_along_track_m)
        self.capacity = int(queue_bytes or record_queue_bytes(config))
        self.flush_every_s = float(flush_every_s)
        self.notify = notify
        self._claim: NameClaim | None = NameClaim(self.path)
        self._file: LiveFile | None = None
        self._datasets: dict = {}
        self._items: deque = deque()
        self._bytes = 0  # bytes of the blocks queued or being written
        self._cond = threading.Condition()
        self._ending = False
        self._final: dict = {}
        self.written = 0  # pulses whose rows are in the file (shots, inserted zeros)
        self.dropped = 0  # pulses not recorded
        self.dropped_runs: list[list[int]] = []
        self.failure: WriteFailed | None = None
        self._next_pulse = 0  # the stream's next pulse (checks the order)
        self._in_hand: list = []  # the items being written (lost with them if they fail)
        self._thread = threading.Thread(target=self._run, name="rtsar-record", daemon=True)
        self._thread.start()

    # ---- the pipeline's side (never waits) -------------------------------------------------
    def pulses(self, block, info: StreamInfo) -> None:
        n = len(block)
        if not n:
            return
        if block.first_pulse != self._next_pulse:
            raise RuntimeError("the recorder was handed pulses out of order")
        self._next_pulse += n
        nbytes = _nbytes(block)
        with self._cond:
            fits = self._bytes + nbytes <= self.capacity or not self._bytes
            if self.failure is None and not self._ending and fits:
                self._items.append(block)
                self._bytes += nbytes
                self._cond.notify()
            else:
                self._drop(block.first_pulse, n)

    def _drop(self, first: int, count: int) -> None:
        """Pulses not recorded: counted, listed, and (while the file lives) marked in it."""
        self.dropped += count
        runs = self.dropped_runs
        if runs and runs[-1][0] + runs[-1][1] == first:
            runs[-1][1] += count
        elif len(runs) < MAX_RUNS_LISTED:
            runs.append([first, count])
        if self.failure is None:
            last = self._items[-1] if self._items else None
            if isinstance(last, _Dropped) and last.first + last.count == first:
                last.count += count
            else:
                self._items.append(_Dropped(first, count))
                self._cond.notify()

    def has_room(self, nbytes: int) -> bool:
        """Whether a block of ``nbytes`` would be queued now (``rtsar bench`` waits on it)."""
        with self._cond:
            return self._bytes + nbytes <= self.capacity or not self._bytes

    def counters(self) -> dict:
        return {"record_written": self.written, "record_dropped": self.dropped}

    def end(self, stats: dict, info: StreamInfo) -> None:
        self.finish(stats.get("counters", {}))

    def finish(self, counters: dict | None = None, complete: bool = True) -> None:
        """Write what is queued, close the file with the final attributes, release the name.
        A failure is kept in ``failure`` (and was told through ``notify``)."""
        with self._cond:
            if not self._ending:
                self._final = {"counters": counters or {}, "complete": complete}
                self._ending = True
            self._cond.notify()
        self._thread.join()

    def close(self) -> None:
        """End the recording if the run's end never came (it stays marked incomplete)."""
        self.finish(complete=False)

    # ---- the writer thread -----------------------------------------------------------------
    def _run(self) -> None:
        try:
            while True:
                with self._cond:
                    while not self._items and not self._ending:
                        self._cond.wait(self.flush_every_s)
                        if self._file is not None and self._file.dirty and self._file.due():
                            break
                    if self._items and self._bytes < ROUND_BYTES:  # a few larger writes
                        ready = lambda: self._ending or self._bytes >= ROUND_BYTES  # noqa: E731
                        self._cond.wait_for(ready, ROUND_S)
                    items, size = self._take()
                    ending = self._ending and not self._items
                if items and self.failure is None:
                    self._write(items)
                with self._cond:
                    self._bytes -= size
                if self._file is not None and self.failure is None and self._file.dirty:
                    if self._file.due():
                        self._guarded(self._file.flush)
                if ending:
                    break
            self._close()
        finally:
            if self._claim is not None:  # no pulse ever came: the name goes free
                self._claim.release()
                self._claim = None

    def _take(self) -> tuple[list, int]:
        """Items from the queue, up to :data:`TAKE_BYTES` (at least one)."""
        items, size = [], 0
        while self._items and (not items or size < TAKE_BYTES):
            item = self._items.popleft()
            items.append(item)
            size += 0 if isinstance(item, _Dropped) else _nbytes(item)
        return items, size

    def _guarded(self, work) -> bool:
        """Run a write; a failed one ends the recording (said once), never the run."""
        try:
            work()
            return True
        except WriteFailed as exc:
            self._fail(exc)
            return False

    def _fail(self, exc: WriteFailed) -> None:
        with self._cond:
            self.failure = exc
            # What was being written and what is queued is lost: not recorded.
            for x in [*self._in_hand, *self._items]:
                if not isinstance(x, _Dropped):  # (a drop is counted already)
                    self._drop(x.first_pulse, len(x))
            self._items.clear()
            self._in_hand = []
        if self.notify is not None:
            self.notify(
                f"rtsar: --record {self.path} stopped: {exc}; the image goes on, the shots not "
                "written are counted (record_dropped)"
            )

    def _write(self, items: list) -> None:
        self._in_hand = items
        if self._file is None:
            first = next((x for x in items if not isinstance(x, _Dropped)), None)
            widths = {} if first is None else {k: a.shape[1] for k, a in first.aux.items()}
            if not self._guarded(lambda: self._create(widths)):
                return
        if self._guarded(lambda: self._append(items)):
            self.written += sum(len(x) for x in items if not isinstance(x, _Dropped))
        self._in_hand = []

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
        a["config"] = json.dumps(self.config.to_dict())
        a["scene"] = json.dumps(self.scene)
        a["channels"] = describe_channels(self.config, widths)
        a["rtsar_version"] = __version__
        a["source"] = self.source
        a["recorded_live"] = True
        a["pulse_flags_meaning"] = FLAGS_MEANING
        a["complete"] = False

    def _trim(self, rows: int) -> None:
        """After a failed write: every dataset back to the rows written whole."""
        for d in self._datasets.values():
            if d.shape[0] > rows:
                d.resize(rows, axis=0)

    def _append(self, items: list) -> None:
        """Rows for the items: shots and channels where recorded (inserted and dropped pulses
        are left unwritten, reading as zeros), then the per-pulse data, pulse_index last."""
        start = self._file.rows
        end = start + sum(x.count if isinstance(x, _Dropped) else len(x) for x in items)
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
            meta = {
                "time_s": p / self.config.geometry.prf_hz,
                "along_track_m": self.start_along_track_m
                + p * self.config.geometry.along_track_step_m,
                "instrument_seq": np.concatenate([_seq(x) for x in items]),
                "instrument_time_s": np.concatenate([_time(x) for x in items]),
                "pulse_flags": np.concatenate([_flags(x) for x in items]),
                "pulse_index": p,
            }
            for name, _ in _META:
                ds[name].resize(end, axis=0)
                ds[name][start:end] = meta[name]
        self._file.stored(end)

    def _close(self) -> None:
        if self._file is None or self.failure is not None:
            return
        final = self._final or {"counters": {}, "complete": False}
        attrs = {
            "counters": json.dumps(final["counters"]),
            "record_written": self.written,
            "record_dropped": self.dropped,
            "record_dropped_runs": json.dumps(self.dropped_runs),
            "complete": final["complete"],
        }
        self._guarded(lambda: self._file.close(attrs))


def _runs_of_shots(items: list, start: int):
    """(first row, [blocks]) of each run of consecutive blocks that hold shots (inserted zero
    pulses and dropped pulses break a run: their rows are not written)."""
    row, group, first = start, [], start
    for x in items:
        n = x.count if isinstance(x, _Dropped) else len(x)
        if isinstance(x, _Dropped) or not _nbytes(x):
            if group:
                yield first, group
            group = []
        else:
            if not group:
                first = row
            group.append(x)
        row += n
    if group:
        yield first, group


def _joined(group: list, channel: str | None) -> np.ndarray:
    """The main channel (None) or an auxiliary one of consecutive blocks, as one array."""
    parts = [x.samples if channel is None else x.aux[channel] for x in group]
    return parts[0] if len(parts) == 1 else np.concatenate(parts)


def _seq(x) -> np.ndarray:
    if isinstance(x, _Dropped) or x.seq is None:
        return np.zeros(x.count if isinstance(x, _Dropped) else len(x), np.int64)
    return np.where(_inserted(x), 0, x.seq)


def _time(x) -> np.ndarray:
    if isinstance(x, _Dropped) or x.time_s is None:
        return np.full(x.count if isinstance(x, _Dropped) else len(x), np.nan)
    return np.where(_inserted(x), np.nan, x.time_s)


def _inserted(x) -> np.ndarray:
    return np.zeros(len(x), bool) if x.inserted is None else x.inserted


def _flags(x) -> np.ndarray:
    if isinstance(x, _Dropped):
        return np.full(x.count, NOT_RECORDED, np.uint8)
    inserted = _inserted(x)
    zeroed = x.flagged & ~inserted
    return (inserted * INSERTED + zeroed * ZEROED).astype(np.uint8)
