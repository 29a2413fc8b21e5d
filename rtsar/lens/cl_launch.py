"""Kernel launches that let the other threads run: clEnqueueNDRangeKernel called without the GIL
(and the launch's other small calls, ``gil_free_calls``, made without pyopencl's overhead).

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
_calls = None


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
    """(the launch function, RawCalls), each None where no loader can be called."""
    if os.environ.get("RTSAR_CL_GIL_FREE", "1").strip().lower() in ("0", "false", "no", "off"):
        return None, None
    path = _loader_path()
    if path is None:
        return None, None
    try:
        lib = ctypes.CDLL(path)  # CDLL: the GIL is released in calls
        fn = lib.clEnqueueNDRangeKernel
        calls = RawCalls(lib)
    except (OSError, AttributeError):
        return None, None
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
    return fn, calls


class RawCalls:
    """The launch's small calls straight to the loader: pyopencl spends 10-19 µs on a scalar
    ``set_arg`` and ~15 µs on a non-blocking ``enqueue_copy`` (holding the GIL), against about
    1 µs each here; a lens call of one pulse took 101 against 53 µs on Intel's runtime
    (2026-11-28, this 2-core machine).  Events are raw handles: ``wait`` then ``release``."""

    def __init__(self, lib):
        vp, u32, size = ctypes.c_void_p, ctypes.c_uint32, ctypes.c_size_t
        self._set = lib.clSetKernelArg
        self._set.restype, self._set.argtypes = ctypes.c_int32, [vp, u32, size, vp]
        self._read = lib.clEnqueueReadBuffer
        self._read.restype = ctypes.c_int32
        self._read.argtypes = [vp, vp, u32, size, size, vp, u32, vp, vp]
        self._wait = lib.clWaitForEvents
        self._wait.restype, self._wait.argtypes = ctypes.c_int32, [u32, vp]
        self._release = lib.clReleaseEvent
        self._release.restype, self._release.argtypes = ctypes.c_int32, [vp]

    def set_uint(self, kernel, index: int, value: int) -> None:
        """Kernel argument ``index`` = ``value`` as a cl_uint."""
        v = ctypes.c_uint32(value)
        _check("clSetKernelArg", self._set(kernel.int_ptr, index, 4, ctypes.byref(v)))

    def read(self, queue, buffer, out) -> ctypes.c_void_p:
        """Enqueue the copy of ``buffer``'s first ``out.nbytes`` into ``out`` (a C-contiguous
        array that must live until the event is waited for); its event."""
        event = ctypes.c_void_p()
        code = self._read(
            queue.int_ptr, buffer.int_ptr, 0, 0, out.nbytes, out.ctypes.data, 0, None,
            ctypes.byref(event),
        )  # fmt: skip
        _check("clEnqueueReadBuffer", code)
        return event

    def wait(self, event: ctypes.c_void_p) -> None:
        """Wait for the event (the GIL released), then release it."""
        try:
            _check("clWaitForEvents", self._wait(1, ctypes.byref(event)))
        finally:
            self._release(event)


def _check(name: str, code: int) -> None:
    if code:
        raise RuntimeError(f"{name} failed with OpenCL error {code}")


def gil_free_calls() -> RawCalls | None:
    """The launch's other calls through ctypes (RawCalls), or None as gil_free_enqueue."""
    gil_free_enqueue()
    return _calls


def gil_free_enqueue():
    """``enqueue(queue, kernel, global_size, local_size)`` for 1-D launches, releasing the GIL
    during the call (raises RuntimeError with the OpenCL error code); None where no OpenCL
    loader can be called through ctypes."""
    global _resolved, _enqueue, _calls
    with _lock:
        if not _resolved:
            (_enqueue, _calls), _resolved = _resolve(), True
    fn = _enqueue
    if fn is None:
        return None

    def enqueue(queue, kernel, global_size: int, local_size: int) -> None:
        g, local = ctypes.c_size_t(global_size), ctypes.c_size_t(local_size)
        code = fn(queue.int_ptr, kernel.int_ptr, 1, None, g, local, 0, None, None)
        if code:
            raise RuntimeError(f"clEnqueueNDRangeKernel failed with OpenCL error {code}")

    return enqueue
