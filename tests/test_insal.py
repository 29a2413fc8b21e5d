"""Interferometric SAL: receivers, surfaces, registration, flat earth, heights (Zhao 2014)."""

import math

import numpy as np
import pytest
from scipy import ndimage

from rtsar.analysis import analyse_point_target
from rtsar.app.quicklook import save_height_quicklook
from rtsar.presets import preset
from rtsar.scene.effects import load_effects
from rtsar.scene.model import Scene, Targets
from rtsar.scene.relief import (
    default_spacing_m,
    penny_relief,
    ridge,
    slanted_plane,
    sphere_cap,
    surface_scene,
    truth_on_grid,
    zhao_config,
)
from rtsar.scene.simulator import Simulator
from rtsar.stream.engine import process_block
from rtsar.topo.insar import (
    FringeRamp,
    estimate_fringe_ramp,
    form_interferogram,
    height_error,
    height_map,
)
from rtsar.topo.insar_geometry import ZHAO_LOOK_ANGLE_RAD, InsalGeometry, zhao_ambiguity_height_m
from rtsar.topo.looks import box_sum
from rtsar.topo.registration import (
    Registration,
    estimate_registration,
    integer_offset,
    shift_image,
)

LAMBDA = 1.55e-6


def small_config():
    # Zhao's geometry (1550 nm, 2.4 m, look angle atan √2) at a test size: 64-sample shots,
    # 48-pulse aperture (0.78 mm azimuth resolution), 48 range bins of 170 µm.
    return zhao_config(sample_rate_hz=640.0, aperture_pulses=48, range_bins=48)


def zhao_geometry(cfg, passes=1):
    return InsalGeometry.from_config(cfg, 1.6e-3, 0.0, passes)


# ---- geometry ------------------------------------------------------------------------------
def test_ambiguity_height_at_zhao_numbers():
    """2π per ≈3.3 mm at 2.4 m with a 1.6 mm baseline (Zhao 2014, eq. 1 and text)."""
    h_platform = 2.4 * math.cos(ZHAO_LOOK_ANGLE_RAD)
    geo = InsalGeometry(LAMBDA, h_platform, 1.6e-3, 0.0)
    exact = float(geo.ambiguity_height_m(2.4))
    closed = float(geo.ambiguity_height_closed_form_m(2.4))
    assert abs(exact - 3.3e-3) < 0.05e-3
    assert abs(closed - exact) < 1e-3 * exact  # first-order formula vs exact geometry
    # Zhao's own expression at Φ = 45°: λ L0 / (B cos Φ), hand value √2 · 1.55e-6 · 2.4 / 1.6e-3
    assert zhao_ambiguity_height_m(LAMBDA, 2.4, 1.6e-3, math.pi / 4) == pytest.approx(
        3.2880e-3, rel=1e-4
    )
    # Two passes: two-way path difference, half the ambiguity height.
    two = InsalGeometry(LAMBDA, h_platform, 1.6e-3, 0.0, passes=2)
    assert float(two.ambiguity_height_m(2.4)) == pytest.approx(exact / 2, rel=1e-6)
    # A vertical baseline: B_⊥ = B sinθ, so h_2π = λR/B whatever the look angle.
    vertical = InsalGeometry(LAMBDA, h_platform, 1.6e-3, 90.0)
    assert float(vertical.ambiguity_height_m(2.4)) == pytest.approx(LAMBDA * 2.4 / 1.6e-3, rel=2e-3)


def test_phase_and_height_inversion_against_direct_positions():
    geo = InsalGeometry(LAMBDA, 1.3, 1.6e-3, 30.0)
    r = np.array([2.39, 2.4, 2.41])[:, None]
    h = np.array([-1e-3, 0.0, 0.7e-3, 2.5e-3])[None, :]
    # Direct reference: positions, two hypotenuses, in float64 (the module avoids the cancellation).
    y = np.sqrt(r**2 - (1.3 - h) ** 2)
    by, bz = 1.6e-3 * math.cos(math.radians(30)), 1.6e-3 * math.sin(math.radians(30))
    direct = 2 * math.pi * (np.hypot(y - by, 1.3 + bz - h) - np.hypot(y, 1.3 - h)) / LAMBDA
    assert np.max(np.abs(geo.phase_rad(r, h) - direct)) < 1e-6
    residual = geo.phase_rad(r, h) - geo.phase_rad(r, 0.0)
    assert np.max(np.abs(geo.height_from_phase(r, residual) - h)) < 1e-10


