"""A correlator block option that --correlator's correlator does not read is refused in one
line (rtsar.app.cli.block_options; before, `--correlator fft --partition-lines 8` ran with
fft's blocks and said nothing)."""

import pytest

from rtsar.app.cli import main


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp("blocks")
    scene = folder / "s.toml"
    scene.write_text('preset = "tiny"\n[[targets]]\nalong_track_m = 20.0\nslant_range_m = 2000.0\n')
    rec = folder / "rec.h5"
    assert main(["simulate", str(scene), "-o", str(rec), "--pulses", "200"]) == 0
    return rec


@pytest.mark.parametrize(
    "correlator, option, value, readers",
    [
        ("fft", "--partition-lines", "8", "partitioned and nonuniform correlators"),
        ("direct", "--partition-lines", "8", "partitioned and nonuniform correlators"),
        ("partitioned", "--tail-block-lines", "64", "nonuniform correlator"),
        ("nonuniform", "--fft-length", "1024", "fft correlator"),
    ],
)
def test_a_block_option_the_correlator_does_not_read_is_refused(
    correlator, option, value, readers, recording, tmp_path, capsys
):
    out = tmp_path / "img.h5"
    args = ["process", str(recording), "-o", str(out), "--correlator", correlator, option, value]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert f"{option} sets the block of the {readers}; the {correlator} correlator does not" in err
    assert not out.exists()


def test_the_options_a_correlator_reads_are_taken(recording, tmp_path, capsys):
    """The same options with the correlators that read them: the recording is focused."""
    for correlator, option, value in (
        ("partitioned", "--partition-lines", "8"),
        ("nonuniform", "--tail-block-lines", "64"),
        ("fft", "--fft-length", "1024"),
    ):
        out = tmp_path / f"{correlator}.h5"
        args = ["process", str(recording), "--correlator", correlator, option, value]
        assert main(args + ["-o", str(out)]) == 0 and out.exists()


@pytest.mark.parametrize("given, runs", [([], "nonuniform"), (["--fft-length", "1024"], "fft")])
def test_demo_runs_fft_where_fft_length_is_given(given, runs, tmp_path, monkeypatch):
    """`rtsar demo` runs nonuniform by default, fft where --fft-length asks for it (a cold
    review: `demo --fft-length 1024` was refused for a --correlator nobody gave)."""
    from rtsar.app.cli import replay

    seen = []
    monkeypatch.setattr(replay, "cache_dir", lambda: tmp_path)
    monkeypatch.setattr(replay, "simulate_to", lambda scene, path: path.touch())
    monkeypatch.setattr(replay, "cmd_replay", lambda args: seen.append(args.correlator) or 0)
    assert main(["demo", *given]) == 0
    assert seen == [runs]


def test_a_block_option_the_recording_s_correlator_does_not_read_is_refused(
    recording, tmp_path, capsys
):
    """Without --correlator, process (and replay --rate max, which make no live choice) run
    the recording's correlator, fft in the presets: --partition-lines is refused there, and
    taken by a paced replay, which runs nonuniform (a cold review: a configured correlator
    was not checked)."""
    out = tmp_path / "img.h5"
    for command in (["process"], ["replay", "--rate", "max", "--endpoint", f"ipc://{tmp_path}/p"]):
        args = [*command, str(recording), "-o", str(out), "--partition-lines", "8"]
        assert main(args) == 2
        said = capsys.readouterr().err
        assert "--partition-lines sets the block of the partitioned and nonuniform" in said
        assert "the recording's fft correlator does not read it" in said and not out.exists()
    args = ["replay", str(recording), "--rate", "4", "-o", str(out), "--partition-lines", "8"]
    assert main(args + ["--lens", "numpy", "--endpoint", f"ipc://{tmp_path}/q.pub"]) == 0
    assert out.exists()


def test_a_live_run_that_keeps_fft_refuses_partition_lines(recording, tmp_path, capsys):
    """A paced replay runs nonuniform where its configuration names fft, but keeps fft with
    --fft-length: --partition-lines is then refused when the granularity is chosen (before,
    ignored without a word)."""
    out = tmp_path / "img.h5"
    args = ["replay", str(recording), "--rate", "4", "--fft-length", "128", "-o", str(out)]
    args += ["--partition-lines", "8", "--lens", "numpy", "--endpoint", f"ipc://{tmp_path}/r"]
    assert main(args) == 2
    said = capsys.readouterr().err
    assert "--partition-lines sets the block of the partitioned and nonuniform" in said
    assert "this run keeps fft, which does not read it" in said and not out.exists()
