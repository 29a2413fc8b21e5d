"""The streaming pipeline: source → ingest → AO lens → shifting CCD → strips → publishers.

Each stage is a thread, joined to the next by a bounded queue (capacity in pulses or lines);
the heavy work releases the GIL.  ``stages``: "split" (lens and CCD threads), "fused" (one
thread), "overlapped" (one thread, the lens computing batch k + 1 while the CCD correlates
batch k).  A live source's shots are dropped and counted when the first queue is full (ingest
zero-fills their slots); a replay waits.  Each stage takes all the work waiting, up to a cap
(``lens_align`` = B: the lens first waits for the pulses that complete a block of B).

Corrections (rtsar.focus.chain) run in the lens thread in pulse order: "raw" stages before the
lens, "lines" stages between lens and CCD; a line stage may hold pulses (PGA holds a block),
their arrival times and flags waiting with them (rtsar.stream.hold).  3D (``height``): the
auxiliary receivers through their own lens and CCD in step (rtsar.stream.height), height strips
published beside the image strips.  ``swath_workers`` = K: lens and CCD in K processes, a range
slice each (rtsar.stream.swath).

Latency of an image line: from the arrival of the last pulse that contributes to it (pulse
j + N - 1 for line j, Psaltis & Wagner 1981: the row leaves the CCD after N shifts) to the
publication of its strip: a strip goes out when it holds ``strip_lines`` (with every line then
waiting, up to ``strip_most_lines``), or its oldest line waited ``strip_deadline_s``
(rtsar.stream.granularity chooses them; rtsar.stream.growth doubles the correlator's block
while the work falls behind, and shrinks it back once there is room).  The pieces:
rtsar.stream.queue, ingest, engine, hold, timing, height, strips, publication (the strip
stage), swath, link (silences), stats, settings, heap (the collector)."""

from __future__ import annotations

import signal
import threading
import time
from collections import deque
from dataclasses import replace

from ..params import Config
from ..sources.base import ShotBatch, Source, join_batches
from . import heap
from .engine import Lines, StreamProcessor
from .growth import config_with_block, growth_of
from .height import HeightBatch, HeightChannel
from .hold import HeldPulses
from .ingest import Ingest, PulseBlock, concat_blocks, regroup_blocks
from .link import LinkWatch
from .memory import check_memory
from .overlap import overlapped_stage
from .publication import strip_stage
from .queue import BoundedQueue
from .settings import PipelineSettings
from .stats import PipelineStats
from .strips import LineBlock, StreamInfo, StripAssembler, StripSink, new_stream_id, utc_text
from .swath import SwathWorkers
from .timing import LineTiming

OWN_COUNTERS = (
    "dropped_pulses", "pulses_processed", "lines_out", "flagged_lines", "strips_published"
)  # fmt: skip


