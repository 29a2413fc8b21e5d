"""Recording format v2: every channel of a shot is recorded, replayed and processed exactly as
the live path feeds it to the corrections (issue 13)."""

import argparse
import json

import h5py
import numpy as np
import pytest

from rtsar.app.cli import main
from rtsar.app.cli.options import correction_chain
from rtsar.scene import Simulator, load_scene
from rtsar.scene.correction_context import correction_context
from rtsar.sinks.image_file import read_image
from rtsar.sinks.io import open_recording
from rtsar.stream.engine import StreamProcessor

SCENE = """
preset = "crouch-sal"
pulses = 200
seed = 1
[processor]
aperture_pulses = 64
range_bins = 512
[geometry]
along_track_step_m = 50e-6
[[targets]]
along_track_m = 0.0
slant_range_m = 1.5
[[effects]]
name = "start_frequency_jitter"
std_hz = 10e9
seed = 3
[[effects]]
name = "chirp_nonlinearity"
sine_fraction = 0.01
sine_periods = 5.0
[[effects]]
name = "reference_interferometer"
[[effects]]
name = "hcn_cell"
oversampling = 8
"""
CHANNELS = ["hcn_cell", "reference_interferometer"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    d = tmp_path_factory.mktemp("channels")
    scene_file, rec = d / "s.toml", d / "r.h5"
    scene_file.write_text(SCENE)
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    return d, load_scene(scene_file), rec


def live_image(scene, specs):
    """What `rtsar run --scene` computes: the simulator's shots and channels, in micro-batches,
    through the engine with the scene's corrections."""

    class Args:
        correct = specs

    cfg = scene.config
    chain = correction_chain(Args, cfg, scene, scene.start_along_track_m)
    eng = StreamProcessor(cfg, "numpy", None, scene.start_along_track_m, chain)
    sim = Simulator(scene)
    parts = []
    for _ in range(0, scene.pulses, cfg.processor.micro_batch):
        main_ch, aux = sim.block_with_aux(cfg.processor.micro_batch)
        parts.append(eng.push(main_ch, aux).lines)
    parts.append(eng.flush().lines)
    return np.concatenate(parts)


def test_simulate_records_every_channel_bit_for_bit(recorded):
    _, scene, rec = recorded
    main_ch, aux = Simulator(scene).block_with_aux(scene.pulses)
    with open_recording(rec) as r:
        assert sorted(r.channels) == CHANNELS
        np.testing.assert_array_equal(r.shots[...], main_ch)
        for name in CHANNELS:
            np.testing.assert_array_equal(r.channels[name][...], aux[name])
    with h5py.File(rec) as f:
        assert f.attrs["format_version"] == 2
        described = {c["name"]: c for c in json.loads(f.attrs["channels"])}
        wf = scene.config.waveform
        assert described["hcn_cell"]["samples_per_shot"] == 8 * wf.samples_per_shot
        assert described["hcn_cell"]["sample_rate_hz"] == 8 * wf.sample_rate_hz


@pytest.mark.parametrize("specs", [["linearize"], ["hcn"], ["hcn", "linearize"]])
def test_process_applies_channel_corrections_as_the_live_path(recorded, specs):
    d, scene, rec = recorded
    img = d / f"{'-'.join(specs)}.h5"
    args = ["process", str(rec), "-o", str(img), "--lens", "numpy"]
    for s in specs:
        args += ["--correct", s]
    assert main(args) == 0
    got, _, _, attrs = read_image(img)
    np.testing.assert_array_equal(got, live_image(scene, specs))
    assert attrs["complete"]


def test_replay_feeds_the_channels_to_the_pipeline(recorded):
    d, scene, rec = recorded
    out = d / "replay.h5"
    ep = "ipc://" + str(d / "pub")
    args = ["replay", str(rec), "--rate", "max", "--endpoint", ep, "-o", str(out)]
    assert main(args + ["--lens", "numpy", "--correct", "hcn", "--correct", "linearize"]) == 0
    got, _, _, _ = read_image(out)
    ref = live_image(scene, ["hcn", "linearize"])
    assert got.shape == ref.shape
    # Other micro-batch boundaries than process: same per-pulse corrections to float32 rounding.
    assert np.abs(got - ref).max() <= 1e-5 * np.abs(ref).max()


def test_a_correction_without_its_channel_is_refused_in_one_line(tmp_path, capsys):
    scene_file, rec = tmp_path / "s.toml", tmp_path / "r.h5"
    scene_file.write_text(SCENE.split("[[effects]]")[0])  # no effect: main channel only
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    capsys.readouterr()
    args = ["process", str(rec), "-o", str(tmp_path / "i.h5"), "--correct", "hcn"]
    assert main(args + ["--lens", "numpy"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--correct hcn reads the auxiliary channel(s) hcn_cell" in err
    assert "main channel only" in err and "\n" not in err
    assert not (tmp_path / "i.h5").exists()


def test_version_1_recordings_still_read(recorded, tmp_path):
    _, scene, rec = recorded
    old = tmp_path / "v1.h5"
    with h5py.File(rec) as src, h5py.File(old, "w") as dst:
        for name in ("shots", "pulse_index", "time_s", "along_track_m"):
            dst[name] = src[name][...]
        for key in ("format", "config", "scene", "rtsar_version"):
            dst.attrs[key] = src.attrs[key]
        dst.attrs["format_version"] = 1
    with open_recording(old) as r:
        assert r.channels == {} and r.pulses == scene.pulses


def test_a_recording_whose_channels_disagree_is_refused(recorded, tmp_path):
    _, _, rec = recorded
    bad = tmp_path / "bad.h5"
    bad.write_bytes(rec.read_bytes())
    with h5py.File(bad, "a") as f:
        del f["channels/hcn_cell"]
    with pytest.raises(ValueError, match="channels listed"):
        open_recording(bad)


def test_correction_context_comes_from_the_recorded_scene(recorded):
    _, scene, rec = recorded
    with open_recording(rec) as r:
        got = correction_context(r.scene_object(), r.start_along_track_m)
    want = correction_context(scene)
    assert got.retro_m == want.retro_m and got.ri_delay_s == want.ri_delay_s


def test_pra_default_finds_the_recorded_scenes_brightest_point(tmp_path, capsys):
    """`--correct pra` without a position: the recorded scene's brightest point, as live."""
    scene_file, rec, img = tmp_path / "s.toml", tmp_path / "r.h5", tmp_path / "i.h5"
    scene_file.write_text(
        'preset = "tiny"\n[[targets]]\nalong_track_m = 0.0\nslant_range_m = 2000.0\n'
        "[[targets]]\nalong_track_m = 10.0\nslant_range_m = 1950.0\namplitude = 0.5\n"
    )
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    assert main(["process", str(rec), "-o", str(img), "--correct", "pra", "--lens", "numpy"]) == 0
    got, _, _, _ = read_image(img)
    np.testing.assert_array_equal(got, live_image(load_scene(scene_file), ["pra"]))
    # What the correction did is said (a cold review: process said nothing of PGA's outcome) and
    # kept with the image.
    assert main(["process", str(rec), "-o", str(img), "--correct", "pga", "--lens", "numpy"]) == 0
    said = capsys.readouterr().err
    assert "corrections: pga.pulses_in" in said and "pga.reasons." in said
    counted = json.loads(read_image(img)[3]["correction_counters"])
    assert counted["pga.pulses_in"] == counted["pga.pulses_out"] > 0


def test_correlator_with_physical_mode_is_refused(recorded, capsys):
    d, _, rec = recorded
    args = ["process", str(rec), "-o", str(d / "x.h5"), "--physical", "range"]
    assert main(args + ["--correlator", "fft", "--lens", "numpy"]) == 2
    assert "--correlator fft does not apply with --physical" in capsys.readouterr().err


def test_a_multichannel_instrument_is_corrected_live_like_its_recording(recorded, tmp_path):
    """The fake instrument sends every channel of a crouch-sal recording (main, reference
    interferometer, HCN cell over 8 frame channels); `run --serial --scene` takes the channel
    map from the scene and corrects with hcn + linearize: the image and its positions equal
    `process` of the recording."""
    import threading

    from tools_loader import load_tool

    from rtsar.sources.channel_map import ChannelMap

    d, scene, rec = recorded
    ref = tmp_path / "ref.h5"
    corrections = ["--correct", "hcn", "--correct", "linearize", "--lens", "numpy"]
    assert main(["process", str(rec), "-o", str(ref)] + corrections) == 0
    fake = load_tool("fake_instrument")
    with open_recording(rec) as r:
        cmap = fake.recording_map(r)
        blocks = list(fake.recording_shots(r))
    assert cmap == ChannelMap.for_scene(scene)
    assert cmap.text == "main,hcn_cell*8,reference_interferometer"
    server = fake.listen("127.0.0.1:0")
    port = server.getsockname()[1]

    def serve():
        with server:
            fake.serve_tcp(server, blocks, 2000.0, start_delay_s=0.1)

    threading.Thread(target=serve, daemon=True).start()
    img = tmp_path / "live.h5"
    args = ["run", "--serial", f"socket://127.0.0.1:{port}", "--scene", str(d / "s.toml")]
    args += ["--no-reconnect", "--duration", "3", "-o", str(img)]
    args += ["--endpoint", "ipc://" + str(tmp_path / "pub")]
    assert main(args + corrections) == 1  # the instrument hung up after its last shot
    got, az, _, attrs = read_image(img)
    want, want_az, _, _ = read_image(ref)
    np.testing.assert_allclose(az, want_az)
    assert got.shape == want.shape
    assert np.abs(got - want).max() <= 1e-5 * np.abs(want).max()
    assert json.loads(attrs["counters"])["wrong_length"] == 0


def test_channel_maps_parse_pack_and_unpack():
    from rtsar.sources.channel_map import ChannelMap

    m = ChannelMap.parse("main, ri ,hcn*3")
    assert m.text == "main,ri,hcn*3" and m.frame_channels == 5 and m.aux_names == ["ri", "hcn"]
    rng = np.random.default_rng(0)
    main_ch = rng.standard_normal((4, 6)).astype(np.complex64)
    aux = {"ri": main_ch * 2, "hcn": rng.standard_normal((4, 18)).astype(np.complex64)}
    frames = m.pack(main_ch, aux)
    assert frames.shape == (4, 5, 6)
    back, back_aux = m.unpack(frames)
    np.testing.assert_array_equal(back, main_ch)
    for k in aux:
        np.testing.assert_array_equal(back_aux[k], aux[k])
    for bad in ("ri,hcn", "main,main", "main*2,ri", "main,hcn*x", "main,bad name"):
        with pytest.raises(ValueError):
            ChannelMap.parse(bad)
    with pytest.raises(ValueError, match="not a multiple"):
        ChannelMap.for_channels(6, {"odd": 7})


def test_a_slow_live_scene_says_how_to_look_sooner(capsys):
    from rtsar.app.cli.streaming import warn_slow_first_line
    from rtsar.scene import load_scene

    # 160 pulses at 5 Hz: 32 s; the live run's fft block at this rate is its smallest (M = N,
    # B = 1), so no block adds to it (before the run chose M: 353 lines, "71 s", said wrongly)
    scene = load_scene("insal-ridge")
    warn_slow_first_line(scene, "insal-ridge")
    err = capsys.readouterr().err
    assert "first image line comes after 32 s" in err and "rtsar replay REC.h5 --rate F" in err
    assert "--correlator nonuniform" not in err
    # --fft-length 512 fixes the block at 353 lines: the first line after 353 pulses, 71 s
    args = argparse.Namespace(partition_lines=None, fft_length=512)
    warn_slow_first_line(scene, "insal-ridge", args)
    err = capsys.readouterr().err
    assert "first image line comes after 71 s" in err and "--correlator nonuniform" in err
    # swath workers keep the configuration's correlator and block (fft, M = 512): 71 s too
    args = argparse.Namespace(partition_lines=None, fft_length=None, swath_workers=2)
    warn_slow_first_line(scene, "insal-ridge", args)
    assert "first image line comes after 71 s" in capsys.readouterr().err
    warn_slow_first_line(load_scene("demo"), "demo")  # 512 pulses at 1600 Hz: no note
    assert capsys.readouterr().err == ""


def test_reference_region_channels_round_trip(tmp_path):
    """The INO patent's two reference receivers: recorded by simulate, fed by process to
    `--correct reference_region` exactly as the live path feeds them."""
    from rtsar.lens.plan import make_plan
    from rtsar.presets import preset

    cfg = preset("zhao-insal").with_processor(aperture_pulses=96, range_bins=32)
    rm = make_plan(cfg).range_m
    r0 = rm[16] + 0.37 * (rm[1] - rm[0])
    depth = 24 * cfg.waveform.range_resolution_m
    scene_file, rec, img = tmp_path / "s.toml", tmp_path / "r.h5", tmp_path / "i.h5"
    scene_file.write_text(
        'preset = "zhao-insal"\nseed = 1\npulses = 160\nstart_along_track_m = -0.004\n'
        "[processor]\naperture_pulses = 96\nrange_bins = 32\n"
        f"[[targets]]\nalong_track_m = 0.0\nslant_range_m = {float(r0)!r}\n"
        '[[effects]]\nname = "reference_region"\nalpha_walk_m = 1.5e-8\nroll_walk_rad = 5e-7\n'
        f"seed = 3\nscatterers_per_cell = 2.0\nregion_depth_m = {float(depth)!r}\n"
    )
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    with open_recording(rec) as r:
        assert sorted(r.channels) == ["reference_rx1", "reference_rx2"]
    args = ["process", str(rec), "-o", str(img), "--lens", "numpy"]
    assert main(args + ["--correct", "reference_region"]) == 0
    got, _, _, _ = read_image(img)
    np.testing.assert_array_equal(got, live_image(load_scene(scene_file), ["reference_region"]))


def test_pra_finds_the_brightest_point_of_a_recording_without_a_scene(tmp_path, capsys):
    """A recording with no scene (a real instrument's): `--correct pra` takes the brightest
    point of a first pass, reports it, and focuses like pra at the true retro-reflector."""
    import h5py

    scene_file, rec, img = tmp_path / "s.toml", tmp_path / "r.h5", tmp_path / "i.h5"
    scene_file.write_text(
        'preset = "tiny"\n[[targets]]\nalong_track_m = 0.0\nslant_range_m = 2000.0\n'
        "[[targets]]\nalong_track_m = 10.0\nslant_range_m = 1950.0\namplitude = 0.5\n"
        '[[effects]]\nname = "piston"\nrandom_walk_rad = 0.3\nseed = 4\n'
    )
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    with h5py.File(rec, "a") as f:
        f.attrs["scene"] = "{}"  # what an instrument's recording holds
    assert main(["process", str(rec), "-o", str(img), "--correct", "pra", "--lens", "numpy"]) == 0
    err = capsys.readouterr().err
    assert "taking the brightest point" in err and "slant range 2000" in err
    got, _, _, _ = read_image(img)
    want = live_image(load_scene(scene_file), ["pra"])
    # Focused as well (both points' peaks within 1 %); the image may sit a line off, as the
    # found point sits within a cell of the true retro-reflector.
    for im in (got, want):
        assert np.abs(im).max() > 0.9
    for sl in (np.s_[:, 28:36], np.s_[:, 12:20]):
        assert np.abs(got[sl]).max() == pytest.approx(np.abs(want[sl]).max(), rel=0.01)
    k_got = np.unravel_index(np.argmax(np.abs(got)), got.shape)
    k_want = np.unravel_index(np.argmax(np.abs(want)), want.shape)
    assert k_got[1] == k_want[1] and abs(k_got[0] - k_want[0]) <= 1
