"""Spatial-amplitude-modulation 3D (INO 3D patent) at Zhao's geometry: height error vs eq. 14.

    python tools/sam3d_report.py [--lines 96] [--range-bins 96] [--per-cell 2]
                                 [--snr-db 10,-20,-30,-40] [--mask-phase-rad 0.6]
                                 [--ambiguity-height-mm 3.3] [--scenes ridge,pin,pin_alone]
                                 [--seed 1] [--no-rate]
                                 [--json FILE] [--png DIR] [-o FILE.md]

Geometry: Zhao 2014's 2.4 m at the look angle atan √2 from the vertical (rtsar.scene.surfaces.
zhao_config, as tools/insal_report.py), 233 µm azimuth and 170 µm range resolution; the FMCW
shot is sampled at 1280 Hz (a 21.8 mm window) to halve the simulation.  The masks' angular period
P_φ is chosen for the same 2π height as Zhao's interferometer: h_2π = P_φ R0 sin φ0 = 3.3 mm
(``--ambiguity-height-mm``), so eq. 14 gives Δh = h_2π/20 = 165 µm.  Masks a = b = 0.5 (patent
eq. 1), offset by ``--mask-phase-rad`` from the patent's ideal alignment: a processor that
assumes the ideal (eq. 7 with θ = 0) is biased, one that knows θ or calibrates on a flat
reference (eq. 15) is not.

Scenes (rtsar.scene.surfaces): ``ridge`` (Zhao Fig. 3, 2.5 mm, 8 mm half-width, crest along
track, ground around), ``pin`` (Zhao Fig. 4, a 10 mm dome of 1.5 mm on the ground) and
``pin_alone`` (the same dome, no return around it: the S0 ≈ 0 pixels are masked and counted).
The flat reference of eq. 15 is a separate speckled plane (other seed, 32 lines).  Each scene is
simulated once without noise (effect amplitude_modulation_3d, S0 = main channel); receiver noise
is then added to the raw shots of all three channels exactly as the ``noise`` effect and the
effect's ``snr_db`` define it (σ² = 10^(-SNR/10) per complex sample for a unit scatterer), one
level at a time, so the sweep costs one simulation.  Focusing: the engine, NumPy lens.
Height: rtsar.topo.sam3d.sam_height, looks 5 × 3, coherence ≥ 0.3; the free 2π cycle of the
unwrapped phase is fixed on ``--reference-edge-bins`` range bins at each swath edge, taken to be
known ground (without ground there, as for pin_alone, on the region's median).  A few minutes.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from ...instrument import SAM_CHANNELS
from ...scene.relief import (
    default_spacing_m,
    ridge,
    slanted_plane,
    sphere_cap,
    surface_scene,
    zhao_config,
)
from ...scene.simulator import Simulator
from ...stream.engine import focus_channels, process_block
from ...topo.sam3d import ModulationGeometry, flat_earth_from_reference, sam_height
from ...topo.sam3d_stream import SamPhaseStream
from ..quicklook import height_colour_limits_mm, save_height_quicklook

AMBIGUITY_HEIGHT_MM = 3.3  # Zhao 2014: 2π of interferometric phase per 3.3 mm of height
SURFACES = {
    "ridge": lambda: ridge(2.5e-3, 8e-3),
    "pin": lambda: sphere_cap(5e-3, 1.5e-3),
    "pin_alone": lambda: sphere_cap(5e-3, 1.5e-3, no_return_outside=True),
}
METHODS = ("mcf", "ls", "skimage")
LOOKS = (5, 3)


def add_receiver_noise(shots: np.ndarray, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """Shots plus circular Gaussian noise of variance 10^(-snr/10) (the ``noise`` effect's rule)."""
    if math.isinf(snr_db):
        return shots
    sigma = math.sqrt(0.5 * 10.0 ** (-snr_db / 10.0))
    noise = rng.standard_normal((2, *shots.shape))
    return (shots + sigma * (noise[0] + 1j * noise[1])).astype(np.complex64)


def focused_noise_power(cfg, lines: int, seed: int = 99) -> float:
    """Mean |pixel|² of unit-variance white noise shots through the engine: N0 at SNR 0 dB.

    What an instrument measures with no return; N0 at another SNR scales by 10^(-SNR/10).
    """
    rng = np.random.default_rng(seed)
    shape = (lines + cfg.processor.aperture_pulses - 1, cfg.waveform.samples_per_shot)
    noise = add_receiver_noise(np.zeros(shape, np.complex64), 0.0, rng)
    image, _, _ = process_block(cfg, noise, "numpy")
    return float(np.mean(np.abs(image.astype(np.complex128)) ** 2))


def noise_power_at(n0_unit: float, snr_db: float) -> float:
    return 0.0 if math.isinf(snr_db) else n0_unit * 10.0 ** (-snr_db / 10.0)


def simulate(cfg, surface, lines, args, effect, seed):
    ss = surface_scene(
        cfg,
        surface,
        lines,
        seed=seed,
        spacing_m=default_spacing_m(cfg, args.per_cell),
        effects=[effect],
    )
    t0 = time.perf_counter()
    main, aux = Simulator(ss.scene).block_with_aux(ss.scene.pulses)
    return ss, main, aux, time.perf_counter() - t0


def focus_noisy(cfg, ss, main, aux, snr_db, seed):
    rng = np.random.default_rng(seed)
    noisy = {k: add_receiver_noise(v, snr_db, rng) for k, v in aux.items()}
    (s0, s1, s2), az, rm = focus_channels(
        cfg,
        add_receiver_noise(main, snr_db, rng),
        noisy,
        SAM_CHANNELS,
        "numpy",
        ss.scene.start_along_track_m,
    )
    return s0, s1, s2, az, rm


def score(height_m, valid, truth, geo) -> dict:
    """rms, bias, max |error| on the scored truth pixels the chain kept; coverage of them."""
    kept = truth.scored & valid
    raised = kept & (truth.height_m > 0)
    if not kept.any():
        return {"rms_um": None, "bias_um": None, "max_um": None, "coverage": 0.0}
    err = height_m[kept] - truth.height_m[kept]
    top = height_m[raised] - truth.height_m[raised]
    rms = float(np.sqrt(np.mean(err**2)))
    return {
        "rms_um": rms * 1e6,
        "rms_raised_um": float(np.sqrt(np.mean(top**2))) * 1e6 if top.size else None,
        "bias_um": float(err.mean()) * 1e6,
        "max_um": float(np.abs(err).max()) * 1e6,
        "coverage": float(kept.sum() / max(1, truth.scored.sum())),
        "phase_rms_rad": rms / geo.ambiguity_height_m * 2 * math.pi,
        "pass": rms <= geo.elevation_resolution_m,
    }


def edge_reference(shape, edge_bins: int):
    """Pixels taken to lie on the reference plane: the first and last ``edge_bins`` range bins."""
    if edge_bins <= 0:
        return None
    ref = np.zeros(shape, bool)
    ref[:, :edge_bins] = ref[:, -edge_bins:] = True
    return ref


def chain(images, rm, geo, flat_earth, method, noise_power, reference, height_model="eq13"):
    t0 = time.perf_counter()
    res = sam_height(
        *images,
        rm,
        geo,
        reference_mask=reference,
        flat_earth=flat_earth,
        looks=LOOKS,
        unwrap_method=method,
        height_model=height_model,
        noise_power=noise_power,
    )
    return res, time.perf_counter() - t0


def masks(res) -> dict:
    ph = res.phase
    return {
        "masked_dark": ph.masked_dark,
        "masked_incoherent": ph.masked_incoherent,
        "masked_geometry": ph.masked_geometry,
        "mean_coherence": float(ph.coherence[ph.valid].mean()) if ph.valid.any() else 0.0,
    }


def scene_report(name, cfg, geo_true, geo_naive, references, n0_unit, args, effect, png_dir):
    ss, main, aux, t_sim = simulate(cfg, SURFACES[name](), args.lines, args, effect, args.seed)
    first_snr = args.snr[0]
    out = {
        "scene": name,
        "targets": len(ss.scene.targets),
        "pulses": ss.scene.pulses,
        "simulate_s": t_sim,
        "rows": [],
        "sweep": [],
    }
    for k, snr in enumerate(args.snr):
        s0, s1, s2, az, rm = focus_noisy(cfg, ss, main, aux, snr, args.seed + 1000 + k)
        truth = ss.truth(az, rm)
        out["image"] = list(s0.shape)
        out["no_return_pixels"] = int((~truth.returns).sum())
        fe_ref = references[snr]
        n0 = noise_power_at(n0_unit, snr)
        ref = edge_reference(s0.shape, args.reference_edge_bins)
        if snr == first_snr:
            options = [
                ("eq. 7, θ = 0 assumed", geo_naive, "geometry", "mcf"),
                ("eq. 7, θ known", geo_true, "geometry", "mcf"),
            ] + [("eq. 15 reference", geo_naive, fe_ref, m) for m in METHODS]
            for label, geo, fe, method in options:
                res, dt = chain((s0, s1, s2), rm, geo, fe, method, n0, ref)
                exact, _ = chain((s0, s1, s2), rm, geo, fe, method, n0, ref, "exact")
                row = {"flat_earth": label, "method": method, "seconds": dt}
                row |= score(res.height_m, res.valid, truth, geo)
                row["rms_exact_um"] = score(exact.height_m, exact.valid, truth, geo)["rms_um"]
                row |= masks(res)
                out["rows"].append(row)
                if png_dir is not None and label.startswith("eq. 15") and method == "mcf":
                    write_pngs(png_dir, name, res, truth, az, rm, geo)
        res, _ = chain((s0, s1, s2), rm, geo_naive, fe_ref, "mcf", n0, ref)
        plain, _ = chain((s0, s1, s2), rm, geo_naive, fe_ref, "mcf", 0.0, ref)
        signal = np.mean(np.abs(s0[truth.returns].astype(np.complex128)) ** 2) - n0
        image_snr = 10 * math.log10(signal / n0) if n0 > 0 else math.inf
        row = {"snr_db": snr, "noise_power": n0, "image_snr_db": image_snr}
        row |= score(res.height_m, res.valid, truth, geo_naive) | masks(res)
        ignored = score(plain.height_m, plain.valid, truth, geo_naive)
        row |= {"rms_n0_ignored_um": ignored["rms_um"], "coverage_n0_ignored": ignored["coverage"]}
        row["masked_n0_ignored"] = plain.phase.masked
        for method in METHODS[1:]:
            other, _ = chain((s0, s1, s2), rm, geo_naive, fe_ref, method, n0, ref)
            row[f"rms_{method}_um"] = score(other.height_m, other.valid, truth, geo_naive)["rms_um"]
        out["sweep"].append(row)
    return out


def write_pngs(png_dir, name, res, truth, az, rm, geo):
    lim = height_colour_limits_mm(truth.height_m, truth.returns, 0.0)
    save_height_quicklook(
        png_dir / f"sam_{name}_truth.png",
        truth.height_m,
        truth.scored,
        az,
        rm,
        f"{name}: truth on the image grid",
        lim,
    )
    save_height_quicklook(
        png_dir / f"sam_{name}_height.png",
        res.height_m,
        res.valid,
        az,
        rm,
        f"{name}: SAM height (eq. 15 flat earth, mcf)",
        lim,
    )
    kept = res.valid & truth.scored
    dh_mm = geo.elevation_resolution_m * 1e3
    save_height_quicklook(
        png_dir / f"sam_{name}_error.png",
        np.where(kept, res.height_m - truth.height_m, 0.0),
        kept,
        az,
        rm,
        f"{name}: height error (colour limits ±Δh of eq. 14)",
        (-dh_mm, dh_mm),
        "RdBu_r",
    )


def flat_references(cfg, args, effect, geo, n0_unit):
    """Eq. 15's ψ_FE per SNR from one simulated flat speckled plane (32 lines, another seed)."""
    ss, main, aux, t_sim = simulate(cfg, slanted_plane(), 32, args, effect, args.seed + 7)
    refs = {}
    for k, snr in enumerate(args.snr):
        s0, s1, s2, _, _ = focus_noisy(cfg, ss, main, aux, snr, args.seed + 2000 + k)
        refs[snr] = flat_earth_from_reference(
            s0, s1, s2, geo.mask_offset_a, noise_power=noise_power_at(n0_unit, snr)
        )
    return refs, t_sim


def stream_rate(geo, range_bins, lines=1024, batch=32, seed=0) -> float:
    """Lines per second of SamPhaseStream (one image line per pulse after the CCD)."""
    rng = np.random.default_rng(seed)
    rm = 2.4 + (np.arange(range_bins) - range_bins // 2) * 170e-6
    s = rng.standard_normal((3, lines, range_bins)) + 1j * rng.standard_normal(
        (3, lines, range_bins)
    )
    stage = SamPhaseStream(geo, rm, dark_floor=0.05, looks=LOOKS)
    t0 = time.perf_counter()
    for i in range(0, lines, batch):
        stage.push(s[0, i : i + batch], s[1, i : i + batch], s[2, i : i + batch])
    stage.flush()
    return lines / (time.perf_counter() - t0)


def fmt(value, spec):
    return "-" if value is None else format(value, spec)


def markdown(info, reports, rates) -> str:
    out = ["# SAM 3D (INO 3D patent) at Zhao's geometry", ""]
    out += [f"* {k}: {v}" for k, v in info.items()]
    for rep in reports:
        out += [
            "",
            f"## {rep['scene']} ({rep['targets']} scatterers, {rep['pulses']} pulses, image "
            f"{rep['image']}, simulated in {rep['simulate_s']:.0f} s; {rep['no_return_pixels']} "
            "pixels see no surface)",
            "",
            f"SNR {rep['sweep'][0]['snr_db']:g} dB per sample.  Acceptance: rms ≤ Δh (eq. 14).",
            "",
            "| flat earth | unwrap | rms µm (eq. 13) | rms µm (eq. 9) | rms raised µm | bias µm "
            "| max µm | coverage | dark / incoherent / geometry | γ mean | time s | ≤ Δh |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rep["rows"]:
            out.append(
                f"| {r['flat_earth']} | {r['method']} | {fmt(r['rms_um'], '.1f')} | "
                f"{fmt(r['rms_exact_um'], '.1f')} | {fmt(r.get('rms_raised_um'), '.1f')} | "
                f"{fmt(r['bias_um'], '+.1f')} | {fmt(r['max_um'], '.0f')} | "
                f"{r['coverage']:.3f} | {r['masked_dark']} / {r['masked_incoherent']} / "
                f"{r['masked_geometry']} | {r['mean_coherence']:.2f} | {r['seconds']:.2f} | "
                f"{'yes' if r.get('pass') else 'NO'} |"
            )
        out += [
            "",
            "SNR sweep (eq. 15 reference, mcf; N0 known unless marked):",
            "",
            "| SNR dB/sample | S0 pixel SNR dB | rms µm | phase rms rad (eq. 14 takes 0.314) "
            "| coverage "
            "| dark / incoherent | γ mean | ≤ Δh | rms µm, N0 ignored | coverage, N0 ignored "
            "| masked, N0 ignored | rms µm ls / skimage |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in rep["sweep"]:
            out.append(
                f"| {r['snr_db']:g} | {r['image_snr_db']:.1f} | {fmt(r['rms_um'], '.1f')} | "
                f"{fmt(r.get('phase_rms_rad'), '.3f')} | {r['coverage']:.3f} | "
                f"{r['masked_dark']} / {r['masked_incoherent']} | {r['mean_coherence']:.2f} | "
                f"{'yes' if r.get('pass') else 'NO'} | {fmt(r['rms_n0_ignored_um'], '.1f')} | "
                f"{r['coverage_n0_ignored']:.3f} | {r['masked_n0_ignored']} | "
                f"{fmt(r['rms_ls_um'], '.1f')} / {fmt(r['rms_skimage_um'], '.1f')} |"
            )
    if rates:
        out += ["", "## SamPhaseStream rate (image lines/s = pulses/s, after the CCD)", ""]
        out += [f"* {k}" for k in rates]
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--lines", type=int, default=96)
    ap.add_argument("--range-bins", type=int, default=96)
    ap.add_argument("--per-cell", type=float, default=2.0, help="scatterers per resolution cell")
    ap.add_argument("--snr-db", default="10,-20,-30,-40", help="per-sample SNRs; 'inf': none")
    ap.add_argument(
        "--ambiguity-height-mm",
        type=float,
        default=AMBIGUITY_HEIGHT_MM,
        help="h_2π = P_φ R0 sin φ0, sets the masks' period (Zhao's 3.3 mm by default)",
    )
    ap.add_argument(
        "--reference-edge-bins",
        type=int,
        default=8,
        help="range bins at each swath edge known to lie on the reference plane (0: none)",
    )
    ap.add_argument("--mask-phase-rad", type=float, default=0.6, help="the masks' true offset θ")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--scenes", default="ridge,pin,pin_alone")
    ap.add_argument("--no-rate", action="store_true", help="skip the stream-stage timing")
    ap.add_argument("--json", help="write the numbers here")
    ap.add_argument("--png", help="write quicklooks (truth, height, error) into this folder")
    ap.add_argument("-o", "--output", help="write the Markdown here too")
    args = ap.parse_args(argv)
    args.snr = [float(v) for v in args.snr_db.split(",")]
    cfg = zhao_config(sample_rate_hz=1280.0, aperture_pulses=160, range_bins=args.range_bins)
    g = cfg.geometry
    look = math.acos(g.platform_height_m / g.slant_range_m)
    period = args.ambiguity_height_mm * 1e-3 / (g.slant_range_m * math.sin(look))
    theta = args.mask_phase_rad
    geo_true = ModulationGeometry.from_config(cfg, period, mask_phase_rad=theta)
    geo_naive = ModulationGeometry.from_config(cfg, period)
    effect = ("amplitude_modulation_3d", {"angular_period_rad": period, "mask_phase_rad": theta})
    png_dir = None
    if args.png:
        png_dir = Path(args.png)
        png_dir.mkdir(parents=True, exist_ok=True)
    info = {
        "range R0, look angle φ0 from vertical, platform height H0": (
            f"{g.slant_range_m} m, {math.degrees(look):.2f}°, {g.platform_height_m:.4f} m"
        ),
        "mask angular period P_φ": f"{period * 1e3:.4f} mrad (a = b = 0.5, true θ = {theta} rad)",
        "h_2π = P_φ R0 sin φ0; Δh (eq. 14)": (
            f"{geo_naive.ambiguity_height_m * 1e3:.3f} mm; "
            f"{geo_naive.elevation_resolution_m * 1e6:.0f} µm"
        ),
        "receiver aperture for a sharp mask (λ/D ≤ P_φ/10)": (
            f"D ≥ {g.wavelength_m / (period / 10) * 1e3:.1f} mm"
        ),
        "resolution azimuth / range": (
            f"{cfg.azimuth_resolution_m() * 1e6:.0f} µm / "
            f"{cfg.waveform.range_resolution_m * 1e6:.0f} µm"
        ),
        "processing": f"looks {LOOKS[0]} × {LOOKS[1]} (az × rg), coherence ≥ 0.3, dark floor "
        "1 % of the 99th percentile of the averaged |S0|²; 2π cycle: median phase of the "
        f"first and last {args.reference_edge_bins} range bins (known ground) in [-π, π), "
        "else of the region",
    }
    n0_unit = focused_noise_power(cfg, args.lines)
    info["noise power N0 of a focused S0 pixel at 0 dB per sample"] = f"{n0_unit:.3g}"
    t0 = time.perf_counter()
    references, t_ref = flat_references(cfg, args, effect, geo_naive, n0_unit)
    print(f"reference: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    info["flat reference (eq. 15)"] = f"32 lines, simulated in {t_ref:.0f} s"
    reports = []
    for name in args.scenes.split(","):
        t0 = time.perf_counter()
        reports.append(
            scene_report(name, cfg, geo_true, geo_naive, references, n0_unit, args, effect, png_dir)
        )
        print(f"{name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr)
    rates = []
    if not args.no_rate:
        for bins in (args.range_bins, 256):
            rates.append(
                f"{bins} range bins, batches of 32 lines: "
                f"{stream_rate(geo_naive, bins):.0f} lines/s"
            )
    text = markdown(info, reports, rates)
    print(text)
    if args.output:
        Path(args.output).write_text(text + "\n")
    if args.json:
        Path(args.json).write_text(
            json.dumps({"geometry": info, "scenes": reports, "rates": rates}, indent=2)
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
