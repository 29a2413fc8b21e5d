"""Projective SAL (Crouch ch. 8): a stick and a few points through 3-D from two spotlight images."""

import math

import numpy as np
import pytest

from rtsar.spot.pfa import PfaSettings, PolarFormatPlan, polar_format
from rtsar.spot.projective import line_distance_m, reconstruct_line, reconstruct_points
from rtsar.spot.scene import reduced_spotlight, spot_points
from rtsar.spot.simulate import SpotlightSimulator

QUARTER = 0.5 * math.pi


@pytest.fixture(scope="module")
def bench():
    # 1° of sweep: ρx = 0.886 λ/2Δθ ≈ 39 µm, commensurate with ρy = 0.886 c/2B ≈ 44 µm
    cfg, geo = reduced_spotlight(64, 3.2e-3, 1.0)
    plan = PolarFormatPlan(cfg, geo, settings=PfaSettings(extent_m=(2e-3, 2e-3)))
    return cfg, geo, plan


def _pair(bench, pos, amp=None):
    cfg, geo, plan = bench
    out = []
    for rot in (0.0, QUARTER):  # the rotation stage: a quarter turn about the beam axis
        data = SpotlightSimulator(spot_points(cfg, geo, pos, amp, rotation_rad=rot)).block()[0]
        out.append(polar_format(data, plan))
    return out


def test_a_stick_is_reconstructed_within_a_resolution_cell(bench):
    _, geo, plan = bench
    rng = np.random.default_rng(3)
    p0, p1 = np.array([-4e-4, -6e-4, -3e-4]), np.array([5e-4, 6e-4, 4e-4])
    pos = p0 + np.linspace(0, 1, 120)[:, None] * (p1 - p0)  # a rough stick: random phases
    a, b = _pair(bench, pos, np.exp(2j * math.pi * rng.random(len(pos))))
    rec = reconstruct_line(a, b, plan.x_m, plan.y_m, 0.0, QUARTER)
    cell = 0.886 * 1.55e-6 / (2 * geo.sweep_rad)
    assert len(rec.points_m) >= 25  # the stick spans 1.2 mm of range: 48 columns of 25 µm
    dist = line_distance_m(rec.points_m, p0, p1)
    assert np.sqrt(np.mean(dist**2)) < cell
    along = (rec.points_m - p0) @ (p1 - p0) / np.sum((p1 - p0) ** 2)
    assert along.min() < 0.15 and along.max() > 0.85  # end to end


def test_a_few_points_and_an_honest_ambiguity(bench):
    _, _, plan = bench
    truth = np.array([[3e-4, -5e-4, 2e-4], [-4e-4, 0, 5e-4], [1e-4, 4e-4, -3e-4]])
    a, b = _pair(bench, truth)
    rec = reconstruct_points(a, b, plan.x_m, plan.y_m, 0.0, QUARTER)
    assert len(rec.points_m) == 3 and not rec.ambiguous
    for p in truth:
        assert np.min(np.linalg.norm(rec.points_m - p, axis=1)) < 5e-6
    # two scatterers in one range cell: (x1, z1), (x2, z2) or (x1, z2), (x2, z1) both fit
    a, b = _pair(bench, np.array([[3e-4, 0, 2e-4], [-4e-4, 0, -5e-4]]))
    rec = reconstruct_points(a, b, plan.x_m, plan.y_m, 0.0, QUARTER)
    assert len(rec.points_m) == 0 and [(n_a, n_b) for _, n_a, n_b in rec.ambiguous] == [(2, 2)]
    with pytest.raises(ValueError, match="quarter turn"):
        reconstruct_points(a, b, plan.x_m, plan.y_m, 0.0, 0.0)
