"""Commands on files: ``presets``, ``simulate``, ``process``, ``quicklook``."""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...ccd.base import azimuth_cell_m, squint_aperture_pulses
from ...lens import range_axis_m
from ...lens.plan import make_plan
from ...presets import PRESETS, preset
from ...samples import nonfinite_shots
from ...scene import load_scene
from ...sinks.image_file import ImageWriter, read_heights, read_image
from ...sinks.io import RecordingWriter, replace_when_complete
from ...sinks.record import collection_attrs, processing_attrs
from ...stream.engine import StreamProcessor
from ...stream.timing import RecordedFlags
from .. import signals
from ..progress import Progress
from ..quicklook import save_height_quicklook, save_quicklook, spotlight_words
from .inputs import open_input, warn_outside_swath
from .options import (
    add_process_options,
    check_channels,
    correction_chain,
    die,
    height_stage,
    physical_ccd,
    processor_changes,
)


def cmd_presets(args) -> int:
    rows = []
    for name in PRESETS:
        c = preset(name)
        rm = range_axis_m(c)
        column = squint_aperture_pulses(c)  # pulses of a range column's aperture
        aperture_m, r0 = column * c.geometry.along_track_step_m, c.geometry.slant_range_m
        rows.append(
            {
                "preset": name,
                "waveform": c.waveform.kind,
                "slant_range_m": c.geometry.slant_range_m,
                "swath_m": [float(rm[0]), float(rm[-1])],
                "range_resolution_m": c.waveform.range_resolution_m,
                "azimuth_resolution_m": azimuth_cell_m(c),
                "aperture_pulses": c.processor.aperture_pulses,
                "column_aperture_pulses": column,
                "range_bins": c.processor.range_bins,
                "samples_per_shot": c.waveform.samples_per_shot,
                "prf_hz": c.geometry.prf_hz,
                "illuminated_length_m": c.geometry.illuminated_length_m,
                "synthetic_aperture_m": aperture_m,
                "range_curvature_m": math.hypot(r0, 0.5 * aperture_m) - r0,
            }
        )
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    width = max(len("preset"), *(len(r["preset"]) for r in rows))
    print(
        f"{'preset':{width}} {'kind':6} {'swath (slant range)':>23} {'rho_R':>10} {'rho_A':>10} "
        f"{'N':>5} {'bins':>5} {'samples':>7} {'PRF Hz':>8} {'L illum.':>10} {'aperture':>10} "
        f"{'curvature':>10}"
    )
    for r in rows:
        swath = f"{r['swath_m'][0]:.6g}–{r['swath_m'][1]:.6g}"
        print(
            f"{r['preset']:{width}} {r['waveform']:6} {swath:>23} {r['range_resolution_m']:10.4g} "
            f"{r['azimuth_resolution_m']:10.4g} {r['aperture_pulses']:5d} {r['range_bins']:5d} "
            f"{r['samples_per_shot']:7d} {r['prf_hz']:8g} {r['illuminated_length_m']:10.4g} "
            f"{r['synthetic_aperture_m']:10.4g} {r['range_curvature_m']:10.3g}"
        )
    print(
        "(lengths in metres; rho_A = λR/2L unweighted, Crouch eq. 4.8, L the aperture a range "
        "column uses: N rows, less those a squinted beam's centre walks across the swath)"
    )
    return 0


def cmd_simulate(args) -> int:
    scene = load_scene(args.scene)
    if args.pulses is not None:
        if args.pulses < 1:
            return die(f"--pulses must be >= 1, got {args.pulses}")
        scene = replace(scene, pulses=args.pulses)
    warn_outside_swath(scene)
    simulate_to(scene, args.output)
    return 0


