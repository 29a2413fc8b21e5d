"""Streaming benchmark (``rtsar bench``): the whole pipeline, end to end, in one run.

Not a test.  For a preset it measures, on the same simulated shots held in memory:

* capacity: the pipeline fed as fast as it takes shots (replay ``max``), pulses/s ÷ PRF;
* paced at the PRF, the source behaving as an instrument (dropped when the pipeline is full):
  the shots kept of those offered, the drops, the latency from the arrival of the last pulse
  of a line to the publication of its strip (median, p99), and the achieved PRF of the source;
* capacity against the micro-batch cap;
* a plain NumPy batch range-Doppler processor (FFT matched filter in range, FFT fast convolution
  in azimuth over the whole block) on the same shots, as a ratio;
* the CCD stage's rate inside the pipeline (its busy time) as a fraction of the same correlator
  alone (CorrelatorAlone: one measurement, shared with the bench's correlator table);
* placement: lens and CCD in two worker processes, a range half each (``--swath-workers 2``),
  at max rate and paced, for the partitioned and the nonuniform correlators;
* latency against the offered rate, 25-150 % of the PRF, the granularity a live run chooses
  at each (rtsar.app.bench_latency).

Strips go to a ZeroMQ publisher on a loopback port with no subscriber (publication is part of
the measured path), or, with ``stalled_subscriber``, with a subscriber that never reads.  They
are cut as a live run cuts them (rtsar.stream.granularity): 16 lines, and the lines that wait
go out together, up to MOST_STRIP_LINES.  (Strips of exactly 16 took the strip stage a
message per 16 lines however far behind it was: psaltis-max's nonuniform pipeline at max rate
gave 9.0-9.8k pulses/s against 10.4-11.3k, three interleaved pairs.)
"""

from __future__ import annotations

import time

import numpy as np
import zmq

from ..ccd.base import design_mask
from ..lens.plan import make_plan
from ..params import Config
from ..scene import Simulator, point_scene
from ..sinks.publish import ZmqPublisher
from ..sources.replay import ReplaySource, parse_rate
from ..stream.granularity import MOST_STRIP_LINES, live_correlator, migration_domain_for
from ..stream.pipeline import Pipeline, PipelineSettings
from . import bench_alone
from .bench_alone import ABOVE_ONE, CorrelatorAlone, LensAlone, against_ideal
from .bench_latency import latency_against_rate


class Cyclic:
    """A block of shots repeated to any length (pulse p reads shot p mod len)."""

    def __init__(self, shots: np.ndarray, total: int):
        self.shots, self.total = shots, int(total)

    def __len__(self) -> int:
        return self.total

    def __getitem__(self, sl: slice) -> np.ndarray:
        start, stop, _ = sl.indices(self.total)
        n = len(self.shots)
        a, b = start % n, start % n + (stop - start)
        if b <= n:
            return self.shots[a:b]
        return self.shots[np.arange(start, stop) % n]


def pipeline_kinds(cfg) -> tuple[tuple[str, ...], str]:
    """(correlators the pipeline runs compare, the one the other runs use).  A plan whose
    range-migration taps read in the azimuth spectrum (``range_migration_domain = "doppler"``:
    the radarsat1 preset) runs on the "fft" correlator and on "nonuniform" with the walk's ring
    (a live run's, rtsar.stream.granularity.live_correlator), fft the base; elsewhere
    partitioned, nonuniform and fft, with partitioned the base."""
    p = cfg.processor
    if p.range_migration_taps and p.range_migration_domain == "doppler":
        return ("fft", "nonuniform"), "fft"
    return ("partitioned", "nonuniform", "fft"), "partitioned"


def with_correlator(cfg, kind: str):
    """``cfg`` with the correlator ``kind`` and the range-migration domain that kind reads in
    (rtsar.stream.granularity.migration_domain_for: the Doppler-domain read is fft's, the
    walk's ring nonuniform's where the beam is squinted, the time domain another kind's)."""
    domain = migration_domain_for(cfg, kind)
    return cfg.with_processor(correlator=kind, range_migration_domain=domain)


