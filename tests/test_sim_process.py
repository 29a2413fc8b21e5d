"""The simulator in a process of its own (rtsar.sources.sim_process, ``rtsar run``'s source):
the same shots as in process, bit for bit, auxiliary channels with them; the child ends when
the stream is stopped and when its parent is gone, ignores Ctrl-C, and a failure in it is
raised here with its words."""

import os
import signal
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pytest

from rtsar.scene import load_scene
from rtsar.sources import sim_process
from rtsar.sources.sim import SimSource
from rtsar.sources.sim_process import ShotFeed


def _fast(source: SimSource) -> SimSource:
    source.prf_hz = 1e5  # released as fast as they come (the pacer's rate)
    return source


@pytest.mark.parametrize("scene_name, pulses", [("demo", 70), ("insal-ridge", 40)])
def test_the_separate_process_makes_the_same_shots(scene_name, pulses):
    """Blocks of 16 from the child, released here as the pacer cuts them: the shots and the
    auxiliary channels (insal-ridge's second receiver) are the in-process simulator's, in
    order."""
    scene = load_scene(scene_name)
    here = list(_fast(SimSource(scene, pulses=pulses, chunk=3)))
    there_source = _fast(SimSource(scene, pulses=pulses, chunk=3, separate=True))
    there_source.prepare()
    there = list(there_source)
    # (how the pacer cuts its releases depends on the machine's load: the pulses are the test)
    assert np.concatenate([b.seq for b in there]).tolist() == list(range(pulses))
    assert np.concatenate([b.seq for b in here]).tolist() == list(range(pulses))
    np.testing.assert_array_equal(
        np.concatenate([b.samples for b in there]), np.concatenate([b.samples for b in here])
    )
    names = sorted(here[0].aux)
    assert sorted(there[0].aux) == names and (scene_name == "insal-ridge") == bool(names)
    for name in names:
        np.testing.assert_array_equal(
            np.concatenate([b.aux[name] for b in there]),
            np.concatenate([b.aux[name] for b in here]),
        )
    assert there_source._feed._process is None  # ended with the stream
    assert there_source.cost_per_pulse_s() == 0.0  # not this process's work


def test_a_stopped_stream_ends_the_child_and_ctrl_c_does_not():
    scene = load_scene("demo")
    source = SimSource(scene, pulses=5000, separate=True)
    source.prepare()
    child = source._feed._process
    os.kill(child.pid, signal.SIGINT)  # an interrupt sent to it (its session is its own)
    batches = iter(source)
    next(batches)
    time.sleep(0.3)
    assert child.poll() is None  # still making shots: the parent ends it, not the interrupt
    source.close()
    for _ in batches:  # the stream ends at its next release
        pass
    assert child.poll() is not None


def test_a_failure_in_the_child_is_raised_with_its_words():
    feed = ShotFeed(replace(load_scene("demo"), effects="not effects"), 10)
    try:
        with pytest.raises(RuntimeError, match="the simulator's process failed: "):
            feed.take(1)
    finally:
        feed.close()


def test_a_child_that_ends_before_it_is_ready_is_an_error_with_its_last_words(monkeypatch):
    """Before, the parent's first send waited for a peer that never came: a hang."""
    words = "import sys; sys.stderr.write('no module named numba\\n'); sys.exit(3)"
    monkeypatch.setattr(sim_process, "module_argv", lambda *a: [sys.executable, "-c", words])
    feed = ShotFeed(load_scene("demo"), 10)
    t0 = time.monotonic()
    with pytest.raises(RuntimeError, match=r"ended \(exit status 3: no module named numba\)"):
        feed.start()
    assert time.monotonic() - t0 < 30 and feed._process is None and feed._folder is None


def test_the_socket_is_this_user_s_only():
    """Both ends unpickle what they receive: the socket lies in a folder only its user may
    enter (mkdtemp's 0700), and the folder goes with the feed."""
    feed = ShotFeed(load_scene("demo"), 10)
    feed.start()
    try:
        folder = feed._folder
        assert folder is not None and os.stat(folder).st_mode & 0o777 == 0o700
    finally:
        feed.close()
    assert not os.path.exists(folder)


def test_the_child_ends_when_its_parent_is_gone(tmp_path):
    """A parent that dies without closing (a kill): its child sees it gone and exits."""
    pid_file = tmp_path / "child.pid"
    parent = (
        "import os, sys\n"
        "from rtsar.scene import load_scene\n"
        "from rtsar.sources.sim_process import ShotFeed\n"
        "feed = ShotFeed(load_scene('demo'), 100000)\n"
        "feed.start()\n"
        "feed.take(1)\n"
        f"open({str(pid_file)!r}, 'w').write(str(feed._process.pid))\n"
        "os._exit(0)\n"
    )
    subprocess.run([sys.executable, "-c", parent], check=True, timeout=120)
    pid = int(pid_file.read_text())
    deadline = time.monotonic() + 10 * sim_process.POLL_MS / 1000 + 5
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return
        with open(f"/proc/{pid}/stat") as stat:  # a zombie has ended (its parent is gone)
            if stat.read().split(")")[-1].split()[0] == "Z":
                return
        time.sleep(0.1)
    os.kill(pid, signal.SIGKILL)
    pytest.fail("the simulator's process outlived its parent")
