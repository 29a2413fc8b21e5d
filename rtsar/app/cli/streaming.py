"""Streaming commands: ``run``, ``subscribe``, ``keygen`` (``replay`` and ``demo``: cli.replay;
``view``: its own module)."""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import zmq.auth

from ...ccd import first_line_pulses
from ...presets import PRESETS, preset
from ...scene import DEMO_SCENE, load_scene
from ...scene.files import built_in_scenes
from ...sinks.io import check_writable
from ...sinks.publish import DEFAULT_ENDPOINT
from ...sources.channel_map import ChannelMap
from ...sources.formats.instrument_config import instrument_config
from ...sources.formats.instrument_file import read_instrument_file
from ...sources.serial import SerialSource
from ...sources.sim import SimSource
from ...sources.zmq_in import ZmqSource
from ..live import (
    check_channels_delivered,
    run_stream,
    scene_channel_fix,
    serial_channel_fix,
    zmq_channel_fix,
)
from ..live_granularity import block_candidates, block_config, live_correlator, request_of
from ..subscribe import subscribe
from .inputs import warn_outside_swath
from .options import (
    add_pipeline_options,
    add_subscriber_options,
    correction_chain,
    die,
    height_stage,
    physical_ccd,
    pipeline_settings,
    processor_changes,
    strip_lines,
    zmq_endpoint,
)
from .run_options import add_run_options, add_wait_subscribers


def channel_map(args, scene) -> ChannelMap | None:
    """--channel-map, or the scene's channels (main + its effects' auxiliary ones), or None."""
    if args.channel_map:
        return ChannelMap.parse(args.channel_map)
    return None if scene is None else ChannelMap.for_scene(scene)


SLOW_FIRST_LINE_S = 30.0  # a live run whose first line takes longer than this gets a hint


def warn_slow_first_line(scene, name, args=None) -> None:
    """A live simulation waits at the real PRF for its first line (an aperture of N pulses,
    and the correlator's block): say so when that is long (a lidar bench at a few Hz), and how
    to look at the scene sooner.  The block: the smallest candidate of the run's correlator
    (rtsar.app.live_granularity; at a rate this slow the wait outweighs any work), the one
    ``args`` fixes, or with swath workers the configuration's correlator and block."""
    g, p = scene.config.geometry, scene.config.processor
    given = (getattr(args, "partition_lines", None), getattr(args, "fft_length", None))
    if not getattr(args, "swath_workers", 0):  # the correlator and block a live run chooses
        config = live_correlator(scene.config, getattr(args, "correlator", None), given[1])[0]
        p = block_config(config, block_candidates(config.processor, None, *given)[0][0]).processor
    pulses = first_line_pulses(p)
    wait_s = pulses / g.prf_hz
    if wait_s > SLOW_FIRST_LINE_S:
        block = (
            f"; the {p.correlator} correlator's lines then leave in blocks, so the first "
            f"after {pulses} pulses (--correlator nonuniform: lines every "
            f"{p.partition_lines} pulses)"
            if pulses > p.aperture_pulses
            else ""
        )
        print(
            f"note: at the scene's real PRF ({g.prf_hz:g} Hz) the first image line comes after "
            f"{wait_s:,.0f} s (an aperture of {p.aperture_pulses} pulses{block}). For a "
            f"quicker look: rtsar simulate {name} -o REC.h5, then rtsar replay REC.h5 --rate F "
            "(F times the PRF, or max)",
            file=sys.stderr,
            flush=True,
        )


