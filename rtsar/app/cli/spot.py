"""Spotlight commands: ``spot-simulate``, ``spotlight`` (batch, replayed or live, progressive
images on ZeroMQ), ``projective`` (two images a quarter turn apart → 3-D points)."""

from __future__ import annotations

import json
import math
import sys
from dataclasses import replace

import numpy as np

from ...sinks.io import replace_when_complete
from ...sinks.publish import DEFAULT_ENDPOINT, ZmqPublisher
from ...spot.pfa import PolarFormatPlan
from ...spot.projective import reconstruct_line, reconstruct_points
from ...spot.scene import load_spot_scene
from ...spot.simulate import BISTATIC_CHANNEL
from .. import spotlight as run
from ..quicklook import file_pyplot, save_figure, save_quicklook, spotlight_words
from .options import die


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "spot-simulate",
        description="Simulate a spotlight scene shot by shot: the Tx/Rx station on an arc about "
        "the scene centre (crouch-spotlight: 4.6 m, 50 µm steps, the crouch-sal chirp), exact "
        "path lengths (Crouch eqs. 9.1-9.2), and the fixed bistatic receiver as channel "
        "'bistatic' when the scene has one.  Scene format: "
        "docs/pages/guide/spotlight.md.",
    )
    s.add_argument(
        "scene", nargs="?", help="spotlight scene (.toml); default: the built-in spotlight-scene"
    )
    s.add_argument("-o", "--output", required=True, help="recording to write (.h5)")
    s.add_argument("--sweep-deg", type=float, help="override the sweep Δθ (default: the scene's)")
    s.add_argument("--rotation-deg", type=float, help="rotation stage angle about the beam axis")
    s.set_defaults(func=cmd_spot_simulate)

    s = sub.add_parser(
        "spotlight",
        description="Form the spotlight image of a recording from `rtsar spot-simulate` (or, "
        "with --live, of a scene simulated as the shots arrive) by the polar format algorithm "
        "with chirp-z spectral zoom (range per shot, then azimuth) or by backprojection.  "
        "With --every K the shots are streamed: every K shots an image of the aperture so far "
        "is formed (resolution w·λ/2Δθ_so_far, w the window's factor: 0.886 unweighted) and "
        "published on the ZeroMQ topic 'spot'; "
        "the last one equals the batch image.",
    )
    s.add_argument(
        "recording",
        nargs="?",
        help="spotlight recording (.h5, or its `rtsar export` as .cphd / .sigmf-meta); omit "
        "with --live",
    )
    s.add_argument("-o", "--output", help="image file to write (.h5, image[x, y])")
    s.add_argument(
        "--live",
        nargs="?",
        const="spotlight-scene",
        metavar="SCENE",
        help="simulate SCENE (default the built-in spotlight-scene) and stream its shots",
    )
    s.add_argument(
        "--channel",
        choices=("main", BISTATIC_CHANNEL),
        default="main",
        help="receive channel (default main; bistatic: the fixed receiver, eq. 9.2b)",
    )
    s.add_argument(
        "--look",
        choices=("exact", "monostatic"),
        default="exact",
        help="exact: the polar grid of the channel's own geometry (default exact), or "
        "monostatic: a bistatic channel processed as if monostatic (the uncorrected image)",
    )
    s.add_argument(
        "--method",
        choices=("pfa", "backprojection"),
        default="pfa",
        help="pfa (default) or backprojection (16x upsampled profiles, exact phase, the same "
        "spectral aperture and window; its cost grows as pixels x shots, about 100x PFA's: "
        "give a small --extent-mm)",
    )
    s.add_argument(
        "--oversampling", type=float, default=2.0, help="pixels per resolution cell (default 2)"
    )
    s.add_argument(
        "--extent-mm",
        type=float,
        nargs=2,
        metavar=("X", "Y"),
        help="image extent, cross-range and range, mm (default: the alias-free extents, at "
        "most 4096 pixels each)",
    )
    s.add_argument(
        "--window", default="rect", help="taper over k_x and k_y: rect (default), hann, taylor"
    )
    s.add_argument(
        "--range-interpolation",
        choices=("czt", "sinc"),
        default="czt",
        help="range zoom per shot: czt (DFT interpolant by chirp-z, default) or sinc (24 taps)",
    )
    s.add_argument(
        "--every",
        type=int,
        metavar="K",
        help="stream: a progressive image every K shots (the first once the shots so far span "
        "a k_x extent common to every range row: at K unless K is very small)",
    )
    s.add_argument(
        "--publish",
        nargs="?",
        const=DEFAULT_ENDPOINT,
        metavar="ENDPOINT",
        help=f"publish the progressive images on topic 'spot' (default {DEFAULT_ENDPOINT})",
    )
    s.add_argument(
        "--wait-subscribers",
        type=int,
        default=0,
        metavar="N",
        help="with --publish: wait (up to 10 s) for N subscribers before the first image "
        "(default 0: do not wait)",
    )
    s.add_argument("--png", help="also write a dB picture of the image (.png)")
    s.set_defaults(func=cmd_spotlight)

    s = sub.add_parser(
        "projective",
        description="Combine two spotlight images of one object, the second taken after the "
        "rotation stage turned it (about the beam axis, a quarter turn: Crouch Fig. 32), into "
        "3-D points: each image gives one cross-range coordinate, both give range.  Scatterers "
        "are associated by range; range cells where that is not unique are reported as "
        "ambiguous, never guessed.  Writes CSV (x_m, y_m, z_m, power_db) and a picture.",
    )
    s.add_argument("images", nargs="*", help="two spotlight images (.h5) from `rtsar spotlight`")
    s.add_argument(
        "--simulate",
        metavar="SCENE",
        help="instead: simulate SCENE (.toml or spotlight-scene) at rotations 0° and 90° and "
        "form both images here",
    )
    s.add_argument("-o", "--output", required=True, help="3-D points to write (.csv)")
    s.add_argument(
        "--rule",
        choices=("points", "line"),
        default="points",
        help="association: points (2-D peaks paired by range, default) or line (one scatterer "
        "per range cell: a stick)",
    )
    s.add_argument(
        "--threshold-db",
        type=float,
        help="peaks kept above this level re the brightest (default -10 points, -15 line)",
    )
    s.add_argument("--png", help="also draw the 3-D points (.png)")
    s.set_defaults(func=cmd_projective)


