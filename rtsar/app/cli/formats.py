"""``rtsar export``: recordings to CPHD 1.0.1 and SigMF, images to SICD
(docs/pages/guide/recordings.md).  The writers are rtsar.sinks.exports; they need the optional
extra ``formats``."""

from __future__ import annotations

import math
import sys
import time

from ...analysis.azimuth_response import azimuth_theory
from ...sinks.exports.cphd import write_cphd
from ...sinks.exports.sigmf_export import write_sigmf
from ...sinks.image_file import image_config, read_image
from ...sinks.io import check_writable
from ...sources.formats.geometry import DEFAULT_HEADING_DEG, LocalFrame
from .inputs import open_input
from .options import die


def _frame(text: str) -> LocalFrame:
    try:
        values = [float(v) for v in text.split(",")]
        if len(values) not in (2, 3):
            raise ValueError
    except ValueError:
        raise ValueError(
            f"--origin must be LAT,LON or LAT,LON,HEADING in degrees, got {text!r}"
        ) from None
    lat, lon = values[:2]
    heading = values[2] if len(values) == 3 else DEFAULT_HEADING_DEG
    if not (-90 <= lat <= 90 and -180 <= lon <= 360):
        raise ValueError(f"--origin {text!r} is not a latitude,longitude in degrees")
    if not (math.isfinite(heading) and 0 <= heading < 360):
        raise ValueError(f"--origin {text!r}: the heading must be in [0, 360) degrees")
    return LocalFrame(lat, lon, heading)


def _note_zeroed(nonfinite: dict, rec, out: str) -> None:
    """One warning per channel whose shots held NaN/Inf: written as zeros, as ``process`` images
    them (rtsar.sinks.exports.screen)."""
    for name, count in nonfinite.items():
        which = "" if name == "main" else f" of channel {name!r}"
        print(
            f"rtsar: warning: {count} of {rec.pulses} shots{which} of {rec.path} held NaN/Inf "
            f"and were written to {out} as zeros",
            file=sys.stderr,
        )


def _scene_azimuth_irw(args):
    """With --scene: the azimuth width to declare, the correlator's response to the scene's
    antenna beam (the theory `rtsar measure --scene` holds the image to)."""
    if args.scene is None:
        return None
    from ..measure_image import scene_antenna_gain  # the measure's own theory (--scene only)

    cfg = image_config(read_image(args.input)[3], args.input)
    gain = scene_antenna_gain(args.scene, cfg, args.input)
    return lambda config, range_m: azimuth_theory(config, range_m, gain).irw_m


def cmd_export(args) -> int:
    outputs = [o for o in (args.cphd, args.sigmf, args.sicd) if o]
    if not outputs:
        return die("export: say what to write: --cphd OUT.cphd, --sigmf OUT or --sicd OUT.nitf")
    for out in outputs:
        check_writable(out)
    frame = _frame(args.origin)
    t0 = time.perf_counter()
    if args.scene is not None and not args.sicd:
        return die("--scene goes with --sicd (an image's declared azimuth width)")
    if args.sicd:
        if args.cphd or args.sigmf:
            return die("--sicd takes an image file; --cphd and --sigmf take a recording")
        # Here, not above: sarpy takes ~1 s to load and only --sicd needs it.
        from ...sinks.exports.sicd import write_sicd

        info = write_sicd(args.input, args.sicd, frame, _scene_azimuth_irw(args))
        print(
            f"wrote {args.sicd}: SICD {info['version']}, {info['rows']} × {info['cols']} "
            f"pixels ({time.perf_counter() - t0:.1f} s)"
        )
        return 0
    # A CPHD export refuses shot times out of order itself (one line): no warning first.
    with open_input(args.input, note_times=not args.cphd) as rec:
        if args.cphd:
            info = write_cphd(rec, args.cphd, frame)
            _note_zeroed(info["nonfinite"], rec, args.cphd)
            print(
                f"wrote {args.cphd}: CPHD 1.0.1 {info['mode']}, {info['vectors']} vectors × "
                f"{info['samples']} samples, channel(s) {', '.join(info['channels'])}, "
                f"{info['domain']} domain ({time.perf_counter() - t0:.1f} s)"
            )
            if info["left_out"]:
                print(
                    f"note: {args.cphd} leaves out the auxiliary channel(s) "
                    f"{', '.join(info['left_out'])} (rtsar's strip-map CPHD export writes the "
                    f"main channel only): {args.input} keeps them, and so does "
                    f"`rtsar export {args.input} --sigmf OUT`",
                    file=sys.stderr,
                )
        if args.sigmf:
            info = write_sigmf(rec, args.sigmf)
            _note_zeroed(info["nonfinite"], rec, info["base"] + ".sigmf-data")
            more = f" + channels {', '.join(info['channels'])}" if info["channels"] else ""
            print(
                f"wrote {info['base']}.sigmf-meta/-data: {info['shots']} shots{more} "
                f"({time.perf_counter() - t0:.1f} s)"
            )
            if not info["start_known"]:
                print(
                    f"note: {args.input} keeps no collection start: the SigMF captures have no "
                    "core:datetime, and rtsar:collection_start_utc says unknown",
                    file=sys.stderr,
                )
    return 0


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "export",
        description="Write a recording (rtsar .h5, or a CPHD / SigMF file rtsar reads) as "
        "CPHD 1.0.1 (NGA phase history: FX domain, per-pulse positions, the scene reference "
        "point on the centre line; a spotlight recording on its arc, the SRP at the scene "
        "centre, its bistatic receiver as a second channel; strip-map auxiliary channels are "
        "left out, and named) and/or SigMF (one capture and one annotation per shot, every "
        "channel), or an image file as SICD (NITF).  Needs the optional packages: "
        'pip install "rtsar[formats]".  Fields filled: docs/pages/reference/files.md.',
    )
    s.add_argument("input", help="recording (.h5, .cphd, .sigmf-meta) or, with --sicd, image (.h5)")
    s.add_argument("--cphd", metavar="OUT.cphd", help="write the recording as CPHD 1.0.1")
    s.add_argument(
        "--sigmf",
        metavar="OUT",
        help="write the recording as SigMF: OUT.sigmf-meta + OUT.sigmf-data (+ OUT.NAME.* per "
        "auxiliary channel)",
    )
    s.add_argument("--sicd", metavar="OUT.nitf", help="write the image file as SICD 1.3 (NITF)")
    s.add_argument(
        "--scene",
        help="with --sicd: the scene file or built-in name the image was simulated from, so the "
        "declared azimuth width (ImpRespWid) is the correlator's response to its antenna beam, "
        "the theory `rtsar measure --scene` uses (default: none, the processor's weighted "
        "band alone)",
    )
    s.add_argument(
        "--origin",
        default="0,0",
        metavar="LAT,LON[,HEADING]",
        help="where rtsar's local frame (x along track, y to its right towards the scene, z up) "
        "sits on the WGS-84 ellipsoid: its origin's latitude and longitude, and the track's "
        "heading clockwise from north, in degrees (default 0,0,80: east by north; a heading "
        "of 90, due east, puts SICD's SCPCOA angles on their 0/360 wrap)",
    )
    s.set_defaults(func=cmd_export)
