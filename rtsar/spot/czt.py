"""Chirp-z spectral zoom: a DTFT on an arbitrary uniform frequency grid, a different one per row.

X[p, k] = Σ_n x[p, n] exp(i (ω0_p + dω_p k) n),  k = 0 … K-1

is the chirp-z transform on the unit circle (Rabiner, Schafer & Rader 1969) that Crouch (ch. 9,
"Polar Format Implementation") and Sandia use for polar formatting: a "spectral zoom" with any
start and spacing, exact, not zero-padding plus interpolation.  Computed by Bluestein's identity
nk = (n² + k² - (k-n)²)/2 as one FFT convolution per row; every row may have its own ω0 and dω
(the zoom of polar formatting changes from shot to shot).  Phases are formed in float64 and
reduced mod 2π before the exponential.  ``dtft_reference`` is the plain float64 sum.
"""

from __future__ import annotations

import numpy as np
from scipy import fft as sfft

TWO_PI = 2.0 * np.pi


def _phasor(phase: np.ndarray) -> np.ndarray:
    return np.exp(1j * np.mod(phase, TWO_PI))


def zoom_dtft(x: np.ndarray, w0, dw, k: int) -> np.ndarray:
    """X[p, k] of the module docstring for rows x[p, :]; ``w0``, ``dw`` scalars or one per row.

    Returns complex128 [P, K].  Cost: FFTs of length ≥ N + K - 1 per row.
    """
    x = np.atleast_2d(np.asarray(x, np.complex128))
    p, n = x.shape
    w0 = np.broadcast_to(np.asarray(w0, np.float64), (p,))[:, None]
    dw = np.broadcast_to(np.asarray(dw, np.float64), (p,))[:, None]
    if k < 1 or n < 1:
        return np.zeros((p, max(k, 0)), np.complex128)
    length = sfft.next_fast_len(n + k - 1)
    nn = np.arange(n, dtype=np.float64)
    kk = np.arange(k, dtype=np.float64)
    # y_n = x_n e^{i ω0 n} e^{i dω n²/2};  h_m = e^{-i dω m²/2}, m = k - n ∈ [-(N-1), K-1]
    y = np.zeros((p, length), np.complex128)
    y[:, :n] = x * _phasor(w0 * nn + 0.5 * dw * nn * nn)
    m = np.arange(length, dtype=np.float64)
    m = np.where(m < k, m, m - length)  # circular indices: 0…K-1, then the negative lags
    h = _phasor(-0.5 * dw * m * m)
    conv = sfft.ifft(sfft.fft(y, axis=1, workers=-1) * sfft.fft(h, axis=1, workers=-1), axis=1)
    return conv[:, :k] * _phasor(0.5 * dw * kk * kk)


def dtft_reference(x: np.ndarray, w0, dw, k: int) -> np.ndarray:
    """Float64 reference of ``zoom_dtft``: the direct sum (a [K, N] matrix per row)."""
    x = np.atleast_2d(np.asarray(x, np.complex128))
    p, n = x.shape
    w0 = np.broadcast_to(np.asarray(w0, np.float64), (p,))
    dw = np.broadcast_to(np.asarray(dw, np.float64), (p,))
    out = np.empty((p, k), np.complex128)
    nn = np.arange(n, dtype=np.float64)
    for row in range(p):
        omega = w0[row] + dw[row] * np.arange(k)
        out[row] = _phasor(omega[:, None] * nn[None, :]) @ x[row]
    return out
