"""What an export writes is true or refused, never silently wrong (issue 28, a cold review):
shots holding NaN/Inf are zeroed and said (the CPHD then passes sarkit's consistency checks:
before, 256 NaN samples and no message); shot times that step back are said by every reader and
refused by the CPHD export (sarpy: "TxTime is monotonic"), and SigMF captures whose times
contradict the shots' are refused; a strip map with fewer than two full-aperture lines gives
no CPHD (before: an image area of negative extent, "Polygon is clockwise")."""

import json
import re
import shutil

import h5py
import numpy as np
import pytest

sv = pytest.importorskip("sarkit.verification")
pytest.importorskip("sigmf")

from rtsar.app.cli import main  # noqa: E402

PULSES = 72


@pytest.fixture(scope="module")
def good(tiny_exports):
    """The sound files (conftest.tiny_exports)."""
    return tiny_exports


def _recording(good, tmp_path, change) -> str:
    out = tmp_path / "bad-rec.h5"
    shutil.copy(good / "rec.h5", out)
    with h5py.File(out, "r+") as f:
        change(f)
    return str(out)


def _nan_shot(f):
    shots = f["shots"][...]
    shots[9, 5] = np.nan
    f["shots"][...] = shots


def _time_back(f):
    t = f["time_s"][...]
    t[7] = t[3]
    f["time_s"][...] = t


def _block(raw: bytes, name: str) -> int:
    """A CPHD file header's ``NAME_BLOCK_BYTE_OFFSET``."""
    return int(re.search(rb"%s_BLOCK_BYTE_OFFSET := (\d+)" % name.encode(), raw).group(1))


def _cphd(good, tmp_path, change) -> str:
    raw = bytearray((good / "rec.cphd").read_bytes())
    change(raw)
    out = tmp_path / "bad.cphd"
    out.write_bytes(bytes(raw))
    return str(out)


def _cphd_nan_sample(raw):
    # the channel's NumSamples (the image grid's comes first)
    samples = int(re.search(rb"</NumVectors><NumSamples>(\d+)<", bytes(raw)).group(1))
    at = _block(raw, "SIGNAL") + 8 * (9 * samples + 5)  # vector 9, sample 5 (CF8)
    raw[at : at + 4] = np.array(np.nan, ">f4").tobytes()  # CPHD is big-endian


def _cphd_txtime_back(raw):
    size = int(re.search(rb"<NumBytesPVP>(\d+)<", bytes(raw)).group(1))
    pvp = _block(raw, "PVP")  # TxTime is each vector's first word
    raw[pvp + 7 * size : pvp + 7 * size + 8] = raw[pvp + 3 * size : pvp + 3 * size + 8]


def _consistency_failures(path) -> list:
    with open(path, "rb") as f:
        checker = sv.CphdConsistency.from_file(f, thorough=True)
        checker.check()
    return [
        (n, d["details"])
        for n, v in checker.failures().items()
        for d in v["details"]
        if not d["passed"]
    ]


def _warnings(err: str) -> list[str]:
    """rtsar's warnings (not the DeprecationWarnings sarpy's first import raises)."""
    lines = err.strip().splitlines()
    return [e for e in lines if e.startswith("rtsar: warning:") and "deprecated" not in e]


def _one_error(err: str, name: str) -> str:
    lines = [e for e in err.strip().splitlines() if "deprecated" not in e]
    assert len(lines) == 1 and lines[0].startswith("rtsar: error:") and name in lines[0], lines
    return lines[0]