def simulate_to(scene, output) -> None:
    """Simulate every shot of ``scene`` (all its channels) into the recording ``output``,
    written under a temporary name until complete; progress on stderr, a summary line."""
    from ...scene import Simulator  # numba's simulator kernels: for simulate only
    from ...scene.tones import kernels_compiled

    sim = Simulator(scene)
    t_prepare = time.perf_counter()
    sim.prepare()  # compiled (first run) or loaded now: not in the first batch the ETA reads
    if kernels_compiled():
        print(
            f"simulate: numba compiled the simulator's kernels in "
            f"{time.perf_counter() - t_prepare:.1f} s (once: cached for later runs)",
            file=sys.stderr,
        )
    prog = Progress(scene.pulses, "simulate")
    batch = scene.config.processor.micro_batch
    t0 = time.perf_counter()
    with (
        signals.deferred(),
        replace_when_complete(output) as tmp,
        RecordingWriter(tmp, scene.config, scene.to_dict(), chunk_pulses=batch) as rec,
    ):
        done = 0
        while done < scene.pulses:
            signals.check()
            shots = list(sim.shots(batch))
            rec.write(
                [s.samples for s in shots],
                [s.index for s in shots],
                [s.time_s for s in shots],
                [s.along_track_m for s in shots],
                {name: np.stack([s.aux[name] for s in shots]) for name in shots[0].aux},
            )
            done += len(shots)
            prog.update(done)
    dt = time.perf_counter() - t0
    prog.done(done)
    effects = ", ".join(n for n, _ in scene.effects) or "none"
    channels = f" + channels {', '.join(rec.channel_names)}" if rec.channel_names else ""
    print(
        f"wrote {output}: {done} shots × {sim.samples_per_shot} samples{channels}, "
        f"{len(scene.targets)} target{'' if len(scene.targets) == 1 else 's'}, effects: "
        f"{effects}; {1e6 * dt / max(done, 1):.1f} µs/shot"
    )


def _ccd_words(cfg, physical) -> str:
    """The azimuth stage in words: the correlator, or the physical CCD that emulates it."""
    if physical is None:
        return f"{cfg.processor.correlator} correlator"
    return f"physical CCD, carrier in {physical.carrier}"


def process_setup(args, rec, retro_from=None):
    """What process derives from its options and the opened recording before any lens is
    built, in its order: (configuration, correction chain, height stage, the auxiliary
    channels they read); a request it refuses is a ValueError.  ``retro_from``: the recording
    a bare ``pra`` finds its retro-reflector in (a first pass over it); ``batch`` checks its
    files with this before its cluster starts."""
    cfg = processor_changes(args, rec.config, as_configured=True)
    scene = rec.scene_object()
    chain = correction_chain(args, cfg, scene, rec.start_along_track_m, retro_from)
    heights = height_stage(args, cfg, scene)
    channels = check_channels(rec, chain, heights)
    if heights is not None and chain:
        raise ValueError(
            "--height with --correct is not supported: the corrections act on the main "
            "receiver only and would bias the height phase between the receivers"
        )
    if rec.pulses < cfg.processor.aperture_pulses:
        raise ValueError(
            f"{args.recording} holds {rec.pulses} shots, fewer than the aperture of "
            f"{cfg.processor.aperture_pulses}: no full-aperture line to write"
        )
    return cfg, chain, heights, channels


def lens_for_the_job(args, cfg, pulses: int) -> tuple[str, str | None]:
    """``--lens`` for a recording of ``pulses`` shots to compress: "auto" becomes "numpy",
    with the reason, where the job is too small to pay for a first survey of the OpenCL
    devices (rtsar.lens.auto.survey_not_worth)."""
    if args.lens != "auto" or args.device is not None:
        return args.lens, None
    try:
        from ...lens.auto import survey_not_worth
    except ImportError:  # no pyopencl: auto says so itself
        return args.lens, None
    p = cfg.processor
    why = survey_not_worth(make_plan(cfg), p.precision, p.micro_batch, pulses)
    return ("numpy", why) if why else (args.lens, None)