def cmd_spot_simulate(args) -> int:
    scene = load_spot_scene(args.scene)
    if args.sweep_deg is not None:
        g = scene.geometry
        if not 0 < args.sweep_deg < 60:
            return die(f"--sweep-deg must be in (0, 60), got {args.sweep_deg}")
        pulses = int(round(math.radians(args.sweep_deg) / g.step_rad)) + 1
        scene = replace(scene, geometry=replace(g, pulses=pulses))
    if args.rotation_deg is not None:
        scene = scene.with_rotation(math.radians(args.rotation_deg))
    n, dt = run.timed(run.simulate_to, scene, args.output)
    g = scene.geometry
    bi = " + channel bistatic" if g.bistatic else ""
    print(
        f"wrote {args.output}: {n} shots × {scene.config.waveform.samples_per_shot} samples{bi}, "
        f"sweep {math.degrees(g.sweep_rad):.3f}°, {len(scene.amplitude)} "
        f"target{'' if len(scene.amplitude) == 1 else 's'}, rotation "
        f"{math.degrees(scene.rotation_rad):.1f}°; {1e3 * dt / n:.2f} ms/shot"
    )
    return 0


def cmd_spotlight(args) -> int:
    if (args.recording is None) == (args.live is None):
        return die("give a spotlight recording or --live [SCENE], not both")
    if args.publish and not args.every:
        return die("--publish streams progressive images: give --every K")
    if not (args.output or args.publish or args.png):
        return die("nothing to write: give -o IMAGE.h5, --png or --publish")
    source = None
    if args.live is not None:
        scene = load_spot_scene(args.live)
        config, geometry, rotation = scene.config, scene.geometry, scene.rotation_rad
        blocks = run.live_blocks(scene, args.channel, 64)
    else:
        source = run.SpotRecording(args.recording)
        config, geometry, rotation = source.config, source.geometry, source.rotation_rad
        blocks = source.blocks(args.channel, 256)
    if args.channel == "bistatic" and not geometry.bistatic:
        what = args.recording or f"the scene {args.live or '(built-in)'}"
        return die(
            f"{what} has no bistatic receiver, so no bistatic channel: simulate a scene whose "
            "[spotlight] table sets bistatic_range_m and bistatic_angle_deg "
            "(docs/pages/guide/spotlight.md)"
        )
    try:
        plan = PolarFormatPlan(config, geometry, args.channel, run.settings_from(args), args.look)
        print(run.describe(plan), file=sys.stderr)
        if args.every:
            if args.method != "pfa":
                return die("progressive images (--every) are formed by --method pfa")
            image, dt = run.timed(_stream, blocks, plan, args)
        else:
            data = np.concatenate(list(blocks))
            image, dt = run.timed(run.batch_image, data, plan, args.method)
    finally:
        if source is not None:
            source.close()
    if args.output:
        run.write_spot_image(args.output, image, plan, rotation, method=args.method)
    if args.png:
        save_quicklook(
            args.png,
            image,
            plan.x_m,
            plan.y_m,
            title=spotlight_words(args.channel, args.look, args.method),
            true_aspect=True,
            spotlight=True,
        )
    print(
        f"spotlight image {image.shape} in {dt:.2f} s"
        + (f" → {args.output}" if args.output else "")
        + (f"; wrote {args.png}" if args.png else "")
    )
    return 0


