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


def test_a_first_survey_and_the_correlator_compile_run_side_by_side(monkeypatch):
    """Where the survey must probe, the correlator compiles meanwhile in this thread; the
    survey's failure is raised here; a known survey runs alone, then the compile only where
    the simulator's kernels compile elsewhere."""
    import pytest

    from rtsar.app import live_granularity as lg

    calls = []
    monkeypatch.setattr(lg.cl_devices, "survey_is_known", lambda: False)
    monkeypatch.setattr(lg, "survey_devices_first", _record(calls, "survey", 0.3))
    monkeypatch.setattr(lg, "warm_correlator", _record(calls, "compile", 0.3))
    lg.survey_and_compile(_Settings(), None, None, object(), print)
    (a, b) = sorted(calls)
    assert {a[0], b[0]} == {"survey", "compile"} and a[1] != b[1]
    assert a[2] < b[3] and b[2] < a[3]  # their times overlap

    def broken(*args):
        raise RuntimeError("the survey failed")

    monkeypatch.setattr(lg, "survey_devices_first", broken)
    with pytest.raises(RuntimeError, match="survey failed"):
        lg.survey_and_compile(_Settings(), None, None, object(), print)

    calls.clear()
    monkeypatch.setattr(lg.cl_devices, "survey_is_known", lambda: True)
    monkeypatch.setattr(lg, "survey_devices_first", _record(calls, "survey"))

    class Warming:
        warming = True

    lg.survey_and_compile(_Settings(), None, None, object(), print)
    assert [c[0] for c in calls] == ["survey"]
    lg.survey_and_compile(_Settings(), None, None, Warming(), print)
    assert [c[0] for c in calls] == ["survey", "survey", "compile"]

    def touched():
        raise AssertionError("OpenCL asked about its survey for a NumPy lens")

    class NumpyLens(_Settings):
        lens_backend = "numpy"

    monkeypatch.setattr(lg.cl_devices, "survey_is_known", touched)
    lg.survey_and_compile(NumpyLens(), None, None, object(), print)
