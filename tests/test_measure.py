"""``rtsar measure``: analytic sincs of known IRW, PSLR and ISLR; found points and given
positions; offsets from a scene's targets in cells; heights against a scene's surface."""

import json
import math

import numpy as np
import pytest
from scipy import integrate

from rtsar.analysis.cut import analyse_cut
from rtsar.analysis.islr2d import theoretical_islr_2d_db
from rtsar.app.cli import main
from rtsar.app.measure_image import POINT_KEYS
from rtsar.presets import preset
from rtsar.sinks.image_file import ImageWriter, write_image

SINC_HALF_POWER = 0.885893  # x where sinc(x)^2 = 1/2, times 2


def sinc_fractions(extent_irw: float) -> tuple[float, float]:
    """(mainlobe, within ±extent IRWs) fractions of the energy of sinc², by quadrature."""

    def f(x):
        return np.sinc(x) ** 2

    main_part = 2 * integrate.quad(f, 0, 1, limit=200)[0]
    edge = extent_irw * SINC_HALF_POWER
    inner = 2 * integrate.quad(f, 0, edge, limit=2000)[0]
    return main_part, inner  # sinc² integrates to 1


def test_one_cut_of_a_sinc_has_the_textbook_irw_pslr_and_islr():
    rho = 1.0
    x = np.arange(-40, 41) * 0.8 + 0.31  # 1.25 samples per null-to-null half-width, off-grid
    m, t = sinc_fractions(10.0)
    cut = analyse_cut(np.sinc(x / rho), 0.8, float(x[0]))
    assert cut.irw_m == pytest.approx(SINC_HALF_POWER * rho, rel=2e-3)
    assert cut.pslr_db == pytest.approx(-13.26, abs=0.02)
    assert cut.islr_db == pytest.approx(10 * math.log10((t - m) / m), abs=0.1)  # -9.7 dB


def sinc_image(points, rho_a: float, rho_r: float, az, rg) -> np.ndarray:
    """Σ sinc((x - x_k)/ρA) sinc((r - r_k)/ρR) a_k, written out (no rtsar code)."""
    img = np.zeros((len(az), len(rg)), np.complex128)
    for x0, r0, a in points:
        img += a * np.outer(np.sinc((az - x0) / rho_a), np.sinc((rg - r0) / rho_r))
    return img.astype(np.complex64)


@pytest.fixture
def tiny_sinc_image(tmp_path):
    """An image file with the tiny preset's configuration (rect windows) holding two analytic
    separable sincs of its theoretical resolutions, off the pixel grid."""
    cfg = preset("tiny")
    rho_r = cfg.waveform.range_resolution_m
    rho_a = cfg.azimuth_resolution_m(2000.0)
    az = np.arange(-160, 161) * 0.8 * rho_a / 1.0
    rg = 1900.0 + np.arange(0, 400) * 0.75 * rho_r
    pts = [(0.3 * rho_a, 2000.0 + 0.2 * rho_r, 1.0), (60.0 * rho_a, 1950.0, 0.5j)]
    path = tmp_path / "sinc.h5"
    write_image(path, sinc_image(pts, rho_a, rho_r, az, rg), az, rg, cfg)
    return path, pts, rho_a, rho_r


def test_measure_reports_the_sincs_against_theory(tiny_sinc_image, tmp_path, capsys):
    path, pts, rho_a, rho_r = tiny_sinc_image
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    points = report["points"]
    assert len(points) == 2 and all(tuple(p) == POINT_KEYS for p in points)
    m, t = sinc_fractions(10.0)
    islr_2d = 10 * math.log10((t * t - m * m) / (m * m))  # -7.0 dB
    for p, th, (x0, r0, a) in zip(points, report["theory"], pts, strict=True):
        assert p["along_track_m"] == pytest.approx(x0, abs=1e-3 * rho_a)
        assert p["range_m"] == pytest.approx(r0, abs=1e-3 * rho_r)
        assert p["peak"] == pytest.approx(abs(a), rel=3e-3)
        assert p["irw_range_m"] == pytest.approx(SINC_HALF_POWER * rho_r, rel=3e-3)
        assert p["pslr_azimuth_db"] == pytest.approx(-13.26, abs=0.05)
        assert p["pslr_range_db"] == pytest.approx(-13.26, abs=0.05)
        assert p["islr_db"] == pytest.approx(islr_2d, abs=0.15)
        # the processor's theory (rect windows) is the same sinc
        assert th["irw_range_m"] == pytest.approx(SINC_HALF_POWER * rho_r, rel=3e-3)
        assert th["pslr_range_db"] == pytest.approx(-13.26, abs=0.05)
        assert th["islr_db"] == pytest.approx(islr_2d, abs=0.1)
    assert points[0]["irw_azimuth_m"] == pytest.approx(SINC_HALF_POWER * rho_a, rel=3e-3)
    assert report["theory"][0]["irw_azimuth_m"] == pytest.approx(SINC_HALF_POWER * rho_a, rel=3e-3)
    text = capsys.readouterr().out
    assert "2 point(s)" in text and "ISLR 2-D" in text


