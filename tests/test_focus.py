"""Point-target acceptance on every preset, full size: position, IRW, PSLR against theory.

Theory (rtsar.acceptance): IRW = 0.886·ρ·k_w with ρR = c/2B, ρA = λR/2L and k_w the window's
broadening; PSLR ≈ -13.26 dB unweighted, ≤ -30 dB with the Taylor window (n̄ = 4, -35 dB).
"""

import math

import numpy as np
import pytest

from rtsar.analysis.acceptance import run_point_targets
from rtsar.ccd.base import aperture_offsets_m
from rtsar.presets import PRESETS, preset
from rtsar.windows import window

RECT_PSLR_DB = -13.26
LENS = "auto"  # the OpenCL AO lens as the instrument uses it; NumPy where no device can build


def curvature_bias_cells(cfg, windows):
    """Where the uncorrected range curvature puts the range peak: the window-weighted mean of
    the migration x²/2R over the aperture, in range cells (the CCD integrates each column)."""
    if cfg.processor.range_migration_taps:  # the CCD's rows follow the migration
        return 0.0
    x = aperture_offsets_m(cfg)
    w = window(windows, len(x))
    r = cfg.geometry.slant_range_m
    return float(np.sum(w * x**2 / (2 * r)) / np.sum(w)) / cfg.waveform.range_resolution_m


@pytest.mark.slow
@pytest.mark.parametrize("windows", ["rect", "taylor"])
@pytest.mark.parametrize("name", sorted(PRESETS))
def test_point_targets_focus_as_theory_says(name, windows):
    cfg = preset(name).with_processor(range_window=windows, azimuth_window=windows)
    bias = curvature_bias_cells(cfg, windows)
    for t in run_point_targets(cfg, lens_backend=LENS):
        where = f"{name}/{windows}/{t.label}"
        assert t.azimuth_error_cells <= 1 / 8, where
        if bias <= 1 / 16:
            assert t.range_error_cells <= 1 / 8, where
        else:
            # crouch-sal: curvature 35 µm = 0.7 ρR is not corrected by the CCD; the peak sits
            # where the physics puts it (see the closing note of the core issue).
            assert abs(t.range_error_cells - bias) <= 0.03, (where, t.range_error_cells, bias)
        assert 0.9 <= t.azimuth_irw_ratio <= 1.1, (where, t.azimuth_irw_ratio)
        assert 0.9 <= t.range_irw_ratio <= 1.1, (where, t.range_irw_ratio)
        if windows == "rect":
            assert abs(t.azimuth_pslr_db - RECT_PSLR_DB) <= 0.7, (where, t.azimuth_pslr_db)
            assert abs(t.range_pslr_db - RECT_PSLR_DB) <= 1.5, (where, t.range_pslr_db)
        else:
            assert t.azimuth_pslr_db <= -30.0, (where, t.azimuth_pslr_db)
            assert t.range_pslr_db <= -30.0, (where, t.range_pslr_db)


def test_antenna_pattern_broadens_azimuth_as_predicted():
    """With the two-way beam simulated, theory is the correlator's own response to it."""
    cfg = preset("zhao-insal")  # beam footprint 9.3 mm vs an 8 mm aperture: a strong taper
    plain = run_point_targets(cfg, lens_backend="numpy")[1]
    beam = run_point_targets(cfg, lens_backend="numpy", antenna=True)[1]
    assert beam.azimuth_irw_m > 1.05 * plain.azimuth_irw_m  # measured: about 1.10
    assert 0.99 <= beam.azimuth_irw_ratio <= 1.01, beam.azimuth_irw_ratio


@pytest.mark.parametrize("windows", ["taylor", "rect"])
def test_a_beam_that_ends_inside_the_aperture_is_no_fixed_taper(windows):
    """The demo's beam (a 58.75 m antenna: nulls ±80 m from the platform, an 80 m aperture, main
    lobe only): the window stays with the mask, the beam moves with the line, so the weights a
    line sees change with its offset.  Measured 32.9 m (Taylor) / 27.8 m (rect); the fixed taper
    |DFT(w·g)| said 39.1 / 29.6 m and sidelobes the response does not have."""
    cfg = preset("psaltis-jpl").with_processor(
        range_window=windows, azimuth_window=windows, range_bins=160
    )
    beam = {"antenna_length_m": 58.75, "main_lobe_only": True}
    t = run_point_targets(cfg, lens_backend="numpy", antenna=beam)[1]
    assert 0.99 <= t.azimuth_irw_ratio <= 1.01, (t.azimuth_irw_m, t.azimuth_irw_theory_m)
    assert t.azimuth_pslr_theory_db == -math.inf  # no sidelobe at all …
    assert t.azimuth_pslr_db < -100.0  # … and the image's are rounding
