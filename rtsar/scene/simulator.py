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

A chirp deviation e(u) (cycles, u from the middle of the transmitted chirp; effects supply it)
adds e(t_n - τ - Tp/2) to a pulsed return and e(t' - τ) - e(t' - τ_ref) to a dechirped FMCW
return.  Phases are accumulated in cycles in float64 and reduced mod 1 before the exponential;
shots are cast to complex64 only at the end.  Effects named by the scene are applied in order;
others are neither imported nor called.  Auxiliary receive channels (effects' ``aux_channels``)
travel beside the main channel in ``Shot.aux``.

Errors common to every receiver of the pass (rtsar.scene.effects.base lists which) reach the
auxiliary receivers as they reach the main one: the platform position through each channel's
geometry, the chirp deviation through ``PulseContext.echo``, and the shot phase of the
``common_to_receivers`` effects (piston, the reference region's target path), applied to the
main echo and to every echo ``PulseContext.echo`` returns, before any receiver's own noise.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from ..lens.plan import receive_window_open_s
from ..params import C_M_PER_S, FMCWChirp, PulsedChirp
from .effects import load_effects
from .effects.base import Effect, PulseContext
from .model import Scene, Targets
from .tones import pulsed_returns, quadratic_phasor, tone_sum


@dataclass(frozen=True, eq=False)
class Shot:
    index: int  # pulse number since the start of the scan
    time_s: float  # nominal transmit time, index / PRF
    along_track_m: float
    samples: np.ndarray  # complex64[samples_per_shot]
    aux: dict = field(default_factory=dict)  # name → complex64[samples_per_shot]


class Simulator:
    """Generates the raw shots of a scene; ``shots()`` is a generator a live stream can consume."""

    def __init__(self, scene: Scene):
        self.scene = scene
        cfg = scene.config
        self.config = cfg
        self.effects = load_effects(scene.effects, cfg)
        self._gain_effects = self._overriding("target_gain")
        shot_effects = self._overriding("apply_to_shot")
        self._common_effects = [e for e in shot_effects if e.common_to_receivers]
        self._shot_effects = [e for e in shot_effects if not e.common_to_receivers]
        self._chirp_effects = self._overriding("chirp_deviation_cycles")
        self._position_effects = self._overriding("along_track_error_m")
        self._aux_effects = self._overriding("aux_channels")
        self._rng = np.random.default_rng(scene.seed)
        self._seen = self._visible_targets()
        self._next = 0
        wf = cfg.waveform
        self.samples_per_shot = wf.samples_per_shot
        n = np.arange(self.samples_per_shot)
        if isinstance(wf, PulsedChirp):
            self._t_open = receive_window_open_s(cfg)
            self._t = self._t_open + n / wf.sample_rate_hz
            fs = wf.sample_rate_hz
            self._chirp_q = quadratic_phasor(n.size, 0.5 * wf.chirp_rate_hz_per_s / (fs * fs))
        elif isinstance(wf, FMCWChirp):
            self._t = (n - self.samples_per_shot / 2) / wf.sample_rate_hz
        else:  # pragma: no cover - params validation prevents it
            raise TypeError(type(wf).__name__)

    def prepare(self) -> None:
        """Compile (first run) or load from numba's cache the synthesis kernels now, not on the
        first shot of a live stream (a few seconds the first time, ~1 s after)."""
        self._tone_echo(np.zeros(1), np.zeros(1))  # zero gain: the kernels run on no scatterer

    def _overriding(self, hook: str) -> list[Effect]:
        """The effects that implement ``hook`` (the others are never called for it)."""
        return [e for e in self.effects if getattr(type(e), hook) is not getattr(Effect, hook)]

    def _visible_targets(self):
        """(targets sorted along track, half-width of the offsets any gain leaves non-zero), or
        None: every scatterer is synthesised on every pulse.  Scatterers outside the half-width
        have gain exactly 0, which both echo paths skip, so skipping them first changes no
        sample; auxiliary channels see all targets (their effects may have gains of their own)."""
        tg = self.scene.targets
        if self._aux_effects or len(tg) == 0:
            return None
        r_max = float(tg.slant_range_m.max())
        bounds = [e.along_track_support_m(r_max) for e in self._gain_effects]
        bounds = [b for b in bounds if b is not None]
        if not bounds:
            return None
        order = np.argsort(tg.along_track_m, kind="stable")
        sorted_tg = Targets(tg.along_track_m[order], tg.slant_range_m[order], tg.amplitude[order])
        return sorted_tg, min(bounds)

    # -- one shot -------------------------------------------------------------------------
    def echo(self, range_m, gain, deviation=None, lo_range_m=None) -> np.ndarray:
        """Returns from scatterers at ranges ``range_m`` with complex ``gain`` (complex128 samples).

        The exact synthesis of the module docstring for any set of (effective, e.g. bistatic
        half-path) ranges; ``deviation`` is the chirp deviation e(u) in cycles (None: ideal chirp)
        and ``lo_range_m`` the FMCW LO delay as a range (None: the waveform's reference range).
        """
        if deviation is None:
            return self._tone_echo(range_m, gain, lo_range_m)
        return self.direct_echo(range_m, gain, deviation, lo_range_m)

    def direct_echo(self, range_m, gain, deviation=None, lo_range_m=None) -> np.ndarray:
        """``echo`` evaluated by the formula of the module docstring, an exponential per scatterer
        and sample (the reference of the tone path; the path taken with a chirp deviation)."""
        wf = self.config.waveform
        out = np.zeros(self.samples_per_shot, np.complex128)
        lam = self.config.geometry.wavelength_m
        if isinstance(wf, PulsedChirp):
            fs, k, tp = wf.sample_rate_hz, wf.chirp_rate_hz_per_s, wf.pulse_duration_s
            for rj, gj in zip(np.atleast_1d(range_m), np.atleast_1d(gain), strict=True):
                if gj == 0:
                    continue
                tau = 2.0 * rj / C_M_PER_S
                lo = max(0, math.ceil((tau - self._t_open) * fs))
                hi = min(self.samples_per_shot, math.ceil((tau + tp - self._t_open) * fs))
                if hi <= lo:
                    continue
                u = self._t[lo:hi] - tau - 0.5 * tp
                carrier = math.fmod(-2.0 * rj / lam, 1.0)
                cycles = carrier + 0.5 * k * u * u
                if deviation is not None:
                    cycles = cycles + deviation(u)
                out[lo:hi] += gj * np.exp(2j * math.pi * np.mod(cycles, 1.0))
            return out
        k = wf.chirp_rate_hz_per_s
        r_lo = wf.reference_range_m if lo_range_m is None else float(lo_range_m)
        tau_ref = 2.0 * r_lo / C_M_PER_S
        lo_dev = None if deviation is None else deviation(self._t - tau_ref)
        r_all = np.atleast_1d(np.asarray(range_m, np.float64))
        g_all = np.atleast_1d(np.asarray(gain, np.complex128))
        keep = g_all != 0
        r_all, g_all = r_all[keep], g_all[keep]
        # Scatterers in chunks of a [targets, samples] phase matrix (bounded memory, vectorised).
        chunk = max(1, (1 << 20) // self.samples_per_shot)
        for i in range(0, len(r_all), chunk):
            rj, gj = r_all[i : i + chunk, None], g_all[i : i + chunk]
            tau = 2.0 * rj / C_M_PER_S
            dtau = 2.0 * (rj - r_lo) / C_M_PER_S
            const = np.fmod(-2.0 * (rj - r_lo) / lam + 0.5 * k * dtau * (tau + tau_ref), 1.0)
            cycles = const - k * dtau * self._t[None, :]
            if deviation is not None:
                for row in range(len(gj)):
                    cycles[row] += deviation(self._t - tau[row, 0]) - lo_dev
            out += gj @ np.exp(2j * math.pi * np.mod(cycles, 1.0))
        return out

    def _tone_echo(self, range_m, gain, lo_range_m=None) -> np.ndarray:
        """``echo`` with an ideal chirp, as windowed tones (rtsar.scene.tones; same samples to
        ~1e-13 of each amplitude, one multiply-add per scatterer and sample)."""
        wf = self.config.waveform
        lam = self.config.geometry.wavelength_m
        r = np.atleast_1d(np.asarray(range_m, np.float64))
        g = np.atleast_1d(np.asarray(gain, np.complex128))
        if r.shape != g.shape:
            raise ValueError(f"echo: {r.shape[0]} ranges but {g.shape[0]} gains")
        keep = g != 0
        r, g = r[keep], g[keep]
        s = self.samples_per_shot
        if isinstance(wf, PulsedChirp):
            return pulsed_returns(
                s,
                r,
                g,
                self._t_open,
                wf.sample_rate_hz,
                wf.chirp_rate_hz_per_s,
                wf.pulse_duration_s,
                lam,
                C_M_PER_S,
                self._chirp_q,
            )
        k = wf.chirp_rate_hz_per_s
        fs = wf.sample_rate_hz
        r_lo = wf.reference_range_m if lo_range_m is None else float(lo_range_m)
        tau = 2.0 * r / C_M_PER_S
        tau_ref = 2.0 * r_lo / C_M_PER_S
        dtau = 2.0 * (r - r_lo) / C_M_PER_S
        const = np.fmod(-2.0 * (r - r_lo) / lam + 0.5 * k * dtau * (tau + tau_ref), 1.0)
        # t_n = (n - S/2)/fs: -K Δτ t_n = K Δτ S/(2 fs) - (K Δτ/fs) n
        alpha = const + np.fmod(k * dtau * (0.5 * s / fs), 1.0)
        beta = np.fmod(-k * dtau / fs, 1.0)
        zeros = np.zeros(len(r), np.int64)
        return tone_sum(s, zeros, zeros + s, alpha, beta, g)

    def _deviation(self, pulse: int):
        """The summed chirp deviation of the effects for this pulse, e(u) in cycles, or None."""
        if not self._chirp_effects:
            return None

        def total(u):
            acc = np.zeros(np.shape(u))
            for e in self._chirp_effects:
                d = e.chirp_deviation_cycles(pulse, u)
                if d is not None:
                    acc = acc + d
            return acc

        return total

    def platform_along_track_m(self, pulse: int) -> float:
        """True platform position at this pulse: nominal x_p plus the effects' errors."""
        x_p = float(self.scene.along_track_of(pulse))
        for e in self._position_effects:
            x_p += float(e.along_track_error_m(pulse))
        return x_p

    def _echo(self, pulse: int) -> tuple[np.ndarray, dict]:
        tg = self.scene.targets
        x_p = self.platform_along_track_m(pulse)
        if self._seen is not None:
            by_x, half_m = self._seen
            i0, i1 = np.searchsorted(by_x.along_track_m, (x_p - half_m, x_p + half_m))
            tg = Targets(
                by_x.along_track_m[i0:i1], by_x.slant_range_m[i0:i1], by_x.amplitude[i0:i1]
            )
        offset = tg.along_track_m - x_p
        r = np.sqrt(tg.slant_range_m**2 + offset**2)
        gain = tg.amplitude.copy()
        for e in self._gain_effects:
            gain *= e.target_gain(pulse, offset, r)
        deviation = self._deviation(pulse)

        def common(samples: np.ndarray) -> np.ndarray:
            """The pass's common shot errors, in place on a fresh complex128 echo."""
            for e in self._common_effects:
                e.apply_to_shot(pulse, samples, self._rng)
            return samples

        out = common(self.echo(r, gain, deviation))
        for e in self._shot_effects:
            e.apply_to_shot(pulse, out, self._rng)
        aux = {}
        if self._aux_effects:

            def bare(range_m, g, lo_range_m=None):
                return self.echo(range_m, g, deviation, lo_range_m)

            ctx = PulseContext(
                pulse,
                self.config,
                x_p,
                tg,
                offset,
                r,
                gain,
                self._t,
                deviation,
                lambda range_m, g, lo_range_m=None: common(bare(range_m, g, lo_range_m)),
                self._rng,
                bare,
            )
            for e in self._aux_effects:
                for name, samples in e.aux_channels(ctx).items():
                    if name in aux:
                        raise ValueError(f"two effects produce the auxiliary channel {name!r}")
                    aux[name] = np.asarray(samples).astype(np.complex64)
        return out, aux

    def shot(self, pulse: int) -> Shot:
        """The next shot; pulses must be requested in order (effects keep RNG state)."""
        if pulse != self._next:
            raise ValueError(
                f"shots are generated in order: expected pulse {self._next}, got {pulse}"
            )
        self._next += 1
        g = self.config.geometry
        samples, aux = self._echo(pulse)
        return Shot(
            pulse,
            pulse / g.prf_hz,
            float(self.scene.along_track_of(pulse)),
            samples.astype(np.complex64),
            aux,
        )

    def shots(self, count: int | None = None) -> Iterator[Shot]:
        """Yield the scene's shots one at a time (all remaining ones by default)."""
        stop = self.scene.pulses if count is None else min(self.scene.pulses, self._next + count)
        while self._next < stop:
            yield self.shot(self._next)

    def block(self, count: int) -> np.ndarray:
        """The next ``count`` shots as one complex64 array [pulse, sample] (main channel)."""
        return self.block_with_aux(count)[0]

    def block_with_aux(self, count: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """The next ``count`` shots: main channel [pulse, sample], {aux name: [pulse, sample]}."""
        shots = list(self.shots(count))
        if not shots:
            return np.zeros((0, self.samples_per_shot), np.complex64), {}
        aux = {name: np.stack([s.aux[name] for s in shots]) for name in shots[0].aux}
        return np.stack([s.samples for s in shots]), aux
