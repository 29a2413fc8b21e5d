"""Two ways of running a live stream, alternated in one process: their line latencies (not a test).

A live run's latency on a shared 2-core machine swings by a third from one minute to the next,
more than most changes worth measuring.  Here a preset's shots are replayed from memory, paced
at a share of its PRF, with the granularity a live run chooses at that rate (chosen once), in
short runs that alternate between the run as it is ("new") and the run with the named change
taken back ("old"), in the order new-old, old-new, …: a swing of the machine falls on both
alike.  Each run's latencies (from a line's last pulse to its strip's publication) give a
median and a 99th percentile, the first tenth of its lines left out (its start); the rounds'
figures are printed side by side, then their means and how many rounds the new run's median
was the lower.

    python tools/ab_latency.py psaltis-jpl --rate 1.5 --lens hybrid --without route
    python tools/ab_latency.py psaltis-jpl --without slack
    python tools/ab_latency.py psaltis-max --rate 0.5 --block 8 --without growth
    python tools/ab_latency.py psaltis-max --rate 0.5 --block 8 --without shrink --load-s 3
    python tools/ab_latency.py psaltis-jpl --rounds 3 --seconds 5 --without correlator

``--without``: ``route`` (with ``--lens hybrid``: the lens's small calls on SciPy's FFT,
rtsar.lens.small_calls), ``slack`` (the replay's pacing thread's tight sleeps,
rtsar.sources.pacing), ``growth`` (the correlator's block doubled while the run falls behind,
rtsar.stream.growth; ``--block B`` starts both runs at blocks of B, as if the granularity had
chosen it, the new one free to grow to 64), ``shrink`` (a grown block shrunk back once the
run has room, rtsar.stream.growth's QuietWatch; both runs free to grow), ``correlator`` (a
live run's nonuniform correlator in place of the preset's fft, rtsar.stream.granularity's
live_correlator: the old run keeps fft, its block chosen by the same rule).  ``--load-s S``:
busy loops, each in a process of its own, take ``--load-cores`` cores (1) for the first S s
of each run, and the figures are those of the lines published from S + 2 s on (what a run
makes of its time once the load is gone: the quiet window and a swap take about that).  The
correlator is the nonuniform one (a live run's with the psaltis presets), but in ``--without
correlator``'s old run.
"""

from __future__ import annotations

import argparse
import dataclasses
import subprocess
import sys
import time

import numpy as np

from rtsar.app import bench_pipeline
from rtsar.app.live_granularity import GranularityRequest, block_candidates
from rtsar.presets import PRESETS, preset
from rtsar.sources import pacing
from rtsar.stream import growth, stats
from rtsar.stream.settings import PipelineSettings