def bench_shots(cfg: Config, pulses: int = 4096, seed: int = 0) -> np.ndarray:
    """Shots of a few point targets spread over the swath (what the pipeline sees in a scan)."""
    plan = make_plan(cfg)
    rm = plan.range_m
    rng = np.random.default_rng(seed)
    ranges = rng.uniform(rm[len(rm) // 8], rm[-len(rm) // 8], 6)
    d = cfg.geometry.along_track_step_m
    along = rng.uniform(0, pulses * d, 6)
    scene = point_scene(cfg, along, ranges, pulses=pulses, start_along_track_m=0.0)
    return Simulator(scene).block(pulses)


def _source(cfg, shots, total, rate, batch, live):
    seq = np.arange(total)
    prf = cfg.geometry.prf_hz
    return ReplaySource(Cyclic(shots, total), seq, seq / prf, prf, rate, batch, "bench", live)


def stream_run(
    cfg: Config,
    shots: np.ndarray,
    seconds: float,
    rate: str,
    settings: PipelineSettings,
    endpoint_ctx=None,
    stalled_subscriber: bool = False,
) -> dict:
    """One pipeline run on ``shots`` (repeated) for about ``seconds`` of source time; ``rate``
    "max", "real" or a factor of the PRF (paced)."""
    prf = cfg.geometry.prf_hz
    live = rate != "max"
    factor = parse_rate(rate) or 1.0
    total = int(seconds * prf * factor) if live else int(seconds * prf * 3)
    batch = settings.max_batch or cfg.processor.micro_batch
    src = _source(cfg, shots, total, rate, batch, live)
    pub = ZmqPublisher("tcp://127.0.0.1:*", "drop", context=endpoint_ctx)
    sub = None
    if stalled_subscriber:
        sub = zmq.Context.instance().socket(zmq.SUB)
        sub.setsockopt(zmq.SUBSCRIBE, b"")
        sub.connect(pub.endpoint)
        pub.wait_for_subscribers(1, timeout_s=10)
    pipe = Pipeline(cfg, src, [pub], settings)
    if not live:  # bound the run by time, not by pulses
        timer = _stop_after(src, seconds)
    t0 = time.perf_counter()
    stats = pipe.run()
    wall = time.perf_counter() - t0
    if not live:
        timer.cancel()
    pub.close()
    if sub is not None:
        sub.close(0)
    d = stats.as_dict()
    c = d["counters"]
    done = c["pulses_processed"]
    out = {
        "rate": rate,
        "stages": settings.stages,
        "correlator": cfg.processor.correlator,
        "max_batch": pipe.max_batch,  # what its stages took at most (at "max": 4 batches)
        "strip_lines": settings.strip_lines,
        "pulses": done,
        "wall_s": wall,
        "pulses_per_s": done / wall,
        "real_time_factor": done / wall / prf,  # capacity, at max rate only (below)
        "dropped_pulses": c["dropped_pulses"],
        "gap_pulses": c["gap_pulses"],
        "latency_median_ms": d["latency_median_ms"],
        "latency_p99_ms": d["latency_p99_ms"],
        "latency_max_ms": d["latency_max_ms"],
        "stage_busy_s": d["stage_busy_s"],
        "strips": c["strips_published"],
        "correlator_growths": c.get("correlator_growths", 0),  # rtsar.stream.growth
        "correlator_shrinks": c.get("correlator_shrinks", 0),
        "correlator_block_lines": c.get("correlator_block_lines"),
    }
    if live:  # paced: what the instrument-like source offered, and how much of it was kept
        out.update(paced_figures(total, done, c["gap_pulses"]))
        out["achieved_prf_hz"] = src.achieved_rate_hz()
        out["prf_error"] = out["achieved_prf_hz"] / (prf * factor) - 1
        del out["real_time_factor"]  # the source sets the rate: not a measure of capacity
    ccd_busy = d["stage_busy_s"].get("ccd")
    if ccd_busy:
        out["ccd_stage_pulses_per_s"] = done / ccd_busy
    return out


def paced_figures(offered: int, processed: int, gap_filled: int) -> dict:
    """A paced run's shots: offered by the source, kept (processed, less the zero pulses that
    stood in for dropped ones), and the kept fraction."""
    kept = processed - gap_filled
    return {
        "offered_pulses": offered,
        "kept_pulses": kept,
        "kept_fraction": kept / offered if offered else 0.0,
    }


def _stop_after(source, seconds: float):
    import threading

    t = threading.Timer(seconds, source.close)
    t.daemon = True
    t.start()
    return t


def numpy_range_doppler(cfg: Config, shots: np.ndarray) -> np.ndarray:
    """Plain NumPy batch processor: range matched filter by FFT, then azimuth fast convolution
    with the same per-range-bin mask over the whole block (range-Doppler, no migration
    correction).  complex64 FFTs; image[line, range_bin] for lines with a full aperture."""
    plan = make_plan(cfg)
    nfft = plan.nfft

    def dft(a, sign):  # unnormalised, like the plan's transforms
        return np.fft.fft(a, nfft, axis=1) if sign < 0 else np.fft.ifft(a, nfft, axis=1) * nfft

    x = dft(np.asarray(shots, np.complex64) * plan.pre.astype(np.complex64), plan.sign1)
    if plan.two_pass:
        x = dft(x * plan.spectrum.astype(np.complex64), plan.sign2)
    bins = (plan.bin_start + np.arange(plan.bin_count)) % nfft
    lines = (x[:, bins] * plan.post.astype(np.complex64)).astype(np.complex64)
    mask = design_mask(cfg, plan.range_m).astype(np.complex64)
    n, p = mask.shape[0], len(lines)
    m = 1 << int(np.ceil(np.log2(p + n - 1)))
    a = np.fft.fft(lines, m, axis=0)
    a *= np.fft.fft(mask[::-1], m, axis=0)
    return np.fft.ifft(a, axis=0)[n - 1 : p].astype(np.complex64)


def bench_numpy_range_doppler(cfg: Config, shots: np.ndarray, repeats: int = 2) -> float:
    """Best pulses/s of :func:`numpy_range_doppler` on ``shots``."""
    best = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        numpy_range_doppler(cfg, shots)
        best = max(best, len(shots) / (time.perf_counter() - t0))
    return best


__all__ = [
    "Cyclic",
    "bench_numpy_range_doppler",
    "bench_shots",
    "CorrelatorAlone",
    "LensAlone",
    "numpy_range_doppler",
    "paced_figures",
    "stream_run",
    "summarize_runs",
]


def bench_pipeline(
    name: str,
    cfg: Config,
    seconds: float,
    real_seconds: float,
    log=print,
    repeats: int = 1,
    alone: CorrelatorAlone | None = None,
    lenses: LensAlone | None = None,
) -> dict:
    """The streaming figures of one preset, all measured in this call (see module docstring).

    ``repeats`` > 1: every run is made that many times, in rounds (each configuration once per
    round, always in the same order), so that a shared machine's slow swings fall on all of
    them alike; ``summary`` then gives each figure's median and range over the rounds.
    ``alone``, ``lenses``: the correlators' and lenses' rates alone, shared with the bench's
    correlator and lens tables, so a figure measured there is the same number here."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    alone = alone or CorrelatorAlone(min(seconds, 1.0))
    lenses = lenses or LensAlone(min(seconds, 1.0))
    shots = bench_shots(cfg, 2048)
    result = {"preset": name, "prf_hz": cfg.geometry.prf_hz, "repeats": repeats, "runs": []}
    kinds, base_kind = pipeline_kinds(cfg)
    part = with_correlator(cfg, base_kind)

    def run(label, c, rate, secs, round_, **kw):
        stalled = kw.pop("stalled_subscriber", False)
        kw.setdefault("strip_most_lines", MOST_STRIP_LINES)  # as a live run (docstring)
        r = stream_run(c, shots, secs, rate, PipelineSettings(**kw), stalled_subscriber=stalled)
        r["label"], r["round"] = label, round_
        result["runs"].append(r)
        log(f"  {label:42} {run_line(r)}")
        return r

    log(
        f"{name}: PRF {cfg.geometry.prf_hz:g} Hz, CCD {cfg.processor.aperture_pulses} x "
        f"{cfg.processor.range_bins}, {cfg.waveform.samples_per_shot} samples/shot"
        + (f"; {repeats} rounds of every run" if repeats > 1 else "")
    )
    # Warm-up (OpenCL build, numba cache, FFT plans), not recorded.
    stream_run(part, shots, 0.5, "max", PipelineSettings())
    take = PipelineSettings().take_cap(cfg.processor.micro_batch, paced=False)  # at max rate
    lens_alone = bench_alone.lens_alone(name, cfg, lenses, take)
    result["lens_alone"] = lens_alone
    log(
        f"  the pipeline's lens alone ({lens_alone['backend']}), batches of "
        f"{lens_alone['batch']}: {lens_alone['pulses_per_s']:,.0f} pulses/s "
        f"({lens_alone['source']})"
    )
    stalled_ratios = []
    for round_ in range(repeats):
        if repeats > 1:
            log(f"  round {round_ + 1} of {repeats}")
        for kind in kinds:
            c = with_correlator(cfg, kind)
            top = run(f"{kind}: max rate", c, "max", seconds, round_)
            iso = alone.rate(name, c, top["max_batch"])
            top["isolated_correlator_pulses_per_s"] = iso
            if "ccd_stage_pulses_per_s" in top:
                top["ccd_stage_over_isolated"] = top["ccd_stage_pulses_per_s"] / iso
            against_ideal(top, lens_alone, iso, log)  # under the run it is of
            run(f"{kind}: paced at the PRF ({real_seconds:g} s)", c, "real", real_seconds, round_)
            if kind != "fft":  # the one-thread layout, lens overlapped with the CCD
                over = run(f"{kind}: max rate, overlapped stages", c, "max", seconds, round_,
                           stages="overlapped")  # fmt: skip
                against_ideal(over, lens_alone, iso, log)
        run(f"{base_kind}: max rate, fused stages", part, "max", seconds, round_, stages="fused")
        # A stalled subscriber (connected, never reads) against no subscriber, back to back:
        # the same configuration as "{base_kind}: max rate", measured again beside its pair.
        log(f"  {base_kind} at max rate twice more, back to back: no subscriber, then one that")
        log("  never reads (their ratio below; the machine's swings fall on both alike)")
        none = run("subscriber check: none", part, "max", seconds, round_)
        stalled = run(
            "subscriber check: one that never reads",
            part,
            "max",
            seconds,
            round_,
            stalled_subscriber=True,
        )
        stalled_ratios.append(stalled["pulses_per_s"] / none["pulses_per_s"])
        for mb in (8, 16, 64):  # (64: a paced stream's; at "max" the stages take 256)
            label = f"{base_kind}: max rate, max batch {mb}"
            run(label, part, "max", seconds, round_, max_batch=mb)
        # Placement: lens + CCD in two worker processes, a range half each (rtsar.stream.swath;
        # not with range-migration taps, which read across the halves' edge).
        swath_kinds = [] if cfg.processor.range_migration_taps else kinds
        for kind in [k for k in swath_kinds if k != "fft"]:
            c = with_correlator(cfg, kind)
            run(f"{kind}: max rate, 2 swath processes", c, "max", seconds, round_, swath_workers=2)
            run(
                f"{kind}: paced, 2 swath processes",
                c,
                "real",
                real_seconds,
                round_,
                swath_workers=2,
            )
    # Latency against the offered rate, the correlator and granularity a live run chooses at
    # each (rtsar.app.bench_latency); its capacity: that correlator's at max rate.
    kind = live_correlator(cfg)[0].processor.correlator
    capacity = summarize_runs(result["runs"])[f"{kind}: max rate"]["real_time_factor"][0]
    result["latency_against_rate"] = latency_against_rate(
        cfg, shots, min(real_seconds, 5.0), capacity, log, stream_run
    )
    result["stalled_subscriber_over_none"] = float(np.median(stalled_ratios))
    rd = bench_numpy_range_doppler(cfg, np.concatenate([shots] * 2))
    result["numpy_range_doppler_pulses_per_s"] = rd
    result["pipeline_over_numpy_range_doppler"] = {
        r["label"]: r["pulses_per_s"] / rd for r in result["runs"] if r["rate"] == "max"
    }
    result["summary"] = summarize_runs(result["runs"])
    base = result["summary"][f"{base_kind}: max rate"]
    log(
        f"  plain NumPy batch range-Doppler (4096 pulses): {rd:,.0f} pulses/s = "
        f"{rd / cfg.geometry.prf_hz:.2f}x real time; '{base_kind}: max rate' / NumPy = "
        f"{base['pulses_per_s'][0] / rd:.2f}"
    )
    for label, f in result["summary"].items():
        if "ccd_stage_over_isolated" in f:
            kind = label.split(":")[0]
            batch = next(r["max_batch"] for r in result["runs"] if r["label"] == label)
            log(
                f"  {kind}: CCD stage in the '{label}' run (pulses over its busy time): "
                f"{_spread(f['ccd_stage_pulses_per_s'], ',.0f')} pulses/s = "
                f"{_spread(f['ccd_stage_over_isolated'], '.2f')} x ("
                + alone.label(name, with_correlator(cfg, kind), batch)
                + ")"
                + ABOVE_ONE * (f["ccd_stage_over_isolated"][0] > 1.05)
            )
    log(
        f"  throughput with a stalled subscriber / with none: "
        f"{result['stalled_subscriber_over_none']:.2f}"
    )
    if repeats > 1:
        log(f"  median [min–max] over {repeats} rounds:")
        for label, f in result["summary"].items():
            log(f"  {label:42} {summary_line(f)}")
    return result


def run_line(r: dict) -> str:
    """One run, labelled by what it measures: capacity at max rate; what was kept when paced."""
    latency = f"latency median {r['latency_median_ms']:8.2f} ms, p99 {r['latency_p99_ms']:8.2f} ms"
    if "kept_fraction" not in r:
        return f"capacity {r['real_time_factor']:6.2f}x real time  {latency}"
    kept = f"{100 * r['kept_fraction']:.1f} %"
    return (
        f"kept {r['kept_pulses']:,} of {r['offered_pulses']:,} shots ({kept}), "
        f"dropped {r['dropped_pulses']:,}  {latency}  PRF error {100 * r['prf_error']:+.3f} %"
    )


def summary_line(f: dict) -> str:
    """A label's figures over the rounds, median [min–max], named as in run_line."""
    latency = (
        f"latency median {_spread(f['latency_median_ms'], '.2f')} ms, p99 "
        f"{_spread(f['latency_p99_ms'], '.2f')} ms"
    )
    if "kept_fraction" not in f:
        return f"capacity {_spread(f['real_time_factor'], '.2f')}x real time  {latency}"
    return (
        f"kept {_spread(tuple(100 * v for v in f['kept_fraction']), '.1f')} %, dropped "
        f"{int(f['dropped_pulses'][2])} at most  {latency}"
    )


SUMMARIZED = (
    "real_time_factor",
    "kept_fraction",
    "pulses_per_s",
    "dropped_pulses",
    "latency_median_ms",
    "latency_p99_ms",
    "ccd_stage_pulses_per_s",
    "isolated_correlator_pulses_per_s",
    "ccd_stage_over_isolated",
    "over_two_core_ideal",
)


def summarize_runs(runs: list[dict]) -> dict:
    """label → figure → (median, min, max) over the runs of that label (its rounds); the
    figures of SUMMARIZED that the runs have."""
    by_label: dict[str, list[dict]] = {}
    for r in runs:
        by_label.setdefault(r["label"], []).append(r)
    out = {}
    for label, group in by_label.items():
        out[label] = {
            key: (float(np.median(v)), float(min(v)), float(max(v)))
            for key in SUMMARIZED
            if (v := [r[key] for r in group if key in r])
        }
    return out


def _spread(figure: tuple, fmt: str) -> str:
    """'median' (one round) or 'median [min–max]'."""
    median, low, high = figure
    if low == high:
        return f"{median:{fmt}}"
    return f"{median:{fmt}} [{low:{fmt}}–{high:{fmt}}]"