def test_measure_at_given_positions_and_truth_in_cells(tiny_sinc_image, tmp_path, capsys):
    path, pts, rho_a, rho_r = tiny_sinc_image
    scene = tmp_path / "s.toml"
    scene.write_text(
        'preset = "tiny"\n[[targets]]\nalong_track_m = 0.0\nslant_range_m = 2000.0\n'
        "[[targets]]\nalong_track_m = 500.0\nslant_range_m = 2050.0\n"
    )
    out = tmp_path / "m.json"
    args = ["measure", str(path), "--scene", str(scene), "--json", str(out)]
    assert main(args + ["--at", f"{pts[0][0] + 0.5 * rho_a},{pts[0][1]}", "--at", "60,1950"]) == 0
    report = json.loads(out.read_text())
    assert len(report["points"]) == 2 and report["height"] is None
    first, second = report["truth"]
    assert first["offset_azimuth_cells"] == pytest.approx(0.3, abs=2e-3)
    assert first["offset_range_cells"] == pytest.approx(0.2, abs=2e-3)
    assert second is None  # no scene target within 3 cells of the second point
    assert "offset +0.300 azimuth, +0.200 range cells" in capsys.readouterr().out


def test_found_points_are_the_isolated_peaks_not_the_speckle(tmp_path, rng):
    cfg = preset("tiny")
    rho_r, rho_a = cfg.waveform.range_resolution_m, cfg.azimuth_resolution_m(2000.0)
    az = np.arange(-200, 201) * 0.8 * rho_a
    rg = 1900.0 + np.arange(400) * 0.75 * rho_r
    # speckle of a diffuse area over the middle of the image, 25 dB under the points: white
    # complex noise there, band-limited to the sincs' band (|f| < 1/2ρ: 0.4 and 0.375 cycles
    # per pixel)
    noise = np.zeros((len(az), len(rg)), np.complex128)
    noise[100:300, 100:300] = rng.standard_normal((200, 200)) + 1j * rng.standard_normal((200, 200))
    f_az = np.abs(np.fft.fftfreq(len(az)))[:, None] <= 0.4
    f_rg = np.abs(np.fft.fftfreq(len(rg)))[None, :] <= 0.375
    speckle = np.fft.ifft2(np.fft.fft2(noise) * (f_az & f_rg))
    speckle *= 10 ** (-25 / 20) / np.sqrt(np.mean(np.abs(speckle[120:280, 120:280]) ** 2))
    pts = [(az[30] + 0.2 * rho_a, rg[350], 1.0), (az[370], rg[40] + 0.4 * rho_r, 0.8)]
    floor = 10 ** (-45 / 20) * (
        rng.standard_normal(noise.shape) + 1j * rng.standard_normal(noise.shape)
    )
    img = sinc_image(pts, rho_a, rho_r, az, rg) + (speckle + floor).astype(np.complex64)
    path = tmp_path / "speckle.h5"
    write_image(path, img, az, rg, cfg)
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    found = report["points"]
    assert len(found) == 2
    for p, (x0, r0, _) in zip(found, pts, strict=True):
        assert abs(p["along_track_m"] - x0) < 0.01 * rho_a
        assert abs(p["range_m"] - r0) < 0.01 * rho_r
    # Issue 37: points in clutter 25 dB under them, alone, get no clutter note: their ISLR
    # is their response's ...
    assert not any("clutter" in n for notes in report["notes"] for n in notes)
    # ... and a point 5 dB over the speckle is told that its ISLR measures the scene.
    weak = sinc_image([(az[200], rg[200], 10 ** (-20 / 20))], rho_a, rho_r, az, rg)
    write_image(path, img + weak, az, rg, cfg)
    assert main(["measure", str(path), "--at", f"{az[200]},{rg[200]}", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    islr, theory = report["points"][0]["islr_db"], report["theory"][0]["islr_db"]
    assert islr > theory + 10.0
    assert any("clutter, speckle, noise" in n for n in report["notes"][0])


def test_height_rmse_and_valid_fraction_against_the_scene_surface(tmp_path):
    from rtsar.scene.files import load_surface_scene

    scene = tmp_path / "ridge.toml"
    scene.write_text(
        'preset = "zhao-insal"\nseed = 2\n[geometry]\nplatform_height_m = 1.3856406460551016\n'
        '[processor]\naperture_pulses = 48\nrange_bins = 48\n[surface]\nshape = "ridge"\n'
        "lines = 16\n"
    )
    surface = load_surface_scene(scene)
    cfg = surface.config
    from rtsar.lens import range_axis_m

    rg = range_axis_m(cfg)
    az = (np.arange(16) - 7.5) * cfg.geometry.along_track_step_m
    truth = surface.truth(az, rg)
    error = np.where(np.arange(len(rg)) % 2 == 0, 2e-6, -2e-6)[None, :]  # RMSE 2 µm exactly
    valid = truth.scored.copy()
    valid[:4] = False  # a quarter of the lines without heights
    path = tmp_path / "h.h5"
    w = ImageWriter(path, cfg, rg, heights=True)
    w.write(np.ones((16, len(rg)), np.complex64), az)
    w.write_heights(0, (truth.height_m + error).astype(np.float32), valid)
    w.close()
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--scene", str(scene), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert report["points"] == []  # a flat image: no point target
    h = report["height"]
    assert h["rmse_m"] == pytest.approx(2e-6, rel=1e-3)
    expect = valid.sum() / truth.scored.sum()
    assert h["valid_fraction"] == pytest.approx(expect) and 0.6 < expect < 0.8


def test_theory_of_a_taylor_weighting_is_lower_sidelobes():
    from rtsar.windows import window

    rect = theoretical_islr_2d_db(np.ones(256), np.ones(256))
    taylor = theoretical_islr_2d_db(window("taylor", 256), window("taylor", 256))
    assert rect == pytest.approx(-7.0, abs=0.05) and taylor < rect - 15


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--at", "abc"], "--at takes X,R"),
        (["--at", "1e9,2000"], "outside the image"),
        (["--max-points", "0"], "--max-points"),
        (["--scene", "nope.toml"], "scene file not found"),
    ],
)
def test_bad_requests_are_one_line(tiny_sinc_image, capsys, extra, message):
    path = tiny_sinc_image[0]
    assert main(["measure", str(path)] + extra) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