# ---- the receivers effect -------------------------------------------------------------------
def point_scene_3d(cfg, height_m, dy_m, effect_params):
    g = cfg.geometry
    big_h = g.platform_height_m
    y = math.sqrt(g.slant_range_m**2 - big_h**2) + dy_m
    r = math.hypot(y, big_h - height_m)
    targets = Targets(
        np.zeros(1),
        np.array([r]),
        np.ones(1, np.complex128),
        ground_range_m=np.array([y]),
        height_m=np.array([height_m]),
    )
    n = cfg.processor.aperture_pulses
    start = -(4 + 0.5 * (n - 1)) * g.along_track_step_m
    effects = (("interferometric_receivers", effect_params),)
    return Scene(cfg, targets, n + 8, start, 0, effects, "point"), r, y


@pytest.mark.parametrize("mode, passes", [("one_pass", 1), ("two_pass", 2)])
def test_receiver_channel_phase_and_range_follow_geometry(mode, passes):
    """The focused second channel: bistatic half path (one pass) or monostatic (two passes)."""
    cfg = small_config()
    height = 1.1e-3
    scene, r_tx, y = point_scene_3d(cfg, height, 0.4e-3, {"mode": mode})
    main, aux = Simulator(scene).block_with_aux(scene.pulses)
    m, az, rg = process_block(cfg, main, "numpy", scene.start_along_track_m)
    s, _, _ = process_block(cfg, aux["rx1"], "numpy", scene.start_along_track_m)
    pm = analyse_point_target(m, az, rg, chip=16)
    ps = analyse_point_target(s, az, rg, chip=16)
    big_h = cfg.geometry.platform_height_m
    r_rx = math.hypot(y - 1.6e-3, big_h - height)  # horizontal 1.6 mm baseline
    expected_shift = (r_rx - r_tx) / 2 if mode == "one_pass" else r_rx - r_tx
    assert abs((ps.range_m - pm.range_m) - expected_shift) < 0.05 * 170e-6
    geo = zhao_geometry(cfg, passes)
    measured = np.angle(pm.peak_value * np.conj(ps.peak_value))
    expected = float(geo.phase_rad(r_tx, height))
    assert abs(np.angle(np.exp(1j * (measured - expected)))) < 0.05


def test_two_pass_piston_is_the_seeded_truth():
    cfg = small_config()
    params = {"mode": "two_pass", "piston_step_rad": 0.3, "seed": 7}
    scene, _, _ = point_scene_3d(cfg, 0.0, 0.0, params)
    _, with_piston = Simulator(scene).block_with_aux(20)
    quiet, _, _ = point_scene_3d(cfg, 0.0, 0.0, {"mode": "two_pass"})
    _, without = Simulator(quiet).block_with_aux(20)
    effect = load_effects([("interferometric_receivers", params)], cfg)[0]
    psi = effect.truth(20)[1]
    assert np.allclose(
        effect.truth(20), load_effects([("interferometric_receivers", params)], cfg)[0].truth(20)
    )
    got = np.angle(np.sum(with_piston["rx1"] * np.conj(without["rx1"]), axis=1))
    assert np.max(np.abs(np.angle(np.exp(1j * (got - psi))))) < 1e-4
    assert np.std(np.diff(psi)) == pytest.approx(0.3, rel=0.5)


def test_receiver_effect_rejects_bad_setups():
    cfg = small_config()
    with pytest.raises(ValueError, match="platform_height_m"):
        load_effects([("interferometric_receivers", {})], preset("zhao-insal"))
    with pytest.raises(ValueError, match="two_pass"):
        load_effects([("interferometric_receivers", {"piston_step_rad": 0.1})], cfg)
    with pytest.raises(ValueError, match="unknown parameters"):
        load_effects([("interferometric_receivers", {"baseline": 1e-3})], cfg)
    scene, _, _ = point_scene_3d(cfg, 0.0, 0.0, {})
    bare = Scene(
        cfg, Targets(np.zeros(1), scene.targets.slant_range_m, np.ones(1)), 4, 0.0, 0, scene.effects
    )
    with pytest.raises(ValueError, match="ground_range_m"):
        Simulator(bare).block_with_aux(1)


