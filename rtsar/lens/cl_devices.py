"""Which OpenCL device runs the AO lens: every device the loader sees, probed and measured.

Every device of every platform is a candidate: pyopencl's bundled PoCL, the system's drivers
(``/etc/OpenCL/vendors``), a driver installed with pip (:mod:`rtsar.lens.cl_vendors`), GPUs.
The *survey* probes each one in a child process of its own (a driver that crashes or hangs
while compiling takes only that process down): it builds the lens kernel for the
``psaltis-max`` plan, compares 8 pulses with the float64 reference
(:func:`rtsar.lens.base.compress_reference`; refused beyond 1e-5 of the peak) and measures the
lens's throughput.  The survey is kept in the cache folder (:mod:`rtsar.lens.cache`), keyed by
a fingerprint of the devices, their drivers, the CPU, the host and the kernel source: it is
measured once per machine, and again when any of these changes (``rtsar devices`` measures
anew and shows it all).

The default device (no ``--device``, no ``RTSAR_OPENCL_DEVICE``) is the fastest device that
builds and computes the lens right, at batch 64 on ``psaltis-max``; with one such device, that
one.  A survey again keeps the default before unless another device is DEFAULT_MARGIN faster
(``kept_default``).  A device asked for is a case-insensitive part of ``"platform / device"``
(as before), of ``"platform driver / device"`` or of ``"platform version / device (driver
version)"`` (a driver version tells two PoCLs apart), or its index in ``rtsar devices``;
several matches: the fastest that builds.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import os
import platform as _platform
import shlex
import sys
import threading
import time
from dataclasses import asdict

import pyopencl as cl

from . import cl_probe, cl_vendors
from .cache import measuring, rates_or_none, read_json, write_json
from .cl_probe import (
    NO_PLATFORM,
    SURVEY_BATCH,
    SURVEY_PRESET,
    TOLERANCE,
    DeviceReport,
    describe,
    identity,
    probe_all,
)
from .cl_sources import kernel_source

__all__ = [
    "ENV_DEVICE",
    "SURVEY_BATCH",
    "SURVEY_PRESET",
    "TOLERANCE",
    "DeviceReport",
    "default_device",
    "install_hint",
    "list_devices",
    "measure",
    "ranked",
    "select_device",
    "survey",
]

ENV_DEVICE = "RTSAR_OPENCL_DEVICE"
_CACHE = "opencl-devices.json"
# A survey again (`rtsar devices`) names another default only where it is this much faster than
# the default before: two devices within it swap places on the machine's noise (2-core Xeon,
# 2026-11-30, five runs of `rtsar devices`: Intel's runtime 118,414 against PoCL 3.0's
# 122,897 pulses/s at batch 64, the default moved to PoCL, and back at the next run).
DEFAULT_MARGIN = 0.10
KEEP_SURVEYS = 8  # fingerprints kept (checkouts, driver versions): the newest


def list_devices() -> list[cl.Device]:
    """All OpenCL devices of all platforms, in the loader's order; RuntimeError (with what to
    install) if there is none."""
    return cl_probe.list_devices(install_hint())


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return _platform.processor() or _platform.machine()


# rtsar's own code on the lens's path: a refusal it caused must not outlive its fix
_HOST_SOURCES = ("opencl.py", "cl_launch.py", "plan.py", "cl_probe_child.py", "cl_loader.py")
# what sets how fast a driver runs besides the driver itself
_SPEED_ENV = ("POCL_", "OMP_", "NUMBA_", "KMP_", "CL_CONFIG_", "TBB_")
_NOT_SPEED = ("_CACHE_DIR", "_DEBUG_CACHE")  # where caches live: no device runs faster for it


def _driver_files() -> list:
    """(path, size, mtime) of every driver library the loader can load: a patched driver
    with the same version string is another driver."""
    folders = [os.environ.get(cl_vendors.ENV_VENDORS), "/etc/OpenCL/vendors"]
    libs = set()
    for folder in filter(None, folders):
        try:
            for icd in os.scandir(folder):
                if icd.name.endswith(".icd"):
                    with open(icd.path, encoding="utf-8", errors="replace") as f:
                        libs.add(f.read().strip())
        except OSError:
            continue
    bundled = os.path.join(os.path.dirname(cl.__file__), ".libs")  # pyopencl's own PoCL
    try:
        libs.update(e.path for e in os.scandir(bundled) if ".so" in e.name)
    except OSError:
        pass
    out = []
    for lib in sorted(libs):
        try:
            st = os.stat(lib)
            out.append((lib, st.st_size, int(st.st_mtime)))
        except OSError:  # a bare name the loader resolves itself
            out.append((lib, None, None))
    return out


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def fingerprint(reports: list[DeviceReport]) -> str:
    """What the survey's result depends on: devices, driver versions and libraries, CPU, cores,
    host, the speed settings in the environment, the kernel source and rtsar's host code."""
    here = os.path.dirname(__file__)
    host = []
    for name in _HOST_SOURCES:
        try:
            with open(os.path.join(here, name), encoding="utf-8") as f:
                host.append(f.read())
        except OSError:
            host.append(name)
    speed = sorted(
        (k, v)
        for k, v in os.environ.items()
        if k.startswith(_SPEED_ENV) and not k.endswith(_NOT_SPEED)
    )
    h = hashlib.sha256()
    for part in (
        json.dumps([identity(r) for r in reports]),
        json.dumps(_driver_files()),
        _cpu_model(),
        str(_cores()),
        _platform.node(),
        json.dumps(speed),
        kernel_source("lens.cl"),
        *host,
        json.dumps([SURVEY_PRESET, SURVEY_BATCH, TOLERANCE]),
    ):
        h.update(part.encode("utf-8", "replace"))
        h.update(b"\0")
    return h.hexdigest()[:32]


