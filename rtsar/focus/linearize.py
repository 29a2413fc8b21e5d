"""Chirp linearization: resample each dechirped shot on the reference-interferometer phase.

Physics (Crouch 2012, ch. 3, eqs. 3.2-3.5 and "Chirp Linearization"; Zhao 2014, channel 2)
------------------------------------------------------------------------------------------
The laser's phase in cycles is φ(u) = f0 u + K u²/2 + e(u), u from the middle of the chirp,
so its optical frequency is f(u) = f0 + ν(u) with ν(u) = K u + e'(u); e is the deviation from the
linear chirp (rtsar.scene.effects.chirp).  Dechirping a return of delay τ against the LO delayed
by τ_ref (Crouch eq. 3.4 without dropping e) gives

    s(t) = exp i2π[φ(t - τ) - φ(t - τ_ref)] ≈ exp -i2π Δτ f(t - τ̄),   Δτ = τ - τ_ref,

a tone only while f is linear in t: a non-linear chirp smears the range response (Crouch
Fig. 5).  The reference interferometer beats the transmitted light with itself through a fibre
delay τ_ri (channel 2 of Zhao; the fibre length reference of Crouch Fig. 6):

    r(t) = exp i2π[φ(t - τ_ri) - φ(t)] ≈ exp -i2π τ_ri f(t - τ_ri/2),

so ν(t) = -unwrap(arg r)/(2π τ_ri) + const: the instantaneous frequency up to one constant per
shot.  Resampling s at the instants τ_k where ν(τ_k) = K t_k restores
s(τ_k) = exp -i2π Δτ (f0 + K t_k): the linear-chirp shot, for every range at once (the
"resampling procedure" Crouch cites for early SAL with chirps "not better than 1 %").

The constant is not observable in the interferometer.  Without an absolute reference it is
chosen so that ν - K t has zero mean over the shot; with an HCN cell (rtsar.focus.hcn_align) it
is measured from the absorption lines, which also removes the start-frequency jitter.

Limit: resampling cannot undo aliasing.  A return at Δτ beats at Δτ·(K + Δf'(t)); where that
exceeds fs/2 the raw samples are already aliased (the non-linear sweep raises the local chirp
rate: +31 % for a 1 % sine of 5 periods).  The stage counts the shots whose measured peak chirp
rate puts the edge of the processor's range window beyond fs/2 (``shots_beat_aliased``); the
24-tap resampler is accurate to 2e-5 up to 0.36 fs.

Stream stage: raw shots, between ingest and the AO lens (``ChirpLinearizer.process``).
"""

from __future__ import annotations

import math

import numpy as np

from ..instrument import (
    RI_CHANNEL,
    channel_times_s,
    default_delay_s,
    fmcw_waveform,
    infer_oversampling,
)
from ..lens.plan import range_axis_m
from ..params import C_M_PER_S
from ..samples import zero_nonfinite_rows
from .hcn_align import offsets_reference
from .resample import (
    DEFAULT_KAISER_BETA,
    DEFAULT_TAPS,
    check_resampler,
    resample,
    resample_reference,
)
from .stage import CorrectionStage

# --------------------------------------------------------------------------------------------
# Reference interferometer → instantaneous frequency
# --------------------------------------------------------------------------------------------


