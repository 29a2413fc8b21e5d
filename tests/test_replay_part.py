"""`rtsar replay --start/--duration`: a part of a recording through the live pipeline gives the
whole replay's lines, where the whole replay puts them, for the apertures the part holds."""

import numpy as np
import pytest

from rtsar.app.cli import main
from rtsar.app.cli.replay import replayed_part
from rtsar.sinks.image_file import read_image

SCENE = """
preset = "tiny"
seed = 5
[processor]
correlator = "{correlator}"
[[targets]]
along_track_m = {x}
slant_range_m = 2000.0
[[targets]]
along_track_m = {x2}
slant_range_m = 1960.0
amplitude = 0.5
"""

PRF_HZ, STEP_M, APERTURE = 500.0, 0.5, 64  # the tiny preset's


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("part")
    scene = folder / "s.toml"
    scene.write_text(SCENE.format(correlator="nonuniform", x=60.0, x2=120.0))
    rec = str(folder / "rec.h5")
    assert main(["simulate", str(scene), "-o", rec, "--pulses", "500"]) == 0
    return folder, rec


def _replay(folder, rec, name, *extra):
    out = str(folder / name)
    args = ["replay", rec, "--rate", "max", "--lens", "numpy", "-o", out]
    assert main(args + ["--endpoint", f"ipc://{folder}/{name}.pub", *extra]) == 0
    return read_image(out)


@pytest.mark.parametrize("start_s, duration_s", [(0.3, 0.5), (0.0, 0.4), (0.55, None)])
def test_a_part_gives_the_whole_replays_lines_of_the_apertures_it_holds(
    recording, start_s, duration_s, capsys
):
    folder, rec = recording
    whole, whole_az, whole_r, _ = _replay(folder, rec, "whole.h5")
    extra = ["--start", str(start_s)] + (
        [] if duration_s is None else ["--duration", str(duration_s)]
    )
    part, part_az, part_r, attrs = _replay(folder, rec, f"part-{start_s}-{duration_s}.h5", *extra)
    out = capsys.readouterr().out
    first = round(start_s * PRF_HZ)
    count = 500 - first if duration_s is None else round(duration_s * PRF_HZ)
    if count < 500:
        assert f"shots {first:,} … {first + count - 1:,} of 500" in out
    np.testing.assert_array_equal(part_r, whole_r)
    # Every line of the part sits on a line of the whole (same along-track positions).
    at = np.searchsorted(whole_az, part_az)
    assert np.all(at < len(whole_az))
    np.testing.assert_allclose(whole_az[at], part_az, atol=1e-9 * STEP_M)
    # A line leaves once its whole aperture has arrived: the part gives one line a shot after
    # its first aperture, each the whole replay's line at that position (float32 sums in
    # another block order: to 1e-5 of the image's peak).
    assert len(part_az) == count - APERTURE + 1
    assert np.abs(part - whole[at]).max() <= 1e-5 * np.abs(whole).max()


def test_a_part_outside_the_recording_is_refused_in_one_line(recording, capsys):
    folder, rec = recording
    for extra, said in (
        (["--start", "1.0"], "--start 1 s is shot 500, past the recording's last: it holds 500"),
        (["--start", "0.9991"], "0.9991 s is shot 500, past"),  # (< 1 s: rounded to shot 500)
        (["--duration", "0.0005"], "--duration 0.0005 s is less than one shot at 500 Hz"),
        (["--duration", "0.1"], "the part holds 50 shots, fewer than the CCD's 64 rows"),
        (["--duration", "inf"], "--duration must be a finite number of seconds, got inf"),
        (["--start", "inf"], "--start must be a finite number of seconds, got inf"),
        (["--start", "1e307"], "--start 1e+307 s is more shots than any recording holds"),
        (["--duration", "0"], "must be > 0 seconds"),
        (["--start", "-1"], "must be >= 0 seconds"),
    ):
        try:
            status = main(["replay", rec, "--rate", "max", *extra])
        except SystemExit as exc:  # argparse's refusal of the option's value
            status = exc.code
        assert status == 2
        assert said in capsys.readouterr().err


def test_a_parts_collection_start_is_its_first_shots(recording, capsys):
    """A cold review: a part's image kept the whole recording's collection start, so its
    SICD timing was early by --start."""
    import datetime

    from rtsar.sinks.io import open_recording

    folder, rec = recording
    with open_recording(rec) as r:
        whole_start = r.collection_start
    _, _, _, attrs = _replay(folder, rec, "part-start.h5", "--start", "0.3")
    part_start = datetime.datetime.fromisoformat(attrs["collection_start_utc"].rstrip("Z"))
    assert part_start - whole_start == datetime.timedelta(seconds=150 / PRF_HZ)
    capsys.readouterr()


def test_a_part_of_a_cphd_recording_replays(recording, tmp_path, capsys):
    """A cold review: the window read a CPHD channel's shots with a tuple key, which they
    refuse (a traceback)."""
    pytest.importorskip("sarkit")
    folder, rec = recording
    cphd = tmp_path / "rec.cphd"
    assert main(["export", rec, "--cphd", str(cphd)]) == 0
    _, whole_az, _, _ = _replay(folder, rec, "for-cphd.h5", "--start", "0.3")
    part, part_az, _, _ = _replay(tmp_path, str(cphd), "cphd-part.h5", "--start", "0.3")
    np.testing.assert_allclose(part_az, whole_az, atol=1e-9)
    assert len(part_az) == 350 - APERTURE + 1 and np.abs(part).max() > 0
    capsys.readouterr()


