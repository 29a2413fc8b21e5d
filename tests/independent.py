"""References that share no code with rtsar: a point target's echo, its range compression and
its azimuth correlation, from the papers' equations and rtsar's documented conventions alone.

Nothing of ``rtsar`` is imported here: every function reads the public fields of a Config
(``waveform``, ``geometry``, ``processor``; rtsar/params.py) and evaluates its formula directly
in float64 (complex128), so that a fault in rtsar's plan, mask or simulator cannot reach the
reference that checks it (STYLE habit 13).

Sources
-------
* Pulsed linear FM radar: Psaltis & Wagner 1981, eq. 1, s(t) = a(t) exp j(ω0 t + α t²) with
  α = πK; the echo of range R is s delayed by τ = 2R/c (Crouch eq. 3.1).  Range compression is the
  correlation in η of eq. 5 (the lens); azimuth compression the correlation in ξ of eq. 5, here
  with the exact range history R(t) = sqrt(R0² + (v t)²) instead of eq. 2's parabola.
* FMCW dechirp on receive: Crouch 2012, ch. 3, eqs. 3.2-3.4: the return mixed with a local
  oscillator (LO) delayed by τ_ref leaves exp i2π[-f0 Δτ - K Δτ t + K(τ² - τ_ref²)/2],
  Δτ = τ - τ_ref, evaluated here exactly (the residual video phase is kept).
* rtsar's conventions (docs/pages/reference/conventions.md; rtsar/params.py docstrings): complex
  baseband with carrier exp(+i2π f0 t), f0 = c/λ the chirp's centre frequency; a return from R
  compresses to the phase -4πR/λ (pulsed; an FMCW return to -4π(R - R_ref)/λ, see
  ``fmcw_echo``); ``echo[pulse, sample]``, ``line[pulse, range_bin]``, ``image[azimuth, range]``;
  pulse p at x_p = start + p d (stop-and-hop); image line j focused at start + (j + (N-1)/2) d;
  the pulsed receive window, with no ``window_start_s``, placed so that its middle lag sits at
  the range centre (and ``window_start_s``: the delay of the first sample from the pulse centre);
  the FMCW bins at c/2B (files.md, SICD row) from the LO's reference range.

Only the rectangular range and azimuth windows are modelled.  tests/test_independent_references.py
holds rtsar's lens, simulator and focused image to these.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

C_M_PER_S = 299_792_458.0  # exact (SI)


def _phasor(cycles):
    """exp(i2π·cycles), the cycles reduced mod 1 first (float64)."""
    return np.exp(2j * math.pi * np.mod(cycles, 1.0))


def _pulsed(cfg) -> bool:
    kind = cfg.waveform.kind
    if kind not in ("pulsed", "fmcw"):
        raise ValueError(f"unknown waveform kind {kind!r}")
    return kind == "pulsed"


def _rect_only(cfg) -> None:
    proc = cfg.processor
    if proc.range_window != "rect" or proc.azimuth_window != "rect":
        raise ValueError("the independent references model the rectangular windows only")


def range_centre_m(cfg) -> float:
    """The processor's range centre: its ``range_centre_m``, else the scene centre's range."""
    return cfg.processor.range_centre_m or cfg.geometry.slant_range_m


# ---- timing: when the receiver samples ---------------------------------------------------------


def window_open_s(cfg) -> float:
    """Pulsed: the two-way delay of a shot's first sample, counted from the START of the
    transmitted pulse (an echo of range R starts 2R/c after it).

    A fixed window (``window_start_s``, counted from the pulse centre): that delay plus Tp/2.
    Otherwise the window is centred on the range centre's echo (its middle lag at the range
    centre): the echo of R_c fills samples (S - P)/2 … (S + P)/2 - 1 of the S, so its middle
    arrives with the window's middle.  An odd S - P has no middle lag and is refused.
    """
    wf = cfg.waveform
    if wf.window_start_s is not None:
        return wf.window_start_s + 0.5 * wf.pulse_duration_s
    gap = wf.samples_per_shot - wf.pulse_samples
    if gap % 2:
        raise ValueError("S - P is odd: the receive window has no middle lag")
    return 2.0 * range_centre_m(cfg) / C_M_PER_S - 0.5 * gap / wf.sample_rate_hz


def fmcw_sample_times_s(cfg) -> np.ndarray:
    """FMCW: the time of each beat sample from the middle of the transmitted chirp (where its
    frequency is f0): the S samples span the chirp, t_n = (n - S/2)/fs."""
    wf = cfg.waveform
    return (np.arange(wf.samples_per_shot) - 0.5 * wf.samples_per_shot) / wf.sample_rate_hz


# ---- (a) the echo ------------------------------------------------------------------------------


def _snap(x: float) -> float:
    """x rounded to the nearest integer when float64 rounding alone keeps it off one."""
    r = round(x)
    return float(r) if abs(x - r) < 1e-7 else x


def pulsed_echo(cfg, range_m, amplitude=1.0) -> np.ndarray:
    """One shot of a pulsed radar from scatterers at ranges ``range_m`` (complex128[S]).

    Psaltis & Wagner eq. 1 heterodyned to baseband, delayed by τ = 2R/c: with t_n = τ_open + n/fs
    (``window_open_s``) and u = t_n - τ the time since the echo began,

        x[n] = a · exp(-i4πR/λ) · exp(iπK (u - Tp/2)²)   for 0 <= u < Tp, else 0,

    K the signed chirp rate (-B/Tp for a down-chirp), the chirp centred on the pulse's middle.
    """
    wf, lam = cfg.waveform, cfg.geometry.wavelength_m
    fs, tp = wf.sample_rate_hz, wf.pulse_duration_s
    k = -wf.bandwidth_hz / tp if wf.down_chirp else wf.bandwidth_hz / tp
    t_open = window_open_s(cfg)
    n = np.arange(wf.samples_per_shot)
    out = np.zeros(wf.samples_per_shot, np.complex128)
    ranges = np.atleast_1d(np.asarray(range_m, np.float64))
    gains = np.broadcast_to(np.asarray(amplitude, np.complex128), ranges.shape)
    length = _snap(tp * fs)
    for r, a in zip(ranges, gains, strict=True):
        begin = _snap((2.0 * r / C_M_PER_S - t_open) * fs)  # sample at which the echo starts
        inside = (n >= begin) & (n < begin + length)
        u = (n[inside] - begin) / fs  # time since the echo began
        cycles = -2.0 * r / lam + 0.5 * k * (u - 0.5 * tp) ** 2
        out[inside] += a * _phasor(cycles)
    return out


def fmcw_echo(cfg, range_m, amplitude=1.0) -> np.ndarray:
    """One dechirped FMCW shot from scatterers at ranges ``range_m`` (complex128[S]).

    Crouch eqs. 3.2-3.3 in rtsar's sign (carrier exp(+i2π f0 t)): the chirp is
    exp i2π(f0 t + K t²/2), the return that chirp delayed by τ = 2R/c, the LO that chirp delayed
    by τ_ref = 2 R_ref/c; mixing keeps return × conj(LO) (eq. 3.4, whose phase falls with
    range as rtsar's conventions ask):

        x[n] = a · exp i2π[-f0 Δτ - K Δτ t_n + K (τ² - τ_ref²)/2],   Δτ = τ - τ_ref,

    t_n from ``fmcw_sample_times_s``.  The term f0 Δτ is formed as 2(R - R_ref)/λ.  The phase a
    return compresses to is therefore -4π(R - R_ref)/λ (plus the residual video phase): the LO
    path's own carrier phase 4π R_ref/λ is not in it (Crouch's τ is the delay relative to the
    LO path), where conventions.md writes -4πR/λ for both waveforms.
    """
    wf, lam = cfg.waveform, cfg.geometry.wavelength_m
    k = wf.bandwidth_hz / wf.chirp_duration_s
    t = fmcw_sample_times_s(cfg)
    r_ref = wf.reference_range_m
    tau_ref = 2.0 * r_ref / C_M_PER_S
    out = np.zeros(wf.samples_per_shot, np.complex128)
    ranges = np.atleast_1d(np.asarray(range_m, np.float64))
    gains = np.broadcast_to(np.asarray(amplitude, np.complex128), ranges.shape)
    for r, a in zip(ranges, gains, strict=True):
        tau = 2.0 * r / C_M_PER_S
        dtau = 2.0 * (r - r_ref) / C_M_PER_S
        constant = -2.0 * (r - r_ref) / lam + 0.5 * k * dtau * (tau + tau_ref)
        out += a * _phasor(constant - k * dtau * t)
    return out


def echo(cfg, range_m, amplitude=1.0) -> np.ndarray:
    """One shot (complex128[S]) of either waveform."""
    if _pulsed(cfg):
        return pulsed_echo(cfg, range_m, amplitude)
    return fmcw_echo(cfg, range_m, amplitude)


def platform_m(start_m: float, pulses: int, step_m: float) -> np.ndarray:
    """Along-track position of each pulse, x_p = start + p d (stop-and-hop)."""
    return start_m + np.arange(pulses) * step_m


def point_shots(cfg, along_track_m, slant_range_m, start_m, pulses, amplitude=1.0):
    """Shots[pulse, sample] (complex128) of one point scatterer at closest-approach range R0 and
    along-track u: pulse p sees it at R_p = sqrt(R0² + (x_p - u)²), i.e. R(t) = sqrt(R0² + (v t)²)
    with v t = x_p - u (broadside, straight track, no antenna pattern)."""
    x = platform_m(start_m, pulses, cfg.geometry.along_track_step_m)
    ranges = np.hypot(slant_range_m, x - along_track_m)
    return np.stack([echo(cfg, r, amplitude) for r in ranges])


# ---- (b) the lens: range compression -----------------------------------------------------------


def range_axis_m(cfg) -> np.ndarray:
    """The slant range of each output bin, from the documented rules (float64[range_bins]).

    Pulsed: bins one sample apart, c/(2 fs), the middle bin (index bins // 2) at the range centre
    (``window_start_s`` None).  FMCW: the beat frequency of bin k is k fs/(S·o) (a DFT of the S
    beat samples, zero-padded o = range_oversampling times), i.e. the range R_ref + k c fs/(2KSo),
    which is c/2B per bin at o = 1; the middle bin is the one nearest the range centre.
    """
    wf, proc = cfg.waveform, cfg.processor
    j = np.arange(proc.range_bins) - proc.range_bins // 2
    if _pulsed(cfg):
        if wf.window_start_s is not None:
            raise ValueError("a fixed receive window's bins are not modelled here")
        return range_centre_m(cfg) + j * C_M_PER_S / (2.0 * wf.sample_rate_hz)
    k = wf.bandwidth_hz / wf.chirp_duration_s
    step = C_M_PER_S * wf.sample_rate_hz / (2.0 * k * wf.samples_per_shot * proc.range_oversampling)
    middle = round((range_centre_m(cfg) - wf.reference_range_m) / step)
    return wf.reference_range_m + (middle + j) * step


def pulsed_compress_at(cfg, shots, range_m) -> np.ndarray:
    """Matched filter of a pulsed shot over the chirp band, at any ranges (complex128).

    Psaltis & Wagner eq. 5, the η correlation: with the replica r[m] = exp(iπK(m/fs - Tp/2)²),
    m < P, the correlation at whole lags d (the echo starting at sample d),

        c[d] = (1/P) Σ_m x[d + m] conj(r[m]),      d = -(P-1) … S-1 (every overlap),

    is kept to the chirp's band |f| <= B/2 (the lens's aperture): y(ℓ) = Σ_d c[d] (B/fs)
    sinc(B (ℓ - d)/fs), at the lag ℓ = (2R/c - τ_open) fs of each range, whole or not.  A
    unit-amplitude echo gives c = 1 at its lag; the band keeps about 0.98 of it.
    """
    _rect_only(cfg)
    wf = cfg.waveform
    fs, tp, b = wf.sample_rate_hz, wf.pulse_duration_s, wf.bandwidth_hz
    s, p = wf.samples_per_shot, wf.pulse_samples
    k = -b / tp if wf.down_chirp else b / tp
    u = np.arange(p) / fs - 0.5 * tp
    replica = _phasor(0.5 * k * u * u)
    x = np.atleast_2d(np.asarray(shots, np.complex128))
    padded = np.zeros((x.shape[0], s + 2 * (p - 1)), np.complex128)
    padded[:, p - 1 : p - 1 + s] = x
    corr = sliding_window_view(padded, p, axis=1) @ np.conj(replica) / p  # [pulse, S + P - 1]
    lags = np.arange(-(p - 1), s)
    ell = (2.0 * np.asarray(range_m, np.float64) / C_M_PER_S - window_open_s(cfg)) * fs
    band = (b / fs) * np.sinc(b * (ell[:, None] - lags[None, :]) / fs)
    return corr @ band.T


def fmcw_compress_at(cfg, shots, range_m) -> np.ndarray:
    """Dechirp lens (Crouch eq. 3.7): the DFT of the S beat samples at the beat frequency
    f = 2K(R - R_ref)/c of each range, y(R) = (1/S) Σ_n x[n] exp(+i2π f t_n), t_n from the
    chirp's middle; a return at R gives exactly its phase at t = 0 there (complex128)."""
    _rect_only(cfg)
    wf = cfg.waveform
    k = wf.bandwidth_hz / wf.chirp_duration_s
    f = 2.0 * k * (np.asarray(range_m, np.float64) - wf.reference_range_m) / C_M_PER_S
    kernel = _phasor(f[:, None] * fmcw_sample_times_s(cfg)[None, :])
    x = np.atleast_2d(np.asarray(shots, np.complex128))
    return x @ kernel.T / wf.samples_per_shot


