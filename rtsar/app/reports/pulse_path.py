"""One pulse's path through the live pipeline's own stages, a lens call at a time in one
thread: what each part costs in the company of the others, against the granularity's figures.

    python tools/pulse_path.py [--preset psaltis-jpl] [--rate 1.0] [--pulses 2000]

A Pipeline is built as a live run at ``rate`` × the PRF builds it (the granularity it chooses,
rtsar.app.live_granularity), and the shots go through its ingest, lens, correlator and strip
publication in turn, as many a call as its lens takes while keeping up (a block's, where the
lens is aligned; else one), with the pipeline's own methods and its threads not started; the
mean of each part a pulse over ``pulses`` shots after the aperture fills, beside the share the
granularity's figures gave.  The granularity times a block's path the same way on synthetic
parts (its line timing and strip outside a Pipeline); before it did (issue 38), it timed each
part alone, back to back, and psaltis-jpl's parts summed to 264-424 µs a pulse against
600-760 µs here (2-core AMD EPYC Zen 3, blocks of 1).
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ...presets import PRESETS, preset
from ...sinks.publish import ZmqPublisher
from ...sources.base import ShotBatch
from ...stream.pipeline import Pipeline, PipelineSettings
from ..bench_pipeline import _source, bench_shots, with_correlator
from ..live_granularity import GranularityRequest

PARTS = ("ingest", "lens", "correlator", "strips")


def measure(preset_name: str, rate: float, pulses: int, lens: str, correlator: str) -> dict:
    """Mean seconds a pulse of each part (PARTS), their sum, and the granularity chosen."""
    cfg = with_correlator(preset(preset_name), correlator)
    prf = cfg.geometry.prf_hz
    shots = bench_shots(cfg, 2048)
    request = GranularityRequest(rate * prf, correlator=correlator)  # the one asked for
    chosen, settings, g, words = request.apply(cfg, PipelineSettings(lens_backend=lens))
    pub = ZmqPublisher("tcp://127.0.0.1:*", "drop")
    idle = _source(chosen, shots, len(shots), "max", 1, False)  # never iterated: fed below
    pipe = Pipeline(chosen, idle, [pub], settings)
    clock = time.perf_counter
    step = min(settings.lens_align, pipe.max_batch) or 1  # shots a lens call takes, keeping up
    warm = -(-(chosen.processor.aperture_pulses + 64) // step)
    calls = -(-pulses // step)
    spent = np.zeros((calls, len(PARTS)))
    try:
        for k in range(warm + calls):
            i = k * step + np.arange(step)
            batch = ShotBatch(i, i / prf, np.full(step, clock()), shots[i % len(shots)])
            t0 = clock()
            blocks = pipe._ingest([batch])
            t1 = clock()
            ranged = [b for b in map(pipe._range, blocks) if b is not None]
            t2 = clock()
            lines = pipe._ccd_step(ranged) if ranged else None
            t3 = clock()
            if lines is not None:
                pipe.strips.add(lines, clock())
            s = settings
            while count := pipe.strips.due(
                clock(), s.strip_lines, s.strip_most_lines, s.strip_deadline_s
            ):
                pipe._publish(count)
            t4 = clock()
            if k >= warm:
                spent[k - warm] = np.array((t1 - t0, t2 - t1, t3 - t2, t4 - t3)) / step
    finally:
        pipe.engine.correlator.close()
        pub.close()
    means = dict(zip(PARTS, spent.mean(axis=0), strict=True))
    return {
        "preset": preset_name,
        "rate_hz": rate * prf,
        "granularity": words,
        "block_lines": g.block_lines,
        "per_pulse_s": means,
        "total_s": float(spent.sum(axis=1).mean()),
        "period_s": 1.0 / (rate * prf),
        "model_utilisation": g.utilisation,
    }


def print_path(r: dict) -> None:
    us = 1e6
    print(f"{r['preset']} at {r['rate_hz']:,.0f} pulses/s: {r['granularity']}")
    for part, s in r["per_pulse_s"].items():
        print(f"  {part:11} {s * us:8.1f} µs a pulse")
    share = r["total_s"] / r["period_s"]
    print(
        f"  {'the path':11} {r['total_s'] * us:8.1f} µs a pulse: {share:.0%} of the pulse period "
        f"on one core, where the granularity's figures gave {r['model_utilisation']:.0%}"
    )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--preset", default="psaltis-jpl", choices=sorted(PRESETS))
    ap.add_argument(
        "--rate", type=float, default=1.0, help="the offered rate, × the PRF (default 1)"
    )
    ap.add_argument("--pulses", type=int, default=2000, help="pulses timed (default 2000)")
    ap.add_argument("--lens", default="auto", choices=("auto", "opencl", "numpy"))
    ap.add_argument("--correlator", default="nonuniform", help="(default nonuniform)")
    args = ap.parse_args(argv)
    if args.pulses < 1 or not args.rate > 0:
        print("pulse_path: --pulses must be >= 1 and --rate > 0", file=sys.stderr)
        return 2
    print_path(measure(args.preset, args.rate, args.pulses, args.lens, args.correlator))
    return 0
