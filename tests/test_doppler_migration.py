"""The range read in the azimuth spectrum (rtsar.ccd.doppler_migration, (M4)) against the exact
two-dimensional mask of the time domain (rtsar.ccd.migration, (M2)) on a squinted scene, and
its own invariants."""

from __future__ import annotations

import math

import numpy as np
import pytest
from point_focus import focus_points, whole_and_in_pieces

from rtsar.ccd.doppler_migration import DopplerMigrationCorrelator, doppler_migration_bins
from rtsar.lens import make_plan
from rtsar.params import Processor
from rtsar.presets import preset
from rtsar.scene import Simulator
from rtsar.scene.model import point_scene

C = 299_792_458.0


@pytest.fixture(scope="module")
def scene():
    cfg = preset("radarsat1")
    rs = make_plan(cfg).range_m[[300, 1500]] + np.array([0.9, 2.3])
    xs = np.array([2000.0, 2600.0])
    sc = point_scene(cfg, xs, rs, effects=[("antenna_pattern", {"main_lobe_only": True})])
    return cfg, sc, Simulator(sc).block(sc.pulses), xs, rs


def test_the_migration_at_the_centroid_is_the_beam_centre_range():
    """Δ(f, r) of (M4) at the frequency bin nearest the centroid, from the instrument's own
    conventions: the beam centre sees R0 at R0 / cos θ; an echo centred at sample n of the fixed
    window lies at R = c (window_start + n / fs) / 2, and the lens labels the middle bin
    R_c - R0 short of that (R_c (1 - cos θ) at the middle)."""
    cfg = preset("radarsat1")
    g, wf = cfg.geometry, cfg.waveform
    label = make_plan(cfg).range_m  # the columns' R0, as the image declares them
    m = 4096
    shift = doppler_migration_bins(cfg, label, m)
    k = round((g.doppler_centroid_hz % g.prf_hz) * m / g.prf_hz) % m
    f = g.doppler_centroid_hz + ((k * g.prf_hz / m - g.doppler_centroid_hz) % g.prf_hz)
    f -= g.prf_hz if f - g.doppler_centroid_hz > g.prf_hz / 2 else 0.0
    cos_f = math.sqrt(1 - (g.wavelength_m * f / (2 * g.speed_mps)) ** 2)
    cos_dc = math.sqrt(1 - (g.wavelength_m * g.doppler_centroid_hz / (2 * g.speed_mps)) ** 2)
    bin_m = C / (2 * wf.sample_rate_hz)
    # bin 1024 is the lag where an echo starts 1024 - P//2 samples into the window: its centre
    # is half the pulse later, and R = c (window_start + n_centre / fs) / 2 there
    n_centre = 1024 - wf.pulse_samples // 2 + 0.5 * wf.pulse_duration_s * wf.sample_rate_hz
    raw_mid = 0.5 * C * (wf.window_start_s + n_centre / wf.sample_rate_hz)
    expect = (label / cos_f - label - raw_mid * (1 - cos_dc)) / bin_m
    assert abs(f - g.doppler_centroid_hz) < g.prf_hz / m
    assert np.abs(shift[k] - expect).max() < 1e-3


def test_streaming_equals_one_block(scene):
    cfg, sc, shots, *_ = scene
    kind, a, b, _ = whole_and_in_pieces(cfg, shots)
    assert issubclass(kind, DopplerMigrationCorrelator)
    assert a.shape == b.shape
    assert np.array_equal(a, b)


@pytest.mark.slow
def test_doppler_domain_focuses_as_the_exact_time_domain_mask(scene):
    cfg, sc, shots, xs, rs = scene
    step, cell = cfg.geometry.along_track_step_m, C / (2 * cfg.waveform.sample_rate_hz)
    start = sc.start_along_track_m
    reports = {d: focus_points(cfg, shots, start, xs, rs, range_migration_domain=d)
               for d in ("time", "doppler")}  # fmt: skip
    for t, d, x, r in zip(reports["time"], reports["doppler"], xs, rs, strict=True):
        assert abs(d.azimuth_m - x) / step < 0.05 and abs(d.range_m - r) / cell < 0.05
        assert d.azimuth.irw_m == pytest.approx(t.azimuth.irw_m, rel=0.01)
        assert d.range.irw_m == pytest.approx(t.range.irw_m, rel=0.01)
        assert abs(d.peak_value) == pytest.approx(abs(t.peak_value), rel=0.02)


def test_doppler_domain_needs_the_fft_correlator():
    with pytest.raises(ValueError, match="range_migration_domain"):
        Processor(8, 8, correlator="direct", range_migration_domain="doppler")
    with pytest.raises(ValueError, match="range_migration_domain"):
        Processor(8, 8, range_migration_domain="frequency")


@pytest.mark.parametrize("squint_sin", [0.0277, 0.4])
def test_secondary_range_compression_is_cumming_and_wongs_at_any_squint(squint_sin):
    """The lens's SRC filter exp(-iπ f² / K_src), K_src = 2 V² f0³ D³ / (c R f_η²),
    D = sqrt(1 - (λ f_η / 2V)²) (Cumming & Wong 2005, sec. 6.2), over the chirp's band, at
    RADARSAT-1's squint (D = 0.9996) and at a squint of 24° (D = 0.917: a D² in place of D³
    moves the band edge's phase by radians there, by a thousandth of one at RADARSAT-1's)."""
    from dataclasses import replace

    from rtsar.lens.plan import secondary_range_compression

    cfg = preset("radarsat1")
    g = cfg.geometry
    speed = g.along_track_step_m * g.prf_hz
    f_eta = -squint_sin * 2.0 * speed / g.wavelength_m
    cfg = replace(cfg, geometry=replace(g, doppler_centroid_hz=f_eta))
    f0 = 299_792_458.0 / g.wavelength_m
    d = math.sqrt(1.0 - (g.wavelength_m * f_eta / (2.0 * speed)) ** 2)
    k_src = 2.0 * speed**2 * f0**3 * d**3 / (299_792_458.0 * g.slant_range_m * f_eta**2)
    f = np.linspace(-0.5, 0.5, 101) * cfg.waveform.bandwidth_hz
    expected = np.exp(-1j * np.mod(math.pi * f**2 / k_src, 2.0 * math.pi))
    assert cfg.processor.range_centre_m is None  # R: the geometry's slant range
    np.testing.assert_allclose(secondary_range_compression(cfg, f), expected, atol=1e-9)
