"""The streaming pipeline: source → ingest → AO lens → shifting CCD → strips → publishers.

Each stage is a thread; stages are joined by bounded queues whose capacity is counted in
pulses (or lines), so memory is bounded whatever the source does.  The heavy work releases the
GIL (OpenCL waits in pyopencl, numba ``nogil`` kernels, SciPy's FFT), so threads overlap.
``stages="fused"`` runs lens and CCD in one thread instead (one queue hop less; the benchmark
measures both).

Back-pressure: a live source (simulator, serial instrument) never waits: when the first queue
is full its shots are dropped and counted, and ingest zero-fills their slots so azimuth timing
holds.  A replay waits.  Downstream stages always wait for each other (nothing is lost inside).

Every stage takes *all* the work waiting for it, up to a cap (adaptive micro-batching): when the
pipeline keeps up, batches are small and latency is low; when it falls behind, batches grow and
the per-launch overheads are amortised.

Corrections (a :class:`rtsar.corrections.CorrectionChain`: chirp linearization, the reference-
region method, phase-to-retro, PGA) run in the lens thread, in pulse order: "raw" stages before
the AO lens (they see the auxiliary channels), "lines" stages between the lens and the CCD.  A
line stage may hold pulses back (PGA holds a block): the pulses' arrival times and flags wait
with them, so latency and flags stay exact; the held pulses come out at the end of the stream.
Their counters join the pipeline's.

3D imaging (``height``: an rtsar.topo.stream.HeightStripStage): the auxiliary channel of the
second receiver (``height_channel``) goes through its own AO lens and CCD in step with the main
channel; the stage turns each pair of line blocks into height strips (unwrapped with overlap, so
heights stay continuous across strips), published beside the image strips (sink method
``height``).

Latency of an image line: from the arrival of the last pulse that contributes to it (pulse
j + N - 1 for line j, Psaltis & Wagner 1981: the row leaves the CCD after N shifts) to the
publication of the strip holding it.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .engine import StreamProcessor
from .ingest import Ingest, PulseBlock, concat_blocks
from .params import Config
from .publish import new_stream_id
from .sources.base import Source

STAGE_LAYOUTS = ("split", "fused")


class Closed(Exception):
    """Raised by BoundedQueue.put after close()."""


class BoundedQueue:
    """FIFO with a capacity in units (pulses or lines); ``get_batch`` takes what is waiting."""

    def __init__(self, capacity: int, name: str = "queue"):
        self.capacity = max(1, int(capacity))
        self.name = name
        self._items: deque = deque()
        self._size = 0
        self._closed = False
        self._cv = threading.Condition()
        self.high_water = 0  # the most units ever held

    def put(self, item, block: bool = True) -> bool:
        """Add ``item`` (len(item) units).  Non-blocking: False if it does not fit."""
        n = len(item)
        with self._cv:
            while self._size > 0 and self._size + n > self.capacity:
                if self._closed:
                    raise Closed(self.name)
                if not block:
                    return False
                self._cv.wait(0.1)
            if self._closed:
                raise Closed(self.name)
            self._items.append(item)
            self._size += n
            self.high_water = max(self.high_water, self._size)
            self._cv.notify_all()
            return True

    def get_batch(self, max_units: int, timeout: float | None = None) -> list | None:
        """Wait for at least one item, then take items while they fit in ``max_units``.

        Returns [] on timeout and None once the queue is closed and empty.
        """
        deadline = None if timeout is None else time.perf_counter() + timeout
        with self._cv:
            while not self._items:
                if self._closed:
                    return None
                left = None if deadline is None else deadline - time.perf_counter()
                if left is not None and left <= 0:
                    return []
                self._cv.wait(0.1 if left is None else min(left, 0.1))
            out = [self._items.popleft()]
            taken = len(out[0])
            while self._items and taken + len(self._items[0]) <= max_units:
                item = self._items.popleft()
                taken += len(item)
                out.append(item)
            self._size -= taken
            self._cv.notify_all()
            return out

    def close(self) -> None:
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    @property
    def size(self) -> int:
        return self._size


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


@dataclass
class HeightBatch:
    """Height strips travelling to the publisher with the image lines (no queue units)."""

    strips: list

    def __len__(self) -> int:
        return 0


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


class LatencyStats:
    """Latency distribution in bounded memory: a log-spaced histogram (0.5 % wide bins)."""

    BINS_PER_DECADE = 460
    LOW_S = 1e-6

    def __init__(self):
        self.counts = np.zeros(9 * self.BINS_PER_DECADE + 2, np.int64)  # 1 µs … 1e3 s
        self.recent: deque[float] = deque(maxlen=4000)
        self.total = 0
        self.max_s = 0.0

    def add(self, latency_s: np.ndarray) -> None:
        latency_s = np.asarray(latency_s, np.float64)
        if not latency_s.size:
            return
        decades = np.log10(np.maximum(latency_s, self.LOW_S) / self.LOW_S)
        k = np.floor(decades * self.BINS_PER_DECADE)
        np.add.at(self.counts, np.clip(k.astype(np.int64) + 1, 0, len(self.counts) - 1), 1)
        self.recent.extend(latency_s[-self.recent.maxlen :].tolist())
        self.total += latency_s.size
        self.max_s = max(self.max_s, float(latency_s.max()))

    def percentile(self, q: float) -> float:
        """q-th percentile (s), to the histogram's 0.5 %; NaN when empty."""
        if self.total == 0:
            return float("nan")
        k = int(np.searchsorted(np.cumsum(self.counts), q / 100 * self.total, "left"))
        return self.LOW_S * 10 ** ((k - 0.5) / self.BINS_PER_DECADE)

    def recent_percentile(self, q: float) -> float:
        return float(np.percentile(self.recent, q)) if self.recent else float("nan")


