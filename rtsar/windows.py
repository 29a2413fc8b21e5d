"""Amplitude tapers for the range spectrum and the azimuth mask.

``taylor`` is the Taylor window with n̄ = 4 and -35 dB design sidelobes (scipy's implementation),
the usual SAR choice; ``hann`` and ``hamming`` are the textbook raised cosines (Crouch eq. 2.15).
"""

from __future__ import annotations

import numpy as np

from .params import WINDOWS

TAYLOR_NBAR = 4
TAYLOR_SLL_DB = 35.0


def window(name: str, n: int) -> np.ndarray:
    """Symmetric window of length n (float64, peak near 1)."""
    if n < 1:
        raise ValueError("window length must be >= 1")
    if name == "rect":
        return np.ones(n)
    # Imported here: scipy.signal takes about a second to load, and the rectangular window (and
    # every command that never builds a taper) does without it.
    from scipy.signal import windows as _sw

    if name == "hann":
        return _sw.hann(n, sym=True) if n > 2 else np.ones(n)
    if name == "hamming":
        return _sw.hamming(n, sym=True)
    if name == "taylor":
        return _sw.taylor(n, nbar=TAYLOR_NBAR, sll=TAYLOR_SLL_DB, norm=True, sym=True)
    raise ValueError(f"unknown window {name!r}; choose one of {WINDOWS}")


def window_at(name: str, u: np.ndarray) -> np.ndarray:
    """Window evaluated at fractional positions u in [0, 1] (0 outside), for spectral tapers."""
    u = np.asarray(u, dtype=np.float64)
    inside = (u >= 0) & (u <= 1)
    out = np.zeros_like(u)
    if name == "rect":
        out[inside] = 1.0
        return out
    # Sample the window densely and interpolate: exact enough (1e-7) for a taper.
    grid = np.linspace(0.0, 1.0, 4097)
    out[inside] = np.interp(u[inside], grid, window(name, grid.size))
    return out
