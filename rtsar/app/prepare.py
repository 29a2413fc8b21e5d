"""``rtsar prepare``: once after installing, what a first run would otherwise stop to do
(issue 37): numba's kernels compiled into its on-disk cache, the OpenCL devices surveyed.

numba compiles a kernel the first time an installation runs it (``cache=True``: later runs load
it in a fraction of a second).  Cold, on a shared 2-core AMD EPYC (Zen 3), one group after
another in one interpreter: the nonuniform correlator's kernels 15.7 s (16-23 s beside another
compile), the threaded partitioned correlator's 4.5 s, the physical CCD's 3.7 s, RADARSAT-1's
Doppler-domain migration 2.7 s, the partitioned 1.9 s, the simulator's 1.7 s, the direct
1.7 s.  So a machine's first ``rtsar run``, ``process`` or ``demo`` paid them.  Here each group
compiles in a process of its own (``python -m rtsar.app.prepare GROUP``: a compile holds its
interpreter, and a process that crashes or is killed is one failed group, not a hang),
``workers`` at a time, longest first; then the device survey runs alone (its timings must not
share the cores: rtsar.app.live_granularity).

numba writes its cache beside the modules where the user can write there, else in its
user-wide folder (or ``$NUMBA_CACHE_DIR``): prepare as the user, and in the environment, that
runs rtsar.

The kernels compiled are those of the presets' precision (complex64) and every correlator a
preset or built-in scene uses; a complex128 run (``tradeoff``, ``--precision complex128``)
still compiles its own on first use.  ``kernel_cache_state`` reads numba's cache index files
(private to numba: where it cannot tell, it says so) to tell what is cached.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
from numba.core import event
from numba.core.registry import CPUDispatcher

from ..ccd import make_ccd
from ..child import module_argv
from ..focus.resample import resample
from ..lens import cl_devices, make_plan
from ..physical import PhysicalSettings
from ..presets import preset
from ..scene import Simulator, load_scene

# Every module of rtsar that holds numba kernels (tests/test_prepare.py checks the list against
# the sources), and the task that compiles each.
KERNEL_MODULES = {
    "rtsar.ccd.tiled": "nonuniform",
    "rtsar.ccd.partitioned": "partitioned",
    "rtsar.ccd.direct": "direct",
    "rtsar.ccd.doppler_migration": "migration",
    "rtsar.ccd.walk_deskew": "migration",
    "rtsar.physical.register": "physical",
    "rtsar.scene.tones": "simulator",
    "rtsar.focus.resample": "resampler",
}


TASKS = {  # each group: what it compiles, for its line; longest first (cold, above), as started
    "nonuniform": "the nonuniform correlator (psaltis-jpl, psaltis-max)",
    "partitioned": "the partitioned correlator, one thread and threaded",
    "physical": "the physical CCD emulation",
    "migration": "the range migration of a squinted beam (radarsat1: Doppler domain, walk)",
    "simulator": "the simulator (pulsed and FMCW scenes)",
    "direct": "the direct shift-register correlator",
    "resampler": "the band-limited resampler (chirp linearization, HCN, PFA)",
}


def _push_zeros(preset_name: str, correlator: str | None = None, physical=None, **processor):
    """Build the CCD of a preset (``correlator``: another kind; ``processor``: more of its
    settings) and push zeros through it, an aperture and more: its kernels compile (or load)
    for the shapes a run gives them, the lines leaving it included."""
    cfg = preset(preset_name)
    if correlator is not None:
        processor["correlator"] = correlator
    cfg = cfg.with_processor(**processor) if processor else cfg
    range_m = make_plan(cfg).range_m
    ccd = make_ccd(cfg, range_m, physical)
    try:
        zeros = np.zeros((16, len(range_m)), np.complex64)
        for _ in range(-(-cfg.processor.aperture_pulses // 16) + 1):
            ccd.push(zeros)
        ccd.flush()
    finally:
        if hasattr(ccd, "close"):
            ccd.close()


def _compile(name: str) -> None:
    if name == "nonuniform":
        _push_zeros("psaltis-jpl", "nonuniform")
        _push_zeros("psaltis-max", "nonuniform")
    elif name == "partitioned":
        _push_zeros("psaltis-jpl", "partitioned")
        _push_zeros("psaltis-max", "partitioned")  # a large plan: the threaded kernel
    elif name == "physical":
        _push_zeros("psaltis-jpl", physical=PhysicalSettings())
    elif name == "migration":
        _push_zeros("radarsat1")  # the file's fft correlator, the Doppler-domain read
        # a live run's (rtsar.stream.granularity.live_correlator)
        _push_zeros("radarsat1", "nonuniform", range_migration_domain="walk")
    elif name == "simulator":
        for scene in ("demo", "sal-demo"):  # a pulsed chirp's kernels, an FMCW chirp's
            Simulator(load_scene(scene)).prepare()
    elif name == "direct":
        _push_zeros("psaltis-jpl", "direct")
    elif name == "resampler":
        resample(np.zeros((2, 64), np.complex64), np.tile(np.linspace(0.0, 63.0, 64), (2, 1)))
    else:
        raise ValueError(f"no such task: {name!r}")


def run_task(name: str) -> tuple[str, float, int, str | None]:
    """In a worker: (name, seconds, kernels numba compiled (not loaded from its cache), the
    error that stopped it or None)."""
    compiled = [0]

    class Count(event.Listener):
        def on_start(self, ev) -> None:
            compiled[0] += 1

        def on_end(self, ev) -> None:
            pass

    t0 = time.perf_counter()
    try:
        with event.install_listener("numba:compile", Count()):
            _compile(name)
    except Exception as exc:  # said by the parent; the other groups go on
        return name, time.perf_counter() - t0, compiled[0], f"{type(exc).__name__}: {exc}"
    return name, time.perf_counter() - t0, compiled[0], None


def kernel_cache_state() -> tuple[int, int, list[str], list[str]] | None:
    """(kernels with an entry in numba's on-disk cache for the installed source, kernels,
    their cache folders, the names of those without) over KERNEL_MODULES, inlined helpers left
    out (they compile into their callers); None where numba's private layout cannot be read."""
    try:
        cached = total = 0
        folders, missing = [], []
        for module_name in KERNEL_MODULES:
            module = importlib.import_module(module_name)
            for obj in vars(module).values():
                if not isinstance(obj, CPUDispatcher) or obj.py_func.__module__ != module_name:
                    continue
                if obj.targetoptions.get("inline") == "always":
                    continue
                total += 1
                cache_file = obj._cache._cache_file
                if cache_file._load_index():
                    cached += 1
                else:
                    missing.append(f"{module_name}.{obj.py_func.__name__}")
                if cache_file._cache_path not in folders:
                    folders.append(cache_file._cache_path)
        return cached, total, folders, missing
    except Exception:  # numba's private layout changed: not knowing is not an error
        return None


