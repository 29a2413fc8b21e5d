"""The ``rtsar`` command.  ``rtsar COMMAND --help`` explains each command."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

EPILOG = """examples:
  rtsar run                                  live demo: the built-in scene streamed at its PRF
  rtsar presets                              the instrument presets and their theoretical figures
  rtsar simulate scene.toml -o rec.h5        raw shots of a scene
  rtsar process rec.h5 -o img.h5             range + azimuth compression (streaming engine)
  rtsar quicklook img.h5 -o img.png          dB image with axes in metres
  rtsar bench                                lens and correlator throughput in one run
"""


def _die(msg: str) -> int:
    print(f"rtsar: error: {msg}", file=sys.stderr)
    return 2


def cmd_presets(args) -> int:
    from .lens_plan import make_plan
    from .params import PRESETS, preset

    rows = []
    for name in PRESETS:
        c = preset(name)
        rm = make_plan(c).range_m
        rows.append(
            {
                "preset": name,
                "waveform": c.waveform.kind,
                "slant_range_m": c.geometry.slant_range_m,
                "swath_m": [float(rm[0]), float(rm[-1])],
                "range_resolution_m": c.waveform.range_resolution_m,
                "azimuth_resolution_m": c.azimuth_resolution_m(),
                "aperture_pulses": c.processor.aperture_pulses,
                "range_bins": c.processor.range_bins,
                "samples_per_shot": c.waveform.samples_per_shot,
                "prf_hz": c.geometry.prf_hz,
                "illuminated_length_m": c.geometry.illuminated_length_m,
                "synthetic_aperture_m": c.synthetic_aperture_m,
                "range_curvature_m": c.range_curvature_m,
            }
        )
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    print(
        f"{'preset':12} {'kind':6} {'swath (slant range)':>23} {'rho_R':>10} {'rho_A':>10} "
        f"{'N':>5} {'bins':>5} {'samples':>7} {'PRF Hz':>8} {'L illum.':>10} {'aperture':>10} "
        f"{'curvature':>10}"
    )
    for r in rows:
        swath = f"{r['swath_m'][0]:.6g}–{r['swath_m'][1]:.6g}"
        print(
            f"{r['preset']:12} {r['waveform']:6} {swath:>23} {r['range_resolution_m']:10.4g} "
            f"{r['azimuth_resolution_m']:10.4g} {r['aperture_pulses']:5d} {r['range_bins']:5d} "
            f"{r['samples_per_shot']:7d} {r['prf_hz']:8g} {r['illuminated_length_m']:10.4g} "
            f"{r['synthetic_aperture_m']:10.4g} {r['range_curvature_m']:10.3g}"
        )
    print("(lengths in metres; rho_A = λR/2L unweighted, Crouch eq. 4.8)")
    return 0


def _warn_outside_swath(scene) -> None:
    outside = scene.targets_outside_swath()
    if outside:
        from .lens_plan import make_plan

        rm = make_plan(scene.config).range_m
        print(f"warning: {len(outside)} of {len(scene.targets)} targets (indices {outside[:10]}) "
              f"lie outside the range window {rm[0]:.6g}–{rm[-1]:.6g} m and will not be imaged",
              file=sys.stderr)


def cmd_simulate(args) -> int:
    from .io import RecordingWriter
    from .progress import Progress
    from .scene import Simulator, load_scene

    scene = load_scene(args.scene)
    if args.pulses is not None:
        from dataclasses import replace

        if args.pulses < 1:
            return _die(f"--pulses must be >= 1, got {args.pulses}")
        scene = replace(scene, pulses=args.pulses)
    _warn_outside_swath(scene)
    sim = Simulator(scene)
    prog = Progress(scene.pulses, "simulate")
    batch = scene.config.processor.micro_batch
    t0 = time.perf_counter()
    with RecordingWriter(args.output, scene.config, scene.to_dict(), chunk_pulses=batch) as rec:
        done = 0
        while done < scene.pulses:
            shots = list(sim.shots(batch))
            rec.write(
                [s.samples for s in shots],
                [s.index for s in shots],
                [s.time_s for s in shots],
                [s.along_track_m for s in shots],
            )
            done += len(shots)
            prog.update(done)
    dt = time.perf_counter() - t0
    prog.done(done)
    effects = ", ".join(n for n, _ in scene.effects) or "none"
    print(
        f"wrote {args.output}: {done} shots × {sim.samples_per_shot} samples, "
        f"{len(scene.targets)} targets, effects: {effects}; {1e6 * dt / max(done, 1):.1f} µs/shot"
    )
    return 0


def cmd_process(args) -> int:
    import numpy as np

    from .engine import StreamProcessor
    from .io import open_recording, write_image
    from .progress import Progress

    with open_recording(args.recording) as rec:
        changes = {}
        if args.correlator:
            changes["correlator"] = args.correlator
        if args.micro_batch is not None:
            changes["micro_batch"] = args.micro_batch
        cfg = rec.config.with_processor(**changes) if changes else rec.config
        eng = StreamProcessor(cfg, args.lens, args.device, rec.start_along_track_m)
        prog = Progress(rec.pulses, "process")
        parts, done = [], 0
        t0 = time.perf_counter()
        for shots in rec.batches(cfg.processor.micro_batch):
            parts.append(eng.push(shots).lines)
            done += len(shots)
            prog.update(done)
        parts.append(eng.flush().lines)
        dt = time.perf_counter() - t0
        prog.done(done)
    image = np.concatenate(parts)
    if eng.nonfinite_pulses:
        print(f"warning: {eng.nonfinite_pulses} of {done} shots held NaN/Inf and were zeroed",
              file=sys.stderr)
    if len(image) == 0:
        return _die(
            f"{args.recording} holds {rec.pulses} shots, fewer than the aperture of "
            f"{cfg.processor.aperture_pulses}: no full-aperture line to write"
        )
    write_image(
        args.output,
        image,
        eng.azimuth_m(0, len(image)),
        eng.range_m,
        cfg,
        source=str(args.recording),
        lens=args.lens,
        correlator=cfg.processor.correlator,
        nonfinite_pulses=eng.nonfinite_pulses,
    )
    print(
        f"wrote {args.output}: image {image.shape[0]} azimuth × {image.shape[1]} range, "
        f"{done / dt:,.0f} pulses/s ({args.lens} lens, {cfg.processor.correlator} correlator)"
    )
    return 0


def cmd_quicklook(args) -> int:
    from .io import read_image
    from .quicklook import save_quicklook

    image, az, rg, attrs = read_image(args.image)
    save_quicklook(
        args.output,
        image,
        az,
        rg,
        dynamic_range_db=args.dynamic_range_db,
        title=Path(args.image).name,
    )
    print(f"wrote {args.output}")
    return 0


def cmd_run(args) -> int:
    from .live import run_live
    from .scene import DEMO_SCENE, load_scene

    scene = load_scene(args.scene or DEMO_SCENE)
    if args.duration is not None and args.duration <= 0:
        return _die(f"--duration must be > 0 seconds, got {args.duration}")
    if args.correlator:
        from dataclasses import replace

        scene = replace(scene, config=scene.config.with_processor(correlator=args.correlator))
    _warn_outside_swath(scene)
    return run_live(
        scene,
        duration_s=args.duration,
        lens_backend=args.lens,
        device=args.device,
        output=args.output,
    )


def cmd_bench(args) -> int:
    from .bench import run_bench

    return run_bench(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="rtsar",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=EPILOG,
        description="Real-time SAR/SAL image formation after Psaltis & Wagner's acousto-optic/CCD "
        "processor: an OpenCL 'AO lens' compresses each pulse in range, a shifting-"
        "CCD correlator with a chirp mask compresses in azimuth.",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    s = sub.add_parser("presets", help="list instrument presets and their theoretical figures")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_presets)

    s = sub.add_parser(
        "simulate",
        help="simulate the raw shots of a scene into a recording",
        description="Simulate a TOML scene (format: README 'Scene files') shot by "
        "shot with the exact range history; writes an HDF5 recording.",
    )
    s.add_argument("scene", help="scene file (.toml)")
    s.add_argument("-o", "--output", required=True, help="recording to write (.h5)")
    s.add_argument("--pulses", type=int, help="override the scene's number of shots")
    s.set_defaults(func=cmd_simulate)

    lens_help = "AO lens backend: opencl (default; PoCL CPU unless RTSAR_OPENCL_DEVICE) or numpy"
    s = sub.add_parser(
        "process",
        help="focus a recording through the streaming engine",
        description="Run a recording through the streaming engine as fast as "
        "possible; writes image[azimuth, range] with axes in metres.",
    )
    s.add_argument("recording", help="recording from `rtsar simulate` (.h5)")
    s.add_argument("-o", "--output", required=True, help="image file to write (.h5)")
    s.add_argument("--lens", default="opencl", choices=("opencl", "numpy"), help=lens_help)
    s.add_argument("--device", help="OpenCL platform/device name substring")
    s.add_argument(
        "--correlator",
        choices=("direct", "fft"),
        help="direct = CCD shift-register emulation; fft = overlap-save blocks",
    )
    s.add_argument("--micro-batch", type=int, help="pulses per lens launch")
    s.set_defaults(func=cmd_process)

    s = sub.add_parser("quicklook", help="PNG of an image file (dB, axes in metres)")
    s.add_argument("image", help="image file from `rtsar process` (.h5)")
    s.add_argument("-o", "--output", required=True, help="PNG to write")
    s.add_argument(
        "--dynamic-range-db",
        type=float,
        default=50.0,
        help="dB below the peak shown as black (default 50)",
    )
    s.set_defaults(func=cmd_quicklook)

    s = sub.add_parser(
        "run",
        help="live demo: stream a simulated scene at its PRF",
        description="Simulate a scene live, paced at its PRF, through the "
        "streaming engine; prints rates, latency and counters.",
    )
    s.add_argument("--scene", help="scene file (default: the built-in demo scene)")
    s.add_argument("--duration", type=float, help="stop after this many seconds")
    s.add_argument("--lens", default="opencl", choices=("opencl", "numpy"), help=lens_help)
    s.add_argument("--device", help="OpenCL platform/device name substring")
    s.add_argument("--correlator", choices=("direct", "fft"),
                   help="direct: one line per pulse (CCD emulation); fft: blocks, lower load")
    s.add_argument("-o", "--output", help="also write the focused image here (.h5; also on Ctrl-C)")
    s.set_defaults(func=cmd_run)

    s = sub.add_parser(
        "bench",
        help="throughput of the lens and correlators in one run",
        description="Not a test: measures pulses/s of the AO lens (OpenCL vs the same plan on "
        "NumPy's and SciPy's FFT, and one bare FFT of the batch) and of the direct and FFT "
        "correlators, in one run, as ratios.",
    )
    s.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    s.add_argument("--seconds", type=float, default=1.0, help="time per measurement")
    s.add_argument("--preset", default="psaltis-max",
                   help="geometry to measure at (default psaltis-max: 1200 bins, N = 512)")
    s.add_argument("--device", help="OpenCL platform/device name substring")
    s.set_defaults(func=cmd_bench)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        return args.func(args)
    except (ValueError, OSError, RuntimeError) as exc:
        return _die(str(exc))
    except KeyboardInterrupt:
        print("\nrtsar: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
