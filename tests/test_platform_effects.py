"""Platform phase-error effects: piston (Crouch eq. 4.12), step jitter (eq. 4.13), the INO
patent's reference-region channels (eqs. 3-4, 10); truth regenerated and checked against what the
simulator produces."""

import math
from dataclasses import replace

import numpy as np
import pytest

from rtsar.lens.base import compress_reference
from rtsar.lens.plan import make_plan
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene
from rtsar.scene.effects import load_effects
from rtsar.scene.effects.platform import PulseProcess


def wrap(a):
    return np.angle(np.exp(1j * np.asarray(a)))


def peak_phases(cfg, shots):
    """Phase of the brightest compressed bin of each shot (float64 lens reference)."""
    lines = compress_reference(make_plan(cfg), shots)
    k = np.argmax(np.abs(lines), axis=1)
    return np.angle(lines[np.arange(len(lines)), k])


# -- the error sequence ------------------------------------------------------------------------
def test_process_is_reproducible_in_any_order_and_across_chunks():
    kw = dict(white=0.1, walk=0.3, drift=5e-3, vibration=2.0, vibration_hz=0.3, seed=9)
    a = PulseProcess(2.0, **kw)
    b = PulseProcess(2.0, **kw)
    pulses = np.arange(0, 3 * PulseProcess.CHUNK + 17)
    whole = a.values(pulses)
    rng = np.random.default_rng(0)
    order = rng.permutation(len(pulses))
    assert np.array_equal(b.values(pulses[order]), whole[order])  # chunks met out of order
    assert not np.allclose(PulseProcess(2.0, **{**kw, "seed": 10}).values(pulses), whole)
    assert np.isfinite(whole).all()


def test_process_statistics():
    n = 20000
    p = np.arange(n)
    walk = PulseProcess(1.0, walk=0.3, seed=1).values(p)
    assert np.std(np.diff(walk)) == pytest.approx(0.3, rel=0.03)  # step std of the walk
    white = PulseProcess(1.0, white=0.2, seed=2).values(p)
    assert np.std(white) == pytest.approx(0.2, rel=0.03)
    assert abs(np.corrcoef(white[1:], white[:-1])[0, 1]) < 0.03  # independent per pulse
    drift = PulseProcess(1.0, drift=1e-3, seed=3).values(p)
    assert np.std(np.diff(drift, 2)) == pytest.approx(1e-3, rel=0.03)  # rate random walk
    # A sampled sinusoid obeys v[p+1] + v[p-1] = 2 cos(ω) v[p], ω = 2π f / PRF.
    prf, f, amp = 5.0, 0.37, 2.5
    vib = PulseProcess(prf, vibration=amp, vibration_hz=f, seed=4).values(p[:500])
    omega = 2 * math.pi * f / prf
    assert np.allclose(vib[2:] + vib[:-2], 2 * math.cos(omega) * vib[1:-1], atol=1e-9)
    assert np.max(np.abs(vib)) == pytest.approx(amp, rel=1e-3)


@pytest.mark.parametrize(
    "name, params",
    [
        ("piston", {"random_walk_rad": -1.0}),
        ("piston", {"vibration_hz": float("nan")}),
        ("piston", {"seed": -1}),
        ("piston", {"walk": 1.0}),
        ("along_track_jitter", {"std_m": "big"}),
        ("reference_region", {"D_m": 0.0}),
        ("reference_region", {"beam_diameter_m": 0.05}),  # breaks πF²/(4λH) < 2π
        ("reference_region", {"region_depth_m": 1.0}),  # leaves the aux range window
    ],
)
def test_bad_parameters_are_errors(name, params):
    with pytest.raises(ValueError):
        load_effects([(name, params)], preset("zhao-insal"))


def test_reference_region_needs_fmcw():
    with pytest.raises(ValueError, match="FMCW"):
        load_effects([("reference_region", {})], preset("tiny"))


