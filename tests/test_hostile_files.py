"""Every reader refuses a bad file in one line, exit 2, never a traceback (issue 28).

The files a hostile-input campaign found (a CPHD of integer samples, images missing or
mismatching an axis, 1-D, integer or NaN images, SigMF metadata that contradicts itself, a
spotlight SigMF without its geometry), each through the commands that read it; then a fuzz:
deterministic structural corruptions of a recording, an image, a CPHD and a SigMF recording,
each given to the command that reads it, which must end with 0 or a one-line error (2) and
nothing else.
"""

import json
import shutil

import h5py
import numpy as np
import pytest

pytest.importorskip("sarkit.cphd")
pytest.importorskip("sigmf")
pytest.importorskip("sarpy")

from rtsar.app.cli import main  # noqa: E402


@pytest.fixture(scope="module")
def good(tiny_exports):
    """The sound files (conftest.tiny_exports)."""
    return tiny_exports


def _one_line_error(capsys, name) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    err = [e for e in err if not e.startswith("rtsar: warning:")]
    assert len(err) == 1 and err[0].startswith("rtsar: error:"), err
    assert "Traceback" not in err[0] and name in err[0], err
    return err[0]


# ---- the files the campaign found ---------------------------------------------------------------
def _image(good, tmp_path, change) -> str:
    out = tmp_path / "bad-img.h5"
    shutil.copy(good / "img.h5", out)
    with h5py.File(out, "r+") as f:
        change(f)
    return str(out)


def _replace(f, name, data):
    del f[name]
    f.create_dataset(name, data=data)


IMAGES = {
    "no range_m": lambda f: f.__delitem__("range_m"),
    "range_m too short": lambda f: _replace(f, "range_m", f["range_m"][:-3]),
    "1-D image": lambda f: _replace(f, "image", f["image"][0]),
    "int8 image": lambda f: _replace(f, "image", np.zeros(f["image"].shape, np.int8)),
    "all-NaN image": lambda f: _replace(
        f, "image", np.full(f["image"].shape, np.nan, np.complex64)
    ),
    "azimuth_m backwards": lambda f: _replace(f, "azimuth_m", f["azimuth_m"][...][::-1]),
}


def _huge_rate(f):  # a configuration whose shot size overflows an int (1e308 × 1e308)
    cfg = json.loads(f.attrs["config"])
    cfg["waveform"].update(sample_rate_hz=1e308, receive_window_s=1e308)
    f.attrs["config"] = json.dumps(cfg)


# (quicklook draws pixels and axes alone: an image whose configuration is damaged still draws
# right; the SICD export, which describes the collection from it, refuses it.)
IMAGE_CASES = [(c, cmd) for c in sorted(IMAGES) for cmd in ("quicklook", "sicd")]
IMAGE_CASES.append(("config overflowing", "sicd"))
IMAGES["config overflowing"] = _huge_rate


@pytest.mark.parametrize(("case", "command"), IMAGE_CASES)
def test_a_bad_image_is_refused_in_one_line(good, tmp_path, capsys, case, command):
    path = _image(good, tmp_path, IMAGES[case])
    capsys.readouterr()
    if command == "quicklook":
        argv = ["quicklook", path, "-o", str(tmp_path / "q.png")]
    else:
        argv = ["export", path, "--sicd", str(tmp_path / "i.nitf")]
    assert main(argv) == 2
    _one_line_error(capsys, "bad-img.h5")


def _sigmf(good, tmp_path, change) -> str:
    for suffix in (".sigmf-meta", ".sigmf-data"):
        shutil.copy(good / ("sig" + suffix), tmp_path / ("bad" + suffix))
    meta = json.loads((tmp_path / "bad.sigmf-meta").read_text())
    change(meta)
    (tmp_path / "bad.sigmf-meta").write_text(json.dumps(meta))
    return str(tmp_path / "bad.sigmf-meta")


def _stations(meta):  # a spotlight export's per-shot stations, its geometry gone
    for a in meta["annotations"]:
        a["rtsar:station_position_m"] = [0.0, -4.6, 0.0]


