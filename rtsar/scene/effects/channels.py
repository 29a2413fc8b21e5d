"""Reference receive channels of an FMCW ladar: the reference interferometer and the HCN cell.

Zhao 2014 records four channels: 1, the transmission of an HCN cell ("accurate frequency
reference for different shots"); 2, a reference heterodyne signal for the chirp non-linearity;
3-4, the target returns.  Crouch 2012 (ch. 3) uses the HCN cell to align the shots' start
frequency and a fibre-delay interferometer to linearize the chirp.  Both channels here read the
pulse's total chirp deviation e(u) (``ctx.deviation``: non-linearity, start-frequency jitter)
so they see exactly the defects of the target channel.

Channel time axis: q·S samples at q·fs (q = ``oversampling``), sample m at
(m - qS/2)/(q fs) from mid-chirp, so sample q·n is main sample n (rtsar.focus.linearize).
"""

from __future__ import annotations

import math

import numpy as np

from ...instrument import (
    DEFAULT_LINEWIDTH_HZ,
    HCN_CHANNEL,
    RI_CHANNEL,
    channel_times_s,
    default_delay_s,
    hcn_absorbance,
    hcn_lines,
)
from ...params import FMCWChirp
from .base import Effect, PulseContext


def _fmcw(config, who: str) -> FMCWChirp:
    wf = config.waveform
    if not isinstance(wf, FMCWChirp):
        raise ValueError(f"{who} needs an FMCW waveform (it monitors the laser chirp)")
    return wf


