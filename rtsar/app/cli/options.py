"""Options shared by several commands, declared once, with their choices from the library.

Also the small translations from options to library objects that several commands share
(processor changes, the correction chain, the physical CCD, strip length).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from dataclasses import replace

from ...ccd.migration import edge_gain_db, taps_for_band
from ...focus.spec import ORDER as CORRECTIONS
from ...focus.spec import correct_option
from ...lens import LENS_BACKENDS, range_axis_m
from ...params import PRECISIONS, Processor
from ...physical import CARRIERS, paper_ccd
from ...sinks.endpoint import DEFAULT_ENDPOINT, DELIVERIES, STALL_TIMEOUT_S, endpoint_error
from ...stream.granularity import migration_domain_for
from ...stream.pipeline import PipelineSettings
from ...stream.settings import STAGE_LAYOUTS
from .block_options import check_block_options


def die(msg: str) -> int:
    """Report a usage or input error in one line (a message that spans lines, as some
    libraries' do, is joined); exit status 2."""
    one_line = " ".join(str(msg).split())
    print(f"rtsar: error: {one_line}", file=sys.stderr)
    return 2


# ---- option groups ---------------------------------------------------------------------------
def zmq_endpoint(text: str) -> str:
    """An argparse type: a ZeroMQ endpoint, checked before start (one line, exit 2)."""
    if text == argparse.SUPPRESS:  # an optional positional left out (add_subscriber_options)
        return text
    why = endpoint_error(text)
    if why:
        raise argparse.ArgumentTypeError(f"{text!r}: {why}")
    return text


def swath_address(text: str) -> str:
    """An argparse type for --swath-bind: a HOST, or tcp://HOST:PORT."""
    if "://" in text and (not text.startswith("tcp://") or endpoint_error(text)):
        raise argparse.ArgumentTypeError(f"{text!r}: give a HOST or tcp://HOST:PORT (port 0-65535)")
    if not text.strip():
        raise argparse.ArgumentTypeError("give a HOST or tcp://HOST:PORT")
    return text


def add_lens_options(g) -> None:
    """--lens and --device (process, run, replay)."""
    g.add_argument(
        "--lens",
        default=LENS_BACKENDS[0],
        choices=LENS_BACKENDS,
        help="AO lens backend: auto (default: the OpenCL lens where it is faster than NumPy's for "
        "this configuration, timed once and kept; else NumPy; said on the banner's lens: line), "
        "opencl (on --device; an error if it cannot build), numpy, or hybrid (auto's lens, and "
        "in a live run the calls of a few pulses on SciPy's FFT where that takes less CPU than "
        "the OpenCL lens: for a CPU OpenCL driver on a machine of few cores; said on the "
        "banner's granularity line)",
    )
    g.add_argument(
        "--device",
        help="OpenCL device for the lens: an index of `rtsar devices`, or a part of its "
        "'platform version / device' name (e.g. Intel, 3.1+debian) (default: "
        "$RTSAR_OPENCL_DEVICE, else the fastest device that builds the lens, measured once per "
        "machine, a default kept until another is over 10 %% faster: `rtsar devices`)",
    )


def add_correlator_option(g) -> None:
    g.add_argument(
        "--correlator",
        choices=Processor.CORRELATORS,
        help="direct: CCD shift register, one line per pulse; fft: overlap-save blocks (fast, "
        "one block of latency); partitioned: partitioned overlap-save (low latency, fast); "
        "nonuniform: a short head block and long tail blocks (the partitioned latency, fewer "
        "multiply-adds) (default: the configuration's; a live run at a rate runs nonuniform "
        "where it names fft, lines as they come, but not with --fft-length, time-domain "
        "range-migration taps or --swath-workers; a squinted beam's Doppler-domain taps then "
        "read on the walk's ring if it leaves out under a bin of curvature, as nonuniform's)",
    )
    g.add_argument(
        "--partition-lines",
        type=int,
        metavar="L",
        help="block of the partitioned correlator, head block of the nonuniform one: lines "
        "leave in blocks of L (power of two; default: the configuration's, 16 in the presets; "
        "a live run at a rate chooses it from 1 up to 64 by the work measured, and grows it "
        "where the run falls behind)",
    )
    g.add_argument(
        "--fft-length",
        type=int,
        metavar="M",
        help="transform length of the fft correlator: lines leave in blocks of M - N + 1, N "
        "the aperture (M >= N, a product of 2, 3 and 5 such as 1000, 1024, 1080; default: "
        "the configuration's, 2N rounded up to a power of two in the presets; a live run at a "
        "rate that runs fft chooses it from the work measured, blocks of about 1, 2, 4, … "
        "lines up to the configuration's)",
    )
    g.add_argument(
        "--tail-block-lines",
        type=int,
        metavar="B",
        help="largest tail block of the nonuniform correlator (power of two; default: the "
        "configuration's, 128)",
    )


def add_processing_knobs(g) -> None:
    """Accuracy knobs and corrections (process, run, replay)."""
    g.add_argument(
        "--precision",
        choices=PRECISIONS,
        help="sample type of lens and CCD (complex128: ~1e-15 instead of ~1e-7, ~2× the cost; "
        "default: the configuration's)",
    )
    g.add_argument(
        "--range-migration-taps",
        type=int,
        metavar="T",
        help="range migration by a T-tap interpolating 2-D mask (0: off, most presets'; an "
        "import's: the fewest losing under 2 dB at its band's edge, RADARSAT-1 16; ~2-5x)",
    )
    g.add_argument(
        "--range-migration-domain",
        choices=Processor.MIGRATION_DOMAINS,
        help="where the taps read: time (exact 2-D mask), doppler (fft only: each block's "
        "azimuth spectrum), walk (nonuniform only: the squint's walk out first, up to 1 bin "
        "of curvature left) (default: the configuration's, or the one --correlator's takes)",
    )
    g.add_argument(
        "--correct",
        action="append",
        metavar="NAME[:KEY=VALUE,...]",
        help=f"phase/chirp correction in the stream, repeatable: {', '.join(CORRECTIONS)} "
        "(pra: pra:along_track_m=X,range_m=R; default the scene's brightest point, or a "
        "recording's found in a first pass; pga: e.g. pga:follow_walk=0 skips the "
        "walk-following second pass, pga:doppler_anchor=0 the Doppler anchor; an unknown key's "
        "error lists the keys a correction takes; default: none; "
        "docs/pages/guide/corrections.md)",
    )
    g.add_argument(
        "--physical",
        choices=CARRIERS,
        help="physical mode: the paper's CCD (bias, full well, noise, 12-bit ADC, blooming) "
        "with the coherent-detection carrier in range or in azimuth (default: off, the ideal "
        "correlator)",
    )
    g.add_argument(
        "--full-scale",
        type=float,
        metavar="A",
        help="physical mode: focused-image amplitude whose charge swing fills the well above "
        "the bias (the drive level; set it ~1.4× the brightest target's peak, default 1)",
    )


HEIGHT_METHODS = ("insal", "sam")


def add_process_options(s) -> None:
    """The processing options of ``process`` (and ``batch``, which runs process per file)."""
    add_lens_options(s)
    add_correlator_option(s)
    s.add_argument(
        "--micro-batch", type=int, help="pulses per lens launch (default: the configuration's)"
    )
    add_processing_knobs(s)
    add_height_options(s)


def add_height_options(g) -> None:
    """--height and its strip size (process, run, replay)."""
    g.add_argument(
        "--height",
        choices=HEIGHT_METHODS,
        help="3D: height strips, written beside the image (live runs also publish them on the "
        "'height' topic): "
        "insal (a second receiver, Zhao 2014; the scene's interferometric_receivers effect) or "
        "sam (cosine/sine-masked channels S1, S2, the INO 3D patent; the scene's "
        "amplitude_modulation_3d effect) (default: none, no height strips; insal in `rtsar "
        "demo`)",
    )
    g.add_argument(
        "--height-strip-lines",
        type=int,
        default=32,
        metavar="L",
        help="lines per height strip (default 32, at least 8; unwrapped with 8 lines of overlap)",
    )


def height_stage(args, cfg, scene):
    """The HeightStripStage asked for by --height (None without it)."""
    if not getattr(args, "height", None):
        return None
    if args.height_strip_lines < 8:
        raise ValueError(f"--height-strip-lines must be >= 8, got {args.height_strip_lines}")
    if getattr(args, "physical", None):
        raise ValueError("--height with --physical is not supported (the ideal CCD only)")
    rg, lines = range_axis_m(cfg), args.height_strip_lines
    if args.height == "sam":
        from ...scene.correction_context import modulation_geometry
        from ...topo.sam3d_strips import SamHeightStripStage

        return SamHeightStripStage(modulation_geometry(scene), rg, strip_lines=lines)
    from ...scene.correction_context import insal_geometry
    from ...topo.stream import HeightStripStage

    return HeightStripStage(insal_geometry(scene), rg, strip_lines=lines)


def add_pipeline_options(s, delivery: str) -> None:
    """The live pipeline's options (run, replay): processing, publication, the image file."""
    g = s.add_argument_group("processing")
    add_lens_options(g)
    add_correlator_option(g)
    g.add_argument(
        "--stages",
        choices=STAGE_LAYOUTS,
        default=None,
        help="split: lens and CCD in their own threads; fused: one thread; overlapped: one "
        "thread, the lens computing the next batch while the CCD correlates (with an OpenCL "
        "lens and no --correct/--height/--physical; otherwise as fused) (default: a live run "
        "at a rate chooses fused where the work measured takes at most 70%% of the stream's "
        "time, else split, said on the banner; otherwise split)",
    )
    g.add_argument(
        "--max-batch",
        type=int,
        help="most pulses per lens launch and correlator push (default: the configuration's "
        "micro_batch; four of them for --rate max; fewer when keeping up)",
    )
    g.add_argument(
        "--max-gap-pulses",
        type=int,
        metavar="P",
        help="longest run of missing sequence numbers that is zero-filled; a longer jump that "
        "the next shot confirms is a restart (default: one aperture)",
    )
    g.add_argument(
        "--swath-workers",
        type=int,
        default=0,
        metavar="K",
        help="run lens and CCD in K processes, each on 1/K of the range bins, merged here "
        "(docs/pages/guide/batch-swath.md; default 0: in this process)",
    )
    g.add_argument(
        "--swath-bind",
        default="127.0.0.1",
        type=swath_address,
        metavar="HOST|tcp://HOST:PORT",
        help="where the swath workers connect; with a PORT the workers are not started here: "
        "run `rtsar swath-worker --connect tcp://HOST:PORT --index k` for k = 0 … K-1 "
        "(default 127.0.0.1: K local workers on random loopback ports)",
    )
    add_processing_knobs(g)
    add_height_options(g)
    g = s.add_argument_group("publication (ZeroMQ; wire format in docs/pages/reference/wire.md)")
    g.add_argument(
        "--endpoint",
        default=DEFAULT_ENDPOINT,
        type=zmq_endpoint,
        help=f"where to publish strips (default {DEFAULT_ENDPOINT}, loopback)",
    )
    g.add_argument(
        "--delivery",
        choices=DELIVERIES,
        default=delivery,
        help="drop: a slow subscriber loses strips, the pipeline never waits; "
        f"lossless: the pipeline waits for the slowest subscriber (default {delivery})",
    )
    g.add_argument(
        "--strip-lines",
        type=int,
        help="lines per strip (default: chosen with the correlator's block from the work "
        "measured at the run's rate, said on the banner's granularity: line, a partial strip "
        "going out after 1 ms; 16 for a replay at --rate max)",
    )
    g.add_argument(
        "--strip-ms",
        type=float,
        help="strip length in ms at the PRF instead (default: none, --strip-lines rules)",
    )
    g.add_argument(
        "--stall-timeout",
        type=float,
        default=STALL_TIMEOUT_S,
        metavar="S",
        help="lossless delivery: the longest wait for a subscriber that reads nothing before it "
        f"is cut off, counted and reported (default {STALL_TIMEOUT_S:g} s)",
    )
    g.add_argument(
        "--curve-key",
        metavar="SECRET_KEY_FILE",
        help="encrypt with ZeroMQ CURVE (key pair from `rtsar keygen`)",
    )
    g.add_argument(
        "--curve-clients",
        metavar="DIR",
        help="with --curve-key: admit only the subscribers whose public keys (*.key from "
        "`rtsar keygen`) are in DIR",
    )
    s.add_argument(
        "-o",
        "--output",
        help="also write the focused image here, losslessly (.h5; also on Ctrl-C)",
    )


def add_subscriber_options(s) -> None:
    """The publisher to connect to (subscribe, view)."""
    s.add_argument(
        "endpoint",
        nargs="?",
        default=argparse.SUPPRESS,  # absent: --endpoint's value (or its default) stands
        type=zmq_endpoint,
        help=f"publisher (default {DEFAULT_ENDPOINT}); or --endpoint, as run and replay take it",
    )
    s.add_argument(
        "--endpoint",
        dest="endpoint",
        default=DEFAULT_ENDPOINT,
        type=zmq_endpoint,
        help=f"the publisher, as an option (the same as the positional ENDPOINT; default "
        f"{DEFAULT_ENDPOINT})",
    )
    s.add_argument(
        "--curve-server-key",
        metavar="PUBLIC_KEY_FILE",
        help="the publisher's public key when it uses CURVE",
    )
    s.add_argument(
        "--curve-client-key",
        metavar="SECRET_KEY_FILE",
        help="this subscriber's secret key, when the publisher admits only known clients",
    )


# ---- options → library objects ---------------------------------------------------------------
def processor_changes(args, cfg, as_configured: bool = False):
    """The configuration with the processor knobs given on the command line.
    ``as_configured``: the command runs the configuration's correlator where --correlator
    names none (process, batch, replay --rate max; not a live run at a rate, which may run
    another), so the block options are checked against it too (check_block_options)."""
    if getattr(args, "device", None) is not None and getattr(args, "lens", None) == "numpy":
        raise ValueError("--device names an OpenCL device; --lens numpy runs no OpenCL")
    changes = {}
    if args.correlator and getattr(args, "physical", None):
        raise ValueError(
            f"--correlator {args.correlator} does not apply with --physical: the physical mode "
            "emulates the paper's CCD itself (a shift register with its own charge transfer)"
        )
    if args.correlator:
        changes["correlator"] = args.correlator
    for name in ("micro_batch", "partition_lines", "fft_length", "tail_block_lines"):
        if getattr(args, name, None) is not None:
            changes[name] = getattr(args, name)
    physical = getattr(args, "physical", None)
    configured = cfg.processor.correlator if as_configured and not physical else None
    check_block_options(args, cfg.processor.aperture_pulses, configured)
    if getattr(args, "precision", None):
        changes["precision"] = args.precision
    if getattr(args, "range_migration_taps", None) is not None:
        changes["range_migration_taps"] = args.range_migration_taps
    if getattr(args, "range_migration_domain", None):
        changes["range_migration_domain"] = args.range_migration_domain
    elif args.correlator:
        changes["range_migration_domain"] = migration_domain_for(cfg, args.correlator)
    cfg = cfg.with_processor(**changes) if changes else cfg
    p = cfg.processor
    wf = cfg.waveform
    band = wf.bandwidth_hz / wf.sample_rate_hz if wf.kind == "pulsed" else 0.0  # no oversampling
    if p.range_migration_taps and band and p.range_migration_taps < (enough := taps_for_band(band)):
        loss_db = -edge_gain_db(p.range_migration_taps, band / 2)
        warnings.warn(
            f"--range-migration-taps {p.range_migration_taps} on a critically sampled range "
            f"axis (fs/B = {1 / band:.2f}) loses {loss_db:.1f} dB at the band's edge and "
            f"widens the range response; {enough} taps lose "
            f"{-edge_gain_db(enough, band / 2):.1f} dB (rtsar.ccd.migration.taps_for_band)",
            stacklevel=2,
        )
    elif p.range_migration_taps and p.range_oversampling < 2 and wf.kind == "fmcw":
        warnings.warn(
            f"--range-migration-taps {p.range_migration_taps} on a critically sampled range "
            "axis (range_oversampling 1) interpolates less accurately; set range_oversampling "
            "= 2 in the scene's [processor] table (docs/pages/reference/tradeoff.md)",
            stacklevel=2,
        )
    return cfg


def correction_chain(args, cfg, scene=None, start_along_track_m=0.0, recording=None):
    """The --correct stages as a CorrectionChain (None when none are asked for); ``scene``
    supplies the defaults and geometry the corrections read from it.  ``pra`` without a position
    and without a scene that names one takes the brightest point of ``recording`` (a first,
    uncorrected pass over it)."""
    if not getattr(args, "correct", None):
        return None
    from ...focus.chain import CorrectionChain
    from ...scene.correction_context import correction_context
    from ...stream.engine import brightest_point

    context = correction_context(scene, start_along_track_m)
    bare_pra = any(s.split(":")[0].strip() == "pra" and "=" not in s for s in args.correct)
    if bare_pra and context.retro_m is None and recording is not None:
        batches = recording.batches(cfg.processor.micro_batch)
        x, r = brightest_point(cfg, batches, recording.start_along_track_m)
        print(
            f"pra: taking the brightest point of {recording.path} as the retro-reflector: "
            f"along track {x:.6g} m, slant range {r:.6g} m (found in a first pass)",
            file=sys.stderr,
        )
        context = replace(context, retro_m=(x, r))
    return CorrectionChain.from_specs(args.correct, cfg, context)


def check_channels(recording, chain=None, heights=None) -> list[str]:
    """The auxiliary channels the --correct stages and the --height stage read (the only ones
    to read from ``recording``); a clear error when the recording lacks one."""
    readers = [(correct_option(name), stage) for name, stage in (chain.named if chain else [])]
    if heights is not None:
        readers.append((f"--height {heights.kind}", heights))
    have, needed = set(recording.channels), set()
    for option, stage in readers:
        missing = [c for c in stage.channels if c not in have]
        if missing:
            held = ", ".join(sorted(have)) or "the main channel only"
            if str(recording.path).lower().endswith(".cphd"):  # rtsar's CPHD export drops them
                raise ValueError(
                    f"{option} reads the auxiliary channel(s) {', '.join(missing)}, but "
                    f"{recording.path} holds {held} (a CPHD export leaves auxiliary channels "
                    "out): process the .h5 recording it was exported from, or its SigMF "
                    "export (`rtsar export REC.h5 --sigmf OUT`), which keep every channel"
                )
            raise ValueError(
                f"{option} reads the auxiliary channel(s) {', '.join(missing)}, but "
                f"{recording.path} holds {held}: simulate the scene with the effect that makes "
                "it (this rtsar records every channel), or run the scene live"
            )
        needed.update(stage.channels)
    return sorted(needed)


def physical_ccd(args):
    """--physical CARRIER: the paper's CCD (rtsar.physical.paper_ccd) with that carrier."""
    full_scale = getattr(args, "full_scale", None)
    if not getattr(args, "physical", None):
        if full_scale is not None:
            raise ValueError("--full-scale sets the physical mode's drive level: give --physical")
        return None
    return replace(
        paper_ccd(args.physical), full_scale_amplitude=1.0 if full_scale is None else full_scale
    )


def pipeline_settings(args, deadline: bool = False) -> PipelineSettings:
    for name in ("max_batch", "max_gap_pulses"):
        value = getattr(args, name)
        if value is not None and value < 1:
            raise ValueError(f"--{name.replace('_', '-')} must be >= 1, got {value}")
    if not args.stall_timeout > 0:
        raise ValueError(f"--stall-timeout must be > 0 seconds, got {args.stall_timeout}")
    if args.swath_workers > 0:  # before any worker starts (the pipeline refuses it too)
        given = [
            f"--{name}" for name in ("correct", "physical", "height") if getattr(args, name, None)
        ]
        if given:
            raise ValueError(f"--swath-workers runs without {', '.join(given)}")
    return PipelineSettings(
        lens_backend=args.lens,
        device=args.device,
        stages=args.stages or STAGE_LAYOUTS[0],
        strip_lines=args.strip_lines or PipelineSettings.strip_lines,
        max_batch=args.max_batch or 0,
        max_gap_pulses=args.max_gap_pulses or 0,
        deadline=deadline,
        swath_workers=max(0, args.swath_workers),
        swath_spawn=not args.swath_bind.startswith("tcp://"),
        swath_bind=args.swath_bind,
    )


def strip_lines(args, prf_hz: float) -> None:
    """--strip-ms → lines at the PRF (at least one); neither given: None (chosen)."""
    if args.strip_ms is not None:
        if args.strip_ms <= 0:
            raise ValueError(f"--strip-ms must be > 0, got {args.strip_ms}")
        args.strip_lines = max(1, round(args.strip_ms * 1e-3 * prf_hz))
    if args.strip_lines is not None and args.strip_lines < 1:
        raise ValueError(f"--strip-lines must be >= 1, got {args.strip_lines}")