def compress_at(cfg, shots, range_m) -> np.ndarray:
    """Range-compressed lines[pulse, range] (complex128) at the given ranges, either waveform."""
    if _pulsed(cfg):
        return pulsed_compress_at(cfg, shots, range_m)
    return fmcw_compress_at(cfg, shots, range_m)


def compress(cfg, shots) -> np.ndarray:
    """Range-compressed lines[pulse, bin] on ``range_axis_m(cfg)`` (complex128)."""
    return compress_at(cfg, shots, range_axis_m(cfg))


# ---- (c) the azimuth correlation ---------------------------------------------------------------


def azimuth_axis_m(cfg, start_m: float, lines: int) -> np.ndarray:
    """Along-track position of image lines 0 … lines-1: line j, the one whose N-pulse aperture
    ends with pulse j + N - 1, is focused at the aperture centre start + (j + (N-1)/2) d."""
    n, d = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    return start_m + (np.arange(lines) + 0.5 * (n - 1)) * d


def focus(cfg, lines, range_m=None) -> np.ndarray:
    """Azimuth correlation of range-compressed lines[pulse, bin] → image[line, bin] (complex128).

    Psaltis & Wagner eq. 5, the ξ correlation, with the exact range history: image line j sums
    the N pulses of its aperture, p = j … j+N-1, each at the offset v t = x_p - X_j =
    (k - (N-1)/2) d from the line's position X_j; a scatterer at closest approach R seen from
    there lies at R(t) = sqrt(R² + (v t)²), so its line carries exp(-i4πR(t)/λ) and

        image[j, r] = (1/N) Σ_k line[j + k, r] · exp(+i4π (R(t_k) - R)/λ),   R = range_m[r],

    a unit-amplitude history focusing to a unit peak with the phase its line had at closest
    approach.  Each column reads its own range bin (no migration across bins, as rtsar's CCD with
    range_migration_taps = 0 and Psaltis's separable eq. 5).
    """
    _rect_only(cfg)
    n, lam = cfg.processor.aperture_pulses, cfg.geometry.wavelength_m
    r = range_axis_m(cfg) if range_m is None else np.asarray(range_m, np.float64)
    vt = (np.arange(n) - 0.5 * (n - 1)) * cfg.geometry.along_track_step_m
    excess_m = np.hypot(r[None, :], vt[:, None]) - r[None, :]  # float64: ~1e-16 of R, ample
    kernel = _phasor(2.0 * excess_m / lam) / n  # [k, bin]
    x = np.asarray(lines, np.complex128)
    if x.shape[0] < n:
        return np.zeros((0, x.shape[1]), np.complex128)
    windows = sliding_window_view(x, n, axis=0)  # [line, bin, k]
    return np.einsum("jrk,kr->jr", windows, kernel)


