"""The InSAL report's numbers (rtsar.app.reports.insal) on a scaled-down ridge (32 x 48).

Independent expectations (one pass, transmit on receiver 0, horizontal baseline B, look angle θ
from the vertical over flat ground, cos θ = H/R): the receivers' path difference is -B sin θ,
which moves the second image by -B sin θ/(2Δr) range bins; its phase 2π(-B sin θ)/λ changes with
slant range by -2π B cos²θ/(λ R sin θ) (the flat-earth fringes); one cycle of it per height
h_2π = λ R sin θ/B_⊥ = λ R tan θ/B (B_⊥ = B cos θ).  Heights against the surface's own truth.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest

from rtsar.app.reports import insal as report
from rtsar.scene.relief import zhao_config
from rtsar.topo.insar_geometry import InsalGeometry

PAGE = Path(__file__).resolve().parents[1] / "docs" / "pages" / "guide" / "3d.md"
BASELINE_M = 1.6e-3


@pytest.fixture(scope="module")
def ridge():
    cfg = zhao_config(sample_rate_hz=1280.0, aperture_pulses=160, range_bins=48)
    geo = InsalGeometry.from_config(cfg, BASELINE_M)
    args = argparse.Namespace(lines=32, per_cell=1.0, snr_db=10.0, seed=1)
    return cfg, geo, report.scene_report("ridge", cfg, geo, args, None)


def test_interferometer_figures_follow_the_geometry(ridge):
    cfg, _, rep = ridge
    lam, h = cfg.geometry.wavelength_m, cfg.geometry.platform_height_m
    rg = rep["_rg"]
    r = float(np.mean(rg))
    dr = abs(rg[1] - rg[0])
    theta = math.acos(h / r)
    h2pi = lam * r * math.tan(theta) / BASELINE_M
    assert rep["h2pi_mm"] == pytest.approx(h2pi * 1e3, rel=2e-3)
    assert rep["limit_um"] == pytest.approx(rep["h2pi_mm"] * 1e3 / 20)
    shift_px = -BASELINE_M * math.sin(theta) / (2 * dr)
    assert rep["expected_range_px"] == pytest.approx(shift_px, rel=5e-3)
    assert rep["registration_px"][1] == pytest.approx(shift_px, abs=0.05)  # measured on speckle
    assert abs(rep["registration_px"][0]) < 0.05  # no along-track offset in one pass
    fringes = -BASELINE_M * math.cos(theta) ** 2 * dr / (lam * r * math.sin(theta))
    assert rep["geometric_fringe_cycles_per_bin"] == pytest.approx(fringes, rel=0.01)
    # 3d.md: "h_2π = 3.29 mm per pixel", limit h_2π/20 = 164 µm (Zhao's geometry)
    page = PAGE.read_text(encoding="utf-8")
    assert f"h_2π = {rep['h2pi_mm']:.2f} mm per pixel" in page
    assert f"| {rep['limit_um']:.0f} µm |" in page


def test_heights_against_the_surface(ridge):
    """With the geometry's flat earth every unwrapper gives the same heights, within h_2π/20 of
    the ridge's truth, on most of the image; the pass column says so."""
    _, _, rep = ridge
    rows = [r for r in rep["rows"] if r["flat_earth"] == "geometry"]
    assert [r["method"] for r in rows] == ["mcf", "ls", "skimage"]
    for r in rows:
        assert r["rms_um"] <= rep["limit_um"] and r["pass"] is True
        assert abs(r["bias_um"]) < 0.2 * rep["limit_um"]
        assert r["coverage"] > 0.8
        assert r["rms_um"] == pytest.approx(rows[0]["rms_um"], abs=0.01)
    for r in rep["rows"]:  # the pass column is the rule it states
        assert r["pass"] == (r["rms_um"] is not None and r["rms_um"] <= rep["limit_um"])


def test_stream_strips_equal_the_batch_chain(ridge):
    """3d.md: height strips in the stream are identical to the batch chain."""
    _, geo, rep = ridge
    s = report.stream_report(geo, rep, strip_lines=8, overlap_lines=4)
    assert s["lines_in"] == 32 and s["strips_out"] == 32 // 8
    assert s["valid_masks_equal_batch"] is True
    assert s["max_abs_diff_vs_batch_m"] == 0.0
    assert s["strips_not_aligned"] == 0


def test_markdown_carries_the_figures(ridge):
    _, _, rep = ridge
    text = report.markdown({"baseline": "1.6 mm"}, [rep], {"strips_out": 4}, ["r"])
    assert f"h_2π = {rep['h2pi_mm']:.3f} mm, acceptance rms ≤ h_2π/20 = " in text
    assert f"{rep['limit_um']:.0f} µm." in text
    mcf = rep["rows"][0]
    assert f"| geometry | mcf | {mcf['rms_um']:.1f} | " in text
    assert "* baseline: 1.6 mm" in text and "* strips_out: 4" in text


def test_a_range_window_the_shot_cannot_hold_is_one_line_exit_2(capsys):
    """`tools/insal_report.py --range-bins 192` died with a traceback (found re-running 3d.md)."""
    from rtsar.app.reports import insal

    with pytest.raises(SystemExit) as stop:
        insal.main(["--range-bins", "192", "--no-rate"])
    assert stop.value.code == 2
    assert "--range-bins 192" in capsys.readouterr().err
