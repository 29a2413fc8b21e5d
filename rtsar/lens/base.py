"""The AO lens: one interface, a factory for its backends, and the float64 reference.

The lens of Psaltis & Wagner (1981, "Description of the processor") Fourier-transforms the pulse
held by the AO cell; digitally it range-compresses each shot with the chain of a
:class:`rtsar.lens.plan.LensPlan`.  Backends (one module each): ``opencl`` (kernels in
``kernels/lens.cl``) and ``numpy`` (NumPy's or SciPy's FFT); ``auto`` (the default) is the OpenCL
lens where the device can build a kernel, else the NumPy lens with a warning that says why.
Both are tested against :func:`compress_reference`, the plain NumPy float64 evaluation of the
plan: relative RMS error about 1e-7 in complex64 (tolerance 1e-5) and about 1e-16 in complex128
(tolerance 1e-12).
"""

from __future__ import annotations

import os
import warnings
from typing import Protocol

import numpy as np

from .numpy_lens import NumpyLens
from .plan import LensPlan, dft

LENS_BACKENDS = ("auto", "opencl", "numpy")


class Lens(Protocol):
    """What every lens backend offers: ``compress(shots[pulse, sample]) → lines[pulse, bin]``."""

    plan: LensPlan
    backend: str  # "opencl" or "numpy": the backend in use
    fallback_reason: str | None  # why "auto" did not get OpenCL; None otherwise
    precision: str  # Processor.precision
    dtype: type  # the sample type of its output lines

    def compress(self, shots: np.ndarray) -> np.ndarray: ...


def make_lens(
    plan: LensPlan,
    backend: str = "auto",
    device: str | None = None,
    precision: str = "complex64",
) -> Lens:
    """The AO lens on OpenCL or NumPy's FFT, in ``precision`` (Processor.precision).

    ``backend="auto"``: OpenCL when :func:`opencl_unavailable` finds a working device, else the
    NumPy lens, with a RuntimeWarning and the reason in the lens's ``fallback_reason`` (unless a
    device was asked for by ``device`` or RTSAR_OPENCL_DEVICE: then its error is raised).  The
    backend in use is the lens's ``backend`` attribute.
    """
    if backend == "auto":
        requested = _device_requested(device)  # a device asked for by name is never replaced
        reason = opencl_unavailable(device)
        if reason is None or requested:
            from .opencl import AOLens

            try:
                return AOLens(plan, device=device, precision=precision)
            except (RuntimeError, ValueError) as exc:  # the probe built, this plan did not
                if requested:
                    raise
                reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        warnings.warn(
            f"OpenCL lens unavailable, using the NumPy lens (same results, slower): {reason}."
            " `--lens numpy` says so without this warning.",
            RuntimeWarning,
            stacklevel=2,
        )
        lens = NumpyLens(plan, precision=precision)
        lens.fallback_reason = reason
        return lens
    if backend == "opencl":
        # Imported here, not above: pyopencl takes a while to load and the NumPy backend and
        # the tools that never compress (presets, quicklook, subscribe) do without it.
        from .opencl import AOLens

        return AOLens(plan, device=device, precision=precision)
    if backend == "numpy":
        return NumpyLens(plan, precision=precision)
    raise ValueError(f"lens backend must be one of {LENS_BACKENDS}, got {backend!r}")


def _device_requested(device) -> bool:
    from .cl_loader import ENV_DEVICE

    return device is not None or bool(os.environ.get(ENV_DEVICE, "").strip())


def opencl_unavailable(device: str | None = None) -> str | None:
    """None if an OpenCL lens can run on ``device`` here, else the reason (one line)."""
    try:
        from . import cl_loader
    except ImportError as exc:  # pyopencl missing or its driver library broken
        return f"pyopencl cannot be imported ({exc})"
    return cl_loader.probe(device)


def compress_reference(plan: LensPlan, shots: np.ndarray) -> np.ndarray:
    """Float64 reference of the AO lens: shots[pulse, sample] → lines[pulse, bin] (complex128)."""
    x = np.asarray(shots, dtype=np.complex128)
    if x.ndim != 2 or x.shape[1] != plan.samples_per_shot:
        raise ValueError(f"shots must be [pulses, {plan.samples_per_shot}], got {x.shape}")
    y = dft(x * plan.pre, plan.sign1, plan.nfft)
    if plan.spectrum is not None:
        y = dft(y * plan.spectrum, plan.sign2, plan.nfft)
    idx = (plan.bin_start + np.arange(plan.bin_count)) % plan.nfft
    return y[:, idx] * plan.post