SPOT_SCENE = """
preset = "crouch-spotlight"
[waveform]
sample_rate_hz = 213.33333333333334
[geometry]
along_track_step_m = 0.0011140625
[processor]
aperture_pulses = 2
range_bins = 64
[spotlight]
sweep_deg = 5.0
[[targets]]
x_m = 0.0
[[targets]]
x_m = 0.0004
y_m = 0.0003
"""


def test_a_spotlight_image_is_measured_against_its_inscribed_rectangle(tmp_path, capsys):
    """From a cold review: spotlight images were refused. x is cross-range ("azimuth"), y
    down-range ("range"); the theory is the inscribed rectangle's 2π/Δk per axis, which at a
    5° sweep keeps 94 % of the band (c/2B alone is 6 % too fine in y)."""
    scene, rec, img = tmp_path / "s.toml", tmp_path / "s.h5", tmp_path / "img.h5"
    scene.write_text(SPOT_SCENE)
    assert main(["spot-simulate", str(scene), "-o", str(rec)]) == 0
    assert main(["spotlight", str(rec), "-o", str(img), "--extent-mm", "1.2", "1.2"]) == 0
    capsys.readouterr()
    assert main(["measure", str(img), "--json", str(tmp_path / "m.json")]) == 0
    header = capsys.readouterr().out.splitlines()[1]  # the table's column headings
    assert "cross range [m]" in header and "down range [m]" in header
    assert "along track" not in header and "azimuth" not in header
    report = json.loads((tmp_path / "m.json").read_text())
    assert "cross-range x" in report["method"]["axes"] and len(report["points"]) == 2
    for point, theory in zip(report["points"], report["theory"], strict=True):
        assert set(point) == set(POINT_KEYS)
        for key in ("irw_azimuth_m", "irw_range_m"):
            assert point[key] == pytest.approx(theory[key], rel=0.02), key
        assert point["pslr_range_db"] == pytest.approx(-13.26, abs=0.3)
    # the range theory is the rectangle's, not c/2B (0.886 c/2B = 44.27 µm here)
    assert report["theory"][0]["irw_range_m"] > 1.04 * 44.27e-6
    assert main(["measure", str(img), "--scene", str(scene)]) == 2
    assert "spotlight image: its truth offsets are not measured yet" in capsys.readouterr().err


