"""The phase-error report's numbers (rtsar.app.reports.phase_error, docs corrections.md).

Its residual figure is checked on phases whose answer is known by hand; its stream focus on a
scaled-down phase-to-retro case (crouch-sal, N = 128) against the injected piston and the
azimuth width λR/(2L) of Crouch eq. 4.8; its table against the figures it was given.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from rtsar.analysis import analyse_point_target
from rtsar.app.reports import phase_error as report
from rtsar.focus.pra import PhaseToRetro
from rtsar.lens.plan import range_axis_m
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene


def _aperture_config(n: int = 64):
    cfg = preset("tiny").with_processor(aperture_pulses=n)
    assert cfg.geometry.along_track_step_m == 0.5  # tiny's step (the numbers below use it)
    return cfg


def test_aperture_residual_ignores_constant_slope_and_wraps():
    """Estimate = truth + 57 rad + 0.3 rad/pulse (wrapped): nothing that defocuses is left."""
    cfg = _aperture_config()
    p = np.arange(400)
    truth = 40 * np.sin(2 * np.pi * p / 170)
    estimate = np.angle(np.exp(1j * (truth + 57.0 + 0.3 * p)))  # wrapped, as a stage gives it
    rms = report.aperture_residual_rms_rad(cfg, estimate, truth, 0.0, 100.0)
    assert rms < 1e-9


def test_aperture_residual_is_the_sine_in_the_targets_aperture():
    """A sine of amplitude A with whole periods over the N pulses that image the target
    (positions x ± (N - 1)/2 steps) reads A/√2 there; pulses outside that window do not count."""
    cfg = _aperture_config(n=64)
    step = cfg.geometry.along_track_step_m
    start_m, x_m, n = -3.0, 40.25, 64
    first = 55  # (x - start)/step = 86.5 pulses, less (N - 1)/2: the aperture's first pulse
    p = np.arange(600)
    inside = (p >= first) & (p < first + n)
    error = np.where(inside, 0.2 * np.cos(2 * np.pi * 4 * (p - first) / n), 0.0)
    error[~inside] = 5.0 * np.sin(p[~inside])  # large, but outside the target's aperture
    truth = np.zeros(len(p))
    rms = report.aperture_residual_rms_rad(cfg, error, truth, start_m, x_m)
    # (cos over 4 whole periods: its projection on 1 and t is ~1e-3 of it)
    assert rms == pytest.approx(0.2 / math.sqrt(2), rel=2e-3)
    moved = report.aperture_residual_rms_rad(cfg, error, truth, start_m, x_m + 100 * step)
    assert moved > 1.0  # 100 pulses along, the window sees the large part


@pytest.fixture(scope="module")
def pra_small():
    """crouch-sal at N = 128 and 50 µm steps (as the chirp report scales it): a retro and a
    target 20 dB weaker 3 mm along, a piston of hundreds of radians, corrected by
    phase-to-retro in the report's stream (its micro-batches)."""
    n = 128
    cfg = preset("crouch-sal").with_processor(
        aperture_pulses=n, range_bins=64, range_window="taylor"
    )
    cfg = replace(cfg, geometry=replace(cfg.geometry, along_track_step_m=50e-6))
    step = cfg.geometry.along_track_step_m
    rm = range_axis_m(cfg)
    dr = rm[1] - rm[0]
    targets = [(0.0, rm[20] + 0.3 * dr), (3e-3, rm[44] + 0.41 * dr)]
    margin = 60
    start = -(0.5 * (n - 1) + margin) * step
    pulses = n + 2 * margin + int(round(3e-3 / step))
    piston = ("piston", dict(random_walk_rad=0.3, drift_rad=0.05, vibration_rad=3.0,
                             vibration_hz=0.13, white_rad=0.1, seed=7))  # fmt: skip
    xs, rs = zip(*targets, strict=True)

    def shots(extra):
        scene = point_scene(cfg, xs, rs, [10.0, 1.0], effects=[*extra, ("noise", {"snr_db": 0})],
                            seed=3, start_along_track_m=start, pulses=pulses)  # fmt: skip
        sim = Simulator(scene)
        return sim, sim.block(pulses)

    _, clean = shots([])
    sim, err = shots([piston])
    truth = sim.effects[0].truth(np.arange(pulses))
    stage = PhaseToRetro(cfg, *targets[0], start)
    fixed = report.focus_stream(cfg, err, start, line_stage=stage)
    raw = report.focus_stream(cfg, err, start)
    ref = report.focus_stream(cfg, clean, start)
    return cfg, targets, start, truth, stage, fixed, raw, ref


