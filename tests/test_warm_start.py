"""A live run's first start: where numba's cache lacks the simulator's kernels, a process of
their own compiles them (rtsar.scene.warm) while the run compiles its correlator, and the
simulator then loads them (rtsar.sources.sim ``warm_from``).  Measured, `rtsar run --duration
3` with numba's cache empty: 8.2-8.7 s against 8.5-10.2 s compiling both in turn (3 pairs)."""

import json
import os
import subprocess
import sys

SCRIPT = """
import json
from rtsar.scene import DEMO_SCENE, load_scene
from rtsar.scene.tones import kernels_cached, kernels_compiled
from rtsar.sources.sim import SimSource

before = kernels_cached(True)
source = SimSource(load_scene(DEMO_SCENE), 8, warm_from=str(DEMO_SCENE))
started = source._warming is not None
source.prepare()
again = SimSource(load_scene(DEMO_SCENE), 8, warm_from=str(DEMO_SCENE))
print(json.dumps({"before": before, "started": started, "compiled_here": kernels_compiled(),
                  "after": kernels_cached(True), "started_again": again._warming is not None}))
"""


def test_the_simulator_kernels_compile_in_their_own_process_once(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env, timeout=300
    )
    assert done.returncode == 0, done.stderr
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got == {
        "before": False,  # an empty cache: nothing there
        "started": True,  # so a process compiles them
        "compiled_here": 0,  # and this one loads them from the cache it wrote
        "after": True,
        "started_again": False,  # cached now: no second process
    }, got


class _Settings:
    lens_backend, device, swath_workers = "auto", None, 0


def _record(calls, name, seconds=0.0):
    import threading
    import time

    def call(*args, **kwargs):
        start = time.perf_counter()
        time.sleep(seconds)
        calls.append((name, threading.current_thread().name, start, time.perf_counter()))

    return call


def test_the_survey_is_timed_alone_and_the_correlator_compiles_beside_the_simulator(
    monkeypatch,
):
    """The correlator compiles here only while the simulator's kernels compile elsewhere, and
    before the survey; where the survey must probe, the simulator's process is waited for
    first (a survey timed beside a compile cached rates a third to a half low, two devices
    swapped); a NumPy lens asks OpenCL nothing."""
    from rtsar.app import live_granularity as lg

    calls = []
    monkeypatch.setattr(lg, "survey_devices_first", _record(calls, "survey"))
    monkeypatch.setattr(lg, "warm_correlator", _record(calls, "compile"))

    class Source:
        warming = True

        def wait_warm(self, say=None):
            calls.append(("wait",))
            self.warming = False

    monkeypatch.setattr(lg.cl_devices, "survey_is_known", lambda: False)
    lg.survey_and_compile(_Settings(), None, None, Source(), print)
    assert [c[0] for c in calls] == ["compile", "wait", "survey"]  # the survey last, alone

    calls.clear()
    monkeypatch.setattr(lg.cl_devices, "survey_is_known", lambda: True)
    lg.survey_and_compile(_Settings(), None, None, Source(), print)
    assert [c[0] for c in calls] == ["compile", "survey"]  # no wait: the survey is cached
    calls.clear()
    lg.survey_and_compile(_Settings(), None, None, object(), print)
    assert [c[0] for c in calls] == ["survey"]

    def touched():
        raise AssertionError("OpenCL asked about its survey for a NumPy lens")

    class NumpyLens(_Settings):
        lens_backend = "numpy"

    monkeypatch.setattr(lg.cl_devices, "survey_is_known", touched)
    lg.survey_and_compile(NumpyLens(), None, None, object(), print)


def test_a_run_that_ends_before_preparing_leaves_no_warming_process(tmp_path):
    """A live command that fails before prepare() (a port in use) ended while its warming
    process went on alone, an orphan (a cold review found it); now it ends with the command."""
    script = (
        "from rtsar.scene import DEMO_SCENE, load_scene\n"
        "from rtsar.sources.sim import SimSource\n"
        "s = SimSource(load_scene(DEMO_SCENE), 8, warm_from=str(DEMO_SCENE))\n"
        "print(s._warming.pid)\n"
    )
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba")}
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120
    )
    assert done.returncode == 0, done.stderr
    pid = int(done.stdout.split()[-1])
    try:
        os.kill(pid, 0)
        alive = True
    except ProcessLookupError:
        alive = False
    assert not alive, f"the warming process {pid} outlived its command"