SIGMF = {
    "prf -1": (lambda m: m["global"].update({"rtsar:prf_hz": -1}), "rtsar:prf_hz"),
    "sample rate NaN": (
        lambda m: m["global"].update({"core:sample_rate": float("nan")}),
        "core:sample_rate",
    ),
    "sample rate text": (lambda m: m["global"].update({"core:sample_rate": "NaN"}), "SigMF"),
    "no capture": (lambda m: m.update({"captures": []}), "capture"),
    "no annotation": (lambda m: m.update({"annotations": []}), "annotation"),
    "a capture inside a shot": (
        lambda m: m["captures"][1].update({"core:sample_start": 7}),
        "capture",
    ),
    "time NaN": (lambda m: m["annotations"][3].update({"rtsar:time_s": float("nan")}), "time"),
    "spotlight without its scene": (_stations, "spotlight"),
    "chirp of another rate": (
        lambda m: m["global"]["rtsar:chirp"].update({"rate_hz_per_s": 1.0}),
        "rtsar:chirp",
    ),
    # (a cold review: accepted with exit 0, or refused without naming the key)
    "a shot annotation of the wrong length": (
        lambda m: m["annotations"][4].update({"core:sample_count": 5}),
        "shot 4's annotation has core:sample_count 5",
    ),
    "a time that is text": (
        lambda m: m["annotations"][4].update({"rtsar:time_s": "x"}),
        "shot 4's rtsar:time_s 'x'",
    ),
    "captures an object": (lambda m: m.update({"captures": {}}), "'captures' is a dict"),
    "a capture that is a list": (
        lambda m: m["captures"].__setitem__(2, [0]),
        "captures[2] is a list",
    ),
    "a datetime that is no time": (
        lambda m: m["captures"][3].update({"core:datetime": "not a time"}),
        "at ['captures'][3]['core:datetime']: 'not a time' is not of the form",
    ),
}


def test_a_recording_whose_configuration_overflows_is_refused(good, tmp_path, capsys):
    rec = tmp_path / "bad-rec.h5"
    shutil.copy(good / "rec.h5", rec)
    with h5py.File(rec, "r+") as f:
        _huge_rate(f)
    capsys.readouterr()
    assert main(["process", str(rec), "-o", str(tmp_path / "x.h5")]) == 2
    assert "samples per shot" in _one_line_error(capsys, "bad-rec.h5")


@pytest.mark.parametrize("case", sorted(SIGMF))
def test_sigmf_metadata_that_contradicts_itself_is_refused(good, tmp_path, capsys, case):
    change, said = SIGMF[case]
    path = _sigmf(good, tmp_path, change)
    capsys.readouterr()
    assert main(["process", path, "-o", str(tmp_path / "x.h5")]) == 2
    assert said in _one_line_error(capsys, "bad.sigmf-meta")


@pytest.mark.parametrize("command", ["process", "replay", "export"])
def test_a_cphd_of_integer_samples_is_refused(good, tmp_path, capsys, command):
    raw = (good / "rec.cphd").read_bytes()
    assert raw.count(b"<SignalArrayFormat>CF8<") == 1
    bad = tmp_path / "ci4.cphd"  # CI4 is 8 bytes a sample too: the file stays consistent
    bad.write_bytes(raw.replace(b"<SignalArrayFormat>CF8<", b"<SignalArrayFormat>CI4<"))
    capsys.readouterr()
    argv = {
        "process": ["process", str(bad), "-o", str(tmp_path / "x.h5")],
        "replay": [
            "replay",
            str(bad),
            "--rate",
            "max",
            "--endpoint",
            "ipc://" + str(tmp_path / "p"),
        ],
        "export": ["export", str(bad), "--sigmf", str(tmp_path / "o")],
    }[command]
    assert main(argv) == 2
    assert "CI4" in _one_line_error(capsys, "ci4.cphd")


def _cphd_edit(good, tmp_path, old: bytes, new: bytes) -> str:
    raw = (good / "rec.cphd").read_bytes()
    assert raw.count(old) == 1 and len(old) == len(new)  # the header's offsets stay true
    bad = tmp_path / "edited.cphd"
    bad.write_bytes(raw.replace(old, new))
    return str(bad)


