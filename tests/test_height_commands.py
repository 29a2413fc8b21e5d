"""3D from the commands: `process`/`replay --height insal` write height maps beside the image,
`quicklook --height` draws them (issue 13)."""

import json
import re
import shutil

import h5py
import numpy as np
import pytest
from conftest import free_port

from rtsar.app.cli import main
from rtsar.instrument import SECOND_RECEIVER
from rtsar.scene.correction_context import insal_geometry
from rtsar.scene.relief import default_spacing_m, ridge, surface_scene, zhao_config
from rtsar.scene.simulator import Simulator
from rtsar.sinks.image_file import read_heights, read_image
from rtsar.sinks.io import RecordingWriter
from rtsar.stream.engine import process_block
from rtsar.topo.stream import HeightStripStage

STRIP = 16


@pytest.fixture(scope="module")
def insal_recording(tmp_path_factory):
    d = tmp_path_factory.mktemp("insal")
    cfg = zhao_config(sample_rate_hz=640.0, aperture_pulses=48, range_bins=48)
    ss = surface_scene(
        cfg,
        ridge(2.5e-3, 4e-3),
        64,
        seed=5,
        spacing_m=default_spacing_m(cfg, 2.0),
        effects=[("noise", {"snr_db": 5.0}), ("interferometric_receivers", {"snr_db": 5.0})],
    )
    scene = ss.scene
    shots, aux = Simulator(scene).block_with_aux(scene.pulses)
    idx = np.arange(scene.pulses)
    rec = d / "insal.h5"
    with RecordingWriter(rec, cfg, scene.to_dict()) as w:
        w.write(shots, idx, idx / cfg.geometry.prf_hz, scene.along_track_of(idx), aux)
    # What the height stage makes of the two focused images, in one go.
    main_img, _, rg = process_block(cfg, shots, "numpy", scene.start_along_track_m)
    rx1_img, _, _ = process_block(cfg, aux[SECOND_RECEIVER], "numpy", scene.start_along_track_m)
    stage = HeightStripStage(insal_geometry(scene), rg, strip_lines=STRIP)
    strips = stage.process(main_img, rx1_img) + stage.flush()
    h = np.zeros(main_img.shape)
    v = np.zeros(main_img.shape, bool)
    c = np.zeros(main_img.shape)
    for s in strips:
        h[s.first_line : s.first_line + len(s)] = s.height_m
        v[s.first_line : s.first_line + len(s)] = s.valid
        c[s.first_line : s.first_line + len(s)] = s.coherence
    return d, rec, h, v, c


def test_process_writes_the_height_map(insal_recording):
    d, rec, h, v, c = insal_recording
    img = d / "p.h5"
    args = ["process", str(rec), "-o", str(img), "--lens", "numpy", "--height", "insal"]
    assert main(args + ["--height-strip-lines", str(STRIP)]) == 0
    height, valid = read_heights(img)
    _, _, _, attrs = read_image(img)
    assert attrs["height_method"] == "insal" and attrs["height_strips"] >= 3
    np.testing.assert_array_equal(valid, v)
    assert valid.mean() > 0.5  # most of the ridge is coherent and unwrapped
    np.testing.assert_allclose(height, np.where(v, h, 0.0), atol=1e-7)  # float32 storage
    with h5py.File(img) as f:
        np.testing.assert_allclose(f["coherence"][...], c, atol=1e-6)


def test_replay_records_the_same_heights_and_quicklook_draws_them(insal_recording, capsys):
    d, rec, h, v, c = insal_recording
    img, png, hpng = d / "r.h5", d / "r.png", d / "h.png"
    args = ["replay", str(rec), "--rate", "max", "--lens", "numpy", "--height", "insal"]
    args += ["--height-strip-lines", str(STRIP), "-o", str(img)]
    assert main(args + ["--endpoint", "ipc://" + str(d / "pub")]) == 0
    height, valid = read_heights(img)
    np.testing.assert_array_equal(valid, v)
    np.testing.assert_allclose(height, np.where(v, h, 0.0), atol=1e-7)
    assert main(["quicklook", str(img), "-o", str(png), "--height", str(hpng)]) == 0
    assert hpng.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_height_without_an_interferometer_is_a_one_line_error(tmp_path, capsys):
    scene_file, rec = tmp_path / "s.toml", tmp_path / "r.h5"
    scene_file.write_text(
        'preset = "tiny"\n[[targets]]\nalong_track_m = 0.0\nslant_range_m = 2e3\n'
    )
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    capsys.readouterr()
    args = ["process", str(rec), "-o", str(tmp_path / "i.h5"), "--height", "insal"]
    assert main(args + ["--lens", "numpy"]) == 2
    assert "interferometric_receivers effect" in capsys.readouterr().err
    assert main(["quicklook", str(rec), "-o", str(tmp_path / "q.png")]) == 2


