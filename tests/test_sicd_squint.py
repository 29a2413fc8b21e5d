"""A squinted image as SICD (NGA.STND.0024, RMA / INCA): the radarsat1 preset's scene (1.58° of
squint, a down-chirp) and a variant squinted 300 Hz the other way with an up-chirp, exported
and read back with NGA's readers.  Against the pixels and the scene's truth, not the writer:

* the centres of the pixels' spectra (a power-weighted circular mean, written here) are the
  DeltaKCOAPoly the SICD declares, times the sample spacing: f_dc / PRF along track (wrapped),
  2 (cos θ - 1) δr / λ in range;
* the centre of aperture trails closest approach by R0 tan θ / V, and the Doppler cone angle
  at the SCP is 90° + θ, sin θ = -λ f_dc / 2V (a beam that looks back);
* each point's measured pixel projects (sarpy's image_to_ground) onto the closest approach
  where the scene put it, within 0.05 of a cell;
* sarkit's consistency checks pass, and sarpy's recursive validity for the up-chirp.  (sarpy
  2.1 reads SICD's transmit FM rate as unsigned: with a down-chirp's negative rate and its
  start at the top of the band, as sarkit checks it, four of its waveform checks fail.)
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

sksicd = pytest.importorskip("sarkit.sicd")
pytest.importorskip("sarkit.verification")
pytest.importorskip("sarpy")

from point_focus import three_points_focused  # noqa: E402
from sicd_checks import sarkit_errors  # noqa: E402

from rtsar.analysis.point_target import analyse_point_target  # noqa: E402
from rtsar.lens import make_plan  # noqa: E402
from rtsar.presets import preset  # noqa: E402
from rtsar.sinks.exports.sicd import write_sicd  # noqa: E402
from rtsar.sinks.image_file import write_image  # noqa: E402
from rtsar.sources.formats.geometry import LocalFrame  # noqa: E402

C = 299_792_458.0
VARIANTS = {"radarsat1": None, "up-chirp, +300 Hz": 300.0}


def _config(variant: str):
    cfg = preset("radarsat1")
    f_dc = VARIANTS[variant]
    if f_dc is not None:
        cfg = replace(
            cfg,
            geometry=replace(cfg.geometry, doppler_centroid_hz=f_dc),
            waveform=replace(cfg.waveform, down_chirp=False),
        )
    return cfg


@pytest.fixture(scope="module", params=list(VARIANTS))
def exported(request, tmp_path_factory):
    """(cfg, SICD read by sarpy, pixels [azimuth, range], SICD xml, truth [(x, R)])."""
    from sarpy.io.complex.converter import open_complex

    cfg = _config(request.param)
    scene, _, image, az, rg, xs, rs = three_points_focused(cfg)
    folder = tmp_path_factory.mktemp("sicd-squint")
    write_image(folder / "sq.h5", image, az, rg, cfg)
    write_sicd(folder / "sq.h5", folder / "sq.nitf")
    with open(folder / "sq.nitf", "rb") as f, sksicd.NitfReader(f) as r:
        xml, pixels = r.metadata.xmltree, r.read_image()
    sicd = open_complex(str(folder / "sq.nitf")).get_sicds_as_tuple()[0]
    truth = list(zip(xs, rs, strict=True))
    return cfg, sicd, pixels.T, xml, truth, folder / "sq.nitf", scene.start_along_track_m


def _sin_squint(cfg) -> float:
    g = cfg.geometry
    return -g.wavelength_m * g.doppler_centroid_hz / (2.0 * g.along_track_step_m * g.prf_hz)


def _wrapped(cycles: float) -> float:
    return (cycles + 0.5) % 1.0 - 0.5


def _spectrum_centre(image: np.ndarray, axis: int) -> float:
    """Cycles a sample: the power-weighted circular mean of the spectrum along ``axis``
    (NumPy's forward transform, SICD's Sgn = -1)."""
    power = (np.abs(np.fft.fft(image, axis=axis)) ** 2).sum(axis=1 - axis)
    f = np.fft.fftfreq(len(power))
    return float(np.angle(np.sum(power * np.exp(2j * np.pi * f))) / (2.0 * np.pi))


def test_the_declared_spectral_centres_are_the_pixels(exported):
    cfg, sicd, image, *_ = exported
    g = cfg.geometry
    col, row = sicd.Grid.Col, sicd.Grid.Row
    declared_az = _wrapped(col.DeltaKCOAPoly.Coefs[0, 0] * col.SS)
    declared_rg = _wrapped(row.DeltaKCOAPoly.Coefs[0, 0] * row.SS)
    # radarsat1: -0.4893 and -0.0626 measured -0.4893 and -0.0628 (compared on the circle:
    # -0.49 sits by the wrap at ±0.5)
    assert abs(_wrapped(_spectrum_centre(image, 0) - declared_az)) < 0.005
    assert abs(_wrapped(_spectrum_centre(image, 1) - declared_rg)) < 0.005
    # and what the geometry says they are (the spectra's centres, from the squint alone)
    s = _sin_squint(cfg)
    assert declared_az == pytest.approx(_wrapped(g.doppler_centroid_hz / g.prf_hz), abs=1e-9)
    delta_r = C / (2.0 * cfg.waveform.sample_rate_hz)
    range_centre = 2.0 * (math.sqrt(1.0 - s * s) - 1.0) * delta_r / g.wavelength_m
    assert declared_rg == pytest.approx(range_centre, rel=1e-6)


def test_the_centre_of_aperture_trails_closest_approach(exported):
    cfg, sicd, *_ = exported
    s = _sin_squint(cfg)
    speed = cfg.geometry.along_track_step_m * cfg.geometry.prf_hz
    r_scp = sicd.RMA.INCA.R_CA_SCP
    lag_s = sicd.SCPCOA.SCPTime - sicd.RMA.INCA.TimeCAPoly[0]
    tan_t = s / math.sqrt(1.0 - s * s)
    assert lag_s == pytest.approx(r_scp * tan_t / speed, rel=1e-6)
    # and at every pixel: R0 tan θ / V with R0 its own range (row coordinate: metres from the
    # SCP's range; column: along track)
    for row_m, col_m in ((-4000.0, -500.0), (0.0, 700.0), (4000.0, 0.0)):
        coa = sicd.Grid.TimeCOAPoly(row_m, col_m)
        ca = sicd.RMA.INCA.TimeCAPoly(col_m)
        assert coa - ca == pytest.approx((r_scp + row_m) * tan_t / speed, rel=1e-9)
    assert sicd.SCPCOA.DopplerConeAng == pytest.approx(90.0 + math.degrees(math.asin(s)), abs=1e-4)


def test_every_pixels_centre_of_aperture_lies_in_the_collection(exported):
    """The track starts where the scene's first pulse was (a squinted beam's look-back added
    to the first line's position): without it, the real block's SCP had its centre of aperture
    at 4.50 s of a 1.22 s collection, which sarkit does not check (a review)."""
    cfg, sicd, image, _, _, _, start_m = exported
    frame = LocalFrame()
    assert frame.from_ecf(sicd.Position.ARPPoly(0.0))[0] == pytest.approx(start_m, abs=1e-3)
    form = sicd.ImageFormation
    rows, cols = image.shape[1], image.shape[0]
    scp = sicd.ImageData.SCPPixel
    for r, c in ((0, 0), (0, cols - 1), (rows - 1, 0), (rows - 1, cols - 1)):
        row_m = (r - scp.Row) * sicd.Grid.Row.SS
        col_m = (c - scp.Col) * sicd.Grid.Col.SS
        assert form.TStartProc <= sicd.Grid.TimeCOAPoly(row_m, col_m) <= form.TEndProc


def test_points_project_to_where_the_scene_put_them(exported):
    """Each point's measured pixel, projected by sarpy, lands on the scene's closest approach.
    (On a straight track this checks the INCA geometry, TimeCAPoly and R_CA, and the pixels:
    every centre-of-aperture time gives the same contour; the lag is checked above.)"""
    cfg, sicd, image, _, truth, *_ = exported
    row, col = sicd.Grid.Row, sicd.Grid.Col
    az = np.arange(image.shape[0]) * col.SS
    rg = np.arange(image.shape[1]) * row.SS
    frame = LocalFrame()  # write_sicd's frame (none given)
    arp_local = frame.from_ecf(sicd.SCPCOA.ARPPos.get_array())
    height = arp_local[2]
    cell_m = C / (2.0 * cfg.waveform.sample_rate_hz)
    centres = {
        "azimuth_centre_cycles": _wrapped(col.DeltaKCOAPoly.Coefs[0, 0] * col.SS),
        "range_centre_cycles": _wrapped(row.DeltaKCOAPoly.Coefs[0, 0] * row.SS),
    }
    # Each point: found near where the SICD's own projection of the truth says it is.
    for x0, r0 in truth:
        ground = frame.to_ecf(np.array([x0, math.sqrt(r0 * r0 - height * height), 0.0]))
        r_pix, c_pix = np.ravel(sicd.project_ground_to_image(ground)[0])
        rep = analyse_point_target(
            image, az, rg, c_pix * col.SS, r_pix * row.SS, (60.0, 20.0), **centres
        )
        measured = np.array([[rep.range_m / row.SS, rep.azimuth_m / col.SS]])
        # onto the SCP's height above the ellipsoid (sarpy's default surface); on a straight
        # track every point of the pixel's range-Doppler contour has one closest approach:
        # along track x, at range sqrt(y² + (h - z)²) from the track
        x, y, z = frame.from_ecf(sicd.project_image_to_ground(measured)[0])
        assert abs(x - x0) / cfg.geometry.along_track_step_m < 0.05
        assert abs(math.hypot(y, height - z) - r0) / cell_m < 0.05


def test_ngas_checks_pass(exported):
    cfg, sicd, _, _, _, path, _ = exported
    passes, errors = sarkit_errors(path)
    assert passes and not errors, errors
    if cfg.waveform.chirp_rate_hz_per_s > 0:
        assert sicd.is_valid(recursive=True)


def test_a_broadside_down_chirp_starts_at_the_top_of_its_band(tmp_path):
    """SICD's TxFMRate is signed and TxFreqStart + TxFMRate · TxPulseLength is where the sweep
    ends (sarkit's check_tx_freq_bounds): a down-chirp's start was written at the bottom of its
    band, and sarkit's check failed for every down-chirp, squinted or not."""
    cfg = preset("radarsat1")
    cfg = replace(cfg, geometry=replace(cfg.geometry, doppler_centroid_hz=0.0))
    rm = make_plan(cfg).range_m[:64]
    image = np.zeros((64, len(rm)), np.complex64)
    image[32, 32] = 1.0
    write_image(tmp_path / "b.h5", image, np.arange(64) * cfg.geometry.along_track_step_m, rm, cfg)
    write_sicd(tmp_path / "b.h5", tmp_path / "b.nitf")
    with open(tmp_path / "b.nitf", "rb") as f, sksicd.NitfReader(f) as r:
        x = sksicd.XmlHelper(r.metadata.xmltree)
        start = x.load("{*}RadarCollection/{*}Waveform/{*}WFParameters/{*}TxFreqStart")
        rate = x.load("{*}RadarCollection/{*}Waveform/{*}WFParameters/{*}TxFMRate")
        length = x.load("{*}RadarCollection/{*}Waveform/{*}WFParameters/{*}TxPulseLength")
        f_max = x.load("{*}RadarCollection/{*}TxFrequency/{*}Max")
        f_min = x.load("{*}RadarCollection/{*}TxFrequency/{*}Min")
    assert rate < 0
    assert start == pytest.approx(f_max, abs=1.0)
    assert start + rate * length == pytest.approx(f_min, rel=1e-6)
    passes, errors = sarkit_errors(tmp_path / "b.nitf")
    assert passes and not errors, errors
