"""Reference-region correction (INO phase-error patent, eqs. 5-11): α and β against the injected
truth (≤ λ/20 of optical path), the stream stage against the float64 reference, the target
focused again within 10 % of the error-free image."""

import math

import numpy as np
import pytest

from rtsar.analysis import analyse_point_target
from rtsar.ccd.base import correlate_reference, design_mask
from rtsar.focus.reference_region import (
    ReferenceGeometry,
    ReferenceRegionCorrector,
    reference_region_reference,
)
from rtsar.lens.numpy_lens import NumpyLens
from rtsar.lens.plan import make_plan
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene

CFG = preset("zhao-insal").with_processor(aperture_pulses=96, range_bins=32, range_window="taylor")
LAM = CFG.geometry.wavelength_m


def wrap(a):
    return np.angle(np.exp(1j * np.asarray(a)))


def rms_about_mean(x):
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean((x - x.mean()) ** 2)))


@pytest.fixture(scope="module")
def run():
    """A point target and the reference region with Crouch-size common error (α: ~10 µm,
    over 100 rad on the target) and a roll β; plus the error-free scene."""
    g = CFG.geometry
    rm = make_plan(CFG).range_m
    r0 = rm[16] + 0.37 * (rm[1] - rm[0])
    n = CFG.processor.aperture_pulses
    pulses, start = n + 64, -(0.5 * (n - 1) + 32) * g.along_track_step_m
    params = dict(
        alpha_drift_m=6e-9, alpha_walk_m=1.5e-8, alpha_vibration_m=1e-7, alpha_vibration_hz=0.4,
        roll_walk_rad=5e-7, roll_vibration_rad=1e-5, roll_vibration_hz=0.1, seed=3,
        scatterers_per_cell=2.0, region_depth_m=24 * CFG.waveform.range_resolution_m,
    )  # fmt: skip
    common = dict(seed=1, start_along_track_m=start, pulses=pulses)
    scene = point_scene(CFG, [0.0], [r0], effects=[("reference_region", params)], **common)
    sim = Simulator(scene)
    main, aux = sim.block_with_aux(pulses)
    clean = Simulator(point_scene(CFG, [0.0], [r0], **common)).block(pulses)
    effect = sim.effects[0]
    geometry = ReferenceGeometry.from_effect(effect)
    return dict(main=main, aux=aux, clean=clean, effect=effect, r0=r0, start=start,
                geometry=geometry, pulses=np.arange(pulses))  # fmt: skip


def test_eq_9_solves_alpha_and_beta_from_two_channels():
    """No speckle: each reference channel is one constant-range return whose phase is exactly
    -2π/λ × its round-trip error (eqs. 5a, 5b); α, β and φ1t must come back to rounding."""
    rng = np.random.default_rng(4)
    geo = ReferenceGeometry(d_m=0.01, D_m=0.05, region_range_m=2.4, region_depth_m=3e-3)
    n = 200
    alpha = np.cumsum(rng.normal(0, 2e-8, n)) + 3e-7 * np.sin(0.1 * np.arange(n))
    beta = np.cumsum(rng.normal(0, 2e-7, n))
    k = 2 * math.pi / LAM
    samples = CFG.waveform.samples_per_shot
    # With the LO at the region centre the return is a DC beat tone in both channels.
    aux = {
        "reference_rx1": np.exp(-1j * k * (2 * alpha - geo.D_m * beta))[:, None] * np.ones(samples),
        "reference_rx2": np.exp(-1j * k * (2 * alpha - 2 * geo.D_m * beta))[:, None]
        * np.ones(samples),
    }
    main = np.ones((n, 8), np.complex128)
    out = reference_region_reference(main, aux, CFG, geo)
    assert out["estimated"].all()
    assert np.allclose(out["alpha_m"], alpha - alpha[0], atol=1e-6 * LAM)
    assert np.allclose(out["beta_rad"], beta - beta[0], atol=1e-6 * LAM / geo.D_m)
    phi1t = -k * (2 * (alpha - alpha[0]) + geo.d_m * (beta - beta[0]))
    assert np.allclose(out["target_phase_rad"], phi1t, atol=1e-6)
    assert np.allclose(np.angle(out["corrected"][:, 0]), wrap(-phi1t), atol=1e-6)


def test_alpha_beta_within_lambda_over_20(run):
    e, p = run["effect"], run["pulses"]
    target_truth = e.target_phase_rad(p)
    assert np.ptp(target_truth) > 100  # hundreds of radians on the target: Crouch's scale
    assert np.ptp(e.beta_rad(p)) * e.D_m > LAM / 2  # the roll matters too
    ref = reference_region_reference(run["main"], run["aux"], CFG, run["geometry"])
    assert ref["estimated"].all()
    alpha_err = rms_about_mean(ref["alpha_m"] - e.alpha_m(p))
    path_beta_err = e.D_m * rms_about_mean(ref["beta_rad"] - e.beta_rad(p))
    assert alpha_err <= LAM / 20
    assert path_beta_err <= LAM / 20
    residual = wrap(ref["target_phase_rad"] - target_truth)
    assert rms_about_mean(wrap(residual - residual.mean())) < 0.3  # rad, on the target