@dataclass
class PipelineSettings:
    """How the pipeline runs (the processing itself is the Config)."""

    lens_backend: str = "opencl"
    device: str | None = None
    stages: str = "split"  # "split": lens and CCD in their own threads; "fused": one thread
    strip_lines: int = 16  # lines per published strip
    queue_pulses: int = 0  # capacity of each queue (0: 8 apertures of pulses)
    max_batch: int = 0  # most pulses per lens launch / CCD push (0: config micro_batch)
    max_gap_pulses: int = 0  # longer sequence jumps are discontinuities (0: 60 s of pulses)

    def __post_init__(self):
        if self.stages not in STAGE_LAYOUTS:
            raise ValueError(f"stages must be one of {STAGE_LAYOUTS}, got {self.stages!r}")
        if self.strip_lines < 1:
            raise ValueError("strip_lines must be >= 1")


@dataclass
class PipelineStats:
    """What a run did: counters, latency, timing.  ``as_dict`` is what the stats topic carries."""

    counters: dict = field(default_factory=dict)
    latency: LatencyStats = field(default_factory=LatencyStats)
    started_s: float = 0.0
    elapsed_s: float = 0.0
    busy_s: dict = field(default_factory=dict)  # seconds of work per stage

    def as_dict(self) -> dict:
        d = {k: int(v) for k, v in self.counters.items()}
        lat = self.latency
        return {
            "counters": d,
            "elapsed_s": self.elapsed_s,
            "pulse_rate_hz": d.get("pulses_processed", 0) / max(self.elapsed_s, 1e-9),
            "latency_median_ms": lat.percentile(50) * 1e3,
            "latency_p99_ms": lat.percentile(99) * 1e3,
            "latency_max_ms": lat.max_s * 1e3,
            "stage_busy_s": dict(self.busy_s),
        }