def test_subscribe_records_the_published_heights(insal_recording):
    import threading

    d, rec, h, v, c = insal_recording
    ep = f"tcp://127.0.0.1:{free_port()}"  # outside the ephemeral range (conftest)
    out, codes = d / "sub.h5", []
    sub = threading.Thread(
        target=lambda: codes.append(main(["subscribe", ep, "-o", str(out), "--timeout", "30"]))
    )
    sub.start()
    args = ["replay", str(rec), "--rate", "max", "--endpoint", ep, "--wait-subscribers", "1"]
    args += ["--lens", "numpy", "--height", "insal", "--height-strip-lines", str(STRIP)]
    assert main(args) == 0
    sub.join(60)
    assert codes == [0]
    height, valid = read_heights(out)
    np.testing.assert_array_equal(valid, v)
    np.testing.assert_allclose(height, np.where(v, h, 0.0), atol=1e-7)
    _, _, _, attrs = read_image(out)
    assert attrs["height_strips"] >= 3 and attrs["inconsistent_heights"] == 0
    with h5py.File(out) as f:  # the coherence came over the wire (height messages v2)
        np.testing.assert_allclose(f["coherence"][...], c, atol=1e-6)


SURFACE_SCENE = """
preset = "zhao-insal"
seed = 2
[geometry]
platform_height_m = 1.3856406460551016
[waveform]
sample_rate_hz = 640.0
[processor]
aperture_pulses = 48
range_bins = 48
[surface]
shape = "{shape}"
lines = 32
[[effects]]
name = "noise"
snr_db = 10.0
[[effects]]
name = "interferometric_receivers"
snr_db = 10.0
"""


@pytest.mark.parametrize("shape", ["ridge", "drawing_pin"])
def test_a_surface_scene_file_gives_heights_from_the_commands_alone(tmp_path, shape):
    """simulate → process --height insal on a [surface] scene file: heights within h_2π/20 of
    the surface's truth (Zhao's acceptance), at every strip size the command accepts."""
    from rtsar.scene import load_scene
    from rtsar.scene.files import SHAPES
    from rtsar.scene.relief import default_spacing_m, surface_scene
    from rtsar.topo.insar import height_error

    scene_file, rec = tmp_path / "s.toml", tmp_path / "r.h5"
    scene_file.write_text(SURFACE_SCENE.format(shape=shape))
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    scene = load_scene(scene_file)
    truth_scene = surface_scene(
        scene.config,
        SHAPES[shape](),
        32,
        spacing_m=default_spacing_m(scene.config, 2.0),
        seed=2,
        effects=scene.effects,
    )
    assert len(truth_scene.scene.targets) == len(scene.targets)  # the same scatterers
    geo = insal_geometry(scene)
    for strip in (8, 16, 32):
        img = tmp_path / f"i{strip}.h5"
        args = ["process", str(rec), "-o", str(img), "--lens", "numpy", "--height", "insal"]
        assert main(args + ["--height-strip-lines", str(strip)]) == 0
        _, az, rg, _ = read_image(img)
        h, v = read_heights(img)
        truth = truth_scene.truth(az, rg)
        e = height_error(h, v, truth.height_m, truth.scored)
        h2pi = float(geo.ambiguity_height_m(float(np.mean(rg))))
        assert e["coverage"] > 0.8 and e["rms_m"] <= h2pi / 20, (strip, e, h2pi)
        assert abs(e["bias_m"]) < h2pi / 4  # no 2π slip


def test_surface_scene_files_refuse_what_does_not_fit(tmp_path):
    from rtsar.scene import load_scene

    bad = {
        'shape = "wave"': "surface.shape must be one of",
        "lines = 0": "surface.lines",
        "scatterers_per_cell = -1": "scatterers_per_cell",
        "bump = 3": "surface (ridge)",
    }
    for line, message in bad.items():
        f = tmp_path / "s.toml"
        text = SURFACE_SCENE.format(shape="ridge")
        key = line.split(" =")[0]
        old = (
            next(t for t in text.splitlines() if t.startswith(key + " =")) if key in text else None
        )
        f.write_text(
            text.replace(old, line) if old else text.replace("lines = 32", "lines = 32\n" + line)
        )
        with pytest.raises(ValueError, match=re.escape(message)):
            load_scene(f)
    f.write_text(SURFACE_SCENE.format(shape="ridge") + "[[targets]]\nalong_track_m = 0\n")
    with pytest.raises(ValueError, match="sets its own targets"):
        load_scene(f)


