"""Standard formats (issue 16): CPHD 1.0.1 and SigMF round trips, the FX phase reference, SICD
of an image, and the one-line error without the optional packages."""

import datetime
import json
import re

import numpy as np
import pytest
from conftest import fmcw_scene_with_reference, free_port

sarkit_cphd = pytest.importorskip("sarkit.cphd")
skver = pytest.importorskip("sarkit.verification")
sigmf = pytest.importorskip("sigmf")
pytest.importorskip("sarpy")

from sicd_checks import sarkit_errors  # noqa: E402

from rtsar.analysis.point_target import analyse_point_target  # noqa: E402
from rtsar.app.cli import main  # noqa: E402
from rtsar.params import C_M_PER_S  # noqa: E402
from rtsar.scene.model import scene_from_dict  # noqa: E402
from rtsar.scene.simulator import Simulator  # noqa: E402
from rtsar.sinks.image_file import read_image  # noqa: E402
from rtsar.sinks.io import open_recording  # noqa: E402
from rtsar.sources.formats.cphd_reader import open_cphd  # noqa: E402
from rtsar.sources.formats.phase_history import fx_mapping, fx_to_shots, shots_to_fx  # noqa: E402
from rtsar.sources.formats.sigmf_reader import open_sigmf  # noqa: E402
from rtsar.sources.formats.timebase import parse_utc  # noqa: E402

PULSED = """
preset = "tiny"
seed = 1
pulses = 120
start_along_track_m = -20.0
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
[[targets]]
along_track_m = 6.0
slant_range_m = 2031.3
amplitude = 0.7
[[effects]]
name = "noise"
snr_db = 10.0
"""

FMCW = fmcw_scene_with_reference(80, 32, 128)


def _recording(tmp_path, text, name):
    scene = tmp_path / f"{name}.toml"
    scene.write_text(text)
    rec = tmp_path / f"{name}.h5"
    assert main(["simulate", str(scene), "-o", str(rec)]) == 0
    return rec


@pytest.fixture(scope="module")
def pulsed(tmp_path_factory):
    return _recording(tmp_path_factory.mktemp("pulsed"), PULSED, "pulsed")


def test_cphd_round_trip_consistent_and_same_image(pulsed, tmp_path):
    out = tmp_path / "rec.cphd"
    assert main(["export", str(pulsed), "--cphd", str(out)]) == 0
    with open(out, "rb") as f:  # NGA's consistency checks (sarkit), reading the whole file
        con = skver.CphdConsistency.from_file(f, thorough=True)
        con.check()
        assert con.passes() and not con.failures(), con.failures()
    from sarpy.io.phase_history.converter import open_phase_history

    reader = open_phase_history(str(out))  # an independent reader opens it
    with open(out, "rb") as f, sarkit_cphd.Reader(f) as sk:
        np.testing.assert_array_equal(reader[:, :], sk.read_signal("rtsar-main"))
        pvp = sk.read_pvps("rtsar-main")
    # The SRP follows the track (a strip map): abeam of the platform at every vector, on the
    # centre line (the processor's range centre), so each vector's SRP range is R_c.
    srp, tx, vel = pvp["SRPPos"], pvp["TxPos"], pvp["TxVel"]
    along = np.sum((srp - tx) * vel, axis=-1) / np.linalg.norm(vel, axis=-1)
    assert np.abs(along).max() < 1e-6
    np.testing.assert_allclose(np.linalg.norm(srp - tx, axis=-1), 2000.0, rtol=1e-12)
    assert np.linalg.norm(srp[-1] - srp[0]) == pytest.approx(119 * 0.5, rel=1e-9)
    with open_recording(pulsed) as rec:
        with open_cphd(out) as back:
            assert back.pulses == rec.pulses and back.start_along_track_m == rec.start_along_track_m
            np.testing.assert_array_equal(back.pulse_index, rec.pulse_index)
            np.testing.assert_array_equal(back.time_s, rec.time_s)
            shots = rec.shots[...]
            err = np.abs(back.shots[0 : rec.pulses] - shots).max() / np.abs(shots).max()
            assert err < 1e-6
    img_h5, img_cphd = tmp_path / "a.h5", tmp_path / "b.h5"
    assert main(["process", str(pulsed), "-o", str(img_h5), "--lens", "numpy"]) == 0
    assert main(["process", str(out), "-o", str(img_cphd), "--lens", "numpy"]) == 0
    a, az_a, rg_a, _ = read_image(img_h5)
    b, az_b, rg_b, _ = read_image(img_cphd)
    np.testing.assert_array_equal(az_a, az_b)
    np.testing.assert_array_equal(rg_a, rg_b)
    assert np.abs(a - b).max() / np.abs(a).max() <= 1e-5


