"""Probing OpenCL devices for the AO lens, each driver in a child process of its own.

A driver that crashes or hangs while compiling must not take rtsar down with it, so every
device is probed by ``python -m rtsar.lens.cl_probe probe …`` in a process of its own: the lens
kernel of a preset built, 8 pulses compared with the float64 reference
(:func:`rtsar.lens.base.compress_reference`; refused beyond ``TOLERANCE`` of the peak).  The
devices that pass are then timed together by one more child process, ``… time …``,
interleaved in rounds with the NumPy lens of the same plan (each keeps its best round), so a
neighbour's burst of load on a shared machine favours none of them.  A crash, a hang or an
error becomes that device's ``reason``.
"""

from __future__ import annotations

import contextlib
import json
import signal
import subprocess
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import pyopencl as cl

from ..child import module_argv
from . import cl_vendors

# The ICD loader reads OCL_ICD_VENDORS at its first call (importing pyopencl makes none).
cl_vendors.register()

__all__ = [
    "SURVEY_BATCH",
    "SURVEY_PRESET",
    "TOLERANCE",
    "DeviceReport",
    "best_rates",
    "describe",
    "first_line",
    "identity",
    "keeps_signal_handlers",
    "list_devices",
    "probe_all",
    "throughput",
]

SURVEY_PRESET = "psaltis-max"
SURVEY_BATCH = 64
TOLERANCE = 1e-5  # max |lens − reference| / peak, complex64
NO_PLATFORM = "no OpenCL platform found"
_TIMEOUT_S = 180.0  # a build; timing is given its own length on top


@dataclass
class DeviceReport:
    """One device as probed (``reason`` None: it builds and its lines are right)."""

    index: int
    platform: str
    platform_version: str
    name: str
    driver_version: str
    kind: str
    reason: str | None = None
    error: float | None = None  # max |lens − reference| / peak
    build_s: float | None = None  # kernel build and first batch, s (a driver's cache shortens it)
    rates: dict = field(default_factory=dict)  # batch (str) → pulses/s on the probed preset
    note: str | None = None  # why a device that builds and is right has no rates

    @property
    def label(self) -> str:
        return f"{self.platform} / {self.name}"

    @property
    def short_label(self) -> str:
        return f"{self.platform} {self.driver_version} / {self.name}"

    @property
    def full_label(self) -> str:
        driver = f"(driver {self.driver_version})"
        return f"{self.platform} {self.platform_version} / {self.name} {driver}"

    def rate(self, batch: int = SURVEY_BATCH) -> float | None:
        return self.rates.get(str(batch))


def _clean(text) -> str:
    return " ".join(str(text).split())


def _kind(device_type: int) -> str:
    for bit, name in (
        (cl.device_type.GPU, "GPU"),
        (cl.device_type.CPU, "CPU"),
        (cl.device_type.ACCELERATOR, "accelerator"),
    ):
        if device_type & bit:
            return name
    return cl.device_type.to_string(device_type)


_found: list | None = None  # the devices, listed once a process (the drivers do not change)

_KEPT_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")


@contextlib.contextmanager
def keeps_signal_handlers():
    """The process's handlers of SIGINT, SIGTERM and SIGHUP as they were before the block or
    the call (main thread only): an OpenCL driver built on LLVM (PoCL, Intel's CPU runtime)
    puts handlers of its own on them as it loads, builds or makes a context, ones the system
    resets to the default while they run, so that a second signal then killed rtsar outright
    (rtsar.app.signals, which puts rtsar's back again before a run's stream).  A generator's
    context manager, so each decorated call keeps its own (one instance shared by every call
    of a decorated function had let a call on another thread overwrite the main thread's)."""
    main = threading.current_thread() is threading.main_thread()
    names = [n for n in _KEPT_SIGNALS if hasattr(signal, n)] if main else []
    saved = [(getattr(signal, n), signal.getsignal(getattr(signal, n))) for n in names]
    try:
        yield
    finally:
        for signum, handler in saved:
            if handler is not None:  # (None: set outside Python; nothing to put back)
                signal.signal(signum, handler)


@keeps_signal_handlers()
def list_devices(hint: str = "") -> list[cl.Device]:
    """All OpenCL devices of all platforms, in the loader's order; RuntimeError if none.
    Listed once a process (about 20 ms a listing with three drivers)."""
    global _found
    if _found:
        return list(_found)
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:  # PLATFORM_NOT_FOUND_KHR from the ICD loader
        raise RuntimeError(f"{NO_PLATFORM}{'; ' + hint if hint else ''}") from exc
    devices = []
    for plat in platforms:
        try:
            devices.extend(plat.get_devices())
        except cl.Error:  # a platform without devices
            continue
    if not devices:
        raise RuntimeError(f"{NO_PLATFORM}{'; ' + hint if hint else ''}")
    _found = devices
    return list(devices)


def describe(index: int, device: cl.Device) -> DeviceReport:
    """The identity of a device (nothing probed yet)."""
    return DeviceReport(
        index=index,
        platform=_clean(device.platform.name),
        platform_version=_clean(device.platform.version),
        name=_clean(device.name),
        driver_version=_clean(device.driver_version),
        kind=_kind(device.type),
    )


