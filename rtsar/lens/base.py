"""The AO lens: one interface, a factory for its backends, and the float64 reference.

The lens of Psaltis & Wagner (1981, "Description of the processor") Fourier-transforms the pulse
held by the AO cell; digitally it range-compresses each shot with the chain of a
:class:`rtsar.lens.plan.LensPlan`.  Backends (one module each): ``opencl`` (kernels in
``kernels/lens.cl``) and ``numpy`` (NumPy's or SciPy's FFT); ``auto`` (the default,
:mod:`rtsar.lens.auto`) is the OpenCL lens on the fastest device that builds it, unless the
NumPy lens is clearly faster for the plan, else the NumPy lens with a warning that says why.
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

LENS_BACKENDS = ("auto", "opencl", "numpy", "hybrid")


class Lens(Protocol):
    """What every lens backend offers: ``compress(shots[pulse, sample]) → lines[pulse, bin]``."""

    plan: LensPlan
    backend: str  # "opencl" or "numpy": the backend in use
    fallback_reason: str | None  # why "auto" could not run OpenCL at all; None otherwise
    choice: str | None  # what runs and why, for the banner (set by make_lens)
    precision: str  # Processor.precision
    dtype: type  # the sample type of its output lines

    def compress(self, shots: np.ndarray) -> np.ndarray: ...


def make_lens(
    plan: LensPlan,
    backend: str = "auto",
    device: str | None = None,
    precision: str = "complex64",
    batch: int | None = None,
) -> Lens:
    """The AO lens on OpenCL or NumPy's FFT, in ``precision`` (Processor.precision).

    ``backend="auto"``: :func:`rtsar.lens.auto.choose`: the OpenCL lens on a device asked for
    (``device`` or RTSAR_OPENCL_DEVICE; its error raised if it cannot build), else on the
    default device where it is faster than the NumPy plan at the run's batch sizes (``batch``:
    the configured micro-batch), else the NumPy lens, with a RuntimeWarning and the reason in
    ``fallback_reason`` where OpenCL cannot run at all.  Every lens says what runs
    and why in its ``choice`` line; the backend in use is its ``backend`` attribute.
    ``backend="hybrid"``: the same lens as ``auto`` here; a live run then times its small
    calls both ways and sends those that take less CPU on SciPy's FFT there
    (rtsar.lens.small_calls).
    """
    if backend in ("auto", "hybrid"):
        try:
            from .auto import choose
        except ImportError as exc:  # pyopencl missing or its driver library broken
            lens = NumpyLens(plan, precision=precision)
            lens.fallback_reason = f"pyopencl cannot be imported ({exc})"
            lens.choice = f"NumPy lens ({lens.fallback_reason})"
        else:
            lens = choose(plan, precision, batch, device)
        if lens.fallback_reason:
            warnings.warn(
                f"OpenCL lens unavailable, using the NumPy lens (same results, slower): "
                f"{lens.fallback_reason}. `--lens numpy` says so without this warning.",
                RuntimeWarning,
                stacklevel=2,
            )
        return lens
    if backend == "opencl":
        # Imported here, not above: pyopencl takes a while to load and the NumPy backend and
        # the tools that never compress (presets, quicklook, subscribe) do without it.
        from .opencl import AOLens

        lens = AOLens(plan, device=device, precision=precision)
        lens.choice = f"OpenCL lens on {lens.device_label} (--lens opencl; {lens.selection_reason})"
        return lens
    if backend == "numpy":
        lens = NumpyLens(plan, precision=precision)
        lens.choice = "NumPy lens (--lens numpy)"
        return lens
    raise ValueError(f"lens backend must be one of {LENS_BACKENDS}, got {backend!r}")


def survey_wanted(backend: str, device: str | None) -> bool:
    """Whether the lens will need the device survey: ``auto``, ``hybrid`` or ``opencl`` with no
    device asked for (``--device``, RTSAR_OPENCL_DEVICE)."""
    return not (backend == "numpy" or device is not None or os.environ.get("RTSAR_OPENCL_DEVICE"))


def survey_devices_first(backend: str, device: str | None, say) -> None:
    """Probe the OpenCL devices now where the lens will need them (survey_wanted), so the
    first run on a machine says what its pause is (``say``: one line before the probing;
    nothing when the survey is cached)."""
    if not survey_wanted(backend, device):
        return
    try:
        from .cl_devices import survey
    except ImportError:  # pyopencl missing: make_lens says so
        return
    try:
        survey(say=say)
    except RuntimeError:  # no platform: make_lens says so
        pass


def opencl_unavailable(device: str | None = None, say=None) -> str | None:
    """None if an OpenCL lens can run on ``device`` (default: the survey's choice) here, else
    the reason (one line, with what to install where nothing runs)."""
    try:
        from . import cl_loader
    except ImportError as exc:  # pyopencl missing or its driver library broken
        return f"pyopencl cannot be imported ({exc})"
    return cl_loader.probe(device, say=say)


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