def add_arguments(s) -> None:
    s.add_argument(
        "--workers",
        type=int,
        default=min(2, os.cpu_count() or 1),
        help="processes compiling at once (default: 2, or 1 on a one-core machine)",
    )
    s.add_argument(
        "--no-survey",
        action="store_true",
        help="compile only; leave the OpenCL survey to the first run that needs it",
    )


def _start(name: str) -> tuple[subprocess.Popen, object]:
    """A process compiling group ``name``; its output goes to a temporary file (a pipe left
    unread could fill and stall it)."""
    out = tempfile.TemporaryFile(mode="w+")
    cmd = module_argv("rtsar.app.prepare", name)
    return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, text=True), out


def _outcome(process: subprocess.Popen, out) -> tuple[float, int, str | None]:
    """(seconds, kernels compiled, error or None) of a finished group's process."""
    out.seek(0)
    lines = out.read().splitlines()
    out.close()
    for line in reversed(lines):
        if line.startswith("{"):
            try:
                answer = json.loads(line)
                return answer["seconds"], answer["compiled"], answer["error"]
            except (ValueError, KeyError):
                break
    code = process.returncode
    why = f"killed by signal {-code}" if code < 0 else f"exit status {code}"
    last = next((ln.strip() for ln in reversed(lines) if ln.strip()), "no output")
    return 0.0, 0, f"its process ended without an answer ({why}; {last})"


