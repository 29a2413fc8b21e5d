"""The chirp report's numbers (rtsar.app.reports.chirp) at its documented settings.

crouch-sal with 50 µm steps and N = 128 (``python tools/chirp_report.py``'s default).  The
residual phase of an uncorrected defect is known in closed form: the report measures
2π Δτ_edge · rms(ν_true(t_k) - K t_k), and the defects are defined by their instantaneous
frequency (rtsar.scene.effects.chirp: Δf = B a sin(π m x + φ), B c₂ x², δf_p ~ N(0, σ²), with
x = 2t/T).  The corrected residuals and widths are the figures corrections.md quotes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtsar.app.reports import chirp as report
from rtsar.lens.plan import range_axis_m
from rtsar.params import C_M_PER_S

CFG = report.config_for("crouch-sal", None)


def _edge_phase_per_hz() -> float:
    """2π Δτ_edge: phase (rad) per Hz of frequency error at the far edge of the swath."""
    far_m = range_axis_m(CFG)[-1]
    return 2 * math.pi * 2 * (far_m - CFG.waveform.reference_range_m) / C_M_PER_S


def _x() -> np.ndarray:
    """x = 2t/T at the shot's samples (t from mid-chirp)."""
    wf = CFG.waveform
    t = (np.arange(wf.samples_per_shot) - 0.5 * wf.samples_per_shot) / wf.sample_rate_hz
    return 2 * t / wf.chirp_duration_s


def _rms_about_mean(v) -> float:
    return float(np.sqrt(np.mean((v - np.mean(v)) ** 2)))


@pytest.fixture(scope="module")
def uncorrected():
    """Each defect alone, no correction (no reference channel simulated: none is used)."""
    return {
        "free": report.run_case(CFG, [], None),
        "sine": report.run_case(CFG, [report.SINE], None),
        "quad": report.run_case(CFG, [report.QUAD], None),
        "jitter": report.run_case(CFG, [report.JITTER], None),
    }


def test_error_free_focus_is_the_theory(uncorrected):
    """No defect: residual 0; IRW 0.886 λR/(2 N d) along track (Crouch eq. 4.8) and
    0.886 c/(2B) in range (rect windows), PSLR of a sinc."""
    m = uncorrected["free"]
    g, n = CFG.geometry, CFG.processor.aperture_pulses
    assert CFG.processor.range_window == CFG.processor.azimuth_window == "rect"
    assert m["phase_rms_rad"] == 0.0
    az = 0.886 * g.wavelength_m * m["target_range_m"] / (2 * n * g.along_track_step_m)
    assert m["az_irw_m"] == pytest.approx(az, rel=0.01)
    assert m["rg_irw_m"] == pytest.approx(0.886 * C_M_PER_S / (2 * CFG.waveform.bandwidth_hz),
                                          rel=0.015)  # fmt: skip
    assert m["az_pslr_db"] == pytest.approx(-13.26, abs=0.2)
    assert m["rg_pslr_db"] == pytest.approx(-13.26, abs=0.3)
    rm = range_axis_m(CFG)
    assert m["target_range_m"] > rm[0] + 0.9 * (rm[-1] - rm[0])  # the far edge, as documented


def test_uncorrected_residuals_are_the_injected_sweep(uncorrected):
    """1 % sine of 5 periods: 2πΔτ·B·0.01/√2 (11.3 rad in corrections.md); 1 % quadratic
    (c₂ = 0.015): 2πΔτ·B·c₂·std(x²) = 2πΔτ·B·0.015·√(4/45) (7.17 rad); 10 GHz jitter:
    2πΔτ·10 GHz to the spread of the drawn offsets (5.35 rad)."""
    k, b, x = _edge_phase_per_hz(), CFG.waveform.bandwidth_hz, _x()
    sine = k * b * _rms_about_mean(0.01 * np.sin(5 * math.pi * x + 0.5 * math.pi))
    assert sine == pytest.approx(k * b * 0.01 / math.sqrt(2), rel=1e-3)  # whole periods
    assert uncorrected["sine"]["phase_rms_rad"] == pytest.approx(sine, rel=1e-6)
    quad = k * b * _rms_about_mean(0.015 * x**2)
    assert quad == pytest.approx(k * b * 0.015 * math.sqrt(4 / 45), rel=1e-3)
    assert uncorrected["quad"]["phase_rms_rad"] == pytest.approx(quad, rel=1e-6)
    assert uncorrected["jitter"]["phase_rms_rad"] == pytest.approx(k * 10e9, rel=0.12)
    # the figures of corrections.md's table
    assert f"{uncorrected['sine']['phase_rms_rad']:.3g}" == "11.3"
    assert f"{uncorrected['quad']['phase_rms_rad']:.3g}" == "7.17"
    assert f"{uncorrected['jitter']['phase_rms_rad']:.3g}" == "5.35"
    free = uncorrected["free"]
    assert uncorrected["quad"]["rg_irw_m"] > 10 * free["rg_irw_m"]  # smeared in range
    assert uncorrected["jitter"]["az_pslr_db"] > -5.0  # defocused along track


def test_linearizer_removes_the_quadratic_sweep(uncorrected):
    """corrections.md: 1 % quadratic, linearize: 7.17 → 7e-6 rad, range IRW ratio 1.006."""
    m = report.run_case(CFG, [report.QUAD, report.RI], "lin")
    assert m["phase_rms_rad"] < 2e-5
    assert f"{m['phase_rms_rad']:.0e}" == "7e-06"
    free = uncorrected["free"]
    assert m["rg_irw_m"] / free["rg_irw_m"] == pytest.approx(1.0, abs=0.01)
    assert m["rg_pslr_db"] < -12.5
    assert m["counters"]["shots_not_linearized"] == 0
    assert m["counters"]["shots_beat_aliased"] == 0


def test_hcn_alignment_removes_the_jitter(uncorrected):
    """corrections.md: 10 GHz jitter, hcn: 5.35 → 1.9e-9 rad, azimuth IRW 1.000."""
    m = report.run_case(CFG, [report.JITTER, report.HCN], "hcn")
    assert m["phase_rms_rad"] < 1e-8  # the page's 1.9e-9: rounding, not a figure to pin
    assert m["az_irw_m"] / uncorrected["free"]["az_irw_m"] == pytest.approx(1.0, abs=0.002)
    assert m["az_pslr_db"] == pytest.approx(-13.3, abs=0.1)
    assert m["counters"] == {"shots_not_aligned": 0}


def test_markdown_ratios_are_against_the_error_free_row():
    base = {"phase_rms_rad": 0.0, "az_irw_m": 160e-6, "az_pslr_db": -13.25, "rg_irw_m": 44e-6,
            "rg_pslr_db": -13.2, "target_range_m": 1.5111, "counters": {}}  # fmt: skip
    bad = base | {"phase_rms_rad": 11.33, "az_irw_m": 240e-6, "rg_irw_m": 1.1e-3,
                  "rg_pslr_db": float("inf"), "counters": {"samples_zeroed": 7}}  # fmt: skip
    text = report.markdown("crouch-sal", CFG, [("ok", [], None, base), ("bad", [], "lin", bad)],
                           {"lin": 1234.4})  # fmt: skip
    assert "target at 1.5111 m (far swath edge)" in text
    assert "| bad | lin | 11.3 | 240.0 (1.500) | -13.2 | 1100.00 (25.000) | – |" in text
    assert "samples_zeroed 7 |" in text
    assert "| lin | raw shots (before the AO lens) | 1234 |" in text
