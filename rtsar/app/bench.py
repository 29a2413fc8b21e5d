"""``rtsar bench``: throughput of the AO lens and of the correlators, measured in one run.

Not a test.  Machines are shared and noisy, so every figure is reported beside its comparison
measured in the same run (ratios), at the psaltis-max geometry (1200 range bins, N = 512) unless
the caller asks for another preset.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np

from ..analysis.timing import rate_per_s
from ..ccd.base import design_mask
from ..ccd.direct import DirectCorrelator
from ..ccd.fft import FFTCorrelator
from ..ccd.nonuniform import NonUniformCorrelator
from ..ccd.partitioned import PartitionedCorrelator
from ..lens.base import make_lens, opencl_unavailable
from ..lens.numpy_lens import NumpyLens
from ..lens.plan import make_plan
from ..presets import preset
from ..sinks.io import check_writable, replace_when_complete
from .bench_pipeline import bench_pipeline
from .bench_record import bench_recording, recording_lines


def bench_lens(
    cfg, batches=(16, 64, 256), seconds=1.0, device=None, rounds=3, opencl=True
) -> list[dict]:
    """Pulses/s of the OpenCL lens and of the same plan on NumPy's and SciPy's FFT (complex64).

    The three backends alternate for ``rounds`` rounds and each keeps its best round, so a
    neighbour's load on the shared machine penalises none of them in particular.  With
    ``opencl=False`` (no working OpenCL device) the OpenCL figures are None.
    """
    plan = make_plan(cfg)
    rng = np.random.default_rng(0)
    backends = {"numpy": NumpyLens(plan), "scipy": NumpyLens(plan, library="scipy")}
    if opencl:
        backends["opencl"] = make_lens(plan, "opencl", device)
    nfft = plan.nfft
    rows = []
    for b in batches:
        shape = (b, plan.samples_per_shot)
        shots = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
        calls = {name: lens.compress for name, lens in backends.items()}
        # A single bare forward FFT of the batch: less work than the lens plan (two transforms
        # for the matched filter, plus window, filter, gather), shown as the floor of NumPy.
        calls["numpy_one_fft"] = lambda s: np.fft.fft(s, nfft, axis=-1)
        best = dict.fromkeys(calls, 0.0)
        for _ in range(rounds):
            for name, call in calls.items():
                rate = rate_per_s(lambda s=shots, f=call: f(s), b, seconds / rounds)
                best[name] = max(best[name], rate)
        cl = best.get("opencl")
        rows.append(
            {
                "stage": "lens",
                "batch": b,
                "opencl_pulses_per_s": cl,
                "numpy_fft_pulses_per_s": best["numpy"],
                "scipy_fft_pulses_per_s": best["scipy"],
                "numpy_one_fft_pulses_per_s": best["numpy_one_fft"],
                "opencl_over_numpy": cl and cl / best["numpy"],
                "opencl_over_scipy": cl and cl / best["scipy"],
                "opencl_over_numpy_one_fft": cl and cl / best["numpy_one_fft"],
            }
        )
    return rows


def bench_correlators(cfg, batch=64, seconds=1.0, pushes=400) -> list[dict]:
    """Pulses/s of the four correlators, pushes of ``batch`` lines, measured in one run.

    The partitioned correlator (blocks of ``cfg.processor.partition_lines`` = L) and the
    nonuniform one (head block L, tail blocks up to ``tail_block_lines``) are also fed the way a
    low-latency stream feeds them, one block of L per push: their pulses/s then, and the time of
    such a push (what it adds to a line's latency), median and 99th percentile of ``pushes``.
    """
    plan = make_plan(cfg)
    mask = design_mask(cfg, plan.range_m)
    block = min(cfg.processor.partition_lines, mask.shape[0])
    rng = np.random.default_rng(1)
    shape = (max(batch, block), plan.bin_count)
    lines = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
    corrs = {
        "direct": DirectCorrelator(mask),
        "fft": FFTCorrelator(mask),
        "partitioned": PartitionedCorrelator(mask, block),
        "nonuniform": NonUniformCorrelator(mask, block, cfg.processor.tail_block_lines),
    }
    rates = {}
    for name, corr in corrs.items():
        rates[name] = rate_per_s(lambda c=corr, x=lines[:batch]: c.push(x), batch, seconds)
    one_block = lines[:block]
    blocks = {}
    for name in ("partitioned", "nonuniform"):
        streaming = corrs[name]
        block_rate = rate_per_s(lambda c=streaming: c.push(one_block), block, seconds)
        times = np.empty(pushes)
        for i in range(pushes):
            t0 = time.perf_counter()
            streaming.push(one_block)
            times[i] = time.perf_counter() - t0
        blocks[name] = (block_rate, times)
    corrs["nonuniform"].close()
    row = {
        "stage": "correlator",
        "batch": batch,
        "direct_pulses_per_s": rates["direct"],
        "fft_pulses_per_s": rates["fft"],
        "fft_over_direct": rates["fft"] / rates["direct"],
        "partitioned_pulses_per_s": rates["partitioned"],
        "partitioned_over_fft": rates["partitioned"] / rates["fft"],
        "nonuniform_pulses_per_s": rates["nonuniform"],
        "nonuniform_over_partitioned": rates["nonuniform"] / rates["partitioned"],
        "partition_lines": block,
        "tail_block_lines": cfg.processor.tail_block_lines,
        "aperture_pulses": mask.shape[0],
        "range_bins": mask.shape[1],
    }
    for name, (block_rate, times) in blocks.items():
        row[f"{name}_one_block_pulses_per_s"] = block_rate
        row[f"{name}_push_median_ms"] = 1e3 * float(np.median(times))
        row[f"{name}_push_p99_ms"] = 1e3 * float(np.percentile(times, 99))
    return [row]


def add_arguments(parser) -> None:
    """Options of ``rtsar bench``."""
    parser.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    parser.add_argument(
        "--seconds", type=float, default=1.0, help="time per measurement (default 1 s)"
    )
    parser.add_argument(
        "--preset",
        help="measure at this preset only (default: lens and correlators at psaltis-max; "
        "the live pipeline at psaltis-max and psaltis-jpl)",
    )
    parser.add_argument(
        "--real-seconds",
        type=float,
        default=10.0,
        help="length of each real-rate pipeline run (default 10 s)",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=1,
        metavar="R",
        help="make every live-pipeline run R times, in rounds (each configuration once per "
        "round), and report each figure as median [min–max]: on a shared machine whose speed "
        "swings, one run of each says little (default 1; R times the pipeline part's time)",
    )
    parser.add_argument("--device", help="OpenCL platform/device name substring")
    parser.add_argument(
        "--record-dir",
        metavar="DIR",
        help="where the raw recording row writes (a temporary folder in DIR, removed after; "
        "default: the current folder, the disk `run --record` would write to)",
    )


def _num(value, width: int, fmt: str) -> str:
    return f"{'n/a':>{width}}" if value is None else f"{value:{width}{fmt}}"


def run_bench(args) -> int:
    name = getattr(args, "preset", None) or "psaltis-max"  # lens and correlators alone
    cfg = preset(name)
    out = sys.stdout
    seconds = args.seconds
    if args.repeats < 1:
        raise ValueError(f"--repeats must be >= 1, got {args.repeats}")
    if args.json:
        check_writable(args.json)  # before the minutes of measuring
    reason = None if args.device else opencl_unavailable()
    if reason is None:
        from ..lens.cl_loader import default_device, device_info

        device = device_info(args.device)
        if not args.device:
            device += f", the default device: {default_device()[1]} (`rtsar devices`)"
    else:
        device = f"unavailable ({reason}); OpenCL columns empty, pipelines on the NumPy lens"
    print(
        f"rtsar bench: preset {name} (samples/shot {cfg.waveform.samples_per_shot}, "
        f"{cfg.processor.range_bins} range bins, N = {cfg.processor.aperture_pulses}, "
        f"PRF {cfg.geometry.prf_hz:g} Hz); OpenCL: {device}",
        file=out,
    )
    lens_rows = bench_lens(cfg, seconds=seconds, device=args.device, opencl=reason is None)
    print("\nAO lens (range compression), pulses/s", file=out)
    print(
        "(NumPy/SciPy: the same plan in complex64; 1 FFT: one bare np.fft.fft of the batch)",
        file=out,
    )
    print(
        f"{'batch':>6} {'OpenCL':>10} {'NumPy':>10} {'SciPy':>10} {'1 FFT':>10} "
        f"{'CL/NumPy':>9} {'CL/SciPy':>9} {'CL/1 FFT':>9}",
        file=out,
    )
    for r in lens_rows:
        print(
            f"{r['batch']:6d} {_num(r['opencl_pulses_per_s'], 10, ',.0f')} "
            f"{r['numpy_fft_pulses_per_s']:10,.0f} {r['scipy_fft_pulses_per_s']:10,.0f} "
            f"{r['numpy_one_fft_pulses_per_s']:10,.0f} {_num(r['opencl_over_numpy'], 9, '.2f')} "
            f"{_num(r['opencl_over_scipy'], 9, '.2f')} "
            f"{_num(r['opencl_over_numpy_one_fft'], 9, '.2f')}",
            file=out,
        )
    corr_rows = bench_correlators(cfg, seconds=seconds)
    print("\nShifting CCD (azimuth correlation), pulses/s", file=out)
    for r in corr_rows:
        print(
            f"batch {r['batch']}: direct {r['direct_pulses_per_s']:,.0f}, "
            f"fft {r['fft_pulses_per_s']:,.0f}, fft/direct {r['fft_over_direct']:.1f}x, "
            f"partitioned {r['partitioned_pulses_per_s']:,.0f}, "
            f"nonuniform {r['nonuniform_pulses_per_s']:,.0f}, nonuniform/partitioned "
            f"{r['nonuniform_over_partitioned']:.2f}x ({r['aperture_pulses']} x "
            f"{r['range_bins']})",
            file=out,
        )
        for kind in ("partitioned", "nonuniform"):
            print(
                f"  {kind}, one block of {r['partition_lines']} per push: "
                f"{r[f'{kind}_one_block_pulses_per_s']:,.0f} pulses/s, push median "
                f"{r[f'{kind}_push_median_ms']:.3f} ms, p99 {r[f'{kind}_push_p99_ms']:.3f} ms",
                file=out,
            )
    prf = cfg.geometry.prf_hz
    best = max(corr_rows[0]["fft_pulses_per_s"], corr_rows[0]["direct_pulses_per_s"])
    lens_key = "opencl_pulses_per_s" if reason is None else "numpy_fft_pulses_per_s"
    lens_best = max(r[lens_key] for r in lens_rows)
    print(
        f"\nreal-time factors at PRF {prf:g} Hz: lens {lens_best / prf:.2f}x, "
        f"best correlator {best / prf:.2f}x",
        file=out,
    )
    pipeline_rows = []
    names = (
        [getattr(args, "preset", None)]
        if getattr(args, "preset", None)
        else ["psaltis-max", "psaltis-jpl"]
    )
    print(
        "\nLive pipeline end to end (simulated shots from memory, strips published on a "
        "loopback ZeroMQ socket)",
        file=out,
    )
    for pname in names:
        pipeline_rows.append(
            bench_pipeline(
                pname,
                preset(pname),
                seconds=max(2.0, 2 * seconds),
                real_seconds=args.real_seconds,
                log=lambda m: print(m, file=out, flush=True),
                repeats=args.repeats,
            )
        )
    rec_name = getattr(args, "preset", None) or "psaltis-max"
    recording = bench_recording(
        preset(rec_name), getattr(args, "record_dir", None), seconds=max(2.0, 2 * seconds)
    )
    for line in recording_lines(rec_name, recording):
        print(line, file=out, flush=True)
    if args.json:
        with replace_when_complete(args.json) as tmp, open(tmp, "w") as f:
            json.dump(
                {
                    "preset": name,
                    "device": device,
                    "lens": lens_rows,
                    "correlator": corr_rows,
                    "pipeline": pipeline_rows,
                    "recording": recording,
                },
                f,
                indent=2,
            )
        print(f"wrote {args.json}", file=out)
    return 0