# ---- surfaces and truth ---------------------------------------------------------------------
def test_truth_of_a_tilted_plane_matches_the_closed_form():
    cfg = small_config()
    big_h = cfg.geometry.platform_height_m
    y_c = math.sqrt(2.4**2 - big_h**2)
    s = 0.05
    rg = np.linspace(2.396, 2.404, 9)
    truth = truth_on_grid(slanted_plane(slope_cross=s), big_h, y_c, [0.0, 1e-3], rg, 1e-6)
    # R² = y² + (H - s(y - y_c))²: a quadratic in y, solved here independently.
    a = 1 + s * s
    b = -2 * s * (big_h + s * y_c)
    c = (big_h + s * y_c) ** 2 - rg**2
    y = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    assert np.max(np.abs(truth.height_m - s * (y - y_c))) < 1e-8
    assert truth.returns.all() and not truth.layover.any()


def test_layover_is_flagged_only_on_slopes_steeper_than_the_line_of_sight():
    cfg = small_config()
    big_h = cfg.geometry.platform_height_m
    y_c = math.sqrt(2.4**2 - big_h**2)
    rg = 2.4 + (np.arange(48) - 24) * 170e-6
    # The near slope faces the sensor; layover needs a slope above tanθ = √2 (θ from vertical).
    gentle = truth_on_grid(ridge(2.5e-3, 2.0e-3), big_h, y_c, [0.0], rg)
    steep = truth_on_grid(ridge(2.5e-3, 1.0e-3), big_h, y_c, [0.0], rg)
    assert not gentle.layover.any()
    assert steep.layover.sum() >= 3
    assert gentle.height_m.max() == pytest.approx(2.5e-3, abs=0.1e-3)


def test_surface_shapes():
    cap = sphere_cap(5e-3, 1.5e-3)
    assert float(cap.height(0.0, 0.0)) == pytest.approx(1.5e-3, rel=1e-12)
    assert float(cap.height(0.0, 5e-3)) == pytest.approx(0.0, abs=1e-12)
    # Hand value: ρ = (25 + 2.25)/3 mm; h(3 mm) = sqrt(ρ² - 9) - (ρ - 1.5) mm
    rho = 27.25 / 3
    assert float(cap.height(3e-3, 0.0)) == pytest.approx(
        (math.sqrt(rho**2 - 9) - (rho - 1.5)) * 1e-3, rel=1e-9
    )
    penny = penny_relief(180e-6)
    x, y = np.meshgrid(np.linspace(-10e-3, 10e-3, 201), np.linspace(-10e-3, 10e-3, 201))
    assert 150e-6 <= penny.height(x, y).max() <= 200e-6
    assert not penny.returns_at(10e-3, 0.0) and penny.returns_at(0.0, 0.0)


def test_speckle_scene_is_consistent_and_seeded():
    cfg = small_config()
    surf = sphere_cap(3e-3, 1e-3, no_return_outside=True)
    a = surface_scene(cfg, surf, 64, seed=3)  # scatterers span ±3.1 mm along track
    b = surface_scene(cfg, surf, 64, seed=3)
    t = a.scene.targets
    assert np.array_equal(t.along_track_m, b.scene.targets.along_track_m)
    big_h = cfg.geometry.platform_height_m
    assert np.allclose(np.hypot(t.ground_range_m, big_h - t.height_m), t.slant_range_m, atol=1e-12)
    u = t.ground_range_m - a.centre_ground_range_m
    assert np.allclose(t.height_m, surf.height(t.along_track_m, u), atol=1e-15)
    assert np.all(np.hypot(t.along_track_m, u) <= 3e-3)  # no return outside the pin
    # Density: default spacing puts 4 scatterers per resolution cell (cell area / spacing area).
    dx, dy = default_spacing_m(cfg)
    sin_t = math.sqrt(1 - (big_h / 2.4) ** 2)
    cell = cfg.azimuth_resolution_m() * (cfg.waveform.range_resolution_m / sin_t)
    assert cell / (dx * dy) == pytest.approx(4.0, rel=1e-9)
    assert len(t) == pytest.approx(math.pi * 9e-6 / (dx * dy), rel=0.1)


# ---- registration, resampling, filters ------------------------------------------------------
def band_limited_speckle(rng, rows, cols, band=(0.3, 0.8)):
    spec = np.fft.fft2(rng.standard_normal((rows, cols)) + 1j * rng.standard_normal((rows, cols)))
    fa, fr = np.fft.fftfreq(rows)[:, None], np.fft.fftfreq(cols)[None, :]
    spec *= (np.abs(fa) < band[0] / 2) & (np.abs(fr) < band[1] / 2)
    return spec, fa, fr