# -- piston ------------------------------------------------------------------------------------
def test_piston_adds_its_truth_to_every_shot():
    """Crouch eq. 4.12: one phase per shot, whatever the target; scale of Crouch Fig. 20."""
    cfg = preset("crouch-sal").with_processor(aperture_pulses=64, range_bins=64)
    r = cfg.geometry.slant_range_m
    params = dict(
        random_walk_rad=0.3,
        drift_rad=0.2,
        vibration_rad=3.0,
        vibration_hz=0.3,
        white_rad=0.1,
        seed=5,
    )
    n = 120
    for x in (0.0, 2e-4):  # the error does not depend on the target's position
        clean = point_scene(cfg, [x], [r], start_along_track_m=-3e-4, pulses=n)
        err = point_scene(
            cfg, [x], [r], effects=[("piston", params)], start_along_track_m=-3e-4, pulses=n
        )
        sim = Simulator(err)
        measured = peak_phases(cfg, sim.block(n)) - peak_phases(cfg, Simulator(clean).block(n))
        truth = sim.effects[0].truth(np.arange(n))
        assert np.max(np.abs(wrap(measured - truth))) < 1e-4
    assert np.ptp(truth) > 50  # tens to hundreds of radians: Crouch Fig. 20 scale
    disp = sim.effects[0].displacement_m(np.arange(n))
    assert np.allclose(4 * np.pi * disp / cfg.geometry.wavelength_m, truth)


# -- along-track jitter ------------------------------------------------------------------------
def test_jitter_moves_the_platform_and_changes_phase_as_eq_4_13():
    """Crouch's own numbers: x = 1 cm, Δ = 2.5 µm, λ = 1.55 µm, R = 1 m → 2πxΔ/(λR) ≈ 0.1 rad
    one way; the simulator's two-way phase change must be twice that, 4πxΔ/(λR)."""
    cfg = preset("crouch-sal").with_processor(aperture_pulses=64, range_bins=64)
    r, x, n = cfg.geometry.slant_range_m, 0.01, 40
    eff = [("along_track_jitter", {"std_m": 2.5e-6, "seed": 2})]
    # Platform at x = 0 for every shot (along_track_step tiny against the target offset).
    clean = point_scene(cfg, [x], [r], start_along_track_m=0.0, pulses=n)
    jit = point_scene(cfg, [x], [r], effects=eff, start_along_track_m=0.0, pulses=n)
    sim = Simulator(jit)
    phase = peak_phases(cfg, sim.block(n)) - peak_phases(cfg, Simulator(clean).block(n))
    effect = sim.effects[0]
    delta = effect.truth(np.arange(n))
    nominal = jit.along_track_of(np.arange(n))
    assert np.allclose([sim.platform_along_track_m(p) for p in range(n)], nominal + delta)
    lam = cfg.geometry.wavelength_m
    # Offset x seen from platform p: x - x_p (x_p = p·10 µm); Crouch eq. 4.13, two-way.
    expected = 4 * np.pi * (x - nominal) * delta / (lam * r)
    assert np.max(np.abs(wrap(phase - expected))) < 0.02 * np.max(np.abs(expected)) + 1e-4
    assert np.std(delta) == pytest.approx(2.5e-6, rel=0.35)
    assert 2 * np.pi * 0.01 * 2.5e-6 / (1.55e-6 * 1.0) == pytest.approx(0.1, rel=0.02)


def test_accumulated_jitter_is_a_random_walk():
    cfg = preset("zhao-insal")
    (eff,) = load_effects([("along_track_jitter", {"std_m": 1e-6, "accumulate": True})], cfg)
    d = eff.truth(np.arange(5000))
    assert np.std(np.diff(d)) == pytest.approx(1e-6, rel=0.05)
    assert np.std(d) > 10e-6  # wanders far beyond one step


