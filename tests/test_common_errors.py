"""Errors common to the receivers of one pass reach every receiver (rtsar.scene.effects.base).

A platform piston (Crouch eq. 4.12) is the same phase on the main channel and on each auxiliary
receiver of the same illumination: Zhao 2014's second InSAL receiver, the INO 3D patent's
masked detectors S1, S2 ("the three channels share every pulse").  Per shot, the phase of
Σ_n with[n]·conj(without[n]) must equal the injected truth ε(p) on every channel, so the
interferometric phase between channels is unchanged.  Receiver noise stays per receiver, the
reference region's reference channels model their own paths, and a second pass's ψ_k stays the
differential error.  Also: a surface table with a key its shape does not take is a one-line
error listing the accepted keys.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from rtsar.presets import preset
from rtsar.scene.files import scene_from_table
from rtsar.scene.model import Scene, Targets
from rtsar.scene.simulator import Simulator

H0_M = 2.4 * math.cos(math.atan(math.sqrt(2.0)))  # Zhao's look angle at 2.4 m
PULSES = 12
PISTON = {"random_walk_rad": 0.3, "vibration_rad": 3.0, "vibration_hz": 0.13, "seed": 11}


def _config():
    """zhao-insal (FMCW) with a platform height and 64-sample shots, for speed."""
    cfg = preset("zhao-insal")
    return replace(
        cfg,
        waveform=replace(cfg.waveform, sample_rate_hz=640.0),
        geometry=replace(cfg.geometry, platform_height_m=H0_M),
    ).with_processor(range_bins=48, aperture_pulses=48)


def _scene(cfg, effects, seed=3):
    """Three scatterers at different heights near the scene centre, in the receivers' view."""
    ground0 = math.sqrt(cfg.geometry.slant_range_m**2 - H0_M**2)
    ground = ground0 + np.array([-0.6e-3, 0.0, 0.5e-3])
    height = np.array([0.4e-3, 1.1e-3, -0.3e-3])
    slant = np.hypot(ground, H0_M - height)
    amp = np.array([1.0, 0.7 - 0.2j, 0.5j])
    targets = Targets(np.array([-2e-4, 0.0, 1e-4]), slant, amp, ground, height)
    return Scene(cfg, targets, PULSES, -3e-4, seed, tuple(effects))


def _run(cfg, effects):
    main, aux = Simulator(_scene(cfg, effects)).block_with_aux(PULSES)
    return {"shots": main, **aux}


def _added_phase(with_error, without):
    """Per shot: the phase that turns ``without`` into ``with_error`` (rad, wrapped)."""
    return np.angle(np.sum(with_error * np.conj(without), axis=1))


def _wrap(a):
    return np.angle(np.exp(1j * np.asarray(a)))


def _piston_truth(cfg):
    sim = Simulator(_scene(cfg, [("piston", PISTON)]))
    return sim.effects[0].truth(np.arange(PULSES))


@pytest.mark.parametrize(
    "receivers, channels",
    [
        (("interferometric_receivers", {"baseline_m": 1.6e-3}), ["rx1"]),
        (("interferometric_receivers", {"baseline_m": 1.6e-3, "receivers": 3}), ["rx1", "rx2"]),
        (("amplitude_modulation_3d", {"angular_period_rad": 0.05}), ["sam_s1", "sam_s2"]),
    ],
)
@pytest.mark.parametrize("piston_first", [True, False])
def test_piston_reaches_every_receiver_of_the_pass(receivers, channels, piston_first):
    cfg = _config()
    clean = _run(cfg, [receivers])
    effects = [("piston", PISTON), receivers] if piston_first else [receivers, ("piston", PISTON)]
    with_piston = _run(cfg, effects)
    truth = _piston_truth(cfg)
    assert np.ptp(truth) > 1.0  # a real error, not a constant
    for name in ["shots", *channels]:
        got = _added_phase(with_piston[name], clean[name])
        assert np.max(np.abs(_wrap(got - truth))) < 1e-5, name
        # The interferometric phase between the channels is untouched, shot by shot.
        if name != "shots":
            ifg_clean = np.angle(np.sum(clean[name] * np.conj(clean["shots"]), axis=1))
            ifg = np.angle(np.sum(with_piston[name] * np.conj(with_piston["shots"]), axis=1))
            assert np.max(np.abs(_wrap(ifg - ifg_clean))) < 1e-5, name