def test_shift_image_and_registration_recover_a_known_offset(rng):
    spec, fa, fr = band_limited_speckle(rng, 128, 128)
    d_az, d_rg = 1.3, -3.7
    # Reference: the exact band-limited (periodic) shift of the whole scene, then a crop.
    main = np.fft.ifft2(spec)[32:96, 32:96]
    slave_crop = np.fft.ifft2(spec * np.exp(-2j * np.pi * (fa * d_az + fr * d_rg)))[32:96, 32:96]
    out, ok = shift_image(slave_crop, d_az, d_rg, taps=16)
    inner = ok.copy()
    inner[:, :8] = inner[:, -8:] = False  # a range line is shifted whole: edge ringing
    inner[:8] = inner[-8:] = False  # truncated azimuth kernels near the first and last lines
    err = np.abs(out - main)[inner]
    assert np.sqrt(np.mean(err**2)) < 0.02 * np.sqrt(np.mean(np.abs(main) ** 2))
    # The slave shows at (i + d) what the main shows at i.
    assert integer_offset(main, slave_crop) == (1, -4)
    reg = estimate_registration(main, slave_crop, "both")
    assert abs(reg.azimuth_px - d_az) < 0.05 and abs(reg.range_px - d_rg) < 0.05
    assert reg.coherence > 0.95
    coarse = estimate_registration(main, slave_crop, "none")
    assert (coarse.azimuth_px, coarse.range_px) == (1.0, -4.0)


def test_box_sum_equals_scipy_uniform_filter(rng):
    x = rng.standard_normal((20, 17))
    ref = ndimage.uniform_filter(x, size=(5, 3), mode="constant") * 15
    assert np.max(np.abs(box_sum(x, (5, 3)) - ref)) < 1e-12
    with pytest.raises(ValueError):
        box_sum(x, (4, 3))


@pytest.mark.parametrize("method, noise", [("peak", 0.5), ("gradient", 0.1)])
def test_fringe_ramp_estimate_on_a_noisy_ramp(rng, method, noise):
    truth = FringeRamp(0.0123, -0.0311, 0.7)
    ifg = truth.phasor(np.arange(40), np.arange(60)) + noise * (
        rng.standard_normal((40, 60)) + 1j * rng.standard_normal((40, 60))
    )
    got = estimate_fringe_ramp(ifg, method=method)
    assert abs(got.azimuth_cycles_per_line - 0.0123) < 5e-4
    assert abs(got.range_cycles_per_bin + 0.0311) < 5e-4
    assert abs(np.angle(np.exp(1j * (got.phase_rad - 0.7)))) < 0.1


def test_fringe_gradient_estimate_is_not_pulled_by_a_wide_target():
    """A roof over 70 % of the range span: the spectral peak follows a slope, the mean step not."""
    j = np.arange(96)
    roof = 2 * np.pi * 0.8 * np.maximum(0.0, 1 - np.abs(j - 48) / 34.0)
    phase = 2 * np.pi * (-0.03 * j)[None, :] + roof[None, :] + 0 * np.arange(30)[:, None]
    ifg = np.exp(1j * phase)
    grad = estimate_fringe_ramp(ifg, method="gradient")
    peak = estimate_fringe_ramp(ifg, method="peak")
    assert grad.range_cycles_per_bin == pytest.approx(-0.03, abs=1e-9)
    assert abs(peak.range_cycles_per_bin + 0.03) > 0.005
    # The constant: the base (phase 0 at bin 0 after the ramp) is the most common phase.
    assert abs(np.angle(np.exp(1j * grad.phase_rad))) < 0.05


def test_height_map_refuses_non_finite_input():
    cfg = small_config()
    geo = zhao_geometry(cfg)
    img = np.ones((8, 48), np.complex64)
    bad = img.copy()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        height_map(img, bad, geo, 2.4 + np.arange(48) * 1.7e-4, registration=Registration(0, 0))