def test_the_3d_demo_simulates_once_then_replays_with_heights(tmp_path, monkeypatch):
    from dataclasses import replace

    from rtsar.app.cli import replay as replay_cli
    from rtsar.scene import load_scene

    small = tmp_path / "small.toml"
    small.write_text(SURFACE_SCENE.format(shape="ridge"))
    # the recording is cached in rtsar's cache folder (a cold review: it ignored
    # RTSAR_CACHE_DIR and wrote ~/.cache/rtsar)
    monkeypatch.setenv("RTSAR_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(
        replay_cli, "load_scene", lambda name: replace(load_scene(small), name="insal-ridge")
    )
    args = ["demo", "insal", "--rate", "max", "--lens", "numpy", "--height-strip-lines", "8"]
    args += ["--endpoint", "ipc://" + str(tmp_path / "pub")]
    assert main(args + ["-o", str(tmp_path / "a.h5")]) == 0
    (cached,) = (tmp_path / "cache").glob("insal-ridge-*.h5")
    stamp = cached.stat().st_mtime_ns
    assert main(args + ["-o", str(tmp_path / "b.h5")]) == 0
    assert cached.stat().st_mtime_ns == stamp  # simulated once
    for name in ("a.h5", "b.h5"):
        h, v = read_heights(tmp_path / name)
        assert v.mean() > 0.8 and np.abs(h[v]).max() < 3e-3


def test_recordings_carry_the_3d_platform_position(insal_recording):
    from rtsar.sinks.io import open_recording

    _, rec, _, _, _ = insal_recording
    with open_recording(rec) as r:
        pos = r.position_m
        along = r.start_along_track_m + np.arange(r.pulses) * r.config.geometry.along_track_step_m
        assert pos.shape == (r.pulses, 3)
        np.testing.assert_allclose(pos[:, 0], along)
        assert np.all(pos[:, 1] == 0) and np.all(pos[:, 2] == r.config.geometry.platform_height_m)


SAM_SCENE = SURFACE_SCENE.replace(
    '[[effects]]\nname = "interferometric_receivers"\nsnr_db = 10.0\n',
    '[[effects]]\nname = "amplitude_modulation_3d"\nangular_period_rad = 1.6840315e-3\n'
    "snr_db = 10.0\n",
)


def test_sam_heights_from_the_commands(tmp_path):
    """`--height sam` (INO 3D patent, masks of h_2π = 3.3 mm): process at every strip size and
    replay through the pipeline give the same heights, within eq. 14's Δh = h_2π/20 of the
    truth."""
    from rtsar.scene import load_scene
    from rtsar.scene.correction_context import modulation_geometry
    from rtsar.scene.files import SHAPES
    from rtsar.scene.relief import default_spacing_m, surface_scene
    from rtsar.topo.insar import height_error

    assert "amplitude_modulation_3d" in SAM_SCENE
    scene_file, rec = tmp_path / "s.toml", tmp_path / "r.h5"
    scene_file.write_text(SAM_SCENE.format(shape="ridge"))
    assert main(["simulate", str(scene_file), "-o", str(rec)]) == 0
    scene = load_scene(scene_file)
    truth_scene = surface_scene(
        scene.config,
        SHAPES["ridge"](),
        32,
        spacing_m=default_spacing_m(scene.config, 2.0),
        seed=2,
        effects=scene.effects,
    )
    dh = modulation_geometry(scene).elevation_resolution_m  # eq. 14
    maps = {}
    for strip in (8, 16, 32):
        img = tmp_path / f"i{strip}.h5"
        args = ["process", str(rec), "-o", str(img), "--lens", "numpy", "--height", "sam"]
        assert main(args + ["--height-strip-lines", str(strip)]) == 0
        _, az, rg, attrs = read_image(img)
        h, v = read_heights(img)
        e = height_error(h, v, truth_scene.truth(az, rg).height_m, truth_scene.truth(az, rg).scored)
        assert attrs["height_method"] == "sam"
        assert e["coverage"] > 0.8 and e["rms_m"] <= dh and abs(e["bias_m"]) < 5 * dh, (strip, e)
        maps[strip] = (h, v)
    out = tmp_path / "replay.h5"
    args = ["replay", str(rec), "--rate", "max", "--lens", "numpy", "--height", "sam"]
    args += [
        "--height-strip-lines",
        "16",
        "-o",
        str(out),
        "--endpoint",
        "ipc://" + str(tmp_path / "p"),
    ]
    assert main(args) == 0
    h, v = read_heights(out)
    np.testing.assert_array_equal(v, maps[16][1])
    np.testing.assert_allclose(h, maps[16][0], atol=1e-7)
    assert read_image(out)[3]["height_method"] == "sam"


