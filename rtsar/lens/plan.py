"""What the AO lens computes for a waveform: the LensPlan, its range axis and the FFT sizes.

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

from ..params import C_M_PER_S, Config, FMCWChirp, PulsedChirp
from ..windows import window, window_at


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


def _pulsed_lags(cfg: Config) -> tuple[int, int]:
    """(first lag of the range window, lags the window may take).

    A window centred on the processor's range centre takes only the S - P + 1 lags free of
    wrap-around.  An instrument's fixed window (``PulsedChirp.window_start_s``) keeps every echo
    whose centre falls inside the shot, lags -P/2 … S - P/2 - 1: the echoes near either end are
    compressed with the part of their chirp the window holds (a wider response, told in the
    docs), and the lens transforms over nfft >= S + P so that no lag wraps onto another.
    """
    wf, bins = cfg.waveform, cfg.processor.range_bins
    if wf.window_start_s is not None:
        lags = wf.samples_per_shot
        if bins > lags:
            raise ValueError(
                f"range window of {bins} bins exceeds the {lags} samples of the instrument's "
                "receive window"
            )
        lowest = -(wf.pulse_samples // 2)
        centre = cfg.processor.range_centre_m
        if centre is None:
            first = lowest + (lags - bins) // 2
        else:  # the bins around the asked range centre (where the beam centre sees it)
            centre += cfg.geometry.squint_range_excess_m(centre)
            t_open = wf.window_start_s + 0.5 * wf.pulse_duration_s
            lag = round((2.0 * centre / C_M_PER_S - t_open) * wf.sample_rate_hz) - bins // 2
            first = min(max(lag, lowest), lowest + lags - bins)
        return first, lags
    valid = wf.samples_per_shot - wf.pulse_samples + 1
    if bins > valid:
        raise ValueError(
            f"range window of {bins} bins exceeds the {valid} fully compressed lags of a "
            f"{wf.receive_window_s * 1e6:g} µs receive window with a "
            f"{wf.pulse_duration_s * 1e6:g} µs pulse"
        )
    first = (valid - bins) // 2
    return first, valid


def chirp_fraction_held(cfg: Config) -> np.ndarray:
    """Per output bin, the fraction of a pulsed echo's chirp inside the receive window: 1 on
    the S - P + 1 lags free of wrap-around; an instrument's fixed window keeps the echoes
    whose centre it holds (_pulsed_lags), and those near its ends keep part of their chirp,
    so their band, and their range response, is about that fraction of the chirp's
    (RADARSAT-1: 1 on ~700 of the 2048 bins).  Ones for FMCW."""
    wf = cfg.waveform
    if not isinstance(wf, PulsedChirp):
        return np.ones(cfg.processor.range_bins)
    first, _ = _pulsed_lags(cfg)
    lags = first + np.arange(cfg.processor.range_bins)
    s, p = wf.samples_per_shot, wf.pulse_samples
    return np.clip((np.minimum(lags + p, s) - np.maximum(lags, 0)) / p, 0.0, 1.0)


def receive_window_open_s(cfg: Config) -> float:
    """Two-way delay at which the pulsed receiver's window (the AO aperture) opens, counted
    from the start of the transmitted pulse (the echo of range R starts 2R/c after it).

    An instrument's fixed window: its ``window_start_s`` (counted from the pulse centre) plus
    half the pulse.  Otherwise chosen so that the middle output bin sits at the processor's
    range centre.
    """
    wf = cfg.waveform
    if not isinstance(wf, PulsedChirp):
        raise TypeError("receive_window_open_s applies to pulsed waveforms")
    if wf.window_start_s is not None:
        return wf.window_start_s + 0.5 * wf.pulse_duration_s
    centre = cfg.processor.range_centre_m or cfg.geometry.slant_range_m
    centre += cfg.geometry.squint_range_excess_m(centre)  # where the beam centre sees it
    first, _ = _pulsed_lags(cfg)
    return 2.0 * centre / C_M_PER_S - (first + cfg.processor.range_bins // 2) / wf.sample_rate_hz


def pulsed_replica(wf: PulsedChirp) -> np.ndarray:
    """Baseband replica exp(iπK(t - Tp/2)²), t = m/fs, m < P (complex128)."""
    t = np.arange(wf.pulse_samples) / wf.sample_rate_hz - 0.5 * wf.pulse_duration_s
    return np.exp(1j * math.pi * wf.chirp_rate_hz_per_s * t * t)


def _fmcw_bins(cfg: Config) -> tuple[int, int, float]:
    """FMCW lens: (nfft, first output bin (may be negative), bin width in metres)."""
    wf, proc = cfg.waveform, cfg.processor
    bins = proc.range_bins
    centre = proc.range_centre_m or cfg.geometry.slant_range_m
    nfft = next_pow2(wf.samples_per_shot) * proc.range_oversampling
    bin_m = C_M_PER_S * wf.sample_rate_hz / (2.0 * wf.chirp_rate_hz_per_s * nfft)
    bin_start = int(round((centre - wf.reference_range_m) / bin_m)) - bins // 2
    if bin_start < -nfft // 2 or bin_start + bins > nfft // 2:
        raise ValueError(
            f"range window {bins} bins around {centre:g} m leaves the unambiguous window "
            f"±{wf.unambiguous_range_m / 2:g} m about reference_range_m "
            f"{wf.reference_range_m:g} m"
        )
    return nfft, bin_start, bin_m


def raw_range_axis_m(cfg: Config) -> np.ndarray:
    """Range at which each output bin's echo lies (float64[range_bins]): FMCW R = R_ref +
    c f / (2K) at beat frequency f = k fs / nfft; pulsed R = c (τ_open + l / fs) / 2 at lag l."""
    wf, bins = cfg.waveform, cfg.processor.range_bins
    if isinstance(wf, FMCWChirp):
        _, bin_start, bin_m = _fmcw_bins(cfg)
        return wf.reference_range_m + (bin_start + np.arange(bins)) * bin_m
    if isinstance(wf, PulsedChirp):
        if cfg.processor.range_oversampling != 1:
            raise ValueError(
                "range_oversampling must be 1 for pulsed waveforms (sample_rate_hz "
                "already oversamples the chirp band)"
            )
        first, _ = _pulsed_lags(cfg)
        lags = first + np.arange(bins)
        return 0.5 * C_M_PER_S * (receive_window_open_s(cfg) + lags / wf.sample_rate_hz)
    raise TypeError(f"unsupported waveform {type(wf).__name__}")


def squint_label_offset_m(cfg: Config) -> float:
    """R_c - R0 at the middle bin: what range_axis_m takes off the raw ranges of a squinted
    beam (0 broadside).  The beam centre sees a scatterer of closest-approach range R0 at
    R_c = R0 / cos θ; the CCD's range-migration taps carry the rest, bin by bin."""
    g = cfg.geometry
    if not g.squinted:
        return 0.0
    raw = raw_range_axis_m(cfg)
    r_c = float(raw[len(raw) // 2])
    return r_c - r_c * math.sqrt(1.0 - g.squint_sin**2)  # R_c (1 - cos θ)


def range_axis_m(cfg: Config) -> np.ndarray:
    """Slant range of each output bin (float64[range_bins]): ``make_plan(cfg).range_m`` without
    building the filters.  Broadside the raw range of raw_range_axis_m; a squinted beam's bins
    are labelled with closest-approach ranges (zero-Doppler geometry), the raw ranges less
    squint_label_offset_m."""
    return raw_range_axis_m(cfg) - squint_label_offset_m(cfg)


def make_plan(cfg: Config) -> LensPlan:
    """Build the lens plan for a configuration (raises ValueError if the window cannot fit)."""
    wf, proc = cfg.waveform, cfg.processor
    bins = proc.range_bins
    S = wf.samples_per_shot
    if isinstance(wf, FMCWChirp):
        nfft, bin_start, bin_m = _fmcw_bins(cfg)
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
            range_axis_m(cfg),
        )
    if isinstance(wf, PulsedChirp):
        range_m = range_axis_m(cfg)  # first: it checks the range window fits
        # A fixed window keeps the partly held echoes: no lag may wrap (nfft >= S + P - 1).
        nfft = next_pow2(S + wf.pulse_samples if wf.window_start_s is not None else S)
        first, _ = _pulsed_lags(cfg)
        replica = pulsed_replica(wf)
        ref_spec = np.fft.fft(replica, nfft)
        f = np.fft.fftfreq(nfft, d=1.0 / wf.sample_rate_hz)
        taper = window_at(proc.range_window, (f + 0.5 * wf.bandwidth_hz) / wf.bandwidth_hz)
        spectrum = np.conj(ref_spec) * taper * secondary_range_compression(cfg, f)
        post = np.full(bins, 1.0 / (nfft * wf.pulse_samples), dtype=np.complex128)
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
            range_m,
        )
    raise TypeError(f"unsupported waveform {type(wf).__name__}")