def test_target_focused_within_10_percent_of_error_free(run):
    stage = ReferenceRegionCorrector(CFG, run["geometry"])
    aux, main = run["aux"], run["main"].astype(np.complex64)
    parts = []
    for i in range(0, len(main), 16):
        batch = stage.process(main[i : i + 16], {k: v[i : i + 16] for k, v in aux.items()})
        assert len(batch) == len(main[i : i + 16])  # nothing held back: no added latency
        parts.append(batch)
    corrected = np.concatenate(parts)
    assert stage.pulses_not_estimated == 0

    plan = make_plan(CFG)
    lens, mask = NumpyLens(plan), design_mask(CFG, plan.range_m)
    n, step = CFG.processor.aperture_pulses, CFG.geometry.along_track_step_m

    def azimuth_cut(shots):
        img = correlate_reference(lens.compress(shots), mask)
        az = run["start"] + (np.arange(len(img)) + 0.5 * (n - 1)) * step
        rep = analyse_point_target(
            img, az, plan.range_m, near_azimuth_m=0.0, near_range_m=run["r0"],
            search_radius_m=(4 * CFG.azimuth_resolution_m(), 3e-4), chip=32,
        )  # fmt: skip
        return rep.azimuth

    ref, got, bad = (azimuth_cut(s) for s in (run["clean"], corrected, run["main"]))
    assert got.irw_m == pytest.approx(ref.irw_m, rel=0.10)
    assert got.pslr_db == pytest.approx(ref.pslr_db, rel=0.10)
    assert got.peak_amplitude == pytest.approx(ref.peak_amplitude, rel=0.10)
    assert bad.pslr_db > ref.pslr_db + 6  # uncorrected: not focused


@pytest.mark.parametrize("weighting", ["power", "uniform"])
def test_stream_equals_batch_in_random_micro_batches(run, weighting):
    rng = np.random.default_rng(8)
    aux = {k: v.copy() for k, v in run["aux"].items()}
    aux["reference_rx1"][40:43] = 0  # the reference goes dark for three shots
    aux["reference_rx2"][80, 5] = np.nan  # one bad reference shot
    main = run["main"]
    ref = reference_region_reference(main, aux, CFG, run["geometry"], weighting=weighting)
    stage = ReferenceRegionCorrector(CFG, run["geometry"], weighting=weighting)
    cuts = np.sort(rng.choice(np.arange(1, len(main)), 20, replace=False))
    outs, alphas, betas = [], [], []
    for idx in np.split(np.arange(len(main)), cuts):
        outs.append(
            stage.process(main[idx].astype(np.complex64), {k: v[idx] for k, v in aux.items()})
        )
        alphas.append(stage.last_alpha_m)
        betas.append(stage.last_beta_rad)
    out = np.concatenate(outs)
    assert out.dtype == np.complex64 and np.all(np.isfinite(out))
    assert np.max(np.abs(out - ref["corrected"])) < 1e-5 * np.max(np.abs(ref["corrected"]))
    assert np.max(np.abs(np.concatenate(alphas) - ref["alpha_m"])) < 1e-9 * LAM
    assert np.max(np.abs(np.concatenate(betas) - ref["beta_rad"])) < 1e-9 * LAM
    # Steps into and out of the dark shots (40-43) and around the NaN (80, 81) fail and hold.
    assert stage.pulses_not_estimated == int((~ref["estimated"]).sum()) == 6
    assert stage.nonfinite_reference == 1


def test_bad_arguments(run):
    geo = run["geometry"]
    with pytest.raises(ValueError, match="weighting"):
        ReferenceRegionCorrector(CFG, geo, weighting="mean")
    with pytest.raises(ValueError, match="FMCW"):
        ReferenceRegionCorrector(preset("tiny"), geo)
    with pytest.raises(ValueError):
        ReferenceGeometry(d_m=0.01, D_m=0.0, region_range_m=2.4, region_depth_m=1e-3)
    stage = ReferenceRegionCorrector(CFG, geo)
    main = run["main"][:4]
    with pytest.raises(ValueError, match="aux"):
        stage.process(main, {"reference_rx1": run["aux"]["reference_rx1"][:4]})
    with pytest.raises(ValueError, match="aux"):
        stage.process(main, {k: v[:3] for k, v in run["aux"].items()})
    assert stage.pulses_in == 0
