"""Chirp defects and the reference channels (Crouch 2012 ch. 3; Zhao 2014 channels 1-2).

Every expectation is computed here from the physics in float64 (Crouch eqs. 3.2-3.4, Beer-
Lambert with Lorentzian lines) or by the simulator's own echo synthesis, never by the effect
under test.
"""

import math

import numpy as np
import pytest

from rtsar.instrument import hcn_lines
from rtsar.params import C_M_PER_S
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene
from rtsar.scene.effects import load_effects

CFG = preset("crouch-sal").with_processor(aperture_pulses=64, range_bins=256)
WF = CFG.waveform
F0 = CFG.geometry.carrier_hz
K = WF.chirp_rate_hz_per_s
T_MAIN = (np.arange(WF.samples_per_shot) - 0.5 * WF.samples_per_shot) / WF.sample_rate_hz


def shots(effects, pulses=4, range_m=1.505, seed=1):
    scene = point_scene(
        CFG, [0.0], [range_m], effects=effects, seed=seed, pulses=pulses, start_along_track_m=0.0
    )  # pulse 0 at closest approach: the range is range_m to 1e-10 relative over a few pulses
    sim = Simulator(scene)
    main, aux = sim.block_with_aux(pulses)
    return sim, main, aux


def effect(sim, name):
    return next(e for e in sim.effects if e.name == name)


def numeric_frequency_hz(e, pulse, u):
    """Δf = de/du by a central difference of the effect's phase (cycles), float64."""
    h = 1e-7 * WF.chirp_duration_s
    return (e.chirp_deviation_cycles(pulse, u + h) - e.chirp_deviation_cycles(pulse, u - h)) / (
        2 * h
    )


def test_registry_names_load_and_reject_unknown_parameters():
    specs = [
        ("chirp_nonlinearity", {"sine_fraction": 0.01}),
        ("start_frequency_jitter", {"std_hz": 1e9}),
        ("reference_interferometer", {}),
        ("hcn_cell", {"oversampling": 4}),
    ]
    names = [type(e).__name__ for e in load_effects(specs, CFG)]
    assert names == [
        "ChirpNonlinearity",
        "StartFrequencyJitter",
        "ReferenceInterferometer",
        "HCNCell",
    ]
    with pytest.raises(ValueError, match="unknown parameters"):
        load_effects([("hcn_cell", {"line_width": 1e9})], CFG)


@pytest.mark.parametrize(
    "params",
    [
        {"sine_fraction": 0.01, "sine_periods": 5.0},  # cosine, whole periods: no linear part
        {"poly_fraction": [0.0, 0.0, 0.015]},  # x²: line fit c/3, peak residual 2c/3 = 1 %
    ],
)
def test_one_percent_nonlinearity_as_defined(params):
    """Peak deviation of the instantaneous frequency from its best straight line = 1 % of B."""
    (e,) = load_effects([("chirp_nonlinearity", params)], CFG)
    u = np.linspace(-0.5 * WF.chirp_duration_s, 0.5 * WF.chirp_duration_s, 2001)
    df = numeric_frequency_hz(e, 0, u)
    line = np.polyval(np.polyfit(u, df, 1), u)
    assert np.max(np.abs(df - line)) / WF.bandwidth_hz == pytest.approx(0.01, rel=2e-3)
    assert e.nonlinearity() == pytest.approx(0.01, rel=2e-3)
    # the truth accessor is the derivative of the injected phase
    np.testing.assert_allclose(e.frequency_deviation_hz(0, u), df, rtol=0, atol=1e-6 * 3e10)