def secondary_range_compression(cfg: Config, f_hz: np.ndarray) -> np.ndarray | float:
    """The lens's share of a squinted beam's range-azimuth coupling, for a CCD that reads the
    range in the azimuth spectrum (``range_migration_domain = "doppler"``): there an echo's
    range chirp has the rate K_m = K / (1 - K / K_src), K_src = 2 V² f0³ D³ / (c R f_η²),
    D = sqrt(1 - (λ f_η / 2V)²), and the lens takes out the extra phase -π f² / K_src at the
    Doppler centroid f_η = f_dc and the range centre (Cumming & Wong 2005, sec. 6.2, SRC in the
    range frequency domain): exp(-iπ f² / K_src).  1.0 otherwise: broadside K_src is infinite,
    and the time-domain taps read each pulse's own compressed line, which has no coupling."""
    g = cfg.geometry
    if not g.squinted or cfg.processor.range_migration_domain != "doppler":
        return 1.0
    centre = cfg.processor.range_centre_m or g.slant_range_m
    d = math.sqrt(1.0 - g.squint_sin**2)
    k_src = (
        2.0
        * g.speed_mps**2
        * g.carrier_hz**3
        * d**3
        / (C_M_PER_S * centre * g.doppler_centroid_hz**2)
    )
    cycles = np.mod(-0.5 * f_hz * f_hz / k_src, 1.0)
    return np.exp(2j * math.pi * cycles)


def dft(x: np.ndarray, sign: int, n: int, fft=np.fft) -> np.ndarray:
    """Unnormalised DFT along the last axis with exponent sign ±1 (fft: numpy.fft or scipy.fft)."""
    return fft.fft(x, n, axis=-1) if sign < 0 else fft.ifft(x, n, axis=-1) * n
