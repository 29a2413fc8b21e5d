"""A response whose band straddles the DFT's split (±1/2 cycle a sample) is measured as the same
response at baseband: a squinted image's range band sits 2 (cos θ - 1) δr / λ cycles a bin off
zero (RADARSAT-1: -0.063, its band 0.93 of the sample rate wide), and band-limited
interpolation about zero cut it in two (its range cuts measured 3-9 % wide, sidelobes 1 dB up).

The reference is the ideal band-limited response written from its definition: a band of width
w cycles a sample, centred at c, flat, sampled at n - t0:  w·sinc(w (n - t0))·exp(2πi c (n - t0)),
whose -3 dB width is 0.8859 / w samples and whose PSLR is -13.26 dB whatever c is."""

import numpy as np
import pytest

from rtsar.analysis.cut import analyse_cut
from rtsar.analysis.interpolation import band_centre_cycles
from rtsar.analysis.islr2d import islr_2d_db
from rtsar.analysis.point_target import analyse_point_target

SINC_IRW = 0.88589  # -3 dB width of sinc(x) = sin(πx)/(πx), in units of x
SINC_PSLR_DB = -13.26
RS1_BAND, RS1_CENTRE = 0.932, -0.0626  # RADARSAT-1's range band and its centre, cycles a bin


def band_response(n: int, t0: float, width: float, centre: float) -> np.ndarray:
    k = np.arange(n) - t0
    return width * np.sinc(width * k) * np.exp(2j * np.pi * centre * k)


@pytest.mark.parametrize("centre", [RS1_CENTRE, 0.05, 0.25, 0.45])
def test_a_cut_is_measured_as_its_band_says_wherever_the_band_sits(centre):
    cut = band_response(129, 64.37, RS1_BAND, centre)
    for declared in (None, centre):  # found from the cut, or declared by the caller
        m = analyse_cut(cut, 4.64, 100.0, 16, centre_cycles=declared)
        assert m.irw_m == pytest.approx(SINC_IRW / RS1_BAND * 4.64, rel=2e-3)
        assert m.pslr_db == pytest.approx(SINC_PSLR_DB, abs=0.15)
        assert m.peak_index == pytest.approx(64.37, abs=2e-3)
        # the phase at the peak is the response's own (the centre put back): zero at t0
        assert abs(m.peak_phase_rad) < 2e-3


def test_the_band_centre_is_a_gap_moved_to_the_split_or_nothing():
    straddling = band_response(129, 64.37, RS1_BAND, RS1_CENTRE)
    c = band_centre_cycles(straddling)
    # the gap (0.065 wide, about 1/2 + c) lands on the split: within half the gap of the centre
    assert abs(c - RS1_CENTRE) < 0.5 * (1 - RS1_BAND)
    assert c * 129 == pytest.approx(
        round(c * 129), abs=1e-9
    )  # a whole number of bins: a circular shift, no leakage
    assert band_centre_cycles(band_response(129, 64.37, RS1_BAND, 0.0)) == 0.0  # clear of it
    # a critically sampled sinc fills the circle: no gap, no centre, interpolated as it is
    assert band_centre_cycles(band_response(128, 64.0, 1.0, 0.0)) == 0.0
    assert band_centre_cycles(np.zeros(64, complex)) == 0.0
    # two equal echoes 1.5 samples apart notch a full band more than once: notches, no gap
    # (without the one-run rule these moved the band by 0.23 and 0.49 cycle)
    pair = band_response(129, 60.2, 1.0, 0.0) + band_response(129, 61.7, 1.0, 0.0)
    for ramp_rad in (0.4, 2.0):
        assert band_centre_cycles(pair * np.exp(1j * ramp_rad * np.arange(129))) == 0.0


def test_a_squinted_points_2d_measures_equal_its_baseband_twins():
    """Separable: azimuth a Doppler band 0.8 wide about 0.31 cycle a line, range RADARSAT-1's
    band about its centre.  The ramps are pixel phases: the 2-D peak, widths, PSLRs and ISLR
    are those of the same point at baseband, and the peak's value is the response's own at
    the point, whether the caller declares both centres (image_centres), the azimuth's only,
    or neither (each found from the cut through the brightest pixel).  Measured about zero,
    the range width read 7.5 % wide, the PSLR -11.9 dB and the 2-D ISLR 1.0 dB up; now within
    0.02 % (the chip's edges) and 0.1 dB."""
    az0, rg0 = 40.3, 50.6
    azimuth = band_response(81, az0, 0.8, 0.31)
    squinted = np.outer(azimuth, band_response(101, rg0, RS1_BAND, RS1_CENTRE))
    baseband = np.outer(band_response(81, az0, 0.8, 0.0), band_response(101, rg0, RS1_BAND, 0.0))
    axes = (np.arange(81) * 5.6, np.arange(101) * 4.64)
    want = analyse_point_target(baseband, *axes, chip=(40, 50))
    reports = [
        analyse_point_target(squinted, *axes, chip=(40, 50), **declared)
        for declared in (
            {"azimuth_centre_cycles": 0.31, "range_centre_cycles": RS1_CENTRE},
            {"azimuth_centre_cycles": 0.31},
            {},
        )
    ]
    assert reports[0].centre_cycles == (0.31, RS1_CENTRE)
    assert reports[1].centre_cycles[0] == 0.31
    # found: the middle of each band's gap, within half the gap of the band's centre
    assert abs(reports[1].centre_cycles[1] - RS1_CENTRE) < 0.5 * (1 - RS1_BAND)
    assert abs(reports[2].centre_cycles[0] - 0.31) < 0.5 * (1 - 0.8)
    assert want.centre_cycles == (0.0, 0.0)  # a baseband band is left where it is
    for rep in reports:
        assert rep.peak_px == pytest.approx((az0, rg0), abs=2e-3)
        assert rep.range.irw_m == pytest.approx(SINC_IRW / RS1_BAND * 4.64, rel=2e-3)
        for a, b in ((rep.range, want.range), (rep.azimuth, want.azimuth)):
            assert a.irw_m == pytest.approx(b.irw_m, rel=1e-3)
            assert a.pslr_db == pytest.approx(b.pslr_db, abs=0.02)
        assert abs(rep.peak_value) == pytest.approx(0.8 * RS1_BAND, rel=1e-3)
        assert abs(np.angle(rep.peak_value)) < 2e-3  # both responses real and positive at t0
        # each cut's phase is the point's own, not the baseband chip's
        assert rep.range.peak_phase_rad == rep.azimuth.peak_phase_rad == np.angle(rep.peak_value)
        islr = islr_2d_db(squinted, rep, 5.6, 4.64, 16, 10.0)
        assert islr == pytest.approx(islr_2d_db(baseband, want, 5.6, 4.64, 16, 10.0), abs=0.15)
