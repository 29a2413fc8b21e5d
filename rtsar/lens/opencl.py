"""The AO lens in OpenCL: batched range compression of radar / lidar pulses.

In the acousto-optic processor the lens performs a Fourier transform of the light diffracted by
the AO cell that holds the received pulse (Psaltis & Wagner 1981, 'Description of the
processor').  Here the lens is the chain described by a :class:`rtsar.lens.plan.LensPlan`,

    x·pre → DFT(sign1, nfft) → [·spectrum → DFT(sign2, nfft)] → bins → ·post,

evaluated for a batch of pulses in one kernel launch (``kernels/lens.cl``), in single precision
(``precision="complex64"``, the default) or double (``"complex128"``: the kernel built with
``-DDOUBLE=1``, on devices that support cl_khr_fp64).
:func:`rtsar.lens.base.compress_reference` is the float64 NumPy reference it is tested against:
measured relative RMS error (tests/test_lens.py, tests/test_precision.py) about 1e-7 in single
precision (tolerance 1e-5) and about 1e-16 in double (tolerance 1e-12) on every preset.
"""

from __future__ import annotations

import threading
import weakref

import numpy as np
import pyopencl as cl

from ..samples import precision_dtype
from . import cl_loader
from .cl_launch import gil_free_calls, gil_free_enqueue
from .plan import LensPlan

__all__ = ["KERNELS", "AOLens", "LensJob", "group_layout", "supports_double"]

KERNELS = ("lanes", "group")
_MAX_LANES = 8
# In double, 8 lanes would be double8 vectors (512 bits): PoCL's CPU target builds them with
# "changes the ABI" warnings and then fails to create the kernel, so double stops at double4.
_MAX_LANES_DOUBLE = 4
_MAX_GROUP = 256
# Intel's CPU runtime reads a USE_HOST_PTR buffer in place only where the host array starts on
# a 4096-byte page; NumPy's arrays start 16 or 64 bytes past one, and then each launch read the
# shots at 0.4x the speed (psaltis-max plan, batch 64: 54k against 142k pulses/s, this machine,
# 2026-11-28; by chance one array in a few was aligned: the runtime's "bimodal" figures).  PoCL
# reads any alignment at one speed.  So on Intel's runtime misaligned shots are first copied
# into page-aligned staging arrays (``_Staging``).
PAGE_BYTES = 4096
STAGING_PLATFORMS = ("Intel",)


def supports_double(device: cl.Device) -> bool:
    """True when the OpenCL device computes in double precision (cl_khr_fp64 or OpenCL 3 fp64)."""
    try:
        if int(device.double_fp_config):
            return True
    except (cl.LogicError, cl.RuntimeError, AttributeError):  # pragma: no cover - driver quirks
        pass
    return "cl_khr_fp64" in device.extensions.split()


