"""The Doppler centroid estimator (rtsar/analysis/doppler_centroid.py) on lines built here from
its definition: the pulse-to-pulse phase of a centroid f is 2π f / PRF (D1), and a target whose
range rate is v_r walks v_r / PRF metres a pulse, with f = -2 v_r / λ (D2).  The envelopes are
Gaussians placed off the bin grid, so each walk is known to any fraction of a bin."""

import math

import numpy as np
import pytest

from rtsar.analysis.doppler_centroid import (
    estimate_doppler_centroid,
    fractional_centroid_hz,
    range_walk_bins,
)

PRF_HZ = 1256.98
WAVELENGTH_M = 0.05657
BIN_M = 8.0


def lines(pulses: int, bins: int, centroid_hz: float, walk_bins_per_pulse: float, sigma=3.0):
    """Range-compressed lines [pulse, bin]: one target, its envelope centred at
    bins / 3 + walk · p, its phase advancing 2π centroid / PRF a pulse."""
    p = np.arange(pulses)[:, None]
    r = np.arange(bins)[None, :]
    centre = bins / 3 + walk_bins_per_pulse * p
    envelope = np.exp(-0.5 * ((r - centre) / sigma) ** 2)
    cycles = np.mod(centroid_hz / PRF_HZ * p, 1.0)  # float64, reduced before the exponential
    return envelope * np.exp(2j * math.pi * cycles)


@pytest.mark.parametrize("fraction", [-0.37, 0.05, 0.44])
def test_the_fractional_centroid_is_the_pulse_to_pulse_phase(fraction):
    f_hz, coherence = fractional_centroid_hz(lines(64, 32, fraction * PRF_HZ, 0.0), PRF_HZ)
    assert f_hz == pytest.approx(fraction * PRF_HZ, abs=1e-6)
    assert coherence == pytest.approx(1.0, abs=0.02)  # 63 of 64 pulses' power in the sum


def test_small_single_precision_lines_give_the_same_fraction():
    """A review: single-precision lines of 1e-25 of full scale (a block scaled 1e-30, every
    value a normal float32) had their products underflow to zero, "the echoes are all zero"."""
    y = lines(64, 32, 0.2 * PRF_HZ, 0.0)
    small = (y * 1e-25).astype(np.complex64)  # products 1e-50: under float32's least
    assert np.all(np.abs(small[np.abs(y) > 1e-3]) > np.finfo(np.float32).tiny)
    assert fractional_centroid_hz(small, PRF_HZ)[0] == pytest.approx(0.2 * PRF_HZ, abs=1e-3)


@pytest.mark.parametrize("walk_bins", [3.3, -2.6, 7.5])
def test_the_range_walk_is_found_to_a_tenth_of_a_bin(walk_bins):
    """Over a lag of L pulses the envelope moves walk_bins: the correlation peak, refined by a
    parabola through its three highest samples, must give it within 0.1 bin (a parabola's
    vertex on a Gaussian this wide is within a few hundredths)."""
    lag = 40
    y = lines(200, 128, 0.0, walk_bins / lag, sigma=4.0)
    assert range_walk_bins(y, lag) == pytest.approx(walk_bins, abs=0.1)


@pytest.mark.parametrize("centroid_hz", [-6900.0, -1480.0, 2300.0])
def test_the_ambiguity_comes_from_the_walk(centroid_hz):
    """A centroid several PRFs from zero (RADARSAT-1's is about -5.5 PRF): the phase alone
    gives it modulo the PRF; the walk that the same range rate makes gives the whole."""
    walk_m_per_pulse = WAVELENGTH_M * centroid_hz / 2.0 / PRF_HZ * -1.0  # v_r / PRF
    y = lines(1536, 256, centroid_hz, walk_m_per_pulse / BIN_M)
    est = estimate_doppler_centroid(y, PRF_HZ, WAVELENGTH_M, BIN_M)
    assert est.ambiguity == round(centroid_hz / PRF_HZ)
    assert est.centroid_hz == pytest.approx(centroid_hz, abs=1e-3)