def cmd_process(args) -> int:
    with open_input(args.recording) as rec:
        # Before the lens is built: a wrong request fails at once; only ``channels`` are read.
        cfg, chain, heights, channels = process_setup(args, rec, rec)
        physical = physical_ccd(args)
        compressed = 1 + (len(heights.channels) if heights is not None else 0)  # receivers
        lens, why = lens_for_the_job(args, cfg, rec.pulses * compressed)
        receivers = {}  # each auxiliary receiver's lens and CCD, in step with the main ones
        if heights is not None:
            receivers = {
                c: StreamProcessor(cfg, lens, args.device, rec.start_along_track_m)
                for c in heights.channels
            }
        eng = StreamProcessor(cfg, lens, args.device, rec.start_along_track_m, chain, physical)
        if args.lens != "numpy":  # which lens runs, on which device, and why
            print(f"rtsar: lens: {why or eng.lens.choice}", file=sys.stderr)
        prog = Progress(rec.pulses, "process")
        # A live recording's zero pulses (gaps, zeroed shots, shots not recorded), and shots
        # holding NaN/Inf in any channel read (zeroed, every channel, as replay's ingest does):
        # the lines whose aperture holds one are flagged, as a live run or a replay flags them.
        marked = getattr(rec, "pulse_flags", None)
        marked = None if marked is None else marked != 0
        flags = RecordedFlags(marked, cfg.processor.aperture_pulses, rec.pulses)
        done = nonfinite = 0
        t0 = time.perf_counter()
        # The image goes to disk as it is focused (bounded memory), under a temporary name
        # until it is complete.
        with (
            signals.deferred(),
            replace_when_complete(args.output) as tmp,
            ImageWriter(
                tmp,
                cfg,
                eng.range_m,
                heights=bool(receivers),
                source=str(args.recording),
                **collection_attrs(rec),
            ) as img,
        ):
            for shots, aux in rec.batches_with_aux(cfg.processor.micro_batch, channels):
                signals.check()
                bad = nonfinite_shots([shots, *aux.values()])
                nonfinite += int(bad.sum())
                flags.mark(done, bad)
                zeroed = flags.flagged[done : done + len(shots)]
                if zeroed.any():
                    shots, aux = _zero_marked(zeroed, shots, aux)
                out = eng.push(shots, aux)
                img.write(out.lines, eng.azimuth_m(out.first_line, len(out.lines)))
                flags.add(out.first_line, len(out.lines))
                if receivers:
                    more = [e.push(aux[c]).lines for c, e in receivers.items()]
                    _write_heights(img, heights.process(out.lines, *more))
                done += len(shots)
                prog.update(done)
            out = eng.flush()
            img.write(out.lines, eng.azimuth_m(out.first_line, len(out.lines)))
            flags.add(out.first_line, len(out.lines))
            extra = {}
            if marked is not None or nonfinite:  # (as run -o writes them: rtsar.sinks.record)
                extra["flagged_line_runs"] = json.dumps(flags.runs)
                extra["flagged_lines"] = flags.lines
            if receivers:
                more = [e.flush().lines for e in receivers.values()]
                _write_heights(img, heights.process(out.lines, *more) + heights.flush())
                extra |= {"height_method": args.height, "height_strips": heights.strips_out}
            counted = eng.corrections.counters() if eng.corrections else {}
            if counted:  # what each correction did (PGA: blocks estimated and why not, …)
                extra["correction_counters"] = json.dumps(counted)
            img.close(
                lens=eng.lens.backend,
                nonfinite_pulses=nonfinite,
                **processing_attrs(
                    cfg.processor.correlator,
                    chain.names if chain else (),
                    None if physical is None else physical.to_dict(),
                    chain.specs if chain else (),
                ),
                **extra,
            )
        dt = time.perf_counter() - t0
        prog.done(done)
    if nonfinite:
        print(f"warning: {nonfinite} of {done} shots held NaN/Inf and were zeroed", file=sys.stderr)
    if flags.lines:
        print(
            f"note: {flags.lines} lines flagged (flagged_line_runs): their aperture holds zero "
            f"pulses ({int(flags.flagged.sum())}: the recording's gaps, zeroed shots and shots "
            "not recorded, pulse_flags, and shots holding NaN/Inf)",
            file=sys.stderr,
        )
    if counted:
        said = [f"{k} {v}" for k, v in counted.items() if v]
        print(f"corrections: {', '.join(said) or 'nothing counted'}", file=sys.stderr)
    print(
        f"wrote {args.output}: image {img.lines} azimuth × {len(eng.range_m)} range, "
        f"{done / dt:,.0f} pulses/s ({eng.lens.backend} lens, {_ccd_words(cfg, physical)})"
    )
    return 0


def _zero_marked(marked: np.ndarray, shots: np.ndarray, aux: dict) -> tuple:
    """A block's shots and channels with the marked pulses zeroed (what ingest does with them
    in `replay`; a recording rtsar wrote holds zeros there already)."""
    shots = np.array(shots)
    shots[marked] = 0
    aux = {k: np.array(v) for k, v in aux.items()}
    for v in aux.values():
        v[marked] = 0
    return shots, aux