@pytest.mark.parametrize("preset", ["tiny", "crouch-sal"])
def test_fx_vector_is_phase_history_referenced_to_the_srp(preset):
    """A lone scatterer Δτ beyond the SRP gives FX phase -2π f Δτ over the band (SGN = -1;
    FMCW: plus its residual video phase πKΔτ², Crouch eq. 3.4), against a float64 reference;
    the inverse gives the shot back."""
    cfg = scene_from_dict({"preset": preset, "targets": []}).config
    m = fx_mapping(cfg)
    r_target = m.srp_range_m + 7.3 * cfg.waveform.range_resolution_m
    d = {"preset": preset, "pulses": 1, "targets": [{"along_track_m": 0.0, "slant_range_m": 1.0}]}
    d["targets"][0]["slant_range_m"] = r_target
    shot = Simulator(scene_from_dict(d)).echo(np.array([r_target]), np.array([1.0 + 0j]))
    fx = shots_to_fx(m, shot[None, :])[0].astype(np.complex128)
    f = m.frequency_hz
    width = m.fx2_hz - m.fx1_hz
    band = (f >= m.fx1_hz + 0.1 * width) & (f <= m.fx2_hz - 0.1 * width)
    dtau = 2.0 * (r_target - m.srp_range_m) / C_M_PER_S
    expected = np.exp(-2j * np.pi * np.mod(f[band] * dtau, 1.0))
    residual = np.unwrap(np.angle(fx[band] * np.conj(expected)))
    rvp = 0.0 if m.pulsed else np.pi * cfg.waveform.chirp_rate_hz_per_s * dtau**2
    # Flat: the phase slope over frequency is -2πΔτ (one sample of delay off would tilt it by
    # ~4 rad over the band); what is left is the chirp spectrum's Fresnel ripple of a
    # fractionally delayed echo (±0.1 rad).
    assert np.ptp(residual) < 0.3 and np.std(residual) < 0.06
    assert abs(np.angle(np.exp(1j * (np.mean(residual) - rvp)))) < 0.05
    back = fx_to_shots(m, fx[None, :])
    assert np.abs(back - shot).max() < 1e-5 * np.abs(shot).max()


def test_sigmf_round_trip_bit_identical_with_channels(tmp_path):
    rec_path = _recording(tmp_path, FMCW, "fmcw")
    base = tmp_path / "out"
    assert main(["export", str(rec_path), "--sigmf", str(base)]) == 0
    meta = json.loads((tmp_path / "out.sigmf-meta").read_text())
    handle = sigmf.sigmffile.fromfile(str(tmp_path / "out.sigmf-meta"))
    handle.validate()  # the SigMF schema
    assert meta["global"]["rtsar:prf_hz"] > 0
    assert {"rtsar:pulse_index", "rtsar:time_s"} <= set(meta["annotations"][0])
    with open_recording(rec_path) as rec, open_sigmf(tmp_path / "out.sigmf-meta") as back:
        # One capture per receive window (shot), each dated: the collection start + its time.
        captures = handle.get_captures()
        s = rec.config.waveform.samples_per_shot
        assert [c["core:sample_start"] for c in captures] == [p * s for p in range(rec.pulses)]
        dated = [parse_utc(c["core:datetime"]) for c in captures]
        assert [(d - dated[0]).total_seconds() for d in dated] == pytest.approx(
            rec.time_s - rec.time_s[0], abs=1e-6
        )
        assert dated[0] == rec.collection_start + datetime.timedelta(seconds=rec.time_s[0])
        assert back.collection_start == rec.collection_start
        assert back.config == rec.config
        np.testing.assert_array_equal(back.shots[...], rec.shots[...])
        np.testing.assert_array_equal(back.pulse_index, rec.pulse_index)
        np.testing.assert_array_equal(back.time_s, rec.time_s)
        assert set(back.channels) == set(rec.channels) == {"reference_interferometer"}
        for name, ds in rec.channels.items():
            np.testing.assert_array_equal(back.channels[name], ds[...])
    a, b = tmp_path / "a.h5", tmp_path / "b.h5"
    assert main(["process", str(rec_path), "-o", str(a), "--lens", "numpy"]) == 0
    assert main(["process", str(base) + ".sigmf-meta", "-o", str(b), "--lens", "numpy"]) == 0
    np.testing.assert_array_equal(read_image(a)[0], read_image(b)[0])
    # From a cold review: a SigMF recording exported onto itself was truncated to 0 bytes (its
    # channel files too). Files are now renamed into place when complete: the same bytes.
    before = {f.name: f.read_bytes() for f in sorted(tmp_path.glob("out*.sigmf-data"))}
    assert len(before) == 2  # the shots and the reference interferometer's channel
    assert main(["export", str(base) + ".sigmf-meta", "--sigmf", str(base)]) == 0
    assert {f.name: f.read_bytes() for f in sorted(tmp_path.glob("out*.sigmf-data"))} == before
    assert not list(tmp_path.glob(".*partial*"))