def cmd_run(args) -> int:
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        return die(f"--duration must be a finite number of seconds > 0, got {args.duration}")
    if args.connect_timeout is not None and not args.serial:
        return die(
            "--connect-timeout is for --serial (a ZeroMQ source connects when the "
            "publisher comes up; a simulation has no link)"
        )
    if args.wait_subscribers and (args.serial or args.zmq_in):
        return die(
            "--wait-subscribers is for a simulated run: an instrument does not wait, its shots "
            "would pile up while rtsar waited"
        )
    if args.serial or args.zmq_in:
        # Pulse 0's along-track position: the scene's (the instrument scans the scene the file
        # describes, as the fake instrument does); a bare preset starts at 0 m.
        start_m, described = 0.0, None
        if getattr(args, "instrument", None):
            if args.preset or args.scene:
                return die("--instrument replaces --preset and --scene: give one of them")
            try:
                cfg = _instrument_config(args.instrument)
            except ValueError as exc:
                return die(str(exc))
        elif args.preset and not args.scene:
            cfg = preset(args.preset)
        else:
            described = load_scene(args.scene or DEMO_SCENE)
            cfg, start_m = described.config, described.start_along_track_m
            if not args.scene:  # said: a real instrument would be focused as the demo's
                w = cfg.waveform
                print(
                    "rtsar: no --preset, --scene or --instrument: the instrument is taken to be "
                    f"the demo scene's ({w.samples_per_shot} samples a shot at "
                    f"{cfg.geometry.prf_hz:g} Hz); name yours with --preset or --instrument",
                    flush=True,
                )
        cfg = processor_changes(args, cfg)
        strip_lines(args, cfg.geometry.prf_hz)
        # The stages before the source: their errors come before a port opens.
        chain = correction_chain(args, cfg, described, start_m)
        heights = height_stage(args, cfg, described)
        if args.zmq_in:  # a GNU Radio flowgraph's ZMQ PUB Sink (rtsar.sources.zmq_in)
            source = ZmqSource(
                args.zmq_in,
                cfg.waveform.samples_per_shot,
                cfg.waveform.sample_rate_hz,
                cfg.geometry.prf_hz,
                idle_timeout_s=args.duration,
                batch_shots=cfg.processor.micro_batch,
            )
            fix = zmq_channel_fix(described)
        else:
            cmap = channel_map(args, described)
            fix = serial_channel_fix(cmap, described)
            have = () if cmap is None else cmap.aux_names  # refused before the port opens
            check_channels_delivered(have, f"instrument at {args.serial}", chain, heights, fix)
            source = SerialSource(
                args.serial,
                cfg.waveform.samples_per_shot,
                baudrate=args.baudrate,
                idle_timeout_s=args.duration,
                reconnect=args.reconnect,
                channel_map=cmap,
                connect_timeout_s=args.connect_timeout,
                notify=lambda message: print(message, flush=True),
            )
        source.instrument_file = str(getattr(args, "instrument", None) or "")
        return run_stream(
            cfg,
            source,
            pipeline_settings(args, deadline=args.duration is not None),
            args.endpoint,
            args.delivery,
            start_m,
            output=args.output,
            curve_secret_key=args.curve_key,
            corrections=chain,
            height=heights,
            physical=physical_ccd(args),
            stall_timeout_s=args.stall_timeout,
            curve_clients=args.curve_clients,
            channel_fix=fix,
            record=args.record,
            scene=None if described is None else described.to_dict(),
            link_timeout_s=args.link_timeout,
            granularity=request_of(args, cfg.geometry.prf_hz),
        )

    if args.preset or getattr(args, "instrument", None):
        return die(
            "--preset and --instrument apply to --serial and --zmq-in; a scene file carries its "
            "own configuration"
        )
    scene = load_scene(args.scene or DEMO_SCENE)
    scene = replace(scene, config=processor_changes(args, scene.config))
    warn_outside_swath(scene)
    strip_lines(args, scene.config.geometry.prf_hz)
    warn_slow_first_line(scene, args.scene or scene.name, args)
    prf_hz = scene.config.geometry.prf_hz  # (a duration of more pulses than the scene's: said)
    pulses = None if args.duration is None else int(min(args.duration * prf_hz, 2.0**62))
    source = SimSource(scene, pulses, warm_from=args.scene or DEMO_SCENE, separate=True)
    if pulses is not None and pulses > source.total:  # the scene ends first: said, not hidden
        print(
            f"rtsar: --duration {args.duration:g} s is longer than the scene: the run ends with "
            f"it, after {source.total:,} pulses ({source.total / prf_hz:g} s)",
            flush=True,
        )
    return run_stream(
        scene.config,
        source,
        pipeline_settings(args, deadline=args.duration is not None),
        args.endpoint,
        args.delivery,
        scene.start_along_track_m,
        args.output,
        args.curve_key,
        wait_subscribers=args.wait_subscribers,
        total_pulses=source.total,
        expected_rate_hz=scene.config.geometry.prf_hz,
        height=height_stage(args, scene.config, scene),
        corrections=correction_chain(args, scene.config, scene, scene.start_along_track_m),
        physical=physical_ccd(args),
        stall_timeout_s=args.stall_timeout,
        curve_clients=args.curve_clients,
        channel_fix=scene_channel_fix,
        record=args.record,
        scene=scene.to_dict(),
        link_timeout_s=args.link_timeout,
        granularity=request_of(args, scene.config.geometry.prf_hz),
    )


