"""What the AO lens computes for a waveform, and its plain NumPy float64 reference.

The lens of Psaltis & Wagner focuses the light diffracted by the AO cell: a Fourier transform of
the received pulse.  Digitally the lens is one of two chains, both expressed by one LensPlan:

* FMCW (dechirp on receive, Crouch eqs. 3.4-3.7): window the beat samples, DFT with the time
  origin at the middle of the shot, keep the range window.  Bin k is the beat frequency
  f = k fs / nfft, i.e. range R = R_ref + c f / (2K).
* Pulsed linear FM (Psaltis eqs. 1-2): matched filter by fast correlation,
  y[l] = Σ_m x[l + m] conj(r[m]) with the replica r centred at baseband, computed as
  IDFT(DFT(x) · conj(DFT(r)) · W) with W the range taper over the chirp band.  Lag l is the
  delay τ = τ_open + l / fs; only lags 0 … S-P are free of wrap-around.

The plan, in order:  x·pre  →  DFT(sign1, nfft)  →  [·spectrum → DFT(sign2, nfft)]  →
bins k = bin_start … bin_start+bin_count-1 (mod nfft)  →  ·post.
DFT(sign)[k] = Σ_n x[n] exp(sign·i2πkn/nfft), unnormalised; the 1/nfft and gains sit in post.
A unit-amplitude point target with a rectangular window compresses to a unit peak whose phase is
the carrier phase -2π f0 τ (the convention of rtsar.params).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import C_M_PER_S, PRECISIONS, Config, FMCWChirp, PulsedChirp
from .windows import window, window_at


@dataclass(frozen=True, eq=False)
class LensPlan:
    samples_per_shot: int
    nfft: int
    pre: np.ndarray  # complex128[samples_per_shot]
    sign1: int
    spectrum: np.ndarray | None  # complex128[nfft] or None
    sign2: int
    bin_start: int  # may be negative: bins are taken modulo nfft
    bin_count: int
    post: np.ndarray  # complex128[bin_count]
    range_m: np.ndarray  # float64[bin_count], slant range of each output bin

    @property
    def two_pass(self) -> bool:
        return self.spectrum is not None


def next_pow2(n: int) -> int:
    return 1 << max(0, (int(n) - 1).bit_length())


def precision_dtype(precision: str) -> type:
    """The NumPy sample type of a ``Processor.precision`` name (one of PRECISIONS)."""
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {PRECISIONS}, got {precision!r}")
    return np.complex128 if precision == "complex128" else np.complex64


def _pulsed_lags(wf: PulsedChirp, bins: int) -> tuple[int, int]:
    valid = wf.samples_per_shot - wf.pulse_samples + 1
    if bins > valid:
        raise ValueError(
            f"range window of {bins} bins exceeds the {valid} fully compressed lags of a "
            f"{wf.receive_window_s * 1e6:g} µs receive window with a "
            f"{wf.pulse_duration_s * 1e6:g} µs pulse"
        )
    first = (valid - bins) // 2
    return first, valid


def receive_window_open_s(cfg: Config) -> float:
    """Two-way delay at which the pulsed receiver's window (the AO aperture) opens.

    Chosen so that the middle output bin sits at the processor's range centre.
    """
    wf = cfg.waveform
    if not isinstance(wf, PulsedChirp):
        raise TypeError("receive_window_open_s applies to pulsed waveforms")
    centre = cfg.processor.range_centre_m or cfg.geometry.slant_range_m
    first, _ = _pulsed_lags(wf, cfg.processor.range_bins)
    return 2.0 * centre / C_M_PER_S - (first + cfg.processor.range_bins // 2) / wf.sample_rate_hz


def pulsed_replica(wf: PulsedChirp) -> np.ndarray:
    """Baseband replica exp(iπK(t - Tp/2)²), t = m/fs, m < P (complex128)."""
    t = np.arange(wf.pulse_samples) / wf.sample_rate_hz - 0.5 * wf.pulse_duration_s
    return np.exp(1j * math.pi * wf.chirp_rate_hz_per_s * t * t)


def make_plan(cfg: Config) -> LensPlan:
    """Build the lens plan for a configuration (raises ValueError if the window cannot fit)."""
    wf, proc = cfg.waveform, cfg.processor
    bins = proc.range_bins
    centre = proc.range_centre_m or cfg.geometry.slant_range_m
    S = wf.samples_per_shot
    if isinstance(wf, FMCWChirp):
        nfft = next_pow2(S) * proc.range_oversampling
        fs, K = wf.sample_rate_hz, wf.chirp_rate_hz_per_s
        bin_m = C_M_PER_S * fs / (2.0 * K * nfft)
        k_centre = int(round((centre - wf.reference_range_m) / bin_m))
        bin_start = k_centre - bins // 2
        if bin_start < -nfft // 2 or bin_start + bins > nfft // 2:
            raise ValueError(
                f"range window {bins} bins around {centre:g} m leaves the unambiguous window "
                f"±{wf.unambiguous_range_m / 2:g} m about reference_range_m "
                f"{wf.reference_range_m:g} m"
            )
        k = bin_start + np.arange(bins)
        w = window(proc.range_window, S)
        # Time origin at the middle sample: multiply bin k by exp(-i π k S / nfft) (sign +1 DFT).
        post = np.exp(-1j * math.pi * k * S / nfft) / S
        return LensPlan(
            S,
            nfft,
            w.astype(np.complex128),
            +1,
            None,
            -1,
            bin_start,
            bins,
            post,
            wf.reference_range_m + k * bin_m,
        )
    if isinstance(wf, PulsedChirp):
        if proc.range_oversampling != 1:
            raise ValueError(
                "range_oversampling must be 1 for pulsed waveforms (sample_rate_hz "
                "already oversamples the chirp band)"
            )
        nfft = next_pow2(S)
        first, _ = _pulsed_lags(wf, bins)
        replica = pulsed_replica(wf)
        ref_spec = np.fft.fft(replica, nfft)
        f = np.fft.fftfreq(nfft, d=1.0 / wf.sample_rate_hz)
        taper = window_at(proc.range_window, (f + 0.5 * wf.bandwidth_hz) / wf.bandwidth_hz)
        spectrum = np.conj(ref_spec) * taper
        post = np.full(bins, 1.0 / (nfft * wf.pulse_samples), dtype=np.complex128)
        tau0 = receive_window_open_s(cfg)
        lags = first + np.arange(bins)
        return LensPlan(
            S,
            nfft,
            np.ones(S, np.complex128),
            -1,
            spectrum,
            +1,
            first,
            bins,
            post,
            0.5 * C_M_PER_S * (tau0 + lags / wf.sample_rate_hz),
        )
    raise TypeError(f"unsupported waveform {type(wf).__name__}")


def _dft(x: np.ndarray, sign: int, n: int, fft=np.fft) -> np.ndarray:
    """Unnormalised DFT along the last axis with exponent sign ±1 (fft: numpy.fft or scipy.fft)."""
    return fft.fft(x, n, axis=-1) if sign < 0 else fft.ifft(x, n, axis=-1) * n


def compress_reference(plan: LensPlan, shots: np.ndarray) -> np.ndarray:
    """Float64 reference of the AO lens: shots[pulse, sample] → lines[pulse, bin] (complex128)."""
    x = np.asarray(shots, dtype=np.complex128)
    if x.ndim != 2 or x.shape[1] != plan.samples_per_shot:
        raise ValueError(f"shots must be [pulses, {plan.samples_per_shot}], got {x.shape}")
    y = _dft(x * plan.pre, plan.sign1, plan.nfft)
    if plan.spectrum is not None:
        y = _dft(y * plan.spectrum, plan.sign2, plan.nfft)
    idx = (plan.bin_start + np.arange(plan.bin_count)) % plan.nfft
    return y[:, idx] * plan.post


class NumpyLens:
    """The plan evaluated with NumPy's (or SciPy's) FFT in the processor's precision.

    ``precision="complex64"`` (default): single-precision transforms, complex64 out; relative
    RMS error against compress_reference about 1e-7 (tested to 1e-5).  ``"complex128"``: the
    same chain in double, about 1e-16 (tested to 1e-12).  Not the reference (that is
    compress_reference): a CPU backend to compare the OpenCL lens against, and a fallback where
    no OpenCL device is wanted.
    """

    def __init__(self, plan: LensPlan, library: str = "numpy", precision: str = "complex64"):
        if library == "numpy":
            self._fft = np.fft
        elif library == "scipy":
            from scipy import fft as scipy_fft

            self._fft = scipy_fft
        else:
            raise ValueError("library must be 'numpy' or 'scipy'")
        self.plan = plan
        self.precision = precision
        self.dtype = dt = precision_dtype(precision)
        self._pre = plan.pre.astype(dt)
        self._spec = None if plan.spectrum is None else plan.spectrum.astype(dt)
        self._idx = (plan.bin_start + np.arange(plan.bin_count)) % plan.nfft
        self._post = plan.post.astype(dt)

    def compress(self, shots: np.ndarray) -> np.ndarray:
        p = self.plan
        x = np.asarray(shots)
        if x.ndim != 2 or x.shape[1] != p.samples_per_shot:
            raise ValueError(f"shots must be [pulses, {p.samples_per_shot}], got {x.shape}")
        y = _dft(x.astype(self.dtype, copy=False) * self._pre, p.sign1, p.nfft, self._fft)
        if self._spec is not None:
            y = _dft(y * self._spec, p.sign2, p.nfft, self._fft)
        return (y[:, self._idx] * self._post).astype(self.dtype, copy=False)
