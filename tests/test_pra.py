"""Phase-to-retro (Crouch ch. 4, Appendix A): the float64 reference against physical truth, the
stream stage against the reference, and focus restored after Crouch-size piston errors."""

import numpy as np
import pytest

from rtsar.analysis import analyse_point_target
from rtsar.ccd.base import correlate_reference, design_mask
from rtsar.focus.pra import PhaseToRetro, phase_to_retro_reference
from rtsar.lens.numpy_lens import NumpyLens
from rtsar.lens.plan import make_plan
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene


def wrap(a):
    return np.angle(np.exp(1j * np.asarray(a)))


def residual_rms(estimate, truth):
    """rms of the wrapped difference after removing its circular mean (a constant phase)."""
    d = wrap(np.asarray(estimate) - truth)
    d = wrap(d - np.angle(np.mean(np.exp(1j * d))))
    return float(np.sqrt(np.mean(d**2)))


CFG = preset("zhao-insal").with_processor(aperture_pulses=96, range_bins=48)


def synthetic_lines(rng, pulses=300, snr=None, start_m=-4e-3):
    """Range-compressed lines written from the geometry alone (no rtsar code): a retro of
    amplitude 10 as a sampled sinc at its migrating range, a weaker target, a piston error."""
    g = CFG.geometry
    rm = make_plan(CFG).range_m
    dr = rm[1] - rm[0]
    xr, rr = 1e-4, rm[20] + 0.3 * dr
    x = start_m + np.arange(pulses) * g.along_track_step_m
    rng_r = np.hypot(rr, x - xr)
    n = np.arange(pulses)
    eps = np.cumsum(rng.normal(0, 0.8, pulses)) + 3 * np.sin(0.4 * n) + 2e-3 * (n - pulses / 2) ** 2
    carrier = np.mod(-2 * rng_r / g.wavelength_m, 1.0)
    k = np.arange(len(rm))
    lines = (
        10
        * np.exp(2j * np.pi * carrier + 1j * eps)[:, None]
        * np.sinc(k[None, :] - (rng_r[:, None] - rm[0]) / dr)
    )
    lines = lines + 0.7 * np.exp(1j * rng.uniform(0, 2 * np.pi, (pulses, 1))) * np.sinc(
        k[None, :] - 35.2
    )
    if snr is not None:
        lines = lines + (
            rng.standard_normal(lines.shape) + 1j * rng.standard_normal(lines.shape)
        ) * 10 / np.sqrt(2 * snr)
    return lines, eps, (xr, rr, start_m)


def test_reference_recovers_the_injected_phase(rng):
    lines, eps, (xr, rr, start) = synthetic_lines(rng)
    assert np.ptp(eps) > 20
    out, est, found = phase_to_retro_reference(lines, CFG, xr, rr, start)
    assert found.all()
    # The weaker target's range sidelobes reach the retro's bins at about 0.7/(15π)/10 of its
    # amplitude: a clutter phase of ~1e-3 rad is the only error left.
    assert residual_rms(est, eps) < 3e-3
    # After correction the retro's bin follows the error-free history: its pulse-to-pulse phase
    # steps equal those of -4π/λ sqrt(R² + x²).
    g = CFG.geometry
    x = start + np.arange(len(lines)) * g.along_track_step_m
    ideal = -4 * np.pi * np.hypot(rr, x - xr) / g.wavelength_m
    k = np.argmax(np.abs(out), axis=1)
    got = np.angle(out[np.arange(len(out)), k])
    assert residual_rms(got, ideal) < 3e-3
    # With noise (peak SNR 30 dB) the residual is about 1/sqrt(2·SNR·3 bins) rad.
    lines_n, eps_n, _ = synthetic_lines(np.random.default_rng(1), snr=1000.0)
    _, est_n, _ = phase_to_retro_reference(lines_n, CFG, xr, rr, start)
    assert residual_rms(est_n, eps_n) < 0.05


def test_stream_equals_batch_in_random_micro_batches(rng):
    lines, _, (xr, rr, start) = synthetic_lines(rng, snr=300.0)
    lines[50:53] = 0  # the retro vanishes: held
    lines[90, 4] = np.nan  # a bad line: zeroed, held
    ref, est, found = phase_to_retro_reference(lines, CFG, xr, rr, start)
    stage = PhaseToRetro(CFG, xr, rr, start)
    lines32 = lines.astype(np.complex64)
    cuts = np.sort(rng.choice(np.arange(1, len(lines)), 25, replace=False))
    parts, eps = [], []
    for chunk in np.split(lines32, cuts):
        parts.append(stage.process(chunk))
        eps.append(stage.last_phase_error_rad)
    out = np.concatenate(parts)
    assert out.dtype == np.complex64
    assert np.all(np.isfinite(out))
    assert np.max(np.abs(out - ref)) < 1e-5 * np.max(np.abs(ref))
    assert np.max(np.abs(wrap(np.concatenate(eps) - est))) < 1e-4
    assert stage.shots_not_corrected == int((~found).sum()) == 4
    assert stage.nonfinite_lines == 1
    assert stage.pulses_in == len(lines)
    assert est[50] == est[51] == est[52] == est[49]  # the last good estimate is held


