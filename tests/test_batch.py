"""``rtsar batch``: the images of ``process``, bit for bit, from Dask workers; failures per file."""

import os
import signal
import threading
import time

import h5py
import numpy as np
import pytest
from conftest import fmcw_scene_with_reference

from rtsar.app import batch
from rtsar.app.cli import batch as batch_cli
from rtsar.app.cli import main
from rtsar.sinks.image_file import read_image

pytest.importorskip("distributed")

SCENE = """
preset = "tiny"
seed = {seed}
[[targets]]
along_track_m = {x}
slant_range_m = 2000.0
[[effects]]
name = "noise"
snr_db = 0.0
"""


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recs")
    for seed, x in [(1, 0.0), (2, 5.0), (3, -5.0)]:
        scene = folder / f"s{seed}.toml"
        scene.write_text(SCENE.format(seed=seed, x=x))
        assert main(["simulate", str(scene), "-o", str(folder / f"r{seed}.h5")]) == 0
        scene.unlink()
    return folder


def test_batch_equals_process_bit_for_bit(recordings, tmp_path, capsys):
    """Two worker processes; each image equals `rtsar process` of the same file, same options."""
    out = tmp_path / "imgs"
    knobs = ["--lens", "numpy", "--correlator", "direct"]
    assert main(["batch", str(recordings), "--out-dir", str(out), "--workers", "2", *knobs]) == 0
    table = capsys.readouterr().out
    assert "3 of 3 recordings focused" in table
    for rec in sorted(recordings.glob("*.h5")):
        ref = tmp_path / f"{rec.stem}-ref.h5"
        assert main(["process", str(rec), "-o", str(ref), *knobs]) == 0
        got, az, rg, attrs = read_image(out / f"{rec.stem}-img.h5")
        want, az2, rg2, _ = read_image(ref)
        assert got.shape == want.shape and np.array_equal(got, want)
        assert np.array_equal(az, az2) and np.array_equal(rg, rg2)
        assert attrs["correlator"] == "direct"


def test_a_bad_file_is_reported_and_the_rest_done(recordings, tmp_path, capsys):
    bad_dir = tmp_path / "in"
    bad_dir.mkdir()
    good = bad_dir / "good.h5"
    good.write_bytes((recordings / "r1.h5").read_bytes())
    with h5py.File(bad_dir / "broken.h5", "w") as f:
        f["x"] = 1  # an HDF5 file that is no recording
    out = tmp_path / "imgs"
    status = main(["batch", str(bad_dir), "--out-dir", str(out), "--workers", "1"])
    text = capsys.readouterr().out
    assert status == 1
    assert "1 of 2 recordings focused" in text and "1 failed" in text
    broken_row = next(line for line in text.splitlines() if line.startswith("broken.h5"))
    assert "failed" in broken_row and "broken.h5" in broken_row.split("failed", 1)[1]
    assert (out / "good-img.h5").is_file() and not (out / "broken-img.h5").exists()


def test_inputs_are_checked_before_any_work(tmp_path):
    with pytest.raises(ValueError, match="no such file"):
        batch_cli.find_recordings([str(tmp_path / "missing")])
    with pytest.raises(ValueError, match="no recording"):
        batch_cli.find_recordings([str(tmp_path)])
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    (a / "r.h5").touch(), (b / "r.h5").touch()
    recs, _ = batch_cli.find_recordings([str(a), str(b), str(a / "r.h5")])
    assert len(recs) == 2  # a/r.h5 named twice counts once
    with pytest.raises(ValueError, match="both write"):
        batch_cli.output_paths(recs, tmp_path / "out")


def test_a_link_names_its_image(tmp_path):
    """From a cold read: flight1.h5 -> x/rec.h5 and flight2.h5 -> y/rec.h5 were refused as
    "would both write rec-img.h5" (named after their targets); a link's own name names its
    image, and a file reached twice (named, and through a link) is still focused once."""
    x, y = tmp_path / "x", tmp_path / "y"
    x.mkdir(), y.mkdir()
    (x / "rec.h5").touch(), (y / "rec.h5").touch()
    (tmp_path / "flight1.h5").symlink_to(x / "rec.h5")
    (tmp_path / "flight2.h5").symlink_to(y / "rec.h5")
    named = [str(tmp_path / "flight1.h5"), str(tmp_path / "flight2.h5"), str(x / "rec.h5")]
    recs, _ = batch_cli.find_recordings(named)
    assert [r.name for r in recs] == ["flight1.h5", "flight2.h5"]
    outs = batch_cli.output_paths(recs, tmp_path / "out")
    assert [o.name for o in outs] == ["flight1-img.h5", "flight2-img.h5"]