# --------------------------------------------------------------------------------------------
# the survey and the choice
# --------------------------------------------------------------------------------------------

_lock = threading.RLock()
_survey: list[DeviceReport] | None = None
_survey_key: str | None = None
_survey_at: str = ""  # when it was measured ("%Y-%m-%dT%H:%M:%S%z"; "" where not known)
_survey_kept: str = ""  # the full label of a default kept within DEFAULT_MARGIN ("": none)


def measure(
    preset_name: str = SURVEY_PRESET, batches=(SURVEY_BATCH,), seconds: float = 0.3, say=None
) -> tuple[list[DeviceReport], dict]:
    """Probe every device now (:func:`rtsar.lens.cl_probe.probe_all`): the reports, and the
    NumPy lens's pulses/s timed beside them.  The result becomes the survey where it measured
    what the survey needs (``SURVEY_PRESET`` at ``SURVEY_BATCH``)."""
    with _lock:
        reports = [describe(i, d) for i, d in enumerate(list_devices())]
        if say is not None:
            say(
                f"probing {len(reports)} OpenCL device{'s' if len(reports) != 1 else ''} "
                f"with the lens of {preset_name} (one yardstick plan for every run, whatever "
                "its own; a second or two each; kept for later runs)"
            )
        measured, numpy_rates = probe_all(reports, preset_name, batches, seconds)
        at = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        hung = any("no answer within" in (r.reason or r.note or "") for r in measured)
        if preset_name == SURVEY_PRESET and SURVEY_BATCH in [int(b) for b in batches]:
            key = fingerprint(reports)
            kept = _surveys(read_json(_CACHE))
            stays = kept_default(measured, _default_of(kept.get(key, {})))
            if not hung:  # a hang may be this moment's: the next run asks again
                kept[key] = {
                    "fingerprint": key,
                    "measured_at": at,
                    "preset": SURVEY_PRESET,
                    "devices": [asdict(r) for r in measured],
                    "default": next((r.full_label for r in ranked(measured, stays)), ""),
                    "kept": stays,  # the default before, kept within DEFAULT_MARGIN
                }
                newest = sorted(kept, key=lambda k: str(kept[k].get("measured_at", "")))
                for old_key in newest[:-KEEP_SURVEYS]:
                    del kept[old_key]
                write_json(_CACHE, {"surveys": kept})
            _keep(measured, key, at, stays)
        return measured, numpy_rates


