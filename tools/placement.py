"""Where the stages run: threads, worker processes, thread counts and CPU affinity (not a test).

Each variant runs in a fresh Python process (thread-count variables are read when PoCL and
numba start) and measures the live pipeline at the preset, as ``rtsar bench`` does: the max rate
(replay as fast as it takes shots) and the real rate (dropped pulses, latency median and p99),
for the partitioned and the nonuniform correlators.  All variants are measured in this one run,
so their ratios are comparable; absolute figures move with the machine's load.

    python tools/placement.py [--preset psaltis-max] [--real-seconds 10] [--json F]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

VARIANTS = [
    ("threads (default)", {}, {}),
    ("threads, PoCL 1 compute unit", {"POCL_CPU_MAX_CU_COUNT": "1"}, {}),
    ("threads, numba 1 thread", {"NUMBA_NUM_THREADS": "1"}, {}),
    ("threads, pinned to one core", {}, {"affinity": [0]}),
    ("2 swath processes", {}, {"swath_workers": 2}),
    (
        "2 swath processes, numba 1 thread, PoCL 1 CU",
        {"NUMBA_NUM_THREADS": "1", "POCL_CPU_MAX_CU_COUNT": "1"},
        {"swath_workers": 2},
    ),
]

CHILD = r"""
import json, os, sys
opts = json.loads(sys.argv[1])
if opts.get("affinity"):
    os.sched_setaffinity(0, opts["affinity"])
from rtsar.app.bench_pipeline import bench_shots, stream_run
from rtsar.presets import preset
from rtsar.stream.pipeline import PipelineSettings
cfg = preset(opts["preset"])
shots = bench_shots(cfg, 2048)
rows = []
stream_run(cfg.with_processor(correlator="partitioned"), shots, 0.5, "max", PipelineSettings())
for kind in ("partitioned", "nonuniform"):
    c = cfg.with_processor(correlator=kind)
    s = PipelineSettings(swath_workers=opts.get("swath_workers", 0))
    top = stream_run(c, shots, 3.0, "max", s)
    real = stream_run(c, shots, opts["real_seconds"], "real", s)
    rows.append({
        "correlator": kind,
        "max_rate_x": top["real_time_factor"],
        "real_dropped": real["dropped_pulses"],
        "real_latency_median_ms": real["latency_median_ms"],
        "real_latency_p99_ms": real["latency_p99_ms"],
    })
print(json.dumps(rows))
"""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="psaltis-max", help="preset (default psaltis-max)")
    ap.add_argument(
        "--real-seconds", type=float, default=10.0, help="real-rate run length (default 10 s)"
    )
    ap.add_argument("--json", help="also write the rows here")
    args = ap.parse_args(argv)
    results = []
    print(
        f"{'placement':46} {'correlator':12} {'max rate':>9} {'dropped':>8} "
        f"{'median ms':>10} {'p99 ms':>8}",
        flush=True,
    )
    for label, env, opts in VARIANTS:
        opts = {**opts, "preset": args.preset, "real_seconds": args.real_seconds}
        out = subprocess.run(
            [sys.executable, "-c", CHILD, json.dumps(opts)],
            env={**os.environ, **env},
            capture_output=True,
            text=True,
        )
        if out.returncode != 0:
            print(f"{label:46} failed: {out.stderr.strip().splitlines()[-1:]}", flush=True)
            continue
        for row in json.loads(out.stdout.strip().splitlines()[-1]):
            row["placement"] = label
            results.append(row)
            print(
                f"{label:46} {row['correlator']:12} {row['max_rate_x']:8.2f}x "
                f"{row['real_dropped']:8d} {row['real_latency_median_ms']:10.2f} "
                f"{row['real_latency_p99_ms']:8.2f}",
                flush=True,
            )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
