"""Every OpenCL device that builds the lens, side by side: the lens alone and the live pipeline.

Not a test.  One run measures, on this machine, for each device of ``rtsar devices`` that
builds the lens and for the NumPy lens:

* the lens alone at batches 16, 64 and 256 (:func:`rtsar.lens.cl_devices.measure`: each device
  probed in its own process, then all timed together, interleaved, best of 3 rounds);
* the live pipeline at a preset (psaltis-max by default) with one correlator (nonuniform):
  at max rate (real-time factor) and paced at the PRF as an instrument (dropped pulses, line
  latency median and p99), the lenses interleaved in rounds so a shared machine's swings
  fall on all of them alike; each figure the median over the rounds.

    python tools/device_compare.py [--preset psaltis-max] [--correlator nonuniform]
                                   [--rounds 2] [--seconds 4] [--real-seconds 8] [--json F]
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from ...lens import cl_devices
from ...presets import PRESETS, preset
from ...stream.pipeline import PipelineSettings
from ..bench_pipeline import bench_shots, stream_run


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="device_compare", description=__doc__.split("\n\n")[0])
    p.add_argument("--preset", default="psaltis-max", choices=sorted(PRESETS))
    p.add_argument("--correlator", default="nonuniform")
    p.add_argument("--rounds", type=int, default=2)
    p.add_argument("--seconds", type=float, default=4.0, help="each max-rate run")
    p.add_argument("--real-seconds", type=float, default=8.0, help="each real-rate run")
    p.add_argument("--json", metavar="F")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    cfg = preset(args.preset).with_processor(correlator=args.correlator)
    batches = [16, 64, 256]
    print(f"lens alone, {args.preset}: every device probed and timed (pulses/s) …", flush=True)
    reports, numpy_rates = cl_devices.measure(args.preset, batches, 0.6)
    lenses = [(f"[{r.index}] {r.short_label}", "opencl", str(r.index), r.rates) for r in reports
              if r.reason is None]  # fmt: skip
    lenses.append(("NumPy lens", "numpy", None, numpy_rates))
    for r in reports:
        if r.reason is not None:
            print(f"  refused: [{r.index}] {r.short_label}: {r.reason}")
    shots = bench_shots(cfg, 2048)
    runs = {label: [] for label, *_ in lenses}
    for _label, backend, device, _ in lenses:  # warm-up: builds, numba, FFT plans
        stream_run(cfg, shots, 0.5, "max", PipelineSettings(lens_backend=backend, device=device))
    for k in range(args.rounds):
        print(f"round {k + 1} of {args.rounds}", flush=True)
        for label, backend, device, _ in lenses:
            settings = PipelineSettings(lens_backend=backend, device=device)
            top = stream_run(cfg, shots, args.seconds, "max", settings)
            real = stream_run(cfg, shots, args.real_seconds, "real", settings)
            runs[label].append((top, real))
            print(
                f"  {label[:60]:60} max rate: capacity {top['real_time_factor']:5.2f}x real time; "
                f"paced at the PRF: dropped {real['dropped_pulses']} of {real['offered_pulses']}, "
                f"latency median {real['latency_median_ms']:.2f} ms, "
                f"p99 {real['latency_p99_ms']:.2f} ms",
                flush=True,
            )
    rows = []
    for label, _, _, rates in lenses:
        tops, reals = zip(*runs[label], strict=True)
        rows.append(
            {
                "lens": label,
                "lens_pulses_per_s": {str(b): rates.get(str(b)) for b in batches},
                "max_rate_rt": float(np.median([t["real_time_factor"] for t in tops])),
                "real_dropped": int(max(r["dropped_pulses"] for r in reals)),
                "real_latency_median_ms": float(np.median([r["latency_median_ms"] for r in reals])),
                "real_latency_p99_ms": float(np.median([r["latency_p99_ms"] for r in reals])),
            }
        )
    print(
        f"\n| lens | alone, batch 16 / 64 / 256 (pulses/s) | {args.preset} {args.correlator}: "
        "max rate | real rate: dropped | latency median / p99 |\n|---|---|---|---|---|"
    )
    for r in rows:
        alone = " / ".join(f"{(r['lens_pulses_per_s'][str(b)] or 0):,.0f}" for b in batches)
        print(
            f"| {r['lens']} | {alone} | {r['max_rate_rt']:.2f}× | {r['real_dropped']} | "
            f"{r['real_latency_median_ms']:.2f} / {r['real_latency_p99_ms']:.2f} ms |"
        )
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump({"preset": args.preset, "correlator": args.correlator, "rows": rows}, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
