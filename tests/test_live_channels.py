"""Live sources declare the auxiliary channels they deliver, and `rtsar run` refuses a --correct or
--height stage that reads another one before anything starts (no banner, no wait for the first
shot), in one line naming the channel and how to give the source it."""

import time

import numpy as np
import pytest

from rtsar.app import live
from rtsar.app.cli import main
from rtsar.scene import load_scene
from rtsar.sources.channel_map import ChannelMap
from rtsar.sources.replay import ReplaySource
from rtsar.sources.serial import SerialSource
from rtsar.sources.sim import SimSource
from rtsar.sources.zmq_in import ZmqSource

SCENE = """
preset = "crouch-sal"
pulses = 64
seed = 1
[processor]
aperture_pulses = 32
range_bins = 64
[[targets]]
along_track_m = 0.0
slant_range_m = 1.5
[[effects]]
name = "reference_interferometer"
[[effects]]
name = "hcn_cell"
oversampling = 8
"""
BARE = SCENE.split("[[effects]]")[0]  # the same scene, main channel only


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    d = tmp_path_factory.mktemp("live_channels")
    full, bare = d / "full.toml", d / "bare.toml"
    full.write_text(SCENE)
    bare.write_text(BARE)
    return full, bare


def test_every_live_source_declares_its_channels(scenes):
    full, bare = scenes
    mapped = SerialSource("loop://", 8, channel_map=ChannelMap.parse("main,hcn_cell*4,rx1"))
    plain = SerialSource("loop://", 8)
    try:
        assert mapped.aux_channels() == ("hcn_cell", "rx1")
        assert plain.aux_channels() == ()
    finally:
        mapped.close()
        plain.close()
    assert ZmqSource("tcp://127.0.0.1:1", 8, 1e6, 100.0).aux_channels() == ()
    assert SimSource(load_scene(full)).aux_channels() == ("hcn_cell", "reference_interferometer")
    assert SimSource(load_scene(bare)).aux_channels() == ()
    shots = np.zeros((3, 4), np.complex64)
    replay = ReplaySource(shots, np.arange(3), np.arange(3.0), 10.0, aux={"rx1": shots})
    assert replay.aux_channels() == ("rx1",)


class _Stage:
    def __init__(self, channels):
        self.channels = channels


class _Chain:
    def __init__(self, named):
        self.named = named

    def __bool__(self):
        return bool(self.named)


class _Unknown(ZmqSource):
    def aux_channels(self):
        return None


def test_the_check_names_option_channel_and_fix_and_skips_unknown():
    source = ZmqSource("tcp://127.0.0.1:1", 8, 1e6, 100.0)
    chain = _Chain([("pga", _Stage(())), ("hcn", _Stage(("hcn_cell",)))])
    with pytest.raises(ValueError) as err:
        live.check_source_channels(source, chain, fix=lambda missing: f"FIX {missing}")
    message = str(err.value)
    assert "\n" not in message
    assert message.startswith("--correct hcn reads the auxiliary channel hcn_cell, but")
    assert message.endswith("delivers the main channel only: FIX ['hcn_cell']")
    live.check_source_channels(source, _Chain([("pga", _Stage(()))]))  # reads none: no check
    live.check_source_channels(_Unknown("tcp://127.0.0.1:1", 8, 1e6, 100.0), chain)  # unknown


def _refused(capsys, argv):
    """`rtsar run ARGV`: exit status 2, one error line, nothing started (no banner)."""
    t0 = time.perf_counter()
    status = main(argv)
    elapsed = time.perf_counter() - t0
    out, err = capsys.readouterr()
    assert status == 2, (out, err)
    assert "preparing" not in out and out == "", out
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("rtsar: error: "), err
    assert elapsed < 10.0
    return lines[0]


def test_zmq_in_refuses_channels_it_cannot_carry(scenes, capsys):
    full, _ = scenes
    base = ["run", "--zmq-in", "tcp://127.0.0.1:5699", "--duration", "1", "--lens", "numpy"]
    base += ["--endpoint", "tcp://127.0.0.1:5698"]
    line = _refused(capsys, [*base, "--scene", str(full), "--correct", "hcn"])
    assert "--correct hcn reads the auxiliary channel hcn_cell" in line
    assert "(--zmq-in) carries the main channel only" in line
    assert "--serial URL --channel-map main,hcn_cell*8" in line
    line = _refused(capsys, [*base, "--scene", "insal-ridge", "--height", "insal"])
    assert "--height insal reads the auxiliary channel rx1" in line
    assert "--channel-map main,rx1" in line


def test_serial_refuses_before_opening_the_port(scenes, capsys):
    full, _ = scenes
    # Nothing listens on port 1: a check made after opening would say "cannot open".
    base = ["run", "--serial", "socket://127.0.0.1:1", "--no-reconnect", "--lens", "numpy"]
    base += ["--endpoint", "tcp://127.0.0.1:5697", "--scene", str(full)]
    line = _refused(capsys, [*base, "--channel-map", "main", "--correct", "hcn"])
    assert "--correct hcn reads the auxiliary channel hcn_cell" in line
    assert "add hcn_cell*8 to --channel-map" in line
    assert "--channel-map main,hcn_cell*8)" in line
    assert "--scene's map is main,hcn_cell*8,reference_interferometer" in line
    # A preset says nothing of the channels' widths: NAME*K, and what K is.
    preset = ["run", "--serial", "socket://127.0.0.1:1", "--preset", "crouch-sal"]
    line = _refused(capsys, [*preset, "--correct", "linearize", "--lens", "numpy"])
    assert "--correct linearize reads the auxiliary channel reference_interferometer" in line
    assert "--channel-map main,reference_interferometer*K)" in line
    assert "K: the frame channels each spans" in line


def test_simulated_scene_without_the_effect_is_refused(scenes, capsys):
    _, bare = scenes
    argv = ["run", "--scene", str(bare), "--correct", "hcn", "--duration", "0.1"]
    line = _refused(capsys, [*argv, "--lens", "numpy", "--endpoint", "tcp://127.0.0.1:5696"])
    assert "--correct hcn reads the auxiliary channel hcn_cell" in line
    assert "simulated scene 'bare'" in line
    assert 'add [[effects]] name = "hcn_cell" to the scene' in line
