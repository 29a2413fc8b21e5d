"""Instrument models shared by the simulator and the processor: the channel map of a shot,
the time axis of oversampled auxiliary channels, and the HCN reference cell's line list.

A shot holds the main receive channel and, when the instrument has them, named auxiliary
channels (Zhao 2014 records four: the HCN cell, the reference interferometer and two target
receivers; the INO patents add reference-region receivers and spatial-amplitude-modulation
channels).  The names below are the keys of ``ShotBatch.aux``, of recordings and of the
correction stages; the simulator's effects produce them and the processor reads them, as an
instrument and its calibration sheet share one description.

HCN line list
-------------
A *synthetic* HCN-like comb, not certified line centres.  It is a rigid-rotor P/R band
ν(m) = ν0 + (B' + B'') m + (B' - B'') m², m = -J (P branch), J + 1 (R branch), with constants of
the order of those of the H¹³C¹⁴N 2ν3 band used for 1.53-1.56 µm wavelength references
(ν0 = 194.32 THz ≈ 1542.8 nm, B'' = 43.17 GHz, B' = 42.86 GHz) and Boltzmann strengths at 296 K;
P lines span 1543-1565 nm.  The absolute values are a documented stand-in (the NIST SRM 2519a
table could not be cited from here).  Crouch 2012, ch. 3 and Appendix A; Zhao 2014, channel 1.

Channel time axis
-----------------
A channel sampled q times faster than the main one (``oversampling`` q) holds q·S samples per
shot; sample m sits at (m - qS/2)/(q fs) from mid-chirp, so sample q·n is main sample n (the
simulator's FMCW time axis).
"""

from __future__ import annotations

import math

import numpy as np

from .params import FMCWChirp

# ---- the channel map ----------------------------------------------------------------------
RI_CHANNEL = "reference_interferometer"  # chirp linearization (Zhao channel 2, Crouch Fig. 6)
HCN_CHANNEL = "hcn_cell"  # absolute frequency reference (Zhao channel 1)
REFERENCE_CHANNELS = ("reference_rx1", "reference_rx2")  # INO phase-error patent, S1r and S2r
SAM_CHANNELS = ("sam_s1", "sam_s2")  # INO 3D patent: cosine mask, sine mask (S0 is the main one)
SECOND_RECEIVER = "rx1"  # interferometric SAL: the second receiver (Zhao channels 3-4)


def fmcw_waveform(config, who: str = "this stage") -> FMCWChirp:
    """The FMCW waveform of ``config``; ValueError naming ``who`` for any other waveform."""
    wf = config.waveform
    if not isinstance(wf, FMCWChirp):
        raise ValueError(f"{who} needs an FMCW waveform (dechirp on receive)")
    return wf


def channel_times_s(config, oversampling: int = 1) -> np.ndarray:
    """Sample times (s, from mid-chirp) of a channel sampled ``oversampling`` times faster.

    Sample m of a channel with M = oversampling·S samples is at (m - M/2) / (oversampling·fs),
    so sample q·n coincides with main-channel sample n (module docstring).
    """
    wf = fmcw_waveform(config, "an oversampled channel")
    q = int(oversampling)
    if q < 1:
        raise ValueError(f"oversampling must be an integer >= 1, got {oversampling!r}")
    m = q * wf.samples_per_shot
    return (np.arange(m) - 0.5 * m) / (q * wf.sample_rate_hz)


def default_delay_s(config, oversampling: int = 1) -> float:
    """Reference-interferometer delay whose beat sits at a quarter of the channel's sample rate.

    The beat frequency K τ_ri must stay inside (0, q·fs/2) for the phase to unwrap, with margin
    for the chirp-rate excursions of a non-linear chirp: τ_ri = q·fs / (4K).
    """
    wf = fmcw_waveform(config, "an oversampled channel")
    return 0.25 * oversampling * wf.sample_rate_hz / wf.chirp_rate_hz_per_s


def infer_oversampling(config, channel: np.ndarray, name: str) -> int:
    """The integer ratio of an auxiliary channel's length to the main shot length."""
    s = fmcw_waveform(config, f"channel {name!r}").samples_per_shot
    m = channel.shape[-1]
    if m % s or m < s:
        raise ValueError(f"channel {name!r} has {m} samples per shot, not a multiple of {s}")
    return m // s


# ---- the HCN reference cell ---------------------------------------------------------------
BAND_ORIGIN_HZ = 194.32e12
B_LOWER_HZ = 43.17e9
B_UPPER_HZ = 42.86e9
CELL_TEMPERATURE_K = 296.0
MAX_J = 45
DEFAULT_LINEWIDTH_HZ = 1.0e9  # Lorentzian FWHM, of the order of a low-pressure reference cell
_H_OVER_K = 6.62607015e-34 / 1.380649e-23  # s·K


def hcn_lines(lo_hz: float = -math.inf, hi_hz: float = math.inf):
    """Synthetic HCN-like line list (module docstring): (frequency_hz, relative strength ≤ 1).

    Strength ∝ |m| exp(-h B'' J''(J''+1) / kT), normalised to the strongest line of the band.
    Only lines with lo_hz ≤ f ≤ hi_hz are returned, sorted by frequency.
    """
    j = np.arange(MAX_J + 1)
    m = np.concatenate([-j[1:], j + 1])  # P(J), J ≥ 1 ; R(J), J ≥ 0
    j_lower = np.concatenate([j[1:], j])
    freq = BAND_ORIGIN_HZ + (B_UPPER_HZ + B_LOWER_HZ) * m + (B_UPPER_HZ - B_LOWER_HZ) * m**2
    boltzmann = np.exp(-_H_OVER_K * B_LOWER_HZ * j_lower * (j_lower + 1) / CELL_TEMPERATURE_K)
    strength = np.abs(m) * boltzmann
    strength = strength / strength.max()
    keep = (freq >= lo_hz) & (freq <= hi_hz)
    order = np.argsort(freq[keep])
    return freq[keep][order], strength[keep][order]


def hcn_absorbance(
    frequency_hz, linewidth_hz: float = DEFAULT_LINEWIDTH_HZ, peak_absorbance: float = 1.0
) -> np.ndarray:
    """Absorbance A(f) = a Σ_j s_j / (1 + (2(f - f_j)/γ)²) of the cell; transmission exp(-A).

    γ is the Lorentzian FWHM (``linewidth_hz``), a the peak absorbance of the strongest line.
    Lines farther than 10³ γ from every requested frequency are skipped (tails < 2.5e-7 a).
    """
    f = np.asarray(frequency_hz, np.float64)
    span = 1e3 * linewidth_hz
    lines, strength = hcn_lines(float(np.min(f)) - span, float(np.max(f)) + span)
    out = np.zeros(f.shape)
    for fj, sj in zip(lines, strength, strict=True):
        out += sj / (1.0 + (2.0 * (f - fj) / linewidth_hz) ** 2)
    return peak_absorbance * out
