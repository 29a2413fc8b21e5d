"""Opening an HDF5 input in whatever state its writer left it (rtsar.sinks.h5_open): a file cut
short is refused in one line at once.  From a fault review: opened in SWMR mode as a fallback,
a truncated recording or image made process, replay, quicklook and measure retry inside HDF5
for over ten minutes, deaf to Ctrl-C and SIGTERM.  Each case runs in a child process with a
time limit, so that a regression fails here instead of hanging the suite."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rtsar.app.cli import main

SCENE = """
preset = "tiny"
[[targets]]
along_track_m = 20.0
slant_range_m = 2000.0
"""

LIMIT_S = 60  # each child's: an answer within h5_open.PROBE_LIMIT_S (15 s) and start-up


def _child(*code_or_args: str, module: bool = False) -> subprocess.CompletedProcess:
    args = ["-m", "rtsar", *code_or_args] if module else ["-c", code_or_args[0]]
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=LIMIT_S)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("h5open")
    (folder / "s.toml").write_text(SCENE)
    rec = folder / "rec.h5"
    assert main(["simulate", str(folder / "s.toml"), "-o", str(rec), "--pulses", "300"]) == 0
    return rec


@pytest.mark.parametrize("keep", [1000, 0.5])
def test_a_truncated_recording_is_refused_in_one_line_at_once(recording, tmp_path, keep):
    cut = tmp_path / "cut.h5"
    data = recording.read_bytes()
    cut.write_bytes(data[: keep if isinstance(keep, int) else int(len(data) * keep)])
    for command in (
        ["process", str(cut), "-o", str(tmp_path / "img.h5")],
        ["quicklook", str(cut), "-o", str(tmp_path / "q.png")],
    ):
        done = _child(*command, module=True)
        assert done.returncode == 2, done.stderr
        err = done.stderr.strip().splitlines()
        assert err[-1].startswith(f"rtsar: error: {cut}: truncated: it holds ")
        assert f"of its {len(data):,} bytes" in err[-1]
    assert not (tmp_path / "img.h5").exists()


WRITER = """
import sys, time, h5py, numpy as np
f = h5py.File(sys.argv[1], "w", libver="latest")
chunk, chunks = int(sys.argv[2]), int(sys.argv[3])
d = f.create_dataset("x", (0,), maxshape=(None,), chunks=(chunk,), dtype="f8")
f.attrs["format"] = "rtsar-image"
f.swmr_mode = True
for i in range(0, chunks, 40):
    d.resize((d.shape[0] + 40 * chunk,)); d[-40 * chunk:] = i; f.flush()
print("written", flush=True)
time.sleep(60)
"""


def _killed_writers_file(path, chunk: int, chunks: int) -> None:
    """A file an SWMR writer grew to ``chunks`` chunks of ``chunk`` values, then was killed."""
    writer = subprocess.Popen(
        [sys.executable, "-c", WRITER, str(path), str(chunk), str(chunks)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert writer.stdout.readline().strip() == "written"
    finally:
        os.kill(writer.pid, signal.SIGKILL)
        writer.wait()


def test_a_killed_writers_file_opens_and_cut_short_is_refused(tmp_path):
    path = tmp_path / "live.h5"
    _killed_writers_file(path, 4096, 40)
    opened = "from pathlib import Path; from rtsar.sinks.h5_open import open_for_reading as o; "
    whole = _child(opened + f"f = o(Path({str(path)!r})); print(f['x'].shape[0])")
    assert whole.returncode == 0 and int(whole.stdout) > 0, whole.stderr  # SWMR: as it was left
    size = path.stat().st_size
    os.truncate(path, size - 4096)  # its last rows gone, its structure whole: it opens
    short = _child(opened + f"f = o(Path({str(path)!r})); print(f['x'].shape[0])")
    assert short.returncode == 0, short.stderr
    os.truncate(path, 2000)  # its structure cut off: in SWMR mode its reads would never end
    t0 = time.perf_counter()
    cut = _child(opened + f"o(Path({str(path)!r}))")
    assert cut.returncode == 1
    assert f"truncated: it holds 2,000 of its {size:,} bytes, its structure " in cut.stderr
    assert time.perf_counter() - t0 < LIMIT_S


def test_a_live_recording_cut_short_is_refused_after_the_probes_limit(recording, tmp_path):
    """The review's case: `run --record`'s file (SWMR, chunk indexes checksummed) cut to 1,000
    bytes; its child probe never finishes, and the refusal comes after PROBE_LIMIT_S."""
    from rtsar.sinks.h5_open import PROBE_LIMIT_S

    scene, raw = recording.parent / "s.toml", tmp_path / "raw.h5"
    run = ["run", "--scene", str(scene), "--duration", "0.3", "--record", str(raw)]
    done = _child(*run, "--lens", "numpy", "--endpoint", f"ipc://{tmp_path}/p", module=True)
    assert done.returncode == 0, done.stderr
    size = raw.stat().st_size
    os.truncate(raw, 1000)
    t0 = time.perf_counter()
    done = _child("process", str(raw), "-o", str(tmp_path / "img.h5"), module=True)
    took_s = time.perf_counter() - t0
    assert done.returncode == 2
    assert f"truncated: it holds 1,000 of its {size:,} bytes" in done.stderr
    assert took_s < PROBE_LIMIT_S + 20


def test_a_disk_full_file_of_many_chunks_opens_at_once(tmp_path):
    """A cold review: the probe read the chunk index chunk by chunk (h5py's get_chunk_info
    walks it from the start each call), so 12,000 chunks, a long run --record's 12 GB, took
    over the probe's limit and a whole structure was refused.  It walks the index once now."""
    path = tmp_path / "long.h5"
    _killed_writers_file(path, 16, 12_000)
    os.truncate(path, path.stat().st_size - 4096)  # its disk filled: the last rows lost
    t0 = time.perf_counter()
    opened = "from pathlib import Path; from rtsar.sinks.h5_open import open_for_reading as o; "
    done = _child(opened + f"print(o(Path({str(path)!r}))['x'].shape[0])")
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) == 12_000 * 16
    assert time.perf_counter() - t0 < 10  # the probe's own limit is 15 s


def test_the_probe_finds_h5py_where_its_caller_found_it(tmp_path):
    """A cold review: run isolated (-I), the probe ignored PYTHONPATH and could not import
    h5py where the caller found it only there (an HPC module system): a disk-full file whose
    structure is whole was refused.  The child now takes the caller's own path."""
    import sysconfig

    path = tmp_path / "short.h5"
    _killed_writers_file(path, 4096, 40)
    os.truncate(path, path.stat().st_size - 4096)
    base = getattr(sys, "_base_executable", sys.executable)  # the interpreter, not the venv's
    found = os.pathsep.join([sysconfig.get_paths()["purelib"], str(Path(__file__).parents[1])])
    code = "from pathlib import Path; from rtsar.sinks.h5_open import open_for_reading as o; "
    code += f"print(o(Path({str(path)!r}))['x'].shape[0])"
    env = {**os.environ, "PYTHONPATH": found}
    done = subprocess.run(
        [base, "-c", code], capture_output=True, text=True, timeout=LIMIT_S, env=env
    )
    assert done.returncode == 0, done.stderr
    assert int(done.stdout) > 0
