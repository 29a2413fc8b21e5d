"""The fields a SAR user reads in rtsar's files, each read back by rtsar and by the reference
library (issue 28): the collection start (recording → CPHD CollectionStart, SigMF core:datetime,
image → SICD CollectStart), CPHD TxRcv (the chirp and the receiver), and SigMF archives read by
process, replay and batch."""

import tarfile

import lxml.etree as etree
import numpy as np
import pytest

sarkit_cphd = pytest.importorskip("sarkit.cphd")
sksicd = pytest.importorskip("sarkit.sicd")
sigmf = pytest.importorskip("sigmf")
pytest.importorskip("sarpy")

from rtsar.app.cli import main  # noqa: E402
from rtsar.sinks.image_file import read_image  # noqa: E402
from rtsar.sinks.io import open_recording  # noqa: E402
from rtsar.sources.formats.cphd_reader import open_cphd  # noqa: E402
from rtsar.sources.formats.timebase import parse_utc  # noqa: E402

SCENE = """
preset = "tiny"
pulses = 100
start_along_track_m = -15.0
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
"""


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """A recording, its image (process) and its CPHD and SigMF exports."""
    d = tmp_path_factory.mktemp("fields")
    (d / "s.toml").write_text(SCENE)
    assert main(["simulate", str(d / "s.toml"), "-o", str(d / "rec.h5")]) == 0
    assert main(["process", str(d / "rec.h5"), "-o", str(d / "img.h5"), "--lens", "numpy"]) == 0
    assert main(["export", str(d / "rec.h5"), "--cphd", str(d / "rec.cphd")]) == 0
    assert main(["export", str(d / "rec.h5"), "--sigmf", str(d / "sig")]) == 0
    return d


def _start(d):
    with open_recording(d / "rec.h5") as rec:
        return rec.collection_start, rec.config


def test_the_collection_start_travels_to_cphd_and_sicd(made, tmp_path):
    start, _ = _start(made)
    assert start is not None  # simulate keeps when the recording began
    with open(made / "rec.cphd", "rb") as f, sarkit_cphd.Reader(f) as r:
        declared = r.metadata.xmltree.findtext("{*}Global/{*}Timeline/{*}CollectionStart")
    assert parse_utc(declared) == start  # sarkit's file: the recording's time, to the µs
    with open_cphd(made / "rec.cphd") as back:
        assert back.collection_start == start
    assert read_image(made / "img.h5")[3]["collection_start_utc"]
    assert main(["export", str(made / "img.h5"), "--sicd", str(tmp_path / "i.nitf")]) == 0
    with open(tmp_path / "i.nitf", "rb") as f, sksicd.NitfReader(f) as r:
        collect = r.metadata.xmltree.findtext("{*}Timeline/{*}CollectStart")
    assert parse_utc(collect) == start
    # A CPHD made again from the CPHD keeps it (the reader hands it on).
    assert main(["export", str(made / "rec.cphd"), "--cphd", str(tmp_path / "again.cphd")]) == 0
    with open_cphd(tmp_path / "again.cphd") as again:
        assert again.collection_start == start


def test_cphd_txrcv_declares_the_chirp_and_the_receiver(made, tmp_path, capsys):
    _, cfg = _start(made)
    wf = cfg.waveform
    with open(made / "rec.cphd", "rb") as f, sarkit_cphd.Reader(f) as r:
        x = sarkit_cphd.XmlHelper(r.metadata.xmltree)
        root = r.metadata.xmltree.getroot()
    tx, rcv = "{*}TxRcv/{*}TxWFParameters/{*}", "{*}TxRcv/{*}RcvParameters/{*}"
    assert x.load(tx + "PulseLength") == pytest.approx(wf.pulse_duration_s, rel=1e-12)
    assert x.load(tx + "RFBandwidth") == pytest.approx(wf.bandwidth_hz, rel=1e-12)
    assert x.load(tx + "LFMRate") == pytest.approx(wf.chirp_rate_hz_per_s, rel=1e-12)
    assert x.load(tx + "FreqCenter") == pytest.approx(cfg.geometry.carrier_hz, rel=1e-12)
    assert x.load(rcv + "SampleRate") == pytest.approx(wf.sample_rate_hz, rel=1e-12)
    assert x.load(rcv + "WindowLength") == pytest.approx(wf.receive_window_s, rel=1e-12)
    assert root.find(rcv + "LFMRate") is None  # a fixed-LO receiver: no stretch rate
    ids = root.find("{*}Channel/{*}Parameters/{*}TxRcv")
    assert [e.text for e in ids] == [x.load(tx + "Identifier"), x.load(rcv + "Identifier")]
    # rtsar checks what the file declares against its configuration: an edited one is refused.
    raw = (made / "rec.cphd").read_bytes()
    old = etree.tostring(root.find(tx + "PulseLength")).split(b">")[1].split(b"<")[0]
    edited = tmp_path / "edited.cphd"
    edited.write_bytes(
        raw.replace(b">" + old + b"</PulseLength", b">" + b"9" * len(old) + b"</PulseLength", 1)
    )
    capsys.readouterr()
    assert main(["process", str(edited), "-o", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "TxRcv PulseLength" in err[0] and "rtsar:config" in err[0]


def test_a_sigmf_archive_is_read_by_process_replay_and_batch(made, tmp_path, capsys):
    """The archive the sigmf package writes (an uncompressed tar): the same image as the .h5."""
    handle = sigmf.sigmffile.fromfile(str(made / "sig.sigmf-meta"))
    archive = tmp_path / "rec.sigmf"
    handle.archive(str(archive))
    with tarfile.open(archive) as t:  # (the layout: NAME/NAME.sigmf-meta, NAME/NAME.sigmf-data)
        assert sorted(m.name for m in t.getmembers() if m.isfile()) == [
            "rec/rec.sigmf-data",
            "rec/rec.sigmf-meta",
        ]
    want = read_image(made / "img.h5")
    a = tmp_path / "a.h5"
    assert main(["process", str(archive), "-o", str(a), "--lens", "numpy"]) == 0
    np.testing.assert_array_equal(read_image(a)[0], want[0])
    assert read_image(a)[3]["collection_start_utc"] == want[3]["collection_start_utc"]
    b = tmp_path / "b.h5"
    replay = ["replay", str(archive), "--rate", "max", "--lens", "numpy", "-o", str(b)]
    assert main([*replay, "--endpoint", "ipc://" + str(tmp_path / "pub")]) == 0
    assert np.abs(read_image(b)[0] - want[0]).max() <= 1e-5 * np.abs(want[0]).max()
    folder, out = tmp_path / "in", tmp_path / "out"
    folder.mkdir()
    archive.rename(folder / "rec.sigmf")
    batch = ["batch", str(folder), "--out-dir", str(out), "--workers", "1", "--lens", "numpy"]
    assert main(batch) == 0
    np.testing.assert_array_equal(read_image(out / "rec-img.h5")[0], want[0])
    # A compressed archive is named for what it is, in one line.
    (tmp_path / "z.sigmf.gz").write_bytes(b"\x1f\x8b not really")
    capsys.readouterr()
    assert main(["process", str(tmp_path / "z.sigmf.gz"), "-o", str(tmp_path / "z.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "compressed SigMF archive" in err[0]