class Pipeline:
    """Run ``source`` through the engine and hand strips to ``sinks`` (publishers, recorders).

    A sink implements rtsar.stream.strips.StripSink (``strip``, ``height``, ``stats``, ``end``,
    and ``pulses`` for a raw recorder; each receives the run's StreamInfo, never the pipeline).
    ``run()`` blocks until the source ends or ``stop()``; Ctrl-C in ``run()`` stops the source,
    drains the pipeline and flushes the CCD, so every pulse that arrived is focused and published.
    """

    def __init__(
        self,
        config: Config,
        source: Source,
        sinks: list[StripSink],
        settings: PipelineSettings | None = None,
        start_along_track_m: float = 0.0,
        on_stats=None,
        stats_every_s: float = 1.0,
        corrections=None,
        physical=None,
        height=None,
        stream_id: str | None = None,
        notify=None,
        link_timeout_s: float | None = None,
    ):
        self.config = config
        self.corrections = corrections
        if height is not None and corrections:
            raise ValueError(
                "height strips with --correct are not supported: the corrections act on the "
                "main receiver only and would bias the height phase between the receivers"
            )
        self.source = source
        # A live source's silences are told (``notify``) and end the run at link_timeout_s.
        prf = config.geometry.prf_hz
        self.link = LinkWatch(prf, notify, link_timeout_s, source.close) if source.live else None
        self.sinks = list(sinks)
        for sink in self.sinks:  # a wrong object fails here, not in a stage thread mid-stream
            if not isinstance(sink, StripSink):
                raise TypeError(f"sinks must be StripSink objects, got {type(sink).__name__}")
        self._pulse_sinks = [sink for sink in self.sinks if sink.wants_pulses]
        self.settings = s = replace(settings) if settings else PipelineSettings()  # a growth sets
        n = config.processor.aperture_pulses
        capacity = s.queue_pulses or 8 * n
        aux, growing = 0 if height is None else len(height.channels), len(s.grow_blocks) > 1
        largest = config_with_block(config, s.grow_blocks[-1]) if growing else config
        check_memory(largest, capacity, aux, growing)  # (a history, correlators built beside)
        azimuth = not s.swath_workers  # with swath workers, they correlate: no CCD here
        self.engine = StreamProcessor(
            config, s.lens_backend, s.device, start_along_track_m, corrections, physical, azimuth, s
        )
        where = (s.lens_backend, s.device, start_along_track_m)  # the receivers' lenses
        self.height = None if height is None else HeightChannel(config, height, *where)
        self.notify = notify
        self.max_batch = s.take_cap(config.processor.micro_batch, source.paced)
        self.growth = growth_of(config, s, self.engine, physical, height, self.max_batch)
        self._held = HeldPulses()  # pulses inside the line stages (metadata)
        self._holding = bool(corrections and corrections.line_stages)
        self.q_shots = BoundedQueue(capacity, "shots")
        self.q_lines = BoundedQueue(capacity, "compressed")
        self.q_image = BoundedQueue(capacity, "image lines")
        max_gap, origin = s.max_gap_pulses or n, getattr(source, "seq_origin", None)
        samples = config.waveform.samples_per_shot
        self.ingest = Ingest(samples, n, max_gap, self.engine.dtype, origin_seq=origin)
        self._anchored = False  # an anchored source's start is moved once (_anchor)
        block = config.processor.fft_length or 2 * n
        self.timing = LineTiming(n, 4 * (n + block + capacity + self.max_batch))
        self.stats = PipelineStats()
        self.on_stats = on_stats
        self.stats_every_s = stats_every_s
        self.own = dict.fromkeys(OWN_COUNTERS, 0)  # source and ingest keep theirs
        self._errors: list[BaseException] = []
        self._stop = threading.Event()
        self._ended: list[threading.Event] = []  # set by each stage thread as it ends
        self._height_seq = 0
        self._fused_ccd_s = 0.0  # the CCD's work in the fused lens stage (its busy time)
        self.strips = StripAssembler(StreamInfo(  # the stream's info: the strips' (``info``)
            stream_id=stream_id or new_stream_id(),
            config=config,
            source=source.description,
            lens_backend=self.engine.lens.backend,
            range_m=self.engine.range_m,
            start_along_track_m=float(start_along_track_m),
            clock_offset_s=time.time() - time.perf_counter(),  # + perf_counter = UNIX time
            heights=self.height is not None,
            height_kind="" if height is None else height.kind,
            corrections=tuple(corrections.names) if corrections else (),
            correction_specs=tuple(corrections.specs) if corrections else (),
            physical=None if physical is None else physical.to_dict(),
            collection_start_utc=utc_text(getattr(source, "collection_start", None)),
            instrument_file=str(getattr(source, "instrument_file", "") or ""),
        ))  # fmt: skip
        self.swath = None  # lens + CCD in worker processes (rtsar.stream.swath)
        if s.swath_workers:
            if corrections or physical is not None or height is not None:
                raise ValueError("--swath-workers runs without --correct, --physical, --height")
            self.swath = SwathWorkers(
                config, s.swath_workers, s.lens_backend, s.device, s.swath_spawn, s.swath_bind,
                notify=notify,
            )  # fmt: skip
            self._sent = deque()  # metadata of the pulse blocks sent to the workers

    @property
    def stream_id(self) -> str:
        return self.info.stream_id

    @property
    def info(self) -> StreamInfo:
        """What the sinks know of the run (a new block's config from its first strip)."""
        return self.strips.info

    # ---- stages ---------------------------------------------------------------------------
    def _source_stage(self) -> None:
        live, stamps_start = self.source.live, getattr(self.source, "clock_is_start", True)
        if self.link is not None:  # the silence is timed from here, not from the pipeline's build
            self.link.start()
        try:
            for batch in self.source:
                if self._stop.is_set():
                    break
                if self.link is not None and len(batch):
                    self.link.heard(int(batch.seq[0]), int(batch.seq[-1]))
                if len(batch) and stamps_start:
                    self.info.first_shot_at(float(batch.arrival_s[0]))
                if not self.q_shots.put(batch, block=not live):
                    self.own["dropped_pulses"] += len(batch)
        finally:
            if self.link is not None:
                self.link.ended()
            self.q_shots.close()
            for sink in self.sinks if self.settings.deadline else ():
                sink.hurry()

    def _overlapped_stage(self) -> None:
        overlapped_stage(self)

    def _lens_stage(self) -> None:
        busy = 0.0
        key = "lens" if self.settings.stages == "split" else "lens+ccd"
        try:
            while True:  # align > 1: a block's pulses in one call (a silence: then what came)
                align, hold_s = self.settings.lens_align, self.settings.lens_hold_s  # may grow
                split = align and ShotBatch.split  # aligned: a source's release cut at the batch
                into = (self.ingest.next_pulse - self.settings.lens_align_from) % (align or 1)
                need = min(align - into, self.max_batch) if align else 1
                batches = self.q_shots.get_batch(self.max_batch, None, need, hold_s, split)
                t = time.perf_counter()
                blocks = self._ingest(batches)
                busy += time.perf_counter() - t
                for block in regroup_blocks(blocks, self.max_batch):
                    t = time.perf_counter()
                    if self.swath is not None:
                        self._to_workers(block)
                        continue
                    out = self._range(block)
                    busy += time.perf_counter() - t
                    self.stats.busy_s[key] = busy + self._fused_ccd_s  # in every stats message
                    self._forward(out)
                if batches is None:
                    break
            if self.swath is not None and not self._stop.is_set():  # failed: join() stops them
                self.swath.end()
            if self._holding:
                self._forward(self._held.release(self.engine.flush_range()))
            if self.settings.stages != "split":
                self._put_image(self._ccd_flush())
        finally:
            self.stats.busy_s[key] = busy + self._fused_ccd_s
            (self.q_image if self.settings.stages != "split" else self.q_lines).close()
            if self.settings.stages != "split":  # fused: the CCD's stage is this one
                self._close_correlators()

    def _ingest(self, batches: list | None) -> list[PulseBlock]:
        """Ingest checks on the batches taken (None: the source ended), joined where they can be
        (rtsar.sources.base.join_batches); the first shot anchors."""
        if batches is None:
            blocks = self.ingest.flush()
        else:
            blocks = [b for batch in join_batches(batches) for b in self.ingest(batch)]
            if not self._anchored and self.ingest.counters["pulses_received"]:
                self._anchor()
        for block in blocks:  # the stream as ingest made it: to a raw recorder
            for sink in self._pulse_sinks:
                sink.pulses(block, self.info)
        return blocks

    def _anchor(self) -> None:
        """The first shot arrived: a source that numbers from the scan's pulse 0 puts stream
        pulse 0 at pulse ``ingest.start_pulses`` of the scan (rtsar.stream.ingest), so pulse 0's
        position moves by that many steps, everywhere it is held, before any line is formed."""
        self._anchored = True
        shift_m = self.ingest.start_pulses * self.config.geometry.along_track_step_m
        if not shift_m:
            return
        start = self.info.start_along_track_m + shift_m
        self.strips.info = replace(self.info, start_along_track_m=start)
        engines = [self.engine, *(self.height.engines.values() if self.height else ())]
        for engine in engines:
            engine.start_along_track_m = start
        if self.corrections:
            self.corrections.move_start(shift_m)

    def _range(self, block: PulseBlock) -> PulseBlock | None:
        """Range half of the engine on one block; the pulses it releases, with their metadata."""
        zero = bool(block.flagged.all())  # zero pulses (gap fill): zero lines, no launch
        lines = self.engine.range_stage(block.samples, block.aux, zero)
        aux = {} if self.height is None else self.height.compress(block)
        if self._holding:  # a line stage may hold pulses: their metadata waits with them
            self._held.hold(block.with_samples(block.samples[:, :0]))
            return self._held.release(lines)
        return block.with_samples(lines, aux)

    def _forward(self, block: PulseBlock | None) -> None:
        """Hand a block of range-compressed pulses to the CCD (its thread, or here if fused)."""
        if block is None or not len(block):
            return
        if self.settings.stages != "split":  # the CCD's work here is this stage's too
            t = time.perf_counter()
            lines = self._ccd_step([block])
            self._fused_ccd_s += time.perf_counter() - t
            self._put_image(lines)
        else:
            self.q_lines.put(block)

    def _to_workers(self, block: PulseBlock) -> None:
        meta = block.with_samples(block.samples[:, :0])
        self._sent.append(meta)  # before the send: its lines cannot come back before it
        self.swath.send(block.first_pulse, block.samples, bool(block.flagged.all()))

    def _swath_stage(self) -> None:
        """The CCD stage when workers run lens and CCD: their merged lines become line blocks."""
        try:
            while not self._stop.is_set():
                out = self.swath.receive(0.05)
                while self._sent:
                    meta = self._sent.popleft()
                    self.timing.record(meta)
                    self.own["pulses_processed"] += len(meta)
                if out is not None:
                    self.swath.downstream_since = time.monotonic()
                    try:  # the workers wait on us meanwhile: not a stall of theirs
                        self._put_image(self._line_block(out))
                    finally:
                        self.swath.downstream_since = None
                elif self.swath.finished:
                    break
        finally:
            self.q_image.close()  # the sockets close in join(), once no stage uses them

    def _put_image(self, block: LineBlock | HeightBatch | None) -> None:
        """Image lines (or height strips, in order with them) queued for publication."""
        if block is not None:
            self.q_image.put(block)

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
                self.stats.busy_s["ccd"] = busy
                self._put_image(out)
            self._put_image(self._ccd_flush())
        finally:
            self.stats.busy_s["ccd"] = busy
            self.q_image.close()
            self._close_correlators()

    def _close_correlators(self) -> None:
        """The run's end: its correlator, and any built for a change of block that did not come."""
        self.engine.correlator.close()
        if self.growth is not None:
            self.growth.close()

    def _ccd_step(self, blocks: list[PulseBlock]) -> LineBlock | None:
        block = concat_blocks(blocks)
        self.timing.record(block)
        self.own["pulses_processed"] += len(block)
        out = self.engine.azimuth_stage(block.samples)
        # the block changed (behind, or room: rtsar.stream.growth): the new info after its lines
        info = self.growth.step(self, block.samples) if self.growth is not None else None
        if self.height is not None:
            self._put_image(self.height.correlate(out.lines, block.aux))
        if info is None:
            return self._line_block(out)
        self._put_image(self._line_block(out))
        self._put_image(info)

    def _ccd_flush(self) -> LineBlock | None:
        out = self.engine.flush_azimuth()
        if self.height is not None:
            self._put_image(self.height.flush(out.lines))
        return self._line_block(out)

    def _line_block(self, out: Lines) -> LineBlock | None:
        block = self.timing.lines(out.first_line, out.lines)
        if block is not None:
            self.own["lines_out"] += len(block)
            self.own["flagged_lines"] += int(block.flagged.sum())
        return block

    def _strip_stage(self) -> None:
        strip_stage(self)

    def _publish(self, count: int) -> None:
        """Publish the first ``count`` pending lines as one strip."""
        strip, last_arrival_s = self.strips.take(count, self.counters())
        for sink in self.sinks:
            sink.strip(strip, self.info)
        self.stats.latency.add(time.perf_counter() - last_arrival_s)
        self.own["strips_published"] += 1

    def counters(self) -> dict:
        """All counters: source, ingest, corrections, sinks and pipeline."""
        c = dict(self.source.counters)
        c.update(self.ingest.counters)
        c.update(self.corrections.counters() if self.corrections else {})
        for sink in self.sinks:
            c.update(sink.counters())
        for part in (self.link, self.swath, self.growth):  # silences, refusals, growths
            c.update(part.counters() if part is not None else {})
        c.update(self.own)
        return c

    def _send_stats(self, final: bool = False) -> None:
        self.stats.elapsed_s = time.perf_counter() - self.stats.started_s
        self.stats.counters = self.counters()
        d = self.stats.as_dict()
        queues = (self.q_shots, self.q_lines, self.q_image)
        d["queue_fill"] = {q.name: q.size / q.capacity for q in queues}
        d["latency_recent_median_ms"] = self.stats.latency.recent_percentile(50) * 1e3
        d["latency_recent_p99_ms"] = self.stats.latency.recent_percentile(99) * 1e3
        d["final"] = final
        d["link"] = None if self.link is None else self.link.state()  # a silence being told
        if self.height is not None:
            d["height"] = {k: float(v) for k, v in self.height.stage.stats.items()}
        if not final:
            for sink in self.sinks:
                sink.stats(d, self.info)
        else:  # files end first (the image's lines on disk, then the recording), so the end
            first = [sink for sink in self.sinks if sink.ends_first]  # message has their word
            try:
                for sink in first:
                    sink.end(d, self.info)
            finally:  # (one that failed: the others still end)
                if first:
                    self.stats.counters = self.counters()
                    d["counters"] = {k: int(v) for k, v in self.stats.counters.items()}
                for sink in self.sinks:
                    if sink not in first:
                        sink.end(d, self.info)
        if self.on_stats is not None:
            self.on_stats(d)

    # ---- control ----------------------------------------------------------------------------
    def _guard(self, target, ended: threading.Event):
        def run():
            try:
                target()
            except BaseException as exc:  # a stage failed: stop everything, report in run()
                self._errors.append(exc)
                self._stop.set()
                if self.swath is not None:
                    self.swath.abort()
                self.source.close()
                for q in (self.q_shots, self.q_lines, self.q_image):
                    q.close()
            finally:
                ended.set()

        return run

    def start(self) -> None:
        heap.freeze(self)  # the collector walks only what the stream makes (rtsar.stream.heap)
        self.stats.started_s = time.perf_counter()
        # overlapped: with no line stage holding pulses and no height channel (else fused)
        overlap = self.settings.stages == "overlapped" and not self._holding and not self.height
        middle = self._overlapped_stage if overlap else self._lens_stage
        stages = [self._source_stage, middle, self._strip_stage]
        if self.settings.stages == "split":
            stages.insert(2, self._ccd_stage if self.swath is None else self._swath_stage)
        if self.link is not None:  # the watch ends with the source (LinkWatch.ended)
            threading.Thread(target=self.link.run, name="rtsar-link", daemon=True).start()
        try:
            for target in stages:
                ended = threading.Event()
                self._ended.append(ended)
                name = f"rtsar-{target.__name__[1:]}"
                threading.Thread(target=self._guard(target, ended), name=name, daemon=True).start()
        except BaseException:  # no join() will follow: the heap is thawed here
            heap.thaw(self)
            raise

    def interrupted(self, exc: KeyboardInterrupt) -> None:
        """Stopped by a signal ``exc``: said in stopped_by where it cut the source short."""
        if self._ended and not self._ended[0].is_set():
            self.stats.stopped_by = signal.Signals(getattr(exc, "signum", signal.SIGINT)).name
        self.stop()

    def stop(self) -> None:
        """Stop the source; what is in flight is still processed and published, promptly: the
        sinks stop waiting on stalled subscribers."""
        self.source.close()
        for sink in self.sinks:
            sink.hurry()

    def join(self) -> PipelineStats:
        """Wait for the run to end.  Ctrl-C (or a signal raised as KeyboardInterrupt) stops the
        source, finishes what arrived, then raises; a second one while finishing is ignored, a
        third gives up on finishing."""
        try:
            self._wait()
        except KeyboardInterrupt as exc:
            self.interrupted(exc)
            for more in range(3):
                try:
                    self._wait()
                    break
                except KeyboardInterrupt:
                    if more == 2:
                        raise
            raise
        finally:
            heap.thaw(self)
            if self.swath is not None:  # workers that were told the end finish; others go
                reason = f"{self._errors[0]}" if self._errors else ""
                self.swath.close(wait_s=0.0 if self._errors else 5.0, reason=reason)
            if self._errors:
                raise self._errors[0]
        return self.stats

    def _wait(self) -> None:  # events: a Ctrl-C in Thread.join can mark a live thread ended
        for ended in self._ended:
            while not ended.wait(0.1):
                pass

    def run(self) -> PipelineStats:
        self.start()
        return self.join()