@pytest.mark.parametrize(
    ("old", "new", "said"),
    [
        (b"<FxBW>40000000.0<", b"<FxBW>90000000.0<", "Channel FxBW 90000000.0 Hz contradicts"),
        (b"<ModeType>STRIPMAP<", b"<ModeType>DYNAMIC <", "ModeType DYNAMIC"),
    ],
)
@pytest.mark.parametrize("command", ["process", "export"])
def test_a_cphd_that_contradicts_what_rtsar_processes_is_refused(
    good, tmp_path, capsys, old, new, said, command
):
    bad = _cphd_edit(good, tmp_path, old, new)
    capsys.readouterr()
    if command == "process":
        argv = ["process", bad, "-o", str(tmp_path / "x.h5"), "--lens", "numpy"]
    else:
        argv = ["export", bad, "--sigmf", str(tmp_path / "o")]
    assert main(argv) == 2
    assert said in _one_line_error(capsys, "edited.cphd")


def test_a_cphd_track_off_the_configuration_is_said_with_its_figure(good, tmp_path, capsys):
    import re

    raw = bytearray((good / "rec.cphd").read_bytes())
    size = int(re.search(rb"<NumBytesPVP>(\d+)<", bytes(raw)).group(1))
    pvp = int(re.search(rb"PVP_BLOCK_BYTE_OFFSET := (\d+)", bytes(raw)).group(1))
    for v in range(72):  # TxPos X (ECF; up, at the origin 0,0): ±50 m, across the track
        at = pvp + v * size + 8  # after TxTime
        x = np.frombuffer(bytes(raw[at : at + 8]), ">f8")[0] + (50.0 if v % 2 else -50.0)
        raw[at : at + 8] = np.array(x, ">f8").tobytes()
    bad = tmp_path / "wander.cphd"
    bad.write_bytes(bytes(raw))
    capsys.readouterr()
    assert main(["process", str(bad), "-o", str(tmp_path / "x.h5"), "--lens", "numpy"]) == 0
    said = [e for e in capsys.readouterr().err.splitlines() if "TxPos" in e]
    assert len(said) == 1 and said[0].startswith("rtsar: warning: ") and "wander.cphd" in said[0]
    assert "by 50 m rms" in said[0], said


GARBAGE_COMMANDS = {
    "process": lambda p, o: ["process", p, "-o", str(o / "x.h5")],
    "replay": lambda p, o: ["replay", p, "--rate", "max", "--endpoint", "ipc://" + str(o / "e")],
    "export --cphd": lambda p, o: ["export", p, "--cphd", str(o / "x.cphd")],
    "export --sicd": lambda p, o: ["export", p, "--sicd", str(o / "x.nitf")],
    "quicklook": lambda p, o: ["quicklook", p, "-o", str(o / "x.png")],
    "measure": lambda p, o: ["measure", p],
    "spotlight": lambda p, o: ["spotlight", p, "-o", str(o / "x.h5")],
    "batch": lambda p, o: ["batch", p, "--out-dir", str(o)],
}


@pytest.mark.parametrize("command", sorted(GARBAGE_COMMANDS))
def test_a_garbage_hdf5_file_is_named_by_every_command(tmp_path, capsys, command):
    bad = tmp_path / "garbage.h5"  # HDF5's signature, then noise: h5py raises RuntimeError
    rng = np.random.default_rng(7)
    bad.write_bytes(b"\x89HDF\r\n\x1a\n" + rng.integers(0, 256, 4096, np.uint8).tobytes())
    capsys.readouterr()
    assert main(GARBAGE_COMMANDS[command](str(bad), tmp_path)) == 2
    assert "not an HDF5 file" in _one_line_error(capsys, "garbage.h5")


def test_export_help_says_one_capture_per_shot_as_written(good, capsys):
    with pytest.raises(SystemExit):
        main(["export", "--help"])
    words = " ".join(capsys.readouterr().out.split())
    assert "one capture and one annotation per shot" in words
    meta = json.loads((good / "sig.sigmf-meta").read_text())
    assert len(meta["captures"]) == len(meta["annotations"]) == 72


# ---- a fuzz of structural corruptions -----------------------------------------------------------
FUZZ_SEED = 28
FUZZ_FILES = 24  # of each kind

