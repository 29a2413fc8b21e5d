"""Spotlight SAL: simulation, polar format, backprojection reference, streaming (Crouch ch. 9)."""

import math

import numpy as np
import pytest

from rtsar.analysis.point_target import analyse_point_target
from rtsar.params import C_M_PER_S
from rtsar.spot.backprojection import backproject, backproject_exact
from rtsar.spot.czt import dtft_reference, zoom_dtft
from rtsar.spot.geometry import cross_range_resolution_m, sample_times_s
from rtsar.spot.pfa import PfaSettings, PolarFormatPlan, ProgressivePolarFormat, polar_format
from rtsar.spot.scene import reduced_spotlight, spot_points, spot_scene_from_dict
from rtsar.spot.simulate import SpotlightSimulator

LAM = 1.55e-6
POINTS = [[0.0, 0.0, 0.0], [4e-4, 3e-4, 0.0], [-6e-4, -5e-4, 0.0]]


@pytest.fixture(scope="module")
def five_degrees():
    """Crouch's 5° sweep, scaled to 64 samples per shot and a 3.2 mm alias-free spot."""
    cfg, geo = reduced_spotlight(64, 3.2e-3, 5.0)
    data, _ = SpotlightSimulator(spot_points(cfg, geo, POINTS)).block()
    return cfg, geo, data


def test_zoom_dtft_matches_the_direct_sum(rng):
    x = rng.standard_normal((3, 50)) + 1j * rng.standard_normal((3, 50))
    w0, dw = [0.1, -2.0, 3.0], [0.01, 0.2, -0.05]
    ref = dtft_reference(x, w0, dw, 77)
    assert np.max(np.abs(zoom_dtft(x, w0, dw, 77) - ref)) < 1e-11 * np.max(np.abs(ref))


def test_shots_follow_the_exact_path_of_eq_9_2a():
    cfg, geo = reduced_spotlight(32, 3.2e-3, 1.0)
    p = np.array([[7e-4, -4e-4, 2e-4]])
    shots = SpotlightSimulator(spot_points(cfg, geo, p)).block()[0]
    wf = cfg.waveform
    t = sample_times_s(wf)
    for n in (0, geo.pulses - 1):
        th = geo.angles_rad([n])[0]
        station = -geo.range_m * np.array([math.sin(th), math.cos(th), 0.0])
        r = np.linalg.norm(station - p[0])  # eq. 9.1a, exact
        # Crouch eq. 3.5 with R measured from the LO delay: exp(-i 2 ΔR (ω + κ t)/c)
        omega_t = 2 * math.pi * (C_M_PER_S / LAM + wf.chirp_rate_hz_per_s * t)
        naive = np.exp(
            -1j * np.mod(2 * (r - wf.reference_range_m) * omega_t / C_M_PER_S, 2 * math.pi)
        )
        # the residual κτ²/2 term of eq. 3.3 is kept by the simulator: ~1e-5 rad here
        assert np.max(np.abs(shots[n] - naive)) < 1e-3


def _analyse(img, plan, p):
    xy = plan.to_frame(np.asarray(p))[0]
    return xy, analyse_point_target(img, plan.x_m, plan.y_m, xy[0], xy[1], search_radius_m=2e-4)


def test_pfa_point_targets_meet_eq_9_5_and_c_over_2b(five_degrees):
    cfg, geo, data = five_degrees
    plan = PolarFormatPlan(cfg, geo, settings=PfaSettings(extent_m=(2.5e-3, 2.5e-3)))
    img = polar_format(data, plan)
    rho_x = 0.886 * cross_range_resolution_m(LAM, geo.sweep_rad)
    rho_y = 0.886 * cfg.waveform.range_resolution_m
    assert rho_x < 10e-6  # Crouch: "At 5 degrees, the cross range resolution is below 10 microns"
    for p in POINTS:
        xy, rep = _analyse(img, plan, p)
        assert rep.azimuth.irw_m == pytest.approx(rho_x, rel=0.10)
        assert rep.range.irw_m == pytest.approx(rho_y, rel=0.10)
        assert abs(rep.azimuth_m - xy[0]) < rho_x / 8
        assert abs(rep.range_m - xy[1]) < rho_y / 8
        assert rep.azimuth.pslr_db == pytest.approx(-13.26, abs=0.5)
        assert rep.range.pslr_db == pytest.approx(-13.26, abs=0.5)
        assert abs(rep.peak_value) == pytest.approx(1.0, abs=0.1)


def test_taylor_windows_widen_by_their_factor(five_degrees):
    from rtsar.analysis.theory import theoretical_irw_factor
    from rtsar.windows import window

    cfg, geo, data = five_degrees
    s = PfaSettings(extent_m=(1.5e-3, 1.5e-3), range_window="taylor", azimuth_window="taylor")
    plan = PolarFormatPlan(cfg, geo, settings=s)
    _, rep = _analyse(polar_format(data, plan), plan, POINTS[0])
    factor = theoretical_irw_factor(window("taylor", 256))
    rho_x = 0.886 * cross_range_resolution_m(LAM, geo.sweep_rad) * factor
    assert rep.azimuth.irw_m == pytest.approx(rho_x, rel=0.10)
    assert rep.azimuth.pslr_db < -30


def _patch(plan, p, half=4):
    xy = plan.to_frame(np.asarray(p))[0]
    i = int(np.argmin(np.abs(plan.x_m - xy[0])))
    j = int(np.argmin(np.abs(plan.y_m - xy[1])))
    return slice(max(i - half, 0), i + half + 1), slice(max(j - half, 0), j + half + 1)


