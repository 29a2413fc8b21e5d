"""Exports of spotlight recordings and the messages around exports (review 3, items 1-4): the
CPHD of a spotlight recording holds its arc (and the bistatic receiver as its own channel), so a
generic FX-domain processor focuses it; rtsar reads its CPHD/SigMF back into the same image;
process/replay/SICD say in one line what a spotlight file is; a strip-map CPHD export names the
auxiliary channels it leaves out, and a missing channel in a CPHD points to the .h5/SigMF."""

import json
import tarfile

import numpy as np
import pytest
from conftest import fmcw_scene_with_reference

sarkit_cphd = pytest.importorskip("sarkit.cphd")
pytest.importorskip("sigmf")
pytest.importorskip("sarpy")

from rtsar.app.cli import main  # noqa: E402
from rtsar.params import C_M_PER_S  # noqa: E402
from rtsar.sinks.image_file import read_image  # noqa: E402

R0_M, RB_M, STEP_M = 4.6, 4.0, 5e-4
TARGET_M = (0.4e-3, -0.3e-3, 0.0)  # off the scene centre: its phase depends on the geometry


SPOT_SCENE = f"""
preset = "crouch-spotlight"
[geometry]
along_track_step_m = {STEP_M}
antenna_length_m = 1e-3
[processor]
aperture_pulses = 8
[spotlight]
pulses = 161
bistatic_range_m = {RB_M}
bistatic_angle_deg = 8.0
[[targets]]
x_m = {TARGET_M[0]}
y_m = {TARGET_M[1]}
"""


@pytest.fixture(scope="module")
def spot(tmp_path_factory):
    """A noise-free spotlight recording (1°, 161 shots of 0.5 mm, one target off the centre,
    the bistatic receiver at 8°), exported to CPHD and SigMF."""
    d = tmp_path_factory.mktemp("spot")
    (d / "spot.toml").write_text(SPOT_SCENE)
    rec = d / "spot.h5"
    assert main(["spot-simulate", str(d / "spot.toml"), "-o", str(rec)]) == 0
    assert main(["export", str(rec), "--cphd", str(d / "spot.cphd")]) == 0
    assert main(["export", str(rec), "--sigmf", str(d / "sig")]) == 0
    return d


def _fx_channels(path):
    with open(path, "rb") as f, sarkit_cphd.Reader(f) as r:
        root = r.metadata.xmltree.getroot()
        ids = [c.findtext("{*}Identifier") for c in root.findall("./{*}Data/{*}Channel")]
        planar = root.find("./{*}SceneCoordinates/{*}ReferenceSurface/{*}Planar")
        axes = [
            np.array([float(planar.findtext(f"{{*}}{a}/{{*}}{c}")) for c in "XYZ"])
            for a in ("uIAX", "uIAY")
        ]
        iarp = np.array(
            [
                float(root.findtext(f"./{{*}}SceneCoordinates/{{*}}IARP/{{*}}ECF/{{*}}{c}"))
                for c in "XYZ"
            ]
        )
        return {i: (r.read_pvps(i), r.read_signal(i)) for i in ids}, iarp, axes


def _error_line(capsys) -> str:
    """The one ``rtsar: error:`` line on stderr (library warnings printed once per process
    may precede it)."""
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("rtsar: error:")]
    assert len(lines) == 1, lines
    return lines[0]


def _coherence(pvp, fx, point_ecf) -> float:
    """|Σ FX·e^{+i2π f (τ_p - τ_srp)}| / Σ|FX|: how well a generic CPHD processor (SGN = -1,
    delays from the PVPs' TxPos/RcvPos) focuses ``point_ecf``; 1 for a matched point target."""

    def delay(p):
        return (
            np.linalg.norm(pvp["TxPos"] - p, axis=-1) + np.linalg.norm(pvp["RcvPos"] - p, axis=-1)
        ) / C_M_PER_S

    dtau = delay(point_ecf) - delay(pvp["SRPPos"][0])
    f = pvp["SC0"][:, None] + pvp["SCSS"][:, None] * np.arange(fx.shape[1])[None, :]
    cycles = np.mod(f[:, :1] * dtau[:, None], 1.0) + np.mod(
        (f - f[:, :1]) * dtau[:, None], 1.0
    )  # float64, reduced before the exponential
    s = np.sum(fx.astype(np.complex128) * np.exp(2j * np.pi * np.mod(cycles, 1.0)))
    return float(abs(s) / np.sum(np.abs(fx)))


def test_spotlight_cphd_holds_the_arc_and_a_generic_processor_focuses_both_channels(spot):
    d = spot
    chans, iarp, (u_x, u_y) = _fx_channels(d / "spot.cphd")
    assert list(chans) == ["rtsar-main", "rtsar-bistatic"]  # the receiver is not dropped
    for ident, (pvp, fx) in chans.items():
        r_tx = np.linalg.norm(pvp["TxPos"] - pvp["SRPPos"], axis=-1)
        r_rcv = np.linalg.norm(pvp["RcvPos"] - pvp["SRPPos"], axis=-1)
        # The arc keeps R₀ at every vector (a straight track was 175 µm off at the ends).
        assert np.abs(r_tx - R0_M).max() < 1e-8, ident
        assert np.abs(r_rcv - (RB_M if ident == "rtsar-bistatic" else R0_M)).max() < 1e-8
        # The target on the image plane the file declares: IARP + x uIAX + y uIAY.
        target = iarp + TARGET_M[0] * u_x + TARGET_M[1] * u_y
        focused = _coherence(pvp, fx, target)
        beside = _coherence(pvp, fx, target + 60e-6 * u_x)  # ~1.5 cross-range cells away
        assert focused > 0.99 and beside < 0.5, (ident, focused, beside)