def _compile_all(workers: int, say) -> list[str]:
    """Every group of TASKS in processes of its own, ``workers`` at a time, each said as it
    ends; the groups that failed.  Ctrl-C (or any error here) kills the processes left."""
    pending, running, failed = list(TASKS), {}, []
    try:
        while pending or running:
            while pending and len(running) < workers:
                name = pending.pop(0)
                running[name] = _start(name)
            for name, (process, out) in list(running.items()):
                if process.poll() is None:
                    continue
                del running[name]
                seconds, compiled, error = _outcome(process, out)
                if error is not None:
                    failed.append(name)
                    say(f"  {TASKS[name]}: failed: {error}", flush=True)
                    continue
                what = (
                    f"{compiled} kernel{'s' if compiled != 1 else ''} compiled"
                    if compiled
                    else "in the cache already"
                )
                say(f"  {TASKS[name]}: {what}, {seconds:.1f} s", flush=True)
            time.sleep(0.05)
    finally:
        for process, out in running.values():  # Ctrl-C: the compiles stop now
            process.kill()
            process.wait()
            out.close()
    return failed


def run(args) -> int:
    """``rtsar prepare``: the kernels, then the survey; exit status 1 if a group failed or a
    kernel is not in numba's cache after."""
    if args.workers < 1:
        raise ValueError(f"--workers must be >= 1, got {args.workers}")
    workers = min(args.workers, len(TASKS))
    say = print
    t0 = time.perf_counter()
    say(
        f"compiling rtsar's numba kernels (complex64, the presets' precision) into numba's "
        f"cache, {len(TASKS)} groups, {workers} at a time (once an installation: tens of "
        "seconds on 2 cores; a few seconds when run again) …",
        flush=True,
    )
    failed = _compile_all(workers, say)
    state = kernel_cache_state()
    if state is None:
        say("kernels: numba's cache could not be read (another numba version?)")
    else:
        cached, total, folders, missing = state
        where = ", ".join(folders[:2]) + (", …" if len(folders) > 2 else "")
        say(f"kernels: {cached} of {total} in numba's cache ({where})")
        if missing:
            failed.append("cache")
            shown = ", ".join(missing[:4]) + (", …" if len(missing) > 4 else "")
            say(
                f"  not in this cache: {shown} (compiled by another user, in another "
                "environment or into another folder? run `rtsar prepare` as the runs will run)"
            )
    if not args.no_survey:
        _survey(say)
    say(
        f"prepared in {time.perf_counter() - t0:.1f} s"
        + ("" if not failed else f"; not all: {', '.join(failed)} (above)")
    )
    return 1 if failed else 0


def _survey(say) -> None:
    """The survey of the OpenCL devices a run's ``--lens auto`` chooses from, now and alone."""
    try:
        known = cl_devices.survey_is_known()
        report, why = cl_devices.default_device(say=lambda line: say(line, flush=True))
    except Exception as exc:  # no platform, a driver's error: the runs will say it too
        say(f"OpenCL: not surveyed ({exc}); runs use NumPy's lens where no device works")
        return
    state = "surveyed before, kept" if known else "surveyed, kept for later runs"
    if report is None:
        say(f"OpenCL devices {state}: {why}")
    else:
        say(f"OpenCL devices {state}: the lens runs on {report.short_label} by default")


if __name__ == "__main__":  # one group, in its own process (_start): its answer as JSON
    _name, _seconds, _compiled, _error = run_task(sys.argv[1])
    print(json.dumps({"seconds": _seconds, "compiled": _compiled, "error": _error}), flush=True)
