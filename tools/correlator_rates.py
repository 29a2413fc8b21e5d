"""The azimuth correlators alone, each in a fresh process, interleaved and repeated (not a test).

For each preset and repeat, every variant runs in its own Python process (a correlator's
buffers and numba's thread pool then meet no other correlator's), in turn, so that a change in
the machine's load touches all variants of a round alike: compare the ratios within a round.
Each variant is pushed batches of 64 lines and then one head block (L lines) per push: pulses/s
of both, and the median and 99th percentile of the one-block push time (what a push adds to a
line's latency).  The load average is printed before and after.

    python tools/correlator_rates.py [--presets psaltis-max,crouch-sal] [--repeats 3]
                                     [--seconds 1.5] [--json F]
    python tools/correlator_rates.py --spectra-precision   # what half-precision filters cost

``--spectra-precision`` measures instead the accuracy cost of storing the filter spectra in
float32 or float16 (the issue's "half precision for the filter"): the psaltis-max mask (64
range columns) applied to 2048 complex Gaussian lines by one FFT overlap-save block, only H
rounded, against the float64 reference.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

VARIANTS = ["fft", "partitioned", "nonuniform", "nonuniform-doubling"]

CHILD = r"""
import json, sys, time
import numpy as np
from rtsar.ccd import make_correlator
from rtsar.ccd.base import design_mask
from rtsar.ccd.nonuniform import NonUniformCorrelator
from rtsar.lens.plan import make_plan
from rtsar.presets import preset

opts = json.loads(sys.argv[1])
cfg = preset(opts["preset"])
p = cfg.processor
mask = design_mask(cfg, make_plan(cfg).range_m)
block = min(p.partition_lines, mask.shape[0])
if opts["variant"] == "nonuniform-doubling":
    corr = NonUniformCorrelator(mask, block, p.tail_block_lines, rule="doubling")
else:
    corr = make_correlator(opts["variant"], mask, p.fft_length, partition_lines=block,
                           tail_block_lines=p.tail_block_lines)
rng = np.random.default_rng(1)
shape = (64, mask.shape[1])
lines = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)


def rate(x):
    for _ in range(8):
        corr.push(x)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < opts["seconds"]:
        corr.push(x)
        n += len(x)
    return n / (time.perf_counter() - t0)


row = {"batch64_pulses_per_s": rate(lines)}
if opts["variant"] != "fft":
    one = lines[:block]
    row["one_block_pulses_per_s"] = rate(one)
    times = []
    for _ in range(400):
        t0 = time.perf_counter()
        corr.push(one)
        times.append(time.perf_counter() - t0)
    row["push_median_ms"] = 1e3 * float(np.median(times))
    row["push_p99_ms"] = 1e3 * float(np.percentile(times, 99))
row["segments"] = getattr(corr, "segments", None)
corr.close()
print(json.dumps(row))
"""


def _num(row: dict, key: str, fmt: str, width: int) -> str:
    value = row.get(key)
    return f"{'-':>{width}}" if value is None else f"{value:{width}{fmt}}"


def spectra_precision() -> None:
    """Relative RMS error of eq. (1) with only the filter spectra rounded (see the docstring)."""
    import numpy as np

    from rtsar.analysis import relative_rms
    from rtsar.ccd.base import correlate_reference, design_mask
    from rtsar.lens.plan import make_plan
    from rtsar.presets import preset

    cfg = preset("psaltis-max")
    mask = design_mask(cfg, make_plan(cfg).range_m)[:, :64]
    n, count, m = len(mask), 2048, 4096
    rng = np.random.default_rng(3)
    lines = rng.standard_normal((count, 64)) + 1j * rng.standard_normal((count, 64))
    ref = correlate_reference(lines, mask)
    h = np.zeros((m, 64), complex)
    h[:n] = mask[::-1]
    spec_h = np.fft.fft(h, axis=0)
    spec_x = np.fft.fft(np.vstack([lines, np.zeros((m - count, 64))]), axis=0)
    for dtype in (np.float64, np.float32, np.float16):
        rounded = spec_h.real.astype(dtype) + 1j * spec_h.imag.astype(dtype).astype(float)
        y = np.fft.ifft(spec_x * rounded, axis=0)[n - 1 : count]
        print(f"filter spectra in {dtype.__name__}: relative RMS error {relative_rms(y, ref):.2e}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default="psaltis-max,crouch-sal", help="comma-separated presets")
    ap.add_argument("--repeats", type=int, default=3, help="rounds (default 3)")
    ap.add_argument("--seconds", type=float, default=1.5, help="time per rate (default 1.5 s)")
    ap.add_argument("--json", help="also write the rows here")
    ap.add_argument(
        "--spectra-precision", action="store_true", help="the accuracy of rounded filter spectra"
    )
    args = ap.parse_args(argv)
    if args.spectra_precision:
        spectra_precision()
        return 0
    print(f"load average before: {os.getloadavg()}", flush=True)
    print(
        f"{'preset':12} {'round':>5} {'correlator':20} {'batch 64':>10} {'1 block':>10} "
        f"{'push med ms':>11} {'p99 ms':>8}",
        flush=True,
    )
    rows = []
    for name in args.presets.split(","):
        for rnd in range(args.repeats):
            for variant in VARIANTS:
                opts = {"preset": name, "variant": variant, "seconds": args.seconds}
                run = subprocess.run(
                    [sys.executable, "-c", CHILD, json.dumps(opts)],
                    capture_output=True,
                    text=True,
                )
                if run.returncode:
                    print(f"{name} {variant}: failed: {run.stderr.strip()[-300:]}", flush=True)
                    continue
                row = {"preset": name, "round": rnd, "correlator": variant}
                row.update(json.loads(run.stdout.strip().splitlines()[-1]))
                rows.append(row)

                print(
                    f"{name:12} {rnd:5d} {variant:20} "
                    f"{_num(row, 'batch64_pulses_per_s', ',.0f', 10)} "
                    f"{_num(row, 'one_block_pulses_per_s', ',.0f', 10)} "
                    f"{_num(row, 'push_median_ms', '.3f', 11)} "
                    f"{_num(row, 'push_p99_ms', '.3f', 8)}",
                    flush=True,
                )
    print(f"load average after: {os.getloadavg()}", flush=True)
    for row in rows:
        if row["segments"]:
            print(f"{row['preset']} {row['correlator']} segments (D, T, B): {row['segments']}")
            break
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
