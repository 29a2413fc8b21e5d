"""A disk that refuses the bytes (full, over quota, a file size limit) ends every HDF5 writer in
one error line — never a segmentation fault, a traceback or a leftover temporary file.

The refusal is real, not mocked: a child process runs the writers under RLIMIT_FSIZE (SIGXFSZ
ignored, so a write past the limit fails with EFBIG, "File too large") at limits from 0 to one
byte short of the finished file, so the failure lands in the file's creation, in the data writes
and in the last metadata written at the close.  Before rtsar.sinks.h5_output, HDF5 freed a
dataset whose close failed and crashed on closing it again: the child died with SIGSEGV.
"""

import errno
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

from rtsar.sinks.h5_output import WriteFailed
from rtsar.sinks.image_file import read_image
from rtsar.sinks.io import replace_when_complete

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_FSIZE as on Linux")

SCENE = """
preset = "tiny"
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
"""

CHILD = r"""
import contextlib, io, json, os, resource, signal, sys
from pathlib import Path
import numpy as np

signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails: EFBIG
from rtsar.app.cli import main
from rtsar.presets import preset
from rtsar.sinks.image_file import ImageWriter

tmp = Path(sys.argv[1])
_, HARD = resource.getrlimit(resource.RLIMIT_FSIZE)


def limited(limit, run):
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, HARD))
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            result = run()
    finally:
        resource.setrlimit(resource.RLIMIT_FSIZE, (HARD, HARD))
    return result, err.getvalue()


def limits(size, parts):
    return sorted({0, 2048, size - 2048, size - 1} | {size * k // parts for k in range(parts)})


rec, img = tmp / "rec.h5", tmp / "img.h5"
commands = {
    "simulate": lambda out: ["simulate", str(tmp / "s.toml"), "--pulses", "96", "-o", out],
    "process": lambda out: ["process", str(rec), "--lens", "numpy", "-o", out],
    "replay": lambda out: ["replay", str(rec), "--rate", "max", "--lens", "numpy",
                           "--endpoint", "ipc://" + str(tmp / "ep"), "-o", out],
}
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    assert main(commands["simulate"](str(rec))) == 0
for name, command in commands.items():  # the full size of each output, then short of it
    full = tmp / f"{name}-full.h5"
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert main(command(str(full))) == 0
    for k, limit in enumerate(limits(full.stat().st_size, 16 if name == "replay" else 4)):
        out = tmp / name / f"{k}.h5"
        out.parent.mkdir(exist_ok=True)
        out.write_bytes(b"the earlier file")
        rc, err = limited(limit, lambda: main(command(str(out))))
        print(json.dumps({"case": name, "limit": limit, "out": str(out), "rc": rc, "err": err}))

cfg = preset("tiny")
nr = cfg.processor.range_bins


def live(path, blocks):
    w = ImageWriter(path, cfg, np.arange(nr, dtype=float), crash_safe=True, flush_every_s=60)
    for n in range(0, 16 * blocks, 16):  # each line holds its index + 1
        w.write(np.zeros((16, nr), np.complex64) + (n + 1 + np.arange(16))[:, None],
                np.arange(n, n + 16) * 0.5)
    w.close(counters="{}")
    return "ok"


live(tmp / "live-full.h5", 12)
for k, limit in enumerate(limits((tmp / "live-full.h5").stat().st_size, 32)):
    out = tmp / "live" / f"{k}.h5"
    out.parent.mkdir(exist_ok=True)
    out.write_bytes(b"the earlier file")

    def run():
        try:
            return live(out, 12)
        except Exception as exc:  # the message is checked: WriteFailed's one line
            return str(exc)

    said, err = limited(limit, run)
    print(json.dumps({"case": "live", "limit": limit, "out": str(out), "said": said, "err": err}))
"""

PROGRESS = re.compile(
    r"^(simulate|process): \d+/\d+ pulses|^rtsar: (preparing|replay of)|^t=|^done:"
)


