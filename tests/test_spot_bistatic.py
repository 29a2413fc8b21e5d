"""The bistatic receiver channel (Crouch eqs. 9.1b, 9.2b, 9.4b) before and after its correction."""

import math

import numpy as np
import pytest

from rtsar.analysis.point_target import analyse_point_target
from rtsar.params import C_M_PER_S
from rtsar.spot.geometry import wavenumbers
from rtsar.spot.pfa import PfaSettings, PolarFormatPlan, polar_format
from rtsar.spot.scene import reduced_spotlight, spot_points
from rtsar.spot.simulate import BISTATIC_CHANNEL, SpotlightSimulator

BETA = math.radians(8.0)  # Crouch's Fig. 40: "approximately 8 degrees of offset"
POINT = [6e-4, -5e-4, 0.0]


@pytest.fixture(scope="module")
def bistatic():
    cfg, geo = reduced_spotlight(64, 3.2e-3, 5.0, bistatic_range_m=4.0, bistatic_angle_rad=BETA)
    main, aux = SpotlightSimulator(spot_points(cfg, geo, [POINT])).block()
    return cfg, geo, main, aux[BISTATIC_CHANNEL]


def test_bistatic_channel_is_the_exact_two_leg_path(bistatic):
    cfg, geo, _, shots = bistatic
    wf = cfg.waveform
    n = geo.pulses - 1
    th = geo.angles_rad([n])[0]
    tx = np.hypot(-4.6 * math.sin(th) - POINT[0], -4.6 * math.cos(th) - POINT[1])  # eq. 9.1a
    rx = np.hypot(-4.0 * math.sin(BETA) - POINT[0], -4.0 * math.cos(BETA) - POINT[1])  # eq. 9.1b
    lo = 0.5 * (4.6 + 4.0)  # the receiver's LO matches half its centre path
    t = (np.arange(64) - 32) / wf.sample_rate_hz
    omega_t = 2 * math.pi * (C_M_PER_S / 1.55e-6 + wf.chirp_rate_hz_per_s * t)
    naive = np.exp(-1j * np.mod((tx + rx - 2 * lo) * omega_t / C_M_PER_S, 2 * math.pi))  # eq. 9.2b
    assert np.max(np.abs(shots[n] - naive)) < 1e-3


def test_bistatic_image_before_and_after_the_geometry_correction(bistatic):
    cfg, geo, _, shots = bistatic
    reports = {}
    for look in ("monostatic", "exact"):
        s = PfaSettings(extent_m=(3e-3, 2.5e-3))
        plan = PolarFormatPlan(cfg, geo, BISTATIC_CHANNEL, s, look=look)
        rep = analyse_point_target(polar_format(shots, plan), plan.x_m, plan.y_m)
        reports[look] = (rep, plan.to_frame(np.asarray(POINT))[0])
    # the bisector of transmitter and receiver sweeps Δθ/2 at radius g = 2cos(β_n/2): eq. 9.4b
    th = geo.angles_rad()
    g = 2 * np.cos(0.5 * (th - BETA))
    k_c, dk = wavenumbers(cfg.waveform, 1.55e-6)
    dky = g.min() * (k_c + 31 * dk) - g.max() * (k_c - 32 * dk)  # the inscribed rectangle
    irw_x = 0.886 * 1.55e-6 / (geo.sweep_rad * math.cos(0.5 * BETA))
    irw_y = 0.886 * 2 * math.pi / dky
    after, xy = reports["exact"]
    assert after.azimuth.irw_m == pytest.approx(irw_x, rel=0.10)
    assert after.range.irw_m == pytest.approx(irw_y, rel=0.10)
    assert abs(after.azimuth_m - xy[0]) < irw_x / 8 and abs(after.range_m - xy[1]) < irw_y / 8
    assert after.azimuth.pslr_db == pytest.approx(-13.26, abs=0.5)
    # processed as if monostatic (Crouch's "no range correction"): misplaced and defocused
    before, xy = reports["monostatic"]
    assert abs(before.azimuth_m - xy[0]) > 10 * irw_x
    assert before.azimuth.pslr_db > -11.0  # measured -9.1 dB (tests/test_reports_spot.py)