def _oversampling(who: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 64:
        raise ValueError(f"{who}.oversampling must be an integer in 1..64, got {value!r}")
    return value


def _noise_sigma(who: str, snr_db) -> float | None:
    if snr_db is None:
        return None
    if (
        isinstance(snr_db, bool)
        or not isinstance(snr_db, (int, float))
        or not math.isfinite(snr_db)
    ):
        raise ValueError(f"{who}.snr_db must be a finite number or omitted, got {snr_db!r}")
    return 10.0 ** (-float(snr_db) / 20.0)


class ReferenceInterferometer(Effect):
    """The transmitted chirp beaten with itself through a fibre delay τ_ri (Zhao channel 2).

    r(t) = exp i2π[φ(t - τ_ri) - φ(t)] with φ(u) = f0 u + K u²/2 + e(u) (cycles), i.e.
    r = exp i2π[-f0 τ_ri + K τ_ri²/2 - K τ_ri t + e(t - τ_ri) - e(t)] — the main channel's
    synthesis (rtsar.scene.simulator, FMCW) for a "target" at c τ_ri/2 and the LO at zero delay.
    Its unwrapped phase is ≈ -τ_ri f(t) (Crouch: "a fiber delay serves as a length reference").

    ``delay_s`` τ_ri (default: beat at a quarter of the channel's sample rate,
    rtsar.instrument.default_delay_s); ``oversampling`` q; ``snr_db`` complex white noise
    of variance 10^(-snr_db/10) on the unit-amplitude beat (omitted: noise-free).
    """

    name = "reference_interferometer"

    def __init__(self, config, delay_s: float | None = None, oversampling: int = 1, snr_db=None):
        wf = _fmcw(config, self.name)
        self.oversampling = _oversampling(self.name, oversampling)
        if delay_s is None:
            delay_s = default_delay_s(config, self.oversampling)
        if isinstance(delay_s, bool) or not (
            isinstance(delay_s, (int, float)) and math.isfinite(delay_s) and delay_s > 0
        ):
            raise ValueError(f"{self.name}.delay_s must be finite and > 0, got {delay_s!r}")
        beat_hz = wf.chirp_rate_hz_per_s * delay_s
        nyquist_hz = 0.5 * self.oversampling * wf.sample_rate_hz
        if beat_hz >= nyquist_hz:
            raise ValueError(
                f"{self.name}: beat K·τ_ri = {beat_hz:.4g} Hz exceeds the channel's Nyquist "
                f"{nyquist_hz:.4g} Hz; shorten delay_s or raise oversampling"
            )
        self.delay_s = float(delay_s)
        self.sigma = _noise_sigma(self.name, snr_db)
        self._t = channel_times_s(config, self.oversampling)
        self._f0 = config.geometry.carrier_hz
        self._k = wf.chirp_rate_hz_per_s

    def aux_channels(self, ctx: PulseContext) -> dict[str, np.ndarray]:
        tau, t = self.delay_s, self._t
        const = math.fmod(-self._f0 * tau + 0.5 * self._k * tau * tau, 1.0)
        cycles = const - self._k * tau * t
        if ctx.deviation is not None:
            cycles = cycles + (ctx.deviation(t - tau) - ctx.deviation(t))
        r = np.exp(2j * math.pi * np.mod(cycles, 1.0))
        if self.sigma is not None:
            n = ctx.rng.standard_normal((2, t.size))
            r = r + self.sigma * math.sqrt(0.5) * (n[0] + 1j * n[1])
        return {RI_CHANNEL: r}


class HCNCell(Effect):
    """Intensity of the transmitted light through an HCN absorption cell (Zhao channel 1).

    I(t) = exp(-A(f0 + ν(t))) (Beer-Lambert) with ν(t) = K t + e'(t) the instantaneous frequency
    offset from the carrier (e' by a central difference of ``ctx.deviation``, step 1e-6·T) and
    A the Lorentzian line sum of rtsar.focus.hcn_align.hcn_absorbance (a synthetic HCN-like
    comb; see that module).  Real intensity stored as complex with zero imaginary part.

    ``linewidth_hz`` Lorentzian FWHM γ; ``peak_absorbance`` of the strongest line;
    ``oversampling`` q (default 16: the 1 GHz lines last γ/K ≈ 0.1 ms, a third of a main sample
    of crouch-sal, so the channel is sampled faster); ``snr_db`` real white noise of standard
    deviation 10^(-snr_db/20) relative to the unabsorbed intensity (omitted: noise-free).
    """

    name = "hcn_cell"

    def __init__(
        self,
        config,
        linewidth_hz: float = DEFAULT_LINEWIDTH_HZ,
        peak_absorbance: float = 1.0,
        oversampling: int = 16,
        snr_db=None,
    ):
        wf = _fmcw(config, self.name)
        for key, v in (("linewidth_hz", linewidth_hz), ("peak_absorbance", peak_absorbance)):
            if isinstance(v, bool) or not (
                isinstance(v, (int, float)) and math.isfinite(v) and v > 0
            ):
                raise ValueError(f"{self.name}.{key} must be finite and > 0, got {v!r}")
        self.linewidth_hz = float(linewidth_hz)
        self.peak_absorbance = float(peak_absorbance)
        self.oversampling = _oversampling(self.name, oversampling)
        self.sigma = _noise_sigma(self.name, snr_db)
        self._t = channel_times_s(config, self.oversampling)
        self._f0 = config.geometry.carrier_hz
        self._k = wf.chirp_rate_hz_per_s
        self._h = 1e-6 * wf.chirp_duration_s
        lo, hi = self._f0 + self._k * self._t[0], self._f0 + self._k * self._t[-1]
        if len(hcn_lines(lo, hi)[0]) == 0:
            raise ValueError(
                f"{self.name}: no HCN line in the sweep {lo / 1e12:.3f}-{hi / 1e12:.3f} THz"
            )

    def frequency_offset_hz(self, ctx: PulseContext) -> np.ndarray:
        """ν(t) = K t + e'(t): optical frequency minus the carrier at the channel's samples."""
        t = self._t
        nu = self._k * t
        if ctx.deviation is not None:
            h = self._h
            nu = nu + (ctx.deviation(t + h) - ctx.deviation(t - h)) / (2.0 * h)
        return nu

    def aux_channels(self, ctx: PulseContext) -> dict[str, np.ndarray]:
        nu = self.frequency_offset_hz(ctx)
        i = np.exp(-hcn_absorbance(self._f0 + nu, self.linewidth_hz, self.peak_absorbance))
        if self.sigma is not None:
            i = i + self.sigma * ctx.rng.standard_normal(i.size)
        return {HCN_CHANNEL: i.astype(np.complex128)}