def test_an_image_without_its_configuration_is_one_line(tmp_path, capsys):
    """From a cold review: `rtsar measure` of an image without its `config` attribute was a
    17-line KeyError traceback (quicklook reads such a file; export refuses it properly)."""
    import h5py

    path = tmp_path / "img.h5"
    x = np.arange(8) * 1.0
    write_image(path, np.ones((8, 8), np.complex64), x, x + 100.0, preset("tiny"))
    with h5py.File(path, "a") as f:
        del f.attrs["config"]
    assert main(["measure", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}: no 'config' attribute" in err and "Traceback" not in err
    with h5py.File(path, "a") as f:
        f.attrs["config"] = "{not json"
    assert main(["measure", str(path)]) == 2
    assert "its 'config' attribute does not read" in capsys.readouterr().err


BEAM_SCENE = """preset = "psaltis-jpl"
[processor]
azimuth_window = "taylor"
range_window = "taylor"
range_bins = 160
[[targets]]
along_track_m = 0.0
slant_range_m = 20000.0
[[effects]]
name = "antenna_pattern"
antenna_length_m = 58.75
main_lobe_only = true
"""


def test_azimuth_theory_is_the_correlators_response_to_the_scenes_beam(tmp_path, capsys):
    """The demo's beam (nulls ±80 m, an 80 m aperture): the window stays with the mask, the
    beam moves with the line.  Measured 32.9 m; the fixed taper |DFT(w·g)| said 39.1 m and a
    -42 dB sidelobe the response does not have (the image's read -181 dB: rounding)."""
    from rtsar.analysis.acceptance import _focus_one
    from rtsar.scene.files import load_scene

    scene = tmp_path / "beam.toml"
    scene.write_text(BEAM_SCENE)
    cfg = load_scene(scene).config
    beam = [("antenna_pattern", {"antenna_length_m": 58.75, "main_lobe_only": True})]
    image, az, rg = _focus_one(cfg, 0.0, 20000.0, beam, "numpy", 2600)
    path = tmp_path / "beam.h5"
    write_image(path, image, az, rg, cfg)
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--scene", str(scene), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    (p,), (th,), (notes,) = report["points"], report["theory"], report["notes"]
    assert th["irw_azimuth_m"] == pytest.approx(32.90, abs=0.05)
    assert p["irw_azimuth_m"] == pytest.approx(th["irw_azimuth_m"], rel=0.005)
    assert p["pslr_azimuth_db"] is None and th["pslr_azimuth_db"] is None
    assert any("no azimuth sidelobe above -100 dB" in n for n in notes)
    assert "antenna pattern" in report["method"]["azimuth_theory"]
    assert "no azimuth sidelobe" in capsys.readouterr().out
    # Issue 37: the SICD export declares the same theory when told the scene (it declared the
    # beamless band's width, 34.8 m on the demo, where the pixels measure 33).
    from sarpy.io.complex.converter import open_complex

    for extra, expected in (([], None), (["--scene", str(scene)], th["irw_azimuth_m"])):
        out = tmp_path / f"beam{len(extra)}.nitf"
        assert main(["export", str(path), "--sicd", str(out), *extra]) == 0
        declared = open_complex(str(out)).get_sicds_as_tuple()[0].Grid.Col.ImpRespWid
        if expected is None:
            assert declared > 1.03 * th["irw_azimuth_m"]  # the band alone: not the beam's
        else:
            assert declared == pytest.approx(expected, rel=1e-6)
            assert declared == pytest.approx(p["irw_azimuth_m"], rel=0.005)  # what it measures
    assert main(["export", str(path), "--cphd", str(tmp_path / "x.cphd"), "--scene", "demo"]) == 2


def test_a_scene_of_another_instrument_is_refused(tiny_sinc_image, capsys):
    assert main(["measure", str(tiny_sinc_image[0]), "--scene", "sal-demo"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "does not match" in err[0] and "waveform." in err[0]


def test_several_positions_after_one_at(tiny_sinc_image, tmp_path):
    path, pts, rho_a, rho_r = tiny_sinc_image
    out = tmp_path / "m.json"
    first = f"{pts[0][0]},{pts[0][1]}"
    second = f"{pts[1][0]},{pts[1][1]}"
    assert main(["measure", str(path), "--json", str(out), "--at", first, second]) == 0
    assert len(json.loads(out.read_text())["points"]) == 2
    assert main(["measure", str(path), "--json", str(out), "--at", first, "--at", second]) == 0
    assert len(json.loads(out.read_text())["points"]) == 2


def _pair_image(tmp_path, gap_range_cells: float, amplitudes=(1.0, 1.0)):
    cfg = preset("tiny")
    rho_r, rho_a = cfg.waveform.range_resolution_m, cfg.azimuth_resolution_m(2000.0)
    az = np.arange(-160, 161) * 0.8 * rho_a
    rg = 1900.0 + np.arange(300) * 0.75 * rho_r
    pts = [
        (0.1 * rho_a, 2000.0, amplitudes[0]),
        (0.1 * rho_a, 2000.0 + gap_range_cells * rho_r, amplitudes[1]),
    ]
    path = tmp_path / "pair.h5"
    write_image(path, sinc_image(pts, rho_a, rho_r, az, rg), az, rg, cfg)
    return path, pts, rho_a, rho_r


def test_a_resolved_pair_four_cells_apart_is_two_points_each_noting_the_other(tmp_path):
    """The demo's pair (15 m, four range cells): the detector kept one of them."""
    path, pts, rho_a, rho_r = _pair_image(tmp_path, 4.0, (1.0, 0.9))
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    found = sorted(report["points"], key=lambda p: p["range_m"])
    assert len(found) == 2
    for p, (_, r0, _) in zip(found, pts, strict=True):
        assert p["range_m"] == pytest.approx(r0, abs=0.1 * rho_r)  # each other's sidelobes
    for notes in report["notes"]:
        assert any("on the range cut" in n and "range PSLR and the ISLR" in n for n in notes)
    # the fainter point's cut is measured about its own peak: the brighter one is its sidelobe
    fainter = min(report["points"], key=lambda p: p["peak"])
    brighter = max(report["points"], key=lambda p: p["peak"])
    ratio_db = 20 * math.log10(brighter["peak"] / fainter["peak"])
    assert fainter["pslr_range_db"] == pytest.approx(ratio_db, abs=0.1) and ratio_db > 0.5
    assert fainter["irw_range_m"] == pytest.approx(SINC_HALF_POWER * rho_r, rel=0.05)
    assert set(report) >= {"points", "theory", "notes"}
    assert all(tuple(p) == POINT_KEYS for p in report["points"])


def test_a_point_whose_peak_spans_two_equal_pixels_is_found_once():
    from rtsar.analysis.detect import find_point_targets

    x = np.sinc((np.arange(64) - 31.5)[:, None] / 2.0) * np.sinc((np.arange(64) - 32)[None] / 2.0)
    assert abs(x[31, 32]) == abs(x[32, 32])  # a plateau of two maxima
    assert find_point_targets(x, (2.0, 2.0)) == [(31, 32)]


def test_cuts_and_islr_region_cut_by_the_image_edge_are_noted(tmp_path):
    cfg = preset("tiny")
    rho_r, rho_a = cfg.waveform.range_resolution_m, cfg.azimuth_resolution_m(2000.0)
    az = np.arange(-160, 161) * 0.8 * rho_a
    rg = 1900.0 + np.arange(300) * 0.75 * rho_r
    pts = [(az[5] + 0.2 * rho_a, 2000.0, 1.0)]  # 4 cells from the first line
    path = tmp_path / "edge.h5"
    write_image(path, sinc_image(pts, rho_a, rho_r, az, rg), az, rg, cfg)
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--json", str(out)]) == 0
    (notes,) = json.loads(out.read_text())["notes"]
    assert any("azimuth cut ends at the image edge" in n for n in notes)
    assert any("ISLR region" in n and "image edge in azimuth" in n for n in notes)


def test_2d_islr_of_a_finely_sampled_azimuth_axis_upsamples_range(tmp_path):
    """~450 px per azimuth IRW beside ~1.2 px per range IRW: one shared factor fell to 1 and
    the range axis went un-upsampled (psaltis-max rect: -8.6 dB for -7.0)."""
    cfg = preset("tiny")
    rho_r, rho_a = cfg.waveform.range_resolution_m, cfg.azimuth_resolution_m(2000.0)
    d_az = rho_a / 500.0
    az = (np.arange(12001) - 6000) * d_az
    rg = 1900.0 + np.arange(64) * 0.75 * rho_r
    pts = [(0.3 * d_az, 1900.0 + 31.3 * 0.75 * rho_r, 1.0)]
    path = tmp_path / "fine.h5"
    write_image(path, sinc_image(pts, rho_a, rho_r, az, rg), az, rg, cfg)
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--json", str(out), "--at", f"0,{pts[0][1]}"]) == 0
    m, t = sinc_fractions(10.0)
    islr_2d = 10 * math.log10((t * t - m * m) / (m * m))  # -7.0 dB
    assert json.loads(out.read_text())["points"][0]["islr_db"] == pytest.approx(islr_2d, abs=0.15)


def test_an_edge_beyond_the_cuts_reach_is_not_noted(tmp_path):
    """A new user's review: `the range cut ends at the image edge 28.8 IRWs from the peak (of
    ±12)`: the chip's least size (±32 pixels) is more than ±12 IRWs of a coarsely sampled axis,
    and the note compared the edge with the chip, not with the cut's reach."""
    cfg = preset("tiny")
    rho_r, rho_a = cfg.waveform.range_resolution_m, cfg.azimuth_resolution_m(2000.0)
    az = np.arange(-160, 161) * 0.8 * rho_a
    rg = 1900.0 + np.arange(300) * 0.75 * rho_r  # an IRW about 1.3 pixels: ±12 IRWs ~ 16 px
    near_edge = rg[24]  # 24 pixels from the first column: ~19 IRWs, within the chip's 32
    path = tmp_path / "edge.h5"
    write_image(path, sinc_image([(0.0, near_edge, 1.0)], rho_a, rho_r, az, rg), az, rg, cfg)
    out = tmp_path / "m.json"
    assert main(["measure", str(path), "--json", str(out)]) == 0
    (notes,) = json.loads(out.read_text())["notes"]
    assert not any("range cut ends at the image edge" in n for n in notes), notes


def test_at_takes_a_negative_along_track_position_as_given(tmp_path):
    """A review: `--at -0.005,1.5012576` (the crouch-pga example's -26 dB point) failed with
    "expected at least one argument": argparse took the value for an option."""
    cfg = preset("tiny")
    rho_r, rho_a = cfg.waveform.range_resolution_m, cfg.azimuth_resolution_m(2000.0)
    az = np.arange(-160, 161) * 0.8 * rho_a
    rg = 1900.0 + np.arange(0, 400) * 0.75 * rho_r
    x0 = -20.3 * rho_a
    path, out = tmp_path / "neg.h5", tmp_path / "m.json"
    write_image(path, sinc_image([(x0, 2000.0, 1.0)], rho_a, rho_r, az, rg), az, rg, cfg)
    for at in ([f"{x0:.6g},2000"], [f"{x0:.6g},2000", f"{-x0:.6g},2000"]):
        assert main(["measure", str(path), "--json", str(out), "--at", *at]) == 0
        first = json.loads(out.read_text())["points"][0]
        assert first["along_track_m"] == pytest.approx(x0, abs=0.01 * rho_a)
    assert main(["measure", str(path), "--at", "-5"]) == 2  # still a position's error