def relative_frequency_hz(ri: np.ndarray, delay_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Instantaneous frequency (Hz, up to one constant per shot) from the interferometer.

    ν(t - τ_ri/2) = -unwrap(arg r(t)) / (2π τ_ri) (module docstring).  The phase unwraps only
    if every sample-to-sample step lies in (-1/2, 0) cycles (beat frequency within (0, fs/2));
    a shot violating it, or holding NaN/Inf or zeros, is flagged bad (its row is left finite).

    Returns (nu_hz float64[P, M], ok bool[P]).
    """
    if not (math.isfinite(delay_s) and delay_s > 0):
        raise ValueError(f"delay_s must be finite and > 0, got {delay_s!r}")
    r = np.asarray(ri, np.complex128)
    finite = np.isfinite(r).all(axis=1) & (np.abs(r) > 0).all(axis=1)
    r = np.where(np.isfinite(r), r, 1.0)
    steps = np.angle(r[:, 1:] * np.conj(r[:, :-1])) / (2.0 * math.pi)  # cycles per sample
    ok = finite & (steps < 0.0).all(axis=1)
    cycles = np.concatenate([np.zeros((len(r), 1)), np.cumsum(steps, axis=1)], axis=1)
    return -cycles / delay_s, ok


def _resample_index(nu_hz: np.ndarray, t_nu: np.ndarray, k_t: np.ndarray, fs: float, s: int):
    """Fractional main-sample positions u_k where ν(τ_k) = K t_k, one shot (ν increasing)."""
    tau = np.interp(k_t, nu_hz, t_nu)
    u = tau * fs + 0.5 * s
    beyond = (k_t < nu_hz[0]) | (k_t > nu_hz[-1])
    return np.where(beyond, -1.0, u)  # -1: outside the record, zeroed by the resampler


def linearize_reference(
    config,
    shots: np.ndarray,
    ri: np.ndarray,
    delay_s: float | None = None,
    hcn: np.ndarray | None = None,
    hcn_options: dict | None = None,
    taps: int = DEFAULT_TAPS,
    kaiser_beta: float = DEFAULT_KAISER_BETA,
) -> tuple[np.ndarray, np.ndarray]:
    """Float64 batch reference of ChirpLinearizer (one shot at a time, plain loops).

    ``hcn``: the HCN channel; when given, each shot's constant is measured on it by
    rtsar.focus.hcn_align.offsets_reference(config, hcn, ν, **hcn_options) (absolute anchor);
    otherwise ν - K t is made zero-mean.  A shot whose interferometer phase does not unwrap uses
    the last good shot's ν (none yet: the nominal K t).

    Returns (linearized shots complex128[P, S], resample instants τ_k float64[P, S] in s,
    NaN where the output was zeroed).
    """
    wf = fmcw_waveform(config, "chirp linearization")
    x = zero_nonfinite_rows(np.asarray(shots, np.complex128))[0]
    ri = np.asarray(ri)
    q = infer_oversampling(config, ri, RI_CHANNEL)
    tau_ri = default_delay_s(config, q) if delay_s is None else float(delay_s)
    s, fs, k = wf.samples_per_shot, wf.sample_rate_hz, wf.chirp_rate_hz_per_s
    k_t = k * channel_times_s(config, 1)
    t_ri = channel_times_s(config, q) - 0.5 * tau_ri
    nus = np.zeros((len(x), len(t_ri)))
    last = None
    for p in range(len(x)):
        nu, ok = relative_frequency_hz(ri[p : p + 1], tau_ri)
        if ok[0]:
            nu = nu[0]
            # anchor: ν(t) - K t zero-mean over the main samples (t_ri[q n], n = 0 … S-1)
            nu = nu + np.mean(k * t_ri[::q] - nu[::q])
            last = nu
        else:
            nu = last if last is not None else k * t_ri
        nus[p] = nu
    if hcn is not None:
        hcn = np.asarray(hcn)
        t_hcn = channel_times_s(config, infer_oversampling(config, hcn, "hcn"))
        nu_hcn = np.stack([np.interp(t_hcn, t_ri, row) for row in nus])
        nus += offsets_reference(config, hcn, nu_hcn, **(hcn_options or {}))[:, None]
    out = np.zeros_like(x)
    times = np.full(x.shape, np.nan)
    for p in range(len(x)):
        u = _resample_index(nus[p], t_ri, k_t, fs, s)
        out[p] = resample_reference(x[p : p + 1], u[None, :], taps, kaiser_beta)[0]
        inside = (u >= 0) & (u <= s - 1)
        times[p, inside] = (u[inside] - 0.5 * s) / fs
    return out, times


class ChirpLinearizer(CorrectionStage):
    """Stream stage: resample raw shots onto a linear chirp using the interferometer channel.

    ``stage.process(samples[P, S], aux={RI_CHANNEL: ri[P, q·S], ...})`` → complex64[P, S], one
    micro-batch at a time, in pulse order.  With ``aligner`` (an rtsar.focus.hcn_align.HCNAligner)
    the absolute frequency of each shot is measured on the HCN channel too, so the start-frequency
    jitter is removed in the same resampling.  Causal and bounded: the only state is the last good
    frequency curve (fallback for a shot whose interferometer phase does not unwrap) and counters:

    shots_in, shots_not_linearized (fell back), samples_zeroed (resampled beyond the record),
    shots_nonfinite (main-channel shots holding NaN/Inf, zeroed),
    shots_beat_aliased (the measured peak chirp rate puts the range window's edge beyond fs/2).
    ``last_times_s`` holds the resample instants of the last batch (NaN where zeroed).
    """

    domain = "raw"
    counter_names = (
        "shots_in",
        "shots_not_linearized",
        "shots_beat_aliased",
        "shots_nonfinite",
        "samples_zeroed",
    )

    def __init__(
        self,
        config,
        delay_s: float | None = None,
        aligner=None,
        taps: int = DEFAULT_TAPS,
        kaiser_beta: float = DEFAULT_KAISER_BETA,
        channel: str = RI_CHANNEL,
    ):
        wf = fmcw_waveform(config, "chirp linearization")
        check_resampler(taps, kaiser_beta)
        if delay_s is not None and not (math.isfinite(delay_s) and delay_s > 0):
            raise ValueError(f"delay_s must be finite and > 0, got {delay_s!r}")
        self.config = config
        self.delay_s = delay_s
        self.aligner = aligner
        self.taps, self.kaiser_beta, self.channel = taps, float(kaiser_beta), channel
        self.channels = (channel,) + (aligner.channels if aligner is not None else ())
        self._s, self._fs, self._k = wf.samples_per_shot, wf.sample_rate_hz, wf.chirp_rate_hz_per_s
        self._t_main = channel_times_s(config, 1)
        self._k_t = self._k * self._t_main
        # Largest |τ - τ_ref| of the processor's range window: its beat must stay below fs/2.
        edge_m = np.max(np.abs(range_axis_m(config) - wf.reference_range_m))
        self._max_rate_hz_per_s = 0.5 * self._fs / (2.0 * edge_m / C_M_PER_S)
        self.shots_beat_aliased = 0
        self._last_nu = None
        self.shots_in = 0
        self.shots_not_linearized = 0
        self.shots_nonfinite = 0
        self.samples_zeroed = 0
        self.last_times_s = np.zeros((0, self._s))

    def counter_values(self) -> dict[str, int]:
        """Its own counters, and the HCN aligner's (``hcn_`` …) when it anchors the chirp."""
        out = super().counter_values()
        if self.aligner is not None:
            out.update({f"hcn_{k}": v for k, v in self.aligner.counter_values().items()})
        return out

    def process(self, samples: np.ndarray, aux: dict) -> np.ndarray:
        """Linearize a micro-batch of raw shots [P, S] (complex64 out)."""
        x = np.asarray(samples)
        if x.ndim != 2 or x.shape[1] != self._s:
            raise ValueError(f"samples must be [pulses, {self._s}], got {x.shape}")
        if self.channel not in aux:
            raise ValueError(f"auxiliary channel {self.channel!r} missing (got {sorted(aux)})")
        ri = np.asarray(aux[self.channel])
        if ri.shape[0] != len(x):
            raise ValueError(f"{self.channel!r} has {ri.shape[0]} shots, samples have {len(x)}")
        x, bad = zero_nonfinite_rows(x)
        self.shots_nonfinite += int(bad.sum())
        q = infer_oversampling(self.config, ri, self.channel)
        tau_ri = default_delay_s(self.config, q) if self.delay_s is None else self.delay_s
        t_ri = channel_times_s(self.config, q) - 0.5 * tau_ri
        nu, ok = relative_frequency_hz(ri, tau_ri)
        # Anchor without an absolute reference: ν - K t zero-mean over the main samples.
        nu += np.mean(self._k * t_ri[::q] - nu[:, ::q], axis=1)[:, None]
        for p in range(len(x)):  # causal fallback: the last good curve, else the nominal chirp
            if ok[p]:
                self._last_nu = nu[p].copy()
            else:
                nu[p] = self._last_nu if self._last_nu is not None else self._k * t_ri
        self.shots_not_linearized += int(np.count_nonzero(~ok))
        peak_rate = np.max(np.diff(nu[:, ::q], axis=1), axis=1) * self._fs
        self.shots_beat_aliased += int(np.count_nonzero(peak_rate > self._max_rate_hz_per_s))
        if self.aligner is not None:
            hcn_key = self.aligner.channel
            if hcn_key not in aux:
                raise ValueError(f"auxiliary channel {hcn_key!r} missing (got {sorted(aux)})")
            hcn = np.asarray(aux[hcn_key])
            t_hcn = channel_times_s(self.config, infer_oversampling(self.config, hcn, hcn_key))
            nu_hcn = np.stack([np.interp(t_hcn, t_ri, row) for row in nu])
            nu += self.aligner.offsets_hz(hcn, nu_hcn)[:, None]
        u = np.stack([_resample_index(row, t_ri, self._k_t, self._fs, self._s) for row in nu])
        out, outside = resample(x, u, self.taps, self.kaiser_beta)
        self.shots_in += len(x)
        self.samples_zeroed += int(np.count_nonzero(outside))
        self.last_times_s = np.where(outside, np.nan, (u - 0.5 * self._s) / self._fs)
        return out.astype(np.complex64)