def test_run_refuses_a_duration_that_is_not_finite(capsys):
    for value in ("inf", "nan"):
        assert main(["run", "--duration", value]) == 2
        assert f"--duration must be a finite number of seconds > 0, got {value}" in (
            capsys.readouterr().err
        )


def test_the_part_in_shots():
    assert replayed_part(0.0, None, 500.0, 500) == (0, 500)
    assert replayed_part(0.3, 0.5, 500.0, 500) == (150, 250)
    assert replayed_part(0.9, 5.0, 500.0, 500) == (450, 50)  # to the end, not beyond
    with pytest.raises(ValueError, match="past the recording's last"):
        replayed_part(0.999, None, 500.0, 500)
    with pytest.raises(ValueError, match="fewer than the CCD.s"):
        replayed_part(0.9, None, 500.0, 500, 64)  # a part of 50 shots
    assert replayed_part(0.0, None, 500.0, 50, 64) == (0, 50)  # the whole: as it is


def test_ctrl_c_before_the_stream_starts_is_said_and_writes_nothing(recording, monkeypatch, capsys):
    """From a new user's review: Ctrl-C while a replay measured its granularity ended with
    status 130 and not a word."""
    from rtsar.app import live

    folder, rec = recording

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(live, "survey_and_compile", interrupted)
    out = folder / "early.h5"
    args = ["replay", rec, "-o", str(out), "--endpoint", f"ipc://{folder}/early.pub"]
    assert main(args) == 130
    said = capsys.readouterr().out
    assert (
        "rtsar: interrupted before the stream started: no shot processed, no file written" in said
    )
    assert not out.exists()


def test_a_replay_stopped_by_a_signal_says_so_in_its_image(recording, monkeypatch, capsys):
    """A paced replay with -o stopped by Ctrl-C after its first strip: the pulses received
    are finished, the file closed and complete, and its ``stopped_by`` names the signal, so
    it is not taken for the whole replay of a shorter recording (before, nothing told them
    apart); the whole replay's is empty."""
    from rtsar.stream.pipeline import Pipeline

    folder, rec = recording
    wait = ctrl_c_once(monkeypatch, lambda pipe: pipe.own["strips_published"] > 0)
    out = folder / "stopped.h5"
    args = ["replay", rec, "--lens", "numpy", "-o", str(out)]
    assert main(args + ["--endpoint", f"ipc://{folder}/stopped.pub"]) == 130
    image, _, _, attrs = read_image(out)
    assert attrs["complete"] and attrs["stopped_by"] == "SIGINT"
    assert 0 < len(image) < 500 - APERTURE + 1  # a part: 1 s of shots at 500 Hz, stopped early
    monkeypatch.setattr(Pipeline, "_wait", wait)
    *_, whole = _replay(folder, rec, "unstopped.h5")
    assert whole["complete"] and whole["stopped_by"] == ""


def ctrl_c_once(monkeypatch, when):
    """Pipeline.join's first wait raises Ctrl-C once ``when(pipeline)`` holds (60 s at most),
    later waits are the pipeline's own."""
    import time

    from rtsar.stream.pipeline import Pipeline

    wait, calls = Pipeline._wait, []

    def ctrl_c(self):
        if calls:
            return wait(self)
        calls.append(1)
        deadline = time.monotonic() + 60
        while not when(self) and time.monotonic() < deadline:
            time.sleep(0.005)
        raise KeyboardInterrupt

    monkeypatch.setattr(Pipeline, "_wait", ctrl_c)
    return wait


def test_ctrl_c_after_the_source_has_ended_does_not_say_it_was_cut_short(recording, monkeypatch):
    """Ctrl-C while a replay whose source has delivered the whole recording finishes: the
    image is the whole replay's and ``stopped_by`` stays empty (a cold review: it said
    SIGINT, and the docs then called the image a part)."""
    folder, rec = recording
    ctrl_c_once(monkeypatch, lambda pipe: pipe._ended[0].is_set())
    out = folder / "late-stop.h5"
    args = ["replay", rec, "--rate", "max", "--lens", "numpy", "-o", str(out)]
    assert main(args + ["--endpoint", f"ipc://{folder}/late-stop.pub"]) == 130
    image, _, _, attrs = read_image(out)
    assert attrs["complete"] and attrs["stopped_by"] == ""
    assert len(image) == 500 - APERTURE + 1  # every line of the recording


def test_run_says_where_the_scene_ends_before_its_duration(tmp_path, capsys):
    """A new user's review: `rtsar run --duration 30` of the 10 s demo stopped after 10 s
    without a word."""
    scene = tmp_path / "s.toml"
    text = SCENE.format(correlator="nonuniform", x=20.0, x2=40.0)
    scene.write_text(text.replace('preset = "tiny"', 'preset = "tiny"\npulses = 200'))
    args = ["run", "--scene", str(scene), "--lens", "numpy", "--duration", "100"]
    assert main([*args, "--endpoint", f"ipc://{tmp_path}/p"]) == 0
    out = capsys.readouterr().out
    assert "--duration 100 s is longer than the scene: the run ends with it, after 200 " in out
