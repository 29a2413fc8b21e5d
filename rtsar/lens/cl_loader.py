"""The one OpenCL kernel loader of rtsar: device choice, kernel sources, cached program builds.

Kernels live in ``.cl`` files, one per stage, in the top-level ``kernels/`` folder of a source
checkout; ``pip install`` ships the same folder as the package ``rtsar.kernels``.  Programs are
specialised with ``-D`` build options (never by editing the source text) and built once per
(context, file, options).

Device choice, in order: an explicit ``device`` argument (a ``pyopencl.Device`` or a
case-insensitive substring of "platform name / device name"), the environment variable
``RTSAR_OPENCL_DEVICE`` (same substring rule), else PoCL's CPU device, else any CPU device, else
the first device found.
"""

from __future__ import annotations

import importlib.resources
import os
import threading
import weakref
from collections.abc import Mapping, Sequence
from pathlib import Path

import pyopencl as cl

__all__ = [
    "ENV_DEVICE",
    "build_program",
    "default_queue",
    "device_info",
    "kernel_path",
    "kernel_source",
    "kernels_dir",
    "list_devices",
    "probe",
    "select_device",
]

ENV_DEVICE = "RTSAR_OPENCL_DEVICE"

_NO_PLATFORM = (
    "no OpenCL platform found.  rtsar runs its kernels on any OpenCL device; the portable CPU "
    "driver PoCL comes with `pip install pyopencl[pocl]` (or install an ICD for your GPU)."
)

_lock = threading.RLock()
_programs: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # ctx -> {key: Program}
_queues: dict[int, cl.CommandQueue] = {}  # device.int_ptr -> queue on a context of its own


# --------------------------------------------------------------------------------------------
# kernel sources
# --------------------------------------------------------------------------------------------


def kernels_dir():
    """Folder holding the ``.cl`` sources (a ``Traversable``; a ``Path`` in a source checkout).

    The installed package ``rtsar.kernels`` is preferred; without it (a checkout on
    ``sys.path``) the top-level ``kernels/`` folder next to the ``rtsar`` package is used.
    """
    try:
        folder = importlib.resources.files("rtsar.kernels")
        if folder.joinpath("lens.cl").is_file():
            return folder
    except ModuleNotFoundError:
        pass
    checkout = Path(__file__).resolve().parents[2] / "kernels"
    if (checkout / "__init__.py").is_file():
        return checkout
    raise FileNotFoundError(
        "rtsar's OpenCL kernels were not found: neither the package rtsar.kernels nor the "
        f"folder {checkout} exists (reinstall rtsar, or run from a complete source checkout)"
    )


def kernel_path(name: str):
    """The kernel file ``name`` (e.g. ``"lens.cl"``); FileNotFoundError if it is missing."""
    path = kernels_dir().joinpath(name)
    if not path.is_file():
        raise FileNotFoundError(f"OpenCL kernel file {name!r} not found in {kernels_dir()}")
    return path


def kernel_source(name: str) -> str:
    """Text of the kernel file ``name``."""
    return kernel_path(name).read_text(encoding="utf-8")


# --------------------------------------------------------------------------------------------
# devices
# --------------------------------------------------------------------------------------------


def list_devices() -> list[cl.Device]:
    """All OpenCL devices of all platforms; RuntimeError if there is no platform at all."""
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:  # PLATFORM_NOT_FOUND_KHR from the ICD loader
        raise RuntimeError(_NO_PLATFORM) from exc
    devices = []
    for platform in platforms:
        try:
            devices.extend(platform.get_devices())
        except cl.Error:  # a platform without devices
            continue
    if not devices:
        raise RuntimeError(_NO_PLATFORM)
    return devices


def _label(device: cl.Device) -> str:
    return f"{device.platform.name.strip()} / {device.name.strip()}"


def _is_pocl(device: cl.Device) -> bool:
    name = device.platform.name.lower()
    return "portable computing language" in name or "pocl" in name


def select_device(device: cl.Device | str | None = None) -> cl.Device:
    """Pick the OpenCL device (see the module docstring for the order of preference).

    Parameters
    ----------
    device : pyopencl.Device or str, optional
        A device, or a case-insensitive substring of ``"platform name / device name"``.
        Without it the environment variable ``RTSAR_OPENCL_DEVICE`` is consulted.

    Raises
    ------
    RuntimeError
        No OpenCL platform, or no device matches the requested name.
    """
    if isinstance(device, cl.Device):
        return device
    devices = list_devices()
    wanted = device if device is not None else os.environ.get(ENV_DEVICE, "").strip()
    if wanted:
        matches = [d for d in devices if wanted.lower() in _label(d).lower()]
        if not matches:
            names = "; ".join(_label(d) for d in devices)
            source = "" if device is not None else f" (from {ENV_DEVICE})"
            raise RuntimeError(f"no OpenCL device matches {wanted!r}{source}; available: {names}")
        return matches[0]
    for accept in (
        lambda d: _is_pocl(d) and d.type & cl.device_type.CPU,
        lambda d: d.type & cl.device_type.CPU,
        lambda d: True,
    ):
        for d in devices:
            if accept(d):
                return d
    raise AssertionError("unreachable")


