"""Sample buffers: the NumPy type of each processor precision, and non-finite shots.

Sample buffers are complex64 by default and complex128 with ``Processor.precision =
"complex128"``.  A shot (or line) holding NaN or Inf is replaced by zeros rather than dropped, so
the azimuth timing of every later pulse is kept (Psaltis & Wagner 1981: the CCD shifts one row
per pulse); the callers count what was zeroed.
"""

from __future__ import annotations

import numpy as np

from .params import PRECISIONS


def precision_dtype(precision: str) -> type:
    """The NumPy sample type of a ``Processor.precision`` name (one of PRECISIONS)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return np.complex128 if precision == "complex128" else np.complex64


def nonfinite_rows(samples: np.ndarray) -> np.ndarray:
    """bool[...]: rows (the last axis) of ``samples`` holding a NaN or an Inf."""
    x = np.asarray(samples)
    if np.iscomplexobj(x) and x.flags.c_contiguous:
        x = x.view(x.real.dtype)  # real and imaginary parts side by side: one pass
    return ~np.isfinite(x).all(axis=-1)


def nonfinite_shots(channels) -> np.ndarray:
    """bool [shot]: the shots any of ``channels`` (arrays [shot, sample], at least one) holds a
    NaN or an Inf in: shots ingest and ``rtsar process`` zero in every channel."""
    channels = iter(channels)
    bad = nonfinite_rows(next(channels))
    for samples in channels:
        bad |= nonfinite_rows(samples)
    return bad


def zero_nonfinite_rows(samples: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(samples with every non-finite row zeroed — a copy only if one was —, the bool mask)."""
    x = np.asarray(samples)
    bad = nonfinite_rows(x)
    if bad.any():
        x = x.copy()
        x[bad] = 0
    return x, bad