def group_layout(
    nfft: int, real_bytes: int, local_bytes: int, most_group: int, scratch: str | None = None
) -> tuple[int, str]:
    """(work-group size, "local" or "global") of the group kernel for ``nfft`` points of
    ``real_bytes`` reals (4, 8) on a device of ``local_bytes`` of local memory and work-groups
    of at most ``most_group`` items: up to _MAX_GROUP and nfft/8 items, and the line's two
    buffers (4·real_bytes·nfft bytes) in local memory where they fit there, else in global
    memory (``scratch``: chosen)."""
    group = min(_MAX_GROUP, max(1, nfft // 8), int(most_group))
    if scratch is None:
        scratch = "local" if 4 * real_bytes * nfft <= local_bytes else "global"
    if scratch not in ("local", "global"):
        raise ValueError(f"scratch must be 'local' or 'global', got {scratch!r}")
    return group, scratch


class LensJob:
    """A batch in flight on the device (:meth:`AOLens.submit`): ``wait()`` returns its lines.
    ``event``: pyopencl's, or a raw handle waited for through ``calls`` (cl_launch.RawCalls),
    which a job dropped unwaited still waits for (its lines are written into ``out``)."""

    __slots__ = ("_event", "_out", "_keep", "_calls", "_lock", "_error", "__weakref__")

    def __init__(self, event, out: np.ndarray, keep, calls=None):
        self._event, self._out, self._keep = event, out, keep  # keep: inputs the device reads
        self._calls, self._lock, self._error = calls, threading.Lock(), None

    def wait(self) -> np.ndarray:
        """The lines [pulses, bins], once the device has written them (the GIL released); a
        failed wait raises again at every later call (its lines were never written)."""
        with self._lock:
            if self._event is not None:
                event, self._event = self._event, None
                try:
                    if self._calls is not None:
                        self._calls.wait(event)
                    else:
                        event.wait()
                except Exception as exc:
                    self._error = exc
                finally:
                    self._keep = None
            if self._error is not None:
                raise self._error
        return self._out

    def __del__(self):
        if getattr(self, "_event", None) is not None:
            try:
                self.wait()
            except Exception:  # nobody is left to tell (at exit, a driver already gone)
                pass


class _Staging:
    """Two page-aligned host arrays, each wrapped once as a USE_HOST_PTR buffer, that take
    turns holding a batch's shots (PAGE_BYTES); one is reused only once the job that last read
    it has finished."""

    def __init__(self, context, dtype, samples: int):
        self.context, self.dtype, self.samples = context, np.dtype(dtype), int(samples)
        # array, buffer, weakref to the last job that reads it
        self.slots: list[list] = [[None, None, None], [None, None, None]]
        self.turn = 0

    def take(self, x: np.ndarray):
        """(slot, buffer, its array holding ``x``): the slot whose turn it is, grown if too
        small.  The slot holds its last job weakly (``submit`` sets it): a job the caller
        dropped has waited in its ``__del__``, one still alive is waited for here.

        The host writes the array between launches without mapping the buffer, which OpenCL
        leaves to the implementation for USE_HOST_PTR; on Intel's CPU runtime (the only one
        staged, STAGING_PLATFORMS) a page-aligned host array is the buffer's own memory."""
        slot = self.slots[self.turn]
        self.turn ^= 1
        array, buf, last = slot
        job = last() if last is not None else None
        if job is not None:
            job.wait()  # its last job has read it (the GIL released)
        slot[2] = None
        pulses = x.shape[0]
        if array is None or array.shape[0] < pulses:
            rows = max(pulses, 2 * (0 if array is None else array.shape[0]))
            nbytes = rows * self.samples * self.dtype.itemsize
            raw = np.empty(nbytes + PAGE_BYTES, np.uint8)
            start = -raw.ctypes.data % PAGE_BYTES
            array = raw[start : start + nbytes].view(self.dtype).reshape(rows, self.samples)
            flags = cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR
            buf = cl.Buffer(self.context, flags, hostbuf=array)
            slot[0], slot[1] = array, buf
        array[:pulses] = x
        return slot, buf, array[:pulses]


class AOLens:
    """Range compressor (the "AO lens") for one :class:`~rtsar.lens.plan.LensPlan`.

    The lens of the optical processor Fourier-transforms the pulse held by the AO cell
    (Psaltis & Wagner 1981, 'Description of the processor'); this class applies the same
    transform, with the matched filter or window of the plan, to batches of digitised pulses.

    Parameters
    ----------
    plan : LensPlan
        What to compute (from :func:`rtsar.lens.plan.make_plan`).
    context : pyopencl.Context, optional
        Context to work in.  A queue on its first device is created unless ``queue`` is given.
    queue : pyopencl.CommandQueue, optional
        In-order queue to enqueue on (its context is used).
    device : pyopencl.Device or str, optional
        Device, or substring of its platform / device name, when neither ``context`` nor
        ``queue`` is given; default: ``RTSAR_OPENCL_DEVICE``, else the fastest device that
        builds the lens (:func:`rtsar.lens.cl_devices.default_device`).  Instances on the
        same device share one context and queue.
    kernel : {"lanes", "group"}, optional
        ``"lanes"``: one work-item transforms 8 pulses at once in SIMD vectors (fast on CPUs);
        ``"group"``: one work-group per pulse (for GPUs).  Default: by device type.
    lanes : int, optional
        Pulses per work-item of the ``"lanes"`` kernel (1, 2, 4 or 8; default 8, fewer if
        the device's local memory is too small; at most 4 in double).
    scratch : {"local", "global"}, optional
        Where the ``"group"`` kernel holds a pulse's two lines while it transforms them: local
        memory (16·nfft bytes, 32·nfft in double), or, the default where the device's local
        memory is smaller than that (NVIDIA's GPUs: 48 KiB, against 64 KiB for radarsat1's
        4096 points), the pulse's rows of a buffer in global memory.
    precision : {"complex64", "complex128"}, optional
        Sample type of the input, the arithmetic and the output (``Processor.precision``).
        ``"complex128"`` needs a device with double support (PoCL's CPU device has it);
        otherwise a ValueError names the device.  Relative RMS error against the float64
        reference: ~1e-7 (complex64), ~1e-16 (complex128).

    Notes
    -----
    ``compress`` may be called with any batch size; device buffers are kept between calls and
    grown when a larger batch arrives (on CPU devices the kernel reads the input array in
    place).  Launches on one instance are serialised by a lock; :meth:`compress` waits for its
    result (the GIL released meanwhile), :meth:`submit` returns at once with a job to wait on.
    """

    backend = "opencl"
    fallback_reason: str | None = None
    choice: str | None = None  # what runs and why (set by make_lens)

    def __init__(
        self,
        plan: LensPlan,
        context: cl.Context | None = None,
        queue: cl.CommandQueue | None = None,
        device: cl.Device | str | None = None,
        kernel: str | None = None,
        lanes: int | None = None,
        precision: str = "complex64",
        scratch: str | None = None,
    ):
        if not isinstance(plan, LensPlan):
            raise TypeError(f"plan must be a LensPlan, got {type(plan).__name__}")
        nfft, S = int(plan.nfft), int(plan.samples_per_shot)
        if nfft < 2 or nfft & (nfft - 1):
            raise ValueError(f"plan.nfft must be a power of two >= 2, got {nfft}")
        if not 1 <= S <= nfft:
            raise ValueError(f"plan.samples_per_shot must be in 1..nfft={nfft}, got {S}")
        if plan.bin_count < 1:
            raise ValueError("plan.bin_count must be >= 1")
        self.plan = plan
        self.precision = precision
        self.dtype = precision_dtype(precision)
        double = self.dtype == np.complex128

        # Why this device: the default's reason, or what was asked for (for the banner).
        self.selection_reason = "the context or queue given"
        if queue is None:
            if context is None:
                device, self.selection_reason = cl_loader.chosen_device(device)
                context, queue = cl_loader.default_context_queue(device)
            else:
                queue = cl.CommandQueue(context)
        elif context is None:
            context = queue.context
        self.queue = queue
        self.context = context  # held here too: a queue's own reference is not enough everywhere
        self.device = queue.device
        d = self.device  # platform, driver version and device, as `rtsar devices` names it
        self.device_label = (
            f"{d.platform.name.strip()} {d.driver_version.strip()} / {d.name.strip()}"
        )

        if kernel is None:
            kernel = "lanes" if self.device.type & cl.device_type.CPU else "group"
        if kernel not in KERNELS:
            raise ValueError(f"kernel must be one of {KERNELS}, got {kernel!r}")
        self.kernel_name = kernel
        if double and not supports_double(self.device):
            raise ValueError(
                f"precision 'complex128' needs an OpenCL device with double precision "
                f"(cl_khr_fp64); {self.device.platform.name.strip()} / "
                f"{self.device.name.strip()} has none: use precision 'complex64' or choose "
                f"another device ({cl_loader.ENV_DEVICE})"
            )

        local = int(self.device.local_mem_size)
        real_bytes = self.dtype().real.itemsize  # 4 or 8
        defines = {
            "NFFT": nfft,
            "LOG2_NFFT": nfft.bit_length() - 1,
            "S": S,
            "BIN_COUNT": int(plan.bin_count),
            "BIN_OFFSET": int(plan.bin_start) % nfft,
            "SIGN1": 1 if plan.sign1 > 0 else -1,
            "SIGN2": 1 if plan.sign2 > 0 else -1,
            "TWO_PASS": int(plan.two_pass),
            "DOUBLE": int(double),
        }
        if kernel == "lanes":
            most = _MAX_LANES_DOUBLE if double else _MAX_LANES
            if lanes is None:
                lanes = most
                while lanes > 1 and 4 * real_bytes * lanes * nfft > local:
                    lanes //= 2
            if lanes not in (1, 2, 4, 8) or lanes > most:
                raise ValueError(
                    f"lanes must be 1, 2, 4 or 8 (at most {most} in {precision}), got {lanes}"
                )
            need = 4 * real_bytes * lanes * nfft
            if scratch is not None:
                raise ValueError("scratch is the group kernel's; the lanes kernel has none")
            self.lanes, self.group_size = lanes, 1
            defines["LANES"] = lanes
        else:
            most, chosen = int(self.device.max_work_group_size), scratch is None
            group, scratch = group_layout(nfft, real_bytes, local, most, scratch)
            need = 4 * real_bytes * nfft if scratch == "local" else 0  # two lines
            self.lanes, self.group_size = 1, group
            defines["GROUP_SIZE"] = group
            defines["SCRATCH_GLOBAL"] = int(scratch == "global")
        self.scratch = scratch  # where the group kernel's line lives (None: the lanes kernel)
        if need > local:
            way = (
                "the group kernel (kernel='group') keeps its lines in global memory"
                if kernel == "lanes"
                else "scratch='global' keeps the lines in global memory"
            )
            raise ValueError(
                f"nfft={nfft} needs {need} bytes of local memory per work-group; "
                f"{self.device.name.strip()} has {local}: {way}"
            )
        self.program = cl_loader.build_program(self.context, "lens.cl", defines)
        self._kernel = cl.Kernel(self.program, f"lens_{kernel}")  # own instance: args are state
        if kernel == "group" and scratch == "local" and chosen and self._local_used() > local:
            # the lines fit, but not with what the compiler keeps in local memory itself
            self.scratch, defines["SCRATCH_GLOBAL"] = "global", 1
            self.program = cl_loader.build_program(self.context, "lens.cl", defines)
            self._kernel = cl.Kernel(self.program, "lens_group")

        mf = cl.mem_flags
        twiddle = np.exp(-2j * np.pi * np.arange(nfft) / nfft)  # float64, cast below
        spectrum = plan.spectrum if plan.two_pass else np.zeros(1)

        def constant(a):
            return cl.Buffer(
                self.context,
                mf.READ_ONLY | mf.COPY_HOST_PTR,
                hostbuf=np.ascontiguousarray(a, dtype=self.dtype),
            )

        self._constants = [
            constant(plan.pre),
            constant(spectrum),
            constant(plan.post),
            constant(twiddle),
        ]
        # CPU devices read the caller's array in place (USE_HOST_PTR): one command less per
        # call, which is a good part of a small batch's time with PoCL.
        self._zero_copy = bool(
            self.device.type & cl.device_type.CPU and self.device.host_unified_memory
        )
        platform = self.device.platform.name
        self._staging = (
            _Staging(self.context, self.dtype, S)
            if self._zero_copy and any(name in platform for name in STAGING_PLATFORMS)
            else None
        )
        self._capacity = 0
        self._shots_buf = self._lines_buf = self._scratch_buf = None
        self._args_lines = None  # the output buffer the kernel's fixed arguments were set with
        self._enqueue = gil_free_enqueue()
        self._calls = gil_free_calls()  # None exactly where _enqueue is (cl_launch._resolve)
        self._pulses_arg = None  # the pulse count the kernel's argument holds
        self._lock = threading.Lock()

    def _local_used(self) -> int:
        """Bytes of local memory the built kernel takes a work-group (0 where not told)."""
        try:
            info = cl.kernel_work_group_info.LOCAL_MEM_SIZE
            return int(self._kernel.get_work_group_info(info, self.device))
        except (cl.Error, AttributeError):  # pragma: no cover - a driver that does not say
            return 0

    def __repr__(self) -> str:
        p = self.plan
        return (
            f"AOLens(S={p.samples_per_shot}, nfft={p.nfft}, bins={p.bin_count}, "
            f"two_pass={p.two_pass}, kernel={self.kernel_name!r}, scratch={self.scratch!r}, "
            f"precision={self.precision!r}, "
            f"device={self.device.name.strip()!r})"
        )

    def _check(self, shots) -> np.ndarray:
        x = np.asarray(shots)
        S = self.plan.samples_per_shot
        if x.ndim != 2 or x.shape[1] != S:
            raise ValueError(f"shots must be a 2-D array [pulses, {S}], got shape {x.shape}")
        if x.dtype not in (np.complex64, np.complex128):
            raise ValueError(f"shots must be complex64 or complex128 (cast), got {x.dtype}")
        return np.ascontiguousarray(x, dtype=self.dtype)

    def _ensure(self, pulses: int) -> None:
        if pulses <= self._capacity:
            return
        capacity = max(pulses, 2 * self._capacity)
        size = self.dtype().itemsize
        mf = cl.mem_flags
        if not self._zero_copy:
            self._shots_buf = cl.Buffer(
                self.context, mf.READ_ONLY, capacity * self.plan.samples_per_shot * size
            )
        self._lines_buf = cl.Buffer(
            self.context, mf.WRITE_ONLY, capacity * self.plan.bin_count * size
        )
        if self.scratch == "global":
            self._scratch_buf = cl.Buffer(
                self.context, mf.READ_WRITE, capacity * 2 * self.plan.nfft * size
            )
        self._capacity = capacity

    def compress(self, shots: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Range-compress a batch of pulses.

        Parameters
        ----------
        shots : ndarray, complex64 or complex128 [pulses, samples_per_shot]
            Received samples, one pulse per row (cast to the lens precision).
        out : ndarray [pulses, bin_count] of the lens precision, optional
            C-contiguous array to write the result into.

        Returns
        -------
        ndarray [pulses, bin_count], complex64 (or complex128 with that precision)
            The compressed lines; column b is bin ``plan.bin_start + b`` (range ``plan.range_m``).

        Raises
        ------
        ValueError
            Wrong shape or dtype of ``shots`` or ``out``.
        """
        return self.submit(shots, out).wait()

    def submit(self, shots: np.ndarray, out: np.ndarray | None = None) -> LensJob:
        """Enqueue the compression of a batch and return at once; ``.wait()`` gives the lines.

        The device works while the caller does something else (the pipeline's CCD correlates
        the previous batch meanwhile).  Jobs complete in the order they were submitted (one
        in-order queue); ``shots`` must not be changed before ``wait()`` returns.  Same
        arguments and errors as :meth:`compress`.
        """
        x = self._check(shots)
        pulses, bins = x.shape[0], self.plan.bin_count
        if out is None:
            out = np.empty((pulses, bins), self.dtype)
        elif (
            not isinstance(out, np.ndarray)
            or out.shape != (pulses, bins)
            or out.dtype != self.dtype
            or not out.flags.c_contiguous
        ):
            raise ValueError(
                f"out must be a C-contiguous {self.precision} array of shape {(pulses, bins)}"
            )
        if pulses == 0:
            return LensJob(None, out, x)
        if pulses >= 2**31:
            raise ValueError("too many pulses in one batch")
        groups = -(-pulses // self.lanes)
        with self._lock:
            self._ensure(pulses)
            slot = None
            if self._staging is not None and x.ctypes.data % PAGE_BYTES:
                slot, shots_buf, x = self._staging.take(x)
            elif self._zero_copy:
                shots_buf = cl.Buffer(
                    self.context, cl.mem_flags.READ_ONLY | cl.mem_flags.USE_HOST_PTR, hostbuf=x
                )
            else:
                shots_buf = self._shots_buf
                cl.enqueue_copy(self.queue, shots_buf, x, is_blocking=False)
            # The arguments that change are set alone (pyopencl's kernel call sets all seven,
            # holding the GIL twice as long: 30-58 µs against 14-23 µs a launch on PoCL), and
            # the launch releases the GIL where it can.
            kernel = self._kernel
            kernel.set_arg(0, shots_buf)
            if self._args_lines is not self._lines_buf:
                kernel.set_arg(1, self._lines_buf)
                for i, buf in enumerate(self._constants):
                    kernel.set_arg(2 + i, buf)
                if self.scratch is not None:  # the group kernel's last argument
                    kernel.set_arg(3 + len(self._constants), self._scratch_buf)
                self._args_lines = self._lines_buf
            if self._calls is None:
                kernel.set_arg(2 + len(self._constants), np.uint32(pulses))
            elif self._pulses_arg != pulses:
                self._calls.set_uint(kernel, 2 + len(self._constants), pulses)
                self._pulses_arg = pulses
            if self._enqueue is not None:  # the GIL released (rtsar.lens.cl_launch)
                self._enqueue(self.queue, kernel, groups * self.group_size, self.group_size)
            else:
                cl.enqueue_nd_range_kernel(
                    self.queue, kernel, (groups * self.group_size,), (self.group_size,)
                )
            # In-order queue: this copy follows the kernel, and a later kernel (which reuses
            # the lines buffer) follows this copy.
            try:
                if self._calls is not None:
                    done = self._calls.read(self.queue, self._lines_buf, out)
                else:
                    done = cl.enqueue_copy(self.queue, out, self._lines_buf, is_blocking=False)
                job = LensJob(done, out, (x, shots_buf), self._calls)
            except BaseException:
                self.queue.finish()  # the kernel may still read the shots: let it end first
                raise
            if slot is not None:
                slot[2] = weakref.ref(job)  # free again once this job is done or dropped
        return job

    __call__ = compress