def _stream(blocks, plan, args):
    pub = None
    if args.publish:
        pub = ZmqPublisher(args.publish, delivery="lossless")
        if args.wait_subscribers:
            pub.wait_for_subscribers(args.wait_subscribers, timeout_s=10.0)
    sent = []

    def publish(header, image):
        sent.append(header["shots"])
        if pub is not None:
            pub.send(run.TOPIC, header, np.asarray(image, np.complex64))
        res = header["resolution_m"]
        print(
            f"  image {header['seq']}: {header['shots']} shots, "
            f"Δθ {math.degrees(header['sweep_rad']):.3f}°, ρx {1e6 * res:.2f} µm",
            file=sys.stderr,
        )

    try:
        return run.progressive(blocks, plan, args.every, publish)
    finally:
        if pub is not None:
            pub.send("end", {"images": len(sent), "shots": json.dumps(sent[-1:])})
            pub.close()


def _images_for_projective(args):
    """(image a, image b, x_m, y_m, rotation a, rotation b) from files or a simulation."""
    if args.simulate:
        if args.images:
            raise ValueError("give two images or --simulate SCENE, not both")
        scene = load_spot_scene(args.simulate)
        plan = PolarFormatPlan(scene.config, scene.geometry)
        out = []
        for rot in (0.0, 0.5 * math.pi):
            blocks = run.live_blocks(scene.with_rotation(rot), "main", 256)
            out.append(run.batch_image(np.concatenate(list(blocks)), plan, "pfa"))
        return out[0], out[1], plan.x_m, plan.y_m, 0.0, 0.5 * math.pi
    if len(args.images) != 2:
        raise ValueError("projective needs exactly two spotlight images (or --simulate SCENE)")
    (a, xa, ya, sa), (b, xb, yb, sb) = (run.read_spot_image(p) for p in args.images)
    if a.shape != b.shape or not (np.allclose(xa, xb) and np.allclose(ya, yb)):
        raise ValueError("the two images must share their axes (form both with one geometry)")
    return a, b, xa, ya, float(sa["rotation_rad"]), float(sb["rotation_rad"])


def cmd_projective(args) -> int:
    a, b, x, y, phi_a, phi_b = _images_for_projective(args)
    if args.rule == "line":
        th = -15.0 if args.threshold_db is None else args.threshold_db
        rec = reconstruct_line(a, b, x, y, phi_a, phi_b, th)
    else:
        th = -10.0 if args.threshold_db is None else args.threshold_db
        rec = reconstruct_points(a, b, x, y, phi_a, phi_b, th)
    rows = np.column_stack([rec.points_m, rec.power_db]) if len(rec.points_m) else np.zeros((0, 4))
    with replace_when_complete(args.output) as tmp:
        np.savetxt(tmp, rows, delimiter=",", header="x_m,y_m,z_m,power_db", comments="")
    print(f"wrote {args.output}: {rec.summary()}")
    for y_amb, na, nb in rec.ambiguous[:10]:
        print(
            f"  ambiguous: range {1e3 * y_amb:+.3f} mm holds {na} and {nb} peaks", file=sys.stderr
        )
    if args.png:
        fig = projective_figure(rec.points_m, f"projective SAL: {rec.summary()}")
        save_figure(fig, args.png, dpi=110)
        file_pyplot().close(fig)
    return 0


def projective_figure(points_m: np.ndarray, title: str):
    """3-D points (mm) coloured by z, with a colour bar.  Each axis spans at least a tenth of
    the widest one about its points' centre, and no axis takes an offset: a flat set of points
    (z within 1e-16 mm of 0) shows flat, not as its rounding errors magnified."""
    from matplotlib.ticker import ScalarFormatter

    plt = file_pyplot()
    fig = plt.figure(figsize=(7, 5.5))
    ax = fig.add_subplot(projection="3d")
    p = 1e3 * np.asarray(points_m, np.float64).reshape(-1, 3)
    spans = np.ptp(p, axis=0) if len(p) else np.zeros(3)
    least = 0.1 * max(float(spans.max()), 1e-3)  # 1 µm when every point is one
    limits = []
    for axis in range(3):
        centre = float(np.mean(p[:, axis])) if len(p) else 0.0
        half = 0.55 * max(float(spans[axis]), least)
        limits.append((centre - half, centre + half))
    art = ax.scatter(
        p[:, 0],
        p[:, 1],
        p[:, 2],
        c=p[:, 2],
        cmap="viridis",
        s=14,
        vmin=limits[2][0],
        vmax=limits[2][1],
    )
    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_zlim(*limits[2])
    for a in (ax.xaxis, ax.yaxis, ax.zaxis):
        a.set_major_formatter(ScalarFormatter(useOffset=False))
    ax.set_xlabel("cross-range x (mm)", labelpad=8)
    ax.set_ylabel("down-range y (mm)", labelpad=8)
    ax.set_zlabel("out of plane z (mm)", labelpad=10)
    ax.set_title(title, fontsize=9)
    fig.colorbar(art, ax=ax, label="out of plane z (mm)", shrink=0.65, pad=0.12)
    return fig
