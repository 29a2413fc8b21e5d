"""``rtsar batch``: the images of ``process``, bit for bit, from Dask workers; failures per file."""

import os

import h5py
import numpy as np
import pytest

from rtsar.app import batch
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
        batch.find_recordings([str(tmp_path / "missing")])
    with pytest.raises(ValueError, match="no recording"):
        batch.find_recordings([str(tmp_path)])
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    (a / "r.h5").touch(), (b / "r.h5").touch()
    recs = batch.find_recordings([str(a), str(b), str(a / "r.h5")])
    assert len(recs) == 2  # a/r.h5 named twice counts once
    with pytest.raises(ValueError, match="both write"):
        batch.output_paths(recs, tmp_path / "out")


def test_no_input_is_overwritten_and_earlier_images_are_not_inputs(recordings, tmp_path):
    """From a cold review: `batch bt --out-dir bt` with bt/x.h5 and bt/x-img.h5 replaced the
    recording x-img.h5 by x.h5's image; a second run took the first run's images as inputs."""
    folder = tmp_path / "bt"
    folder.mkdir()
    for name in ("x.h5", "x-img.h5"):
        (folder / name).write_bytes((recordings / "r1.h5").read_bytes())
    with pytest.raises(ValueError, match="would overwrite a recording"):
        batch.output_paths(batch.find_recordings([str(folder)]), folder)
    mix = tmp_path / "mix"
    mix.mkdir()
    (mix / "r1.h5").write_bytes((recordings / "r1.h5").read_bytes())
    assert main(["batch", str(mix), "--out-dir", str(mix), "--workers", "1"]) == 0
    assert (mix / "r1-img.h5").is_file()
    assert batch.find_recordings([str(mix)]) == [(mix / "r1.h5").resolve()]


def _die_and_count(counter: str):
    """A task whose worker dies: it notes the attempt in ``counter``, then ends the process."""
    import os

    with open(counter, "a") as f:
        f.write("x")
    os._exit(3)


def test_a_task_whose_worker_dies_is_tried_retries_plus_one_times(tmp_path):
    """--retries counts the retries of a task whose worker died (Dask's KilledWorker), not
    Dask's own default of 3 (``distributed.scheduler.allowed-failures``)."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(__import__(__name__))
    counter = tmp_path / "attempts"
    rec, out = tmp_path / "r.h5", tmp_path / "r-img.h5"

    def task(options, recording, output):
        return _die_and_count(str(counter))

    with open(os.devnull, "w") as quiet:
        results = batch.run_batch([rec], [out], {}, workers=1, retries=1, stream=quiet, task=task)
    assert [r.status for r in results] == ["failed"]
    assert "KilledWorker" in results[0].message and "1 retries" in results[0].message
    assert counter.read_text() == "xx"


def test_an_interrupted_batch_lists_every_file_and_prints_no_traceback(tmp_path, monkeypatch):
    """From a kill test: Ctrl-C during a batch printed Dask tracebacks and no summary.  The
    interrupt (here raised where the batch waits for its files) ends the batch with every file's
    result, those not done "interrupted"."""
    recs = [tmp_path / f"r{i}.h5" for i in range(3)]
    outs = [tmp_path / f"r{i}-img.h5" for i in range(3)]

    def interrupted(*args):
        raise KeyboardInterrupt

    monkeypatch.setattr(batch, "_collect", interrupted)
    with open(os.devnull, "w") as quiet, pytest.raises(batch.BatchInterrupted) as info:
        batch.run_batch(recs, outs, {}, workers=1, retries=0, stream=quiet)
    assert [r.status for r in info.value.results] == ["interrupted"] * 3
    assert [r.recording for r in info.value.results] == [str(r) for r in recs]
    # An image that a worker finished as the batch stopped is whole (it took its name complete).
    outs[1].write_bytes(b"image")
    assert batch._unfinished(recs[1], outs[1], 0.0).status == "ok"
    assert batch._unfinished(recs[2], outs[2], 0.0).status == "interrupted"
