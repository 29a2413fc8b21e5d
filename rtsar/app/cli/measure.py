"""Measuring commands: ``devices`` (the OpenCL devices), ``measure`` (an image's quality),
``bench``, ``tradeoff``, ``table1`` (the last three declare their own options)."""

from __future__ import annotations

import re

from .. import bench, devices, measure_image, table1, tradeoff
from .options import die

# A negative number, or a position "X,R" whose X is negative (argparse's own matcher takes the
# bare number only and would read "-0.005,1.5" as an unknown option).
NEGATIVE_POSITION = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?(,[-+]?[\d.eE+-]+)*$")


def cmd_measure(args) -> int:
    if not args.max_points >= 1:
        return die(f"--max-points must be >= 1, got {args.max_points}")
    at = [measure_image.parse_at(a) for a in args.at or []]
    report = measure_image.measure_image(
        args.image, args.scene, at, args.threshold_db, args.max_points, args.contrast_db
    )
    for line in measure_image.text_lines(report):
        print(line)
    if args.json:
        measure_image.write_json(report, args.json)
        print(f"wrote {args.json}")
    if not report["points"]:
        print("no point target found (try --threshold-db, or give --at X,R)")
        return 0 if report.get("height") else 1
    return 0


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "devices",
        description="Lists every OpenCL device the loader sees (pyopencl's PoCL, the system's "
        "drivers, drivers installed with pip such as Intel's CPU runtime, GPUs).  Each is "
        "probed in a process of its own: the lens kernel of --preset built, 8 pulses compared "
        "with the float64 reference, pulses/s timed at each batch size; the NumPy lens of the "
        "same plan beside them.  Says which device runs the lens by default (the fastest that "
        "builds, on psaltis-max at batch 64; the default before stays unless another is over "
        "10 % faster) and why a device is refused.  About 1-2 s a device.  Exit status 1 "
        "where no device can run the lens.",
    )
    devices.add_arguments(s)
    s.set_defaults(func=devices.run)

    s = sub.add_parser(
        "measure",
        description="Measure the image you made: finds its point targets (or measures at "
        "--at X,R ...) and reports, per point, along-track and range position, peak |x|, IRW "
        "(-3 dB width) in azimuth and range, PSLR per axis and the 2-D ISLR, beside the theory "
        "of the processor that made it, measured with the same rules: range, its window's "
        "response (0.886 rho_R x the window's broadening, rho_R = c/2B); azimuth, the "
        "correlator's own response to a point (the windowed mask sliding along the exact range "
        "history, times the scene's antenna pattern with --scene, or the instrument's own "
        "two-way beam for an image of a recording `rtsar import` made; 0.886 rho_A x the window's "
        "broadening, rho_A = lambda R / 2L, without a beam).  A spotlight image [x, y] is "
        "measured too: along track and azimuth are cross-range x, range is down-range y, and "
        "the theory is each window over the inscribed rectangle of k-space it was formed from "
        "(0.886 x 2 pi / delta k).  With --scene (which must have the "
        "image's waveform and geometry), each point's offset from the scene's nearest "
        "[[targets]] entry in resolution cells, and for a height image the RMSE, bias and valid "
        "fraction of its heights against the scene's [surface].  Method: a chip of +-12 "
        "theoretical IRWs is upsampled x16 (band-limited, FFT zero-padding, each axis about "
        "its spectral centre: a squinted image's Doppler centroid and range band, from its "
        "configuration) around the peak, refined exactly; the mainlobe runs between the first"
        " nulls (the first minima walking outward from the half-power crossings); PSLR: the "
        "highest sidelobe outside it, anywhere in the cut (none, null, under -100 dB: "
        "rounding); ISLR: the energy within +-10 IRWs on both axes outside the null-to-null "
        "rectangle over the energy inside it (-7.0 dB for an unweighted sinc in both axes; "
        "each 1-D cut alone: -9.7 dB).  Found points: local maxima within +-1.5 IRWs, one per"
        " peak, --contrast-db above the 90th percentile of the +-8 and +-4 cells around them "
        "(off their own cuts), within --threshold-db of the brightest pixel, and, within 4 "
        "cells of a brighter point, within 10 dB of it.  Notes per point say when a cut has "
        "no sidelobe, when another point lies on a cut or in the ISLR region (its PSLR/ISLR "
        "are then that point's), when the image edge cuts a cut or the region short, when the"
        " ISLR stands 10 dB over its theory with no point near (it measures the clutter about"
        " the point), and when an instrument's fixed receive window held only part of the "
        "echo's chirp (its range width then exceeds the theory's).  Exit status 1 when "
        "nothing was measured.",
    )
    s.add_argument("image", help="image file from process, run -o or subscribe -o (.h5)")
    s.add_argument(
        "--scene", help="the scene file (or built-in name) it was made from: truth to compare"
    )
    s.add_argument(
        "--at",
        action="extend",
        nargs="+",
        metavar="X,R",
        help="measure the brightest pixel within 2 resolution cells of along track X, slant "
        "range R (metres) instead of finding points; several positions after one --at, or "
        "--at repeated; a negative X as it is (--at -0.005,1.5)",
    )
    # "-0.005,1.5" is a position, not an option: argparse takes only a bare negative number so
    # (a review: --at -0.005,1.5 said "expected at least one argument")
    if hasattr(s, "_negative_number_matcher"):
        s._negative_number_matcher = NEGATIVE_POSITION
    s.add_argument("--json", metavar="OUT", help="also write the report as JSON")
    s.add_argument(
        "--threshold-db",
        type=float,
        default=-30.0,
        help="found points: within this many dB of the brightest pixel (default -30)",
    )
    s.add_argument(
        "--contrast-db",
        type=float,
        default=20.0,
        help="found points: this many dB above the 90th percentile of the power around them, "
        "off their own cuts (default 20; lower it for points beside bright clutter)",
    )
    s.add_argument(
        "--max-points", type=int, default=20, help="found points: the brightest N (default 20)"
    )
    s.set_defaults(func=cmd_measure)

    s = sub.add_parser(
        "bench",
        description="Not a test: measures pulses/s of the AO lens (OpenCL vs the same plan on "
        "NumPy's and SciPy's FFT, one bare FFT of the batch, and the plan's bare FFT pair on two "
        "threads as the yardstick) and of the correlators, and "
        "the live pipeline end to end (real-time factor, drops, latency; threads and two "
        "swath processes; latency against the offered rate, 25-150 % of the PRF, with the "
        "granularity a live run chooses), in one run, as ratios.  About 4 minutes on 2 "
        "cores (268 s on 2026-11-28; --preset P: about half).",
    )
    bench.add_arguments(s)
    s.set_defaults(func=bench.run_bench)

    s = sub.add_parser(
        "tradeoff",
        description="Varies each processor knob alone from the preset's defaults (precision, "
        "correlator mode and block, micro-batch, aperture, windows, lens, mask per range bin, "
        "range migration, physical CCD) and each correction on scenes whose targets stress it; "
        "measures image error against a float64 reference, IRW/PSLR/ISLR/position of point "
        "targets, pulses/s and the line latency at the PRF, in one run.  Writes JSON, Markdown "
        "and a Pareto plot (PNG).  Not a test: about 6 minutes on 2 cores (--quick: about a "
        "minute).",
    )
    tradeoff.add_arguments(s)
    s.set_defaults(func=tradeoff.run)

    s = sub.add_parser(
        "table1",
        description="Builds Table 1 of Psaltis & Wagner (1981) from the physical CCD/AO-cell "
        "emulation: range resolution and cells (halved with the carrier in range), azimuth "
        "resolution L/N (N halved with the carrier in azimuth), and the dynamic range measured "
        "on emulated images (largest undistorted point target / noise floor of an empty scene), "
        "beside the paper's values.  About 6 s on 2 cores (5.9 s on 2026-11-30).",
    )
    table1.add_arguments(s)
    s.set_defaults(func=table1.run)
