"""Band-limited resampling of shots at fractional sample positions (Kaiser-windowed sinc).

Crouch 2012, ch. 3: early SAL chirps "not better than 1 %" were linearized by a resampling
procedure onto uniform optical frequency; the HCN alignment shifts each shot by a fraction of a
sample the same way.  ``resample`` (numba, table-driven kernel) is what the stages run;
``resample_reference`` is its float64 reference (the full sum over all input samples).
"""

from __future__ import annotations

import functools
import math

import numba
import numpy as np
from scipy import special

DEFAULT_TAPS = 24
DEFAULT_KAISER_BETA = 10.0


def _kernel(x: np.ndarray, taps: int, beta: float, i0=special.i0) -> np.ndarray:
    """Kaiser-windowed sinc h(x) = sinc(x)·I0(β√(1-(2x/T)²))/I0(β) for |x| < T/2, else 0."""
    half = 0.5 * taps
    r = np.clip(1.0 - (x / half) ** 2, 0.0, None)
    return np.where(np.abs(x) < half, np.sinc(x) * i0(beta * np.sqrt(r)) / i0(beta), 0.0)


def check_resampler(taps, beta):
    if not (isinstance(taps, int) and taps >= 2 and taps % 2 == 0):
        raise ValueError(f"taps must be an even integer >= 2, got {taps!r}")
    if not (math.isfinite(beta) and beta >= 0):
        raise ValueError(f"kaiser_beta must be finite and >= 0, got {beta!r}")


_TABLE_STEPS = 4096  # kernel table points per sample: linear interpolation error < 1e-7


@functools.lru_cache(maxsize=8)
def _kernel_table(taps: int, beta: float) -> np.ndarray:
    """h on x = -T/2 … T/2 in steps of 1/_TABLE_STEPS (one extra zero for the last interval)."""
    x = np.arange(taps * _TABLE_STEPS + 2) / _TABLE_STEPS - 0.5 * taps
    table = _kernel(x, taps, beta)
    table.flags.writeable = False
    return table


@numba.njit(nogil=True, cache=True)
def _resample_rows(x, u, table, taps, steps, out):  # pragma: no cover - compiled
    s = x.shape[1]
    half = taps // 2
    for p in range(u.shape[0]):
        for k in range(u.shape[1]):
            uk = u[p, k]
            if not (uk >= 0.0 and uk <= s - 1.0):
                out[p, k] = 0.0
                continue
            b = int(np.floor(uk))
            frac = uk - b
            acc = 0.0j
            for j in range(1 - half, half + 1):
                n = b + j
                if n < 0 or n >= s:
                    continue
                pos = (frac - j + 0.5 * taps) * steps  # table coordinate of x = u - n
                i = int(pos)
                acc += x[p, n] * (table[i] + (pos - i) * (table[i + 1] - table[i]))
            out[p, k] = acc


def resample(
    samples: np.ndarray, index: np.ndarray, taps: int = DEFAULT_TAPS, beta=DEFAULT_KAISER_BETA
) -> tuple[np.ndarray, np.ndarray]:
    """Band-limited interpolation of rows of ``samples`` at fractional sample positions.

    y[p, k] = Σ_n x[p, n] h(u[p, k] - n) over the ``taps`` samples n nearest u (Kaiser-windowed
    sinc, Crouch's resampling onto uniform optical frequency); h is read from a table
    (``_TABLE_STEPS`` points per sample, linear interpolation), the sum runs in numba.  Samples
    beyond the record count as zero; outputs with u outside [0, S-1] are set to zero and
    flagged (the trimmed edge of Crouch's HCN alignment).  Error for tones up to 0.36 fs: below
    2e-5 with 24 taps, β = 10.

    Returns (y complex128[P, K], outside bool[P, K]).
    """
    check_resampler(taps, beta)
    # One specialisation of the kernel whatever the caller holds (complex64 shots, complex128
    # spectra, read-only views): the products were complex128 in the kernel either way.
    x = np.require(samples, np.complex128, ["C", "W"])
    u = np.require(index, np.float64, ["C", "W"])
    if x.ndim != 2 or u.ndim != 2 or len(u) != len(x):
        raise ValueError(f"samples [P, S] and index [P, K] expected, got {x.shape}, {u.shape}")
    out = np.empty(u.shape, np.complex128)
    _resample_rows(x, u, _kernel_table(taps, float(beta)), taps, _TABLE_STEPS, out)
    outside = ~((u >= 0.0) & (u <= x.shape[1] - 1.0))
    return out, outside


def resample_reference(samples, index, taps: int = DEFAULT_TAPS, beta=DEFAULT_KAISER_BETA):
    """Float64 reference of ``resample``: the full sum over all input samples (a [K, S] matrix)."""
    check_resampler(taps, beta)
    x = np.asarray(samples, np.complex128)
    u = np.asarray(index, np.float64)
    s = x.shape[-1]
    out = np.zeros(u.shape, np.complex128)
    n = np.arange(s)
    for p in range(x.shape[0]):
        ok = (u[p] >= 0.0) & (u[p] <= s - 1.0)
        dx = u[p][:, None] - n[None, :]
        near = np.abs(dx) < 0.5 * taps  # h is zero elsewhere: evaluate it only there
        h = np.zeros(dx.shape)
        h[near] = _kernel(dx[near], taps, beta, i0=np.i0)
        out[p] = np.where(ok, h @ x[p], 0.0)
    return out