NASTY = [-1, 0, 1e308, float("nan"), float("inf"), "x", None, [], {}, True, 2**70, -(2**63)]


def _mutate_json(rng, value):
    """``value`` (a JSON tree) with one leaf replaced by a nasty value, or one key dropped."""
    if isinstance(value, dict) and value:
        key = list(value)[int(rng.integers(0, len(value)))]
        if rng.random() < 0.25:
            return {k: v for k, v in value.items() if k != key}
        return {**value, key: _mutate_json(rng, value[key])}
    if isinstance(value, list) and value:
        i = int(rng.integers(0, len(value)))
        return [*value[:i], _mutate_json(rng, value[i]), *value[i + 1 :]]
    return NASTY[int(rng.integers(0, len(NASTY)))]


def _mutate_h5(rng, path, datasets):
    """One structural corruption of an HDF5 file rtsar wrote: a dataset removed, replaced by
    another type or shape, or holding NaN; an attribute that is not what it should be; the
    file cut short."""
    kind = int(rng.integers(0, 6))
    if kind == 5:
        data = path.read_bytes()
        path.write_bytes(data[: int(rng.integers(0, len(data)))])
        return
    with h5py.File(path, "r+") as f:
        name = datasets[int(rng.integers(0, len(datasets)))]
        if kind == 0:
            del f[name]
        elif kind == 1:
            old = f[name][...]
            shape = [old.shape, old.shape[:1], (old.shape[0], 1, 2), (0,), old.shape[::-1]][
                int(rng.integers(0, 5))
            ]
            dtype = [np.int8, np.float32, np.complex64, np.int64, "S3"][int(rng.integers(0, 5))]
            del f[name]
            f.create_dataset(name, data=np.zeros(shape, dtype))
        elif kind == 2:
            values = f[name][...]
            if values.dtype.kind in "fc" and values.size:
                values.flat[int(rng.integers(0, values.size))] = np.nan
                f[name][...] = values
        else:
            attr = [
                "config",
                "scene",
                "format",
                "format_version",
                "channels",
                "collection_start_utc",
            ][int(rng.integers(0, 6))]
            text = f.attrs.get(attr)
            try:
                value = json.loads(text)
            except (TypeError, ValueError):
                value = text
            f.attrs[attr] = json.dumps(_mutate_json(rng, value)) if kind == 3 else "{not json"


def _mutate_cphd(rng, raw: bytes) -> bytes:
    """A CPHD with its XML changed in place (same length: the header's offsets stay true): a
    number's digits replaced, an element's name, a JSON parameter; or the file cut short."""
    import re

    kind = int(rng.integers(0, 4))
    if kind == 3:
        return raw[: int(rng.integers(0, len(raw)))]
    start = raw.index(b"<?xml") if b"<?xml" in raw else raw.index(b"<CPHD")
    end = raw.index(b"</CPHD>") + 7
    xml = bytearray(raw[start:end])
    if kind == 0:
        numbers = list(re.finditer(rb">(-?[0-9][0-9.E+-]*)<", bytes(xml)))
        m = numbers[int(rng.integers(0, len(numbers)))]
        junk = rng.choice(list(b"9-0.NaE+x "), size=m.end(1) - m.start(1))
        xml[m.start(1) : m.end(1)] = bytes(junk.tolist())
    elif kind == 1:
        tags = list(re.finditer(rb"<([A-Za-z]+)>", bytes(xml)))
        m = tags[int(rng.integers(0, len(tags)))]
        xml[m.start(1)] = ord("Q")
    else:
        digits = [i for i, b in enumerate(xml) if 48 <= b <= 57]
        for i in rng.choice(digits, size=3):
            xml[int(i)] = int(rng.choice(list(b"9-.e")))
    return raw[:start] + bytes(xml) + raw[end:]


def _mutate_sigmf(rng, meta: dict, data: bytes) -> tuple[dict, bytes]:
    kind = int(rng.integers(0, 4))
    if kind == 3:
        return meta, data[: int(rng.integers(0, len(data)))]
    part = ["global", "captures", "annotations"][kind]
    if part == "global":
        return {**meta, "global": _mutate_json(rng, meta["global"])}, data
    items = meta[part]
    i = int(rng.integers(0, len(items)))
    return {**meta, part: [*items[:i], _mutate_json(rng, items[i]), *items[i + 1 :]]}, data