def test_rtsar_reads_its_spotlight_cphd_and_sigmf_back_into_the_same_image(spot):
    d = spot
    # A SigMF archive (an uncompressed tar, SigMF's layout NAME/NAME.sigmf-*) holding the
    # recording and its bistatic channel's recording.
    with tarfile.open(d / "arch.sigmf", "w") as tar:
        for name in ("sig", "sig.bistatic"):
            for suffix in (".sigmf-meta", ".sigmf-data"):
                tar.add(d / (name + suffix), arcname=f"sig/{name}{suffix}")
    for channel in ("main", "bistatic"):
        ref = d / f"ref-{channel}.h5"
        common = ["--channel", channel, "--extent-mm", "1.5", "1.5"]
        assert main(["spotlight", str(d / "spot.h5"), "-o", str(ref), *common]) == 0
        want = read_image(ref)[0]
        for src in ("spot.cphd", "sig.sigmf-meta", "sig", "arch.sigmf"):
            out = d / f"back-{channel}.h5"
            assert main(["spotlight", str(d / src), "-o", str(out), *common]) == 0
            got = read_image(out)[0]
            assert np.abs(got - want).max() <= 1e-5 * np.abs(want).max(), (channel, src)


def test_spotlight_sigmf_carries_the_station_on_its_arc_and_the_receiver(spot):
    d = spot
    meta = json.loads((d / "sig.sigmf-meta").read_text())
    got = np.array([a["rtsar:station_position_m"] for a in meta["annotations"]])
    n = np.arange(len(got))
    theta = (n - 0.5 * (len(n) - 1)) * STEP_M / R0_M  # rtsar.spot.geometry: θ_n, P_n
    want = -R0_M * np.stack([np.sin(theta), np.cos(theta), 0 * theta], -1)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    bi = json.loads((d / "sig.bistatic.sigmf-meta").read_text())["global"]
    b = np.radians(8.0)
    want_b = [-RB_M * np.sin(b), -RB_M * np.cos(b), 0.0]
    np.testing.assert_allclose(bi["rtsar:receiver_position_m"], want_b, rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["spot.h5", "spot.cphd", "sig.sigmf-meta"])
@pytest.mark.parametrize("command", ["process", "replay"])
def test_process_and_replay_of_a_spotlight_recording_say_what_it_is(spot, capsys, name, command):
    d = spot
    args = ["-o", str(d / "x.h5")] if command == "process" else ["--rate", "max"]
    assert main([command, str(d / name), *args]) == 2
    err = _error_line(capsys)
    assert "is a spotlight recording" in err, err
    assert "`rtsar spotlight " in err and "does not parse" not in err, err


def test_a_spotlight_cphd_without_its_scene_is_refused_in_one_line(spot, tmp_path, capsys):
    """Its arc cannot be imaged as a strip map: the file says it is a spotlight collection."""
    raw = (spot / "spot.cphd").read_bytes()
    (tmp_path / "x.cphd").write_bytes(raw.replace(b'name="rtsar:scene"', b'name="xtsar:scene"'))
    capsys.readouterr()
    assert main(["process", str(tmp_path / "x.cphd"), "-o", str(tmp_path / "x.h5")]) == 2
    err = _error_line(capsys)
    assert "RadarMode SPOTLIGHT" in err and err.count("x.cphd") == 1, err


def test_sicd_export_of_a_spotlight_image_is_refused_in_one_line(spot, capsys):
    d = spot
    img = d / "img.h5"
    assert main(["spotlight", str(d / "spot.h5"), "-o", str(img), "--extent-mm", "1", "1"]) == 0
    capsys.readouterr()
    assert main(["export", str(img), "--sicd", str(d / "img.nitf")]) == 2
    err = _error_line(capsys)
    assert "SICD export of spotlight images is not supported" in err, err
    assert not (d / "img.nitf").exists()


STRIP_WITH_CHANNEL = fmcw_scene_with_reference(64, 32, 128)


def test_strip_cphd_export_names_the_channels_it_leaves_out_and_process_points_to_them(
    tmp_path, capsys
):
    scene = tmp_path / "ri.toml"
    scene.write_text(STRIP_WITH_CHANNEL)
    rec, cphd = tmp_path / "ri.h5", tmp_path / "ri.cphd"
    assert main(["simulate", str(scene), "-o", str(rec)]) == 0
    capsys.readouterr()
    assert main(["export", str(rec), "--cphd", str(cphd)]) == 0
    err = capsys.readouterr().err
    assert "leaves out the auxiliary channel(s) reference_interferometer" in err, err
    assert f"{rec} keeps them" in err and "--sigmf" in err, err
    assert main(["process", str(cphd), "-o", str(tmp_path / "x.h5"), "--correct", "linearize"]) == 2
    err = _error_line(capsys)
    assert "reference_interferometer" in err, err
    assert "simulate the scene" not in err and ".h5 recording" in err and "--sigmf" in err, err
