"""Band-limited interpolation of sampled impulse responses (shared by the point-target tools).

The samples are taken as one period of a periodic, band-limited signal (FFT zero-padding; the
Nyquist bin of an even length is split in two halves).  Values between samples are evaluated
exactly from the DFT, so peak positions and values are not limited to an upsampled grid.

That interpolant is the signal's only where its band leaves the DFT's split at ±1/2 cycle a
sample empty.  A band that straddles it is cut in two and the halves interpolated a sample
rate apart: a squinted image's range spectrum sits 2 (cos θ - 1) δr / λ cycles a bin off zero
(the mask's phase (4π/λ)(sqrt(R² + u²) - R) changes with R; RADARSAT-1: -0.063 cycle a bin,
its band 0.93 of the sample rate wide), and its range cut measured 3-9 % wide with the
sidelobes 1 dB up.  :func:`band_centre_cycles` finds such a band's centre, to be taken out
before interpolating and put back after.
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


#: A band "straddles" the split when, in stretches of the spectrum 2·SPLIT_HALF_WIDTH wide,
#: those under GAP_DEPTH of the mean make one run (a band's gap, not notches inside a band:
#: crouch-sal's paired echoes dip to 0.04, two echoes a few samples apart to zero, every
#: 1/spacing), and the one about ±1/2 holds over GAP_DEPTH of the mean and over
#: GAP_CONTRAST times the gap's.
SPLIT_HALF_WIDTH = 1 / 64  # cycles a sample, rounded to whole bins
GAP_DEPTH = 0.01
GAP_CONTRAST = 10.0


def band_centre_cycles(x: np.ndarray, axis: int = -1) -> float:
    """The shift (cycles a sample, a whole number of bins, in [-1/2, 1/2)) that moves a band
    straddling the DFT's split off it, or 0.

    The power spectrum along ``axis`` (summed over the other axes), summed over stretches
    2·SPLIT_HALF_WIDTH wide, is least at the band's gap; where the band straddles the split
    (GAP_DEPTH, GAP_CONTRAST), ``x · exp(-2πi c n)`` with the returned c puts the gap's middle
    there.  A gap must hold a stretch: one narrower than 2·SPLIT_HALF_WIDTH + 1 bin (a band
    over 0.97 of the circle; RADARSAT-1's range cut over fewer than ~57 samples) is not found,
    so callers that know a band's centre declare it (point_target.image_centres).
    Elsewhere 0, so a band already clear of the split, or one that fills the whole circle (a
    critically sampled sinc: no gap), is interpolated as it is.  A gap, not the power's
    centroid: a real chirp's band is lopsided (RADARSAT-1's centroid sits 0.03 cycle from
    its band's middle).
    """
    x = np.asarray(x)
    axis = axis % x.ndim
    n = x.shape[axis]
    if n < 4:
        return 0.0
    p = np.abs(_fft.fft(x, axis=axis)) ** 2
    if x.ndim > 1:
        p = p.sum(axis=tuple(a for a in range(x.ndim) if a != axis))
    half = round(SPLIT_HALF_WIDTH * n)  # 0 (single bins) up to 32 samples
    stretch = np.zeros(n)
    for k in range(-half, half + 1):  # circular sums over 2·half + 1 bins
        stretch += np.roll(p, -k)
    mean, split = float(stretch.mean()), float(stretch[n // 2])
    low = stretch <= GAP_DEPTH * mean
    starts = np.flatnonzero(low & ~np.roll(low, 1))
    one_gap = len(starts) == 1  # notches come in rows
    deep = one_gap and float(stretch.min()) * GAP_CONTRAST <= split
    if not (mean > 0 and deep and split >= GAP_DEPTH * mean):
        return 0.0
    gap = (int(starts[0]) + (int(np.count_nonzero(low)) - 1) // 2) % n  # the gap's middle
    return float(((gap - n // 2) / n + 0.5) % 1.0 - 0.5)


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
