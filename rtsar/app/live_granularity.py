"""A live run's granularity, chosen at its start: the engine's work timed here on synthetic
shots, then the rule of rtsar.stream.granularity (issue 38).

Timed, each figure the median of 3 rounds of calls made back to back (at least 3 calls or
10 ms a round): the run's own lens (the backend ``--lens`` picks, at the configuration's
batch) at 1, 2, 4, … pulses a call, up to the first that keeps up with the rate; the run's
correlator built with each candidate block, smallest first, up to the first whose work stays
under the target; one strip's cut and message header.  With ``--height`` each receiver adds a
lens and a correlator, so their figures count once a channel.  About 0.1-0.5 s where a small
block fits (most of it building the correlator); more where none does.  What the command line
fixed (``--partition-lines``, ``--strip-lines`` / ``--strip-ms``, ``--max-batch``) stays.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace

import numpy as np

from ..analysis.timing import rate_per_s
from ..ccd import make_ccd
from ..lens import cl_devices, make_lens, make_plan
from ..lens.base import survey_devices_first, survey_wanted
from ..lens.plan import next_pow2
from ..params import Config, Processor
from ..sinks.wire import strip_header
from ..stream.granularity import (
    TARGET_UTILISATION,
    Granularity,
    StageCosts,
    auto_strip_lines,
    choose_granularity,
    granularity_words,
    utilisation,
)
from ..stream.settings import PipelineSettings
from ..stream.stats import LatencyStats
from ..stream.strips import LineBlock, StreamInfo, StripAssembler

ROUND_S = 0.01  # each of a figure's 3 rounds
BLOCKED_KINDS = ("partitioned", "nonuniform")  # their block is the head block L


@dataclass(frozen=True)
class GranularityRequest:
    """What to choose for a live run at ``rate_hz`` pulses/s: None for what the command line
    left to the choice."""

    rate_hz: float
    block_lines: int | None = None  # --partition-lines
    strip_lines: int | None = None  # --strip-lines, --strip-ms

    def apply(
        self,
        config: Config,
        settings: PipelineSettings,
        physical=None,
        height=None,
        say=None,
        source_s: float = 0.0,
    ):
        """(config, settings, Granularity, the banner's line) with the chosen granularity;
        ``say`` (a message) is told when the measuring starts; ``source_s``: the source's own
        work a pulse in this process (StageCosts)."""
        if say is not None:
            say(f"measuring the work at {self.rate_hz:,.0f} pulses/s to choose the granularity …")
        copies = 1 + (len(height.channels) if height is not None else 0)
        lens_batch = settings.max_batch or config.processor.micro_batch
        blocks, fixed = block_candidates(config.processor, physical, self.block_lines)
        costs = measure_costs(
            config, settings, self.rate_hz, blocks, copies, physical, self, source_s
        )
        g = choose_granularity(self.rate_hz, costs, lens_batch, self.strip_lines, fixed_block=fixed)
        words = granularity_words(g, costs)
        return chosen_config(config, g), chosen_settings(settings, g), g, words


def request_of(args, rate_hz: float | None) -> GranularityRequest | None:
    """The request of a run/replay command line (None: a replay as fast as it goes, no rate to
    choose for; swath workers, which correlate in their own processes: as configured)."""
    if rate_hz is None or getattr(args, "swath_workers", 0):
        return None
    return GranularityRequest(rate_hz, args.partition_lines, args.strip_lines)


def block_candidates(p: Processor, physical=None, given: int | None = None) -> tuple[list, str]:
    """(the blocks to choose among, why there is one only or ""): the partitioned and the
    nonuniform correlators' head block L, 1, 2, 4, … up to the configuration's partition_lines
    (16 in the presets; ``given``: --partition-lines); the fft correlator's M - N + 1; the
    direct and physical CCDs release a line a pulse, so their block is the strip's: 1 … 16."""
    if physical is None and p.correlator == "fft":
        n = p.aperture_pulses
        return [(p.fft_length or next_pow2(2 * n)) - n + 1], "the fft correlator's M - N + 1"
    if physical is None and p.correlator in BLOCKED_KINDS and given:
        return [given], "--partition-lines"
    largest = min(p.partition_lines, p.aperture_pulses) if p.correlator in BLOCKED_KINDS else 16
    return [1 << k for k in range(largest.bit_length()) if 1 << k <= largest], ""


def chosen_config(config: Config, g: Granularity) -> Config:
    """The configuration with the chosen head block (the correlators that have one)."""
    if config.processor.correlator not in BLOCKED_KINDS:
        return config
    return config.with_processor(partition_lines=g.block_lines)


def chosen_settings(settings: PipelineSettings, g: Granularity) -> PipelineSettings:
    return replace(
        settings,
        strip_lines=g.strip_lines,
        strip_most_lines=g.strip_most_lines,
        strip_deadline_s=g.strip_deadline_s,
    )


def per_call_s(call) -> float:
    """Seconds a call, calls made back to back: the median of 3 rounds (analysis.timing)."""
    return float(np.median([1.0 / rate_per_s(call, 1, ROUND_S) for _ in range(3)]))


def measure_costs(
    config, settings, rate_hz, blocks, copies=1, physical=None, request=None, source_s=0.0
):
    """StageCosts of the run (module docstring), each call's figure times ``copies``; the
    blocks measured smallest first, up to the first within TARGET_UTILISATION."""
    p = config.processor
    plan = make_plan(config)
    dtype = np.complex128 if p.precision == "complex128" else np.complex64
    rng = np.random.default_rng(0)

    def noise(rows: int, cols: int) -> np.ndarray:
        return (rng.standard_normal((rows, cols)) + 1j * rng.standard_normal((rows, cols))).astype(
            dtype
        )

    lens = make_lens(plan, settings.lens_backend, settings.device, p.precision, p.micro_batch)
    lens_s: dict[int, float] = {}
    b = 1
    while b <= (settings.max_batch or p.micro_batch):
        shots = noise(b, plan.samples_per_shot)
        lens_s[b] = copies * per_call_s(lambda s=shots: lens.compress(s))
        if lens_s[b] <= b / rate_hz:
            break
        b *= 2
    strip_s = strip_cost_s(config, plan.range_m)
    block_s: dict[int, float] = {}
    fixed_strips = request.strip_lines if request is not None else None
    for block in blocks:
        block_s[block] = copies * push_s(config, plan.range_m, physical, block, noise)
        costs = StageCosts(lens_s, dict(block_s), strip_s, source_s)
        strips = fixed_strips or auto_strip_lines(block)
        if utilisation(rate_hz, costs, block, strips) <= TARGET_UTILISATION:
            break
    return StageCosts(lens_s, block_s, strip_s, source_s)


def push_s(config: Config, range_m, physical, block: int, noise) -> float:
    """Seconds to push one block of ``block`` lines into the run's correlator built with that
    head block (after a few pushes that fill its buffers)."""
    cfg = config
    if config.processor.correlator in BLOCKED_KINDS and physical is None:
        cfg = config.with_processor(partition_lines=block)
    ccd = make_ccd(cfg, range_m, physical)
    lines = noise(block, len(range_m))
    try:
        for _ in range(4):
            ccd.push(lines)
        return per_call_s(lambda: ccd.push(lines))
    finally:
        if hasattr(ccd, "close"):
            ccd.close()


def survey_and_compile(settings, config, physical, source, say) -> None:
    """Where the simulator's kernels compile in a process of their own (``source.warming``),
    the correlator's compile here meanwhile (warm_correlator); then the OpenCL survey
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
        warm_correlator(config, physical)  # beside the simulator's process, before any timing
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