@pytest.mark.parametrize("kind", ["cphd", "sigmf", "sicd"])
def test_an_export_that_dies_leaves_the_old_file_and_no_partial_one(
    pulsed, tmp_path, kind, monkeypatch, capsys
):
    """A run that dies in the middle of writing (here: the writer raises) leaves whatever was at
    the destination as it was, and nothing half-written under any name."""
    from rtsar.sinks.exports import cphd, sicd, sigmf_export

    if kind == "sicd":
        src = tmp_path / "img.h5"
        assert main(["process", str(pulsed), "-o", str(src), "--lens", "numpy"]) == 0
        dest, args = tmp_path / "old.nitf", ["--sicd"]
        monkeypatch.setattr(sicd.sksicd.NitfWriter, "write_image", _boom)
    else:
        src = pulsed
        dest = tmp_path / ("old.cphd" if kind == "cphd" else "old.sigmf-data")
        args = [f"--{kind}"]
        if kind == "cphd":
            monkeypatch.setattr(cphd.skcphd.Writer, "write_pvp", _boom)
        else:
            monkeypatch.setattr(sigmf_export.SigMFFile, "dump", _boom)
    dest.write_bytes(b"the user's earlier file")
    out = dest if kind != "sigmf" else tmp_path / "old"
    assert main(["export", str(src), *args, str(out)]) != 0
    assert "the writer died" in capsys.readouterr().err
    assert dest.read_bytes() == b"the user's earlier file"
    assert not list(tmp_path.glob(".*partial*"))


def _boom(*args, **kwargs):
    raise RuntimeError("the writer died")


def test_sicd_of_an_image_opens_in_sarpy(pulsed, tmp_path, capsys):
    img, out = tmp_path / "img.h5", tmp_path / "img.nitf"
    assert main(["process", str(pulsed), "-o", str(img), "--lens", "numpy"]) == 0
    capsys.readouterr()
    assert main(["export", str(img), "--sicd", str(out)]) == 0
    # The version said is the one the file declares (it said "(1, 1, 0)", the file 1.3.0).
    declared = re.search(rb"urn:SICD:([0-9.]+)", out.read_bytes()).group(1).decode()
    assert f"SICD {declared}," in capsys.readouterr().out
    from sarpy.io.complex.converter import open_complex

    reader = open_complex(str(out))
    sicd = reader.get_sicds_as_tuple()[0]
    image, az, rg, _ = read_image(img)
    np.testing.assert_array_equal(reader[:, :], image.T)  # rows range, columns along track
    assert sicd.Grid.Row.SS == pytest.approx(rg[1] - rg[0], rel=1e-12)
    assert sicd.Grid.Col.SS == pytest.approx(az[1] - az[0], rel=1e-12)
    assert sicd.SCPCOA.SideOfTrack == "R"
    assert sicd.Grid.Row.ImpRespBW == pytest.approx(2 * 40e6 / C_M_PER_S)
    passes, errors = sarkit_errors(out)  # NGA's SICD consistency checks (sarkit): no error
    assert passes and not errors, errors