def _stamp(path) -> tuple | None:
    """(inode, mtime) of a file, None when there is none: tells a file this run wrote."""
    try:
        st = Path(path).stat()
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns


def cmd_subscribe(args) -> int:
    if args.timeout is not None and args.timeout <= 0:
        return die(f"--timeout must be > 0 seconds, got {args.timeout}")
    if args.sicd:
        check_writable(args.sicd)
    before = _stamp(args.output)
    status = subscribe(
        args.endpoint, args.output, args.curve_server_key, args.timeout, args.curve_client_key
    )
    if args.sicd and _stamp(args.output) not in (None, before):  # only an image of this run
        # Here, not above: sarpy takes ~1 s to load and only --sicd needs it.
        from ...sinks.exports.sicd import write_sicd

        info = write_sicd(args.output, args.sicd)
        print(f"wrote {args.sicd}: SICD of {args.output}, {info['rows']} × {info['cols']} pixels")
    return status


def cmd_keygen(args) -> int:
    folder = Path(args.directory)
    public, secret = folder / f"{args.name}.key", folder / f"{args.name}.key_secret"
    there = [str(p) for p in (public, secret) if p.exists()]
    if there and not args.force:
        return die(f"{', '.join(there)} exist(s): keep them, or replace them with --force")
    folder.mkdir(parents=True, exist_ok=True)
    # Made in an owner-only folder beside them and renamed into place: the secret key is never
    # readable by others, and a run that dies leaves the earlier pair as it was.
    with tempfile.TemporaryDirectory(prefix=f".{args.name}.keygen-", dir=folder) as tmp:
        new_public, new_secret = zmq.auth.create_certificates(tmp, args.name)
        os.chmod(new_secret, 0o600)  # the secret key is readable by its owner only
        os.replace(new_secret, secret)
        os.replace(new_public, public)
    print(
        f"wrote {public} (give to subscribers: --curve-server-key; or, for a subscriber's own "
        f"pair, put it in the publisher's --curve-clients folder)\n"
        f"wrote {secret} (owner-only: run/replay --curve-key, or subscribe --curve-client-key)"
    )
    return 0


