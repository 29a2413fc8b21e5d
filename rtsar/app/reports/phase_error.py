"""Platform phase errors and their corrections: the figures of the closing note (Markdown).

    python tools/phase_error_report.py [--quick] [--json FILE]

* Phase-to-retro (Crouch ch. 4) on crouch-sal (N = 2048, Crouch's own geometry) with a piston
  error of Crouch Fig. 20's size (hundreds of radians, fast content on top), with and without
  along-track jitter (Crouch eq. 4.13, Δ = 2.5 µm) for a target 5 mm from the retro.
* Reference-region correction (INO patent, eqs. 5-11) on zhao-insal (N = 160): common error α of
  ~10 µm (over 100 rad on the target) and a roll β, reference regions of 32, 64 and 128 range
  bins, three speckle/error seeds each; α and β against the truth in units of λ, the targets
  focused through the stream (stage → lens → CCD) in micro-batches.
* Every case: residual phase error rms (rad) against the injected truth, azimuth IRW / PSLR of
  the point targets against the error-free focus of the same scene, and the correction's cost in
  pulses/s at the preset size (one timing, numbers depend on the machine).
``--quick`` uses N = 512 for crouch-sal and one seed of the reference region (much faster).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from ...analysis import analyse_point_target
from ...analysis.phase_residual import constant_removed_rms_rad
from ...ccd import make_correlator
from ...ccd.base import design_mask
from ...focus.pra import PhaseToRetro
from ...focus.reference_region import ReferenceGeometry, ReferenceRegionCorrector
from ...lens.numpy_lens import NumpyLens
from ...lens.plan import make_plan, range_axis_m
from ...phase import wrap
from ...presets import preset
from ...scene import Simulator, point_scene

MICRO_BATCH = 64


def aperture_residual_rms_rad(cfg, estimate, truth, start_m, along_track_m) -> float:
    """rms of estimate - truth over the pulses that image a target at ``along_track_m``, after
    removing a constant and a slope (they only shift the image): the part that defocuses."""
    n, step = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    first = int(round((along_track_m - start_m) / step - 0.5 * (n - 1)))
    d = np.unwrap(wrap(np.asarray(estimate) - truth)[first : first + n])
    t = np.arange(len(d))
    fit = np.polyval(np.polyfit(t, d, 1), t)
    return float(np.sqrt(np.mean((d - fit) ** 2)))


def focus_stream(cfg, shots, start_m, raw_stage=None, aux=None, line_stage=None):
    """Micro-batches through [raw_stage] → AO lens (NumPy) → [line_stage] → CCD (as the stream).

    Returns (image, azimuth_m, range_m, per-batch estimates of the stage that has them)."""
    plan = make_plan(cfg)
    p = cfg.processor
    lens = NumpyLens(plan)
    ccd = make_correlator(
        p.correlator,
        design_mask(cfg, plan.range_m),
        p.fft_length,
        partition_lines=p.partition_lines,
    )
    parts, est = [], []
    for i in range(0, len(shots), MICRO_BATCH):
        s = shots[i : i + MICRO_BATCH]
        if raw_stage is not None:
            s = raw_stage.process(s, {k: v[i : i + MICRO_BATCH] for k, v in aux.items()})
            est.append(raw_stage.last_target_phase_rad)
        lines = lens.compress(s)
        if line_stage is not None:
            lines = line_stage.process(lines)
            est.append(line_stage.last_phase_error_rad)
        parts.append(ccd.push(lines))
    parts.append(ccd.flush())
    img = np.concatenate(parts)
    n, step = p.aperture_pulses, cfg.geometry.along_track_step_m
    az = start_m + (np.arange(len(img)) + 0.5 * (n - 1)) * step
    return img, az, plan.range_m, (np.concatenate(est) if est else None)


def azimuth_metrics(cfg, img, az, rg, targets):
    out = []
    for x, r in targets:
        rep = analyse_point_target(
            img, az, rg, near_azimuth_m=x, near_range_m=r,
            search_radius_m=(4 * cfg.azimuth_resolution_m(r), 3 * cfg.waveform.range_resolution_m),
            chip=48,
        )  # fmt: skip
        out.append({"irw_m": rep.azimuth.irw_m, "pslr_db": rep.azimuth.pslr_db,
                    "peak": float(abs(rep.peak_value))})  # fmt: skip
    return out


def _targets_rows(label, cfg, targets, clean, raw, fixed):
    rows = []
    for i, (x, _) in enumerate(targets):
        c, r, f = clean[i], raw[i], fixed[i]
        rows.append({
            "case": label, "target_along_track_m": x,
            "irw_clean_m": c["irw_m"], "irw_raw_m": r["irw_m"], "irw_corrected_m": f["irw_m"],
            "irw_ratio": f["irw_m"] / c["irw_m"],
            "pslr_clean_db": c["pslr_db"], "pslr_raw_db": r["pslr_db"],
            "pslr_corrected_db": f["pslr_db"],
            "pslr_change": (f["pslr_db"] - c["pslr_db"]) / abs(c["pslr_db"]),
            "peak_ratio": f["peak"] / c["peak"],
        })  # fmt: skip
    return rows


def pra_case(quick: bool, jitter_m: float) -> dict:
    n = 512 if quick else 2048
    cfg = preset("crouch-sal").with_processor(aperture_pulses=n, range_bins=128,
                                              range_window="taylor")  # fmt: skip
    g = cfg.geometry
    rm = range_axis_m(cfg)
    dr = rm[1] - rm[0]
    xr, rr = 0.0, rm[40] + 0.3 * dr
    xt, rt = 5e-3 if jitter_m else 1.5e-3, rm[88] + 0.41 * dr
    targets = [(xr, rr), (xt, rt)]
    margin = 120
    start = -(0.5 * (n - 1) + margin) * g.along_track_step_m
    pulses = n + 2 * margin + int(abs(xt) / g.along_track_step_m)
    drift_rad = 0.05 if quick else 1e-2  # hundreds of radians over the scan either way
    piston = ("piston", dict(random_walk_rad=0.3, drift_rad=drift_rad, vibration_rad=3.0,
                             vibration_hz=0.13, white_rad=0.1, seed=7))  # fmt: skip
    effects = [("noise", {"snr_db": -10.0})]
    if jitter_m:
        effects.append(("along_track_jitter", {"std_m": jitter_m, "seed": 5}))

    def shots(extra):
        scene = point_scene(cfg, [xr, xt], [rr, rt], [10.0, 1.0], effects=extra + effects,
                            seed=3, start_along_track_m=start, pulses=pulses)  # fmt: skip
        sim = Simulator(scene)
        return sim, sim.block(pulses)

    _, clean = shots([])
    sim, err = shots([piston])
    truth = sim.effects[0].truth(np.arange(pulses))
    stage = PhaseToRetro(cfg, xr, rr, start)
    img, az, rg, est = focus_stream(cfg, err, start, line_stage=stage)
    fixed = azimuth_metrics(cfg, img, az, rg, targets)
    raw = azimuth_metrics(cfg, *focus_stream(cfg, err, start)[:3], targets)
    ref = azimuth_metrics(cfg, *focus_stream(cfg, clean, start)[:3], targets)
    label = f"PRA, crouch-sal N={n}" + (f", jitter {jitter_m * 1e6:g} µm" if jitter_m else "")
    return {
        "case": label,
        "injected_ptp_rad": float(np.ptp(truth)),
        "injected_rms_rad": float(np.std(truth)),
        "residual_rms_rad": constant_removed_rms_rad(est, truth),
        "aperture_residual_rms_rad": [
            aperture_residual_rms_rad(cfg, est, truth, start, x) for x, _ in targets
        ],
        "shots_not_corrected": stage.shots_not_corrected,
        "targets": _targets_rows(label, cfg, targets, ref, raw, fixed),
    }


def reference_case(seed: int, depth_bins: int) -> dict:
    cfg = preset("zhao-insal").with_processor(range_bins=64, range_window="taylor")
    g = cfg.geometry
    rm = range_axis_m(cfg)
    dr = rm[1] - rm[0]
    targets = [(0.0, rm[32] + 0.37 * dr), (1.2e-3, rm[20] + 0.2 * dr)]
    n = cfg.processor.aperture_pulses
    margin = 48
    start = -(0.5 * (n - 1) + margin) * g.along_track_step_m
    pulses = n + 2 * margin + 30
    params = dict(
        alpha_drift_m=4e-9, alpha_walk_m=1.5e-8, alpha_vibration_m=1e-7, alpha_vibration_hz=0.4,
        roll_walk_rad=5e-7, roll_vibration_rad=1e-5, roll_vibration_hz=0.1, seed=seed,
        scatterers_per_cell=2.0, region_depth_m=depth_bins * cfg.waveform.range_resolution_m,
    )  # fmt: skip
    xs, rs = zip(*targets, strict=True)
    common = dict(seed=1, start_along_track_m=start, pulses=pulses)
    sim = Simulator(point_scene(cfg, xs, rs, effects=[("reference_region", params)], **common))
    main, aux = sim.block_with_aux(pulses)
    clean = Simulator(point_scene(cfg, xs, rs, **common)).block(pulses)
    effect = sim.effects[0]
    geometry = ReferenceGeometry.from_effect(effect)
    p = np.arange(pulses)
    stage = ReferenceRegionCorrector(cfg, geometry)
    alphas, betas = [], []

    class Recorder:  # keeps α, β of every batch beside the stage's target phase
        last_target_phase_rad = None

        def process(self, s, a):
            out = stage.process(s, a)
            alphas.append(stage.last_alpha_m)
            betas.append(stage.last_beta_rad)
            self.last_target_phase_rad = stage.last_target_phase_rad
            return out

    img, az, rg, est = focus_stream(cfg, main, start, raw_stage=Recorder(), aux=aux)
    fixed = azimuth_metrics(cfg, img, az, rg, targets)
    raw = azimuth_metrics(cfg, *focus_stream(cfg, main, start)[:3], targets)
    ref = azimuth_metrics(cfg, *focus_stream(cfg, clean, start)[:3], targets)
    lam = g.wavelength_m
    alpha_err = np.concatenate(alphas) - effect.alpha_m(p)
    beta_err = np.concatenate(betas) - effect.beta_rad(p)
    truth = effect.target_phase_rad(p)
    label = f"reference region, zhao-insal N={n}, {depth_bins} bins, seed {seed}"
    return {
        "case": label,
        "injected_ptp_rad": float(np.ptp(truth)),
        "injected_rms_rad": float(np.std(truth)),
        "alpha_ptp_m": float(np.ptp(effect.alpha_m(p))),
        "roll_path_ptp_m": float(np.ptp(effect.beta_rad(p)) * geometry.D_m),
        "alpha_rms_error_lambda": float(np.std(alpha_err) / lam),
        "beta_rms_error_path_lambda": float(np.std(beta_err) * geometry.D_m / lam),
        "residual_rms_rad": constant_removed_rms_rad(est, truth),
        "aperture_residual_rms_rad": [
            aperture_residual_rms_rad(cfg, est, truth, start, x) for x, _ in targets
        ],
        "pulses_not_estimated": stage.pulses_not_estimated,
        "reference_bins": [int(m.sum()) for m in stage.masks],
        "targets": _targets_rows(label, cfg, targets, ref, raw, fixed),
    }


def _rate(fn, *args) -> float:
    """Pulses per second of fn(*args) → pulses (second of two runs: the first warms up)."""
    fn(*args)
    t0 = time.perf_counter()
    pulses = fn(*args)
    return pulses / (time.perf_counter() - t0)


def _run_pra(cfg, lines, retro_range_m):
    stage = PhaseToRetro(cfg, 0.0, retro_range_m)
    for i in range(0, len(lines), MICRO_BATCH):
        stage.process(lines[i : i + MICRO_BATCH])
    return len(lines)


def _run_reference(cfg, geometry, shots, aux):
    stage = ReferenceRegionCorrector(cfg, geometry)
    for i in range(0, len(shots), MICRO_BATCH):
        stage.process(
            shots[i : i + MICRO_BATCH], {k: v[i : i + MICRO_BATCH] for k, v in aux.items()}
        )
    return len(shots)


def _run_lens(lens, shots):
    for i in range(0, len(shots), MICRO_BATCH):
        lens.compress(shots[i : i + MICRO_BATCH])
    return len(shots)


def costs(pulses: int = 4096) -> list[dict]:
    """Pulses per second of each stage at the full preset sizes, micro-batches of 64 (random
    data: the cost does not depend on the content); the NumPy AO lens for scale."""
    rng = np.random.default_rng(0)

    def noise(shape):
        return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)

    rows = []
    for name in ("crouch-sal", "zhao-insal"):
        cfg = preset(name)
        bins, samples = cfg.processor.range_bins, cfg.waveform.samples_per_shot
        plan = make_plan(cfg)
        lines = noise((pulses, bins))
        lines[:, bins // 2] += 30  # a retro
        shots = noise((pulses, samples))
        aux = {k: noise((pulses, samples)) for k in ("reference_rx1", "reference_rx2")}
        depth_m = 32 * cfg.waveform.range_resolution_m
        geometry = ReferenceGeometry(0.01, 0.05, cfg.geometry.slant_range_m, depth_m)
        rows.append({
            "preset": name, "range_bins": bins, "samples_per_shot": samples,
            "pra_pulses_per_s": _rate(_run_pra, cfg, lines, float(plan.range_m[bins // 2])),
            "reference_region_pulses_per_s": _rate(_run_reference, cfg, geometry, shots, aux),
            "numpy_lens_pulses_per_s": _rate(_run_lens, NumpyLens(plan), shots),
            "prf_hz": cfg.geometry.prf_hz,
        })  # fmt: skip
    return rows


def markdown(cases: list[dict], cost_rows: list[dict]) -> str:
    out = ["### Residual phase error against the injected truth", "",
           "| case | injected ptp / rms [rad] | residual rms, scan [rad] | "
           "residual rms in each target's aperture, mean and slope removed [rad] | "
           "not corrected |", "|---|---|---|---|---|"]  # fmt: skip
    for c in cases:
        miss = c.get("shots_not_corrected", c.get("pulses_not_estimated"))
        aperture = ", ".join(f"{v:.3f}" for v in c["aperture_residual_rms_rad"])
        out.append(f"| {c['case']} | {c['injected_ptp_rad']:.0f} / {c['injected_rms_rad']:.0f} | "
                   f"{c['residual_rms_rad']:.3f} | {aperture} | {miss} |")  # fmt: skip
    out += ["", "### Point targets, azimuth: error-free / uncorrected / corrected", "",
            "| case | target x [mm] | IRW [µm] | IRW ratio | PSLR [dB] | PSLR change | "
            "peak ratio |", "|---|---|---|---|---|---|---|"]  # fmt: skip
    for c in cases:
        for t in c["targets"]:
            out.append(
                f"| {t['case']} | {t['target_along_track_m'] * 1e3:.2f} | "
                f"{t['irw_clean_m'] * 1e6:.1f} / {t['irw_raw_m'] * 1e6:.1f} / "
                f"{t['irw_corrected_m'] * 1e6:.1f} | {t['irw_ratio']:.3f} | "
                f"{t['pslr_clean_db']:.2f} / {t['pslr_raw_db']:.2f} / "
                f"{t['pslr_corrected_db']:.2f} | {100 * t['pslr_change']:+.1f} % | "
                f"{t['peak_ratio']:.3f} |"
            )
    rows = [c for c in cases if "alpha_rms_error_lambda" in c]
    if rows:
        out += ["", "### Reference region: α and β against the truth (rms, mean removed)", "",
                "| case | α ptp [µm] | α error | D·β ptp [µm] | D·β error | bins (S1r, S2r) |",
                "|---|---|---|---|---|---|"]  # fmt: skip
        for c in rows:
            out.append(f"| {c['case']} | {c['alpha_ptp_m'] * 1e6:.1f} | "
                       f"λ/{1 / c['alpha_rms_error_lambda']:.0f} | "
                       f"{c['roll_path_ptp_m'] * 1e6:.2f} | "
                       f"λ/{1 / c['beta_rms_error_path_lambda']:.0f} | "
                       f"{c['reference_bins']} |")  # fmt: skip
        out += ["", f"Goal ≤ λ/20.  Stream: micro-batches of {MICRO_BATCH} shots, each corrected "
                "batch leaves the stage at once (no latency added)."]  # fmt: skip
    out += ["", "### Cost (micro-batches of 64, this machine)", "",
            "| preset | bins / samples | PRA [pulses/s] | reference region [pulses/s] | "
            "NumPy lens [pulses/s] | PRF [Hz] |", "|---|---|---|---|---|---|"]  # fmt: skip
    for r in cost_rows:
        out.append(f"| {r['preset']} | {r['range_bins']} / {r['samples_per_shot']} | "
                   f"{r['pra_pulses_per_s']:.3g} | {r['reference_region_pulses_per_s']:.3g} | "
                   f"{r['numpy_lens_pulses_per_s']:.3g} | {r['prf_hz']:g} |")  # fmt: skip
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--quick", action="store_true", help="crouch-sal with N = 512")
    ap.add_argument("--json", help="also write the figures as JSON here")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    cases = [pra_case(args.quick, 0.0), pra_case(args.quick, 2.5e-6)]
    seeds = (3,) if args.quick else (3, 5, 6)
    depths = (64,) if args.quick else (32, 64, 128)  # speckle error ∝ 1/sqrt(bins)
    cases += [reference_case(seed, bins) for bins in depths for seed in seeds]
    cost_rows = costs()
    print(markdown(cases, cost_rows))
    print(f"\n({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"cases": cases, "costs": cost_rows}, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