def _write_heights(img: ImageWriter, strips) -> None:
    for strip in strips:
        img.write_heights(strip.first_line, strip.height_m, strip.valid, strip.coherence)


def cmd_quicklook(args) -> int:
    if not args.dynamic_range_db > 0:  # before the image is read; named as the option
        return die(f"--dynamic-range-db must be > 0, got {args.dynamic_range_db}")
    if not 0 < args.white_at <= 100:
        return die(f"--white-at must be a percentile in (0, 100], got {args.white_at}")
    image, az, rg, attrs = read_image(args.image)
    spot = json.loads(attrs["spotlight"]) if "spotlight" in attrs else None
    title = Path(args.image).name
    if spot is not None:  # say which channel and how it was focused (before/after pairs)
        title += f": {spotlight_words(spot.get('channel', 'main'), spot.get('look', 'exact'))}"
    save_quicklook(
        args.output,
        image,
        az,
        rg,
        dynamic_range_db=args.dynamic_range_db,
        title=title,
        true_aspect=args.true_aspect,
        spotlight=spot is not None,
        white_at=args.white_at,
    )
    print(f"wrote {args.output}")
    if args.height:
        heights = read_heights(args.image)
        if heights is None:
            return die(f"{args.image} holds no heights (made without --height insal)")
        h, valid = heights
        save_height_quicklook(
            args.height,
            h,
            valid,
            az,
            rg,
            f"{Path(args.image).name}: height",
            true_aspect=args.true_aspect,
        )
        print(f"wrote {args.height}: {valid.mean():.0%} of the pixels valid")
    return 0


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "presets",
        description="The instrument presets of the papers with their swath (slant-range window), "
        "resolutions, CCD size, samples per shot, PRF and range curvature.",
    )
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.set_defaults(func=cmd_presets)

    s = sub.add_parser(
        "simulate",
        description="Simulate a TOML scene (format: docs/pages/guide/scenes.md) shot by "
        "shot with the exact range history; writes an HDF5 recording.",
    )
    s.add_argument(
        "scene",
        help="scene file (.toml), or a built-in scene: demo, sal-demo, insal-ridge, crouch-pga",
    )
    s.add_argument("-o", "--output", required=True, help="recording to write (.h5)")
    s.add_argument("--pulses", type=int, help="number of shots (default: the scene's `pulses`)")
    s.set_defaults(func=cmd_simulate)

    s = sub.add_parser(
        "process",
        description="Run a recording through the streaming engine as fast as "
        "possible; writes image[azimuth, range] with axes in metres.",
    )
    s.add_argument(
        "recording",
        help="recording from `rtsar simulate`, `import` or `run --record` (.h5), or a CPHD "
        "(.cphd) or SigMF (.sigmf-meta) "
        'file (these need pip install "rtsar[formats]"; docs/pages/guide/recordings.md)',
    )
    s.add_argument("-o", "--output", required=True, help="image file to write (.h5)")
    add_process_options(s)
    s.set_defaults(func=cmd_process)

    s = sub.add_parser(
        "quicklook",
        description="Write a PNG of an image file: |image| in dB relative to its peak (or "
        "to a percentile, --white-at), slant range across, along track down, axes as lengths "
        "(km, m, mm or µm, by their span).",
    )
    s.add_argument("image", help="image file from `rtsar process` (.h5)")
    s.add_argument("-o", "--output", required=True, help="PNG to write")
    s.add_argument(
        "--dynamic-range-db",
        type=float,
        default=50.0,
        help="dB below white shown as black (default 50)",
    )
    s.add_argument(
        "--white-at",
        type=float,
        default=100.0,
        metavar="PERCENTILE",
        help="0 dB (white) at this percentile of |image| (default 100: the peak); e.g. 99.9 "
        "for a real scene, whose few bright points (ships) would leave the rest dark",
    )
    s.add_argument(
        "--height",
        metavar="PNG",
        help="also draw the image's height map (an image made with --height insal or sam)",
    )
    s.add_argument(
        "--true-aspect",
        action="store_true",
        default=None,
        help="one metre as long on both axes, so a focused point looks like a point (default: "
        "so where that gives a figure 3-12 inches tall; otherwise the image fills the figure "
        "and its title says how far the vertical axis is stretched)",
    )
    s.set_defaults(func=cmd_quicklook)
