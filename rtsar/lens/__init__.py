"""The AO lens: range compression of each pulse (Psaltis & Wagner 1981; Crouch 2012, ch. 3).

``plan`` (what is computed for a waveform, and the range axis), ``base`` (the Lens interface,
``make_lens`` and the float64 reference), one module per backend (``numpy_lens``, ``opencl``
with its kernels in ``kernels/lens.cl``) and ``cl_loader`` (device choice, kernel loading and
the build cache, shared by every OpenCL kernel of rtsar).
"""

from .base import LENS_BACKENDS, Lens, compress_reference, make_lens, opencl_unavailable
from .numpy_lens import NumpyLens
from .plan import LensPlan, make_plan, next_pow2, range_axis_m

__all__ = [
    "LENS_BACKENDS",
    "Lens",
    "LensPlan",
    "NumpyLens",
    "compress_reference",
    "make_lens",
    "make_plan",
    "opencl_unavailable",
    "next_pow2",
    "range_axis_m",
]