def recorder_header(bins: int) -> dict:
    """The fields of a 3D run's strip and height headers that StripRecorder reads."""
    from rtsar.presets import preset

    return {
        "stream_id": "s",
        "range_bins": bins,
        "range_first_m": 100.0,
        "range_step_m": 1.0,
        "azimuth_step_m": 1.0,
        "config": preset("tiny").to_dict(),
        "height_strips": True,
        "height_kind": "insal",
    }


def test_heights_land_on_their_image_rows_across_a_line_jump(tmp_path):
    """A strip far ahead is not zero-filled (line_jumps); a height strip after it must land on
    the image rows of its lines, not on row = line index."""
    import json as _json

    from rtsar.sinks.record import StripRecorder

    bins, head = 4, recorder_header(4)
    rec = StripRecorder(tmp_path / "j.h5", "test", max_fill_bytes=1000)
    rec.add_strip(
        {**head, "first_line": 0, "azimuth_first_m": 0.0}, np.ones((2, bins), np.complex64)
    )
    far = 10**6
    rec.add_strip(
        {**head, "first_line": far, "azimuth_first_m": float(far)}, np.ones((2, bins), np.complex64)
    )
    # the next strip continues from it: the jump is real (a lone far strip would be dropped)
    rec.add_strip(
        {**head, "first_line": far + 2, "azimuth_first_m": float(far + 2)},
        np.ones((2, bins), np.complex64),
    )
    h = np.full((2, bins), 7e-4, np.float32)
    rec.add_height({**head, "first_line": far}, h, np.ones((2, bins), bool))
    rec.finish()
    height, valid = read_heights(tmp_path / "j.h5")
    assert valid[2:4].all() and not valid[:2].any() and not valid[4:].any()  # far, far + 1
    np.testing.assert_allclose(height[2:4], 7e-4)
    with h5py.File(tmp_path / "j.h5") as f:
        assert _json.loads(f.attrs["line_jumps"]) == [[2, far - 2]]


def test_height_lines_inside_a_line_jump_are_dropped_not_shifted(tmp_path):
    from rtsar.sinks.record import StripRecorder

    bins, head = 4, recorder_header(4)
    rec = StripRecorder(tmp_path / "j.h5", "test", max_fill_bytes=10 * bins * 8)
    for first in (0, 100, 104):  # lines 0-3, then a jump to 100 confirmed by 104
        rec.add_strip(
            {**head, "first_line": first, "azimuth_first_m": float(first)},
            np.ones((4, bins), np.complex64),
        )
    h = (2 + np.arange(4, dtype=np.float32))[:, None] * np.ones((1, bins), np.float32) * 1e-4
    rec.add_height({**head, "first_line": 2}, h, np.ones((4, bins), bool))  # lines 2-5
    rec.add_height({**head, "first_line": 10**7}, h, np.ones((4, bins), bool))  # far beyond
    rec.finish()
    height, valid = read_heights(tmp_path / "j.h5")
    assert valid[2:4].all() and not valid[4:].any()  # lines 4, 5 have no image row
    np.testing.assert_allclose(height[2:4, 0], [2e-4, 3e-4])
    with h5py.File(tmp_path / "j.h5") as f:
        assert f["height_m"].shape[0] <= 12 and f.attrs["inconsistent_heights"] == 1


def test_a_height_image_of_a_marked_recording_keeps_its_flagged_lines(insal_recording, tmp_path):
    """`process RAW.h5 --height insal` of a recording that marks a shot (as `run --record`
    marks the shots ingest zeroed): the height attributes were written in place of the
    flagged lines' (flagged_line_runs and flagged_lines lost), not beside them."""
    d, rec, h, v, c = insal_recording
    marked = tmp_path / "marked.h5"
    shutil.copyfile(rec, marked)
    with h5py.File(marked, "r+") as f:
        flags = np.zeros(len(f["shots"]), np.uint8)
        flags[40] = 2  # a shot ingest zeroed (rtsar.sinks.raw_record ZEROED)
        f.create_dataset("pulse_flags", data=flags)
        n = json.loads(f.attrs["config"])["processor"]["aperture_pulses"]
    img = tmp_path / "p.h5"
    assert (
        main(["process", str(marked), "-o", str(img), "--lens", "numpy", "--height", "insal"]) == 0
    )
    with h5py.File(img, "r") as f:
        lines = len(f["image"])
        assert f.attrs["height_method"] == "insal"
        runs = json.loads(f.attrs["flagged_line_runs"])
        flagged = [j for j in range(lines) if j <= 40 <= j + n - 1]  # line j sums j … j+N-1
        assert runs == [[flagged[0], len(flagged)]] and f.attrs["flagged_lines"] == len(flagged)