class Pipeline:
    """Run ``source`` through the engine and hand strips to ``sinks`` (publishers, recorders).

    A sink has ``strip(strip, pipeline)``, ``stats(stats_dict, pipeline)`` and ``end(...)``
    methods (see :mod:`rtsar.publish`).  ``run()`` blocks until the source ends or ``stop()``;
    Ctrl-C in ``run()`` stops the source, drains the pipeline and flushes the CCD, so every
    pulse that arrived is focused and published.
    """

    def __init__(
        self,
        config: Config,
        source: Source,
        sinks: list,
        settings: PipelineSettings | None = None,
        start_along_track_m: float = 0.0,
        on_stats=None,
        stats_every_s: float = 1.0,
        corrections=None,
        physical=None,
        height=None,
        height_channel: str = "rx1",
    ):
        self.config = config
        self.corrections = corrections
        self.height = height
        self.height_channel = height_channel
        if height is not None and corrections and corrections.line_stages:
            raise ValueError(
                "height strips with line-domain corrections (pra, pga) are not supported: they "
                "correct the main receiver only and would bias the interferometric phase"
            )
        self._held: deque[PulseBlock] = deque()  # pulses inside the line stages (metadata)
        self.source = source
        self.sinks = list(sinks)
        self.settings = s = settings or PipelineSettings()
        self.engine = StreamProcessor(
            config, s.lens_backend, s.device, start_along_track_m, corrections, physical
        )
        # The second receiver's own AO lens and CCD (same configuration) for height strips.
        self.engine_aux = (
            StreamProcessor(config, s.lens_backend, s.device, start_along_track_m)
            if height is not None
            else None
        )
        self._height_seq = 0
        n = config.processor.aperture_pulses
        self.aperture = n
        self.max_batch = s.max_batch or config.processor.micro_batch
        capacity = s.queue_pulses or 8 * n
        self.q_shots = BoundedQueue(capacity, "shots")
        self.q_lines = BoundedQueue(capacity, "compressed")
        self.q_image = BoundedQueue(capacity, "image lines")
        max_gap = s.max_gap_pulses or max(4 * n, int(60 * config.geometry.prf_hz))
        self.ingest = Ingest(config.waveform.samples_per_shot, n, max_gap, self.engine.lens.dtype)
        self.stats = PipelineStats()
        self.on_stats = on_stats
        self.stats_every_s = stats_every_s
        # The pipeline's own counters (source and ingest keep theirs; counters() merges).
        names = (
            "dropped_pulses",
            "pulses_processed",
            "lines_out",
            "flagged_lines",
            "strips_published",
        )
        self.own = dict.fromkeys(names, 0)
        # Arrival time and flag of recent pulses, indexed by pulse % ring (lines need the
        # arrivals of their first and last pulses; the ring spans the CCD plus the queues).
        block = config.processor.fft_length or 2 * n
        ring = 1 << int(np.ceil(np.log2(4 * (n + block + capacity + self.max_batch))))
        self._arrival = np.zeros(ring)
        self._flag_pulses: deque[int] = deque()  # indices of flagged pulses still in a window
        self._errors: list[BaseException] = []
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._strip_seq = 0
        self.stream_id = new_stream_id()
        self.config_dict = config.to_dict()
        # perf_counter times (latency) + this offset = UNIX times (headers).
        self.clock_offset_s = time.time() - time.perf_counter()

    # ---- stages ---------------------------------------------------------------------------
    def _source_stage(self) -> None:
        live = self.source.live
        try:
            for batch in self.source:
                if self._stop.is_set():
                    break
                if not self.q_shots.put(batch, block=not live):
                    self.own["dropped_pulses"] += len(batch)
        finally:
            self.q_shots.close()

    def _lens_stage(self) -> None:
        busy = 0.0
        try:
            while True:
                batches = self.q_shots.get_batch(self.max_batch)
                if batches is None:
                    break
                t = time.perf_counter()
                blocks = [b for batch in batches for b in self.ingest(batch)]
                busy += time.perf_counter() - t
                for block in _groups(blocks, self.max_batch):
                    t = time.perf_counter()
                    chain = self.corrections
                    if chain:
                        block.samples = chain.raw(block.samples, block.aux)
                    if block.flagged.all():  # zero pulses (gap fill): zero lines, no launch
                        block.samples = np.zeros(
                            (len(block), self.engine.plan.bin_count), self.engine.lens.dtype
                        )
                    else:
                        block.samples = self.engine.compress(block.samples)
                    if self.engine_aux is not None:
                        block.aux = {"lines2": self._aux_lines(block)}
                    if chain and chain.line_stages:
                        self._held.append(block)
                        block = self._release(chain.lines(block.samples, block.aux))
                    busy += time.perf_counter() - t
                    self._forward(block)
            if self.corrections and self.corrections.line_stages:
                self._forward(self._release(self.corrections.flush(self.engine.plan.bin_count)))
            if self.settings.stages == "fused":
                tail = self._ccd_flush()
                if tail is not None:
                    self.q_image.put(tail)
        finally:
            self.stats.busy_s["lens" if self.settings.stages == "split" else "lens+ccd"] = busy
            (self.q_image if self.settings.stages == "fused" else self.q_lines).close()

    def _aux_lines(self, block: PulseBlock) -> np.ndarray:
        """Range lines of the second receiver for the pulses of ``block``."""
        raw = block.aux.get(self.height_channel)
        if raw is None:
            raise ValueError(
                f"height strips need the auxiliary channel {self.height_channel!r}; the source "
                f"delivers {sorted(block.aux) or 'none'}"
            )
        if block.flagged.all():
            return np.zeros((len(block), self.engine.plan.bin_count), self.engine.lens.dtype)
        return self.engine_aux.compress(raw)

    def _heights(self, main: np.ndarray, second: np.ndarray, final: bool = False) -> None:
        """Height strips for the main/second line pairs, queued for publication in order."""
        strips = self.height.process(main, second)
        if final:
            strips += self.height.flush()
        if strips:
            self.q_image.put(HeightBatch(strips))

    def _forward(self, block: PulseBlock | None) -> None:
        """Hand a block of range-compressed pulses to the CCD (its thread, or here if fused)."""
        if block is None or not len(block):
            return
        if self.settings.stages == "fused":
            out = self._ccd_step([block])
            if out is not None:
                self.q_image.put(out)
        else:
            self.q_lines.put(block)

    def _release(self, lines: np.ndarray) -> PulseBlock | None:
        """The first len(lines) held pulses, their metadata with the lines the stages released."""
        k = len(lines)
        if k == 0:
            return None
        parts, need = [], k
        while need:
            b = self._held[0]
            if len(b) <= need:
                parts.append(self._held.popleft())
                need -= len(b)
            else:
                parts.append(b.slice(0, need))
                self._held[0] = b.slice(need, len(b))
                need = 0
        meta = concat_blocks(parts)
        return PulseBlock(meta.first_pulse, lines, meta.arrival_s, meta.flagged)

    def _ccd_stage(self) -> None:
        busy = 0.0
        try:
            while True:
                blocks = self.q_lines.get_batch(self.max_batch)
                if blocks is None:
                    break
                t = time.perf_counter()
                out = self._ccd_step(blocks)
                busy += time.perf_counter() - t
                if out is not None:
                    self.q_image.put(out)
            tail = self._ccd_flush()
            if tail is not None:
                self.q_image.put(tail)
        finally:
            self.stats.busy_s["ccd"] = busy
            self.q_image.close()

    def _ccd_step(self, blocks: list[PulseBlock]) -> LineBlock | None:
        block = concat_blocks(blocks)
        ring = len(self._arrival)
        idx = block.first_pulse + np.arange(len(block))
        self._arrival[idx % ring] = block.arrival_s
        self._flag_pulses.extend(idx[block.flagged].tolist())
        self.own["pulses_processed"] += len(block)
        lines = self.engine.correlator.push(block.samples)
        if self.engine_aux is not None:
            self._heights(lines, self.engine_aux.correlator.push(block.aux["lines2"]))
        return self._line_block(lines)

    def _ccd_flush(self) -> LineBlock | None:
        lines = self.engine.correlator.flush()
        if self.engine_aux is not None:
            self._heights(lines, self.engine_aux.correlator.flush(), final=True)
        return self._line_block(lines)

    def _line_block(self, lines: np.ndarray) -> LineBlock | None:
        if not len(lines):
            return None
        first = self.engine.lines_out
        self.engine.lines_out += len(lines)
        j = first + np.arange(len(lines))
        ring = len(self._arrival)
        n = self.aperture
        while self._flag_pulses and self._flag_pulses[0] < first:
            self._flag_pulses.popleft()
        if self._flag_pulses:
            fl = np.fromiter(self._flag_pulses, np.int64)
            k = np.searchsorted(fl, j)
            flagged = (k < len(fl)) & (fl[np.minimum(k, len(fl) - 1)] <= j + n - 1)
        else:
            flagged = np.zeros(len(j), bool)
        self.own["lines_out"] += len(lines)
        self.own["flagged_lines"] += int(flagged.sum())
        return LineBlock(
            first, lines, self._arrival[j % ring], self._arrival[(j + n - 1) % ring], flagged
        )

    def _strip_stage(self) -> None:
        pending: list[LineBlock] = []
        held = 0
        last_stats = time.perf_counter()
        strip_lines = self.settings.strip_lines
        prf = self.config.geometry.prf_hz
        strip_period_s = min(max(strip_lines / prf, 1e-3), self.stats_every_s / 4)
        try:
            while True:
                blocks = self.q_image.get_batch(8 * strip_lines, timeout=strip_period_s)
                if blocks is None:
                    break
                if not blocks and held:  # no new line for a strip's duration: send what is held
                    pending, held = self._publish(pending, held), 0
                for b in blocks:
                    if isinstance(b, HeightBatch):
                        self._publish_heights(b)
                        continue
                    pending.append(b)
                    held += len(b)
                while held >= strip_lines:
                    pending, held = self._publish(pending, strip_lines), held - strip_lines
                now = time.perf_counter()
                if now - last_stats >= self.stats_every_s:
                    last_stats = now
                    self._send_stats()
            while held:
                take = min(held, strip_lines)
                pending, held = self._publish(pending, take), held - take
        finally:
            self._send_stats(final=True)

    def _publish(self, pending: list[LineBlock], count: int) -> list[LineBlock]:
        """Publish the first ``count`` pending lines as one strip; return what is left."""
        parts, rest, need = [], [], count
        for b in pending:
            if need == 0:
                rest.append(b)
            elif len(b) <= need:
                parts.append(b)
                need -= len(b)
            else:
                parts.append(_slice(b, 0, need))
                rest.append(_slice(b, need, len(b)))
                need = 0
        first = parts[0].first_line
        lines = parts[0].lines if len(parts) == 1 else np.concatenate([p.lines for p in parts])
        flagged = np.concatenate([p.flagged for p in parts])
        strip = Strip(
            seq=self._strip_seq,
            first_line=first,
            lines=lines,
            azimuth_m=self.engine.azimuth_m(first, len(lines)),
            first_arrival_s=float(parts[0].first_arrival_s[0]),
            last_arrival_s=float(parts[-1].last_arrival_s[-1]),
            flagged_lines=_runs(first, flagged),
        )
        self._strip_seq += 1
        for sink in self.sinks:
            sink.strip(strip, self)
        done = time.perf_counter()
        self.stats.latency.add(done - np.concatenate([p.last_arrival_s for p in parts]))
        self.own["strips_published"] += 1
        return rest

    def _publish_heights(self, batch: HeightBatch) -> None:
        for strip in batch.strips:
            for sink in self.sinks:
                if hasattr(sink, "height"):
                    sink.height(strip, self._height_seq, self)
            self._height_seq += 1
            self.own["height_strips_published"] = self.own.get("height_strips_published", 0) + 1

    def counters(self) -> dict:
        """All counters: source, ingest and pipeline."""
        c = dict(self.source.counters)
        c.update(self.ingest.counters)
        if self.corrections:
            c.update(self.corrections.counters())
        c.update(self.own)
        return c

    def _send_stats(self, final: bool = False) -> None:
        self.stats.elapsed_s = time.perf_counter() - self.stats.started_s
        self.stats.counters = self.counters()
        d = self.stats.as_dict()
        d["queue_fill"] = {
            q.name: q.size / q.capacity for q in (self.q_shots, self.q_lines, self.q_image)
        }
        d["latency_recent_median_ms"] = self.stats.latency.recent_percentile(50) * 1e3
        d["latency_recent_p99_ms"] = self.stats.latency.recent_percentile(99) * 1e3
        d["final"] = final
        if self.height is not None:
            d["height"] = {k: float(v) for k, v in self.height.stats.items()}
        for sink in self.sinks:
            (sink.end if final else sink.stats)(d, self)
        if self.on_stats is not None:
            self.on_stats(d)

    # ---- control ----------------------------------------------------------------------------
    def _guard(self, target):
        def run():
            try:
                target()
            except BaseException as exc:  # a stage failed: stop everything, report in run()
                self._errors.append(exc)
                self._stop.set()
                self.source.close()
                for q in (self.q_shots, self.q_lines, self.q_image):
                    q.close()

        return run

    def start(self) -> None:
        self.stats.started_s = time.perf_counter()
        stages = [self._source_stage, self._lens_stage, self._strip_stage]
        if self.settings.stages == "split":
            stages.insert(2, self._ccd_stage)
        for target in stages:
            t = threading.Thread(
                target=self._guard(target), name=f"rtsar-{target.__name__[1:]}", daemon=True
            )
            self._threads.append(t)
            t.start()

    def stop(self) -> None:
        """Stop the source; what is in flight is still processed and published."""
        self.source.close()

    def join(self) -> PipelineStats:
        try:
            for t in self._threads:
                while t.is_alive():
                    t.join(0.1)
        except KeyboardInterrupt:
            self.stop()
            for t in self._threads:
                t.join()
            raise
        finally:
            if self._errors:
                raise self._errors[0]
        return self.stats

    def run(self) -> PipelineStats:
        self.start()
        return self.join()


def _groups(blocks: list[PulseBlock], most: int):
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


def _slice(b: LineBlock, start: int, stop: int) -> LineBlock:
    return LineBlock(
        b.first_line + start,
        b.lines[start:stop],
        b.first_arrival_s[start:stop],
        b.last_arrival_s[start:stop],
        b.flagged[start:stop],
    )


def _runs(first: int, flagged: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in ``flagged`` as (first_line, count) pairs."""
    if not flagged.any():
        return []
    f = np.concatenate([[False], flagged, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(f))
    return [(first + int(a), int(b - a)) for a, b in zip(edges[::2], edges[1::2], strict=True)]
