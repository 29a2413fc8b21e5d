"""The SAM 3D report's numbers (rtsar.app.reports.sam3d) and the ridge row 3d.md quotes.

Independent expectations: the noise rule σ² = 10^(-SNR/10) per complex sample; a matched
filter's white-noise gain (N0 = peak²/(samples × pulses)); the scoring by hand; a mask offset θ
that the processor ignores biases every height by θ/2π·h_2π (INO 3D patent eq. 7 with θ = 0
assumed); eq. 14's Δh = h_2π/20; the receiver aperture λ/D ≤ P_φ/10.  The report itself runs
at the page's settings for the ridge alone at 10 dB (its first SNR: the same noise draws).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from rtsar.app.reports import sam3d as report
from rtsar.lens.plan import range_axis_m
from rtsar.scene import Simulator, point_scene
from rtsar.scene.relief import zhao_config
from rtsar.stream.engine import process_block

PAGE = Path(__file__).resolve().parents[1] / "docs" / "pages" / "guide" / "3d.md"


def test_receiver_noise_has_the_declared_variance():
    rng = np.random.default_rng(0)
    shots = np.zeros((200, 500), np.complex64)
    for snr_db in (10.0, -20.0):
        noisy = report.add_receiver_noise(shots, snr_db, rng)
        assert noisy.dtype == np.complex64
        assert np.mean(np.abs(noisy) ** 2) == pytest.approx(10 ** (-snr_db / 10), rel=0.02)
        assert np.mean(noisy.real**2) == pytest.approx(np.mean(noisy.imag**2), rel=0.03)
    assert report.add_receiver_noise(shots, math.inf, rng) is shots
    assert report.noise_power_at(2.0, 20.0) == pytest.approx(0.02)
    assert report.noise_power_at(2.0, math.inf) == 0.0


def test_focused_noise_power_is_the_matched_filters_white_noise_gain():
    """A matched filter over S samples and N pulses gives a unit point target a peak p and
    unit white noise a mean power p²/(S N): N0 of the report against the focused target."""
    cfg = zhao_config(sample_rate_hz=1280.0, aperture_pulses=160, range_bins=48)
    s, n = cfg.waveform.samples_per_shot, cfg.processor.aperture_pulses
    d = cfg.geometry.along_track_step_m
    n0 = report.focused_noise_power(cfg, 256)  # (~2600 independent pixels: lines are 1/5 cell)
    lines = 32
    start = -(0.5 * (n - 1) + lines // 2) * d  # the target on line 16, on a bin
    scene = point_scene(cfg, [0.0], [range_axis_m(cfg)[24]], [1.0], start_along_track_m=start,
                        pulses=lines + n - 1)  # fmt: skip
    image, _, _ = process_block(cfg, Simulator(scene).block(lines + n - 1), "numpy", start)
    peak2 = float(np.max(np.abs(image.astype(np.complex128)) ** 2))
    assert n0 == pytest.approx(peak2 / (s * n), rel=0.06)


def test_score_by_hand():
    truth = SimpleNamespace(
        height_m=np.array([[0.0, 1e-3, 2e-3, 0.0]]),
        scored=np.array([[True, True, True, False]]),
    )
    geo = SimpleNamespace(ambiguity_height_m=3.3e-3, elevation_resolution_m=165e-6)
    height = np.array([[30e-6, 1e-3 - 40e-6, 2e-3, 5.0]])
    valid = np.array([[True, True, False, True]])
    s = report.score(height, valid, truth, geo)
    assert s["rms_um"] == pytest.approx(math.sqrt((30**2 + 40**2) / 2))
    assert s["rms_raised_um"] == pytest.approx(40.0)
    assert s["bias_um"] == pytest.approx(-5.0)
    assert s["max_um"] == pytest.approx(40.0)
    assert s["coverage"] == pytest.approx(2 / 3)
    assert s["phase_rms_rad"] == pytest.approx(s["rms_um"] * 1e-6 / 3.3e-3 * 2 * math.pi)
    assert s["pass"] is True
    none = report.score(height, np.zeros_like(valid), truth, geo)
    assert none["rms_um"] is None and none["coverage"] == 0.0
    ref = report.edge_reference((5, 20), 3)
    assert ref.sum() == 5 * 6 and ref[:, :3].all() and ref[:, -3:].all()
    assert report.edge_reference((5, 20), 0) is None


@pytest.fixture(scope="module")
def ridge(tmp_path_factory):
    out = tmp_path_factory.mktemp("sam3d") / "sam.json"
    argv = ["--snr-db", "10", "--scenes", "ridge", "--no-rate", "--json", str(out)]
    assert report.main(argv) == 0
    return json.loads(out.read_text())


def test_geometry_figures(ridge):
    """h_2π = 3.3 mm (the masks' period is chosen for it), Δh = h_2π/20 (eq. 14), D ≥ 10 λ/P_φ,
    N0 = peak²/(S N) with a unit peak (the engine's gain)."""
    info = ridge["geometry"]
    cfg = zhao_config(sample_rate_hz=1280.0, aperture_pulses=160, range_bins=96)
    g = cfg.geometry
    look = math.acos(g.platform_height_m / g.slant_range_m)
    assert math.degrees(look) == pytest.approx(math.degrees(math.atan(math.sqrt(2))), abs=0.01)
    period = float(info["mask angular period P_φ"].split()[0]) * 1e-3
    assert period * g.slant_range_m * math.sin(look) == pytest.approx(3.3e-3, rel=1e-4)
    assert info["h_2π = P_φ R0 sin φ0; Δh (eq. 14)"] == f"3.300 mm; {3.3e-3 / 20 * 1e6:.0f} µm"
    d_mm = g.wavelength_m / (period / 10) * 1e3
    assert info["receiver aperture for a sharp mask (λ/D ≤ P_φ/10)"] == f"D ≥ {d_mm:.1f} mm"
    n0 = float(info["noise power N0 of a focused S0 pixel at 0 dB per sample"])
    assert n0 == pytest.approx(1 / (cfg.waveform.samples_per_shot * 160), rel=0.03)


def test_ridge_rows(ridge):
    """Ignoring the masks' θ = 0.6 rad biases the heights by θ/2π·h_2π = 315 µm; knowing it, or
    calibrating on a flat reference (eq. 15), leaves no bias and an rms within Δh; the
    unwrappers agree on this unambiguous ridge; the sweep's phase rms is rms·2π/h_2π."""
    h2pi = 3.3e-3
    rep = ridge["scenes"][0]
    assert rep["scene"] == "ridge" and rep["image"] == [96, 96]
    rows = {(r["flat_earth"], r["method"]): r for r in rep["rows"]}
    naive = rows[("eq. 7, θ = 0 assumed", "mcf")]
    assert naive["bias_um"] == pytest.approx(0.6 / (2 * math.pi) * h2pi * 1e6, abs=8.0)
    assert naive["pass"] is False
    known = rows[("eq. 7, θ known", "mcf")]
    assert abs(known["bias_um"]) < 10.0 and known["rms_um"] < 165.0 and known["pass"]
    cal = [rows[("eq. 15 reference", m)] for m in ("mcf", "ls", "skimage")]
    assert all(abs(r["bias_um"]) < 10.0 and r["pass"] for r in cal)
    assert [r["rms_um"] for r in cal] == pytest.approx([cal[0]["rms_um"]] * 3, abs=0.01)
    sweep = rep["sweep"][0]
    assert sweep["snr_db"] == 10.0
    assert sweep["phase_rms_rad"] == pytest.approx(sweep["rms_um"] * 1e-6 * 2 * math.pi / h2pi)
    assert sweep["rms_um"] == pytest.approx(cal[0]["rms_um"])  # the same chain
    # 3d.md's SAM table, ridge row: 315 µm / 37.2 µm / 41.8 µm
    page = [ln for ln in PAGE.read_text(encoding="utf-8").splitlines()
            if ln.startswith("| ridge 2.5 mm |") and "bias θ/2π" in ln]  # fmt: skip
    assert len(page) == 1
    assert page[0].startswith(
        f"| ridge 2.5 mm | {naive['rms_um']:.0f} µm (bias θ/2π·h_2π) | "
        f"{known['rms_um']:.1f} µm | {cal[0]['rms_um']:.1f} µm | 165 µm |"
    )
