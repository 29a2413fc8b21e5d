"""The PGA-on-other-presets report's numbers (rtsar.app.reports.pga_presets), zhao-insal.

One piston seed at the report's own size (640 shots, 64 bins; ~7 s): the injected error is the
two-way phase 4π δ/λ of the piston (Crouch eq. 4.12); PGA with the Doppler anchor restores the
bright points to their error-free widths and peaks, moved by the error's own slope only (a
fraction of a cell), as corrections.md's zhao-insal row says (piston 265–278 rad p-p: shift
≤ 0.85 cells, IRW 0.996–1.022, peak ≥ 0.980; seed 11 is its first).  psaltis-jpl (5120
pulses × 320 bins) is too large for a unit test and is not run here.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtsar.app.reports import pga as small
from rtsar.app.reports import pga_presets as report
from rtsar.presets import preset


@pytest.fixture(scope="module")
def seed11():
    return report.case("zhao-insal", 11)


def test_injected_piston_is_its_two_way_phase(seed11):
    lam = preset("zhao-insal").geometry.wavelength_m
    ptp = 4 * math.pi * float(np.ptp(small.piston_m(640, 11))) / lam
    assert seed11["piston_ptp_rad"] == pytest.approx(ptp, rel=1e-9)
    assert 265.0 <= seed11["piston_ptp_rad"] <= 278.0  # corrections.md's range


def test_points_refocus_and_move_by_the_errors_slope(seed11):
    r = seed11
    assert r["points"] == 11 and r["unchanged"] is False
    assert r["doppler_anchored_blocks"] >= 1
    assert 0.996 <= min(r["irw_ratio"]) and max(r["irw_ratio"]) <= 1.022
    assert min(r["peak_ratio"]) >= 0.980
    assert max(r["pslr_rel_dev"]) <= 0.17
    assert max(abs(c) for c in r["shift_cells"]) <= 0.85
    shift = np.array(r["shift_lines"])
    assert -3.85 <= shift.min() and shift.max() <= -0.6  # the page: −3.8 … −0.6 lines
    assert np.ptp(shift) < 0.6  # one rigid shift: every point alike
    assert float(np.mean(shift)) == pytest.approx(r["error_slope_shift_lines"], abs=0.3)
    assert r["stream_vs_batch_max"] < 1e-6  # the stream is the float64 batch
    assert set(r["reasons"]) <= {"converged", "window_floor", "max_iterations"}


def test_markdown_row(seed11):
    text = report.markdown([seed11])
    row = [ln for ln in text.splitlines() if ln.startswith("| zhao-insal |")]
    assert len(row) == 1
    irw = seed11["irw_ratio"]
    assert f"| zhao-insal | 11 | {seed11['piston_ptp_rad']:.0f} | 11 | " in row[0]
    assert f"{min(irw):.3f} … {max(irw):.3f}" in row[0]
    assert f"≤ {100 * max(seed11['pslr_rel_dev']):.1f} %" in row[0]
    assert f"; anchored {seed11['doppler_anchored_blocks']} |" in row[0]
