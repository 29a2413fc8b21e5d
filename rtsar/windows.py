"""Amplitude tapers for the range spectrum and the azimuth mask.

``taylor`` is the Taylor window with n̄ = 4 and -35 dB design sidelobes, the usual SAR choice
(Carrara, Goodman & Majewski, Spotlight SAR, eqs. D.1-D.5: the same definition and normalisation
as scipy.signal.windows.taylor, written out here because scipy.signal takes over a second to
load); ``hann`` and ``hamming`` are the textbook raised cosines (Crouch eq. 2.15).
"""

from __future__ import annotations

import functools

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
    k = np.arange(n, dtype=np.float64)
    if name == "hann":
        return 0.5 - 0.5 * np.cos(2.0 * np.pi * k / (n - 1)) if n > 2 else np.ones(n)
    if name == "hamming":
        return 0.54 - 0.46 * np.cos(2.0 * np.pi * k / (n - 1)) if n > 1 else np.ones(n)
    if name == "taylor":
        return taylor(n, TAYLOR_NBAR, TAYLOR_SLL_DB)
    raise ValueError(f"unknown window {name!r}; choose one of {WINDOWS}")


def taylor(n: int, nbar: int, sll_db: float) -> np.ndarray:
    """Taylor window of length n: n̄ - 1 cosine terms whose coefficients F_m put the first
    n̄ - 1 sidelobes at -``sll_db`` (Carrara et al. eqs. D.1-D.5), scaled to 1 at the centre."""
    a = np.arccosh(10.0 ** (sll_db / 20.0)) / np.pi
    sigma2 = nbar**2 / (a**2 + (nbar - 0.5) ** 2)  # the stretch that joins the two zero sets
    m = np.arange(1, nbar, dtype=np.float64)
    f = np.empty(m.size)
    for i, mi in enumerate(m):
        numerator = np.prod(1.0 - mi**2 / sigma2 / (a**2 + (m - 0.5) ** 2))
        others = m[m != mi]
        denominator = 2.0 * np.prod(1.0 - mi**2 / others**2)
        f[i] = (-1.0) ** (mi + 1) * numerator / denominator
    x = (np.arange(n) - n / 2.0 + 0.5) / n  # sample positions about the centre, in lengths
    w = 1.0 + 2.0 * np.cos(2.0 * np.pi * np.outer(x, m)) @ f
    return w / (1.0 + 2.0 * f.sum())  # 1 at the centre, (n - 1) / 2


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


@functools.cache
def impulse_response_width(name: str) -> float:
    """-3 dB width of the impulse response of a band weighted by window ``name``, in units of
    1 / bandwidth (rect: 0.8859, the |sinc|² half-power width; a taper widens it).

    The band is the continuous interval [-1/2, 1/2] (sampled densely at the midpoints of 4096
    cells); the response W(t) = Σ w(u) exp(i2π t u) / Σ w(u) is evaluated directly and its
    half-power point found by bisection, so the figure holds to ~1e-7 for every window.
    """
    from scipy.optimize import brentq  # (see window(): scipy loads slowly)

    cells = 4096
    u = (np.arange(cells) + 0.5) / cells - 0.5
    w = window(name, cells)
    w = w / w.sum()

    def excess(t: float) -> float:  # |W(t)|² - 1/2; W is real (the taper is symmetric)
        return float(np.dot(w, np.cos(2.0 * np.pi * t * u))) ** 2 - 0.5

    return 2.0 * brentq(excess, 0.0, 1.5, xtol=1e-12)


def band_response_width(weights) -> float:
    """-3 dB width, in units of 1 / bandwidth, of a band made of ``len(weights)`` equal cells
    weighted by ``weights`` (each at its cell's centre): W(t) = Σ w_k exp(i2π t u_k) / Σ w_k,
    u_k = (k + 1/2)/n - 1/2, the model SICD's WgtFunct stands for (its readers derive the width
    from it the same way).  A uniform band gives 0.8859 as n grows."""
    from scipy.optimize import brentq  # (see window(): scipy loads slowly)

    w = np.asarray(weights, np.float64)
    u = (np.arange(w.size) + 0.5) / w.size - 0.5
    w = w / w.sum()

    def excess(t: float) -> float:
        return abs(complex(np.dot(w, np.exp(2j * np.pi * t * u)))) ** 2 - 0.5

    return 2.0 * brentq(excess, 0.0, 1.5, xtol=1e-12)
