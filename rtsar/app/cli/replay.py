"""Replay commands: ``replay`` (a recording through the live pipeline, at its rate, a factor
of it, or as fast as it goes; the whole recording or a part of it) and ``demo`` (the 3-D demo:
a built-in scene simulated once, then replayed with height strips)."""

from __future__ import annotations

import math

from ... import __version__
from ...lens.cache import cache_dir  # $RTSAR_CACHE_DIR, else ~/.cache/rtsar
from ...scene import load_scene
from ...scene.files import BUILT_IN
from ...sources.replay import ReplaySource
from ..live import run_stream
from ..live_granularity import request_of
from .files import simulate_to
from .inputs import open_input
from .options import (
    add_pipeline_options,
    check_channels,
    correction_chain,
    die,
    height_stage,
    physical_ccd,
    pipeline_settings,
    processor_changes,
    strip_lines,
)
from .run_options import add_wait_subscribers, positive_seconds, seconds_at_least_zero


def replayed_part(
    start_s: float, duration_s: float | None, prf_hz: float, shots: int, aperture: int = 1
):
    """(first shot, shots) of ``--start`` and ``--duration``, seconds of the recording at its
    PRF (shot n is recorded at n / PRF), rounded to whole shots; ValueError naming the option
    for a part that is not finite, holds no shot, or (a part, not the whole) fewer than one
    ``aperture``: no line would be focused."""
    for option, seconds in (("--start", start_s), ("--duration", duration_s)):
        if seconds is not None and not math.isfinite(seconds):
            raise ValueError(f"{option} must be a finite number of seconds, got {seconds}")
        if seconds is not None and not math.isfinite(seconds * prf_hz):
            raise ValueError(f"{option} {seconds:g} s is more shots than any recording holds")
    first = round(start_s * prf_hz)
    if first >= shots:
        raise ValueError(
            f"--start {start_s:g} s is shot {first:,}, past the recording's last: it holds "
            f"{shots:,} shots, the last at {(shots - 1) / prf_hz:.6g} s at its {prf_hz:g} Hz"
        )
    count = shots - first if duration_s is None else min(round(duration_s * prf_hz), shots - first)
    if count < 1:
        raise ValueError(f"--duration {duration_s:g} s is less than one shot at {prf_hz:g} Hz")
    if count < min(aperture, shots):
        raise ValueError(
            f"--start/--duration: the part holds {count:,} shots, fewer than the CCD's "
            f"{aperture:,} rows (the aperture, and a squinted beam's walk across the swath): "
            "no line would be focused"
        )
    return first, count


def cmd_replay(args) -> int:
    with open_input(args.recording) as rec:
        # at --rate max no live choice of correlator: the recording's runs
        cfg = processor_changes(args, rec.config, as_configured=args.rate == "max")
        strip_lines(args, cfg.geometry.prf_hz)
        batch = args.max_batch or cfg.processor.micro_batch
        try:
            first, count = replayed_part(
                getattr(args, "start", 0.0),
                getattr(args, "duration", None),
                cfg.geometry.prf_hz,
                len(rec.pulse_index),
                cfg.processor.aperture_pulses,
            )
        except ValueError as exc:
            return die(f"{args.recording}: {exc}")
        # The part's first shot is the stream's pulse 0: its position, on the recording's step.
        start_m = rec.start_along_track_m + first * cfg.geometry.along_track_step_m
        scene = rec.scene_object()
        chain = correction_chain(args, cfg, scene, start_m, rec)
        heights = height_stage(args, cfg, scene)
        channels = check_channels(rec, chain, heights)
        source = ReplaySource.from_recording(rec, args.rate, batch, channels, first, count)
        rate_hz = None if source.factor is None else cfg.geometry.prf_hz * source.factor
        return run_stream(
            cfg,
            source,
            pipeline_settings(args),
            args.endpoint,
            args.delivery,
            start_m,
            args.output,
            args.curve_key,
            wait_subscribers=args.wait_subscribers,
            total_pulses=count,
            expected_rate_hz=rate_hz,
            corrections=chain,
            height=heights,
            physical=physical_ccd(args),
            stall_timeout_s=args.stall_timeout,
            curve_clients=args.curve_clients,
            granularity=request_of(args, rate_hz),
        )