SPIN = (
    "import sys, time\nend = time.time() + float(sys.argv[1])\nwhile time.time() < end:\n    pass\n"
)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("preset", choices=sorted(PRESETS))
    ap.add_argument("--rate", type=float, default=1.0, help="share of the PRF offered (1.0)")
    ap.add_argument("--rounds", type=int, default=8, help="pairs of runs (8)")
    ap.add_argument("--seconds", type=float, default=3.0, help="seconds of a run (3)")
    ap.add_argument(
        "--without", choices=("route", "slack", "growth", "shrink", "correlator"), default="slack"
    )
    ap.add_argument("--block", type=int, help="start at blocks of this many lines")
    ap.add_argument("--lens", default="auto", help="the lens backend (hybrid: the route runs)")
    ap.add_argument("--load-s", type=float, default=0.0, help="cores taken for this long first")
    ap.add_argument("--load-cores", type=int, default=1, help="how many (1)")
    args = ap.parse_args(argv)
    if args.without == "route" and args.lens != "hybrid":
        ap.error("--without route compares --lens hybrid with its route taken back")

    latencies: list[float] = []
    published: list[float] = []  # when each was recorded
    record, observe = stats.LatencyStats.add, growth.QuietWatch.observe

    def add(self, seconds):  # every line's latency, as the pipeline records it
        values = np.asarray(seconds, float).ravel().tolist()
        latencies.extend(values)
        published.extend([time.perf_counter()] * len(values))
        return record(self, seconds)

    stats.LatencyStats.add = add
    cfg = bench_pipeline.with_correlator(preset(args.preset), "nonuniform")
    shots = bench_pipeline.bench_shots(cfg, 2048)
    rate_hz = cfg.geometry.prf_hz * args.rate
    asked = PipelineSettings(lens_backend=args.lens)
    config, settings, _, words = GranularityRequest(rate_hz, args.block).apply(cfg, asked)
    if args.block:  # fixed: the granularity leaves it be; free to grow in the new run
        larger = [b for b in block_candidates(cfg.processor)[0] if b >= args.block]
        settings = dataclasses.replace(settings, grow_blocks=tuple(larger), grow_rate_hz=rate_hz)
    print(words)
    tight_sleeps = pacing.tight_sleeps
    old_config, old_settings = config, settings
    if args.without == "correlator":  # the preset's own fft, its block chosen by the same rule
        fft = GranularityRequest(rate_hz, args.block, correlator="fft")
        old_config, old_settings, _, old_words = fft.apply(preset(args.preset), asked)
        print(f"old: {old_words}")
    if args.without == "route":
        old_settings = dataclasses.replace(settings, lens_cpu_below=0)
    if args.without == "growth":
        old_settings = dataclasses.replace(settings, grow_blocks=())

    figures: dict[str, list[tuple[float, float, int]]] = {"new": [], "old": []}
    grew = {"new": "", "old": ""}
    for r in range(args.rounds):
        for which in ("new", "old") if r % 2 == 0 else ("old", "new"):
            takes_back_slack = which == "old" and args.without == "slack"
            pacing.tight_sleeps = (lambda *a: False) if takes_back_slack else tight_sleeps
            shrinks = which == "new" or args.without != "shrink"
            growth.QuietWatch.observe = observe if shrinks else (lambda *a: None)
            latencies.clear()
            published.clear()
            start = time.perf_counter()
            spin = [sys.executable, "-c", SPIN, str(args.load_s)]
            loads = [subprocess.Popen(spin) for _ in range(args.load_cores if args.load_s else 0)]
            run = bench_pipeline.stream_run(
                config if which == "new" else old_config, shots, args.seconds, args.rate,
                settings if which == "new" else old_settings,
            )  # fmt: skip
            for load in loads:
                load.wait()
            kept = np.array(latencies[len(latencies) // 10 :])
            if args.load_s:  # the lines published once the load had gone, 2 s on
                after = np.array(published) >= start + args.load_s + 2.0
                kept = np.array(latencies)[after]
            ms = kept * 1e3
            figures[which].append((np.median(ms), np.percentile(ms, 99), run["dropped_pulses"]))
            g, k = run["correlator_growths"], run["correlator_shrinks"]
            grew[which] = f" (grown {g}, shrunk {k}: {run['correlator_block_lines']})"
        new, old = figures["new"][-1], figures["old"][-1]
        print(f"round {r + 1}: median / p99 new {new[0]:.2f} / {new[1]:.2f} ms{grew['new']}, "
              f"old {old[0]:.2f} / {old[1]:.2f} ms{grew['old']}")  # fmt: skip
    pacing.tight_sleeps = tight_sleeps
    growth.QuietWatch.observe = observe
    for which in ("new", "old"):
        a = np.array(figures[which])
        print(f"{which}: mean median {a[:, 0].mean():.2f} ms, mean p99 {a[:, 1].mean():.2f} ms, "
              f"dropped {int(a[:, 2].sum())}")  # fmt: skip
    lower = sum(n[0] < o[0] for n, o in zip(figures["new"], figures["old"], strict=True))
    print(f"the new run's median was the lower in {lower} of {args.rounds} rounds")


if __name__ == "__main__":
    main()
