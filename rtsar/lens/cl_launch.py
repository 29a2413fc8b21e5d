"""Kernel launches that let the other threads run: clEnqueueNDRangeKernel called without the GIL.

pyopencl holds Python's GIL through ``enqueue_nd_range_kernel``.  On PoCL's CPU device that
call does real work (it wakes the device's threads and schedules the work-groups): 14-23 µs a
launch on a quiet 2-core machine and up to 100-150 µs on a loaded one, during which the CCD and
publishing threads of the pipeline cannot run a line of Python.  A ctypes call releases the GIL,
so :func:`gil_free_enqueue` calls the same OpenCL entry point through ctypes on the objects
pyopencl made (their handles, ``int_ptr``): every OpenCL object carries its driver's dispatch
table, so any ICD loader routes the call to the right driver.  The loader is the one already in
the process (pyopencl's), found in /proc/self/maps, else the system's ``libOpenCL``.  Without
one, or with ``RTSAR_CL_GIL_FREE`` set to 0, false, no or off (read once per process),
:func:`gil_free_enqueue` returns None and the lens launches through pyopencl.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading

_lock = threading.Lock()
_resolved = False
_enqueue = None


def _loader_path() -> str | None:
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as maps:
            for line in maps:
                path = line.split()[-1] if line.strip() else ""
                if "libOpenCL" in os.path.basename(path) and os.path.exists(path):
                    return path
    except OSError:  # not Linux
        pass
    return ctypes.util.find_library("OpenCL")


def _resolve():
    if os.environ.get("RTSAR_CL_GIL_FREE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None
    path = _loader_path()
    if path is None:
        return None
    try:
        fn = ctypes.CDLL(path).clEnqueueNDRangeKernel  # CDLL: the GIL is released in calls
    except (OSError, AttributeError):
        return None
    size_p = ctypes.POINTER(ctypes.c_size_t)
    fn.restype = ctypes.c_int32
    fn.argtypes = [
        ctypes.c_void_p,  # command queue
        ctypes.c_void_p,  # kernel
        ctypes.c_uint32,  # work dimensions
        ctypes.c_void_p,  # global offset (NULL)
        size_p,  # global size
        size_p,  # local size
        ctypes.c_uint32,  # events to wait for (none)
        ctypes.c_void_p,
        ctypes.c_void_p,  # event out (none)
    ]
    return fn


def gil_free_enqueue():
    """``enqueue(queue, kernel, global_size, local_size)`` for 1-D launches, releasing the GIL
    during the call (raises RuntimeError with the OpenCL error code); None where no OpenCL
    loader can be called through ctypes."""
    global _resolved, _enqueue
    with _lock:
        if not _resolved:
            _enqueue, _resolved = _resolve(), True
    fn = _enqueue
    if fn is None:
        return None

    def enqueue(queue, kernel, global_size: int, local_size: int) -> None:
        g, local = ctypes.c_size_t(global_size), ctypes.c_size_t(local_size)
        code = fn(queue.int_ptr, kernel.int_ptr, 1, None, g, local, 0, None, None)
        if code:
            raise RuntimeError(f"clEnqueueNDRangeKernel failed with OpenCL error {code}")

    return enqueue
