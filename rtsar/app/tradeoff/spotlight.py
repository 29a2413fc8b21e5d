"""Spotlight rows of ``rtsar tradeoff``: polar format variants against exact backprojection.

Scene: crouch-spotlight scaled down (rtsar.spot.scene.reduced_spotlight: the same chirp rate,
carrier and 4.6 m arc; fewer samples per shot and coarser steps, Crouch's 5° sweep), point
targets on rings around the scene centre.  Reference: the exact float64 backprojection sum over
the same spectral aperture and window (rtsar.spot.backprojection.backproject_exact), evaluated on
a 9 x 9 pixel patch around each target.  Per variant and ring: the largest error on the patch in
dB re the reference peak (PFA's planar-wavefront error grows with the distance from the centre),
IRW against 0.886·λ/2Δθ and 0.886·c/2B, PSLR, position error in cells; and the time per image
(best of ``repeats`` passes, after a warm-up, interleaved with the other variants).  Variants:
PFA with the chirp-z range zoom (default), with a 24-tap sinc range interpolation, without the
curvature phase, at 1 and 4 pixels per cell; fast backprojection with 4x and 16x upsampled
profiles.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ...analysis.point_target import analyse_point_target
from ...spot.backprojection import backproject, backproject_exact
from ...spot.geometry import cross_range_resolution_m
from ...spot.pfa import PfaSettings, PolarFormatPlan, polar_format
from ...spot.scene import reduced_spotlight, spot_points
from ...spot.simulate import SpotlightSimulator

CHIP = 24  # pixels each way around a target for the point-target analysis
VARIANTS = (
    ("pfa czt", "pfa", {}),
    ("pfa sinc", "pfa", {"range_interpolation": "sinc"}),
    ("pfa czt, no curvature phase", "pfa", {"curvature_phase": False}),
    ("pfa czt, 1 px/cell", "pfa", {"oversampling": 1.0}),
    ("pfa czt, 4 px/cell", "pfa", {"oversampling": 4.0}),
    ("backprojection x4", "bp4", {}),
    ("backprojection x16", "bp16", {}),
)


def _targets(radius_m: float) -> np.ndarray:
    rings = (0.0, 0.25, 0.5, 0.75, 0.95)
    return np.array(
        [
            [f * radius_m * math.cos(1.1 + 2.2 * i), f * radius_m * math.sin(1.1 + 2.2 * i), 0]
            for i, f in enumerate(rings)
        ]
    )


def _chip(plan, xy, half):
    i = int(np.argmin(np.abs(plan.x_m - xy[0])))
    j = int(np.argmin(np.abs(plan.y_m - xy[1])))
    return slice(max(i - half, 0), i + half + 1), slice(max(j - half, 0), j + half + 1)


def run_spotlight(
    quick: bool = False, repeats: int = 2, log=None, size: tuple | None = None, variants=VARIANTS
) -> tuple[list[dict], dict]:
    """Measure every variant → (rows, scene description); ``size`` = (samples per shot,
    alias-free extent m, sweep °) overrides the scene's scale; ``variants`` a subset of
    VARIANTS.

    PFA forms its whole image (timed); backprojection is evaluated on a chip of
    (2·CHIP + 1)² pixels around each target and its time scaled to the PFA image's pixel count
    (its cost is proportional to pixels x shots; the rows say "extrapolated")."""
    samples, extent, sweep = size or ((64, 3.2e-3, 2.5) if quick else (512, 20e-3, 5.0))
    cfg, geo = reduced_spotlight(samples, extent, sweep)
    radius = 0.4 * min(extent, samples * cfg.waveform.range_resolution_m)
    targets = _targets(radius)
    data = SpotlightSimulator(spot_points(cfg, geo, targets)).block()[0]
    lam = cfg.geometry.wavelength_m
    rho_x = 0.886 * cross_range_resolution_m(lam, geo.sweep_rad)
    rho_y = 0.886 * cfg.waveform.range_resolution_m
    box = (2.2 * radius, 2.2 * radius)
    rows, refs, runs = [], {}, []
    for name, method, knobs in variants:
        settings = PfaSettings(extent_m=box, **knobs)
        plan = PolarFormatPlan(cfg, geo, settings=settings)
        chips = [_chip(plan, plan.to_frame(p)[0], CHIP) for p in targets]
        runs.append((name, method, settings, plan, chips))

    def form(method, plan, chips):
        """One timed pass: the variant's image (PFA) or its chips (backprojection)."""
        n, pts = geo.pulses, plan.scene_points()
        if method == "pfa":
            image = polar_format(data, plan)
            return [image[c] for c in chips]
        up = int(method[2:])
        # one call for every chip: the per-shot work (the profile FFT) is shared
        flat = np.concatenate([pts[c].reshape(-1, 3) for c in chips])
        vals = backproject(data, cfg, geo, flat, "main", plan.polar_weights(0, n), 0, up)
        images, at = [], 0
        for c in chips:
            shape = pts[c].shape[:2]
            chip = vals[at : at + shape[0] * shape[1]].reshape(shape)
            images.append(plan.baseband(chip, 0, n, c))
            at += shape[0] * shape[1]
        return images

    # Warm-up (JIT, FFT plans), then interleaved rounds in a rotating order, so neither the
    # first variant's compilation nor a change in the machine's load favours one variant.
    formed = [form(method, plan, chips) for _, method, _, plan, chips in runs]
    passes: list[list[float]] = [[] for _ in runs]
    for r in range(repeats):
        order = list(range(len(runs)))
        for i in order[r % len(order) :] + order[: r % len(order)]:
            _, method, _, plan, chips = runs[i]
            t0 = time.perf_counter()
            form(method, plan, chips)
            passes[i].append(time.perf_counter() - t0)
    for (name, method, settings, plan, chips), images, timed in zip(
        runs, formed, passes, strict=True
    ):
        n = geo.pulses
        pts = plan.scene_points()
        pixels = pts.shape[0] * pts.shape[1]
        best = min(timed)
        spread = (sorted(timed)[1] - best) / best if len(timed) > 1 else 0.0
        if method != "pfa":
            best *= pixels / sum(im.size for im in images)
        ring_rows = []
        for p, c, img in zip(targets, chips, images, strict=True):
            xy = plan.to_frame(p)[0]
            xs, ys = plan.x_m[c[0]], plan.y_m[c[1]]
            inner = _chip(plan, xy, 4)
            key = (settings.oversampling, inner[0].start, inner[1].start)
            if key not in refs:
                weights = plan.polar_weights(0, n)
                exact = backproject_exact(data, cfg, geo, pts[inner], "main", weights)
                refs[key] = plan.baseband(exact, 0, n, inner)
            ref = refs[key]
            local = (
                slice(inner[0].start - c[0].start, inner[0].stop - c[0].start),
                slice(inner[1].start - c[1].start, inner[1].stop - c[1].start),
            )
            err_db = 20 * math.log10(np.max(np.abs(img[local] - ref)) / np.max(np.abs(ref)))
            search = max(0.3 * rho_y, 1.5 * max(plan.dx, plan.dy))
            rep = analyse_point_target(img, xs, ys, xy[0], xy[1], search)
            ring_rows.append(
                {
                    "radius_m": float(np.hypot(*p[:2])),
                    "error_db": err_db,
                    "x_irw_ratio": rep.azimuth.irw_m / rho_x,
                    "y_irw_ratio": rep.range.irw_m / rho_y,
                    "x_pslr_db": rep.azimuth.pslr_db,
                    "y_pslr_db": rep.range.pslr_db,
                    "position_error_cells": max(
                        abs(rep.azimuth_m - xy[0]) / rho_x, abs(rep.range_m - xy[1]) / rho_y
                    ),
                }
            )
        rows.append(
            {
                "variant": name + ("" if method == "pfa" else " (time extrapolated)"),
                "default": name == "pfa czt",
                "seconds_per_image": best,
                "spread": spread,  # second fastest pass over the fastest, less one
                "us_per_shot": 1e6 * best / geo.pulses,
                "pixels": int(pixels),
                "rings": ring_rows,
            }
        )
        if log:
            worst = max(r["error_db"] for r in ring_rows)
            log(
                f"[spotlight] {name}: {best:.2f} s per image (passes ±{100 * spread:.0f} %), "
                f"worst ring error {worst:.1f} dB"
            )
    scene = {
        "description": f"crouch-spotlight scaled: {samples} samples/shot, {geo.pulses} shots "
        f"over {sweep}°, targets on rings to {1e3 * radius:.2f} mm; ρx {1e6 * rho_x:.2f} µm, "
        f"ρy {1e6 * rho_y:.2f} µm; reference: exact backprojection, same aperture",
        "rings_m": [float(np.hypot(*p[:2])) for p in targets],
    }
    return rows, scene


