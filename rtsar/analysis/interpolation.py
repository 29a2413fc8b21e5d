"""Band-limited interpolation of sampled impulse responses (shared by the point-target tools).

The samples are taken as one period of a periodic, band-limited signal (FFT zero-padding; the
Nyquist bin of an even length is split in two halves).  Values between samples are evaluated
exactly from the DFT, so peak positions and values are not limited to an upsampled grid.
"""

from __future__ import annotations

import numpy as np
from scipy import fft as _fft
from scipy import optimize as _opt


def check_factor(factor) -> int:
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
        raise ValueError(f"upsample factor must be an integer >= 1, got {factor!r}")
    return int(factor)


def upsample(x: np.ndarray, factor: int, axis: int = -1) -> np.ndarray:
    """Band-limited interpolation by FFT zero-padding.

    Parameters
    ----------
    x : np.ndarray
        Signal (complex or real), one period of a band-limited periodic signal along ``axis``.
    factor : int
        Upsampling factor (>= 1); the output has ``factor`` times as many samples along ``axis``.
    axis : int, optional
        Axis to interpolate along (default last).

    Returns
    -------
    np.ndarray
        ``y`` with ``y.take(range(0, n * factor, factor), axis) == x`` to rounding; complex for
        complex input, real for real input.  The Nyquist bin of an even length is split into
        equal halves at ``+n/2`` and ``-n/2``, which keeps the interpolant real for real input
        and makes it pass through the original samples.

    Raises
    ------
    ValueError
        If ``factor`` is not an integer >= 1 or the axis is empty.
    """
    factor = check_factor(factor)
    x = np.asarray(x)
    if x.ndim == 0:
        raise ValueError("upsample needs an array with at least one axis")
    axis = axis % x.ndim
    n = x.shape[axis]
    if n == 0:
        raise ValueError("cannot upsample an empty axis")
    if factor == 1:
        return x.copy()
    is_real = not np.iscomplexobj(x)
    spectrum = _fft.fft(x, axis=axis)
    m = n * factor
    out_shape = list(x.shape)
    out_shape[axis] = m
    padded = np.zeros(out_shape, dtype=spectrum.dtype)

    def sl(start, stop):
        index = [slice(None)] * x.ndim
        index[axis] = slice(start, stop)
        return tuple(index)

    n_pos = (n + 1) // 2  # DC and the positive frequencies below Nyquist
    n_neg = (n - 1) // 2  # the negative frequencies above -Nyquist
    padded[sl(0, n_pos)] = spectrum[sl(0, n_pos)]
    if n_neg:
        padded[sl(m - n_neg, m)] = spectrum[sl(n - n_neg, n)]
    if n % 2 == 0:
        nyquist = spectrum[sl(n // 2, n // 2 + 1)] * 0.5
        padded[sl(n // 2, n // 2 + 1)] = nyquist
        padded[sl(m - n // 2, m - n // 2 + 1)] = nyquist
    y = _fft.ifft(padded, axis=axis) * factor
    return y.real.copy() if is_real else y


def synthesis_vector(n: int, t: float) -> np.ndarray:
    """Row ``v`` with ``x(t) = v @ fft(x) / n``: the band-limited interpolant of :func:`upsample`.

    ``t`` is in samples; the Nyquist term of an even ``n`` is ``cos(pi t)`` (the split bin).
    """
    k = _fft.fftfreq(n, d=1.0 / n)
    v = np.exp(2j * np.pi * k * (t / n))
    if n % 2 == 0:
        v[n // 2] = np.cos(np.pi * t)
    return v


def evaluate(spectrum: np.ndarray, t: float) -> complex:
    """Band-limited interpolant of a 1-D signal (given by its DFT) at fractional sample ``t``."""
    n = spectrum.size
    return complex(synthesis_vector(n, t) @ spectrum) / n


def refine_max(spectrum: np.ndarray, t_lo: float, t_hi: float, t_guess: float, xatol: float = 1e-9):
    """Maximise ``|x(t)|**2`` on ``[t_lo, t_hi]``; return ``(t, x(t))`` (no worse than guess)."""
    value_guess = evaluate(spectrum, t_guess)
    if t_hi <= t_lo:
        return t_guess, value_guess
    scale = abs(value_guess) ** 2 or 1.0

    def negative_power(dt):  # offset from the guess keeps Brent's relative tolerance tiny
        return -(abs(evaluate(spectrum, t_guess + dt)) ** 2) / scale

    res = _opt.minimize_scalar(
        negative_power,
        bounds=(t_lo - t_guess, t_hi - t_guess),
        method="bounded",
        options={"xatol": xatol},
    )
    t_best = t_guess + float(res.x)
    value_best = evaluate(spectrum, t_best)
    if abs(value_best) < abs(value_guess):
        return t_guess, value_guess
    return t_best, value_best
