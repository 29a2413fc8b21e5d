"""The ``rtsar`` command.  ``rtsar COMMAND --help`` explains each command."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

EPILOG = """examples:
  rtsar run                                  live demo: the built-in scene streamed at its PRF,
                                             strips published on tcp://127.0.0.1:5555
  rtsar view --png live.png                  snapshot of the live strips (or a window)
  rtsar subscribe -o live.h5                 record the published strips into an image file
  rtsar replay rec.h5 --rate max             a recording through the live pipeline
  rtsar presets                              the instrument presets and their theoretical figures
  rtsar simulate scene.toml -o rec.h5        raw shots of a scene
  rtsar process rec.h5 -o img.h5             range + azimuth compression (streaming engine)
  rtsar quicklook img.h5 -o img.png          dB image with axes in metres
  rtsar bench                                lens and correlator throughput in one run
  rtsar tradeoff                             what accuracy costs in time: every knob, one run
  rtsar table1                               Psaltis & Wagner's Table 1 from the physical emulation
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
        print(
            f"warning: {len(outside)} of {len(scene.targets)} targets (indices {outside[:10]}) "
            f"lie outside the range window {rm[0]:.6g}–{rm[-1]:.6g} m and will not be imaged",
            file=sys.stderr,
        )


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
        cfg = _processor_changes(args, rec.config)
        eng = StreamProcessor(
            cfg,
            args.lens,
            args.device,
            rec.start_along_track_m,
            _corrections(args, cfg, None, rec.start_along_track_m),
            _physical(args),
        )
        prog = Progress(rec.pulses, "process")
        parts, done = [], 0
        t0 = time.perf_counter()
        if eng.corrections and eng.corrections.raw_stages:
            raise ValueError(
                "corrections that use auxiliary channels (hcn, linearize, reference_region) run "
                "in `rtsar run --scene`; recordings hold the main channel only"
            )
        for shots in rec.batches(cfg.processor.micro_batch):
            parts.append(eng.push(shots).lines)
            done += len(shots)
            prog.update(done)
        parts.append(eng.flush().lines)
        dt = time.perf_counter() - t0
        prog.done(done)
    image = np.concatenate(parts)
    if eng.nonfinite_pulses:
        print(
            f"warning: {eng.nonfinite_pulses} of {done} shots held NaN/Inf and were zeroed",
            file=sys.stderr,
        )
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


def _settings(args):
    from .pipeline import PipelineSettings

    return PipelineSettings(
        lens_backend=args.lens,
        device=args.device,
        stages=args.stages,
        strip_lines=args.strip_lines,
        max_batch=args.max_batch or 0,
    )


def _processor_changes(args, cfg):
    changes = {}
    if args.correlator:
        changes["correlator"] = args.correlator
    if getattr(args, "micro_batch", None) is not None:
        changes["micro_batch"] = args.micro_batch
    if getattr(args, "precision", None):
        changes["precision"] = args.precision
    if getattr(args, "range_migration_taps", None) is not None:
        changes["range_migration_taps"] = args.range_migration_taps
    return cfg.with_processor(**changes) if changes else cfg


def _corrections(args, cfg, scene=None, start_along_track_m=0.0):
    """The --correct stages as a CorrectionChain (None when none are asked for)."""
    if not getattr(args, "correct", None):
        return None
    from .corrections import CorrectionChain

    return CorrectionChain.from_specs(args.correct, cfg, scene, start_along_track_m)


def _physical(args):
    """--physical CARRIER: the paper's CCD (rtsar.physical.paper_ccd) with that carrier."""
    if not getattr(args, "physical", None):
        return None
    from dataclasses import replace

    from .physical import paper_ccd

    return replace(paper_ccd(args.physical), full_scale_amplitude=args.full_scale)


def add_processing_knobs(g) -> None:
    """Options shared by process, run and replay: accuracy knobs and corrections."""
    g.add_argument(
        "--precision",
        choices=("complex64", "complex128"),
        help="sample type of lens and CCD (complex128: ~1e-15 instead of ~1e-7, ~2× the cost)",
    )
    g.add_argument(
        "--range-migration-taps",
        type=int,
        metavar="T",
        help="handle range migration with a T-tap interpolating 2-D mask (0: off; use with "
        "range oversampling 2; ~2-5× the CCD cost)",
    )
    g.add_argument(
        "--correct",
        action="append",
        metavar="NAME[:KEY=VALUE,...]",
        help="phase/chirp correction in the stream, repeatable: hcn, linearize, "
        "reference_region, pra (retro: pra:along_track_m=X,range_m=R; default the scene's "
        "brightest point), pga (README 'Phase errors and focusing')",
    )
    g.add_argument(
        "--physical",
        choices=("range", "azimuth"),
        help="physical mode: the paper's CCD (bias, full well, noise, 12-bit ADC, blooming) "
        "with the coherent-detection carrier in range or in azimuth",
    )
    g.add_argument(
        "--full-scale",
        type=float,
        default=1.0,
        metavar="A",
        help="physical mode: focused-image amplitude whose charge swing fills the well above "
        "the bias (the drive level; set it ~1.4× the brightest target's peak, default 1)",
    )