def spotlight_markdown(rows: list[dict], scene: dict) -> str:
    rings = scene["rings_m"]
    head = " | ".join(f"err @ {1e3 * r:.2f} mm [dB]" for r in rings)
    out = [
        f"**spotlight**: {scene['description']}\n",
        f"| variant | s / image | µs / shot | pixels | {head} | x / y IRW ratio (worst) | "
        "x / y PSLR [dB] (worst) | pos. error [cells] |",
        "|" + "---|" * (7 + len(rings)),
    ]
    for r in rows:
        rr = r["rings"]
        name = f"**{r['variant']}**" if r["default"] else r["variant"]
        errs = " | ".join(f"{x['error_db']:.1f}" for x in rr)
        out.append(
            f"| {name} | {r['seconds_per_image']:.3f} (±{100 * r.get('spread', 0.0):.0f} %) | "
            f"{r['us_per_shot']:.0f} | {r['pixels']} | "
            f"{errs} | {max(x['x_irw_ratio'] for x in rr):.3f} / "
            f"{max(x['y_irw_ratio'] for x in rr):.3f} | "
            f"{max(x['x_pslr_db'] for x in rr):.1f} / {max(x['y_pslr_db'] for x in rr):.1f} | "
            f"{max(x['position_error_cells'] for x in rr):.3f} |"
        )
    return "\n".join(out) + "\n"
