"""3D from the commands: `process`/`replay --height insal` write height maps beside the image,
`quicklook --height` draws them (issue 13)."""

import numpy as np
import pytest

from rtsar.app.cli import main
from rtsar.instrument import SECOND_RECEIVER
from rtsar.scene.correction_context import insal_geometry
from rtsar.scene.relief import default_spacing_m, ridge, surface_scene, zhao_config
from rtsar.scene.simulator import Simulator
from rtsar.sinks.io import RecordingWriter, read_heights, read_image
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
    for s in strips:
        h[s.first_line : s.first_line + len(s)] = s.height_m
        v[s.first_line : s.first_line + len(s)] = s.valid
    return d, rec, h, v


def test_process_writes_the_height_map(insal_recording):
    d, rec, h, v = insal_recording
    img = d / "p.h5"
    args = ["process", str(rec), "-o", str(img), "--lens", "numpy", "--height", "insal"]
    assert main(args + ["--height-strip-lines", str(STRIP)]) == 0
    height, valid = read_heights(img)
    _, _, _, attrs = read_image(img)
    assert attrs["height_method"] == "insal" and attrs["height_strips"] >= 3
    np.testing.assert_array_equal(valid, v)
    assert valid.mean() > 0.5  # most of the ridge is coherent and unwrapped
    np.testing.assert_allclose(height, np.where(v, h, 0.0), atol=1e-7)  # float32 storage


def test_replay_records_the_same_heights_and_quicklook_draws_them(insal_recording, capsys):
    d, rec, h, v = insal_recording
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
    import socket
    import threading

    d, rec, h, v = insal_recording
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        ep = f"tcp://127.0.0.1:{s.getsockname()[1]}"
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