def test_no_input_is_overwritten_and_earlier_images_are_not_inputs(recordings, tmp_path):
    """From a cold review: `batch bt --out-dir bt` with bt/x.h5 and bt/x-img.h5 replaced the
    recording x-img.h5 by x.h5's image; a second run took the first run's images as inputs."""
    folder = tmp_path / "bt"
    folder.mkdir()
    for name in ("x.h5", "x-img.h5"):
        (folder / name).write_bytes((recordings / "r1.h5").read_bytes())
    with pytest.raises(ValueError, match="would overwrite a recording"):
        batch_cli.output_paths(batch_cli.find_recordings([str(folder)])[0], folder)
    mix = tmp_path / "mix"
    mix.mkdir()
    (mix / "r1.h5").write_bytes((recordings / "r1.h5").read_bytes())
    assert main(["batch", str(mix), "--out-dir", str(mix), "--workers", "1"]) == 0
    assert (mix / "r1-img.h5").is_file()
    assert batch_cli.find_recordings([str(mix)])[0] == [(mix / "r1.h5").resolve()]


def _die_and_count(counter: str, output: str):
    """A task whose worker dies: it notes the attempt in ``counter``, starts writing ``output``
    as process does (its temporary beside it), then ends the process."""
    import os

    from rtsar.sinks.io import replace_when_complete

    with open(counter, "a") as f:
        f.write("x")
    with replace_when_complete(output) as tmp:
        tmp.write_bytes(bytes(1 << 20))
        os._exit(3)


@pytest.mark.slow
def test_a_dead_workers_row_says_how_it_ended_and_a_raised_error_is_carried(tmp_path):
    """--retries counts the retries of a task whose worker died (Dask's KilledWorker, not
    Dask's default of 3).  From a cold review: the row read only "KilledWorker: Attempted to run
    task ... on 3 different workers, but all those workers died"; it now says how the worker
    ended (the nanny's exit status), and an error the task raised is in its row as raised."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(__import__(__name__))
    counter = tmp_path / "attempts"
    recs = [tmp_path / "dies.h5", tmp_path / "full.h5"]
    outs = [tmp_path / "dies-img.h5", tmp_path / "full-img.h5"]

    def task(options, recording, output):
        if recording.endswith("dies.h5"):
            return _die_and_count(str(counter), output)
        raise MemoryError("disk or memory full: 28")

    with open(os.devnull, "w") as quiet:
        results = batch.run_batch(recs, outs, {}, workers=1, retries=1, stream=quiet, task=task)
    assert [r.status for r in results] == ["failed", "failed"]
    assert "died on each of 2 tries" in results[0].message
    assert "exited with status 3" in results[0].message
    assert results[1].message.startswith("MemoryError: disk or memory full: 28")
    assert counter.read_text() == "xx"
    # Issue 29: the dead workers' temporaries (and name claims) stayed in the out-dir (40 MB
    # in one run); the batch removes them once its cluster is closed.
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def _signal_soon(marker=None, delay_s=0.0):
    """SIGINT to this process once ``marker`` exists (or at once), from a thread."""

    def send():
        while marker is not None and not marker.exists():
            time.sleep(0.05)
        time.sleep(delay_s)
        os.kill(os.getpid(), signal.SIGINT)

    threading.Thread(target=send, daemon=True).start()


def _start_then_wait(options, recording, output):
    """r2.h5 says it started (a file beside the output) and waits; the others are processed."""
    import time as time_

    from rtsar.app import batch as batch_

    if recording.endswith("r2.h5"):
        open(output + ".started", "w").close()
        time_.sleep(60)
    return batch_.process_one(options, recording, output)


@pytest.mark.slow
def test_an_interrupted_batch_lists_every_file_and_prints_no_noise(recordings, tmp_path, capfd):
    """From a cold review: Ctrl-C with 2 workers printed Dask/tornado tracebacks, and when it
    came during the cluster's close, no table (only `rtsar: interrupted`).  Now: r1 done, r2
    interrupted (its worker was on it), r3 not started; exit status 130; nothing from Dask."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(__import__(__name__))
    out = tmp_path / "imgs"
    _signal_soon(marker=out / "r2-img.h5.started", delay_s=0.5)
    knobs = ["--lens", "numpy", "--correlator", "direct", "--workers", "1"]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(batch, "process_one", _start_then_wait)
        assert main(["batch", str(recordings), "--out-dir", str(out), *knobs]) == 130
    text, err = capfd.readouterr()
    rows = {line.split()[0]: line for line in text.splitlines()[1:4]}
    assert rows["r1.h5"].split()[1] == "ok" and "wrote" in rows["r1.h5"]
    assert rows["r2.h5"].split()[1] == "interrupted"
    assert rows["r3.h5"].split()[1:3] == ["not", "started"]
    assert "interrupted: 1 of 3 recordings focused" in text
    for noise in ("Traceback", "distributed", "tornado", "Error"):
        assert noise not in err + text


