"""Phase-unwrapping methods compared on the same interferograms: error against truth and time.

    python tools/unwrap_table.py [--size 128] [--repeat 1] [--json FILE]

Interferograms (truth in radians, noise from correlated circular Gaussian pairs of coherence γ
averaged over a few looks, seeded):

* Zhao 2014 geometry (λ 1.55 µm, range 2.4 m, baseline 1.6 mm, side-looking angle such that 2π
  is 3.3 mm of height; Zhao eq. 1), 0.2 mm pixels: the 2.5 mm ridge after flat-earth removal, the
  same ridge with its flat-earth fringes still in, and a drawing-pin sphere cap with no return
  outside the pin (masked, Crouch's penny mask).
* A steep plane (0.9π per pixel in range, noise-free): Itoh's limit.
* A hill on a slope (0.4π per pixel plus a 40 rad Gaussian hill) at falling coherence: where least
  squares fails first, then the reliability-guided peer, while min-cost flow holds (Crouch 2012,
  ch. 6: "the Network Flow algorithm gave a cleaner result").
* The same hill with a band (from one edge) and a hole of no return, unmasked and masked.

Methods: "ls" (DCT least squares; masked → PCG), "ls-w" (PCG weighted by the estimated
coherence), "mcf" (Costantini/OR-tools), "mcf-w" (costs from the estimated coherence),
"skimage" (scikit-image's unwrap_phase, the peer).  Scores on valid pixels: rms error after
removing the best constant 2πk, fraction of pixels wrong by ≥ π, and wall time per call.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings

import numpy as np

from ...phase import wrap
from ...topo.phase import residues
from ...topo.unwrap import unwrap

TWO_PI = 2.0 * np.pi
METHODS = ("ls", "ls-w", "mcf", "mcf-w", "skimage")

# Zhao et al. 2014 geometry; Φ from the quoted 3.3 mm per 2π: cos Φ = λ L0 / (B · 3.3 mm).
WAVELENGTH_M = 1.55e-6
RANGE_M = 2.4
BASELINE_M = 1.6e-3
SIDE_LOOK_RAD = float(np.arccos(WAVELENGTH_M * RANGE_M / (BASELINE_M * 3.3e-3)))
AMBIGUITY_HEIGHT_M = WAVELENGTH_M * RANGE_M / (BASELINE_M * np.cos(SIDE_LOOK_RAD))
PIXEL_M = 0.2e-3


def zhao_phase_rad(range_offset_m: np.ndarray, height_m: np.ndarray, flat_earth: bool):
    """Interferometric phase, Zhao 2014 eq. 1, ``−2π B (y0 sin Φ − z0 cos Φ) / (λ0 L0)``."""
    y_term = range_offset_m * np.sin(SIDE_LOOK_RAD) if flat_earth else 0.0
    return (
        -TWO_PI
        * BASELINE_M
        * (y_term - height_m * np.cos(SIDE_LOOK_RAD))
        / (WAVELENGTH_M * RANGE_M)
    )


def noisy(truth_rad, coherence, looks: int, seed: int):
    """Wrapped phase and estimated coherence of an L-look interferogram of true coherence γ."""
    rng = np.random.default_rng(seed)
    shape = (looks, *truth_rad.shape)
    a = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2)
    b = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / np.sqrt(2)
    g = np.broadcast_to(np.asarray(coherence, dtype=np.float64), truth_rad.shape)
    s2 = g * a + np.sqrt(1.0 - g**2) * b
    ifg = (a * np.conj(s2)).sum(axis=0)
    power = np.sqrt((np.abs(a) ** 2).sum(axis=0) * (np.abs(s2) ** 2).sum(axis=0))
    return np.angle(ifg * np.exp(1j * truth_rad)), np.abs(ifg) / power


def interferograms(n: int):
    """(name, truth_rad, wrapped_rad, coherence_estimate, mask or None, scored pixels)."""
    y, x = np.mgrid[0:n, 0:n].astype(np.float64)  # y = azimuth row, x = range column
    ym, xm = (y - n / 2) * PIXEL_M, (x - n / 2) * PIXEL_M
    cases = []
    everywhere = np.ones((n, n), bool)
    ridge_m = 2.5e-3 * np.clip(1.0 - np.abs(xm) / (0.3 * n * PIXEL_M), 0.0, None)
    for flat in (False, True):
        truth = zhao_phase_rad(xm, ridge_m, flat)
        psi, coh = noisy(truth, 0.9, 4, seed=1 + flat)
        name = "zhao ridge 2.5 mm" + (" + flat-earth fringes" if flat else "") + ", γ 0.9 L4"
        cases.append((name, truth, psi, coh, None, everywhere))
    pin_radius_m = 0.25 * n * PIXEL_M
    r2 = xm**2 + ym**2
    sphere_m = (pin_radius_m**2 + 2.0e-3**2) / (2 * 2.0e-3)  # 2 mm tall cap on that base
    pin_m = np.where(r2 < pin_radius_m**2, np.sqrt(np.maximum(sphere_m**2 - r2, 0.0)), 0.0)
    pin_m = np.where(r2 < pin_radius_m**2, pin_m - (sphere_m - 2.0e-3), 0.0)
    pin = r2 < pin_radius_m**2
    truth = zhao_phase_rad(xm, pin_m, False)
    psi, coh = noisy(truth, np.where(pin, 0.9, 0.0), 4, seed=3)
    cases.append(("zhao drawing pin 2 mm, masked, γ 0.9 L4", truth, psi, coh, pin, pin))
    steep = 0.9 * np.pi * x + 0.3 * y
    cases.append(
        ("steep plane 0.9π/px, noise-free", steep, wrap(steep), np.ones((n, n)), None, everywhere)
    )
    hill = 0.4 * np.pi * x + 40.0 * np.exp(
        -((x - n / 2) ** 2 + (y - n / 2) ** 2) / (2 * (n / 6) ** 2)
    )
    for k, gamma in enumerate((0.95, 0.8, 0.7, 0.6, 0.5, 0.4)):
        psi, coh = noisy(hill, gamma, 4, seed=10 + k)
        cases.append((f"hill on slope, γ {gamma} L4", hill, psi, coh, None, everywhere))
    # A band from the left edge to 70 % of the width (the valid area stays connected) and a hole.
    band = (np.abs(y - 0.3 * n) < 0.04 * n) & (x < 0.7 * n)
    dead = band | ((x - 0.7 * n) ** 2 + (y - 0.65 * n) ** 2 < (0.12 * n) ** 2)
    psi, coh = noisy(hill, np.where(dead, 0.0, 0.85), 4, seed=20)
    # Both scored where there is a return; only the second tells the unwrapper where that is.
    cases.append(("hill, no-return band + hole, unmasked, γ 0.85", hill, psi, coh, None, ~dead))
    cases.append(("hill, no-return band + hole, masked, γ 0.85", hill, psi, coh, ~dead, ~dead))
    return cases


def score(unwrapped, truth, valid):
    """rms error after the best constant 2πk, and the fraction of pixels wrong by ≥ π."""
    e = (unwrapped - truth)[valid]
    e = e - TWO_PI * np.rint(e.mean() / TWO_PI)
    return float(np.sqrt(np.mean(e**2))), float(np.mean(np.abs(e) >= np.pi))


def run_method(method: str, psi, coh, mask, repeat: int):
    base = method.removesuffix("-w")
    weights = coh if method.endswith("-w") else None
    best = float("inf")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for _ in range(repeat):
            t0 = time.perf_counter()
            out = unwrap(psi, base, mask=mask, weights=weights)
            best = min(best, time.perf_counter() - t0)
    return out, best, [str(w.message) for w in caught]


def build(n: int, repeat: int):
    unwrap(wrap(np.zeros((8, 8))), "mcf")  # import OR-tools, scipy.fft and skimage first
    unwrap(np.zeros((8, 8)), "skimage")
    unwrap(np.zeros((8, 8)), "ls", weights=np.ones((8, 8)))
    rows = []
    for name, truth, psi, coh, mask, valid in interferograms(n):
        charge = residues(psi, mask)
        floor_rad = float(np.sqrt(np.mean(wrap(psi - truth)[valid] ** 2)))
        row = {
            "interferogram": name,
            "size": n,
            "residues": int(np.abs(charge).sum()),
            "noise_floor_rms_rad": floor_rad,
            "methods": {},
        }
        for method in METHODS:
            out, seconds, warned = run_method(method, psi, coh, mask, repeat)
            rms, wrong = score(out, truth, valid)
            row["methods"][method] = {
                "rms_rad": rms,
                "wrong_fraction": wrong,
                "time_s": seconds,
                "warnings": warned,
            }
        rows.append(row)
    return rows


def markdown(rows) -> str:
    n = rows[0]["size"]
    lines = [
        f"Unwrapping on {n}×{n} interferograms; each cell: rms error (rad) after the best 2πk / "
        "pixels wrong by ≥ π / time per call.",
        f"Zhao geometry: 2π = {AMBIGUITY_HEIGHT_M * 1e3:.2f} mm of height, so 1/20 of the ambiguity"
        f" = {TWO_PI / 20:.3f} rad = {AMBIGUITY_HEIGHT_M / 20 * 1e3:.3f} mm.",
        "",
        "| interferogram | residues | noise floor (rad) | " + " | ".join(METHODS) + " |",
        "|---|---:|---:|" + "---|" * len(METHODS),
    ]
    for row in rows:
        cells = []
        for method in METHODS:
            m = row["methods"][method]
            flag = " ⚠" if m["warnings"] else ""
            cells.append(
                f"{m['rms_rad']:.2f} / {100 * m['wrong_fraction']:.1f}% / "
                f"{1e3 * m['time_s']:.0f} ms{flag}"
            )
        lines.append(
            f"| {row['interferogram']} | {row['residues']} | "
            f"{row['noise_floor_rms_rad']:.2f} | " + " | ".join(cells) + " |"
        )
    warned = {w for row in rows for m in row["methods"].values() for w in m["warnings"]}
    if warned:
        lines += ["", "⚠ warnings: " + "; ".join(sorted(warned))]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--size", type=int, default=128, help="interferogram side in pixels")
    ap.add_argument("--repeat", type=int, default=1, help="calls per method, best time kept")
    ap.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    args = ap.parse_args(argv)
    if args.size < 16 or args.repeat < 1:
        ap.error("--size must be ≥ 16 and --repeat ≥ 1")
    rows = build(args.size, args.repeat)
    print(markdown(rows))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                {
                    "size": args.size,
                    "side_look_rad": SIDE_LOOK_RAD,
                    "ambiguity_height_m": AMBIGUITY_HEIGHT_M,
                    "rows": rows,
                },
                f,
                indent=1,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
