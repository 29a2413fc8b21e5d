"""The user-facing contract: simulate → process → quicklook, file layouts, clear errors."""

import h5py
import numpy as np
import pytest

from rtsar.analysis import relative_rms
from rtsar.app.cli import main
from rtsar.scene import Simulator, load_scene
from rtsar.sinks.image_file import read_image
from rtsar.sinks.io import open_recording
from rtsar.stream.engine import process_block

SCENE = """
preset = "tiny"
seed = 3
[processor]
correlator = "{correlator}"
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
[[targets]]
along_track_m = 10.0
slant_range_m = 1950.0
amplitude = 0.5
phase_rad = 1.0
[[effects]]
name = "noise"
snr_db = 0.0
"""


@pytest.mark.parametrize("correlator, lens", [("fft", "auto"), ("direct", "numpy")])
def test_simulate_process_quicklook(tmp_path, capsys, correlator, lens):
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(SCENE.format(correlator=correlator))
    rec, img, png = tmp_path / "r.h5", tmp_path / "i.h5", tmp_path / "i.png"
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(img), "--lens", lens]) == 0
    assert main(["quicklook", str(img), "-o", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    scene = load_scene(scene_file)
    with open_recording(rec) as r:
        assert r.pulses == scene.pulses and r.config == scene.config
        assert r.scene["targets"][1]["phase_rad"] == pytest.approx(1.0)
    image, az, rg, attrs = read_image(img)
    assert image.dtype == np.complex64 and image.shape == (len(az), len(rg))
    assert attrs["format"] == "rtsar-image" and "aperture_pulses" in attrs["config"]
    # The file equals the engine run on the same shots (process is the streaming engine).
    shots = Simulator(scene).block(scene.pulses)
    expect, az2, rg2 = process_block(scene.config, shots, "numpy", scene.start_along_track_m)
    assert relative_rms(image, expect) < 1e-5
    np.testing.assert_allclose(az, az2)
    np.testing.assert_allclose(rg, rg2)
    # The brightest pixel is the unit target at (0 m, 2000 m) within a resolution cell.
    ia, ir = np.unravel_index(np.argmax(np.abs(image)), image.shape)
    assert abs(az[ia]) <= scene.config.azimuth_resolution_m()
    assert abs(rg[ir] - 2000.0) <= scene.config.waveform.range_resolution_m


def test_errors_are_clear(tmp_path, capsys):
    assert main(["process", str(tmp_path / "none.h5"), "-o", str(tmp_path / "x.h5")]) == 2
    assert "no such file" in capsys.readouterr().err
    junk = tmp_path / "junk.h5"
    with h5py.File(junk, "w") as f:
        f["x"] = 1
    assert main(["quicklook", str(junk), "-o", str(tmp_path / "x.png")]) == 2
    assert "expected an rtsar-image file" in capsys.readouterr().err
    with h5py.File(junk, "a") as f:  # a recording where an image is wanted, and back
        f.attrs["format"] = "rtsar-recording"
    assert main(["quicklook", str(junk), "-o", str(tmp_path / "x.png")]) == 2
    assert "; a recording: `rtsar process REC.h5 -o IMG.h5` focuses it" in capsys.readouterr().err
    with h5py.File(junk, "a") as f:
        f.attrs["format"] = "rtsar-image"
    assert main(["export", str(junk), "--cphd", str(tmp_path / "x.cphd")]) == 2
    assert "; an image: `rtsar quicklook` draws it" in capsys.readouterr().err
    assert main(["simulate", str(tmp_path / "nope.toml"), "-o", str(tmp_path / "r.h5")]) == 2


def test_help_explains(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for word in ("simulate", "process", "quicklook", "run", "bench"):
        assert word in out
    assert main(["presets"]) == 0
    assert "psaltis-max" in capsys.readouterr().out


def test_nonfinite_shots_are_zeroed_counted_and_never_reach_the_image():
    from rtsar.presets import preset
    from rtsar.scene import point_scene
    from rtsar.stream.engine import StreamProcessor

    cfg = preset("tiny")
    scene = point_scene(cfg, [0.0], [2000.0])
    shots = Simulator(scene).block(scene.pulses)
    clean, _, _ = process_block(cfg, shots, "numpy", scene.start_along_track_m)
    bad = shots.copy()
    bad[5, 3] = np.nan
    bad[9, 0] = np.inf
    eng = StreamProcessor(cfg, "auto", start_along_track_m=scene.start_along_track_m)
    image = np.concatenate(
        [eng.push(bad[i : i + 16]).lines for i in range(0, len(bad), 16)] + [eng.flush().lines]
    )
    assert eng.nonfinite_pulses == 2 and eng.pulses_in == len(bad)
    assert np.isfinite(image).all() and image.shape == clean.shape
    # Dropping two of 64 aperture pulses costs a little peak, nothing more.
    assert np.abs(image).max() == pytest.approx(np.abs(clean).max(), rel=0.1)


def test_user_mistakes_get_one_line_errors(tmp_path, capsys, monkeypatch):
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(SCENE.format(correlator="fft").replace("2000.0", "20000.0"))
    rec = tmp_path / "r.h5"
    assert main(["simulate", str(scene_file), "-o", str(rec), "--pulses", "0"]) == 2
    assert "--pulses" in capsys.readouterr().err
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    assert "outside the range window" in capsys.readouterr().err
    monkeypatch.setenv("RTSAR_OPENCL_DEVICE", "no-such-device-xyz")
    assert main(["process", str(rec), "-o", str(tmp_path / "i.h5")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("rtsar: error:") and "Traceback" not in err


def test_quicklook_true_aspect(tmp_path):
    """--true-aspect: equal metres on both axes (the image's shape follows its extent)."""
    from rtsar.app.quicklook import save_quicklook

    img = np.zeros((40, 10), np.complex64)  # all below the dynamic range: black
    az, rg = np.arange(40) * 1.0, 100.0 + np.arange(10) * 1.0  # 40 m along track, 10 m range
    plain, true = tmp_path / "plain.png", tmp_path / "true.png"
    save_quicklook(plain, img, az, rg)
    save_quicklook(true, img, az, rg, true_aspect=True)
    import matplotlib.image as mpimg

    def dark_box(path):  # the image area: black pixels left of the colour bar
        a = mpimg.imread(path)[..., :3].mean(axis=2)
        a = a[:, : int(0.7 * a.shape[1])]
        rows, cols = np.nonzero(a < 0.05)
        return np.ptp(rows), np.ptp(cols)

    h, w = dark_box(true)
    assert h / w == pytest.approx(4.0, rel=0.1)  # 40 m by 10 m drawn 4:1
    assert plain.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_outputs_are_checked_before_the_work(tmp_path, capsys):
    """An output that cannot be written is reported at once (exit 2), not after the work."""
    import time

    bad = str(tmp_path / "no-such-folder" / "x")
    for args in (
        ["table1", "--out", bad + ".md"],
        ["bench", "--json", bad + ".json"],
        ["run", "--duration", "30", "-o", bad + ".h5", "--endpoint", "ipc://" + bad + ".pub"],
        ["subscribe", "ipc://" + str(tmp_path / "nothing"), "-o", bad + ".h5"],
    ):
        t0 = time.perf_counter()
        assert main(args) == 2, args
        assert time.perf_counter() - t0 < 5, args
        assert "does not exist" in capsys.readouterr().err
    # process told it only after preparing its lens (a new user's review): now before
    rec, scene_file = tmp_path / "rec.h5", tmp_path / "s.toml"
    scene_file.write_text(SCENE.format(correlator="fft"))
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    capsys.readouterr()
    assert main(["process", str(rec), "-o", bad + ".h5"]) == 2
    err = capsys.readouterr().err
    assert "the folder" in err and "does not exist" in err and "lens" not in err, err


def test_an_output_never_replaces_the_commands_input(tmp_path, capsys, monkeypatch):
    """From a cold review: `process rec.h5 -o rec.h5` (and `replay … -o`, `simulate s.toml -o
    s.toml`, `quicklook img.h5 -o img.h5`) replaced the input by the output, exit 0; an
    instrument's raw recording may be irreplaceable.  Refused before any work (exit 2), whatever
    the spelling of the name (./x, a symlink); the input is untouched."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(SCENE.format(correlator="fft"))
    assert main(["simulate", "s.toml", "-o", "rec.h5", "--pulses", "300"]) == 0
    (tmp_path / "link.h5").symlink_to(tmp_path / "rec.h5")
    assert main(["process", "rec.h5", "-o", "img.h5", "--lens", "numpy"]) == 0
    before = {p: (tmp_path / p).read_bytes() for p in ("rec.h5", "s.toml", "img.h5")}
    capsys.readouterr()
    for args in (
        ["process", "rec.h5", "-o", "rec.h5"],
        ["process", "rec.h5", "-o", "./rec.h5"],
        ["process", "link.h5", "-o", "rec.h5"],
        ["replay", "rec.h5", "--rate", "max", "-o", "rec.h5", "--endpoint", "inproc://x"],
        ["simulate", "s.toml", "-o", "s.toml"],
        ["quicklook", "img.h5", "-o", "img.h5"],
        ["export", "rec.h5", "--cphd", "rec.h5"],
        ["spotlight", "rec.h5", "-o", "out.h5", "--png", "out.h5"],
        # From a cold read of the guard: quicklook's --height PNG is an output too.
        ["quicklook", "img.h5", "-o", "x.png", "--height", "img.h5"],
        ["quicklook", "img.h5", "-o", "same.png", "--height", "same.png"],
        ["projective", "--simulate", "s.toml", "-o", "s.toml"],
    ):
        assert main(args) == 2, args
        err = capsys.readouterr().err
        assert "choose another output name" in err or "two outputs" in err, (args, err)
    assert {p: (tmp_path / p).read_bytes() for p in before} == before
    # A built-in scene's name is not a file: an output of that name replaces nothing.
    from rtsar.app.cli import build_parser
    from rtsar.app.cli.outputs import check_outputs_spare_inputs

    check_outputs_spare_inputs(build_parser().parse_args(["simulate", "tiny", "-o", "tiny"]))


def test_an_image_says_how_it_was_focused(tmp_path, capsys):
    """From a cold review: `process --physical range` wrote the same attributes as the ideal
    image (correlator 'fft', no physical key) though the images differ by 0.8 of the peak, and
    said '(… fft correlator)'.  Images now record the corrections and the physical mode, from
    `process` and, through the strip header, from a subscriber."""
    import json

    from rtsar.presets import preset as named
    from rtsar.sinks.record import StripRecorder

    (tmp_path / "s.toml").write_text(SCENE.format(correlator="fft"))
    rec, ideal, phys = (str(tmp_path / n) for n in ("rec.h5", "ideal.h5", "phys.h5"))
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", rec, "--pulses", "300"]) == 0
    assert main(["process", rec, "-o", ideal, "--lens", "numpy"]) == 0
    assert main(["process", rec, "-o", phys, "--lens", "numpy", "--physical", "range"]) == 0
    assert "physical CCD, carrier in range" in capsys.readouterr().out
    a, b = read_image(ideal)[3], read_image(phys)[3]
    assert (a["physical"], a["corrections"]) == ("", "")
    assert json.loads(b["physical"])["carrier"] == "range"
    # A subscriber's image: what the publisher's strip header says (never trusted further).
    bins = 4
    head = {
        "stream_id": "s",
        "range_bins": bins,
        "range_first_m": 100.0,
        "range_step_m": 1.0,
        "azimuth_step_m": 1.0,
        "azimuth_first_m": 0.0,
        "first_line": 0,
        "config": named("tiny").to_dict(),
    }
    lines = np.ones((2, bins), np.complex64)
    for n, processing, want in (
        (
            "sub.h5",
            {"lens": "opencl", "correlator": "fft", "corrections": ["pra", "pga"], "physical": {}},
            ("opencl", "fft", "pra,pga", ""),
        ),
        ("odd.h5", {"lens": 3, "correlator": "fft", "corrections": [], "physical": None}, None),
    ):
        sub = StripRecorder(tmp_path / n, "test")
        sub.add_strip({**head, "processing": processing}, lines)
        sub.finish()
        attrs = read_image(tmp_path / n)[3]
        got = tuple(attrs.get(k) for k in ("lens", "correlator", "corrections", "physical"))
        assert got == (want or (None,) * 4), n


def test_version():
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0


def test_the_status_line_before_the_first_strip_says_so():
    """From a cold review: until the first strip a live run's status read 'latency median nan
    ms p99 nan ms' (at a few Hz, for a minute)."""
    from rtsar.app.live import format_status

    d = {
        "counters": {"pulses_processed": 10},
        "elapsed_s": 2.0,
        "pulse_rate_hz": 5.0,
        "latency_recent_median_ms": float("nan"),
        "latency_recent_p99_ms": float("nan"),
    }
    line = format_status(d)
    assert "nan" not in line and "no strip yet" in line
    d.update(latency_recent_median_ms=3.5, latency_recent_p99_ms=9.0)
    assert "latency median   3.50 ms p99   9.00 ms" in format_status(d)


def test_option_values_are_named_in_their_errors(tmp_path, capsys, monkeypatch):
    """From a cold review: `replay --rate foo` and `--correct pra:along_track_m=abc` answered
    "could not convert string to float: 'foo'" (no option, no key named); `quicklook -o snap`
    failed on the temporary file's name ("Format 'partial-…' is not supported")."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "s.toml").write_text(SCENE.format(correlator="fft"))
    assert main(["simulate", "s.toml", "-o", "rec.h5", "--pulses", "300"]) == 0
    capsys.readouterr()
    for args, said in (
        (["replay", "rec.h5", "--rate", "foo"], "rate must be 'real', 'max' or a factor > 0"),
        (
            ["process", "rec.h5", "-o", "x.h5", "--correct", "pra:along_track_m=abc,range_m=2e3"],
            "correction pra: along_track_m must be a number, got 'abc'",
        ),
        (
            ["process", "rec.h5", "-o", "x.h5", "--correct", "pga:block_pulses=many"],
            "correction pga: block_pulses must be a number",
        ),
    ):
        assert main(args) == 2, args
        assert said in capsys.readouterr().err, args
    assert main(["process", "rec.h5", "-o", "img.h5", "--lens", "numpy"]) == 0
    assert main(["quicklook", "img.h5", "-o", "snap"]) == 0
    assert (tmp_path / "snap").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # no suffix: a PNG


def test_view_refuses_what_subscribe_and_quicklook_refuse(capsys):
    """From a cold review: `view --timeout 0` and `--dynamic-range-db -1` were taken without a
    word (subscribe and quicklook refuse them)."""
    for args in (["view", "--timeout", "0"], ["view", "--dynamic-range-db", "-1", "--png", "x"]):
        assert main(args) == 2
        assert "must be > 0" in capsys.readouterr().err


def test_swath_workers_with_corrections_are_refused_before_any_worker_starts(tmp_path, capsys):
    """From a cold review: refused only after "starting 2 swath workers …" (1.5 s in)."""
    (tmp_path / "s.toml").write_text(SCENE.format(correlator="fft"))
    rec = str(tmp_path / "rec.h5")
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", rec, "--pulses", "300"]) == 0
    capsys.readouterr()
    args = ["replay", rec, "--rate", "max", "--swath-workers", "2", "--correct", "pga"]
    assert main(args) == 2
    captured = capsys.readouterr()
    assert "--swath-workers runs without --correct" in captured.err
    assert "starting" not in captured.out + captured.err


def test_knobs_that_would_do_nothing_or_less_than_asked_are_said(tmp_path, capsys):
    """From a cold review: `--full-scale 0` without --physical was taken (and ignored), and
    `--range-migration-taps 4` on a critically sampled range axis without a word."""
    (tmp_path / "s.toml").write_text(SCENE.format(correlator="fft"))
    rec, out = str(tmp_path / "rec.h5"), str(tmp_path / "img.h5")
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", rec, "--pulses", "300"]) == 0
    capsys.readouterr()
    assert main(["process", rec, "-o", out, "--full-scale", "0"]) == 2
    assert "give --physical" in capsys.readouterr().err
    assert main(["process", rec, "-o", out, "--lens", "numpy", "--range-migration-taps", "4"]) == 0
    assert "critically sampled range axis" in capsys.readouterr().err


def test_an_image_keeps_the_corrections_keys_it_was_focused_with(tmp_path, capsys):
    """From a cold review: `--correct linearize` and `linearize:taps=4` gave different pixels
    with identical attributes (only the stage names were kept).  Images now keep the
    `--correct` values as given, from process, from a live run's -o and through the strip
    header (correction_specs, a JSON list in the order the stages run)."""
    import json

    from rtsar.sinks.record import processing_from_header

    (tmp_path / "s.toml").write_text(SCENE.format(correlator="fft"))
    rec = str(tmp_path / "rec.h5")
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", rec, "--pulses", "300"]) == 0
    given = ["--correct", "pga:follow_walk=0", "--correct", "pra:along_track_m=0,range_m=2000"]
    want = ["pra:along_track_m=0,range_m=2000", "pga:follow_walk=0"]  # the order they run in
    batch_img, live_img = str(tmp_path / "b.h5"), str(tmp_path / "l.h5")
    assert main(["process", rec, "-o", batch_img, "--lens", "numpy", *given]) == 0
    assert main(["replay", rec, "--rate", "max", "-o", live_img, "--lens", "numpy", *given]) == 0
    for img in (batch_img, live_img):
        attrs = read_image(img)[3]
        assert attrs["corrections"] == "pra,pga"
        assert json.loads(attrs["correction_specs"]) == want
    plain = str(tmp_path / "p.h5")
    assert main(["process", rec, "-o", plain, "--lens", "numpy"]) == 0
    assert read_image(plain)[3]["correction_specs"] == ""
    specs = ["pga:follow_walk=0"]
    header = {"processing": {"lens": "numpy", "correlator": "fft", "corrections": ["pga"]}}
    header["processing"].update(correction_specs=specs, physical=None)
    assert json.loads(processing_from_header(header)["correction_specs"]) == ["pga:follow_walk=0"]
    del header["processing"]["correction_specs"]  # an older publisher's header
    assert processing_from_header(header)["correction_specs"] == ""
    capsys.readouterr()


def test_a_correction_value_the_stage_refuses_names_the_correction(tmp_path, capsys):
    """From a cold review: a stage's own check named its class ("PGASettings.follow_walk must
    be 0 or 1", "HCNAligner.max_lines …") or nothing ("taps must be an even integer"), and
    `--correct hcn+linearize`, the stage's name in the README, was an unknown correction."""
    from rtsar.focus.chain import CorrectionChain
    from rtsar.presets import preset as named

    cfg = named("crouch-sal")
    for spec, said in (
        ("pga:follow_walk=2", "correction pga: follow_walk must be 0 or 1"),
        ("hcn:max_lines=-3", "correction hcn: max_lines must be None or an integer >= 1"),
        ("linearize:taps=7", "correction linearize: taps must be an even integer >= 2"),
        ("hcn+linearize", "give those two"),
    ):
        with pytest.raises(ValueError) as caught:
            CorrectionChain.from_specs([spec], cfg)
        assert str(caught.value).startswith(said) or said in str(caught.value), spec
        assert "Settings." not in str(caught.value) and "Aligner." not in str(caught.value)


def test_the_pra_retro_an_image_was_focused_on_is_kept(tmp_path):
    """From a cold review: `--correct pra` without a position took the scene's retro or the
    brightest point of a first pass (printed once), and the image kept only "pra"; images of
    the two differ by the error's own slope (61 lines).  correction_specs holds the point."""
    import json

    from rtsar.focus.chain import CorrectionChain, CorrectionContext
    from rtsar.presets import preset as named

    cfg = named("tiny")
    chain = CorrectionChain.from_specs(["pga", "pra"], cfg, CorrectionContext(retro_m=(1.5, 2e3)))
    assert chain.specs == ["pra:along_track_m=1.5,range_m=2000", "pga"]
    given = CorrectionChain.from_specs(["pra:range_m=1990"], cfg, CorrectionContext(retro_m=(0, 1)))
    assert given.specs == ["pra:along_track_m=0,range_m=1990"]  # what the user gave wins
    (tmp_path / "s.toml").write_text(SCENE.format(correlator="fft"))
    rec = str(tmp_path / "rec.h5")
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", rec, "--pulses", "300"]) == 0
    with h5py.File(rec, "r+") as f:  # a recording without its scene: pra finds the point
        del f.attrs["scene"]
    img = str(tmp_path / "img.h5")
    assert main(["process", rec, "-o", img, "--lens", "numpy", "--correct", "pra"]) == 0
    (spec,) = json.loads(read_image(img)[3]["correction_specs"])
    assert spec.startswith("pra:along_track_m=") and ",range_m=" in spec


def test_a_missing_channel_names_the_options_that_ask_for_it():
    """From a cold read: the channel refusal named `--correct hcn+linearize`, a spelling that
    is itself refused; it names `--correct hcn --correct linearize`."""
    from rtsar.app.live import check_channels_delivered
    from rtsar.focus.chain import CorrectionChain
    from rtsar.focus.spec import correct_option
    from rtsar.presets import preset as named

    assert correct_option("pga") == "--correct pga"
    chain = CorrectionChain.from_specs(["hcn", "linearize"], named("crouch-sal"))
    with pytest.raises(ValueError) as caught:
        check_channels_delivered((), "a ZeroMQ stream", chain)
    assert str(caught.value).startswith("--correct hcn --correct linearize read the auxiliary")


def test_an_hdf5_output_named_like_a_picture_is_refused(tmp_path, capsys):
    """From a new-user review: `process rec.h5 -o x.png` wrote an HDF5 image under a picture's
    name without a word."""
    for args in (
        ["process", "rec.h5", "-o", str(tmp_path / "x.png")],
        ["simulate", "tiny", "-o", str(tmp_path / "x.CSV")],
        ["run", "--duration", "1", "-o", str(tmp_path / "x.nitf")],
    ):
        assert main(args) == 2, args
        assert "writes an HDF5 file (.h5)" in capsys.readouterr().err, args
    assert list(tmp_path.iterdir()) == []


def test_quicklook_chooses_its_aspect_and_says_any_stretch():
    """Issue 37: a short run's quicklook was stretched ~13:1 into streaks, unsaid.  By default
    the picture is drawn 1:1 where that fits a figure; where it does not, the title gives the
    stretch, measured on the drawn axes."""
    from rtsar.app.quicklook import image_axes, quicklook_figure, vertical_stretch

    img = np.ones((40, 10), np.complex64)
    tall = quicklook_figure(img, np.arange(40) * 1.0, 100.0 + np.arange(10), title="t")
    k = vertical_stretch(tall, tall.axes[0], image_axes(np.arange(40.0), np.arange(10.0)))
    assert k < 0.9 and f"{k:.2g}x" in tall.axes[0].get_title()  # 40 m by 10 m: 1:1 is 29 in
    short_az, rg = np.arange(40) * 0.05, 1000.0 + np.arange(300) * 3.0  # 2 m by 900 m
    wide = quicklook_figure(np.ones((40, 300), np.complex64), short_az, rg, title="short run")
    ax = wide.axes[0]
    k = vertical_stretch(wide, ax, image_axes(short_az, rg))
    assert k > 10  # filled, not a 1:450 sliver ...
    assert f"{k:.2g}x" in ax.get_title() and ax.get_title().startswith("short run")  # ... said
    square = quicklook_figure(img[:10], np.arange(10) * 1.0, 100.0 + np.arange(10), title="sq")
    assert square.axes[0].get_title() == "sq"  # 10 m by 10 m: drawn 1:1, nothing to say
    assert vertical_stretch(square, square.axes[0], image_axes(np.arange(10.0), np.arange(10.0)))


def test_presets_give_a_squinted_plans_resolution_over_the_aperture_a_column_uses(capsys):
    """`rtsar presets` said ρA 6.98 m for radarsat1 over all 716 CCD rows, where `import` says
    the aperture is 668 pulses (943 Hz of Doppler): the CCD holds the aperture plus the rows
    the squinted beam's centre walks across the swath (a new user's review).  ρA = λR/2L
    (Crouch eq. 4.8) with L = 668 steps, λ = c / 5.3 GHz, from the instrument's numbers."""
    import json

    assert main(["presets", "--json"]) == 0
    rows = {r["preset"]: r for r in json.loads(capsys.readouterr().out)}
    rs1 = rows["radarsat1"]
    assert (rs1["aperture_pulses"], rs1["column_aperture_pulses"]) == (716, 668)
    step_m = 7062.0 / 1256.98
    wavelength_m = 299_792_458.0 / 5.3e9
    expected = wavelength_m * rs1["slant_range_m"] / (2 * 668 * step_m)
    assert rs1["azimuth_resolution_m"] == pytest.approx(expected, rel=1e-3)  # 7.48 m
    assert rs1["synthetic_aperture_m"] == pytest.approx(668 * step_m, rel=1e-3)
    broadside = rows["psaltis-max"]  # all N rows
    assert broadside["column_aperture_pulses"] == broadside["aperture_pulses"] == 512