def test_a_signal_while_the_cluster_starts_or_closes_still_gives_every_row(tmp_path, capfd):
    """The signal lands inside Dask's start (no file runs: every one "not started") or inside
    its close (every file done); neither raises nor prints anything from Dask."""
    recs = [tmp_path / f"r{i}.h5" for i in range(2)]
    outs = [tmp_path / f"r{i}-img.h5" for i in range(2)]
    real_start, real_close = batch.start_client, batch._close

    def start_signalled(*args):
        os.kill(os.getpid(), signal.SIGINT)  # noted by the StopSignal, raised nowhere
        return real_start(*args)

    def close_signalled(*args):
        os.kill(os.getpid(), signal.SIGINT)
        return real_close(*args)

    def quick(options, recording, output):
        return batch.FileResult(recording, output, "ok", message="done")

    with pytest.MonkeyPatch.context() as mp, open(os.devnull, "w") as quiet:
        mp.setattr(batch, "start_client", start_signalled)
        with batch.StopSignal() as stop:
            results = batch.run_batch(recs, outs, {}, 1, stream=quiet, task=quick, stop=stop)
        assert stop.signum == signal.SIGINT
        assert [r.status for r in results] == ["not started"] * 2
        mp.setattr(batch, "start_client", real_start)
        mp.setattr(batch, "_close", close_signalled)
        with batch.StopSignal() as stop:
            results = batch.run_batch(recs, outs, {}, 1, stream=quiet, task=quick, stop=stop)
        assert stop.signum == signal.SIGINT
        assert [(r.status, r.message) for r in results] == [("ok", "done")] * 2
    text, err = capfd.readouterr()
    for noise in ("Traceback", "distributed", "tornado", "Error"):
        assert noise not in err + text
    # An image that a worker finished as the batch stopped is whole (it took its name complete).
    outs[1].write_bytes(b"image")
    assert batch._unfinished(recs[1], outs[1], 0.0, True).status == "ok"
    assert batch._unfinished(recs[0], outs[0], 0.0, True).status == "interrupted"
    assert batch._unfinished(recs[0], outs[0], 0.0, False).status == "not started"


def _no_cluster(*args):
    raise AssertionError("the cluster was started")


@pytest.mark.parametrize("bad", [["--correct", "foo"], ["--correct", "hcn"]])
def test_options_process_refuses_stop_before_the_cluster(recordings, tmp_path, capsys, bad):
    """From a cold review: `batch --correct foo` started Dask, then every file failed (exit 1
    after ~7 s).  Now process's own line and exit status 2, no cluster; also for a correction
    the recordings' waveform cannot take (hcn on these pulsed recordings)."""
    rec = recordings / "r1.h5"
    assert main(["process", str(rec), "-o", str(tmp_path / "p.h5"), *bad]) == 2
    said = capsys.readouterr().err.strip().splitlines()[-1]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(batch, "start_client", _no_cluster)
        status = main(["batch", str(recordings), "--out-dir", str(tmp_path / "o"), *bad])
    assert status == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == said


def test_files_process_would_refuse_are_rows_and_a_folder_says_what_it_skipped(
    recordings, tmp_path, capsys
):
    """From a cold review: an rtsar image in a folder, and .cphd / .sigmf-meta files, were left
    out without a word; files process would refuse were found only in the workers."""
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "good.h5").write_bytes((recordings / "r1.h5").read_bytes())
    with h5py.File(folder / "broken.h5", "w") as f:
        f["x"] = 1  # an HDF5 file that is no recording
    with h5py.File(folder / "animage.h5", "w") as f:
        f.attrs["format"] = "rtsar-image"
    (folder / "x.cphd").write_bytes(b"not CPHD")
    (folder / "s.sigmf-meta").write_text("{}")
    (folder / "s.sigmf-data").write_bytes(b"")
    (folder / "lone.sigmf-data").write_bytes(b"")
    (folder / "notes.txt").write_text("hello")
    (folder / "sub").mkdir()
    (folder / ".good-img.h5.partial-host-1").write_bytes(b"")
    recs, skipped = batch_cli.find_recordings([str(folder)])
    assert [p.name for p in recs] == ["broken.h5", "good.h5", "s.sigmf-meta", "x.cphd"]
    line = batch_cli.skipped_line(skipped)
    assert line.startswith("skipped 4 files: animage.h5 (an rtsar image, not a recording); ")
    assert "lone.sigmf-data (SigMF data without its .sigmf-meta)" in line
    assert "notes.txt (not a format process reads)" in line and "sub (a folder" in line
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(batch, "start_client", _no_cluster)
        (folder / "good.h5").unlink()  # all refused: no cluster, each reason in its row
        assert main(["batch", str(folder), "--out-dir", str(tmp_path / "o")]) == 2
    out, err = capsys.readouterr()
    assert "skipped 4 files: animage.h5" in err
    rows = {line.split()[0]: line for line in out.splitlines()[1:4]}
    assert set(rows) == {"broken.h5", "s.sigmf-meta", "x.cphd"}
    assert all(r.split()[1] == "failed" for r in rows.values())
    assert "x.cphd" in rows["x.cphd"].split("failed", 1)[1]