def test_missing_retro_from_the_start_is_counted_and_never_nan():
    stage = PhaseToRetro(CFG, 0.0, CFG.geometry.slant_range_m)
    zeros = np.zeros((10, CFG.processor.range_bins), np.complex64)
    out = stage.process(zeros)
    assert np.all(out == 0) and stage.shots_not_corrected == 10
    assert np.all(stage.last_phase_error_rad == 0)
    assert stage.process(zeros[:0]).shape == (0, CFG.processor.range_bins)


def test_bad_arguments():
    with pytest.raises(ValueError, match="search window"):
        PhaseToRetro(CFG, 0.0, CFG.geometry.slant_range_m, search_radius_m=1e-6)
    with pytest.raises(ValueError, match="search window"):
        PhaseToRetro(CFG, 0.0, 1.0)  # far outside the range window
    stage = PhaseToRetro(CFG, 0.0, CFG.geometry.slant_range_m)
    with pytest.raises(ValueError, match="lines must be"):
        stage.process(np.zeros((3, 7), np.complex64))
    with pytest.raises(ValueError):
        PhaseToRetro(CFG, 0.0, CFG.geometry.slant_range_m, min_contrast=0.5)


def test_focus_restored_after_crouch_size_piston():
    """Simulated retro + target with a piston error of hundreds of radians (Crouch Fig. 20):
    uncorrected the image is "worthless"; after PRA both targets' azimuth IRW and PSLR are within
    10 % of the error-free focus of the same scene (noise included)."""
    cfg = CFG.with_processor(range_window="taylor")
    g = cfg.geometry
    rm = make_plan(cfg).range_m
    dr = rm[1] - rm[0]
    xr, rr = 0.0, rm[14] + 0.3 * dr
    xt, rt = 0.6e-3, rm[34] + 0.41 * dr
    n = cfg.processor.aperture_pulses
    start = -(0.5 * (n - 1) + 40) * g.along_track_step_m
    pulses = n + 80
    piston = (
        "piston",
        dict(
            random_walk_rad=0.3,
            drift_rad=0.1,
            vibration_rad=3.0,
            vibration_hz=0.35,
            white_rad=0.1,
            seed=7,
        ),
    )
    noise = ("noise", {"snr_db": 0.0})
    lens, mask = NumpyLens(make_plan(cfg)), design_mask(cfg, rm)

    def lines_of(effects):
        scene = point_scene(
            cfg,
            [xr, xt],
            [rr, rt],
            [10.0, 1.0],
            effects=effects,
            seed=3,
            start_along_track_m=start,
            pulses=pulses,
        )
        sim = Simulator(scene)
        return sim, lens.compress(sim.block(pulses))

    _, clean = lines_of([noise])
    sim, lines = lines_of([piston, noise])
    truth = sim.effects[0].truth(np.arange(pulses))
    assert np.ptp(truth) > 100
    stage = PhaseToRetro(cfg, xr, rr, start)
    parts, est = [], []
    for i in range(0, pulses, 16):
        parts.append(stage.process(lines[i : i + 16]))
        est.append(stage.last_phase_error_rad)
    corrected = np.concatenate(parts)
    assert stage.shots_not_corrected == 0
    # truth is the phase the piston added to each shot, which is what the stage estimates.
    assert residual_rms(np.concatenate(est), truth) < 0.05

    def measure(lines_in):
        img = correlate_reference(lines_in, mask)
        az = start + (np.arange(len(img)) + 0.5 * (n - 1)) * g.along_track_step_m
        return [
            analyse_point_target(
                img,
                az,
                rm,
                near_azimuth_m=x,
                near_range_m=r,
                search_radius_m=(4 * cfg.azimuth_resolution_m(), 3 * dr),
                chip=32,
            ).azimuth
            for x, r in ((xr, rr), (xt, rt))
        ]

    for ref, got, bad in zip(measure(clean), measure(corrected), measure(lines), strict=True):
        assert got.irw_m == pytest.approx(ref.irw_m, rel=0.10)
        assert got.pslr_db == pytest.approx(ref.pslr_db, rel=0.10)
        assert bad.pslr_db > ref.pslr_db + 6  # the uncorrected image: not focused