def _instrument_config(path: str):
    """The Config of an instrument file for a live run (its Doppler centroid must be given:
    a live stream has no block to estimate it from before it starts)."""
    inst = read_instrument_file(path)
    if inst.doppler_centroid_hz is None:
        raise ValueError(
            f"{path}: geometry.doppler_centroid_hz: a live run needs it (rtsar import "
            "estimates it from a recorded block and prints it)"
        )
    return instrument_config(inst, inst.doppler_centroid_hz)


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "run",
        description="Stream shots live through the pipeline (ingest checks, AO lens, shifting "
        "CCD) and publish image strips over ZeroMQ. Without arguments: the built-in demo scene "
        "(the letters SAR, an airfield and corner reflectors, 10 s of flight at 1600 pulses/s; "
        "about 15 s in all) simulated at its PRF, published on "
        f"{DEFAULT_ENDPOINT}. Watch it with `rtsar view` or record it with `rtsar subscribe -o "
        "live.h5`; `-o demo.h5` keeps the image for `rtsar quicklook`, `--record raw.h5` the "
        "raw shots for `rtsar process`/`replay` later.",
    )
    src = s.add_argument_group("source")
    src.add_argument(
        "--scene",
        help=f"scene file or built-in scene name ({', '.join(built_in_scenes())}) to simulate "
        "live (default: demo); with --serial: the configuration to process with",
    )
    src.add_argument(
        "--serial",
        metavar="URL",
        help="read framed shots from an instrument: a "
        "serial port, a pty, or socket://HOST:PORT (frame format: docs/pages/reference/wire.md)",
    )
    src.add_argument(
        "--zmq-in",
        metavar="ENDPOINT",
        type=zmq_endpoint,
        help="read shots from a GNU Radio ZMQ PUB Sink at ENDPOINT (e.g. tcp://127.0.0.1:5600): "
        "complex64 vector items of one shot each, or a flat stream cut by packet_len tags "
        "(pass tags on); processed with --preset or --scene like --serial "
        "(docs/pages/guide/recordings.md); the main channel only: a --correct or --height "
        "stage reading an auxiliary channel is refused before start.  Shots are numbered by "
        "the tag header's item offsets (a late subscriber keeps their positions); a message "
        "over 1 MiB + 256 shots, a bad header or an absurd packet_len is counted and dropped, "
        "never fatal",
    )
    src.add_argument(
        "--preset",
        choices=sorted(PRESETS),
        metavar="NAME",
        help=f"with --serial or --zmq-in: the processing configuration, one of "
        f"{', '.join(sorted(PRESETS))} (default: the --scene's configuration)",
    )
    src.add_argument(
        "--instrument",
        metavar="TOML",
        help="with --serial or --zmq-in: the processing configuration of an instrument file, "
        "as `rtsar import` reads it (docs/pages/guide/own-data.md); its [data] block gives the "
        "samples per pulse, and a live run needs its geometry.doppler_centroid_hz",
    )
    src.add_argument(
        "--baudrate", type=int, default=3_000_000, help="serial line rate (default 3000000)"
    )
    src.add_argument(
        "--channel-map",
        metavar="MAP",
        help="with --serial: the shot's channels in frame order, e.g. "
        "main,reference_interferometer,hcn_cell*8 (NAME*K: K frame channels); default: main "
        "and every auxiliary channel of --scene's effects, by name (fake_instrument prints its "
        "map); main only without a scene. A --correct or --height stage reading a channel the "
        "map lacks is refused before the port opens",
    )
    src.add_argument(
        "--duration",
        type=float,
        help="stop after this many seconds of the stream, i.e. pulses at the PRF (a busy "
        "machine takes longer; --serial, --zmq-in: seconds without a byte or message, a clean "
        "end: see --link-timeout for a failure) (default: the whole scene, 10 s for the demo; "
        "--serial, --zmq-in: never)",
    )
    src.add_argument(
        "--reconnect",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="with --serial: reopen a lost link, pausing 0.1 s doubling to 5 s (default: on for "
        "socket://, off for serial ports)",
    )
    add_run_options(src, s)
    add_wait_subscribers(s)
    add_pipeline_options(s, "drop")
    s.set_defaults(func=cmd_run)

    s = sub.add_parser(
        "subscribe",
        description="Receive strips from a publisher and write them, as they come, into an "
        "image file (same layout as `rtsar process`). Stops at the stream's end message, on "
        "Ctrl-C or after --timeout seconds of silence. Missed strips are zero lines, counted "
        "and listed in the file.",
    )
    add_subscriber_options(s)
    s.add_argument("-o", "--output", required=True, help="image file to write (.h5)")
    s.add_argument(
        "--timeout",
        type=float,
        help="stop after this many seconds of silence (default: none, until the stream's end "
        "message or Ctrl-C); stopped so, before the end, the file says complete = False and "
        "the exit status is 1",
    )
    s.add_argument(
        "--sicd",
        metavar="OUT.nitf",
        help="at the end of the stream, also write the image as SICD (NITF; needs "
        'pip install "rtsar[formats]"; default: none)',
    )
    s.set_defaults(func=cmd_subscribe)

    s = sub.add_parser(
        "keygen",
        description="Write a ZeroMQ CURVE key pair: NAME.key (public: give it to subscribers, "
        "--curve-server-key) and NAME.key_secret (owner-only, mode 0600: run/replay "
        "--curve-key).  A subscriber's own pair lets a publisher admit only known clients "
        "(run/replay --curve-clients DIR holding their NAME.key files; subscribe/view "
        "--curve-client-key).  An existing pair is kept unless --force.",
    )
    s.add_argument("directory", help="folder to write NAME.key and NAME.key_secret into")
    s.add_argument("--name", default="rtsar", help="file name stem (default rtsar)")
    s.add_argument("--force", action="store_true", help="replace an existing key pair")
    s.set_defaults(func=cmd_keygen)