def test_every_writer_ends_in_one_line_on_a_full_disk(tmp_path):
    (tmp_path / "s.toml").write_text(SCENE)
    child = subprocess.run(
        [sys.executable, "-c", CHILD, str(tmp_path)], capture_output=True, text=True, timeout=120
    )
    # No crash (SIGSEGV: -11), no traceback, no "Exception ignored in ... __dealloc__".
    assert child.returncode == 0 and child.stderr == "", (child.returncode, child.stderr[-3000:])
    cases = [json.loads(line) for line in child.stdout.splitlines()]
    assert {c["case"] for c in cases} == {"simulate", "process", "replay", "live"}
    for c in cases:
        out = c["out"]
        leftovers = sorted(p for p in os.listdir(os.path.dirname(out)) if p.startswith("."))
        assert leftovers == [], (c, leftovers)
        if c["case"] != "live":
            said = [line for line in c["err"].splitlines() if not PROGRESS.match(line)]
            assert c["rc"] == 2, c
            if c["case"] == "replay" and open(out, "rb").read() != b"the earlier file":
                # the live writer's file: the lines it says are saved
                assert len(said) == 1 and said[0].startswith("rtsar: error: "), c
                full = read_image(tmp_path / "replay-full.h5")
                _check_saved(out, said[0][len("rtsar: error: ") :], full)
                continue
            assert said == [f"rtsar: error: cannot write {out}: File too large"], c
            assert open(out, "rb").read() == b"the earlier file", c  # left as it was
            continue
        assert c["err"] == "", c
        if open(out, "rb").read() == b"the earlier file":  # failed before its first line
            assert c["said"] == f"cannot write {out}: File too large", c
            continue
        _check_saved(out, c["said"], None)
    # Both kinds of live failure were met: before the first line, and with lines kept.
    live = [c["said"] for c in cases if c["case"] == "live"]
    assert any("lines are saved" in s for s in live) and any(s.endswith("large") for s in live)


def _check_saved(out: str, said: str, full) -> None:
    """A live writer's file after the failure holds the lines its message says, whole: the
    first lines of ``full`` (read_image of the run without a limit), or, with None, lines that
    each hold their own index + 1."""
    found = re.fullmatch(
        rf"cannot write {re.escape(out)}: File too large; (its|at least its first) (\d+) lines "
        r"are saved, marked incomplete \(complete = False\)"
        r"(; no room for the final attributes \(counters, gaps\))?",
        said,
    )
    assert found, said
    image, az, _, attrs = read_image(out)
    n = int(found.group(2))  # "its n": exactly; "at least its first n": those flushed
    assert len(image) == n if found.group(1) == "its" else len(image) >= n
    assert len(az) == len(image) and not attrs["complete"]
    if full is not None:
        np.testing.assert_array_equal(image, full[0][: len(image)])
        np.testing.assert_array_equal(az, full[1][: len(image)])
        return
    expect = np.arange(1, len(image) + 1, dtype=np.float32)
    np.testing.assert_array_equal(image.real, np.broadcast_to(expect[:, None], image.shape))
    np.testing.assert_array_equal(az, np.arange(len(image)) * 0.5)


def test_a_full_disk_under_any_writer_names_the_output(tmp_path):
    """The exports (CPHD, SICD, SigMF: plain files written by other libraries) and every other
    output written through replace_when_complete: ENOSPC in the writer becomes one line naming
    the output, not the temporary; the temporary goes, the earlier file stays."""
    out = tmp_path / "out.nitf"
    out.write_bytes(b"the earlier file")
    with pytest.raises(WriteFailed) as failed:
        with replace_when_complete(out) as tmp:
            tmp.write_bytes(b"half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    assert str(failed.value) == f"cannot write {out}: No space left on device"
    assert out.read_bytes() == b"the earlier file" and os.listdir(tmp_path) == ["out.nitf"]
    with pytest.raises(FileNotFoundError):  # other errors pass as they were
        with replace_when_complete(out) as tmp:
            raise FileNotFoundError(errno.ENOENT, "no input")
    assert os.listdir(tmp_path) == ["out.nitf"]


SIGMF_CHILD = r"""
import contextlib, io, resource, signal, sys
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
from rtsar.app.cli import main
rec, base = sys.argv[1], sys.argv[2]
_, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, hard))
err = io.StringIO()
with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
    rc = main(["export", rec, "--sigmf", base])
resource.setrlimit(resource.RLIMIT_FSIZE, (hard, hard))
print(rc)
print(err.getvalue(), end="")
"""


def test_a_sigmf_export_the_disk_refuses_names_its_data_file(tmp_path):
    """From a cold read: numpy's tofile reported a full disk as "1638400 requested and 157696
    written" (an OSError without errno), naming no file."""
    pytest.importorskip("sigmf")
    from rtsar.app.cli import main

    (tmp_path / "s.toml").write_text(SCENE)
    rec = tmp_path / "rec.h5"
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(rec), "--pulses", "600"]) == 0
    base = tmp_path / "out"
    child = subprocess.run(
        [sys.executable, "-c", SIGMF_CHILD, str(rec), str(base)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    rc, *err = child.stdout.splitlines()
    assert rc == "2" and err == [f"rtsar: error: cannot write {base}.sigmf-data: File too large"]
    assert not [p for p in os.listdir(tmp_path) if p.startswith((".out", "out"))]
