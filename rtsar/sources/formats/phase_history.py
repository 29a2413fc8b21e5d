"""rtsar's shots as a frequency-domain (FX) phase history, and back: the mapping CPHD needs.

A CPHD FX-domain signal vector holds, at RF frequency f, the return of a scatterer whose delay
exceeds the scene reference point's (SRP) by Δτ as a Δτ·exp(-i2π f Δτ) (CPHD 1.0.1 §4, Global/SGN
= -1).  The transform here maps one rtsar shot to such a vector exactly and invertibly (a unit-
modulus rotation per frequency sample), so a CPHD written from a recording reads back into the
same shots (to float32 rounding) and ``rtsar process`` of the CPHD gives the recording's image.

* Pulsed linear FM (Psaltis & Wagner 1981, eq. 1): the shot x[n], taken at t_n = τ_open + n/fs,
  holds a e^{-i2π f0 τ} r(t_n - τ) with r the replica (rtsar.lens.plan).  Its DFT X (nfft points,
  fb = k fs/nfft) times the phase-only matched filter e^{-i arg R(fb)} is
  a |R(fb)| e^{-i2π f0 τ} e^{-i2π fb (τ - τ_open)}; with e^{-i2π fb τ_open} e^{+i2π f τ_srp}
  (f = f0 + fb) it becomes a |R| e^{-i2π f (τ - τ_srp)}: range compressed in the frequency
  domain, referenced to the SRP.  NumSamples = nfft, SC0 = f0 - fs/2, SCSS = fs/nfft.
* FMCW with dechirp on receive (Crouch 2012, eqs. 3.4-3.5; rtsar.scene.simulator's model): the
  beat sample at t_n = (n - S/2)/fs is a e^{-i2π f_n (τ - τ_ref)} e^{iπ K (τ - τ_ref)²} with
  f_n = f0 + K (t_n - τ_ref): already FX; multiplied by e^{+i2π f_n (τ_srp - τ_ref)} it is
  referenced to the SRP.  The residual video phase πK(τ - τ_ref)² stays (it is not a per-sample
  factor; at rtsar's swaths it is below 0.03 rad for the lidar presets).  SC0 = f_0,
  SCSS = K/fs, NumSamples = S.

The mapping is built for τ_c = 2 R_c / c, R_c the processor's range centre; a vector whose SRP
lies at another two-way delay τ_srp (a fixed SRP seen from a moving platform) takes the extra
factor e^{+i2π f (τ_srp - τ_c)} (``dtau_s``).  Every phase is formed in float64 in cycles and
reduced mod 1 before the complex exponential.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...lens.plan import next_pow2, pulsed_replica, range_axis_m, receive_window_open_s
from ...params import C_M_PER_S, Config, FMCWChirp, PulsedChirp


@dataclass(frozen=True, eq=False)
class FxMapping:
    """How one configuration's shots map to FX vectors (see the module docstring)."""

    samples_per_shot: int  # S, samples of an rtsar shot
    num_samples: int  # samples of an FX vector (nfft for pulsed, S for FMCW)
    sc0_hz: float  # RF frequency of FX sample 0
    scss_hz: float  # FX sample spacing
    fx1_hz: float  # the signal's band
    fx2_hz: float
    toa1_s: float  # the processor's range window as delays relative to the SRP
    toa2_s: float
    srp_range_m: float  # R_c: the processor's range centre (τ_c = 2 R_c / c)
    rotation: np.ndarray  # complex128[num_samples]: FX = transform(shot) · rotation
    pulsed: bool

    @property
    def fxc_hz(self) -> float:
        return 0.5 * (self.fx1_hz + self.fx2_hz)

    @property
    def frequency_hz(self) -> np.ndarray:
        return self.sc0_hz + self.scss_hz * np.arange(self.num_samples)


def _cis(cycles: np.ndarray) -> np.ndarray:
    """exp(i2π·cycles) with the cycles reduced mod 1 in float64 first."""
    return np.exp(2j * np.pi * np.mod(cycles, 1.0))