# ---- the chain end to end --------------------------------------------------------------------
@pytest.fixture(scope="module")
def pin_on_board():
    """Zhao's drawing pin (scaled to the test size) on a diffuse board, two receivers, noise."""
    cfg = small_config()
    surf = sphere_cap(2.5e-3, 0.6e-3)
    ss = surface_scene(
        cfg,
        surf,
        40,
        seed=11,
        spacing_m=default_spacing_m(cfg, 2.0),
        effects=[("noise", {"snr_db": 0.0}), ("interferometric_receivers", {"snr_db": 0.0})],
    )
    main, aux = Simulator(ss.scene).block_with_aux(ss.scene.pulses)
    m, az, rg = process_block(cfg, main, "numpy", ss.scene.start_along_track_m)
    s, _, _ = process_block(cfg, aux["rx1"], "numpy", ss.scene.start_along_track_m)
    return cfg, ss, m, s, az, rg, ss.truth(az, rg)


def test_pin_heights_within_a_twentieth_of_the_ambiguity(pin_on_board):
    cfg, ss, m, s, az, rg, truth = pin_on_board
    geo = zhao_geometry(cfg)
    hm = height_map(m, s, geo, rg, method="mcf")
    err = height_error(hm.height_m, hm.valid, truth.height_m, truth.scored)
    h2pi = float(geo.ambiguity_height_m(2.4))
    assert err["rms_m"] <= h2pi / 20
    assert err["coverage"] >= 0.7
    # Sub-pixel registration found the bistatic range offset (R_rx - R_tx)/2 ≈ -B sinθ / 2.
    expected = -1.6e-3 * math.sin(ZHAO_LOOK_ANGLE_RAD) / 2 / 170e-6
    assert abs(hm.registration.range_px - expected) < 0.1
    # The pin stands out: the mean height near its top vs the board.
    top = truth.scored & (truth.height_m > 0.4e-3) & hm.valid
    board = truth.scored & (truth.height_m == 0) & hm.valid
    assert np.mean(hm.height_m[top]) - np.mean(hm.height_m[board]) == pytest.approx(
        np.mean(truth.height_m[top]), abs=0.1e-3
    )
    assert np.isfinite(hm.height_m).all() and np.all(hm.height_m[~hm.valid] == 0)


def test_flat_earth_from_fringes_agrees_with_geometry(pin_on_board):
    cfg, ss, m, s, az, rg, truth = pin_on_board
    geo = zhao_geometry(cfg)
    hm = height_map(m, s, geo, rg, flat_earth="fringes", method="mcf")
    # Geometric fringe rate across range: dφ_flat/dbin from the exact reference-plane phase.
    rate = float(np.mean(np.diff(geo.phase_rad(rg, 0.0)))) / (2 * math.pi)
    assert hm.fringe_ramp.range_cycles_per_bin == pytest.approx(rate, rel=0.05)
    assert abs(hm.fringe_ramp.azimuth_cycles_per_line) < 0.002
    err = height_error(hm.height_m, hm.valid, truth.height_m, truth.scored)
    assert err["rms_m"] <= float(geo.ambiguity_height_m(2.4)) / 20


def test_without_geometry_the_fringes_are_not_heights(pin_on_board):
    """Skipping step IV leaves the flat-earth ramp: the test can tell a missing removal."""
    cfg, ss, m, s, az, rg, truth = pin_on_board
    geo = zhao_geometry(cfg)
    reg = estimate_registration(m, s)
    ifg = form_interferogram(m, s, reg, np.ones(1), (5, 3), 0.3)
    assert ifg.valid.mean() > 0.5
    with_fe = height_map(m, s, geo, rg, registration=reg, method="mcf")
    no_fe = geo.height_from_phase(rg[None, :], np.unwrap(np.angle(ifg.filtered), axis=1))
    both = truth.scored & with_fe.valid & ifg.valid
    e_no = no_fe[both] - truth.height_m[both]
    assert np.std(e_no) > 5 * np.std(with_fe.height_m[both] - truth.height_m[both])


def test_height_quicklook_png(tmp_path, pin_on_board):
    cfg, ss, m, s, az, rg, truth = pin_on_board
    hm = height_map(m, s, zhao_geometry(cfg), rg, method="mcf")
    path = tmp_path / "h.png"
    save_height_quicklook(path, hm.height_m, hm.valid, az, rg, title="pin")
    import matplotlib.image as mpimg

    png = mpimg.imread(path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    grey = np.all(np.abs(png[..., :3] - 0.6) < 0.01, axis=-1)
    assert grey.sum() > 50  # masked pixels drawn grey
    with pytest.raises(ValueError):
        save_height_quicklook(path, np.full((2, 2), np.nan), np.ones((2, 2), bool), [0, 1], [0, 1])