def test_common_phase_is_applied_before_each_receivers_own_noise():
    """Noise is per receiver: the same draws with or without the piston (it is not rotated)."""
    cfg = _config()
    sam = ("amplitude_modulation_3d", {"angular_period_rad": 0.05, "snr_db": 0.0})
    noisy = [("noise", {"snr_db": 0.0}), sam]
    a = _run(cfg, noisy + [("piston", PISTON)])
    b = _run(cfg, noisy)
    signal_a = _run(cfg, [sam, ("piston", PISTON)])
    signal_b = _run(cfg, [sam])
    for name in ("shots", "sam_s1", "sam_s2"):
        noise_a = a[name].astype(np.complex128) - signal_a[name]
        noise_b = b[name].astype(np.complex128) - signal_b[name]
        assert np.max(np.abs(noise_a - noise_b)) < 1e-5, name


def test_two_pass_keeps_psi_as_the_differential_error():
    """A second pass repeats the scene's piston; ψ_k is its error relative to pass 0."""
    cfg = _config()
    params = {"mode": "two_pass", "piston_step_rad": 0.3, "seed": 7}
    rx = ("interferometric_receivers", params)
    plain = _run(cfg, [("interferometric_receivers", {"mode": "two_pass"})])
    both = _run(cfg, [rx, ("piston", PISTON)])
    psi = Simulator(_scene(cfg, [rx])).effects[0].truth(PULSES)[1]
    truth = _piston_truth(cfg)
    got_main = _added_phase(both["shots"], plain["shots"])
    got_rx = _added_phase(both["rx1"], plain["rx1"])
    assert np.max(np.abs(_wrap(got_main - truth))) < 1e-5
    assert np.max(np.abs(_wrap(got_rx - truth - psi))) < 1e-5


def test_reference_region_target_phase_is_common_and_reference_channels_keep_their_own():
    """The INO reference region: the target path's φ1t reaches the SAM detectors too; its
    reference channels are unchanged by a piston (they model their own paths, eqs. 4a-4b)."""
    cfg = _config()
    region = (
        "reference_region",
        {"alpha_walk_m": 2e-8, "roll_vibration_rad": 1e-5, "roll_vibration_hz": 0.2, "seed": 5},
    )
    sam = ("amplitude_modulation_3d", {"angular_period_rad": 0.05})
    clean = _run(cfg, [sam])
    with_region = _run(cfg, [region, sam])
    sim = Simulator(_scene(cfg, [region, sam]))
    phi = sim.effects[0].target_phase_rad(np.arange(PULSES))
    assert np.ptp(phi) > 0.5
    for name in ("shots", "sam_s1", "sam_s2"):
        got = _added_phase(with_region[name], clean[name])
        assert np.max(np.abs(_wrap(got - phi))) < 1e-5, name
    with_piston = _run(cfg, [region, sam, ("piston", PISTON)])
    for name in ("reference_rx1", "reference_rx2"):
        assert np.array_equal(with_piston[name], with_region[name]), name


def _surface_table(**surface):
    return {
        "preset": "zhao-insal",
        "geometry": {"platform_height_m": H0_M},
        "waveform": {"sample_rate_hz": 640.0},
        "processor": {"range_bins": 48, "aperture_pulses": 16},
        "surface": {"lines": 2, "scatterers_per_cell": 0.5, **surface},
    }


def test_unknown_surface_key_is_one_line_listing_the_accepted_keys():
    with pytest.raises(ValueError) as err:
        scene_from_table(_surface_table(shape="coin", height_m=2.5e-3))
    msg = str(err.value)
    assert "\n" not in msg
    assert "unknown key" in msg and "height_m" in msg
    assert "unexpected keyword" not in msg
    for accepted in ("relief_m", "radius_m", "lines", "scatterers_per_cell", "shape"):
        assert accepted in msg
    with pytest.raises(ValueError, match=r"half_width_m.*cap_height_m"):
        scene_from_table(_surface_table(shape="drawing_pin", half_width_m=1e-3))
    # The accepted keys still work.
    scene = scene_from_table(_surface_table(shape="coin", relief_m=1e-4))
    assert len(scene.targets) > 0


def test_a_surface_without_platform_height_says_which_key_to_set():
    """Issue 31: the README's [surface] snippet on a preset without a platform height failed
    with "(see zhao_config)", an internal function no user can act on."""
    table = _surface_table(shape="ridge", height_m=2.5e-3)
    del table["geometry"]
    with pytest.raises(ValueError) as err:
        scene_from_table(table)
    msg = str(err.value)
    assert "\n" not in msg and "platform_height_m" in msg and "[geometry]" in msg
    assert "zhao_config" not in msg
