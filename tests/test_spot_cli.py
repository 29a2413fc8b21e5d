"""Spotlight commands: spot-simulate → spotlight (batch, streamed over ZeroMQ), projective."""

import json
import math
import threading

import numpy as np
import pytest
import zmq
from conftest import free_port as _conftest_free_port

from rtsar.app.cli import main
from rtsar.app.spotlight import read_spot_image
from rtsar.spot.pfa import PfaSettings, PolarFormatPlan, polar_format
from rtsar.spot.scene import load_spot_scene
from rtsar.spot.simulate import SpotlightSimulator

STEP_M = 4.6 * 1.55e-6 / (2 * 3.2e-3)  # a 3.2 mm alias-free spot (rtsar.spot.reduced_spotlight)
SCENE = f"""
preset = "crouch-spotlight"
[waveform]
sample_rate_hz = {64 / 0.3}
[geometry]
along_track_step_m = {STEP_M}
[processor]
aperture_pulses = 2
range_bins = 64
[spotlight]
sweep_deg = 2.0
[[targets]]
x_m = 0.0
[[targets]]
x_m = 4e-4
y_m = 3e-4
z_m = 2e-4
[[targets]]
x_m = -3e-4
y_m = -5e-4
z_m = -4e-4
amplitude = 0.7
"""


def free_endpoint() -> str:
    return f"tcp://127.0.0.1:{_conftest_free_port()}"


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("spot") / "spot.toml"
    path.write_text(SCENE)
    return path


def _batch(path, extent=("1.6", "1.6")):
    scene = load_spot_scene(path)
    ext = tuple(1e-3 * float(e) for e in extent)
    plan = PolarFormatPlan(scene.config, scene.geometry, settings=PfaSettings(extent_m=ext))
    return polar_format(SpotlightSimulator(scene).block()[0], plan)


def test_recording_through_spotlight_equals_the_batch_pfa(scene_file, tmp_path):
    rec, img = tmp_path / "rec.h5", tmp_path / "img.h5"
    assert main(["spot-simulate", str(scene_file), "-o", str(rec)]) == 0
    assert main(["spotlight", str(rec), "-o", str(img), "--extent-mm", "1.6", "1.6"]) == 0
    image, x, y, spot = read_spot_image(img)
    ref = _batch(scene_file)
    assert np.max(np.abs(image - ref)) < 1e-5  # complex64 file of the complex128 image
    assert spot["channel"] == "main" and spot["rotation_rad"] == 0.0
    assert main(["spotlight", str(rec), "-o", str(img), "--channel", "bistatic"]) == 2


def test_live_progressive_images_on_the_spot_topic(scene_file, tmp_path):
    endpoint = free_endpoint()
    ctx = zmq.Context.instance()
    sub = ctx.socket(zmq.SUB)
    sub.setsockopt(zmq.SUBSCRIBE, b"spot")
    sub.setsockopt(zmq.RCVTIMEO, 20000)
    sub.connect(endpoint)
    got = []

    def listen():
        while True:
            frames = sub.recv_multipart()
            header = json.loads(frames[1])
            got.append((header, np.frombuffer(frames[2], "<c8").reshape(header["shape"])))
            if header["final"]:
                return

    t = threading.Thread(target=listen)
    t.start()
    argv = ["spotlight", "--live", str(scene_file), "--every", "40", "--publish", endpoint]
    argv += ["--wait-subscribers", "1", "--extent-mm", "1.6", "1.6", "-o", str(tmp_path / "i.h5")]
    try:
        assert main(argv) == 0
    finally:
        t.join(30)
        sub.close(0)
    headers = [h for h, _ in got]
    assert [h["seq"] for h in headers] == list(range(len(headers))) and len(headers) >= 3
    assert headers[-1]["final"] and headers[-1]["shots"] == headers[-1]["pulses"]
    res = [h["resolution_m"] for h in headers]
    assert all(a > b for a, b in zip(res, res[1:], strict=False))  # finer as Δθ grows
    ref = _batch(scene_file)
    assert np.max(np.abs(got[-1][1] - ref)) < 1e-5  # the last streamed image is the batch one
    written = read_spot_image(tmp_path / "i.h5")[0]
    assert np.max(np.abs(written - ref)) < 1e-5