def identity(r: DeviceReport) -> list:
    return [r.platform, r.platform_version, r.name, r.driver_version, r.kind]


def first_line(exc: BaseException) -> str:
    """The line of a driver's error that says what went wrong."""
    text = str(exc)
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error:")]
    reason = (errors or lines or [type(exc).__name__])[0]
    parts = reason.split(" - ")  # pyopencl repeats "clBuildProgram failed: X - …" per layer
    reason = " - ".join(dict.fromkeys(p.strip() for p in parts))
    if "unknown target CPU" in text:
        reason = f"the driver's compiler does not know this CPU model ({reason})"
    return reason


def throughput(lens, batch: int, seconds: float, rng=None) -> float:
    """Pulses/s of ``lens.compress`` on batches of ``batch`` random pulses: ``batch`` over the
    median time of a call, after 3 warm-up calls, over at least ``seconds`` and 10 calls (the
    median, so a neighbour's burst of load on a shared machine does not decide)."""
    import numpy as np

    rng = rng or np.random.default_rng(0)
    S = lens.plan.samples_per_shot
    x = (rng.standard_normal((batch, S)) + 1j * rng.standard_normal((batch, S))).astype(lens.dtype)
    for _ in range(3):
        lens.compress(x)
    times, start = [], time.perf_counter()
    while len(times) < 10 or time.perf_counter() - start < seconds:
        t0 = time.perf_counter()
        lens.compress(x)
        times.append(time.perf_counter() - t0)
    return batch / float(np.median(times))


def best_rates(lenses: dict, batches, seconds: float, rounds: int = 3) -> dict:
    """``{name: {batch: pulses/s}}`` of several lenses timed interleaved (every lens at every
    batch once a round, ``seconds`` each), each keeping its best round: a neighbour's burst of
    load on a shared machine falls on all of them alike."""
    best = {name: dict.fromkeys(map(int, batches), 0.0) for name in lenses}
    for _ in range(rounds):
        for b in map(int, batches):
            for name, lens in lenses.items():
                best[name][b] = max(best[name][b], throughput(lens, b, seconds))
    return best


# --------------------------------------------------------------------------------------------
# in the parent process
# --------------------------------------------------------------------------------------------


def _child(args: list[str], timeout_s: float) -> tuple[dict | None, str | None]:
    """Run ``python -m rtsar.lens.cl_probe_child ARGS``: (its JSON answer, None) or (None, why)."""
    cmd = module_argv("rtsar.lens.cl_probe_child", *args)
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired:
        return None, f"no answer within {timeout_s:.0f} s"
    if done.returncode < 0:
        try:
            name = signal.Signals(-done.returncode).name
        except ValueError:
            name = f"signal {-done.returncode}"
        return None, f"the driver crashed ({name})"
    for line in reversed(done.stdout.splitlines()):
        if line.startswith("{"):
            try:
                return json.loads(line), None
            except ValueError:
                break
    tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
    return None, f"the probe failed (exit {done.returncode}): {tail}"


def probe_all(
    reports: list[DeviceReport], preset_name: str, batches, seconds: float
) -> tuple[list[DeviceReport], dict]:
    """Every device probed in a child process of its own, then the passing ones timed together
    with the NumPy lens in one more; returns the reports and the NumPy lens's rates.  The
    probes (a build and a check each, no timing) run at once, one child a device: on a shared
    2-core machine, three CPU devices' probes took 2.0-2.9 s together against 2.3-3.5 s one
    after another (two pairs of runs)."""
    jobs = [["probe", str(r.index), json.dumps(identity(r)), preset_name] for r in reports]
    with ThreadPoolExecutor(max_workers=max(1, len(jobs))) as pool:
        answers = list(pool.map(lambda args: _child(args, _TIMEOUT_S), jobs))
    out = []
    for r, (answer, why) in zip(reports, answers, strict=True):
        if answer is None:
            r.reason = f"{why} while building the lens"
            out.append(r)
        else:
            out.append(DeviceReport(**answer))
    by_index = {r.index: r for r in out}
    ok = [r.index for r in out if r.reason is None]
    spec = [preset_name, ",".join(str(int(b)) for b in batches), repr(float(seconds))]
    # the timing's own length (every device and the NumPy lens, every batch), with room
    timeout = _TIMEOUT_S + 3 * float(seconds) * len(batches) * (len(ok) + 1)
    answer, why = _child(["time", ",".join(map(str, ok)), *spec], timeout)
    if answer is None:  # a driver that builds and then fails: time each alone to find it
        answer = {}
        for i in ok:
            one, why_one = _child(["time", str(i), *spec], timeout)
            if one is None and "crashed" in why_one:  # it would crash a run too
                by_index[i].reason = f"{why_one} while timing the lens"
            elif one is None:  # built and right, but not timed: a candidate, ranked last
                by_index[i].note = f"not timed ({why_one})"
            else:
                answer.update({k: v for k, v in one.items() if k != "numpy"})
                answer.setdefault("numpy", one.get("numpy", {}))
    for i in ok:
        if by_index[i].reason is None:
            by_index[i].rates = answer.get(str(i), {})
    return out, answer.get("numpy", {})