def test_nonlinear_chirp_smears_the_beat_tone():
    """Crouch Fig. 5: with a 1 % quadratic sweep the beat frequency drifts by Δτ·Δf'(t)."""
    r = 1.512
    _, lin, _ = shots([], pulses=1, range_m=r)
    _, bad, _ = shots([("chirp_nonlinearity", {"poly_fraction": [0, 0, 0.015]})], 1, r)
    dtau = 2 * (r - WF.reference_range_m) / C_M_PER_S
    # beat phase difference, unwrapped: -Δτ [Δf(t) - Δf(0)] with Δf = 0.015 B (2t/T)²
    diff = np.unwrap(np.angle(bad[0] * np.conj(lin[0]))) / (2 * np.pi)
    expected = -dtau * 0.015 * WF.bandwidth_hz * (2 * T_MAIN / WF.chirp_duration_s) ** 2
    diff -= diff[len(diff) // 2] - expected[len(diff) // 2]
    assert np.max(np.abs(diff - expected)) < 1e-3 * np.ptp(expected)
    assert np.ptp(expected) > 1.0  # more than a cycle across the shot: the tone is smeared


def test_start_frequency_jitter_phase_is_minus_offset_times_delay():
    """e_p(u) = δf_p u gives every return -δf_p Δτ cycles (Crouch ch. 3, HCN cell)."""
    r = 1.495
    _, ref, _ = shots([], pulses=6, range_m=r)
    sim, jit, _ = shots([("start_frequency_jitter", {"std_hz": 10e9, "seed": 4})], 6, r)
    dtau = 2 * (r - WF.reference_range_m) / C_M_PER_S
    truth = effect(sim, "start_frequency_jitter").truth(np.arange(6))
    measured = np.angle(np.sum(jit * np.conj(ref), axis=1))
    expected = np.angle(np.exp(-2j * np.pi * truth * dtau))
    np.testing.assert_allclose(np.angle(np.exp(1j * (measured - expected))), 0, atol=1e-4)
    assert np.std(truth * dtau) > 0.1  # a tenth of a cycle or more: the error matters


def test_jitter_statistics_and_reproducibility():
    (e,) = load_effects([("start_frequency_jitter", {"std_hz": 10e9, "seed": 7})], CFG)
    (same,) = load_effects([("start_frequency_jitter", {"std_hz": 10e9, "seed": 7})], CFG)
    (other,) = load_effects([("start_frequency_jitter", {"std_hz": 10e9, "seed": 8})], CFG)
    p = np.arange(4000)
    d = e.truth(p)
    assert np.std(d) == pytest.approx(10e9, rel=0.05)
    assert abs(np.mean(d)) < 0.1 * 10e9
    np.testing.assert_array_equal(d[::-1], same.truth(p[::-1]))  # order does not matter
    assert not np.allclose(d[:10], other.truth(p[:10]))


def test_reference_interferometer_matches_the_simulators_echo():
    """Channel 2 = the simulator's dechirp of a 'target' at c τ_ri/2 with the LO at zero delay."""
    effects = [
        ("chirp_nonlinearity", {"sine_fraction": 0.01, "sine_periods": 3.0}),
        ("start_frequency_jitter", {"std_hz": 10e9, "seed": 2}),
        ("reference_interferometer", {}),
    ]
    sim, _, aux = shots(effects, pulses=3)
    ri_effect = effect(sim, "reference_interferometer")
    nl, jit = effect(sim, "chirp_nonlinearity"), effect(sim, "start_frequency_jitter")
    ri = aux["reference_interferometer"]
    assert ri.shape == (3, WF.samples_per_shot) and ri.dtype == np.complex64
    for p in range(3):

        def deviation(u, p=p):
            return nl.chirp_deviation_cycles(p, u) + jit.chirp_deviation_cycles(p, u)

        want = sim.echo(0.5 * C_M_PER_S * ri_effect.delay_s, 1.0, deviation, lo_range_m=0.0)
        np.testing.assert_allclose(ri[p], want, atol=2e-6)


def test_reference_interferometer_noise_level():
    sim, _, aux = shots([("reference_interferometer", {"snr_db": 20.0})], pulses=8, seed=3)
    clean = shots([("reference_interferometer", {})], pulses=8)[2]["reference_interferometer"]
    noise = aux["reference_interferometer"] - clean
    assert np.std(noise) == pytest.approx(0.1, rel=0.05)  # 10^(-20/20)
    again = shots([("reference_interferometer", {"snr_db": 20.0})], pulses=8, seed=3)[2]
    np.testing.assert_array_equal(
        again["reference_interferometer"], aux["reference_interferometer"]
    )


def test_hcn_channel_is_beer_lambert_through_lorentzian_lines():
    """Channel 1: I(t) = exp(-a Σ s_j / (1 + (2(f(t) - f_j)/γ)²)), f(t) = f0 + K t + δf + Δf(t)."""
    gamma, a, q = 2e9, 0.8, 4
    effects = [
        ("chirp_nonlinearity", {"poly_fraction": [0, 0, 0.006], "sine_fraction": 0.002}),
        ("start_frequency_jitter", {"std_hz": 10e9, "seed": 5}),
        ("hcn_cell", {"linewidth_hz": gamma, "peak_absorbance": a, "oversampling": q}),
    ]
    sim, _, aux = shots(effects, pulses=2)
    hcn = aux["hcn_cell"]
    m = q * WF.samples_per_shot
    assert hcn.shape == (2, m) and np.all(hcn.imag == 0)
    t = (np.arange(m) - 0.5 * m) / (q * WF.sample_rate_hz)
    lines, strength = hcn_lines()
    for p in range(2):
        f = F0 + K * t + effect(sim, "start_frequency_jitter").offset_hz(p)
        f = f + effect(sim, "chirp_nonlinearity").frequency_deviation_hz(p, t)
        absorbance = np.zeros(m)
        for fj, sj in zip(lines, strength, strict=True):
            absorbance += sj / (1.0 + (2.0 * (f - fj) / gamma) ** 2)
        np.testing.assert_allclose(hcn[p].real, np.exp(-a * absorbance), atol=2e-6)
    assert hcn.real.min() < 0.6  # deep lines are in the sweep
    n_lines = np.count_nonzero(
        (lines > F0 - 0.5 * WF.bandwidth_hz) & (lines < F0 + 0.5 * WF.bandwidth_hz)
    )
    assert n_lines >= 25  # 3 THz over an ~86 GHz comb


def test_channel_and_defect_parameters_are_validated():
    pulsed = preset("tiny")
    with pytest.raises(ValueError, match="FMCW"):
        load_effects([("reference_interferometer", {})], pulsed)
    with pytest.raises(ValueError, match="FMCW"):
        load_effects([("hcn_cell", {})], pulsed)
    with pytest.raises(ValueError, match="Nyquist"):
        load_effects([("reference_interferometer", {"delay_s": 1e-6})], CFG)
    with pytest.raises(ValueError, match="oversampling"):
        load_effects([("hcn_cell", {"oversampling": 0})], CFG)
    with pytest.raises(ValueError, match="no HCN line"):
        from dataclasses import replace

        far = replace(CFG, geometry=replace(CFG.geometry, wavelength_m=1.0e-6))
        load_effects([("hcn_cell", {})], far)
    with pytest.raises(ValueError, match="sine_periods"):
        load_effects([("chirp_nonlinearity", {"sine_periods": 0.0})], CFG)
    with pytest.raises(ValueError, match="poly_fraction"):
        load_effects([("chirp_nonlinearity", {"poly_fraction": "0.01"})], CFG)
    with pytest.raises(ValueError, match="std_hz"):
        load_effects([("start_frequency_jitter", {"std_hz": math.nan})], CFG)
    # the defects also act on a pulsed chirp (Psaltis eq. 1 with a deviation)
    (e,) = load_effects([("chirp_nonlinearity", {"sine_fraction": 0.01})], pulsed)
    assert e.nonlinearity() == pytest.approx(0.01, rel=2e-3)