def default_queue(device: cl.Device | str | None = None) -> cl.CommandQueue:
    """A shared in-order command queue (and context) for the selected device.

    All users of one device share the context, so programs built for it are built once.
    """
    dev = select_device(device)
    with _lock:
        queue = _queues.get(dev.int_ptr)
        if queue is None:
            queue = cl.CommandQueue(cl.Context([dev]))
            _queues[dev.int_ptr] = queue
        return queue


def device_info(device: cl.Device | cl.Context | cl.CommandQueue | str | None = None) -> str:
    """One line describing a device, e.g. for logs and benchmark reports."""
    if isinstance(device, cl.CommandQueue):
        device = device.device
    elif isinstance(device, cl.Context):
        device = device.devices[0]
    dev = select_device(device)
    kind = cl.device_type.to_string(dev.type)
    return (
        f"{dev.name.strip()} [{dev.platform.name.strip()}, {dev.version.strip()}, {kind}, "
        f"{dev.max_compute_units} compute units, {dev.local_mem_size // 1024} KiB local memory]"
    )


# --------------------------------------------------------------------------------------------
# programs
# --------------------------------------------------------------------------------------------


def _define(name: str, value) -> str:
    if not name.isidentifier():
        raise ValueError(f"bad macro name {name!r}")
    if isinstance(value, bool):
        value = int(value)
    text = str(value)
    if not text or any(c.isspace() for c in text):
        raise ValueError(f"macro {name} needs a value without spaces, got {value!r}")
    return f"-D{name}={text}"


def build_program(
    context: cl.Context,
    name: str,
    defines: Mapping[str, object] | None = None,
    options: Sequence[str] = (),
) -> cl.Program:
    """Build (or fetch from the cache) the kernel file ``name`` for ``context``.

    Parameters
    ----------
    context : pyopencl.Context
    name : str
        File in the kernels folder, e.g. ``"lens.cl"``.
    defines : mapping, optional
        Macros passed as ``-DNAME=value`` (the only way kernels are specialised).
    options : sequence of str
        Further compiler options, e.g. ``("-cl-mad-enable",)``.
    """
    opts = tuple(_define(k, v) for k, v in sorted((defines or {}).items())) + tuple(options)
    key = (name, opts)
    with _lock:
        cache = _programs.setdefault(context, {})
        program = cache.get(key)
    if program is not None:
        return program
    source = kernel_source(name)
    try:
        program = cl.Program(context, source).build(options=list(opts))
    except cl.RuntimeError as exc:
        text = str(exc)
        errors = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("error:")]
        first = errors[0] if errors else (text.strip().splitlines() or ["no build log"])[0]
        hint = _build_hint(text).replace("\n", " ")
        raise RuntimeError(
            f"building {name} on {context.devices[0].name.strip()} failed: {first}{hint}"
        ) from exc
    with _lock:
        return cache.setdefault(key, program)


def _build_hint(log: str) -> str:
    """What a user can do about a build failure the driver, not the kernel, caused."""
    if "unknown target CPU" in log:
        return (
            "\nThis OpenCL driver's compiler (PoCL's LLVM) does not know this CPU model, so it "
            "cannot build any kernel here.  Use `--lens numpy` (or `--lens auto`, the default, "
            "which falls back by itself), pick another device with RTSAR_OPENCL_DEVICE, or "
            f"install a newer PoCL.  {FALLBACK_HINT}"
        )
    return ""


FALLBACK_HINT = (
    "Any OpenCL driver works: a newer PoCL (e.g. the distribution's pocl-opencl-icd), a GPU's "
    "ICD, or Intel's CPU OpenCL runtime."
)


_probes: dict[str, str | None] = {}
_PROBE_KERNEL = "__kernel void probe(__global float *x) { x[get_global_id(0)] *= 2.0f; }"


def probe(device: cl.Device | str | None = None) -> str | None:
    """None if OpenCL can build and run a kernel on the selected device, else why not (one line).

    Done once per process and device request; ``make_lens(backend="auto")`` uses it to choose
    between the OpenCL lens and the NumPy one.
    """
    key = device if isinstance(device, str) or device is None else _label(device)
    if device is None:  # the environment chooses the device: a change of it is another probe
        key = f"env:{os.environ.get(ENV_DEVICE, '')}"
    with _lock:
        if key in _probes:
            return _probes[key]
    try:
        queue = default_queue(device)
        program = cl.Program(queue.context, _PROBE_KERNEL).build()
        buf = cl.Buffer(queue.context, cl.mem_flags.READ_WRITE, 4)
        program.probe(queue, (1,), None, buf)
        queue.finish()
        reason = None
    except (cl.Error, RuntimeError) as exc:
        text = str(exc)
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        errors = [ln for ln in lines if ln.startswith("error:")]
        reason = (errors or lines or [type(exc).__name__])[0]
        if "unknown target CPU" in text:
            reason = f"PoCL's compiler does not know this CPU model ({reason})"
    with _lock:
        _probes[key] = reason
    return reason
