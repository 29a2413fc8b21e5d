"""InSAL at Zhao's geometry: ridge and drawing pin height maps, unwrappers, stream continuity.

    python tools/insal_report.py [--lines 96] [--range-bins 96] [--per-cell 2] [--snr-db 10]
                                 [--scenes ridge,pin] [--json FILE] [--png DIR] [-o FILE.md]

Zhao 2014: 1550 nm, 2.4 m, 1.6 mm horizontal baseline at look angle atan √2 (2π per 3.29 mm),
8 mm synthetic aperture (160 pulses, 233 µm), 170 µm range bins.  The FMCW shot is sampled at
1280 Hz (128 samples, a 21.8 mm unambiguous window) rather than the preset's 2560 Hz: same
geometry and resolution, half the simulation time.  Each scene: speckle scatterers on the
surface, receiver noise on both channels, both channels focused by the engine (NumPy lens), then
rtsar.topo.insar.height_map (Zhao steps II-VI).  Acceptance: rms height error on the target
≤ h_2π / 20.  The stream section feeds the ridge's lines, as two engines deliver them, to
rtsar.topo.stream.HeightStripStage and reports the boundary jumps and the stage's rate.
Takes a few minutes (the simulator's scatterer sums dominate).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ...lens.plan import make_plan
from ...scene.relief import default_spacing_m, ridge, sphere_cap, surface_scene, zhao_config
from ...scene.simulator import Simulator
from ...stream.engine import StreamProcessor
from ...topo.insar import height_error, height_map
from ...topo.insar_geometry import InsalGeometry, zhao_ambiguity_height_m
from ...topo.registration import estimate_registration
from ...topo.stream import HeightStripStage
from ..quicklook import height_colour_limits_mm, save_height_quicklook

SURFACES = {
    "ridge": lambda: ridge(2.5e-3, 8e-3),  # Zhao Fig. 3: 2.5 mm total elevation
    "pin": lambda: sphere_cap(5e-3, 1.5e-3),  # Zhao Fig. 4: a drawing pin, 10 mm across
}
METHODS = ("mcf", "ls", "skimage")


def um(value_m):
    """Metres → µm, keeping None (no valid pixel to score)."""
    return None if value_m is None else value_m * 1e6


def fmt(value, spec):
    return "-" if value is None else format(value, spec)


def focus_pair(cfg, ss, batch_rng):
    """Simulate both receivers and focus them with two streaming engines in random batches."""
    t0 = time.perf_counter()
    shots, aux = Simulator(ss.scene).block_with_aux(ss.scene.pulses)
    t_sim = time.perf_counter() - t0
    start = ss.scene.start_along_track_m
    engines = [StreamProcessor(cfg, "numpy", start_along_track_m=start) for _ in range(2)]
    pairs, i = [], 0
    while i < len(shots):
        j = min(len(shots), i + int(batch_rng.integers(1, 24)))
        pairs.append((engines[0].push(shots[i:j]).lines, engines[1].push(aux["rx1"][i:j]).lines))
        i = j
    pairs.append((engines[0].flush().lines, engines[1].flush().lines))
    main = np.concatenate([p[0] for p in pairs])
    slave = np.concatenate([p[1] for p in pairs])
    az = engines[0].azimuth_m(0, len(main))
    return pairs, main, slave, az, engines[0].range_m, t_sim


def scene_report(name, cfg, geo, args, png_dir):
    ss = surface_scene(
        cfg,
        SURFACES[name](),
        args.lines,
        seed=args.seed,
        spacing_m=default_spacing_m(cfg, args.per_cell),
        effects=[
            ("noise", {"snr_db": args.snr_db}),
            ("interferometric_receivers", {"snr_db": args.snr_db}),
        ],
    )
    pairs, main, slave, az, rg, t_sim = focus_pair(cfg, ss, np.random.default_rng(args.seed))
    truth = ss.truth(az, rg)
    raised = truth.scored & (truth.height_m > 0)
    h2pi = float(geo.ambiguity_height_m(float(np.mean(rg))))
    reg = estimate_registration(main, slave)
    expected_rg = float(np.mean(geo.path_difference_m(rg, 0.0))) / 2 / abs(rg[1] - rg[0])
    rows = []
    maps = {}
    variants = [("geometry", m, "gradient") for m in METHODS]
    variants += [("fringes", "mcf", "gradient"), ("fringes", "mcf", "peak")]
    for flat, method, fringe in variants:
        t0 = time.perf_counter()
        hm = height_map(
            main,
            slave,
            geo,
            rg,
            registration=reg,
            flat_earth=flat,
            method=method,
            fringe_method=fringe,
        )
        dt = time.perf_counter() - t0
        e_all = height_error(hm.height_m, hm.valid, truth.height_m, truth.scored)
        e_top = height_error(hm.height_m, hm.valid, truth.height_m, raised)
        rows.append(
            {
                "flat_earth": flat if flat == "geometry" else f"fringes ({fringe})",
                "method": method,
                "rms_um": um(e_all["rms_m"]),
                "rms_raised_um": um(e_top["rms_m"]),
                "bias_um": um(e_all["bias_m"]),
                "max_abs_um": um(e_all["max_abs_m"]),
                "coverage": e_all["coverage"],
                "seconds": dt,
                "pass": e_all["rms_m"] is not None and e_all["rms_m"] <= h2pi / 20,
                "fringe_cycles_per_bin": (
                    None if hm.fringe_ramp is None else hm.fringe_ramp.range_cycles_per_bin
                ),
            }
        )
        maps[(flat, method, fringe)] = hm
    best = maps[("geometry", "mcf", "gradient")]
    if png_dir is not None:
        lim = height_colour_limits_mm(truth.height_m, truth.returns, 0.0)
        save_height_quicklook(
            png_dir / f"{name}_truth.png",
            truth.height_m,
            truth.scored,
            az,
            rg,
            f"{name}: truth on the image grid",
            lim,
        )
        save_height_quicklook(
            png_dir / f"{name}_height.png",
            best.height_m,
            best.valid,
            az,
            rg,
            f"{name}: InSAL height (geometry flat earth, mcf)",
            lim,
        )
        err = np.where(best.valid & truth.scored, best.height_m - truth.height_m, 0.0)
        save_height_quicklook(
            png_dir / f"{name}_error.png",
            err,
            best.valid & truth.scored,
            az,
            rg,
            f"{name}: height error",
            (-h2pi / 20 * 1e3, h2pi / 20 * 1e3),
            "RdBu_r",
        )
    rate = float(np.mean(np.diff(geo.phase_rad(rg, 0.0)))) / (2 * math.pi)
    return {
        "scene": name,
        "targets": len(ss.scene.targets),
        "image": list(main.shape),
        "simulate_s": t_sim,
        "h2pi_mm": h2pi * 1e3,
        "limit_um": h2pi / 20 * 1e6,
        "registration_px": [reg.azimuth_px, reg.range_px],
        "expected_range_px": expected_rg,
        "geometric_fringe_cycles_per_bin": rate,
        "rows": rows,
        "_pairs": pairs,
        "_main": main,
        "_slave": slave,
        "_rg": rg,
        "_reg": reg,
        "_batch": best,
    }


def stream_report(geo, rep, strip_lines, overlap_lines):
    stage = HeightStripStage(
        geo, rep["_rg"], rep["_reg"], strip_lines=strip_lines, overlap_lines=overlap_lines
    )
    strips = []
    for m, s in rep["_pairs"]:
        strips += stage.process(m, s)
    strips += stage.flush()
    h = np.concatenate([s.height_m for s in strips])
    v = np.concatenate([s.valid for s in strips])
    batch = rep["_batch"]
    same = bool(np.array_equal(v, batch.valid))
    return {
        **{k: v for k, v in stage.stats.items()},
        "strip_lines": strip_lines,
        "overlap_lines": overlap_lines,
        "valid_masks_equal_batch": same,
        "max_abs_diff_vs_batch_m": float(np.max(np.abs(h - batch.height_m))),
    }


def stage_rate(geo, range_bins, lines=512, strip_lines=64, overlap_lines=16, seed=0):
    """Lines per second of HeightStripStage on correlated speckle, ``range_bins`` wide."""
    rng = np.random.default_rng(seed)
    rg = 2.4 + (np.arange(range_bins) - range_bins // 2) * 170e-6
    m = rng.standard_normal((lines, range_bins)) + 1j * rng.standard_normal((lines, range_bins))
    noise = rng.standard_normal(m.shape) + 1j * rng.standard_normal(m.shape)
    s = (m + 0.3 * noise) * np.conj(geo.flat_earth_phasor(rg))[None, :]
    out = {}
    for method in METHODS:
        stage = HeightStripStage(
            geo,
            rg,
            estimate_registration(m[:96], s[:96]),
            strip_lines=strip_lines,
            overlap_lines=overlap_lines,
            method=method,
        )
        t0 = time.perf_counter()
        for i in range(0, lines, 32):
            stage.process(m[i : i + 32], s[i : i + 32])
        stage.flush()
        out[method] = lines / (time.perf_counter() - t0)
    return out


def markdown(geo_info, reports, stream, rates) -> str:
    lines = ["# InSAL at Zhao's geometry", ""]
    lines += [f"* {k}: {v}" for k, v in geo_info.items()]
    for rep in reports:
        lines += [
            "",
            f"## {rep['scene']} ({rep['targets']} scatterers, image {rep['image']}, "
            f"simulated in {rep['simulate_s']:.0f} s)",
            "",
            f"h_2π = {rep['h2pi_mm']:.3f} mm, acceptance rms ≤ h_2π/20 = "
            f"{rep['limit_um']:.0f} µm.  "
            f"Registration (azimuth, range) = ({rep['registration_px'][0]:+.3f}, "
            f"{rep['registration_px'][1]:+.3f}) px; geometry predicts range "
            f"{rep['expected_range_px']:+.3f} px.  Geometric flat-earth fringe rate "
            f"{rep['geometric_fringe_cycles_per_bin']:.5f} cycles/bin.",
            "",
            "| flat earth | unwrap | rms µm | rms on raised part µm | bias µm | max µm | coverage "
            "| fringe est. cycles/bin | time s | ≤ h_2π/20 |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rep["rows"]:
            fr = "" if r["fringe_cycles_per_bin"] is None else f"{r['fringe_cycles_per_bin']:.5f}"
            lines.append(
                f"| {r['flat_earth']} | {r['method']} | {fmt(r['rms_um'], '.1f')} | "
                f"{fmt(r['rms_raised_um'], '.1f')} | {fmt(r['bias_um'], '+.1f')} | "
                f"{fmt(r['max_abs_um'], '.0f')} | "
                f"{r['coverage']:.3f} | {fr} | {r['seconds']:.2f} | "
                f"{'yes' if r['pass'] else 'NO'} |"
            )
    if stream:
        lines += ["", "## Stream (ridge lines as two engines deliver them)", ""]
        lines += [f"* {k}: {v}" for k, v in stream.items()]
    if rates:
        lines += ["", "## HeightStripStage rate (lines/s = pulses/s in steady state)", ""]
        lines += [f"* {k}" for k in rates]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--lines", type=int, default=96)
    ap.add_argument("--range-bins", type=int, default=96)
    ap.add_argument("--per-cell", type=float, default=2.0, help="scatterers per resolution cell")
    ap.add_argument("--snr-db", type=float, default=10.0, help="per-sample SNR of each receiver")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--scenes", default="ridge,pin")
    ap.add_argument("--strip-lines", type=int, default=16)
    ap.add_argument("--overlap-lines", type=int, default=4)
    ap.add_argument("--no-rate", action="store_true", help="skip the stage timing")
    ap.add_argument("--json", help="write the numbers here")
    ap.add_argument("--png", help="write quicklooks (truth, height, error) into this folder")
    ap.add_argument("-o", "--output", help="write the Markdown here too")
    args = ap.parse_args(argv)
    cfg = zhao_config(sample_rate_hz=1280.0, aperture_pulses=160, range_bins=args.range_bins)
    try:  # a range window the 1280 Hz shot cannot hold is a usage error, not a traceback
        make_plan(cfg)
    except ValueError as exc:
        ap.error(f"--range-bins {args.range_bins}: {exc}")
    geo = InsalGeometry.from_config(cfg, 1.6e-3)
    png_dir = None
    if args.png:
        png_dir = Path(args.png)
        png_dir.mkdir(parents=True, exist_ok=True)
    theta = math.acos(cfg.geometry.platform_height_m / cfg.geometry.slant_range_m)
    geo_info = {
        "range, look angle from vertical": f"2.4 m, {math.degrees(theta):.2f}°",
        "baseline": "1.6 mm horizontal (one pass, bistatic: transmit on receiver 0)",
        "h_2π exact / λR sinθ/B_⊥": f"{float(geo.ambiguity_height_m(2.4)) * 1e3:.3f} mm / "
        f"{float(geo.ambiguity_height_closed_form_m(2.4)) * 1e3:.3f} mm",
        "Zhao eq. 1 at Φ = 45° (λL0/(B cosΦ))": (
            f"{zhao_ambiguity_height_m(1.55e-6, 2.4, 1.6e-3, math.pi / 4) * 1e3:.3f} mm"
        ),
        "resolution azimuth / range": f"{cfg.azimuth_resolution_m() * 1e6:.0f} µm / "
        f"{cfg.waveform.range_resolution_m * 1e6:.0f} µm",
        "processing": "sub-pixel registration, looks 5 × 3 (az × rg), coherence ≥ 0.3",
    }
    reports = []
    for name in args.scenes.split(","):
        t0 = time.perf_counter()
        reports.append(scene_report(name, cfg, geo, args, png_dir))
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    stream = None
    ridge_rep = next((r for r in reports if r["scene"] == "ridge"), reports[0] if reports else None)
    if ridge_rep is not None:
        stream = stream_report(geo, ridge_rep, args.strip_lines, args.overlap_lines)
    rates = []
    if not args.no_rate:
        for bins in (args.range_bins, 256):
            r = stage_rate(geo, bins)
            rates.append(
                f"{bins} range bins, strips of 64 + 16 overlap: "
                + ", ".join(f"{k} {v:.0f}" for k, v in r.items())
            )
    text = markdown(geo_info, reports, stream, rates)
    print(text)
    if args.output:
        Path(args.output).write_text(text + "\n")
    if args.json:
        clean = [{k: v for k, v in r.items() if not k.startswith("_")} for r in reports]
        Path(args.json).write_text(
            json.dumps(
                {"geometry": geo_info, "scenes": clean, "stream": stream, "rates": rates}, indent=2
            )
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
