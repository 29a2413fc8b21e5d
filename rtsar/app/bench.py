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
from ..ccd import make_correlator
from ..ccd.base import design_mask
from ..lens.base import make_lens, opencl_unavailable
from ..lens.numpy_lens import NumpyLens
from ..lens.plan import make_plan
from ..params import Processor
from ..presets import preset
from ..sinks.io import check_writable, replace_when_complete
from ..stream.settings import PipelineSettings
from .bench_alone import CorrelatorAlone, LensAlone
from .bench_latency import plot_latency
from .bench_pipeline import bench_pipeline, with_correlator
from .bench_record import bench_recording, recording_lines

CORRELATORS = Processor.CORRELATORS  # direct, fft, partitioned, nonuniform


def bench_lens(
    cfg,
    batches=(16, 64, 256),
    seconds=1.0,
    device=None,
    rounds=3,
    opencl=True,
    lenses: LensAlone | None = None,
    name: str = "",
) -> list[dict]:
    """Pulses/s of the OpenCL lens and of the same plan on NumPy's and SciPy's FFT (complex64).

    The three backends alternate for ``rounds`` rounds and each keeps its best round, so a
    neighbour's load on the shared machine penalises none of them in particular.  With
    ``opencl=False`` (no working OpenCL device) the OpenCL figures are None.  ``lenses``
    keeps the OpenCL and NumPy figures (preset ``name``) for the pipeline section to reuse.
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
        # The physical yardstick: the lens's own transform pair (forward and inverse, nfft
        # points) bare, on SciPy's FFT with two threads: what the two cores can do for it.
        calls["fft_pair_2t"] = lambda s: _fft_pair(s, nfft)
        best = dict.fromkeys(calls, 0.0)
        for _ in range(rounds):
            for backend, call in calls.items():
                rate = rate_per_s(lambda s=shots, f=call: f(s), b, seconds / rounds)
                best[backend] = max(best[backend], rate)
        cl = best.get("opencl")
        if lenses is not None:
            for key in ("opencl", "numpy"):
                if key in backends:
                    lenses.record(LensAlone.key(name, backends[key], b), best[key], LENS_TABLE)
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
                "fft_pair_two_threads_pulses_per_s": best["fft_pair_2t"],
                "opencl_share_of_fft_pair": cl and cl / best["fft_pair_2t"],
                "numpy_share_of_fft_pair": best["numpy"] / best["fft_pair_2t"],
            }
        )
    return rows


def _fft_pair(shots: np.ndarray, nfft: int) -> np.ndarray:
    """A forward and an inverse ``nfft``-point FFT of every shot, two threads (scipy.fft)."""
    import scipy.fft

    return scipy.fft.ifft(scipy.fft.fft(shots, nfft, axis=-1, workers=2), axis=-1, workers=2)


CORRELATOR_TABLE = "the correlator table above"
LENS_TABLE = "the AO lens table above"


def bench_correlators(
    cfg, name: str, alone: CorrelatorAlone, batch: int = 64, seconds: float = 1.0, pushes=400
) -> list[dict]:
    """Pulses/s of the four correlators alone, pushes of ``batch`` lines (``alone``: the one
    definition the pipeline's ratios share), measured in one run.

    The partitioned correlator (blocks of ``cfg.processor.partition_lines`` = L) and the
    nonuniform one (head block L, tail blocks up to ``tail_block_lines``) are also fed the way a
    low-latency stream feeds them, one block of L per push: their pulses/s then, and the time of
    such a push (what it adds to a line's latency), median and 99th percentile of ``pushes``.
    """
    plan = make_plan(cfg)
    mask = design_mask(cfg, plan.range_m)
    block = min(cfg.processor.partition_lines, mask.shape[0])
    rates = {
        kind: alone.rate(name, with_correlator(cfg, kind), batch, CORRELATOR_TABLE)
        for kind in CORRELATORS
    }
    rng = np.random.default_rng(1)
    shape = (block, plan.bin_count)
    one_block = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)
    blocks = {}
    for kind in ("partitioned", "nonuniform"):
        p = cfg.processor
        streaming = make_correlator(
            kind, mask, p.fft_length, partition_lines=block, tail_block_lines=p.tail_block_lines
        )
        block_rate = rate_per_s(lambda c=streaming: c.push(one_block), block, seconds)
        times = np.empty(pushes)
        for i in range(pushes):
            t0 = time.perf_counter()
            streaming.push(one_block)
            times[i] = time.perf_counter() - t0
        if hasattr(streaming, "close"):
            streaming.close()
        blocks[kind] = (block_rate, times)
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
    for kind, (block_rate, times) in blocks.items():
        row[f"{kind}_one_block_pulses_per_s"] = block_rate
        row[f"{kind}_push_median_ms"] = 1e3 * float(np.median(times))
        row[f"{kind}_push_p99_ms"] = 1e3 * float(np.percentile(times, 99))
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
        help="length of each paced pipeline run, shots released at the PRF (default 10 s)",
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
        "--plot",
        metavar="PNG",
        help="also draw the latency against the offered rate, every preset measured (default: "
        "none)",
    )
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
    for path in (args.json, getattr(args, "plot", None)):
        if path:
            check_writable(path)  # before the minutes of measuring
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
    lenses = LensAlone(seconds)
    lens_rows = bench_lens(
        cfg, seconds=seconds, device=args.device, opencl=reason is None, lenses=lenses, name=name
    )
    print("\nAO lens (range compression), pulses/s", file=out)
    print(
        "(NumPy/SciPy: the same plan in complex64; 1 FFT: one bare np.fft.fft of the batch; "
        "FFT pair: the plan's forward and inverse transforms bare, SciPy, two threads: the "
        "yardstick; CL share, NumPy share: each lens's rate over it)",
        file=out,
    )
    print(
        f"{'batch':>6} {'OpenCL':>10} {'NumPy':>10} {'SciPy':>10} {'1 FFT':>10} "
        f"{'FFT pair':>10} {'CL/NumPy':>9} {'CL/SciPy':>9} {'CL share':>9} {'NP share':>9}",
        file=out,
    )
    for r in lens_rows:
        print(
            f"{r['batch']:6d} {_num(r['opencl_pulses_per_s'], 10, ',.0f')} "
            f"{r['numpy_fft_pulses_per_s']:10,.0f} {r['scipy_fft_pulses_per_s']:10,.0f} "
            f"{r['numpy_one_fft_pulses_per_s']:10,.0f} "
            f"{r['fft_pair_two_threads_pulses_per_s']:10,.0f} "
            f"{_num(r['opencl_over_numpy'], 9, '.2f')} "
            f"{_num(r['opencl_over_scipy'], 9, '.2f')} "
            f"{_num(r['opencl_share_of_fft_pair'], 9, '.2f')} "
            f"{r['numpy_share_of_fft_pair']:9.2f}",
            file=out,
        )
    alone = CorrelatorAlone(seconds)
    # At the pipeline's own takes at max rate (a replay's), so its ratios below reuse these.
    take = PipelineSettings().take_cap(cfg.processor.micro_batch, paced=False)
    corr_rows = bench_correlators(cfg, name, alone, take, seconds=seconds)
    r = corr_rows[0]
    print(
        f"\nShifting CCD (azimuth correlation) alone, pulses/s: each correlator as the pipeline "
        f"builds it, pushed batches of {r['batch']} lines ({r['aperture_pulses']} x "
        f"{r['range_bins']})",
        file=out,
    )
    print(
        "  "
        + "   ".join(f"{k} {r[f'{k}_pulses_per_s']:,.0f}" for k in CORRELATORS)
        + f"   (fft / direct {r['fft_over_direct']:.1f}x, nonuniform / partitioned "
        f"{r['nonuniform_over_partitioned']:.2f}x)",
        file=out,
    )
    for kind in ("partitioned", "nonuniform"):
        print(
            f"  {kind}, one block of {r['partition_lines']} lines per push (the low-latency "
            f"path): {r[f'{kind}_one_block_pulses_per_s']:,.0f} pulses/s, push median "
            f"{r[f'{kind}_push_median_ms']:.3f} ms, p99 {r[f'{kind}_push_p99_ms']:.3f} ms",
            file=out,
        )
    prf = cfg.geometry.prf_hz
    fastest = max(CORRELATORS, key=lambda k: r[f"{k}_pulses_per_s"])
    lens_key = "opencl_pulses_per_s" if reason is None else "numpy_fft_pulses_per_s"
    lens_row = max(lens_rows, key=lambda row: row[lens_key])
    print(
        f"\nalone, against the PRF ({prf:g} Hz): the "
        f"{'OpenCL' if reason is None else 'NumPy'} lens {lens_row[lens_key] / prf:.2f}x real "
        f"time (batch {lens_row['batch']}, its fastest above); the fastest correlator, "
        f"{fastest}, {r[f'{fastest}_pulses_per_s'] / prf:.2f}x (batches of {r['batch']})",
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
        "loopback ZeroMQ socket).\n"
        "  max rate: shots replayed as fast as the pipeline takes them; capacity = pulses/s ÷ "
        "PRF (x real time); strips of 16 lines, those waiting together up to 64, as a live "
        "run cuts them\n"
        "  paced: shots released at the PRF as an instrument sends them (a full queue drops "
        "them): the shots kept of those offered, and the latency from a line's last pulse to "
        "its strip",
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
                alone=alone,
                lenses=lenses,
            )
        )
    rec_name = getattr(args, "preset", None) or "psaltis-max"
    recording = bench_recording(
        preset(rec_name), getattr(args, "record_dir", None), seconds=max(2.0, 2 * seconds)
    )
    for line in recording_lines(rec_name, recording):
        print(line, file=out, flush=True)
    if getattr(args, "plot", None):
        plot_latency(pipeline_rows, args.plot)
        print(f"wrote {args.plot}", file=out)
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
