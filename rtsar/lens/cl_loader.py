"""The one OpenCL kernel loader of rtsar: kernel sources, shared contexts, cached program builds.

Kernels live in ``.cl`` files, one per stage, in the top-level ``kernels/`` folder of a source
checkout; ``pip install`` ships the same folder as the package ``rtsar.kernels``.  Programs are
specialised with ``-D`` build options (never by editing the source text) and built once per
(context, file, options).  Which device runs them is chosen in :mod:`rtsar.lens.cl_devices`
(every device is a candidate; by default the fastest that builds the lens).
"""

from __future__ import annotations

import os
import threading
import warnings
import weakref
from collections.abc import Mapping, Sequence

import pyopencl as cl

# cl_devices registers the pip-installed drivers on import, before the ICD loader's first call
from .cl_devices import (
    ENV_DEVICE,
    chosen_device,
    default_device,
    install_hint,
    list_devices,
    select_device,
)
from .cl_probe import first_line, keeps_signal_handlers
from .cl_sources import kernel_path, kernel_source, kernels_dir

__all__ = [
    "ENV_DEVICE",
    "build_program",
    "chosen_device",
    "default_context_queue",
    "default_queue",
    "device_info",
    "kernel_path",
    "kernel_source",
    "kernels_dir",
    "list_devices",
    "probe",
    "select_device",
]

_lock = threading.RLock()
_programs: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # ctx -> {key: Program}
_queues: dict[int, tuple[cl.Context, cl.CommandQueue]] = {}  # device.int_ptr -> its own


# --------------------------------------------------------------------------------------------
# devices: chosen in rtsar.lens.cl_devices; one context and queue each, shared
# --------------------------------------------------------------------------------------------


def default_queue(device: cl.Device | str | None = None) -> cl.CommandQueue:
    """A shared in-order command queue (and context) for the selected device.

    All users of one device share the context, so programs built for it are built once.
    """
    return default_context_queue(device)[1]


@keeps_signal_handlers()
def default_context_queue(device: cl.Device | str | None = None):
    """``(context, queue)`` shared by every user of the selected device.

    The context is kept beside its queue: a queue's implicit reference to its context is not
    enough on every driver (Intel's CPU runtime answers ``queue.context`` with INVALID_CONTEXT
    once the application's own reference is gone).
    """
    dev = select_device(device)
    with _lock:
        pair = _queues.get(dev.int_ptr)
        if pair is None:
            context = cl.Context([dev])
            pair = (context, cl.CommandQueue(context))
            _queues[dev.int_ptr] = pair
        return pair


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


@keeps_signal_handlers()
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
        with warnings.catch_warnings():  # a driver's build log (Intel's: vectoriser remarks)
            warnings.simplefilter("ignore", cl.CompilerWarning)  # is not a message for users
            program = cl.Program(context, source).build(options=list(opts))
    except cl.RuntimeError as exc:
        text = str(exc)
        errors = [ln.strip() for ln in text.splitlines() if ln.strip().startswith("error:")]
        first = errors[0] if errors else (text.strip().splitlines() or ["no build log"])[0]
        hint = _build_hint(text).replace("\n", " ")  # "  This OpenCL driver's compiler …"
        raise RuntimeError(
            f"building {name} on {context.devices[0].name.strip()} failed: {first}{hint}"
        ) from exc
    with _lock:
        return cache.setdefault(key, program)


def _build_hint(log: str) -> str:
    """What a user can do about a build failure the driver, not the kernel, caused."""
    if "unknown target CPU" in log:
        return (  # begins with cl_devices.BUILD_HINT_START once its newlines are spaces
            "\n\nThis OpenCL driver's compiler (PoCL 3.0's LLVM) does not know this CPU model, so "
            "it cannot build any kernel here.  Pick another device (`rtsar devices` lists them; "
            f"RTSAR_OPENCL_DEVICE or --device), or {install_hint()}."
        )
    return ""


_probes: dict[str, str | None] = {}
_PROBE_KERNEL = "__kernel void probe(__global float *x) { x[get_global_id(0)] *= 2.0f; }"


@keeps_signal_handlers()
def probe(device: cl.Device | str | None = None, say=None) -> str | None:
    """None if the OpenCL lens can run on the device asked for, else why not (one line).

    Without a device asked for (``device`` or RTSAR_OPENCL_DEVICE), the answer is the survey's
    (:func:`rtsar.lens.cl_devices.default_device`: some device builds the lens, or why none
    does, with what to install).  A device asked for is probed in this process, once.
    """
    wanted = device if device is not None else os.environ.get(ENV_DEVICE, "").strip()
    if not wanted:
        try:
            best, why = default_device(say=say)
        except RuntimeError as exc:  # no platform at all
            return str(exc)
        return None if best is not None else why
    key = wanted if isinstance(wanted, str) else f"{wanted.platform.name} / {wanted.name}"
    with _lock:
        if key in _probes:
            return _probes[key]
    try:
        context, queue = default_context_queue(device)
        program = cl.Program(context, _PROBE_KERNEL).build()
        buf = cl.Buffer(context, cl.mem_flags.READ_WRITE, 4)
        program.probe(queue, (1,), None, buf)
        queue.finish()
        reason = None
    except (cl.Error, RuntimeError) as exc:
        reason = first_line(exc)
    with _lock:
        _probes[key] = reason
    return reason