def survey(say=None) -> list[DeviceReport]:
    """Every device with its probe result (:func:`measure` on ``SURVEY_PRESET``), from the
    cache when it still describes this machine; ``say`` gets a line before any probing (the
    first run on a machine takes about a second a device)."""
    with _lock:
        known = _known_survey()
        if known is not None:
            return known

        def waiting() -> None:
            if say is not None:
                say("another rtsar is surveying the OpenCL devices: waiting for its survey")

        with measuring(_CACHE, waiting):  # one survey at a time on this machine
            known = _known_survey()
            return known if known is not None else measure(say=say)[0]


def survey_is_known() -> bool:
    """Whether :func:`survey` would answer without probing (this process's, or the cache's
    survey of these devices): what the first run on a machine would pay is known here."""
    with _lock:
        return _known_survey() is not None


def _known_survey() -> list[DeviceReport] | None:
    reports = [describe(i, d) for i, d in enumerate(list_devices())]
    key = fingerprint(reports)
    if _survey is not None and _survey_key == key:
        return _survey
    cached = _surveys(read_json(_CACHE)).get(key, {})
    if cached.get("fingerprint") == key:
        try:
            found = [DeviceReport(**d) for d in cached["devices"]]
        except (KeyError, TypeError):
            found = None
        if found and any(r.rates and rates_or_none(r.rates) is None for r in found):
            found = None  # a damaged rate (NaN, negative, not a number) is measured again
        if found and [identity(r) for r in found] == [identity(r) for r in reports]:
            stays = kept_default(found, str(cached.get("kept", "")))
            return _keep(found, key, str(cached.get("measured_at", "")), stays)
    return None


def _surveys(cache: dict) -> dict:
    """The cached surveys by fingerprint (one per checkout and machine that shares the cache
    folder, so two checkouts of one account do not probe again each time the other ran);
    the older one-survey file reads as one entry."""
    found = cache.get("surveys")
    if isinstance(found, dict):
        return {k: v for k, v in found.items() if isinstance(v, dict)}
    if isinstance(cache.get("fingerprint"), str):
        return {cache["fingerprint"]: cache}
    return {}


def survey_fingerprint() -> str:
    """The fingerprint of the devices the survey of this process described ("" before one)."""
    return _survey_key or ""


def _keep(reports: list[DeviceReport], key: str, at: str, stays: str = "") -> list[DeviceReport]:
    global _survey, _survey_key, _survey_at, _survey_kept
    _survey, _survey_key, _survey_at, _survey_kept = reports, key, at, stays
    return reports


def surveyed_words(at: str | None = None) -> str:
    """When the survey's figures were measured, in UTC ("surveyed 2026-11-29 23:25 UTC";
    ``at`` as the cache keeps it, default this process's survey; "" where unknown).  A run
    quotes a kept survey's rate beside its own figures of the same lens: the date says why
    they can differ (a shared machine's speed swings 2x from hour to hour)."""
    at = _survey_at if at is None else at
    try:
        when = datetime.datetime.strptime(at, "%Y-%m-%dT%H:%M:%S%z")
    except ValueError:
        return ""
    return f"surveyed {when.astimezone(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC"


def ranked(reports: list[DeviceReport], kept: str | None = None) -> list[DeviceReport]:
    """The devices that build the lens and compute it right, the fastest first (at
    ``SURVEY_BATCH``; one left untimed last), except the default before where it was kept
    (``kept``, its full label: kept_default; default the survey's own)."""
    ok = sorted((r for r in reports if r.reason is None), key=lambda r: -(r.rate() or 0.0))
    kept = _survey_kept if kept is None else kept
    stays = [r for r in ok if kept and r.full_label == kept]
    return stays + [r for r in ok if r not in stays]