# -- reference region --------------------------------------------------------------------------
@pytest.fixture(scope="module")
def region_runs():
    """One scene with and one without motion errors (same scatterers), 48 pulses."""
    cfg = preset("zhao-insal").with_processor(aperture_pulses=32, range_bins=32)
    r = cfg.geometry.slant_range_m
    base = dict(seed=4, scatterers_per_cell=2.0, region_depth_m=12 * 170e-6)
    motion = dict(
        alpha_walk_m=2e-8,
        alpha_vibration_m=3e-7,
        alpha_vibration_hz=0.4,
        roll_walk_rad=2e-7,
        roll_vibration_rad=3e-6,
        roll_vibration_hz=0.3,
    )
    out = {}
    for key, params in (("clean", base), ("moving", {**base, **motion})):
        scene = point_scene(
            cfg,
            [0.0],
            [r],
            effects=[("reference_region", params)],
            start_along_track_m=-1.2e-3,
            pulses=48,
        )
        sim = Simulator(scene)
        main, aux = sim.block_with_aux(48)
        out[key] = (sim.effects[0], main, aux)
    return cfg, out


def test_reference_region_channels_carry_eq_3_errors(region_runs):
    """S1r gains 2α - Dβ, S2r 2α - 2Dβ, the target 2α + dβ (pure phases, eqs. 3-4, 10)."""
    cfg, runs = region_runs
    eff, main, aux = runs["moving"]
    _, main0, aux0 = runs["clean"]
    p = np.arange(len(main))
    a, b = eff.alpha_m(p), eff.beta_rad(p)
    lam = cfg.geometry.wavelength_m
    k = 2 * np.pi / lam
    expected = {
        "reference_rx1": -k * (2 * a - eff.D_m * b),
        "reference_rx2": -k * (2 * a - 2 * eff.D_m * b),
    }
    for name, phase in expected.items():
        measured = np.angle(np.sum(aux[name] * np.conj(aux0[name]), axis=1))
        assert np.max(np.abs(wrap(measured - phase))) < 1e-3, name
        assert np.ptp(phase) > 1.0  # the errors are not negligible here
    target = np.angle(np.sum(main * np.conj(main0), axis=1))
    assert np.max(np.abs(wrap(target + k * (2 * a + eff.d_m * b)))) < 1e-3
    assert np.allclose(eff.target_phase_rad(p), -k * (2 * a + eff.d_m * b))


def test_reference_region_is_a_speckled_band_in_range(region_runs):
    """Power per range bin: the lit band holds it (amplitude² per cell on average), outside
    it only sidelobes; S2r has no azimuth chirp (collimated), so adjacent shots stay coherent."""
    cfg, runs = region_runs
    eff, _, aux = runs["clean"]
    wide = replace(
        cfg,
        waveform=replace(cfg.waveform, reference_range_m=eff.lo_range_m),
        processor=replace(cfg.processor, range_bins=64, range_centre_m=eff.region_range_m),
    )
    plan = make_plan(wide)
    s2 = compress_reference(plan, aux["reference_rx2"])
    power = np.mean(np.abs(s2) ** 2, axis=0)
    offset = np.abs(plan.range_m - eff.region_range_m)
    band = offset <= 0.5 * eff.region_depth_m
    # Scatterers of rms amplitude A/sqrt(n) at n per range cell and beam diameter F, two-way
    # Gaussian beam power w⁴(u) = exp(-16u²/F²): ∫w⁴ du = F·sqrt(π)/4, so A²·sqrt(π)/4 per bin.
    expected = eff.amplitude**2 * math.sqrt(math.pi) / 4
    assert np.mean(power[band]) == pytest.approx(expected, rel=0.5)
    far = offset > 0.5 * eff.region_depth_m + 6 * cfg.waveform.range_resolution_m
    assert far.sum() > 10
    assert np.mean(power[far]) < 0.05 * np.mean(power[band])
    lag = np.abs(np.sum(s2[1:, band] * np.conj(s2[:-1, band]))) / np.sum(np.abs(s2[1:, band]) ** 2)
    assert lag > 0.9
    assert len(eff._tiles) <= 4  # bounded: only the tiles around the beam are kept
