"""The AO lens: one interface, a factory for its backends, and the float64 reference.

The lens of Psaltis & Wagner (1981, "Description of the processor") Fourier-transforms the pulse
held by the AO cell; digitally it range-compresses each shot with the chain of a
:class:`rtsar.lens.plan.LensPlan`.  Backends (one module each): ``opencl`` (the default, kernels
in ``kernels/lens.cl``) and ``numpy`` (NumPy's or SciPy's FFT).  Both are tested against
:func:`compress_reference`, the plain NumPy float64 evaluation of the plan: relative RMS error
about 1e-7 in complex64 (tolerance 1e-5) and about 1e-16 in complex128 (tolerance 1e-12).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from .numpy_lens import NumpyLens
from .plan import LensPlan, dft

LENS_BACKENDS = ("opencl", "numpy")


class Lens(Protocol):
    """What every lens backend offers: ``compress(shots[pulse, sample]) → lines[pulse, bin]``."""

    plan: LensPlan
    precision: str  # Processor.precision
    dtype: type  # the sample type of its output lines

    def compress(self, shots: np.ndarray) -> np.ndarray: ...


def make_lens(
    plan: LensPlan,
    backend: str = "opencl",
    device: str | None = None,
    precision: str = "complex64",
) -> Lens:
    """The AO lens on OpenCL (default) or NumPy's FFT, in ``precision`` (Processor.precision)."""
    if backend == "opencl":
        # Imported here, not above: pyopencl takes a while to load and the NumPy backend and
        # the tools that never compress (presets, quicklook, subscribe) do without it.
        from .opencl import AOLens

        return AOLens(plan, device=device, precision=precision)
    if backend == "numpy":
        return NumpyLens(plan, precision=precision)
    raise ValueError(f"lens backend must be one of {LENS_BACKENDS}, got {backend!r}")


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