def test_projective_recovers_points_and_reports_ambiguity(scene_file, tmp_path):
    out = tmp_path / "pts.csv"
    assert main(["projective", "--simulate", str(scene_file), "-o", str(out)]) == 0
    pts = np.loadtxt(out, delimiter=",", skiprows=1).reshape(-1, 4)[:, :3]
    truth = np.array([[0, 0, 0], [4e-4, 3e-4, 2e-4], [-3e-4, -5e-4, -4e-4]])
    assert len(pts) == 3
    for p in truth:
        assert np.min(np.linalg.norm(pts - p, axis=1)) < 10e-6  # ρ ≈ 20 x 44 µm here
    # two scatterers at one range: either pairing fits both images, so nothing is guessed
    same = SCENE.replace("y_m = 3e-4", "y_m = 0.0")
    (tmp_path / "amb.toml").write_text(same)
    assert main(["projective", "--simulate", str(tmp_path / "amb.toml"), "-o", str(out)]) == 0
    pts = np.loadtxt(out, delimiter=",", skiprows=1).reshape(-1, 4)
    assert len(pts) == 1 and math.isclose(pts[0, 1], -5e-4, abs_tol=10e-6)


def test_bistatic_channel_from_a_recording(tmp_path):
    scene = SCENE.replace("sweep_deg = 2.0", "sweep_deg = 2.0\nbistatic_angle_deg = 8.0")
    (tmp_path / "bi.toml").write_text(scene)
    rec, img = tmp_path / "bi.h5", tmp_path / "bi_img.h5"
    assert main(["spot-simulate", str(tmp_path / "bi.toml"), "-o", str(rec)]) == 0
    argv = ["spotlight", str(rec), "-o", str(img), "--channel", "bistatic", "--extent-mm", "2", "2"]
    assert main(argv) == 0
    image, _, _, spot = read_spot_image(img)
    s = load_spot_scene(tmp_path / "bi.toml")
    plan = PolarFormatPlan(s.config, s.geometry, "bistatic", PfaSettings(extent_m=(2e-3, 2e-3)))
    ref = polar_format(SpotlightSimulator(s).block()[1]["bistatic"], plan)
    assert spot["channel"] == "bistatic" and np.max(np.abs(image - ref)) < 1e-5
    assert spot["frame_angle_rad"] == pytest.approx(math.radians(4.0), abs=1e-3)  # the bisector


def test_a_bistatic_channel_that_was_never_recorded_says_what_to_simulate(
    scene_file, tmp_path, capsys
):
    """Issue 31: `spotlight REC --channel bistatic` on a recording without a bistatic receiver
    said "this spotlight geometry has no bistatic receiver"; it names the recording and the
    scene keys that make one, in one line, exit status 2, before any imaging."""
    rec = tmp_path / "mono.h5"
    assert main(["spot-simulate", str(scene_file), "-o", str(rec)]) == 0
    capsys.readouterr()
    out = tmp_path / "bi.h5"
    argv = ["spotlight", str(rec), "--channel", "bistatic", "--look", "monostatic", "-o", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(rec) in err
    assert "bistatic_range_m" in err and "bistatic_angle_deg" in err
    assert not out.exists()


def test_progressive_images_come_every_k_shots_whatever_the_sources_blocks(scene_file):
    """A review: `--every 1000` imaged at 1024, 2048, … shots, the recording's blocks of 1,024
    (spotlight.md and --help: every K shots).  The blocks are now cut where an image is due;
    the last image is the whole aperture's, equal to the batch one."""
    from rtsar.app.spotlight import progressive

    scene = load_spot_scene(scene_file)
    settings = PfaSettings(extent_m=(1.6e-3, 1.6e-3))
    plan = PolarFormatPlan(scene.config, scene.geometry, settings=settings)
    data = SpotlightSimulator(scene).block()[0]
    total, every, block = len(data), 40, 64
    shots = []
    blocks = (data[i : i + block] for i in range(0, total, block))
    last = progressive(blocks, plan, every, lambda header, image: shots.append(header["shots"]))
    assert shots[-1] == total
    # the first image waits for a k_x extent common to every row (here: at K); then every K
    assert shots[0] == every, shots
    assert all(b - a == every for a, b in zip(shots, shots[1:-1], strict=False)), shots
    assert np.max(np.abs(last - _batch(scene_file))) < 1e-5