# ---- NaN/Inf shots ------------------------------------------------------------------------------
@pytest.mark.parametrize("source", ["h5", "cphd"])
def test_an_export_zeroes_nan_shots_and_says_so(good, tmp_path, capsys, source):
    if source == "h5":
        path = _recording(good, tmp_path, _nan_shot)
    else:
        path = _cphd(good, tmp_path, _cphd_nan_sample)
    name = path.rsplit("/", 1)[1]
    outs = {"sigmf": ["--sigmf", str(tmp_path / "o")]}
    if source == "h5":
        outs["cphd"] = ["--cphd", str(tmp_path / "o.cphd")]
    for kind, argv in outs.items():
        capsys.readouterr()
        assert main(["export", path, *argv]) == 0
        said = _warnings(capsys.readouterr().err)
        assert len(said) == 1 and f"1 of {PULSES} shots of" in said[0] and name in said[0], said
        assert "NaN/Inf" in said[0]
        if kind == "sigmf":
            data = np.fromfile(tmp_path / "o.sigmf-data", "<c8").reshape(PULSES, -1)
            assert np.isfinite(data).all() and not data[9].any() and data[8].any()
        else:
            import sarkit.cphd as skcphd

            with open(tmp_path / "o.cphd", "rb") as f:
                signal, _ = skcphd.Reader(f).read_channel("rtsar-main")
            assert np.isfinite(signal).all() and not signal[9].any() and signal[8].any()
            assert _consistency_failures(tmp_path / "o.cphd") == []


# ---- shot times out of order --------------------------------------------------------------------
@pytest.mark.parametrize("source", ["h5", "cphd"])
def test_shot_times_that_step_back_are_said_and_refused_by_the_cphd_export(
    good, tmp_path, capsys, source
):
    if source == "h5":
        path, first = _recording(good, tmp_path, _time_back), 7
    else:
        path, first = _cphd(good, tmp_path, _cphd_txtime_back), 7
    name = path.rsplit("/", 1)[1]
    for argv in (
        ["process", path, "-o", str(tmp_path / "i.h5"), "--lens", "numpy"],
        ["export", path, "--sigmf", str(tmp_path / "o")],
    ):
        capsys.readouterr()
        assert main(argv) == 0
        said = _warnings(capsys.readouterr().err)
        assert len(said) == 1 and name in said[0] and f"first at shot {first}" in said[0], said
        assert f"at 1 of {PULSES - 1} steps" in said[0]
    capsys.readouterr()
    assert main(["export", path, "--cphd", str(tmp_path / "o.cphd")]) == 2
    line = _one_error(capsys.readouterr().err, name)
    assert f"shot {first}" in line and "CPHD" in line
    assert not (tmp_path / "o.cphd").exists()


def test_sigmf_captures_whose_times_contradict_the_shots_are_refused(good, tmp_path, capsys):
    for suffix in (".sigmf-meta", ".sigmf-data"):
        shutil.copy(good / ("sig" + suffix), tmp_path / ("bad" + suffix))
    meta = json.loads((tmp_path / "bad.sigmf-meta").read_text())
    meta["captures"][7]["core:datetime"] = meta["captures"][3]["core:datetime"]
    (tmp_path / "bad.sigmf-meta").write_text(json.dumps(meta))
    capsys.readouterr()
    argv = ["export", str(tmp_path / "bad.sigmf-meta"), "--cphd", str(tmp_path / "o.cphd")]
    assert main(argv) == 2
    line = _one_error(capsys.readouterr().err, "bad.sigmf-meta")
    assert "capture 7's core:datetime" in line


# ---- too short for an image area ----------------------------------------------------------------
@pytest.mark.parametrize("pulses", [20, 32])
def test_a_strip_map_without_two_full_aperture_lines_gives_no_cphd(good, tmp_path, capsys, pulses):
    rec = tmp_path / "short.h5"
    assert main(["simulate", str(good / "s.toml"), "--pulses", str(pulses), "-o", str(rec)]) == 0
    capsys.readouterr()
    assert main(["export", str(rec), "--cphd", str(tmp_path / "o.cphd")]) == 2
    assert "aperture of 32" in _one_error(capsys.readouterr().err, "short.h5")
    assert not (tmp_path / "o.cphd").exists()


def test_two_full_aperture_lines_give_a_valid_cphd(good, tmp_path):
    rec = tmp_path / "short.h5"
    assert main(["simulate", str(good / "s.toml"), "--pulses", "33", "-o", str(rec)]) == 0
    assert main(["export", str(rec), "--cphd", str(tmp_path / "o.cphd")]) == 0
    assert _consistency_failures(tmp_path / "o.cphd") == []