AUX_SCENE = fmcw_scene_with_reference(40, 16, 64)


def test_a_sigmf_exports_channel_files_are_read_with_it_not_as_recordings(tmp_path, capsys):
    """From a cold review: `batch` on a folder holding a SigMF export with an auxiliary channel
    counted the channel's .sigmf-meta as a failed recording (exit 1) beside the focused one;
    `process` of it said "give a configuration", which no option does."""
    scene = tmp_path / "s.toml"
    scene.write_text(AUX_SCENE)
    folder = tmp_path / "in"
    folder.mkdir()
    assert main(["simulate", str(scene), "-o", str(tmp_path / "r.h5")]) == 0
    assert main(["export", str(tmp_path / "r.h5"), "--sigmf", str(folder / "r")]) == 0
    aux = folder / "r.reference_interferometer.sigmf-meta"
    assert aux.is_file()
    recs, skipped = batch_cli.find_recordings([str(folder)])
    assert [p.name for p in recs] == ["r.sigmf-meta"] and skipped == []
    (folder / "r.sigmf-meta").rename(tmp_path / "moved.sigmf-meta")
    recs, skipped = batch_cli.find_recordings([str(folder / "r.sigmf-data"), str(folder)])
    assert [(p.name, why) for p, why in skipped if p == aux] == [
        ("r.reference_interferometer.sigmf-meta", "the auxiliary channel of a SigMF export whose "
         "r.sigmf-meta is missing")
    ]  # fmt: skip
    capsys.readouterr()
    assert main(["process", str(aux), "-o", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err
    assert "auxiliary channel 'reference_interferometer' of a SigMF export" in err
    assert "give its recording" in err and "r.sigmf-meta" in err


def test_a_batch_refused_before_its_start_leaves_no_empty_out_dir(tmp_path, capsys):
    """From a new-user review: a batch refused before any file started (every file refused)
    still created its --out-dir, empty."""
    folder = tmp_path / "in"
    folder.mkdir()
    with h5py.File(folder / "broken.h5", "w") as f:
        f["x"] = 1  # an HDF5 file that is no recording
    out = tmp_path / "out"
    assert main(["batch", str(folder), "--out-dir", str(out)]) == 2
    assert not out.exists()
    out.mkdir()  # a folder the user made stays, empty or not
    assert main(["batch", str(folder), "--out-dir", str(out)]) == 2
    assert out.is_dir()
    capsys.readouterr()


def test_rtsar_demo_alone_runs_the_insal_demo():
    from rtsar.app.cli import build_parser

    assert build_parser().parse_args(["demo"]).which == "insal"


def test_a_dead_workers_row_waits_for_the_nannys_line():
    """From a full run on a busy machine: the KilledWorker reached the client before the nanny
    logged how its worker ended, and the row said "how is not known". The row waits for it."""
    from types import SimpleNamespace

    KilledWorker = type("KilledWorker", (Exception,), {})
    exc = KilledWorker("died")
    exc.allowed_failures, exc.last_worker = 1, SimpleNamespace(pid=4242)
    deaths: dict[int, str] = {}
    timer = threading.Timer(0.3, lambda: deaths.update({4242: "exited with status 3"}))
    timer.start()
    why = batch._why(exc, deaths, 1)
    timer.join()
    assert why == "its worker process died on each of 2 tries; the last exited with status 3"


def test_without_dask_distributed_batch_says_what_to_install_before_any_work(
    tmp_path, monkeypatch, capsys
):
    """README command 1 installs no cluster extra: there `rtsar batch` gave its banner and then
    a traceback (ModuleNotFoundError: distributed).  Now one line, exit status 2, nothing made."""
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed: ImportError
    rec = tmp_path / "rec.h5"
    rec.write_bytes(b"")
    out = tmp_path / "imgs"
    assert main(["batch", str(rec), "--out-dir", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['rtsar: error: rtsar batch needs Dask distributed: pip install "rtsar[cluster]"']
    assert not out.exists()