def fx_mapping(cfg: Config) -> FxMapping:
    """The FX mapping of a configuration (CPHD FX domain, SGN = -1)."""
    wf, geo = cfg.waveform, cfg.geometry
    f0 = geo.carrier_hz
    r_c = cfg.processor.range_centre_m or geo.slant_range_m
    tau_srp = 2.0 * r_c / C_M_PER_S
    rng = range_axis_m(cfg)
    toa1, toa2 = 2.0 * (rng[0] - r_c) / C_M_PER_S, 2.0 * (rng[-1] - r_c) / C_M_PER_S
    fs = wf.sample_rate_hz
    if isinstance(wf, PulsedChirp):
        nfft = next_pow2(wf.samples_per_shot)
        fb = np.fft.fftshift(np.fft.fftfreq(nfft, d=1.0 / fs))  # increasing: -fs/2 …
        spectrum = np.fft.fftshift(np.fft.fft(pulsed_replica(wf), nfft))
        tau_open = receive_window_open_s(cfg)
        # cycles: -arg R/2π - fb τ_open + f τ_srp, with f τ_srp = f0 τ_srp + fb τ_srp
        cycles = (
            -np.angle(spectrum) / (2 * np.pi)
            + np.mod(fb * (tau_srp - tau_open), 1.0)
            + np.mod(f0 * tau_srp, 1.0)
        )
        half_band = 0.5 * wf.bandwidth_hz
        return FxMapping(
            wf.samples_per_shot,
            nfft,
            f0 + float(fb[0]),
            fs / nfft,
            f0 - half_band,
            f0 + half_band,
            toa1,
            toa2,
            r_c,
            _cis(cycles),
            True,
        )
    if isinstance(wf, FMCWChirp):
        s = wf.samples_per_shot
        k = wf.chirp_rate_hz_per_s
        tau_ref = 2.0 * wf.reference_range_m / C_M_PER_S
        t = (np.arange(s) - s / 2) / fs
        f = f0 + k * (t - tau_ref)
        d = tau_srp - tau_ref
        cycles = np.mod(f0 * d, 1.0) + np.mod(k * (t - tau_ref) * d, 1.0)
        return FxMapping(
            s,
            s,
            float(f[0]),
            k / fs,
            float(f[0]),
            float(f[-1]),
            toa1,
            toa2,
            r_c,
            _cis(cycles),
            False,
        )
    raise TypeError(f"unsupported waveform {type(wf).__name__}")


def _srp_shift(m: FxMapping, dtau_s) -> np.ndarray | float:
    """e^{+i2π f (τ_srp - τ_c)} per vector [pulse, sample] (1.0 where ``dtau_s`` is None)."""
    if dtau_s is None:
        return 1.0
    dtau = np.asarray(dtau_s, np.float64)[:, None]
    return _cis(
        np.mod(m.sc0_hz * dtau, 1.0) + np.mod(m.scss_hz * np.arange(m.num_samples) * dtau, 1.0)
    )


def shots_to_fx(m: FxMapping, shots: np.ndarray, dtau_s=None) -> np.ndarray:
    """FX vectors complex64[pulse, num_samples] of shots [pulse, samples_per_shot]; ``dtau_s``
    [pulse]: each vector's SRP delay minus τ_c (None: 0)."""
    shots = np.asarray(shots, np.complex128)
    if m.pulsed:
        spec = np.fft.fftshift(np.fft.fft(shots, m.num_samples, axis=-1), axes=-1)
    else:
        spec = shots
    return (spec * m.rotation * _srp_shift(m, dtau_s)).astype(np.complex64)


def fx_to_shots(m: FxMapping, fx: np.ndarray, dtau_s=None) -> np.ndarray:
    """The inverse of :func:`shots_to_fx`: shots complex64[pulse, samples_per_shot]."""
    fx = np.asarray(fx, np.complex128)
    if fx.shape[-1] != m.num_samples:
        raise ValueError(f"FX vectors of {fx.shape[-1]} samples, expected {m.num_samples}")
    spec = fx * np.conj(m.rotation * _srp_shift(m, dtau_s))
    if m.pulsed:
        x = np.fft.ifft(np.fft.ifftshift(spec, axes=-1), axis=-1)[..., : m.samples_per_shot]
        return x.astype(np.complex64)
    return spec.astype(np.complex64)