def _strip_lines(args, prf_hz: float) -> None:
    """--strip-ms → lines at the PRF (at least one)."""
    if args.strip_ms is not None:
        if args.strip_ms <= 0:
            raise ValueError(f"--strip-ms must be > 0, got {args.strip_ms}")
        args.strip_lines = max(1, round(args.strip_ms * 1e-3 * prf_hz))
    if args.strip_lines < 1:
        raise ValueError(f"--strip-lines must be >= 1, got {args.strip_lines}")


def cmd_run(args) -> int:
    from dataclasses import replace

    from .live import run_stream
    from .scene import DEMO_SCENE, load_scene

    if args.duration is not None and args.duration <= 0:
        return _die(f"--duration must be > 0 seconds, got {args.duration}")
    if args.serial:
        from .params import preset
        from .sources.serial import SerialSource

        if args.scene:
            cfg = load_scene(args.scene).config
        else:
            cfg = preset(args.preset) if args.preset else load_scene(DEMO_SCENE).config
        cfg = _processor_changes(args, cfg)
        _strip_lines(args, cfg.geometry.prf_hz)
        source = SerialSource(
            args.serial,
            cfg.waveform.samples_per_shot,
            baudrate=args.baudrate,
            idle_timeout_s=args.duration,
        )
        return run_stream(
            cfg,
            source,
            _settings(args),
            args.endpoint,
            args.delivery,
            output=args.output,
            curve_secret_key=args.curve_key,
            corrections=_corrections(args, cfg),
            physical=_physical(args),
        )
    from .sources.sim import SimSource

    if args.preset:
        return _die("--preset applies to --serial; a scene file carries its own configuration")
    scene = load_scene(args.scene or DEMO_SCENE)
    scene = replace(scene, config=_processor_changes(args, scene.config))
    _warn_outside_swath(scene)
    _strip_lines(args, scene.config.geometry.prf_hz)
    pulses = None if args.duration is None else int(args.duration * scene.config.geometry.prf_hz)
    source = SimSource(scene, pulses)
    return run_stream(
        scene.config,
        source,
        _settings(args),
        args.endpoint,
        args.delivery,
        scene.start_along_track_m,
        args.output,
        args.curve_key,
        total_pulses=source.total,
        corrections=_corrections(args, scene.config, scene, scene.start_along_track_m),
        physical=_physical(args),
    )


def cmd_replay(args) -> int:
    from .io import open_recording
    from .live import run_stream
    from .sources.replay import ReplaySource

    with open_recording(args.recording) as rec:
        cfg = _processor_changes(args, rec.config)
        _strip_lines(args, cfg.geometry.prf_hz)
        batch = args.max_batch or cfg.processor.micro_batch
        source = ReplaySource.from_recording(rec, args.rate, batch)
        return run_stream(
            cfg,
            source,
            _settings(args),
            args.endpoint,
            args.delivery,
            rec.start_along_track_m,
            args.output,
            args.curve_key,
            wait_subscribers=args.wait_subscribers,
            total_pulses=rec.pulses,
            corrections=_corrections(args, cfg, None, rec.start_along_track_m),
            physical=_physical(args),
        )


def cmd_subscribe(args) -> int:
    from .client import subscribe

    if args.timeout is not None and args.timeout <= 0:
        return _die(f"--timeout must be > 0 seconds, got {args.timeout}")
    return subscribe(args.endpoint, args.output, args.curve_server_key, args.timeout)


def cmd_view(args) -> int:
    from .client import view

    if args.lines < 1:
        return _die(f"--lines must be >= 1, got {args.lines}")
    return view(
        args.endpoint,
        args.png,
        args.lines,
        args.dynamic_range_db,
        args.curve_server_key,
        args.timeout,
    )


def cmd_keygen(args) -> int:
    import zmq.auth

    Path(args.directory).mkdir(parents=True, exist_ok=True)
    public, secret = zmq.auth.create_certificates(args.directory, args.name)
    print(
        f"wrote {public} (give to subscribers: --curve-server-key)\n"
        f"wrote {secret} (keep private: run/replay --curve-key)"
    )
    return 0


def cmd_table1(args) -> int:
    from .physical.table1 import run

    return run(args)