def _ends_cleanly(argv, capsys):
    """The command ends with 0, or 2 and one error line; anything raised is a failure."""
    capsys.readouterr()
    status = main(argv)
    if status != 0:
        err = [e for e in capsys.readouterr().err.strip().splitlines() if "warning" not in e]
        assert status == 2 and len(err) == 1 and err[0].startswith("rtsar: error:"), (argv, err)
    return status


def test_fuzz_of_corrupted_files_gives_no_traceback(good, tmp_path, capsys):
    rng = np.random.default_rng(FUZZ_SEED)
    refused = 0
    for k in range(FUZZ_FILES):
        rec = tmp_path / f"rec{k}.h5"
        shutil.copy(good / "rec.h5", rec)
        _mutate_h5(rng, rec, ["shots", "pulse_index", "time_s", "along_track_m"])
        out = tmp_path / "o.h5"
        refused += _ends_cleanly(["process", str(rec), "-o", str(out), "--lens", "numpy"], capsys)
        img = tmp_path / f"img{k}.h5"
        shutil.copy(good / "img.h5", img)
        _mutate_h5(rng, img, ["image", "azimuth_m", "range_m"])
        if k % 2:
            argv = ["export", str(img), "--sicd", str(tmp_path / "o.nitf")]
        else:
            argv = ["quicklook", str(img), "-o", str(tmp_path / "o.png")]
        refused += _ends_cleanly(argv, capsys)
        cphd = tmp_path / f"c{k}.cphd"
        cphd.write_bytes(_mutate_cphd(rng, (good / "rec.cphd").read_bytes()))
        refused += _ends_cleanly(["process", str(cphd), "-o", str(out), "--lens", "numpy"], capsys)
        meta = json.loads((good / "sig.sigmf-meta").read_text())
        meta, data = _mutate_sigmf(rng, meta, (good / "sig.sigmf-data").read_bytes())
        (tmp_path / f"s{k}.sigmf-meta").write_text(json.dumps(meta))
        (tmp_path / f"s{k}.sigmf-data").write_bytes(data)
        argv = ["process", str(tmp_path / f"s{k}.sigmf-meta"), "-o", str(out), "--lens", "numpy"]
        refused += _ends_cleanly(argv, capsys)
    assert refused >= 2 * FUZZ_FILES * 2  # most corruptions are refused (each counts 2)


def test_a_sigmf_archive_bounds_the_metadata_it_expands(tmp_path, monkeypatch):
    """Issue 36, item 6: a 10 KiB .sigmf (a sparse tar of four 1000 MiB metadata members)
    took 5 GB of memory: the cap was per member, not on the total, and a sparse member's
    declared size is not bytes the file holds.  Now the total is bounded before any read, and
    a sparse member is refused, each in one line."""
    import subprocess
    import tarfile

    from rtsar.sources.formats import sigmf_store

    def archive(name, members):
        path = tmp_path / name
        with tarfile.open(path, "w") as tar:
            for member, text in members.items():
                src = tmp_path / member
                src.write_text(text)
                tar.add(src, arcname=member)
        return path

    monkeypatch.setattr(sigmf_store, "MAX_META_BYTES", 100)
    each = '{"global": {}, "pad": "' + "x" * 40 + '"}'  # under the cap alone, over it together
    path = archive("many.sigmf", {f"r{k}.sigmf-meta": each for k in range(3)})
    with pytest.raises(ValueError, match="in all, over the 100-byte limit"):
        sigmf_store.Archive(path)
    sparse = tmp_path / "big.sigmf-meta"
    with open(sparse, "wb") as f:  # 64 MiB declared, a few bytes held
        f.truncate(64 << 20)
    tar = tmp_path / "sparse.sigmf"
    subprocess.run(
        ["tar", "--sparse", "-cf", str(tar), "-C", str(tmp_path), "big.sigmf-meta"], check=True
    )
    assert tar.stat().st_size < 1 << 20
    with pytest.raises(ValueError, match="sparse member"):
        sigmf_store.Archive(tar)