def test_missing_packages_named_in_one_line(pulsed, tmp_path, monkeypatch, capsys):
    import rtsar.sinks.exports.cphd as cphd

    monkeypatch.setattr(cphd, "skcphd", None)
    assert main(["export", str(pulsed), "--cphd", str(tmp_path / "x.cphd")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'pip install "rtsar[formats]"' in err[0]


def test_cphd_from_elsewhere_is_focused_from_its_own_geometry(pulsed, tmp_path):
    """Without rtsar:config, the configuration comes from the PVPs (an FMCW-style range
    compression of the phase history, square resolution): the targets are where the scene put
    them, within a tenth of a cell."""
    out = tmp_path / "rec.cphd"
    assert main(["export", str(pulsed), "--cphd", str(out)]) == 0
    raw = out.read_bytes()
    for name in (b"rtsar:config", b"rtsar:scene", b"rtsar:start_along_track_m"):
        raw = raw.replace(b'name="' + name + b'"', b'name="x' + name[1:] + b'"')
    other = tmp_path / "other.cphd"
    other.write_bytes(raw)
    img = tmp_path / "other.h5"
    assert main(["process", str(other), "-o", str(img), "--lens", "numpy"]) == 0
    image, az, rg, _ = read_image(img)
    with open_recording(pulsed) as rec:  # x = 0 lies abeam of the middle vector's SRP
        d = rec.config.geometry.along_track_step_m
        x_c = rec.start_along_track_m + (rec.pulses // 2) * d
    for x0, r0 in ((0.0, 2000.0), (6.0, 2031.3)):
        rep = analyse_point_target(image, az, rg, x0 - x_c, r0, (4.0, 10.0), chip=16)
        assert abs(rep.azimuth_m - (x0 - x_c)) < 0.1 * (az[1] - az[0])
        assert abs(rep.range_m - r0) < 0.1 * (rg[1] - rg[0])


def test_cphd_outside_rtsar_geometry_refused():
    from rtsar.sources.formats.cphd_geometry import derived_config

    n = 64
    dtype = [(k, "f8", (3,)) for k in ("TxPos", "RcvPos", "SRPPos")]
    dtype += [(k, "f8") for k in ("TxTime", "SC0", "SCSS", "TOA1", "TOA2")]
    pvp = np.zeros(n, dtype)
    x = np.arange(n) * 0.5
    pvp["TxPos"] = np.stack([x, 0 * x, 6378137.0 + 1000.0 + 0.05 * (x / 10) ** 2], axis=-1)
    pvp["RcvPos"] = pvp["TxPos"]
    pvp["SRPPos"] = [16.0, 1700.0, 6378137.0]
    pvp["TxTime"], pvp["SC0"], pvp["SCSS"] = x / 250.0, 1.25e9, 1e5
    pvp["TOA1"], pvp["TOA2"] = -1e-6, 1e-6
    with pytest.raises(ValueError, match="straight"):
        derived_config(pvp, 256)
    pvp["SC0"][3] += 1e6
    with pytest.raises(ValueError, match="fixed sampling"):
        derived_config(pvp, 256)


def test_replay_of_cphd_into_subscribe_sicd(pulsed, tmp_path):
    """`replay` takes the CPHD through the live pipeline; `subscribe --sicd` writes the streamed
    image as SICD at the end of the stream: the same pixels as the recording's `process`."""
    import threading

    from sarpy.io.complex.converter import open_complex

    cphd, batch = tmp_path / "rec.cphd", tmp_path / "batch.h5"
    assert main(["export", str(pulsed), "--cphd", str(cphd)]) == 0
    assert main(["process", str(pulsed), "-o", str(batch), "--lens", "numpy"]) == 0
    ep = f"tcp://127.0.0.1:{free_port()}"  # outside the ephemeral range (conftest)
    sub_h5, sub_sicd, codes = tmp_path / "sub.h5", tmp_path / "sub.nitf", []
    args = ["subscribe", ep, "-o", str(sub_h5), "--sicd", str(sub_sicd), "--timeout", "30"]
    sub = threading.Thread(target=lambda: codes.append(main(args)))
    sub.start()
    replay = ["replay", str(cphd), "--rate", "max", "--endpoint", ep, "--wait-subscribers", "1"]
    assert main(replay + ["--lens", "numpy"]) == 0
    sub.join(60)
    assert codes == [0]
    want = read_image(batch)[0]
    got = read_image(sub_h5)[0]
    assert np.abs(got - want).max() <= 1e-5 * np.abs(want).max()
    np.testing.assert_array_equal(open_complex(str(sub_sicd))[:, :], got.T)


def test_subscribe_sicd_never_exports_a_stale_image(pulsed, tmp_path):
    """From a cold review: with no strip received, an image file left by an earlier run was
    exported as this stream's SICD."""

    stale, sicd = tmp_path / "stale.h5", tmp_path / "stale.nitf"
    assert main(["process", str(pulsed), "-o", str(stale), "--lens", "numpy"]) == 0
    ep = f"tcp://127.0.0.1:{free_port()}"  # outside the ephemeral range (conftest)
    args = ["subscribe", ep, "-o", str(stale), "--sicd", str(sicd), "--timeout", "0.5"]
    assert main(args) == 1  # nothing received
    assert not sicd.exists()


def test_a_cut_short_cphd_is_refused_at_once_by_name(pulsed, tmp_path, capsys):
    """From a cold review: a truncated CPHD failed after processing had started with "Expected
    nbytes_requested=32768; only read 9376", naming no file.  Its size is checked against the
    blocks its header places, before any work, wherever the cut falls."""
    whole = tmp_path / "whole.cphd"
    assert main(["export", str(pulsed), "--cphd", str(whole)]) == 0
    data = whole.read_bytes()
    for keep in (5000, len(data) // 2, len(data) - 1):
        cut = tmp_path / f"cut{keep}.cphd"
        cut.write_bytes(data[:keep])
        capsys.readouterr()
        assert main(["process", str(cut), "-o", str(tmp_path / "x.h5"), "--lens", "numpy"]) == 2
        err = capsys.readouterr().err
        assert str(cut) in err and "cut short" in err and f"holds {keep} bytes" in err