def cmd_tradeoff(args) -> int:
    from .tradeoff import run

    return run(args)


def cmd_bench(args) -> int:
    from .bench import run_bench

    return run_bench(args)


def build_parser() -> argparse.ArgumentParser:
    from .params import Processor

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
        choices=Processor.CORRELATORS,
        help="direct = CCD shift-register emulation; fft = overlap-save blocks; "
        "partitioned = partitioned overlap-save (low latency)",
    )
    s.add_argument("--micro-batch", type=int, help="pulses per lens launch")
    add_processing_knobs(s)
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

    def pipeline_options(s, delivery: str) -> None:
        g = s.add_argument_group("processing")
        g.add_argument("--lens", default="opencl", choices=("opencl", "numpy"), help=lens_help)
        g.add_argument("--device", help="OpenCL platform/device name substring")
        g.add_argument(
            "--correlator",
            choices=Processor.CORRELATORS,
            help="direct: CCD shift register, one line per pulse; fft: overlap-save "
            "blocks (fast, one block of latency); partitioned: low latency, fast",
        )
        g.add_argument(
            "--stages",
            choices=("split", "fused"),
            default="split",
            help="split: lens and CCD in their own threads (default); fused: one",
        )
        g.add_argument(
            "--max-batch",
            type=int,
            help="most pulses per lens launch "
            "(default: the configuration's micro_batch; fewer when keeping up)",
        )
        add_processing_knobs(g)
        g = s.add_argument_group("publication (ZeroMQ; wire format in README 'Strip protocol')")
        g.add_argument(
            "--endpoint",
            default="tcp://127.0.0.1:5555",
            help="where to publish strips (default tcp://127.0.0.1:5555, loopback)",
        )
        g.add_argument(
            "--delivery",
            choices=("drop", "lossless"),
            default=delivery,
            help="drop: a slow subscriber loses strips, the pipeline never waits; "
            f"lossless: the pipeline waits for the slowest subscriber (default "
            f"{delivery})",
        )
        g.add_argument("--strip-lines", type=int, default=16, help="lines per strip (default 16)")
        g.add_argument("--strip-ms", type=float, help="strip length in ms at the PRF instead")
        g.add_argument(
            "--curve-key",
            metavar="SECRET_KEY_FILE",
            help="encrypt with ZeroMQ CURVE (key pair from `rtsar keygen`)",
        )
        s.add_argument(
            "-o",
            "--output",
            help="also write the focused image here, losslessly (.h5; also on Ctrl-C)",
        )

    s = sub.add_parser(
        "run",
        help="live processing: the demo scene (default), a scene, or a serial instrument",
        description="Stream shots live through the pipeline (ingest checks, AO lens, shifting "
        "CCD) and publish image strips over ZeroMQ. Without arguments: the built-in demo scene "
        "simulated at its PRF, published on tcp://127.0.0.1:5555. Watch it with "
        "`rtsar view tcp://127.0.0.1:5555` or record it with `rtsar subscribe`.",
    )
    src = s.add_argument_group("source")
    src.add_argument(
        "--scene",
        help="scene file to simulate live (default: the demo scene); "
        "with --serial: the configuration to process with",
    )
    src.add_argument(
        "--serial",
        metavar="URL",
        help="read framed shots from an instrument: a "
        "serial port, a pty, or socket://HOST:PORT (frame format: README)",
    )
    src.add_argument("--preset", help="with --serial: processing configuration preset")
    src.add_argument("--baudrate", type=int, default=3_000_000, help="serial line rate")
    src.add_argument(
        "--duration", type=float, help="stop after this many seconds (serial: of silence)"
    )
    pipeline_options(s, "drop")
    s.set_defaults(func=cmd_run)

    s = sub.add_parser(
        "replay",
        help="replay a recording through the pipeline at real rate, a factor, or max",
        description="Replay a recording (from `rtsar simulate`) on an absolute schedule "
        "(start + n/PRF: no drift) and publish strips like `rtsar run`. Lossless by default: "
        "the replay waits for the slowest subscriber. Use --wait-subscribers 1 when a "
        "`rtsar subscribe` must see the stream from its first strip.",
    )
    s.add_argument("recording", help="recording (.h5)")
    s.add_argument(
        "--rate",
        default="real",
        help="real (recorded PRF, default), max (as fast as possible) or a factor",
    )
    s.add_argument(
        "--wait-subscribers",
        type=int,
        default=0,
        metavar="N",
        help="wait until N subscribers are connected before starting",
    )
    pipeline_options(s, "lossless")
    s.set_defaults(func=cmd_replay)

    def subscriber_options(s) -> None:
        s.add_argument(
            "endpoint",
            nargs="?",
            default="tcp://127.0.0.1:5555",
            help="publisher (default tcp://127.0.0.1:5555)",
        )
        s.add_argument(
            "--curve-server-key",
            metavar="PUBLIC_KEY_FILE",
            help="the publisher's public key when it uses CURVE",
        )

    s = sub.add_parser(
        "subscribe",
        help="record published strips into an image file",
        description="Receive strips from a publisher and write them, as they come, into an "
        "image file (same layout as `rtsar process`). Stops at the stream's end message, on "
        "Ctrl-C or after --timeout seconds of silence. Missed strips are zero lines, counted "
        "and listed in the file.",
    )
    subscriber_options(s)
    s.add_argument("-o", "--output", required=True, help="image file to write (.h5)")
    s.add_argument("--timeout", type=float, help="stop after this many seconds of silence")
    s.set_defaults(func=cmd_subscribe)

    s = sub.add_parser(
        "view",
        help="live waterfall of published strips (or a PNG snapshot)",
        description="Show the newest image lines as a scrolling waterfall (dB re peak). "
        "Needs a display; --png FILE waits for --lines lines and writes a snapshot instead. "
        "A viewer that cannot keep up skips strips; it never slows the processor.",
    )
    subscriber_options(s)
    s.add_argument("--png", metavar="FILE", help="write a snapshot PNG and exit")
    s.add_argument("--lines", type=int, default=1024, help="lines shown (default 1024)")
    s.add_argument("--dynamic-range-db", type=float, default=50.0, help="dB shown (default 50)")
    s.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        help="--png: give up after this many seconds of silence (default 30)",
    )
    s.set_defaults(func=cmd_view)

    s = sub.add_parser("keygen", help="make a CURVE key pair for encrypted publication")
    s.add_argument("directory", help="folder to write NAME.key and NAME.key_secret into")
    s.add_argument("--name", default="rtsar", help="file name stem (default rtsar)")
    s.set_defaults(func=cmd_keygen)

    s = sub.add_parser(
        "bench",
        help="throughput of the lens and correlators in one run",
        description="Not a test: measures pulses/s of the AO lens (OpenCL vs the same plan on "
        "NumPy's and SciPy's FFT, and one bare FFT of the batch) and of the direct and FFT "
        "correlators, in one run, as ratios.",
    )
    s.add_argument("--json", metavar="FILE", help="also write the results as JSON")
    s.add_argument("--seconds", type=float, default=1.0, help="time per measurement")
    s.add_argument(
        "--preset",
        help="measure at this preset only (default: lens and correlators at psaltis-max; "
        "the live pipeline at psaltis-max and psaltis-jpl)",
    )
    s.add_argument(
        "--real-seconds",
        type=float,
        default=10.0,
        help="length of each real-rate pipeline run (default 10 s)",
    )
    s.add_argument("--device", help="OpenCL platform/device name substring")
    s.set_defaults(func=cmd_bench)

    s = sub.add_parser(
        "table1",
        help="Psaltis & Wagner's Table 1 regenerated from the physical-mode emulation",
        description="Builds Table 1 of Psaltis & Wagner (1981) from the physical CCD/AO-cell "
        "emulation: range resolution and cells (halved with the carrier in range), azimuth "
        "resolution L/N (N halved with the carrier in azimuth), and the dynamic range measured "
        "on emulated images (largest undistorted point target / noise floor of an empty scene), "
        "beside the paper's values.  About 30 s.",
    )
    s.add_argument("--out", metavar="FILE.md", help="also write the Markdown table to FILE.md")
    s.add_argument("--json", metavar="FILE", help="write every number (and settings) as JSON")
    s.add_argument(
        "--speed",
        action="store_true",
        help="also measure the physical CCD's pulses/s against the ideal direct correlator",
    )
    s.set_defaults(func=cmd_table1)

    from .tradeoff import add_arguments as tradeoff_arguments

    s = sub.add_parser(
        "tradeoff",
        help="what accuracy costs in time: every processor knob, quality against cost",
        description="Varies each processor knob alone from the preset's defaults (precision, "
        "correlator mode and block, micro-batch, aperture, windows, lens, mask per range bin, "
        "range migration, physical CCD) on scenes whose targets stress it; measures image error "
        "against a float64 reference, IRW/PSLR/ISLR/position of point targets, pulses/s and the "
        "line latency at the PRF, in one run.  Writes JSON, Markdown and a Pareto plot (PNG). "
        "Not a test: about 5 minutes on 2 cores (--quick: seconds).",
    )
    tradeoff_arguments(s)
    s.set_defaults(func=cmd_tradeoff)
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