# ---- measuring a response ----------------------------------------------------------------------


def peak_and_width(cut, upsample: int = 64) -> tuple[float, float]:
    """(peak position, -3 dB width), both in samples of ``cut`` (a complex 1-D response), by
    band-limited interpolation: the cut's DFT zero-padded ``upsample`` times, the peak refined
    by a parabola through the three finest samples around it, the half-power points found by
    linear interpolation between the fine samples that straddle them."""
    x = np.asarray(cut, np.complex128)
    n, m = x.size, x.size * upsample
    spectrum = np.fft.fft(x)
    padded = np.zeros(m, np.complex128)
    half = n // 2
    padded[:half] = spectrum[:half]
    padded[m - (n - half) :] = spectrum[half:]
    fine = np.fft.ifft(padded) * upsample  # fine[i] is the cut at position i / upsample
    power = np.abs(fine) ** 2
    i = int(np.argmax(power))
    a, b, c = power[i - 1], power[i], power[(i + 1) % m]
    offset = 0.5 * (a - c) / (a - 2.0 * b + c)
    level = 0.5 * b

    def crossing(step: int) -> float:
        j = i
        while power[j % m] > level:
            j += step
        inner, outer = power[(j - step) % m], power[j % m]
        return (j - step) + step * (inner - level) / (inner - outer)

    width = (crossing(+1) - crossing(-1)) / upsample
    return (i + offset) / upsample, width
