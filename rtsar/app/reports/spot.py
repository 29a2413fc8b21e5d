"""Spotlight, bistatic and projective SAL: the issue-15 figures and the pictures of
docs/pages/guide/spotlight.md.

    python tools/spot_report.py [--figures DIR] [--quick]

Printed (Markdown):

* Crouch's bench at full size (crouch-spotlight: 4.6 m arc, 50 µm steps, 1024 samples, the
  5° sweep: 8030 shots): point targets at the centre and 3-6 mm out, PFA (chirp-z, unweighted):
  cross-range and range IRW against 0.886·λ/2Δθ (eq. 9.5) and 0.886·c/2B, PSLR, position error
  in cells, the time to simulate and to form the image; the exact backprojection at the centre
  target (its own IRW, and the PFA error on a 9 x 9 patch, dB);
* the bistatic channel (receiver 8° off, at 4.0 m): IRW and PSLR processed as if monostatic and
  with the bistatic geometry, against the geometry's prediction;
* progressive images: cross-range IRW of the images after 1/8, 1/4, 1/2 and all of the shots
  against 0.886·λ/(2Δθ_so_far);
* projective SAL: a stick through 3-D, rms distance of the reconstructed points to the line.

With ``--figures DIR``: spot_points.png (the built-in spotlight-scene, 5°), spot_bistatic.png
(before/after), spot_progressive.png, spot_projective.png (the 3-D line), spot_*.png only.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...analysis.point_target import analyse_point_target
from ...spot.backprojection import backproject_exact
from ...spot.geometry import cross_range_resolution_m, wavenumbers
from ...spot.pfa import PfaSettings, PolarFormatPlan, ProgressivePolarFormat, polar_format
from ...spot.projective import line_distance_m, reconstruct_line
from ...spot.scene import default_spot_scene, reduced_spotlight, spot_points
from ...spot.simulate import BISTATIC_CHANNEL, SpotlightSimulator
from ..quicklook import file_pyplot, to_db

LAM = 1.55e-6


def _point_rows(img, plan, points, rho_x, rho_y):
    rows = []
    for p in points:
        xy = plan.to_frame(np.asarray(p))[0]
        radius = max(0.3 * rho_y, 0.3 * rho_x, 1.5 * plan.dx, 1.5 * plan.dy)
        rep = analyse_point_target(img, plan.x_m, plan.y_m, xy[0], xy[1], radius)
        rows.append(
            f"| ({1e3 * p[0]:+.1f}, {1e3 * p[1]:+.1f}) mm | {1e6 * rep.azimuth.irw_m:.2f} µm "
            f"({rep.azimuth.irw_m / rho_x:.3f}) | {1e6 * rep.range.irw_m:.2f} µm "
            f"({rep.range.irw_m / rho_y:.3f}) | {rep.azimuth.pslr_db:.2f} / "
            f"{rep.range.pslr_db:.2f} | {abs(rep.azimuth_m - xy[0]) / rho_x:.3f} / "
            f"{abs(rep.range_m - xy[1]) / rho_y:.3f} |"
        )
    return rows


def full_bench(quick: bool) -> tuple[list[str], dict]:
    scene = default_spot_scene()
    if quick:
        scene = replace(scene, geometry=replace(scene.geometry, pulses=1001))
    points = np.array([[0, 0, 0], [3e-3, 1e-3, 0], [-4e-3, -4.5e-3, 0], [6e-3, -3e-3, 0]])
    scene = spot_points(scene.config, scene.geometry, points, name="bench")
    cfg, geo = scene.config, scene.geometry
    t0 = time.perf_counter()
    data = SpotlightSimulator(scene).block()[0]
    t_sim = time.perf_counter() - t0
    plan = PolarFormatPlan(cfg, geo, settings=PfaSettings(extent_m=(14e-3, 11e-3)))
    t0 = time.perf_counter()
    img = polar_format(data, plan)
    t_pfa = time.perf_counter() - t0
    rho_x = 0.886 * cross_range_resolution_m(LAM, geo.sweep_rad)
    rho_y = 0.886 * cfg.waveform.range_resolution_m
    out = [
        f"**Crouch's bench** (crouch-spotlight, {geo.pulses} shots x 1024 samples, sweep "
        f"{math.degrees(geo.sweep_rad):.3f}°): 0.886·λ/2Δθ = {1e6 * rho_x:.2f} µm, 0.886·c/2B = "
        f"{1e6 * rho_y:.2f} µm; simulated in {t_sim:.1f} s, PFA image "
        f"{len(plan.x_m)} x {len(plan.y_m)} px in {t_pfa:.1f} s\n",
        "| target | x IRW (ratio) | y IRW (ratio) | PSLR x / y [dB] | pos. error x / y [cells] |",
        "|---|---|---|---|---|",
        *_point_rows(img, plan, points, rho_x, rho_y),
    ]
    xy = plan.to_frame(points[0])[0]
    i = int(np.argmin(np.abs(plan.x_m - xy[0])))
    j = int(np.argmin(np.abs(plan.y_m - xy[1])))
    sl = (slice(i - 4, i + 5), slice(j - 4, j + 5))
    t0 = time.perf_counter()
    w = plan.polar_weights(0, geo.pulses)
    ref = backproject_exact(data, cfg, geo, plan.scene_points()[sl], weights=w)
    ref = plan.baseband(ref, 0, geo.pulses, sl)
    t_bp = time.perf_counter() - t0
    err = 20 * math.log10(np.max(np.abs(img[sl] - ref)) / np.max(np.abs(ref)))
    out.append(
        f"\nExact backprojection on the 9 x 9 px around the centre target: {t_bp:.1f} s "
        f"({1e6 * t_bp / ref.size:.0f} µs per pixel, "
        f"i.e. {t_bp / ref.size * img.size / 3600:.1f} h "
        f"for the whole image); PFA error there {err:.1f} dB re peak.\n"
    )
    return out, {"scene": scene, "plan": plan, "image": img}


def bistatic_rows() -> list[str]:
    beta = math.radians(8.0)
    cfg, geo = reduced_spotlight(64, 3.2e-3, 5.0, bistatic_range_m=4.0, bistatic_angle_rad=beta)
    p = [6e-4, -5e-4, 0.0]
    shots = SpotlightSimulator(spot_points(cfg, geo, [p])).block()[1][BISTATIC_CHANNEL]
    th = geo.angles_rad()
    g = 2 * np.cos(0.5 * (th - beta))
    k_c, dk = wavenumbers(cfg.waveform, LAM)
    irw_y = 0.886 * 2 * math.pi / (g.min() * (k_c + 31 * dk) - g.max() * (k_c - 32 * dk))
    irw_x = 0.886 * LAM / (geo.sweep_rad * math.cos(0.5 * beta))
    out = [
        f"**Bistatic** (receiver 8° off at 4.0 m; scaled bench, 5°, point at (0.6, -0.5) mm): "
        f"predicted x IRW 0.886·λ/(Δθ cos(β/2)) = {1e6 * irw_x:.2f} µm, y IRW "
        f"0.886·2π/Δk_y(inscribed) = {1e6 * irw_y:.2f} µm (0.886·c/(2B cos(β/2)) = "
        f"{1e6 * 0.886 * cfg.waveform.range_resolution_m / math.cos(beta / 2):.2f} µm before the "
        "inscribed rectangle's loss)\n",
        "| processing | x IRW [µm] | y IRW [µm] | PSLR x / y [dB] | position error [µm] |",
        "|---|---|---|---|---|",
    ]
    images = {}
    for look in ("monostatic", "exact"):
        plan = PolarFormatPlan(
            cfg, geo, BISTATIC_CHANNEL, PfaSettings(extent_m=(3e-3, 2.5e-3)), look=look
        )
        img = polar_format(shots, plan)
        rep = analyse_point_target(img, plan.x_m, plan.y_m)
        xy = plan.to_frame(np.asarray(p))[0]
        err = math.hypot(rep.azimuth_m - xy[0], rep.range_m - xy[1])
        name = "as if monostatic" if look == "monostatic" else "bistatic geometry (corrected)"
        out.append(
            f"| {name} | {1e6 * rep.azimuth.irw_m:.2f} | {1e6 * rep.range.irw_m:.2f} | "
            f"{rep.azimuth.pslr_db:.1f} / {rep.range.pslr_db:.1f} | {1e6 * err:.1f} |"
        )
        images[look] = (img, plan)
    return out + [""], images


def progressive_rows():
    cfg, geo = reduced_spotlight(64, 3.2e-3, 5.0)
    data = SpotlightSimulator(spot_points(cfg, geo, [[0, 0, 0]])).block()[0]
    plan = PolarFormatPlan(cfg, geo, settings=PfaSettings(extent_m=(1e-3, 1e-3)))
    stream = ProgressivePolarFormat(plan)
    out = ["**Progressive images** (scaled bench, 5°): x IRW of the image of the shots so far\n"]
    out += ["| shots | Δθ so far | x IRW [µm] | 0.886·λ/2Δθ [µm] |", "|---|---|---|---|"]
    cuts, snaps = [geo.pulses // 8, geo.pulses // 4, geo.pulses // 2, geo.pulses], []
    for c in cuts:
        stream.push(data[stream.count : c])
        img = stream.image()
        rep = analyse_point_target(img, plan.x_m, plan.y_m)
        pred = 0.886 * cross_range_resolution_m(LAM, stream.sweep_rad())
        out.append(
            f"| {c} | {math.degrees(stream.sweep_rad()):.3f}° | {1e6 * rep.azimuth.irw_m:.2f} | "
            f"{1e6 * pred:.2f} |"
        )
        snaps.append((c, img))
    return out + [""], (plan, snaps)


def projective_rows():
    cfg, geo = reduced_spotlight(64, 3.2e-3, 1.0)
    plan = PolarFormatPlan(cfg, geo, settings=PfaSettings(extent_m=(2e-3, 2e-3)))
    rng = np.random.default_rng(3)
    p0, p1 = np.array([-4e-4, -6e-4, -3e-4]), np.array([5e-4, 6e-4, 4e-4])
    pos = p0 + np.linspace(0, 1, 120)[:, None] * (p1 - p0)
    amp = np.exp(2j * math.pi * rng.random(len(pos)))
    imgs = []
    for rot in (0.0, 0.5 * math.pi):
        d = SpotlightSimulator(spot_points(cfg, geo, pos, amp, rotation_rad=rot)).block()[0]
        imgs.append(polar_format(d, plan))
    rec = reconstruct_line(imgs[0], imgs[1], plan.x_m, plan.y_m, 0.0, 0.5 * math.pi)
    dist = line_distance_m(rec.points_m, p0, p1)
    cell = 0.886 * cross_range_resolution_m(LAM, geo.sweep_rad)
    out = [
        f"**Projective SAL** (scaled bench, 1°: cells {1e6 * cell:.1f} x "
        f"{1e6 * 0.886 * cfg.waveform.range_resolution_m:.1f} µm): a rough stick of 120 "
        f"scatterers from {1e3 * p0} to {1e3 * p1} mm, two images a quarter turn apart: "
        f"{rec.summary()}; rms distance to the true line {1e6 * np.sqrt(np.mean(dist**2)):.1f} µm, "
        f"largest {1e6 * dist.max():.1f} µm\n"
    ]
    return out, (rec, p0, p1)


def _figures(folder: Path, bench, bistatic_images, progressive, projective) -> None:
    plt = file_pyplot()
    folder.mkdir(parents=True, exist_ok=True)

    def show(ax, img, plan, title, db=40):
        art = ax.imshow(
            to_db(img, db).T,
            origin="lower",
            cmap="gray",
            extent=[1e3 * plan.x_m[0], 1e3 * plan.x_m[-1], 1e3 * plan.y_m[0], 1e3 * plan.y_m[-1]],
            aspect="equal",
        )
        ax.set_xlabel("cross-range x (mm)")
        ax.set_ylabel("down-range y (mm)")
        ax.set_title(title, fontsize=9)
        return art

    plan, img = bench["plan"], bench["image"]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.6))
    fig.colorbar(
        show(axes[0], img, plan, "spotlight PFA, 5° sweep: four points (40 dB)"),
        ax=axes[0],
        label="dB re peak",
    )
    i = int(np.argmin(np.abs(plan.x_m)))
    j = int(np.argmin(np.abs(plan.y_m)))
    sl = (slice(i - 25, i + 26), slice(j - 10, j + 11))
    zoom = img[sl]
    axes[1].imshow(
        to_db(zoom, 40).T,
        origin="lower",
        cmap="gray",
        extent=[
            1e6 * plan.x_m[sl[0]][0],
            1e6 * plan.x_m[sl[0]][-1],
            1e6 * plan.y_m[sl[1]][0],
            1e6 * plan.y_m[sl[1]][-1],
        ],
        aspect="equal",
    )
    axes[1].set_xlabel("cross-range x (µm)")
    axes[1].set_ylabel("down-range y (µm)")
    axes[1].set_title("centre point: ρx < 10 µm, ρy 44 µm", fontsize=9)
    fig.tight_layout()
    fig.savefig(folder / "spot_points.png", dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(1, 2, figsize=(9.6, 4.2), layout="constrained")
    for ax, look, title in zip(
        axes,
        ("monostatic", "exact"),
        ("bistatic, as if monostatic", "bistatic geometry"),
        strict=True,
    ):
        im, pl = bistatic_images[look]
        art = show(ax, im, pl, title)
    fig.colorbar(art, ax=list(axes), shrink=0.8, label="dB re each image's peak")
    fig.savefig(folder / "spot_bistatic.png", dpi=100)
    plt.close(fig)

    plan, snaps = progressive
    fig, axes = plt.subplots(
        1, len(snaps), figsize=(3 * len(snaps) + 0.8, 3.4), layout="constrained"
    )
    for ax, (c, im) in zip(axes, snaps, strict=True):
        art = show(ax, im, plan, f"after {c} shots")
    fig.colorbar(art, ax=list(axes), shrink=0.8, label="dB re each image's peak")
    fig.savefig(folder / "spot_progressive.png", dpi=100)
    plt.close(fig)

    rec, p0, p1 = projective
    fig = plt.figure(figsize=(6, 5))
    ax = fig.add_subplot(projection="3d")
    p = 1e3 * rec.points_m
    ax.scatter(p[:, 0], p[:, 1], p[:, 2], c=p[:, 2], cmap="viridis", s=14, label="reconstructed")
    line = 1e3 * np.stack([p0, p1])
    ax.plot(line[:, 0], line[:, 1], line[:, 2], "r-", lw=1, label="true stick")
    ax.set_xlabel("cross-range x (mm)")
    ax.set_ylabel("down-range y (mm)")
    ax.set_zlabel("z (mm)")
    ax.legend(fontsize=8)
    ax.set_title("projective SAL: a stick from two images a quarter turn apart", fontsize=9)
    fig.savefig(folder / "spot_projective.png", dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--figures", help="folder for the spot_*.png pictures")
    ap.add_argument("--quick", action="store_true", help="1001 shots (0.6°) instead of 5°")
    args = ap.parse_args(argv)
    lines, bench = full_bench(args.quick)
    print("\n".join(lines), flush=True)
    bi, bi_images = bistatic_rows()
    print("\n".join(bi), flush=True)
    pr, progressive = progressive_rows()
    print("\n".join(pr), flush=True)
    pj, projective = projective_rows()
    print("\n".join(pj), flush=True)
    if args.figures:
        _figures(Path(args.figures), bench, bi_images, progressive, projective)
        print(f"wrote the spot_*.png figures to {args.figures}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
