"""Tests of rtsar.metrics against closed-form impulse responses.

Reference values are derived here from the continuous responses, never from the code under test:

* rect spectrum of bandwidth B (cycles/sample): h(t) = sinc(B t).  Its -3 dB half-width solves
  sinc(u)^2 = 1/2, u = 0.442946 -> IRW = 0.885893 / B; the first sidelobe (|u| ~ 1.4303) is
  -13.2615 dB; the mainlobe lies between the nulls u = +-1.
* ISLR of the sinc with the sidelobe region clipped at +-10 IRW (u = +-8.85893): with
  S(X) = int_0^X sinc^2 = (Si(2 pi X) - sin^2(pi X) / (pi X)) / pi, the mainlobe energy is
  2 S(1) = 0.902823 and the sidelobe energy 2 (S(8.85893) - S(1)), so
  ISLR = 10 log10((S(8.85893) - S(1)) / S(1)) = -10.216 dB (-9.68 dB for an unclipped region).
* Hann-weighted spectrum 0.5 + 0.5 cos(2 pi f / B) on |f| <= B/2:
  h(u) = sinc(u) + (sinc(u - 1) + sinc(u + 1)) / 2 with u = B t, giving IRW = 1.4406 / B
  (= 1.626 x 0.8859 / B: the "1.44" factor multiplies 1/B, not 0.886/B) and PSLR = -31.47 dB.
  Hamming (0.54 + 0.46 cos): IRW = 1.3030 / B (factor 1.4708), PSLR = -42.68 dB.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar
from scipy.signal import windows as sw
from scipy.special import sici

from rtsar.analysis import (
    CutMetrics,
    PointTargetReport,
    analyse_cut,
    analyse_point_target,
    relative_rms,
    theoretical_irw_factor,
    theoretical_pslr_db,
    upsample,
)

# --------------------------------------------------------------------------------------------
# Closed-form references
# --------------------------------------------------------------------------------------------


def raised_cosine_response(u, a: float):
    """Response of the spectral weighting a + (1 - a) cos(2 pi f / B), |f| <= B/2, at u = B t."""
    u = np.asarray(u, dtype=np.float64)
    return a * np.sinc(u) + 0.5 * (1.0 - a) * (np.sinc(u - 1.0) + np.sinc(u + 1.0))


def raised_cosine_irw(a: float) -> float:
    """-3 dB width (in units of 1/B) of the raised-cosine response."""
    peak2 = raised_cosine_response(0.0, a) ** 2
    half_width = brentq(lambda u: raised_cosine_response(u, a) ** 2 - 0.5 * peak2, 0.05, 1.2)
    return 2.0 * half_width


def raised_cosine_pslr_db(a: float, first_null: float) -> float:
    """Highest sidelobe of the raised-cosine response (searched over the first few lobes)."""
    peak2 = raised_cosine_response(0.0, a) ** 2
    best = 0.0
    for k in range(6):
        lo, hi = first_null + k, first_null + k + 1
        res = minimize_scalar(
            lambda u: -(raised_cosine_response(u, a) ** 2),
            bounds=(lo, hi),
            method="bounded",
            options={"xatol": 1e-10},
        )
        best = max(best, -res.fun)
    return 10.0 * math.log10(best / peak2)


def sinc_energy(x: float) -> float:
    """int_0^x sinc(u)^2 du in closed form (sinc(u) = sin(pi u) / (pi u))."""
    si, _ = sici(2.0 * math.pi * x)
    return (si - math.sin(math.pi * x) ** 2 / (math.pi * x)) / math.pi


SINC_IRW = raised_cosine_irw(1.0)  # 0.885893 (in units of 1/B)
SINC_PSLR_DB = raised_cosine_pslr_db(1.0, 1.0)  # -13.2615
SINC_ISLR_DB = 10.0 * math.log10(
    (sinc_energy(10.0 * SINC_IRW) - sinc_energy(1.0)) / sinc_energy(1.0)
)  # -10.216
HANN_IRW = raised_cosine_irw(0.5)  # 1.4406
HANN_PSLR_DB = raised_cosine_pslr_db(0.5, 2.0)  # -31.47
HAMMING_IRW = raised_cosine_irw(0.54)  # 1.3030
HAMMING_PSLR_DB = raised_cosine_pslr_db(0.54, 2.0)  # -42.68


def test_reference_values():
    """The closed forms above reproduce the textbook numbers."""
    assert SINC_IRW == pytest.approx(0.885893, abs=1e-6)
    assert SINC_PSLR_DB == pytest.approx(-13.2615, abs=1e-3)
    assert SINC_ISLR_DB == pytest.approx(-10.216, abs=2e-3)
    assert 2.0 * sinc_energy(1.0) == pytest.approx(0.902823, abs=1e-6)
    assert HANN_IRW == pytest.approx(1.4406, abs=1e-3)
    assert HANN_PSLR_DB == pytest.approx(-31.47, abs=0.01)
    assert HAMMING_IRW / SINC_IRW == pytest.approx(1.4708, abs=2e-3)
    assert HAMMING_PSLR_DB == pytest.approx(-42.68, abs=0.02)


# --------------------------------------------------------------------------------------------
# Test signals
# --------------------------------------------------------------------------------------------

PHASE_RAD = 0.7
SHIFT = 3.37


def sampled_sinc(n: int, oversampling: float, centre: float) -> np.ndarray:
    """Samples of exp(i phase) sinc(B (t - centre)), B = 1 / oversampling, unit spacing."""
    t = np.arange(n) - centre
    return np.exp(1j * PHASE_RAD) * np.sinc(t / oversampling)


def periodic_response(n: int, m: int, centre: float, a: float = 1.0) -> np.ndarray:
    """Exactly band-limited periodic response: m (odd) DFT bins weighted a + (1-a) cos(2 pi k/m).

    Bandwidth B = m / n cycles/sample; the response is the periodic (Dirichlet) counterpart of
    the continuous one, equal to it to O((B t / m)^2) near the peak.
    """
    k = np.fft.fftfreq(n, d=1.0 / n)
    inside = np.abs(k) <= (m - 1) // 2
    weights = np.where(inside, a + (1.0 - a) * np.cos(2.0 * np.pi * k / m), 0.0)
    spectrum = weights * np.exp(-2j * np.pi * k * centre / n) / weights.sum() * n
    return np.exp(1j * PHASE_RAD) * np.fft.ifft(spectrum)


# --------------------------------------------------------------------------------------------
# upsample
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", [1, 2, 7, 8, 63, 64])
@pytest.mark.parametrize("factor", [1, 2, 3, 16])
def test_upsample_passes_through_samples(n, factor):
    rng = np.random.default_rng(n * 100 + factor)
    x = rng.standard_normal(n) + 1j * rng.standard_normal(n)
    y = upsample(x, factor)
    assert y.shape == (n * factor,)
    np.testing.assert_allclose(y[::factor], x, rtol=0, atol=1e-12)


def test_upsample_even_length_nyquist_is_split():
    # cos(pi n) sits entirely in the Nyquist bin; split, it interpolates to cos(pi t).
    n, factor = 8, 4
    x = np.cos(np.pi * np.arange(n))
    y = upsample(x, factor)
    assert np.isrealobj(y)
    np.testing.assert_allclose(y, np.cos(np.pi * np.arange(n * factor) / factor), atol=1e-12)


def test_upsample_reproduces_band_limited_signal_along_axis():
    n, factor = 32, 5
    t = np.arange(n)
    fine = np.arange(n * factor) / factor

    def signal(tt):
        return np.exp(2j * np.pi * 3 * tt / n) + 0.5 * np.exp(-2j * np.pi * 7 * tt / n)

    x = np.stack([signal(t), 2.0 * signal(t)], axis=0)  # along axis 1
    y = upsample(x.T, factor, axis=0)
    np.testing.assert_allclose(y[:, 0], signal(fine), atol=1e-12)
    np.testing.assert_allclose(y[:, 1], 2.0 * signal(fine), atol=1e-12)


def test_upsample_rejects_bad_factor():
    with pytest.raises(ValueError):
        upsample(np.ones(4), 0)
    with pytest.raises(ValueError):
        upsample(np.ones(4), 2.5)


# --------------------------------------------------------------------------------------------
# analyse_cut: sinc
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("oversampling", [1, 2])
@pytest.mark.parametrize("kind", ["sampled", "periodic"])
def test_sinc_cut(kind, oversampling):
    n = 256
    centre = n // 2 + SHIFT
    if kind == "sampled":
        x = sampled_sinc(n, oversampling, centre)
        bandwidth = 1.0 / oversampling
    else:
        m = n - 1 if oversampling == 1 else n // 2 + 1  # odd number of bins
        x = periodic_response(n, m, centre)
        bandwidth = m / n
    spacing_m, origin_m = 0.25, -12.0
    r = analyse_cut(x, spacing_m, origin_m)

    assert isinstance(r, CutMetrics)
    assert r.peak_index == pytest.approx(centre, abs=0.01)
    assert r.peak_position_m == pytest.approx(origin_m + centre * spacing_m, abs=0.01 * spacing_m)
    assert r.peak_amplitude == pytest.approx(1.0, rel=5e-3)
    assert r.peak_phase_rad == pytest.approx(PHASE_RAD, abs=1e-3)
    assert r.irw_m == pytest.approx(SINC_IRW / bandwidth * spacing_m, rel=0.01)
    assert r.pslr_db == pytest.approx(SINC_PSLR_DB, abs=0.1)
    assert r.islr_db == pytest.approx(SINC_ISLR_DB, abs=0.1)


def test_periodic_sinc_peak_is_exact():
    """An exactly band-limited response gives the peak to well below 1/100 sample."""
    x = periodic_response(255, 255, 100.0 + SHIFT)
    r = analyse_cut(x, 1.0)
    assert r.peak_index == pytest.approx(100.0 + SHIFT, abs=1e-5)
    assert r.peak_amplitude == pytest.approx(1.0, abs=1e-9)
    assert r.peak_phase_rad == pytest.approx(PHASE_RAD, abs=1e-9)


def test_negative_spacing_and_upsample_factor():
    x = sampled_sinc(128, 2, 60.4)
    r = analyse_cut(x, -0.5, 100.0, upsample_factor=8)
    assert r.peak_position_m == pytest.approx(100.0 - 0.5 * 60.4, abs=0.005)
    assert r.irw_m == pytest.approx(SINC_IRW * 2 * 0.5, rel=0.01)


# --------------------------------------------------------------------------------------------
# analyse_cut: weighted responses and edge cases
# --------------------------------------------------------------------------------------------


def test_hann_weighted_cut():
    n, m = 1025, 513  # B = m / n ~ 0.5 (2x oversampled)
    r = analyse_cut(periodic_response(n, m, 500.3, a=0.5), 1.0)
    assert r.irw_m == pytest.approx(HANN_IRW * n / m, rel=0.01)
    assert r.irw_m == pytest.approx(1.626 * SINC_IRW * n / m, rel=0.01)
    assert r.pslr_db == pytest.approx(HANN_PSLR_DB, abs=0.2)
    assert r.islr_db < -30.0


def test_hamming_weighted_cut():
    n, m = 1025, 513
    r = analyse_cut(periodic_response(n, m, 500.3, a=0.54), 1.0)
    assert r.irw_m == pytest.approx(HAMMING_IRW * n / m, rel=0.01)
    assert r.pslr_db == pytest.approx(HAMMING_PSLR_DB, abs=0.5)


def test_no_sidelobe_gives_minus_inf_not_nan():
    # A Gaussian bump falls monotonically to both cut ends: no null, no sidelobe.
    t = np.arange(21, dtype=np.float64)
    r = analyse_cut(np.exp(-(((t - 10.3) / 3.0) ** 2)), 1.0)
    assert r.pslr_db == -math.inf
    assert r.islr_db == -math.inf
    # -3 dB width of exp(-(t/s)^2) in power: 2 s sqrt(ln(2) / 2)
    assert r.irw_m == pytest.approx(2 * 3.0 * math.sqrt(math.log(2) / 2), rel=0.01)
    assert r.peak_index == pytest.approx(10.3, abs=0.01)


def test_one_sided_sidelobes():
    # The cut starts inside the left mainlobe (no left null): PSLR comes from the right side and
    # the ISLR holds one side's sidelobe energy, i.e. the two-sided value - 10 log10(2).
    t = np.arange(80) * 0.25 - 0.8
    r = analyse_cut(np.sinc(t), 0.25)
    assert r.pslr_db == pytest.approx(SINC_PSLR_DB, abs=0.1)
    assert r.islr_db == pytest.approx(SINC_ISLR_DB - 10 * math.log10(2), abs=0.1)
    assert np.isfinite(r.irw_m)


def test_islr_extent_parameter():
    x = periodic_response(1023, 1023, 500.0)
    wide = analyse_cut(x, 1.0, islr_extent=100.0)
    expected = 10 * math.log10((sinc_energy(100.0 * SINC_IRW) - sinc_energy(1.0)) / sinc_energy(1))
    assert wide.islr_db == pytest.approx(expected, abs=0.05)


@pytest.mark.parametrize(
    "cut",
    [
        np.zeros(16, dtype=complex),
        np.array([], dtype=complex),
        np.array([1.0, np.nan, 0.5], dtype=complex),
        np.array([1.0, np.inf, 0.5]),
        np.ones((4, 4), dtype=complex),
    ],
    ids=["all-zero", "empty", "nan", "inf", "2-d"],
)
def test_analyse_cut_rejects_bad_input(cut):
    with pytest.raises(ValueError):
        analyse_cut(cut, 1.0)


def test_analyse_cut_rejects_bad_spacing():
    with pytest.raises(ValueError):
        analyse_cut(np.ones(8), 0.0)
    with pytest.raises(ValueError):
        analyse_cut(np.ones(8), math.nan)


# --------------------------------------------------------------------------------------------
# analyse_point_target
# --------------------------------------------------------------------------------------------

N_AZ, N_RG = 128, 96
AZ_SPACING_M, RG_SPACING_M = 0.05, 0.3
AZ_ORIGIN_M, RG_ORIGIN_M = 120.0, 950.0
AZ_OVERSAMPLING, RG_OVERSAMPLING = 2.0, 1.25


def axes():
    return (
        AZ_ORIGIN_M + AZ_SPACING_M * np.arange(N_AZ),
        RG_ORIGIN_M + RG_SPACING_M * np.arange(N_RG),
    )


def separable_sinc(az_px: float, rg_px: float, amplitude: complex = 1.0) -> np.ndarray:
    az = np.sinc((np.arange(N_AZ) - az_px) / AZ_OVERSAMPLING)
    rg = np.sinc((np.arange(N_RG) - rg_px) / RG_OVERSAMPLING)
    return amplitude * np.outer(az, rg)


def test_point_target_position_and_widths():
    az_px, rg_px = 60.37, 41.71
    value = 2.0 * np.exp(1j * PHASE_RAD)
    image = separable_sinc(az_px, rg_px, value).astype(np.complex64)
    az_m, rg_m = axes()
    rep = analyse_point_target(image, az_m, rg_m)

    assert isinstance(rep, PointTargetReport)
    assert rep.azimuth_m == pytest.approx(AZ_ORIGIN_M + az_px * AZ_SPACING_M, abs=AZ_SPACING_M / 50)
    assert rep.range_m == pytest.approx(RG_ORIGIN_M + rg_px * RG_SPACING_M, abs=RG_SPACING_M / 50)
    assert rep.azimuth.peak_index == pytest.approx(az_px, abs=0.02)
    assert rep.range.peak_index == pytest.approx(rg_px, abs=0.02)
    assert rep.azimuth.peak_position_m == pytest.approx(rep.azimuth_m, abs=AZ_SPACING_M / 100)
    assert rep.range.peak_position_m == pytest.approx(rep.range_m, abs=RG_SPACING_M / 100)
    assert rep.azimuth.irw_m == pytest.approx(SINC_IRW * AZ_OVERSAMPLING * AZ_SPACING_M, rel=0.01)
    assert rep.range.irw_m == pytest.approx(SINC_IRW * RG_OVERSAMPLING * RG_SPACING_M, rel=0.01)
    assert rep.azimuth.pslr_db == pytest.approx(SINC_PSLR_DB, abs=0.2)
    assert rep.range.pslr_db == pytest.approx(SINC_PSLR_DB, abs=0.2)
    assert abs(rep.peak_value) == pytest.approx(2.0, rel=0.01)
    assert np.angle(rep.peak_value) == pytest.approx(PHASE_RAD, abs=1e-3)


def test_point_target_search_window_and_small_chip():
    az_m, rg_m = axes()
    image = separable_sinc(30.2, 20.6, 1.0) + separable_sinc(95.6, 70.3, 3.0)
    brightest = analyse_point_target(image, az_m, rg_m, chip=16)
    assert brightest.azimuth.peak_index == pytest.approx(95.6, abs=0.02)
    near = analyse_point_target(
        image,
        az_m,
        rg_m,
        near_azimuth_m=AZ_ORIGIN_M + 31 * AZ_SPACING_M,
        near_range_m=RG_ORIGIN_M + 20 * RG_SPACING_M,
        search_radius_m=(5 * AZ_SPACING_M, 5 * RG_SPACING_M),
        chip=16,
    )
    assert near.azimuth.peak_index == pytest.approx(30.2, abs=0.02)
    assert near.range.peak_index == pytest.approx(20.6, abs=0.02)
    assert near.range_m == pytest.approx(RG_ORIGIN_M + 20.6 * RG_SPACING_M, abs=RG_SPACING_M / 50)


def test_point_target_errors():
    az_m, rg_m = axes()
    with pytest.raises(ValueError):
        analyse_point_target(np.zeros((N_AZ, N_RG), complex), az_m, rg_m)
    image = separable_sinc(60.0, 40.0)
    image[3, 4] = np.nan
    with pytest.raises(ValueError):
        analyse_point_target(image, az_m, rg_m)
    good = separable_sinc(60.0, 40.0)
    with pytest.raises(ValueError):
        analyse_point_target(good, az_m[:-1], rg_m)
    bent = az_m.copy()
    bent[10] += 0.01
    with pytest.raises(ValueError):
        analyse_point_target(good, bent, rg_m)
    with pytest.raises(ValueError):
        analyse_point_target(good, az_m, rg_m, near_azimuth_m=0.0, search_radius_m=1.0)


# --------------------------------------------------------------------------------------------
# Theoretical factors and relative_rms
# --------------------------------------------------------------------------------------------


def test_theoretical_factors():
    n = 1024
    assert theoretical_irw_factor(np.ones(n)) == pytest.approx(1.0, abs=1e-9)
    assert theoretical_pslr_db(np.ones(n)) == pytest.approx(SINC_PSLR_DB, abs=0.02)
    # A symmetric Hann/Hamming of n points spans n - 1 sample intervals, a rect n intervals.
    stretch = n / (n - 1)
    hann = theoretical_irw_factor(sw.hann(n, sym=True))
    assert hann == pytest.approx(HANN_IRW / SINC_IRW * stretch, rel=2e-3)  # 1.6278
    assert 1.62 < hann < 1.65
    hamming = theoretical_irw_factor(sw.hamming(n, sym=True))
    assert hamming == pytest.approx(HAMMING_IRW / SINC_IRW, rel=3e-3)  # 1.4717
    assert theoretical_pslr_db(sw.hann(n, sym=True)) == pytest.approx(HANN_PSLR_DB, abs=0.05)
    assert theoretical_pslr_db(sw.hamming(n, sym=True)) == pytest.approx(HAMMING_PSLR_DB, abs=0.2)


def test_theoretical_rejects_bad_weights():
    for bad in (np.array([]), np.zeros(8), np.array([1.0, np.nan, 1.0])):
        with pytest.raises(ValueError):
            theoretical_irw_factor(bad)


def test_relative_rms():
    b = np.array([3.0, 4.0], dtype=np.float32)
    a = b + np.array([0.3, -0.4], dtype=np.float32)
    assert relative_rms(a, b) == pytest.approx(0.1, rel=1e-6)
    assert relative_rms(b.astype(np.complex64), b) == 0.0
    with pytest.raises(ValueError):
        relative_rms(np.ones(3), np.ones(4))
    with pytest.raises(ValueError):
        relative_rms(np.ones(3), np.zeros(3))
