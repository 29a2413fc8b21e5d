"""The Doppler centroid of a squinted beam, estimated from range-compressed echoes.

A squinted beam sees each scatterer around the Doppler frequency f_dc = -2 V sin θ / λ, which
may lie many PRFs from zero (RADARSAT-1's Vancouver block: about -5.5 PRF).  Sampled at the PRF
the azimuth signal only tells f_dc modulo the PRF; the range walk tells the rest:

* **fractional part**, from the pulse-to-pulse correlation (the average cross-correlation
  coefficient method): the expected phase advance between neighbouring pulses is 2π f_dc / PRF,
  so with C = Σ_{p, r} y[p + 1, r] · conj(y[p, r]) over the range-compressed lines y,

      f_frac = PRF · arg(C) / 2π        in (-PRF/2, PRF/2]                                 (D1)

* **ambiguity**, from the range walk: a scatterer's echo moves in range at dR/dt = -λ f_dc / 2
  across its aperture, so the scene's range-compressed magnitude, seen Δp pulses later, is
  shifted by Δr = -λ f_dc Δp / (2 PRF) metres.  The shift that maximises the cross-correlation
  of |y| between lines p and p + Δp (summed over p, peak refined by a parabola through the
  three samples around it) gives the walk's own, coarse estimate

      f_walk = -2 Δr PRF / (λ Δp),      f_dc = f_frac + M · PRF,  M = round((f_walk - f_frac)/PRF)
                                                                                            (D2)

The walk must be known to better than half a PRF: λ PRF / 4 m/s (RADARSAT-1: 17.8 m/s, or 1.56
range cells over Δp = 512 pulses), comfortably more than the parabola's error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Below this |C| / Σ|y|² the pulse-to-pulse phase is noise's (white noise: ~1/sqrt(samples);
#: RADARSAT-1's Vancouver block: 0.33).
MIN_COHERENCE = 0.05


@dataclass(frozen=True)
class DopplerEstimate:
    """What the estimator found (every frequency in Hz, walk in metres per second)."""

    centroid_hz: float  # absolute: f_frac + ambiguity · PRF
    fractional_hz: float  # (D1), in (-PRF/2, PRF/2]
    ambiguity: int  # M of (D2)
    walk_m_per_s: float  # dR/dt measured from the range walk
    walk_centroid_hz: float  # f_walk of (D2): the coarse, unambiguous estimate
    coherence: float  # |C| / Σ|y|²: near 0 means the fractional part is noise
    lag_pulses: int  # Δp used for the walk

    def summary(self) -> str:
        return (
            f"Doppler centroid {self.centroid_hz:.1f} Hz = {self.fractional_hz:.1f} Hz "
            f"(pulse-to-pulse phase, coherence {self.coherence:.2f}) {self.ambiguity:+d} PRF "
            f"(range walk {self.walk_m_per_s:.1f} m/s over {self.lag_pulses} pulses: "
            f"{self.walk_centroid_hz:.0f} Hz)"
        )


def fractional_centroid_hz(lines: np.ndarray, prf_hz: float) -> tuple[float, float]:
    """(D1): (f_frac in Hz, coherence) of range-compressed lines[pulse, range_bin]."""
    # in double: a block of small samples (1e-30 of full scale) underflowed single precision's
    # sums to zero and was called "all zero" (a review)
    y = np.asarray(lines, np.complex128)
    if y.ndim != 2 or len(y) < 2:
        raise ValueError("the Doppler centroid needs at least two range lines [pulse, bin]")
    c = complex(np.vdot(y[:-1], y[1:]))  # Σ conj(y[p]) · y[p + 1]
    power = float(np.vdot(y, y).real)
    if power <= 0 or c == 0:
        raise ValueError("the echoes are all zero: no Doppler centroid to estimate")
    return prf_hz * math.atan2(c.imag, c.real) / (2.0 * math.pi), abs(c) / power


def range_walk_bins(lines: np.ndarray, lag_pulses: int) -> float:
    """Range shift (bins, > 0 outward) of |lines| between pulses p and p + lag_pulses, from the
    peak of their cross-correlation across range summed over p (parabolic refinement)."""
    mag = np.abs(np.asarray(lines)).astype(np.float64)
    a, b = mag[:-lag_pulses], mag[lag_pulses:]
    a = a - a.mean(axis=1, keepdims=True)
    b = b - b.mean(axis=1, keepdims=True)
    n = 1 << (2 * mag.shape[1] - 1).bit_length()  # linear, not circular, correlation
    spec = np.fft.rfft(b, n, axis=1) * np.conj(np.fft.rfft(a, n, axis=1))
    cc = np.fft.irfft(spec.sum(axis=0), n)
    k = int(np.argmax(cc))
    lo, mid, hi = cc[k - 1], cc[k], cc[(k + 1) % n]
    curv = lo - 2.0 * mid + hi
    frac = 0.5 * (lo - hi) / curv if curv < 0 else 0.0
    shift = k + frac
    return shift - n if shift > n / 2 else shift


def estimate_doppler_centroid(
    lines: np.ndarray,
    prf_hz: float,
    wavelength_m: float,
    bin_m: float,
    lag_pulses: int | None = None,
) -> DopplerEstimate:
    """The absolute Doppler centroid of range-compressed lines[pulse, range_bin] ((D1), (D2)).

    ``bin_m`` is the range spacing of the bins; ``lag_pulses`` the Δp of the walk (default: a
    third of the pulses, at most 512).  ValueError when there are too few pulses to see a walk.
    """
    y = np.asarray(lines)
    if y.ndim != 2 or len(y) < 16:
        raise ValueError(f"the Doppler centroid needs at least 16 pulses, got {len(y)}")
    if lag_pulses is None:
        lag_pulses = min(512, len(y) // 3)
    if not 1 <= lag_pulses < len(y):
        raise ValueError(f"lag_pulses must be in 1 … {len(y) - 1}, got {lag_pulses}")
    f_frac, coherence = fractional_centroid_hz(y, prf_hz)
    if coherence < MIN_COHERENCE:
        raise ValueError(
            f"the echoes' pulse-to-pulse coherence is {coherence:.3f} (below {MIN_COHERENCE}): "
            "noise, not a scene; no Doppler centroid to estimate"
        )
    walk_m = range_walk_bins(y, lag_pulses) * bin_m
    walk_m_per_s = walk_m * prf_hz / lag_pulses
    f_walk = -2.0 * walk_m_per_s / wavelength_m
    m = int(round((f_walk - f_frac) / prf_hz))
    return DopplerEstimate(
        f_frac + m * prf_hz, f_frac, m, walk_m_per_s, f_walk, coherence, int(lag_pulses)
    )