def _default_of(entry: dict) -> str:
    """The full label of the default a kept survey named (one written before the field: its
    fastest, the default it gave); "" where none."""
    if isinstance(entry.get("default"), str):
        return entry["default"]
    try:  # (a damaged survey, its rates not numbers: none)
        reports = [DeviceReport(**d) for d in entry.get("devices", [])]
        return next((r.full_label for r in ranked(reports, "")), "")
    except (TypeError, ValueError):
        return ""


def kept_default(reports: list[DeviceReport], before: str) -> str:
    """The full label of the default before (``before``) where it stays the default of
    ``reports``: it builds and is timed, the fastest is not DEFAULT_MARGIN faster, and it is
    not the fastest itself; else "" (the fastest is the default)."""
    ok = ranked(reports, "")
    same = [r for r in ok if before and r.full_label == before and r.rate()]
    if not same or same[0] is ok[0]:
        return ""
    return before if (ok[0].rate() or 0.0) <= (1 + DEFAULT_MARGIN) * same[0].rate() else ""


def default_device(say=None) -> tuple[DeviceReport | None, str]:
    """The device the lens runs on by default, and why (one line); None where none builds."""
    reports = survey(say=say)
    ok = ranked(reports)
    if not ok:
        return None, refusal_summary(reports)
    best = ok[0]
    if len(ok) == 1:
        others = len(reports) - 1
        why = (
            "the only OpenCL device here"
            if not others
            else (f"the only one of {len(reports)} OpenCL devices that builds the lens")
        )
        return best, why
    second = ok[1]
    when = surveyed_words()
    when = f"; {when}" if when else ""
    if _survey_kept and best.full_label == _survey_kept:
        return best, (
            f"the default before, kept: {best.rate():,.0f} pulses/s at batch {SURVEY_BATCH} "
            f"on {SURVEY_PRESET}, within {DEFAULT_MARGIN:.0%} of the fastest of {len(ok)} "
            f"OpenCL devices that build the lens ({second.short_label}, "
            f"{second.rate() or 0:,.0f}{when})"
        )
    return best, (
        f"the fastest of {len(ok)} OpenCL devices that build the lens: "
        f"{best.rate():,.0f} pulses/s at batch {SURVEY_BATCH} on {SURVEY_PRESET} "
        f"(next: {second.short_label}, {second.rate() or 0:,.0f}{when})"
    )


def refusal_summary(reports: list[DeviceReport]) -> str:
    """Why no device runs the lens, with what to install (one line)."""
    if not reports:
        return f"{NO_PLATFORM}; {install_hint()}"
    parts = "; ".join(f"{r.label}: {_without_hint(r.reason)}" for r in reports)
    return f"no OpenCL device builds the lens ({parts}); {install_hint(all_refused=True)}"


def _without_hint(reason: str | None) -> str:
    """A device's refusal without the advice a build failure carries (said once, at the end)."""
    text = str(reason or "")
    cut = text.find(BUILD_HINT_START)
    return text[:cut].rstrip() if cut >= 0 else text


BUILD_HINT_START = "  This OpenCL driver's compiler"  # where cl_loader's advice begins


