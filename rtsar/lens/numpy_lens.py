"""The AO lens on NumPy's (or SciPy's) FFT: the CPU backend beside the OpenCL one."""

from __future__ import annotations

import numpy as np

from ..samples import precision_dtype
from .plan import LensPlan, dft


class NumpyLens:
    """The plan evaluated with NumPy's (or SciPy's) FFT in the processor's precision.

    ``precision="complex64"`` (default): single-precision transforms, complex64 out; relative
    RMS error against compress_reference about 1e-7 (tested to 1e-5).  ``"complex128"``: the
    same chain in double, about 1e-16 (tested to 1e-12).  Not the reference (that is
    compress_reference): a CPU backend to compare the OpenCL lens against, and a fallback where
    no OpenCL device is wanted.
    """

    backend = "numpy"
    fallback_reason: str | None = None  # set by make_lens("auto") when OpenCL was unavailable
    choice: str | None = None  # what runs and why (set by make_lens)

    def __init__(self, plan: LensPlan, library: str = "numpy", precision: str = "complex64"):
        if library == "numpy":
            self._fft = np.fft
        elif library == "scipy":
            from scipy import fft as scipy_fft

            self._fft = scipy_fft
        else:
            raise ValueError("library must be 'numpy' or 'scipy'")
        self.plan = plan
        self.precision = precision
        self.dtype = dt = precision_dtype(precision)
        self._pre = plan.pre.astype(dt)
        self._spec = None if plan.spectrum is None else plan.spectrum.astype(dt)
        self._idx = (plan.bin_start + np.arange(plan.bin_count)) % plan.nfft
        self._post = plan.post.astype(dt)

    def compress(self, shots: np.ndarray) -> np.ndarray:
        p = self.plan
        x = np.asarray(shots)
        if x.ndim != 2 or x.shape[1] != p.samples_per_shot:
            raise ValueError(f"shots must be [pulses, {p.samples_per_shot}], got {x.shape}")
        y = dft(x.astype(self.dtype, copy=False) * self._pre, p.sign1, p.nfft, self._fft)
        if self._spec is not None:
            y = dft(y * self._spec, p.sign2, p.nfft, self._fft)
        return (y[:, self._idx] * self._post).astype(self.dtype, copy=False)