def test_pfa_against_exact_backprojection_by_ring(five_degrees):
    """The exact sum defines accuracy: it focuses each point to its amplitude; PFA (same
    aperture and window) stays within -35 dB of it near the centre, and its error grows with
    the distance from the centre (the planar-wavefront approximation)."""
    cfg, geo, data = five_degrees
    s = PfaSettings(extent_m=(2.5e-3, 2.5e-3), range_window="taylor", azimuth_window="taylor")
    plan = PolarFormatPlan(cfg, geo, settings=s)
    img = polar_format(data, plan)
    n = geo.pulses
    weights = plan.polar_weights(0, n)
    pts = plan.scene_points()
    errors = []
    for p in POINTS:
        sl = _patch(plan, p)
        ref = plan.baseband(backproject_exact(data, cfg, geo, pts[sl], weights=weights), 0, n, sl)
        fast = plan.baseband(backproject(data, cfg, geo, pts[sl], weights=weights), 0, n, sl)
        assert np.max(np.abs(fast - ref)) < 3e-3  # 16x upsampled profile, linear interpolation
        exact_at_target = backproject_exact(data, cfg, geo, np.asarray([p]), weights=weights)
        assert abs(exact_at_target[0] - 1.0) < 2e-3  # the reference focuses exactly
        errors.append(20 * np.log10(np.max(np.abs(img[sl] - ref)) / np.max(np.abs(ref))))
    assert max(errors) < -35
    # without the curvature phase the off-centre points are off by k·x²/R₀ (0.1-0.3 rad)
    raw = PolarFormatPlan(
        cfg, geo, settings=PfaSettings(**{**s.__dict__, "curvature_phase": False})
    )
    img_raw = polar_format(data, raw)
    sl = _patch(plan, POINTS[2])
    ref = plan.baseband(backproject_exact(data, cfg, geo, pts[sl], weights=weights), 0, n, sl)
    assert np.max(np.abs(img_raw[sl] - ref)) > 10 * np.max(np.abs(img[sl] - ref))


def test_streaming_equals_batch_and_resolution_follows_the_sweep(five_degrees):
    cfg, geo, data = five_degrees
    plan = PolarFormatPlan(cfg, geo, settings=PfaSettings(extent_m=(1.5e-3, 1.5e-3)))
    batch = polar_format(data, plan)
    stream = ProgressivePolarFormat(plan)
    widths = []
    for start in range(0, geo.pulses, 37):
        stream.push(data[start : start + 37])
        if stream.count in (74, 185):
            _, rep = _analyse(stream.image(), plan, POINTS[0])
            widths.append((stream.sweep_rad(), rep.azimuth.irw_m))
    assert np.max(np.abs(stream.image() - batch)) < 1e-9
    for sweep, irw in widths:
        assert irw == pytest.approx(0.886 * cross_range_resolution_m(LAM, sweep), rel=0.10)
    assert widths[0][1] > 2 * widths[1][1]


def test_spot_scene_file_is_strict():
    with pytest.raises(ValueError, match="unknown keys"):
        spot_scene_from_dict({"spotlight": {"sweep": 5}})
    with pytest.raises(ValueError, match="strip-map track"):
        SpotlightSimulator(spot_scene_from_dict({"effects": [{"name": "antenna_pattern"}]}))
    scene = spot_scene_from_dict({"spotlight": {"sweep_deg": 1.0}, "targets": [{"x_m": 1e-3}]})
    assert scene.geometry.pulses == round(math.radians(1.0) * 4.6 / 50e-6) + 1


def test_a_squinted_first_few_shots_wait_for_more(five_degrees):
    cfg, geo, data = five_degrees
    stream = ProgressivePolarFormat(PolarFormatPlan(cfg, geo, settings=PfaSettings()))
    stream.push(data[:3])
    assert not stream.ready()
    with pytest.raises(ValueError, match="no image yet"):
        stream.image()
    stream.push(data[3:40])
    assert stream.ready() and np.isfinite(stream.image()).all()


def test_tradeoff_spotlight_rows_measure_against_the_exact_sum():
    from rtsar.app.tradeoff.spotlight import VARIANTS, run_spotlight, spotlight_markdown

    chosen = [v for v in VARIANTS if v[0] in ("pfa czt", "backprojection x16")]
    rows, scene = run_spotlight(repeats=1, size=(32, 3.2e-3, 1.0), variants=chosen)
    assert [r["variant"].split(" (")[0] for r in rows] == [v[0] for v in chosen]
    by = {r["variant"].split(" (")[0]: r for r in rows}
    assert all(x["error_db"] < -50 for x in by["backprojection x16"]["rings"])
    assert by["pfa czt"]["rings"][0]["error_db"] < -25
    assert "err @ 0.00 mm" in spotlight_markdown(rows, scene)


def test_shots_holding_nan_are_zeroed_and_counted(five_degrees):
    cfg, geo, data = five_degrees
    plan = PolarFormatPlan(cfg, geo, settings=PfaSettings(extent_m=(1e-3, 1e-3)))
    bad = data.copy()
    bad[100, 5] = np.nan
    zeroed = data.copy()
    zeroed[100] = 0
    stream = ProgressivePolarFormat(plan)
    stream.push(bad)
    assert stream.nonfinite_shots == 1
    img = stream.image()
    assert np.isfinite(img).all()
    assert np.max(np.abs(img - polar_format(zeroed, plan))) < 1e-12
    assert np.max(np.abs(polar_format(bad, plan) - img)) < 1e-12
