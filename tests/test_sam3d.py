"""Spatial-amplitude-modulation 3D (INO 3D patent): the effect, the height chain, the stream.

Truths come from the geometry (patent eq. 9: cos φ = (H0 - h)/R) computed here in float64, never
from the code under test.  Synthetic-image tests build S1 = S0·T1(φ), S2 = S0·T2(φ) per pixel
(patent eqs. 3-4); one end-to-end test simulates a small speckled ridge through the engine.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from rtsar.instrument import SAM_CHANNELS
from rtsar.presets import preset
from rtsar.scene.effects import load_effects
from rtsar.scene.model import Scene, Targets
from rtsar.scene.simulator import Simulator
from rtsar.stream.engine import focus_channels
from rtsar.topo.looks import box_mean
from rtsar.topo.sam3d import (
    ModulationGeometry,
    anchor_cycles,
    flat_earth_from_reference,
    flat_earth_phase_rad,
    sam_height,
    sam_phase,
    wrapped_phase_rad,
)
from rtsar.topo.sam3d_stream import SamPhaseStream

H0_M = 1.386  # platform height (Zhao's 2.4 m at a 54.7° look angle)
R0_M = 2.4
P_PHI_RAD = 3.3e-3 / (R0_M * math.sqrt(1 - (H0_M / R0_M) ** 2))  # h_2π = 3.3 mm, as Zhao


def _config(**processor):
    """zhao-insal with a platform height, 64-sample shots (a 10.9 mm window) for speed."""
    from dataclasses import replace

    cfg = preset("zhao-insal")
    cfg = replace(
        cfg,
        waveform=replace(cfg.waveform, sample_rate_hz=640.0),
        geometry=replace(cfg.geometry, platform_height_m=H0_M),
    )
    return cfg.with_processor(**{"range_bins": 64, "aperture_pulses": 64, **processor})


def _geometry(**kw) -> ModulationGeometry:
    return ModulationGeometry(H0_M, R0_M, P_PHI_RAD, **kw)


def _masks(phi, a=0.5, b=0.5, theta=0.0):
    """Patent eqs. 1, 3-4 written out: cosine and sine transmissions of the return angle."""
    arg = 2 * np.pi * phi / P_PHI_RAD + theta
    return a + b * np.cos(arg), a + b * np.sin(arg)


def _synthetic(height_fn, shape=(48, 64), seed=0, theta=0.0, dark=None):
    """S0 (circular Gaussian speckle), S1, S2 on a slant-range grid around R0; truth heights."""
    rng = np.random.default_rng(seed)
    range_m = R0_M + (np.arange(shape[1]) - shape[1] // 2) * 170e-6
    x = (np.arange(shape[0]) - shape[0] // 2) * 50e-6
    xx, rr = np.meshgrid(x, range_m, indexing="ij")
    h = height_fn(xx, rr)
    phi = np.arccos((H0_M - h) / rr)  # eq. 9
    s0 = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) / math.sqrt(2)
    if dark is not None:
        s0[dark] = 0
    t1, t2 = _masks(phi, theta=theta)
    return s0, s0 * t1, s0 * t2, range_m, h


def _dome(xx, rr):
    """A Gaussian hill of 5 mm: one and a half 2π cycles, so unwrapping is needed."""
    return 5e-3 * np.exp(-(((xx / 0.8e-3) ** 2) + ((rr - R0_M) / 3e-3) ** 2))


# ---- the effect -----------------------------------------------------------------------------
def _effect_scene(cfg, ground_m, height_m, amplitude, effects, pulses=4):
    ground = np.asarray(ground_m, float)
    height = np.asarray(height_m, float)
    slant = np.hypot(ground, H0_M - height)
    targets = Targets(np.zeros(ground.size), slant, np.asarray(amplitude, complex), ground, height)
    return Scene(cfg, targets, pulses, -1e-4, 7, tuple(effects))


def test_effect_channels_are_the_masked_returns_of_each_scatterer():
    cfg = _config()
    r0 = math.sqrt(R0_M**2 - H0_M**2)
    ground = r0 + np.array([-2e-3, 0.4e-3, 3e-3])
    height = np.array([0.0, 1.7e-3, 0.6e-3])
    amp = np.exp(2j * np.pi * np.array([0.1, 0.45, 0.8]))
    params = {"angular_period_rad": P_PHI_RAD, "mask_offset_a": 0.6, "mask_depth_b": -0.3}
    params["mask_phase_rad"] = 0.7
    scene = _effect_scene(cfg, ground, height, amp, [("amplitude_modulation_3d", params)])
    main, aux = Simulator(scene).block_with_aux(4)
    # Reference: each scatterer alone in the main channel, weighted by its own mask values.
    phi = np.arctan2(ground, H0_M - height)
    arg = 2 * np.pi * phi / P_PHI_RAD + 0.7
    t1, t2 = 0.6 - 0.3 * np.cos(arg), 0.6 - 0.3 * np.sin(arg)
    want1 = np.zeros(main.shape, np.complex128)
    want2 = np.zeros(main.shape, np.complex128)
    for j in range(3):
        alone = _effect_scene(cfg, ground[j : j + 1], height[j : j + 1], amp[j : j + 1], [])
        shots = Simulator(alone).block(4).astype(np.complex128)
        want1 += t1[j] * shots
        want2 += t2[j] * shots
    scale = np.abs(main).max()
    assert np.abs(aux["sam_s1"] - want1).max() < 2e-6 * scale
    assert np.abs(aux["sam_s2"] - want2).max() < 2e-6 * scale
    assert aux["sam_s1"].dtype == np.complex64


def test_effect_validates_parameters_and_geometry():
    cfg = _config()
    with pytest.raises(ValueError, match="unknown parameters"):
        load_effects([("amplitude_modulation_3d", {"angular_period_rad": 1e-3, "b": 1})], cfg)
    with pytest.raises(ValueError, match="angular_period_rad"):
        load_effects([("amplitude_modulation_3d", {"angular_period_rad": -1.0})], cfg)
    with pytest.raises(ValueError, match="mask_depth_b"):
        load_effects(
            [("amplitude_modulation_3d", {"angular_period_rad": 1e-3, "mask_depth_b": 0})], cfg
        )
    flat = preset("zhao-insal")  # platform_height_m = 0
    with pytest.raises(ValueError, match="platform_height_m"):
        load_effects([("amplitude_modulation_3d", {"angular_period_rad": 1e-3})], flat)
    (effect,) = load_effects([("amplitude_modulation_3d", {"angular_period_rad": 1e-3})], cfg)
    bad = Targets(np.zeros(1), np.array([2.4]), np.ones(1, complex), np.array([2.0]), np.zeros(1))
    with pytest.raises(ValueError, match="disagrees"):
        effect.return_angle_rad(bad)
    # without ground range the scatterer lies on the reference plane: cos φ = H0 / R
    plane = Targets(np.zeros(1), np.array([2.4]), np.ones(1, complex))
    assert effect.return_angle_rad(plane)[0] == pytest.approx(math.acos(H0_M / 2.4), abs=1e-15)


def test_effect_noise_has_the_stated_snr():
    cfg = _config()
    eff = ("amplitude_modulation_3d", {"angular_period_rad": P_PHI_RAD, "snr_db": 10.0})
    sim = Simulator(_effect_scene(cfg, [], [], [], [eff], pulses=64))
    _, aux = sim.block_with_aux(64)
    for name in ("sam_s1", "sam_s2"):
        power = np.mean(np.abs(aux[name]) ** 2)
        assert power == pytest.approx(0.1, rel=0.05)  # σ² = 10^(-snr/10), 4096 samples


# ---- eqs. 5-7, 13-15 on synthetic images ----------------------------------------------------
def test_wrapped_phase_is_eq5_and_flat_earth_is_eq7():
    s0, s1, s2, range_m, h = _synthetic(_dome)
    phi = np.arccos((H0_M - h) / range_m[None, :])
    want = np.angle(np.exp(2j * np.pi * phi / P_PHI_RAD))
    got = wrapped_phase_rad(s0, s1, s2, 0.5)
    assert np.abs(np.angle(np.exp(1j * (got - want)))).max() < 1e-9
    r = np.array([1.0, H0_M, 2.0, 2.4])
    fe, ok = flat_earth_phase_rad(r, _geometry())
    assert ok.tolist() == [False, False, True, True] and np.isfinite(fe).all()
    want_fe = np.angle(np.exp(2j * np.pi * np.arccos(H0_M / r[2:]) / P_PHI_RAD))
    assert np.abs(np.angle(np.exp(1j * (fe[2:] - want_fe)))).max() < 1e-9


@pytest.mark.parametrize("method", ["mcf", "ls", "skimage"])
def test_height_of_a_dome_over_one_ambiguity(method):
    s0, s1, s2, range_m, h = _synthetic(_dome)
    geo = _geometry()
    exact = sam_height(
        s0,
        s1,
        s2,
        range_m,
        geo,
        looks=(1, 1),
        dark_floor=0.0,
        height_model="exact",
        unwrap_method=method,
    )
    assert exact.valid.all()
    assert np.abs(exact.height_m - h).max() < 1e-3 * geo.elevation_resolution_m
    eq13 = sam_height(s0, s1, s2, range_m, geo, looks=(1, 1), dark_floor=0.0, unwrap_method=method)
    # eq. 13 is linear in the angle above the flat earth: h13 = R0 sin φ0 (φ - arccos(H0/R))
    rr = range_m[None, :]
    h13 = R0_M * math.sin(geo.look_angle_rad) * (np.arccos((H0_M - h) / rr) - np.arccos(H0_M / rr))
    assert np.abs(eq13.height_m - h13).max() < 1e-3 * geo.elevation_resolution_m
    assert np.abs(eq13.height_m - h).max() < 0.1 * geo.elevation_resolution_m  # its 1st-order error
    assert geo.ambiguity_height_m == pytest.approx(3.3e-3, rel=1e-12)
    assert geo.elevation_resolution_m == pytest.approx(3.3e-3 / 20, rel=1e-12)  # eq. 14


def test_dark_pixels_are_masked_and_counted_never_nan():
    dark = np.zeros((48, 64), bool)
    dark[10:20, 30:50] = True  # no return: S0 = S1 = S2 = 0
    s0, s1, s2, range_m, h = _synthetic(_dome, dark=dark)
    s0[30, 5] = s1[30, 5] = s2[30, 5] = 1e-30  # S0 ≈ 0 but not exactly
    geo = _geometry()
    res = sam_height(s0, s1, s2, range_m, geo, looks=(1, 1), dark_floor=1e-6, height_model="exact")
    assert res.phase.masked_dark == dark.sum() + 1
    assert not res.valid[dark].any() and not res.valid[30, 5]
    for arr in (res.height_m, res.unwrapped_rad, res.phase.wrapped_rad, res.phase.coherence):
        assert np.isfinite(arr).all()
    assert np.all(res.height_m[~res.valid] == 0)
    assert np.abs(res.height_m - h)[res.valid].max() < 1e-3 * res.elevation_resolution_m


def test_noise_power_removes_the_bias_of_eq5_and_masks_noise_only_pixels():
    shape = (96, 64)
    none = np.zeros(shape, bool)
    none[:, 48:] = True  # no return: noise only
    s0, s1, s2, range_m, _ = _synthetic(lambda xx, rr: 0 * xx, shape=shape, seed=8, dark=none)
    rng = np.random.default_rng(9)
    n0 = 0.5  # noise power per pixel, each channel independent: S0 signal-to-noise 3 dB
    noise = rng.standard_normal((3, *shape)) + 1j * rng.standard_normal((3, *shape))
    s0, s1, s2 = (s + math.sqrt(n0 / 2) * n for s, n in zip((s0, s1, s2), noise, strict=True))
    geo = _geometry()
    kw = {"looks": (9, 5), "dark_floor": 0.2, "min_coherence": 0.3}
    plain = sam_phase(s0, s1, s2, range_m, geo, **kw)
    fixed = sam_phase(s0, s1, s2, range_m, geo, noise_power=n0, **kw)
    # Expected without the correction: z ∝ ρ b - a (1 - ρ)(1 + i) e^{-iψ_FE}, ρ = 1 / (1 + N0)
    # (h = 0): a bias that turns with the flat-earth phase, a ripple along range
    rho = 1 / (1 + n0)
    fe = 2 * np.pi * np.arccos(H0_M / range_m) / P_PHI_RAD
    biased = np.angle(rho * 0.5 - 0.5 * (1 - rho) * (1 + 1j) * np.exp(-1j * fe))
    cols = np.arange(5, 40)
    rows = slice(10, -10)
    assert fixed.valid[rows, cols].mean() > 0.9
    # where the bias nearly cancels the signal the plain estimator masks the pixels; elsewhere
    # its phase follows the prediction
    ok = plain.valid[rows, cols].mean(axis=0) > 0.9
    assert ok.sum() >= 25
    got_plain = np.median(plain.wrapped_rad[rows, cols], axis=0)
    got_fixed = np.median(fixed.wrapped_rad[rows, cols], axis=0)

    def rms(v):
        return float(np.sqrt(np.mean(v**2)))

    assert rms((got_plain - biased[cols])[ok]) < 0.1  # noise of a median of ~8 looks
    assert rms(biased[cols][ok]) > 0.4  # the bias is large here
    assert rms(got_fixed) < 0.1
    # noise alone: dark to the corrected estimator; the plain one sees γ ≈ a√2/|b| = 1.41 there,
    # above what returns can give (MAX_COHERENCE), but with the spread of the looks it keeps
    # some of those pixels
    alone = np.zeros(shape, bool)
    alone[:, 52:] = True
    assert fixed.valid[alone].mean() < 0.05
    assert 0.1 < plain.valid[alone].mean() < 0.5


def test_reference_calibration_removes_an_unknown_mask_phase():
    theta = 1.1  # mask shifted by 0.175 period: unknown to the processor's geometry
    geo = _geometry()
    s0, s1, s2, range_m, h = _synthetic(_dome, seed=1, theta=theta)
    r0, r1, r2, _, _ = _synthetic(lambda xx, rr: 0 * xx, seed=2, theta=theta)  # flat reference
    fe = flat_earth_from_reference(r0, r1, r2, geo.mask_offset_a)
    assert fe[0].shape == (1, range_m.size) and fe[1].all()
    calibrated = sam_height(s0, s1, s2, range_m, geo, flat_earth=fe, looks=(1, 1), dark_floor=0.0)
    naive = sam_height(s0, s1, s2, range_m, geo, looks=(1, 1), dark_floor=0.0)
    # eq. 7 without θ leaves θ/2π of an ambiguity height in every pixel
    bias = np.mean(naive.height_m - calibrated.height_m)
    assert bias == pytest.approx(theta / (2 * np.pi) * geo.ambiguity_height_m, rel=0.02)
    # a processor told θ (eq. 7 plus the mask phase) agrees with the calibration
    known = sam_height(
        s0, s1, s2, range_m, _geometry(mask_phase_rad=theta), looks=(1, 1), dark_floor=0.0
    )
    assert np.abs(known.height_m - calibrated.height_m).max() < 1e-3 * geo.elevation_resolution_m
    rel = 0.03  # the first-order error of eq. 13 across the ±5 mm swath
    assert np.abs(calibrated.height_m - h).max() < rel * h.max() + 1e-3 * geo.ambiguity_height_m


def test_anchor_picks_the_cycle_that_puts_the_reference_plane_at_zero():
    rng = np.random.default_rng(4)
    truth = np.zeros((20, 30))
    truth[5:15, 10:20] = 2.0  # a raised block on the reference plane
    wrapped = np.angle(np.exp(1j * truth))
    valid = np.ones(truth.shape, bool)
    shifted = truth + 4 * np.pi + 1e-3 * rng.standard_normal(truth.shape)
    got = anchor_cycles(shifted, wrapped, valid)
    assert np.abs(got - truth).max() < 1e-2
    # a least-squares result may also be off by a fraction of a cycle: congruence restores it
    assert np.abs(anchor_cycles(truth - 2 * np.pi + 0.3, wrapped, valid) - truth).max() < 1e-12
    ground = truth == 0
    up = anchor_cycles(truth + 2 * np.pi, wrapped, valid, reference_mask=ground)
    assert np.abs(up - truth).max() < 1e-12


def test_box_mean_is_the_mean_over_the_window_inside_the_image():
    rng = np.random.default_rng(10)
    x = rng.standard_normal((7, 9)) + 1j * rng.standard_normal((7, 9))
    got = box_mean(x, (5, 3))
    want = np.empty_like(x)
    for i in range(7):
        for j in range(9):
            want[i, j] = x[max(0, i - 2) : i + 3, max(0, j - 1) : j + 2].mean()
    assert np.abs(got - want).max() < 1e-12
    with pytest.raises(ValueError, match="odd"):
        box_mean(x, (4, 3))


# ---- in the stream --------------------------------------------------------------------------
def test_stream_equals_batch_over_random_micro_batches():
    dark = np.zeros((48, 64), bool)
    dark[:, 40:44] = True
    s0, s1, s2, range_m, _ = _synthetic(_dome, seed=5, dark=dark)
    rng = np.random.default_rng(6)
    noise = 0.3 * (rng.standard_normal((3, *s0.shape)) + 1j * rng.standard_normal((3, *s0.shape)))
    s0, s1, s2 = s0 + noise[0] * ~dark, s1 + noise[1] * ~dark, s2 + noise[2] * ~dark
    geo = _geometry()
    batch = sam_phase(s0, s1, s2, range_m, geo, looks=(5, 3), dark_floor=0.05, min_coherence=0.5)
    assert batch.masked_dark > 0 and batch.masked_incoherent > 0
    stream = SamPhaseStream(geo, range_m, dark_floor=0.05, looks=(5, 3), min_coherence=0.5)
    cuts = np.sort(rng.choice(np.arange(1, 48), size=9, replace=False))
    parts = [
        stream.push(a, b, c)
        for a, b, c in zip(*(np.split(s, cuts) for s in (s0, s1, s2)), strict=True)
    ]
    parts.append(stream.flush())
    assert [p.first_line for p in parts] == list(
        np.cumsum([0] + [len(p.valid) for p in parts])[:-1]
    )
    wrapped = np.concatenate([p.wrapped_rad for p in parts])
    valid = np.concatenate([p.valid for p in parts])
    coherence = np.concatenate([p.coherence for p in parts])
    assert np.array_equal(valid, batch.valid)
    assert np.abs(wrapped - batch.wrapped_rad).max() < 1e-12
    assert np.abs(coherence - batch.coherence).max() < 1e-12
    assert (stream.masked_dark, stream.masked_incoherent) == (
        batch.masked_dark,
        batch.masked_incoherent,
    )
    assert stream.lines_out == 48


# ---- end to end: simulator, engine, chain ---------------------------------------------------
def test_speckled_ridge_through_the_engine_within_eq14():
    from rtsar.scene import relief as surfaces

    cfg = _config()
    geo = ModulationGeometry.from_config(cfg, P_PHI_RAD)
    surface = surfaces.ridge(height_m=2.5e-3, half_width_m=4e-3)
    effect = ("amplitude_modulation_3d", {"angular_period_rad": P_PHI_RAD})
    ss = surfaces.surface_scene(
        cfg, surface, 16, seed=3, effects=[effect], spacing_m=surfaces.default_spacing_m(cfg, 2.0)
    )
    main, aux = Simulator(ss.scene).block_with_aux(ss.scene.pulses)
    (s0, s1, s2), az, rm = focus_channels(
        cfg, main, aux, SAM_CHANNELS, "numpy", ss.scene.start_along_track_m
    )
    res = sam_height(s0, s1, s2, rm, geo, looks=(5, 3))
    truth = ss.truth(az, rm)
    scored = truth.scored & res.valid
    assert scored.sum() > 0.8 * truth.scored.sum()
    err = res.height_m[scored] - truth.height_m[scored]
    assert np.sqrt(np.mean(err**2)) < geo.elevation_resolution_m  # eq. 14
    assert np.ptp(truth.height_m[scored]) > 2e-3  # the ridge is in the scored pixels