def test_stream_focus_puts_each_target_where_it_is(pra_small):
    """focus_stream's azimuth axis: a target at x is imaged at x (to a tenth of a pulse step:
    half a pulse off would fail), and the error-free azimuth IRW is 0.886 λR/(2 N d) (Crouch
    eq. 4.8, unweighted azimuth)."""
    cfg, targets, _, _, _, _, _, (img, az, rg, _) = pra_small
    g = cfg.geometry
    n = cfg.processor.aperture_pulses
    for x, r in targets:
        rep = analyse_point_target(img, az, rg, x, r, (1e-3, 3e-4), chip=48)
        assert abs(rep.azimuth_m - x) < 0.1 * g.along_track_step_m
        theory = 0.886 * g.wavelength_m * r / (2 * n * g.along_track_step_m)
        assert rep.azimuth.irw_m == pytest.approx(theory, rel=0.01)


def test_phase_to_retro_residual_and_focus(pra_small):
    """The report's figures of the case: the stage's estimate against the injected piston
    (hundreds of radians) is left with thousandths of a radian; the corrected targets focus as
    the error-free ones (IRW, PSLR, peak), the uncorrected do not."""
    cfg, targets, start, truth, stage, fixed, raw, ref = pra_small
    est = fixed[3]
    assert len(est) == len(truth) and np.ptp(truth) > 100.0
    injected = report.constant_removed_rms_rad(np.zeros_like(truth), truth)
    residual = report.constant_removed_rms_rad(est, truth)
    assert residual < 0.02 and injected > 1.0
    apertures = [report.aperture_residual_rms_rad(cfg, est, truth, start, x) for x, _ in targets]
    assert max(apertures) < 0.02
    assert stage.shots_not_corrected == 0
    clean = report.azimuth_metrics(cfg, *ref[:3], targets)
    got = report.azimuth_metrics(cfg, *fixed[:3], targets)
    bad = report.azimuth_metrics(cfg, *raw[:3], targets)
    for c in clean:  # the error-free focus itself: a sinc's first sidelobe
        assert c["pslr_db"] == pytest.approx(-13.26, abs=0.3)
    rows = report._targets_rows("small", cfg, targets, clean, bad, got)
    for row, c, b in zip(rows, clean, bad, strict=True):
        assert row["irw_ratio"] == pytest.approx(1.0, abs=0.01)
        assert abs(row["pslr_change"]) < 0.02
        assert row["peak_ratio"] == pytest.approx(1.0, abs=0.01)
        assert b["peak"] < 0.5 * c["peak"] and b["pslr_db"] > -5.0  # the piston's blur


def test_markdown_prints_the_figures_it_is_given():
    """λ/N columns are 1/error; the residual, ptp and aperture columns their values."""
    target = {
        "case": "c", "target_along_track_m": 1.5e-3, "irw_clean_m": 200e-6,
        "irw_raw_m": 300e-6, "irw_corrected_m": 201e-6, "irw_ratio": 1.005,
        "pslr_clean_db": -13.25, "pslr_raw_db": -1.0, "pslr_corrected_db": -13.0,
        "pslr_change": -0.0189, "peak_ratio": 0.998,
    }  # fmt: skip
    case = {
        "case": "c", "injected_ptp_rad": 196.4, "injected_rms_rad": 51.2,
        "residual_rms_rad": 0.0111, "aperture_residual_rms_rad": [0.08, 0.11],
        "pulses_not_estimated": 3, "alpha_ptp_m": 12.34e-6, "roll_path_ptp_m": 1.5e-6,
        "alpha_rms_error_lambda": 1 / 40, "beta_rms_error_path_lambda": 1 / 137,
        "reference_bins": [64, 63], "targets": [target],
    }  # fmt: skip
    cost = {
        "preset": "p",
        "range_bins": 64,
        "samples_per_shot": 256,
        "pra_pulses_per_s": 12345,
        "reference_region_pulses_per_s": 678,
        "numpy_lens_pulses_per_s": 9e4,
        "prf_hz": 2.0,
    }
    text = report.markdown([case], [cost])
    assert "| c | 196 / 51 | 0.011 | 0.080, 0.110 | 3 |" in text
    assert "| c | 1.50 | 200.0 / 300.0 / 201.0 | 1.005 |" in text
    assert "-1.9 %" in text
    assert "| c | 12.3 | λ/40 | 1.50 | λ/137 | [64, 63] |" in text
    assert "| p | 64 / 256 | 1.23e+04 | 678 | 9e+04 | 2 |" in text
