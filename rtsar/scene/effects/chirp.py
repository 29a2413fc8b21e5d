"""Chirp defects: a non-linear sweep and a start frequency that jitters from shot to shot.

Both are deviations e(u) (cycles) of the transmitted phase from the ideal linear chirp
φ(u) = f0 u + K u²/2, u from the middle of the chirp; the simulator passes them through the
dechirp of every return, e(t - τ) - e(t - τ_ref) (Crouch 2012, eqs. 3.2-3.4), and the reference
channels (rtsar.scene.effects.channels) see the same e.  The instantaneous frequency deviation
is Δf(u) = e'(u) (Hz).
"""

from __future__ import annotations

import math

import numpy as np

from ...params import FMCWChirp, PulsedChirp
from .base import Effect


def _finite(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")
    return float(value)


def _seed(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
    return value


def _chirp_span(config) -> tuple[float, float]:
    """(bandwidth B in Hz, chirp duration T in s) of either waveform."""
    wf = config.waveform
    if isinstance(wf, FMCWChirp):
        return wf.bandwidth_hz, wf.chirp_duration_s
    if isinstance(wf, PulsedChirp):
        return wf.bandwidth_hz, wf.pulse_duration_s
    raise TypeError(type(wf).__name__)  # pragma: no cover - params validation prevents it


def nonlinearity_fraction(deviation_hz, bandwidth_hz: float, duration_s: float) -> float:
    """Chirp non-linearity as used throughout rtsar (Crouch's "linearity ... 1 %").

    Peak |Δf(u) - (a + b u)| over the chirp |u| ≤ T/2, divided by B, with a + b u the
    least-squares straight line through Δf: the deviation of the instantaneous frequency from
    the best linear chirp (an offset or a chirp-rate error is not a non-linearity).
    ``deviation_hz(u)`` gives Δf in Hz; evaluated on 4097 points.
    """
    u = np.linspace(-0.5 * duration_s, 0.5 * duration_s, 4097)
    df = np.asarray(deviation_hz(u), np.float64)
    a = np.vstack([np.ones_like(u), u]).T
    coef, *_ = np.linalg.lstsq(a, df, rcond=None)
    return float(np.max(np.abs(df - a @ coef)) / bandwidth_hz)


class ChirpNonlinearity(Effect):
    """Non-linear frequency sweep: polynomial plus sinusoidal deviation from the linear chirp.

    With x = 2u/T ∈ [-1, 1] over the chirp (T the chirp/pulse duration, B the bandwidth):

        Δf(u) = B [ Σ_k c_k x^k + a_p sin(π m x + φ) ],
        e(u)  = (B T / 2) [ Σ_k c_k x^(k+1)/(k+1) + a_p (cos φ - cos(π m x + φ)) / (π m) ],

    ``poly_fraction`` = (c_0, c_1, c_2, …) (fractions of B; c_0 is a frequency offset, c_1 a
    chirp-rate error, k ≥ 2 the non-linear terms), ``sine_fraction`` a, ``sine_periods`` m
    (periods across the chirp), ``sine_phase_rad`` φ.  ``sine_jitter`` > 0 scales the sine per
    shot, a_p = a (1 + sine_jitter·g_p), g_p standard normal drawn from (seed, pulse, 1): the sweep
    changes from shot to shot, as a free-running laser's does.

    "1 % non-linearity" (Crouch: early SAL chirps "not better than 1 %") means
    ``nonlinearity_fraction`` = 0.01: the peak instantaneous-frequency deviation from the best
    straight line is 1 % of B.  A cosine with whole periods (φ = π/2, m integer) has no straight-
    line part, so sine_fraction = 0.01 is exactly 1 %; the pure quadratic c_2 x² is 1 % at
    c_2 = 0.015 (its straight-line fit is c_2/3, the peak residual 2 c_2/3).
    """

    name = "chirp_nonlinearity"

    def __init__(
        self,
        config,
        poly_fraction=(),
        sine_fraction: float = 0.0,
        sine_periods: float = 5.0,
        sine_phase_rad: float = 0.5 * math.pi,
        sine_jitter: float = 0.0,
        seed: int = 0,
    ):
        if isinstance(poly_fraction, (str, bytes)) or not hasattr(poly_fraction, "__iter__"):
            raise ValueError(
                f"chirp_nonlinearity.poly_fraction must be a list of numbers, got {poly_fraction!r}"
            )
        self.poly = np.array(
            [_finite("chirp_nonlinearity.poly_fraction", c) for c in poly_fraction], np.float64
        )
        self.sine_fraction = _finite("chirp_nonlinearity.sine_fraction", sine_fraction)
        self.sine_periods = _finite("chirp_nonlinearity.sine_periods", sine_periods)
        if self.sine_periods <= 0:
            raise ValueError("chirp_nonlinearity.sine_periods must be > 0")
        self.sine_phase_rad = _finite("chirp_nonlinearity.sine_phase_rad", sine_phase_rad)
        self.sine_jitter = _finite("chirp_nonlinearity.sine_jitter", sine_jitter)
        if self.sine_jitter < 0:
            raise ValueError("chirp_nonlinearity.sine_jitter must be >= 0")
        self.seed = _seed("chirp_nonlinearity.seed", seed)
        self.bandwidth_hz, self.duration_s = _chirp_span(config)

    def sine_amplitude(self, pulse: int) -> float:
        """a_p: the sine's amplitude on this shot (fraction of B)."""
        if self.sine_jitter == 0:
            return self.sine_fraction
        g = np.random.default_rng((self.seed, int(pulse), 1)).standard_normal()
        return self.sine_fraction * (1.0 + self.sine_jitter * g)

    def frequency_deviation_hz(self, pulse: int, u_s) -> np.ndarray:
        """Δf(u) in Hz (the injected truth the linearizer is measured against)."""
        x = 2.0 * np.asarray(u_s, np.float64) / self.duration_s
        df = np.polynomial.polynomial.polyval(x, self.poly) if self.poly.size else 0.0 * x
        m, phi = self.sine_periods, self.sine_phase_rad
        df = df + self.sine_amplitude(pulse) * np.sin(math.pi * m * x + phi)
        return self.bandwidth_hz * df

    def chirp_deviation_cycles(self, pulse, u_s):
        x = 2.0 * np.asarray(u_s, np.float64) / self.duration_s
        k = np.arange(self.poly.size)
        e = np.zeros_like(x)
        if self.poly.size:
            e = np.polynomial.polynomial.polyval(x, np.concatenate([[0.0], self.poly / (k + 1)]))
        m, phi = self.sine_periods, self.sine_phase_rad
        a = self.sine_amplitude(pulse)
        if a:
            e = e + a * (math.cos(phi) - np.cos(math.pi * m * x + phi)) / (math.pi * m)
        return 0.5 * self.bandwidth_hz * self.duration_s * e

    def nonlinearity(self, pulse: int = 0) -> float:
        """``nonlinearity_fraction`` of this shot's sweep."""
        return nonlinearity_fraction(
            lambda u: self.frequency_deviation_hz(pulse, u), self.bandwidth_hz, self.duration_s
        )


class StartFrequencyJitter(Effect):
    """Shot-to-shot start-frequency offset δf_p of the chirp (Crouch 2012, ch. 3, "HCN Cell").

    Crouch: the spectral features wandered by ~1 ms relative to the trigger, ~10 GHz at
    10 THz/s.  A chirp started δt late is, up to a constant phase, the nominal one offset by
    δf = K δt: e_p(u) = δf_p u.  δf_p is normal with standard deviation ``std_hz``
    (default 10 GHz), drawn from (seed, pulse, 2) so ``truth`` regenerates it for any pulses.
    A return at Δτ from the LO range then carries -δf_p Δτ cycles.
    """

    name = "start_frequency_jitter"

    def __init__(self, config, std_hz: float = 10e9, seed: int = 0):
        self.std_hz = _finite("start_frequency_jitter.std_hz", std_hz)
        if self.std_hz < 0:
            raise ValueError("start_frequency_jitter.std_hz must be >= 0")
        self.seed = _seed("start_frequency_jitter.seed", seed)
        _chirp_span(config)

    def offset_hz(self, pulse: int) -> float:
        """δf_p of one shot (Hz)."""
        g = np.random.default_rng((self.seed, int(pulse), 2)).standard_normal()
        return self.std_hz * float(g)

    def truth(self, pulses) -> np.ndarray:
        """δf_p (Hz) for each pulse index in ``pulses``: the injected offsets."""
        return np.array([self.offset_hz(p) for p in np.atleast_1d(pulses)], np.float64)

    def chirp_deviation_cycles(self, pulse, u_s):
        return self.offset_hz(pulse) * np.asarray(u_s, np.float64)