def cmd_demo(args) -> int:
    scene = load_scene(BUILT_IN / f"{args.which}-ridge.toml")  # never a local file of that name
    cached = cache_dir() / f"{scene.name}-{__version__}.h5"
    if not cached.is_file():
        print(f"demo: simulating {scene.name} once into {cached} …", flush=True)
        cached.parent.mkdir(parents=True, exist_ok=True)
        simulate_to(scene, cached)
    args.recording = str(cached)
    args.height = args.height or "insal"
    if not args.correlator and not getattr(args, "physical", None):
        # Lines as they come (blocks of 16 pulses), not the FFT mode's whole-aperture blocks:
        # at this PRF the fft correlator published the whole image at the end; fft where
        # --fft-length asks for it (a live run's rule, rtsar.stream.granularity).
        args.correlator = "fft" if getattr(args, "fft_length", None) else "nonuniform"
    return cmd_replay(args)


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "replay",
        description="Replay a recording (from `rtsar simulate`, `import` or `run --record`) on "
        "an absolute schedule "
        "(start + n/PRF: no drift) and publish strips like `rtsar run`. Lossless by default: "
        "the replay waits for the slowest subscriber. Use --wait-subscribers 1 when a "
        "`rtsar subscribe` must see the stream from its first strip.",
    )
    s.add_argument(
        "recording",
        help="recording from `rtsar simulate`, `import` or `run --record` (.h5), or a CPHD "
        "(.cphd) or SigMF (.sigmf-meta) "
        'file (these need pip install "rtsar[formats]"; docs/pages/guide/recordings.md)',
    )
    s.add_argument(
        "--rate",
        default="real",
        help="real (recorded PRF, default), max (as fast as possible) or a factor",
    )
    s.add_argument(
        "--start",
        type=seconds_at_least_zero,
        default=0.0,
        metavar="S",
        help="begin S seconds into the recording (shot round(S × PRF); default 0). A line "
        "leaves once its whole aperture has arrived, so the part gives the whole replay's lines, "
        "at the same positions, for the apertures it holds: its first line comes one aperture "
        "after S",
    )
    s.add_argument(
        "--duration",
        type=positive_seconds,
        metavar="S",
        help="replay S seconds of the recording, round(S × PRF) shots from --start (default: "
        "to its end; seconds of the recording, not of the clock: --rate 2 plays 10 s in 5)",
    )
    add_wait_subscribers(s)
    add_pipeline_options(s, "lossless")
    s.set_defaults(func=cmd_replay)

    s = sub.add_parser(
        "demo",
        description="Simulate the built-in scene insal-ridge once (a few seconds; the recording "
        "is cached in rtsar's cache folder: $RTSAR_CACHE_DIR, else ~/.cache/rtsar), then "
        "replay it at --rate times its PRF through the "
        "pipeline with height strips (--height insal), publishing image and height strips "
        "like `rtsar replay`, with the nonuniform correlator unless --correlator says "
        "otherwise (lines leave every 16 pulses). Watch with `rtsar subscribe -o demo.h5` "
        "and draw with `rtsar quicklook demo.h5 -o demo.png --height demo-height.png`, or give "
        "-o here.",
    )
    s.add_argument(
        "which",
        nargs="?",
        default="insal",
        choices=("insal",),
        help="the demo to run (insal, the default)",
    )
    s.add_argument(
        "--rate", default="5", help="replay rate: a factor of the PRF (default 5: 10 s), or max"
    )
    add_wait_subscribers(s)
    add_pipeline_options(s, "lossless")
    s.set_defaults(func=cmd_demo, height="insal")
