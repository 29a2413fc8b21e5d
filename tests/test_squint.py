"""A squinted strip-map scene (the radarsat1 preset: RADARSAT-1's parameters, 1.58° of squint,
22 range cells of walk across the aperture) focused by the lens and the shifting CCD, against
the scene's truth: positions in zero-Doppler geometry, -3 dB widths against theory, and the
Doppler centroid estimated back from the echoes."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from point_focus import three_points_focused

from rtsar.analysis.azimuth_response import antenna_gain, azimuth_theory
from rtsar.analysis.doppler_centroid import estimate_doppler_centroid
from rtsar.analysis.point_target import analyse_point_target, image_centres
from rtsar.analysis.theory import theoretical_irw_factor
from rtsar.ccd.base import line_azimuth_m
from rtsar.lens import make_lens, make_plan
from rtsar.presets import preset
from rtsar.scene import Simulator
from rtsar.scene.effects.antenna import AntennaPattern
from rtsar.scene.model import point_scene
from rtsar.windows import window

C = 299_792_458.0


@pytest.fixture(scope="module")
def squinted():
    cfg = preset("radarsat1")
    # truth: closest-approach along-track and range, off the pixel grid
    scene, shots, image, az, rg, xs, rs = three_points_focused(cfg)
    return cfg, cfg.geometry, scene, shots, image, az, rg, xs, rs


def test_the_scene_is_hard(squinted):
    cfg, g, *_ = squinted
    # walk across the aperture from the paper-independent geometry: λ|f_dc|/2 m/s for A/V s
    cell_m = C / (2 * cfg.waveform.sample_rate_hz)
    aperture_s = g.wavelength_m * g.slant_range_m / g.antenna_length_m / g.speed_mps
    walk_cells = g.wavelength_m * abs(g.doppler_centroid_hz) / 2 * aperture_s / cell_m
    assert walk_cells > 20
    assert math.degrees(math.asin(g.squint_sin)) == pytest.approx(1.58, abs=0.01)


def _measured(squinted):
    """(true along track, true range, the point's report) for each target, measured about the
    image's declared spectral centres: the Doppler centroid, and the range band's."""
    cfg, _, _, _, image, az, rg, xs, rs = squinted
    centres = image_centres(cfg)
    return [
        (
            x,
            r,
            analyse_point_target(image, az, rg, x, r, (60.0, 20.0), **centres),
        )
        for x, r in zip(xs, rs, strict=True)
    ]


def test_positions_in_zero_doppler_geometry(squinted):
    cfg, g, scene, shots, image, az, rg, xs, rs = squinted
    cell_m = C / (2 * cfg.waveform.sample_rate_hz)
    for x, r, rep in _measured(squinted):
        # measured 0.008 and 0.0002 (the range 0.004-0.013 where the range band, 0.063 cycle a
        # bin off zero, was interpolated about zero: rtsar.analysis.interpolation)
        assert abs(rep.azimuth_m - x) / g.along_track_step_m < 0.02
        assert abs(rep.range_m - r) / cell_m < 0.005


def test_widths_against_theory(squinted):
    cfg, g, scene, shots, image, az, rg, xs, rs = squinted
    beam = antenna_gain(AntennaPattern(cfg, main_lobe_only=True))
    # range: 0.886 c / 2B times the Taylor window's broadening (Psaltis eq. 6)
    range_irw = 0.886 * C / (2 * cfg.waveform.bandwidth_hz)
    range_irw *= theoretical_irw_factor(window("taylor", 4096))
    # 16 migration taps (rtsar.ccd.migration.taps_for_band) read 1.07x-sampled lines: the range
    # response measured 0.7 % wide, PSLR -33.6 dB (8 taps: 2.1 %, -31.4 dB; measured about
    # zero, the range band straddling the DFT's split: 2.3-4.8 %, -28.4 dB)
    for _, r, rep in _measured(squinted):
        theory = azimuth_theory(cfg, r, gain=beam).irw_m
        assert rep.azimuth.irw_m == pytest.approx(theory, rel=0.01)
        assert rep.range.irw_m == pytest.approx(range_irw, rel=0.012)
        assert rep.range.pslr_db < -33.0


def test_the_range_band_sits_where_the_geometry_declares_it(squinted):
    """image_centres declares the range band 2 (cos θ - 1) δr / λ cycles a bin off zero, from
    the geometry alone (sin θ = -λ f_dc / 2V); each point's range cut through its peak
    measures it (the lag-one phase, the centroid of its power spectrum) within 0.003 cycle:
    -0.0643 against -0.0626.  0.063 cycle puts the band, 0.93 of the bins, across the DFT's
    split, where the analysis interpolated it about zero until it was declared."""
    cfg, g, *_ = squinted
    cell_m = C / (2 * cfg.waveform.sample_rate_hz)
    cos_theta = math.sqrt(1.0 - (g.wavelength_m * g.doppler_centroid_hz / (2 * g.speed_mps)) ** 2)
    declared = image_centres(cfg)["range_centre_cycles"]
    assert declared == pytest.approx(2 * (cos_theta - 1) * cell_m / g.wavelength_m, rel=1e-6)
    assert declared < -0.5 * (1 - cfg.waveform.bandwidth_hz / cfg.waveform.sample_rate_hz)
    image = squinted[4]
    for _, _, rep in _measured(squinted):
        row = image[int(round(rep.peak_px[0]))].astype(complex)
        c = int(round(rep.peak_px[1]))
        cut = row[c - 64 : c + 65]
        measured = np.angle(np.sum(cut[1:] * np.conj(cut[:-1]))) / (2 * np.pi)
        assert measured == pytest.approx(declared, abs=3e-3)


def test_doppler_centroid_estimated_back(squinted):
    cfg, g, scene, shots, *_ = squinted
    lines = make_lens(make_plan(cfg), "numpy").compress(shots)
    est = estimate_doppler_centroid(
        lines, g.prf_hz, g.wavelength_m, C / (2 * cfg.waveform.sample_rate_hz)
    )
    assert est.ambiguity == round(g.doppler_centroid_hz / g.prf_hz)
    assert est.centroid_hz == pytest.approx(g.doppler_centroid_hz, abs=50.0)


def test_broadside_costs_nothing_new():
    """A scene without squint builds the very mask and axis it built before squint existed:
    the window the same for every column, no label offset, lines at the aperture centre."""
    from rtsar.ccd.base import design_mask, line_azimuth_m, mask_window
    from rtsar.lens.plan import range_axis_m, raw_range_axis_m

    cfg = preset("psaltis-jpl")
    r = range_axis_m(cfg)
    assert np.array_equal(r, raw_range_axis_m(cfg))
    w = mask_window(cfg, r)
    assert np.array_equal(w, np.broadcast_to(w[:, :1], w.shape))
    n, d = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    assert line_azimuth_m(cfg, 0.0, 0, 1)[0] == pytest.approx(0.5 * (n - 1) * d)
    assert abs(design_mask(cfg, r)).sum(axis=0) == pytest.approx(np.ones(len(r)))


def test_the_simulated_echo_sits_where_the_instruments_convention_puts_it():
    """Independent of the lens plan: with the fixed window of the radarsat1 preset, an echo
    from slant range R is centred 2R/c after the pulse centre, i.e. at sample
    (2R/c - window_start) fs (the shared instrument.toml's convention)."""
    cfg = preset("radarsat1")
    wf = cfg.waveform
    r = 0.5 * C * (wf.window_start_s + 1000.3 / wf.sample_rate_hz)
    scene = point_scene(cfg, [0.0], [r], pulses=1, start_along_track_m=0.0)
    shot = Simulator(scene).block(1)[0]
    lit = np.flatnonzero(np.abs(shot) > 0.5)
    centre = 0.5 * (lit[0] + lit[-1] + 1)  # the chirp's rectangular envelope, its midpoint
    assert centre == pytest.approx((2 * r / C - wf.window_start_s) * wf.sample_rate_hz, abs=0.6)


@pytest.mark.parametrize("centroid_hz", [-6900.0, 6900.0])
@pytest.mark.parametrize("near_first", [True, False])
def test_a_default_scan_images_targets_at_both_swath_edges(centroid_hz, near_first):
    """The default scan (rtsar.scene.model.scan_extent) holds every target's image line with a
    margin of at least 8 lines, whichever squint and whichever edge the first target is at.
    It covered where the beam sees each target (u_c at its own range) but not where the image
    puts it (lines trail their apertures by u_mid, at the range centre): 130 m apart at
    RADARSAT-1's swath edges, and targets 1800 and 2600 m out fell outside an image of
    1873-2530 m (a cold review)."""
    cfg = preset("radarsat1")
    cfg = replace(cfg, geometry=replace(cfg.geometry, doppler_centroid_hz=centroid_hz))
    edges = make_plan(cfg).range_m[[0, -1]]
    rs = edges if near_first else edges[::-1]
    xs = np.array([1800.0, 2600.0])
    sc = point_scene(cfg, xs, rs)
    n = cfg.processor.aperture_pulses
    az = line_azimuth_m(cfg, sc.start_along_track_m, 0, sc.pulses - n + 1)
    margin_m = 8 * cfg.geometry.along_track_step_m
    assert az[0] <= xs.min() - margin_m and az[-1] >= xs.max() + margin_m


def test_the_chirp_the_fixed_window_holds_is_the_simulated_echos():
    """chirp_fraction_held against the simulator's echo, counted sample by sample: of an echo
    from the range of bin j, the share of its P chirp samples inside the S-sample window
    (the whole chirp on S - P + 1 of the 2048 bins; RADARSAT-1's window start, no squint)."""
    from rtsar.app.measure_notes import window_notes
    from rtsar.lens.plan import chirp_fraction_held, range_axis_m

    cfg = preset("radarsat1")
    cfg = replace(cfg, geometry=replace(cfg.geometry, doppler_centroid_hz=0.0))
    held, axis = chirp_fraction_held(cfg), range_axis_m(cfg)
    wf = cfg.waveform
    assert np.count_nonzero(held == 1.0) == wf.samples_per_shot - wf.pulse_samples + 1
    for j in (5, 400, 1000, 1700, 2040):
        scene = point_scene(cfg, [0.0], [axis[j]], pulses=1, start_along_track_m=0.0)
        lit = np.count_nonzero(np.abs(Simulator(scene).block(1)[0]) > 0.5)
        assert held[j] == pytest.approx(lit / wf.pulse_samples, abs=1.5 / wf.pulse_samples), j
    notes = window_notes([{"range_m": axis[1974]}, {"range_m": axis[1000]}], cfg)
    assert f"holds {100 * held[1974]:.0f} % of this echo's chirp" in notes[0][0]
    assert notes[1] == []
