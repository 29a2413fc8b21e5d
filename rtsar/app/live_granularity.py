"""A live run's granularity, chosen at its start: the engine's work timed here on synthetic
shots, then the rule of rtsar.stream.granularity (issue 38).

Where the correlator releases its lines in blocks (the head block of partitioned and
nonuniform; fft's overlap-save block, set by its transform length), each candidate block's
path is timed part by part as the pipeline runs it (path_costs_s: ingest, the run's own lens,
the correlator built with that block, a published strip), smallest block first, until one
models worse than a smaller one (past_the_least).  The direct and physical CCDs: the lens at
1, 2, 4, … pulses a call up to the first that keeps up, each block's push and one strip timed
alone.  With ``--height`` each receiver adds a lens and a correlator, so their figures count
once a channel.  A fraction of a second to a few seconds (RADARSAT-1's fft plan: about 2.4 s, most
of it building the correlators).  What the command line fixed (``--partition-lines``,
``--fft-length``, ``--strip-lines`` / ``--strip-ms``, ``--max-batch``) stays.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.fft import next_fast_len

from ..analysis.timing import rate_per_s
from ..ccd import make_ccd
from ..lens import cl_devices, make_lens, make_plan
from ..lens.base import survey_devices_first, survey_wanted
from ..lens.numpy_lens import NumpyLens
from ..lens.plan import next_pow2
from ..lens.small_calls import TIMED_UP_TO, SmallCallsOnCPU, call_cost_s, cpu_limit, route_words
from ..params import Config, Processor
from ..sinks.publish import ZmqPublisher
from ..sinks.wire import strip_header
from ..sources.base import ShotBatch
from ..stream.granularity import (
    FUSE_BELOW,
    MOST_STRIP_LINES,
    Granularity,
    StageCosts,
    auto_strip_lines,
    choose_granularity,
    granularity_words,
    live_correlator,
    modelled_latency_s,
    utilisation,
)
from ..stream.growth import (
    GROWING_KINDS,
    HEAD_BLOCK_KINDS,
    config_with_block,
    growth_words,
    why_fixed,
)
from ..stream.ingest import Ingest
from ..stream.settings import PipelineSettings
from ..stream.stats import LatencyStats
from ..stream.strips import LineBlock, StreamInfo, StripAssembler
from ..stream.timing import LineTiming

ROUND_S = 0.01  # each of a figure's 3 rounds


@dataclass(frozen=True)
class GranularityRequest:
    """What to choose for a live run at ``rate_hz`` pulses/s: None for what the command line
    left to the choice."""

    rate_hz: float
    block_lines: int | None = None  # --partition-lines
    strip_lines: int | None = None  # --strip-lines, --strip-ms
    fft_length: int | None = None  # --fft-length
    stages: str | None = None  # --stages
    correlator: str | None = None  # --correlator (None: rtsar.stream.granularity.live_correlator)

    def apply(
        self,
        config: Config,
        settings: PipelineSettings,
        physical=None,
        height=None,
        say=None,
        source_s: float = 0.0,
    ):
        """(config, settings, Granularity, the banner's lines) with the chosen granularity;
        ``say`` (a message) is told when the measuring starts; ``source_s``: the source's own
        work a pulse in this process (StageCosts)."""
        config, switched = self.live_config(config, physical)
        if say is not None:
            say(f"measuring the work at {self.rate_hz:,.0f} pulses/s to choose the granularity …")
        copies = 1 + (len(height.channels) if height is not None else 0)
        lens_batch = settings.max_batch or config.processor.micro_batch
        blocks, fixed = block_candidates(
            config.processor, physical, self.block_lines, self.fft_length
        )
        costs = measure_costs(
            config, settings, self.rate_hz, blocks, copies, physical, self, source_s
        )
        g = choose_granularity(
            self.rate_hz, costs, lens_batch, self.strip_lines, fixed_block=fixed,
            aligned=aligned(config.processor, physical, settings.stages),
        )  # fmt: skip
        words = granularity_words(g, costs)
        if costs.lens_cpu_below > 1:
            words += f"; {small_calls_words(costs)}"
        swath = bool(settings.swath_workers)
        why = why_fixed(config.processor, physical, copies, swath)
        grow = not fixed and not why
        larger = [b for b in blocks if b > g.block_lines] if grow else []
        grow_blocks = (g.block_lines, *larger) if larger else ()
        if grow_blocks:
            words += f"; {growth_words(grow_blocks)}"
        elif not fixed and why:
            words += f"; the block does not grow when behind ({why})"
        if self.stages is None:
            words += f"; {g.stages} stages ({stages_words(g)})"
        chosen = block_config(config, g.block_lines, physical)
        if physical is None and chosen.processor.correlator == "fft":  # what --fft-length sets
            words += f"; fft transform length M = {chosen.processor.fft_length}"
        chosen_s = chosen_settings(settings, g, self.stages is None)
        below = costs.lens_cpu_below if not settings.swath_workers else 0  # workers': their own
        grow_rate_hz = self.rate_hz if grow_blocks else 0.0
        chosen_s = replace(chosen_s, grow_blocks=grow_blocks, grow_rate_hz=grow_rate_hz)
        words = f"{switched}\n{words}" if switched else words  # a line each on the banner
        return chosen, replace(chosen_s, lens_cpu_below=below), g, words

    def live_config(self, config: Config, physical=None) -> tuple[Config, str]:
        """(config with the correlator a live run takes, words for a change): live_correlator"""
        return live_correlator(config, self.correlator, self.fft_length, physical)


def request_of(args, rate_hz: float | None) -> GranularityRequest | None:
    """The request of a run/replay command line (None: a replay as fast as it goes, no rate to
    choose for; swath workers, which correlate in their own processes: as configured)."""
    if rate_hz is None or getattr(args, "swath_workers", 0):
        return None
    return GranularityRequest(
        rate_hz,
        args.partition_lines,
        args.strip_lines,
        getattr(args, "fft_length", None),
        getattr(args, "stages", None),
        getattr(args, "correlator", None),
    )


def small_calls_words(costs) -> str:
    """Why the lens's small calls run on the CPU (StageCosts.lens_cpu_below): the largest."""
    b = max(k for k in costs.lens_route_s if k < costs.lens_cpu_below)
    cl_wall, cl_cpu, wall, cpu = costs.lens_route_s[b]
    return (
        f"{route_words(costs.lens_cpu_below)} (less of the machine: {b} pulse"
        f"{'s' if b != 1 else ''} take it {_us_each(wall, cpu)}, the OpenCL lens "
        f"{_us_each(cl_wall, cl_cpu)})"
    )


def _us_each(wall_s: float, cpu_s: float) -> str:
    return f"{wall_s * 1e6:.0f} µs ({cpu_s * 1e6:.0f} µs of CPU)"


def stages_words(g) -> str:
    """Why the layout the run chose (Granularity.stages)."""
    share = f"the work takes {g.utilisation:.0%}"
    if g.stages == "fused":
        return f"lens and correlator on one thread: {share}, at most {FUSE_BELOW:.0%}"
    return f"lens and correlator on two threads: {share}, over {FUSE_BELOW:.0%}"


def block_candidates(
    p: Processor, physical=None, given: int | None = None, given_fft: int | None = None
) -> tuple[list, str]:
    """(the blocks to choose among, why there is one only or ""): the partitioned and nonuniform
    correlators' head block L, 1, 2, 4, … up to MOST_STRIP_LINES (64: a rate no block of 16
    keeps up with gets larger ones) or partition_lines where larger, at most the aperture
    (``given``: --partition-lines, refused with fft); fft's M - N + 1 for M = the least 2·3·5
    product >= N - 1 + b, b = 1, 2, 4, …, each once, below the configuration's M, and that M
    (``given_fft``: --fft-length); the direct and physical CCDs: the strip's block, 1 … 16."""
    if physical is None and p.correlator == "fft":
        if given:  # (a live run at a rate keeps fft with --fft-length or time-domain taps)
            raise ValueError(
                "--partition-lines sets the block of the partitioned and nonuniform correlators;"
                " this run keeps fft, which does not read it (or name --correlator nonuniform)"
            )
        n = p.aperture_pulses
        if given_fft:
            return [given_fft - n + 1], "--fft-length"
        top = p.fft_length or next_pow2(2 * n)
        lengths, b = [], 1
        while (m := next_fast_len(n - 1 + b, real=True)) < top:  # the least 2·3·5 >= it
            if m not in lengths:
                lengths.append(m)
            b *= 2
        return [m - n + 1 for m in [*lengths, top]], ""
    if physical is None and p.correlator in HEAD_BLOCK_KINDS and given:
        return [given], "--partition-lines"
    largest = 16
    if p.correlator in HEAD_BLOCK_KINDS:
        largest = min(max(p.partition_lines, MOST_STRIP_LINES), p.aperture_pulses)
    return [1 << k for k in range(largest.bit_length()) if 1 << k <= largest], ""


def aligned(p: Processor, physical=None, stages: str = "split") -> bool:
    """Whether the lens takes each block's pulses together (rtsar.stream.granularity): the
    correlators that release lines in blocks (a head block; fft's overlap-save blocks, which
    also end on multiples of their B pulses), in the split or fused stages (the overlapped
    stage's lens takes what waits, rtsar.stream.overlap)."""
    return physical is None and p.correlator in GROWING_KINDS and stages != "overlapped"


def block_config(config: Config, block: int, physical=None) -> Config:
    """``config`` whose correlator releases its lines in blocks of ``block``
    (rtsar.stream.growth.config_with_block); with ``physical`` (its CCD), as it is."""
    return config if physical is not None else config_with_block(config, block)


def chosen_settings(settings: PipelineSettings, g: Granularity, layout=False) -> PipelineSettings:
    """``settings`` with the granularity ``g``; ``layout``: its stages too (--stages not given)."""
    return replace(
        settings,
        stages=g.stages if layout and not settings.swath_workers else settings.stages,
        strip_lines=g.strip_lines,
        strip_most_lines=g.strip_most_lines,
        strip_deadline_s=g.strip_deadline_s,
        lens_align=g.lens_align,
        lens_hold_s=g.lens_hold_s,
    )


def per_call_s(call) -> float:
    """Seconds a call, calls made back to back: the median of 3 rounds (analysis.timing)."""
    return float(np.median([1.0 / rate_per_s(call, 1, ROUND_S) for _ in range(3)]))


def measure_costs(
    config, settings, rate_hz, blocks, copies=1, physical=None, request=None, source_s=0.0
):
    """StageCosts of the run (module docstring), each call's figure times ``copies``; the
    blocks measured smallest first, until one's modelled latency exceeds a smaller one's (it
    only grows from there).  Where the lens takes each block's pulses together (``aligned``):
    each block's path timed in turn (path_costs_s); else the lens at 1, 2, 4, … pulses a
    call, up to the first that keeps up, and the blocks, each alone."""
    p = config.processor
    plan = make_plan(config)
    dtype = np.complex128 if p.precision == "complex128" else np.complex64
    rng = np.random.default_rng(0)

    def noise(rows: int, cols: int) -> np.ndarray:
        return (rng.standard_normal((rows, cols)) + 1j * rng.standard_normal((rows, cols))).astype(
            dtype
        )

    lens = make_lens(plan, settings.lens_backend, settings.device, p.precision, p.micro_batch)
    route: dict[int, tuple[float, float, float, float]] = {}
    # --lens hybrid: small calls on the CPU?  Not with --height: its receivers' engines keep
    # their own lenses.
    if settings.lens_backend == "hybrid" and lens.backend == "opencl" and copies == 1:
        sizes = sorted({min(b, TIMED_UP_TO) for b in blocks} | {1})
        lens, route = small_calls_route(lens, sizes, noise)
    below = getattr(lens, "below", 1)
    fixed_strips = request.strip_lines if request is not None else None
    lens_s: dict[int, float] = {}
    ingest_s: dict[int, float] = {}
    block_s: dict[int, float] = {}
    if aligned(p, physical, settings.stages):
        strip_s = None
        lens_batch = settings.max_batch or p.micro_batch
        for block in blocks:
            parts = path_costs_s(config, plan, lens, block, noise, lens_batch, rate_hz)
            ingest_s[block] = parts[0]  # ingest checks every channel in one call
            lens_s[block], block_s[block] = copies * parts[1], copies * parts[2]
            strip_s = parts[3] if strip_s is None else strip_s  # a strip's cost: the first's
            costs = StageCosts(lens_s, dict(block_s), strip_s, source_s, dict(ingest_s))
            if past_the_least(rate_hz, costs, fixed_strips, True):
                break
        return StageCosts(lens_s, block_s, strip_s, source_s, ingest_s, below, route)
    b = 1
    while b <= (settings.max_batch or p.micro_batch):
        shots = noise(b, plan.samples_per_shot)
        lens_s[b] = copies * per_call_s(lambda s=shots: lens.compress(s))
        ingest_s[b] = ingest_cost_s(config, shots)
        if lens_s[b] <= b / rate_hz:
            break
        b *= 2
    strip_s = strip_cost_s(config, plan.range_m)
    for block in blocks:
        block_s[block] = copies * push_s(config, plan.range_m, physical, block, noise)
        costs = StageCosts(lens_s, dict(block_s), strip_s, source_s, ingest_s)
        if past_the_least(rate_hz, costs, fixed_strips, False):
            break
    return StageCosts(lens_s, block_s, strip_s, source_s, ingest_s, below, route)


def small_calls_route(lens, sizes, noise):
    """(the lens to time and run, {pulses a call: (wall, CPU seconds a call on the OpenCL lens,
    the same on SciPy's FFT)}): the OpenCL ``lens`` and the plan on SciPy's FFT timed at each
    of ``sizes`` in turn, and where SciPy's takes less CPU at the small ones, the lens with
    those calls on it (rtsar.lens.small_calls)."""
    cpu = NumpyLens(lens.plan, "scipy", lens.precision)
    shots = {b: noise(b, lens.plan.samples_per_shot) for b in sizes}
    # SciPy's first, every size, then OpenCL's: the driver's workers spin on after a launch,
    # and that CPU is OpenCL's, not the next timing's
    on_cpu = {b: call_cost_s(cpu, shots[b], ROUND_S) for b in sizes}
    costs = {b: (*call_cost_s(lens, shots[b], ROUND_S), *on_cpu[b]) for b in sizes}
    below = cpu_limit({b: (c[1], c[3]) for b, c in costs.items()})
    return (SmallCallsOnCPU(lens, cpu, below) if below > 1 else lens), costs


def past_the_least(rate_hz: float, costs: StageCosts, strip_lines, lens_aligned: bool) -> bool:
    """Whether the largest block measured has a finite modelled latency above a smaller
    one's: the wait for a block grows with it while the share of the work only falls towards
    its floor, so no larger block does better (the measuring stops there)."""
    *smaller, largest = sorted(costs.block_s)

    def latency(b: int) -> float:
        strips = strip_lines or auto_strip_lines(b)
        return modelled_latency_s(
            rate_hz, utilisation(rate_hz, costs, b, strips, lens_aligned), b, strips
        )

    last = latency(largest)
    return math.isfinite(last) and any(latency(b) < last for b in smaller)


PATH_ROUNDS = 3  # rounds of blocks timed through the path, after PATH_WARM_CALLS blocks
PATH_WARM_CALLS = 4
PATH_LEAST_CALLS = 8  # blocks a round, at least, …
PATH_LEAST_LINES = 64  # … where they hold fewer lines than this (fft's hundreds: one a round)
HOPELESS_SHARE = 2.0  # a block whose warm calls take this share of the stream's time: no rounds
# Each timing's publisher binds a name of its own: a closed socket's inproc name is released
# by ZeroMQ's I/O thread later, so a reused name (once the id of a freed object) could be
# "already in use" under load (CI, 53c0161).
_PROBE_NAMES = itertools.count()


def probe_endpoint() -> str:
    """A fresh inproc name for a timing's publisher: never one this process bound before."""
    return f"inproc://rtsar-granularity-{os.getpid()}-{next(_PROBE_NAMES)}"


def path_costs_s(
    config: Config, plan, lens, block: int, noise, lens_batch: int = 0, rate_hz: float = 0.0
) -> tuple[float, float, float, float]:
    """Seconds a call of each part of a block's path, (ingest, lens, correlator, strip), for
    blocks taken through all four in turn on one thread, as the pipeline takes them: ingest's
    checks on ``block`` shots, the lens on them (calls of ``lens_batch`` at most, as the
    pipeline's lens stage takes them; 0: one call), the push of their lines into the run's
    correlator built with that head block (with the line timing), then their strip cut, its
    latency recorded and its message sent (a publisher with no subscriber).  The correlator is
    first filled with an aperture of zeros, so each push releases its block's lines.  Each
    figure: the median over PATH_ROUNDS rounds of its mean a block, a round spanning the
    correlator's largest block (its tail's, whose work falls on one push in many and is
    waited for there), at least PATH_LEAST_CALLS blocks or PATH_LEAST_LINES lines.  Timed in
    turn, not each part back to back: the parts evict each other's data from the caches in
    the pipeline, and the sum is what one core spends a block (issue 38: back to back,
    psaltis-jpl's parts summed to 264-424 µs a pulse against 600-760 µs in turn).  At
    ``rate_hz``, a block whose warm calls already take HOPELESS_SHARE of the stream's time
    (the fastest of them) is timed on those calls alone: no round would bring it under 1
    (RADARSAT-1's fft blocks of 5 and 14 lines: 3.5 s of rounds)."""
    p = config.processor
    n, samples = p.aperture_pulses, plan.samples_per_shot
    ccd = make_ccd(block_config(config, block), plan.range_m, None)
    ingest = Ingest(samples, n, n, noise(1, 1).dtype)
    timing = LineTiming(n, 4 * (n + 2 * p.micro_batch))
    info = StreamInfo("granularity", config, "calibration", "lens", plan.range_m, 0.0, 0.0)
    strips, latency = StripAssembler(info), LatencyStats()
    publisher = ZmqPublisher(probe_endpoint(), "drop", linger_ms=0)  # no subscriber
    shots = noise(block, samples)
    clock = time.perf_counter
    try:
        fill = -(-(n - 1) // block) * block  # the aperture, to a whole number of blocks
        zeros = np.zeros((fill, samples), shots.dtype)
        filled = ingest(ShotBatch(np.arange(fill), np.zeros(fill), np.zeros(fill), zeros))
        emitted = 0  # lines out so far (the engine's numbering)
        for pulses in filled:
            timing.record(pulses)
            if hasattr(ccd, "skip_zeros"):  # fft: the same state without the transforms
                emitted += ccd.skip_zeros(len(pulses))
                continue
            emitted += len(ccd.push(np.zeros((len(pulses), len(plan.range_m)), shots.dtype)))
        largest = max([block, *(b for _, _, b in getattr(ccd, "segments", ()))])
        least = min(PATH_LEAST_CALLS, -(-PATH_LEAST_LINES // block))
        per_round = max(least, -(-largest // block))
        warm = max(2, min(PATH_WARM_CALLS, least))  # the first: the correlator's first transform
        spent = []
        for k in range(warm + PATH_ROUNDS * per_round):
            seq = fill + k * block + np.arange(block)
            t0 = clock()
            pulses = ingest(ShotBatch(seq, seq * 1e-3, np.full(block, t0), shots))[0]
            t1 = clock()
            step = lens_batch or block
            lines = np.concatenate(
                [lens.compress(pulses.samples[j : j + step]) for j in range(0, block, step)]
            )
            t2 = clock()
            timing.record(pulses)
            got = ccd.push(lines)
            out = timing.lines(emitted, got)
            emitted += len(got)
            t3 = clock()
            if out is not None:
                strips.add(out, t3)
                strip, last_s = strips.take(strips.held, dict(ingest.counters))
                publisher.strip(strip, info)
                latency.add(clock() - last_s)
            spent.append((t1 - t0, t2 - t1, t3 - t2, clock() - t3))
            fastest_s = min(map(sum, spent)) if k + 1 == warm else 0.0  # of the warm calls
            if rate_hz * fastest_s / block >= HOPELESS_SHARE:
                return tuple(float(x) for x in np.median(spent, axis=0))
        rounds = np.reshape(spent[warm:], (PATH_ROUNDS, per_round, 4)).mean(axis=1)
        ingest_s, lens_s, push_s, strip_s = np.median(rounds, axis=0)
        return float(ingest_s), float(lens_s), float(push_s), float(strip_s)
    finally:
        publisher.close()
        if hasattr(ccd, "close"):
            ccd.close()


def ingest_cost_s(config: Config, shots: np.ndarray) -> float:
    """Seconds of ingest's checks on a call of ``shots`` (a batch continuing the stream)."""
    p = config.processor
    ingest = Ingest(shots.shape[1], p.aperture_pulses, p.aperture_pulses, shots.dtype)
    b, k = len(shots), [0]

    def one() -> None:
        seq = k[0] + np.arange(b)
        ingest(ShotBatch(seq, seq * 1e-3, np.zeros(b), shots))
        k[0] += b

    return per_call_s(one)


def push_s(config: Config, range_m, physical, block: int, noise) -> float:
    """Seconds to push one block of ``block`` lines into the run's correlator built with that
    head block (after a few pushes that fill its buffers)."""
    ccd = make_ccd(block_config(config, block, physical), range_m, physical)
    lines = noise(block, len(range_m))
    try:
        for _ in range(4):
            ccd.push(lines)
        return per_call_s(lambda: ccd.push(lines))
    finally:
        if hasattr(ccd, "close"):
            ccd.close()


def survey_and_compile(settings, config, physical, source, say, request=None) -> None:
    """Where the simulator's kernels compile in a process of their own (``source.warming``),
    the correlator's compile here meanwhile (warm_correlator: the one ``request``, a
    GranularityRequest, will run, GranularityRequest.live_config); then the OpenCL survey
    (rtsar.lens.base.survey_devices_first), timed alone: where it must probe, the simulator's
    process is waited for first (``source.wait_warm``).  (Run beside a compile,
    the survey's cached rates fell by a third to a half and two devices swapped places, and a
    Ctrl-C reached its probes from a thread that then cached them as failed: a cold review.)"""
    compile_here = not settings.swath_workers
    probing = False  # no OpenCL touched where the lens will not survey (--lens numpy, --device)
    if survey_wanted(settings.lens_backend, settings.device):
        try:
            probing = not cl_devices.survey_is_known()
        except RuntimeError:  # no OpenCL platform: make_lens says so
            pass
    if compile_here and getattr(source, "warming", False):
        live = request.live_config(config, physical)[0] if request else config
        warm_correlator(live, physical)  # beside the simulator's process, before any timing
    if probing and hasattr(source, "wait_warm"):
        source.wait_warm(say)
    survey_devices_first(settings.lens_backend, settings.device, say)


def warm_correlator(config: Config, physical=None) -> None:
    """Compile (or load) the run's correlator kernels now: push_s on its smallest candidate
    block of zeros.  rtsar.app.live calls it while the simulator's kernels compile in their
    own process (rtsar.sources.sim ``warm_from``), before the work is timed."""
    blocks, _ = block_candidates(config.processor, physical)
    dtype = np.complex128 if config.processor.precision == "complex128" else np.complex64
    push_s(
        config, make_plan(config).range_m, physical, blocks[0], lambda r, c: np.zeros((r, c), dtype)
    )


def strip_cost_s(config: Config, range_m) -> float:
    """Seconds to cut a one-line strip, record its latency and encode its message (the
    publisher's header: rtsar.sinks.wire)."""
    info = StreamInfo("granularity", config, "calibration", "lens", range_m, 0.0, 0.0)
    strips, latency = StripAssembler(info), LatencyStats()
    line = np.zeros((1, len(range_m)), np.complex64)
    counters = dict.fromkeys(("pulses_received", "pulses_processed", "lines_out"), 0)
    k = [0]

    def one() -> None:
        strips.add(LineBlock(k[0], line, np.zeros(1), np.zeros(1), np.zeros(1, bool)))
        strip, last = strips.take(1, dict(counters))
        json.dumps(strip_header(strip, info)).encode()
        latency.add(time.perf_counter() - last)
        k[0] += 1

    return per_call_s(one)
