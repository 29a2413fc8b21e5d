"""Raw-shot simulator: one pulse at a time, exact range history, opt-in effects.

For pulse p the platform is at x_p (stop-and-hop) and scatterer j at closest-approach range R_j
and along-track u_j is at the exact range R_pj = sqrt(R_j² + (x_p - u_j)²) — not the parabolic
approximation of Psaltis eq. 2 — so range curvature is present in the data.  Each return is
written in complex baseband with the conventions of rtsar.params:

* pulsed (Psaltis eq. 1, heterodyned to baseband, the AO window opening at τ_open):
  s[n] = a_j · rect((t_n-τ)/Tp) · exp i2π[-2R/λ + K/2 (t_n - τ - Tp/2)²],  t_n = τ_open + n/fs
* FMCW (Crouch eqs. 3.2-3.4, exact, LO delayed by τ_ref; t' = (n - S/2)/fs from mid-chirp):
  s[n] = a_j · exp i2π[-f0 Δτ - K Δτ t' + K Δτ (τ + τ_ref)/2],  Δτ = τ - τ_ref
  (the last term is Crouch's residual κτ²/2, kept).

Phases are accumulated in cycles in float64 and reduced mod 1 before the exponential; shots are
cast to complex64 only at the end.  Effects named by the scene are applied in order; others are
neither imported nor called.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ..lens_plan import receive_window_open_s
from ..params import C_M_PER_S, FMCWChirp, PulsedChirp
from .effects import load_effects
from .effects.base import Effect
from .model import Scene


@dataclass(frozen=True, eq=False)
class Shot:
    index: int  # pulse number since the start of the scan
    time_s: float  # nominal transmit time, index / PRF
    along_track_m: float
    samples: np.ndarray  # complex64[samples_per_shot]


class Simulator:
    """Generates the raw shots of a scene; ``shots()`` is a generator a live stream can consume."""

    def __init__(self, scene: Scene):
        self.scene = scene
        cfg = scene.config
        self.config = cfg
        self.effects = load_effects(scene.effects, cfg)
        self._gain_effects = [
            e for e in self.effects if type(e).target_gain is not Effect.target_gain
        ]
        self._shot_effects = [
            e for e in self.effects if type(e).apply_to_shot is not Effect.apply_to_shot
        ]
        self._rng = np.random.default_rng(scene.seed)
        self._next = 0
        wf = cfg.waveform
        self.samples_per_shot = wf.samples_per_shot
        n = np.arange(self.samples_per_shot)
        if isinstance(wf, PulsedChirp):
            self._t_open = receive_window_open_s(cfg)
            self._t = self._t_open + n / wf.sample_rate_hz
        elif isinstance(wf, FMCWChirp):
            self._t = (n - self.samples_per_shot / 2) / wf.sample_rate_hz
        else:  # pragma: no cover - params validation prevents it
            raise TypeError(type(wf).__name__)

    # -- one shot -------------------------------------------------------------------------
    def _echo(self, pulse: int) -> np.ndarray:
        cfg, tg = self.config, self.scene.targets
        lam = cfg.geometry.wavelength_m
        x_p = float(self.scene.along_track_of(pulse))
        offset = tg.along_track_m - x_p
        r = np.sqrt(tg.slant_range_m**2 + offset**2)
        gain = tg.amplitude.copy()
        for e in self._gain_effects:
            gain *= e.target_gain(pulse, offset, r)
        out = np.zeros(self.samples_per_shot, np.complex128)
        wf = cfg.waveform
        if isinstance(wf, PulsedChirp):
            fs, k, tp = wf.sample_rate_hz, wf.chirp_rate_hz_per_s, wf.pulse_duration_s
            for rj, gj in zip(r, gain, strict=True):
                if gj == 0:
                    continue
                tau = 2.0 * rj / C_M_PER_S
                lo = max(0, math.ceil((tau - self._t_open) * fs))
                hi = min(self.samples_per_shot, math.ceil((tau + tp - self._t_open) * fs))
                if hi <= lo:
                    continue
                u = self._t[lo:hi] - tau - 0.5 * tp
                carrier = math.fmod(-2.0 * rj / lam, 1.0)
                cycles = np.mod(carrier + 0.5 * k * u * u, 1.0)
                out[lo:hi] += gj * np.exp(2j * math.pi * cycles)
        else:
            k = wf.chirp_rate_hz_per_s
            tau_ref = 2.0 * wf.reference_range_m / C_M_PER_S
            for rj, gj in zip(r, gain, strict=True):
                if gj == 0:
                    continue
                tau = 2.0 * rj / C_M_PER_S
                dtau = 2.0 * (rj - wf.reference_range_m) / C_M_PER_S
                const = math.fmod(
                    -2.0 * (rj - wf.reference_range_m) / lam + 0.5 * k * dtau * (tau + tau_ref), 1.0
                )
                cycles = np.mod(const - k * dtau * self._t, 1.0)
                out += gj * np.exp(2j * math.pi * cycles)
        for e in self._shot_effects:
            e.apply_to_shot(pulse, out, self._rng)
        return out

    def shot(self, pulse: int) -> Shot:
        """The next shot; pulses must be requested in order (effects keep RNG state)."""
        if pulse != self._next:
            raise ValueError(
                f"shots are generated in order: expected pulse {self._next}, got {pulse}"
            )
        self._next += 1
        g = self.config.geometry
        return Shot(
            pulse,
            pulse / g.prf_hz,
            float(self.scene.along_track_of(pulse)),
            self._echo(pulse).astype(np.complex64),
        )

    def shots(self, count: int | None = None) -> Iterator[Shot]:
        """Yield the scene's shots one at a time (all remaining ones by default)."""
        stop = self.scene.pulses if count is None else min(self.scene.pulses, self._next + count)
        while self._next < stop:
            yield self.shot(self._next)

    def block(self, count: int) -> np.ndarray:
        """The next ``count`` shots as one complex64 array [pulse, sample]."""
        shots = list(self.shots(count))
        if not shots:
            return np.zeros((0, self.samples_per_shot), np.complex64)
        return np.stack([s.samples for s in shots])