def install_hint(all_refused: bool = False) -> str:
    """Exactly what to install for a working OpenCL CPU device on this machine (one phrase);
    ``all_refused``: said where every device was refused (Intel's runtime, if installed, too)."""
    machine = _platform.machine().lower()
    # The interpreter in full: `python3 -m pip` in a shell without the environment activated
    # would install outside it, where rtsar never looks.
    python = shlex.quote(sys.executable or "python3")
    pip = f"{python} -m pip install intel-opencl-rt intel-cmplr-lib-rt"
    if sys.platform.startswith("linux"):
        apt = _system_pocl_command()
        if machine in ("x86_64", "amd64"):
            found = cl_vendors.find_pip_drivers()
            reg = cl_vendors.registration()
            own = os.environ.get(cl_vendors.ENV_VENDORS, "")
            if found and own and not (reg is not None and reg.registered):
                lib = next(iter(found.values()))
                return (
                    f"Intel's CPU runtime is installed in this environment, but your "
                    f"{cl_vendors.ENV_VENDORS}={own} hides it from the ICD loader: unset it, "
                    f"or add an .icd file there naming {lib}"
                )
            if found and all_refused:
                return (
                    "Intel's CPU runtime is installed but refused (see `rtsar devices`); "
                    f"install the system's PoCL: {apt}"
                )
            if found:  # it may well be the device that runs: point to it, don't judge it
                return (
                    "Intel's CPU runtime is installed here (`rtsar devices` lists what it "
                    f"builds); where it refuses too, the system's PoCL: {apt}"
                )
            return (
                f"install Intel's CPU OpenCL runtime into this environment: {pip} "
                f"(rtsar registers it itself), or the system's PoCL: {apt}"
            )
        return f"install the system's PoCL: {apt}"
    if sys.platform == "darwin":
        return f"install PoCL into this environment: {python} -m pip install 'pyopencl[pocl]'"
    return "install an OpenCL driver for this machine (a GPU's, Intel's CPU runtime, or PoCL)"


def _system_pocl_command() -> str:
    from shutil import which

    for tool, cmd in (
        ("apt-get", "sudo apt-get install pocl-opencl-icd"),
        ("dnf", "sudo dnf install pocl"),
        ("pacman", "sudo pacman -S pocl"),
        ("zypper", "sudo zypper install pocl"),
    ):
        if which(tool):
            return cmd
    return "your distribution's pocl package"


def _matches(wanted: str, reports: list[DeviceReport]) -> list[DeviceReport]:
    """The devices ``wanted`` names: an index of ``rtsar devices`` (where there is one), else a
    case-insensitive part of "platform / device", of "platform driver / device" or of the
    full label with the platform's version."""
    text = wanted.strip()
    if text.isdigit() and int(text) < len(reports):
        return [r for r in reports if r.index == int(text)]
    low = text.lower()
    return [
        r for r in reports
        if any(low in s.lower() for s in (r.label, r.short_label, r.full_label))
    ]  # fmt: skip


def select_device(device: cl.Device | str | None = None, say=None) -> cl.Device:
    """The OpenCL device for ``device`` (a device, a name substring or an index), else
    ``RTSAR_OPENCL_DEVICE``, else :func:`default_device`.

    Raises RuntimeError when nothing matches, or no device builds the lens by default.
    """
    return chosen_device(device, say)[0]


def chosen_device(device: cl.Device | str | None = None, say=None) -> tuple[cl.Device, str]:
    """:func:`select_device`'s device and why, for the banner: the default's reason, or what
    was asked for, and where it names several devices, which they are (the fastest of them
    that builds runs)."""
    if isinstance(device, cl.Device):
        return device, "the device given"
    devices = list_devices()
    wanted = device if device is not None else os.environ.get(ENV_DEVICE, "").strip()
    if wanted:
        asked = f"--device {wanted}" if device is not None else f"{ENV_DEVICE}={wanted}"
        reports = [describe(i, d) for i, d in enumerate(devices)]
        matches = _matches(str(wanted), reports)
        if not matches:
            names = "; ".join(f"[{r.index}] {r.full_label}" for r in reports)
            source = "" if device is not None else f" (from {ENV_DEVICE})"
            raise RuntimeError(f"no OpenCL device matches {wanted!r}{source}; available: {names}")
        if len(matches) == 1:
            return devices[matches[0].index], f"asked for: {asked}"
        order = {r.index: k for k, r in enumerate(ranked(survey(say=say), ""))}  # fastest
        matches.sort(key=lambda r: order.get(r.index, len(order) + r.index))
        names = ", ".join(f"[{r.index}] {r.short_label}" for r in matches)
        why = (
            f"asked for: {asked}, which names {len(matches)} devices ({names}): the fastest of "
            f"them that builds the lens; `rtsar devices` lists their indexes, for --device N"
        )
        return devices[matches[0].index], why
    best, why = default_device(say=say)
    if best is None:
        raise RuntimeError(why)
    return devices[best.index], why
