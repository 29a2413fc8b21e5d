"""Backprojection: the exact float64 reference that defines a spotlight image's accuracy.

For every pixel p and shot n the exact path (Crouch eqs. 9.2a,b: no plane wave, no expansion)
gives the echo phase model c0 + f·t of rtsar.spot.geometry.echo_cycles; the image is the matched
filter of every sample against it:

    I(p) = Σ_n Σ_m w[n, m] D[n, m] exp(-2πi (c0(p, n) + f(p, n) t_m)) / Σ w

``backproject_exact`` evaluates that sum literally ([pixels, samples] phases per shot; slow, the
definition).  ``backproject`` is the usual fast form: each shot range-compressed once by a
zero-padded FFT (``upsample`` times), its profile read at the pixel's beat frequency by linear
interpolation and multiplied by the exact carrier phase; its error against the exact sum falls as
1/upsample² (measured in the tests).  Both accumulate shot by shot, so a stream can add shots as
they arrive.  ``weights`` (e.g. PolarFormatPlan.polar_weights) restricts the sum to the same
spectral aperture as a PFA image, so that the two differ only by PFA's approximations.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as sfft

from ..params import Config
from .geometry import SpotlightGeometry, echo_cycles, sample_times_s

PIXEL_CHUNK = 4096
BLOCK_ELEMENTS = 1 << 21  # phases per vectorised block (32 MiB of complex128)


def backproject_exact(
    data: np.ndarray,
    config: Config,
    geometry: SpotlightGeometry,
    points_m: np.ndarray,
    channel: str = "main",
    weights: np.ndarray | None = None,
    start: int = 0,
) -> np.ndarray:
    """The matched-filter sum at scene points [..., 3] (complex128, shape points[..., 0])."""
    wf = config.waveform
    lam = config.geometry.wavelength_m
    shape = np.shape(points_m)[:-1]
    pts = np.reshape(np.asarray(points_m, np.float64), (-1, 3))
    t = sample_times_s(wf)
    lo = geometry.lo_range_m(wf, channel)
    d = np.asarray(data, np.complex128)
    w = np.ones(d.shape) if weights is None else np.broadcast_to(weights, d.shape)
    rows = d * w
    out = np.zeros(len(pts), np.complex128)
    shots = max(1, BLOCK_ELEMENTS // max(1, len(pts) * len(t)))
    for c in range(0, len(pts), PIXEL_CHUNK):
        p = pts[c : c + PIXEL_CHUNK]
        for n0 in range(0, len(d), shots):
            n = np.arange(n0, min(n0 + shots, len(d)))
            c0, f = echo_cycles(geometry.half_path_m(p, start + n, channel), lo, wf, lam)
            cycles = np.mod(c0[:, :, None] + f[:, :, None] * t[None, None, :], 1.0)
            out[c : c + PIXEL_CHUNK] += np.einsum(
                "npm,nm->p", np.exp(-2j * math.pi * cycles), rows[n]
            )
    total = float(np.sum(w))
    return (out / total).reshape(shape)


def backproject(
    data: np.ndarray,
    config: Config,
    geometry: SpotlightGeometry,
    points_m: np.ndarray,
    channel: str = "main",
    weights: np.ndarray | None = None,
    start: int = 0,
    upsample: int = 16,
) -> np.ndarray:
    """Fast backprojection: zero-padded range FFT, linear interpolation, exact carrier phase."""
    if not (isinstance(upsample, int) and upsample >= 1):
        raise ValueError(f"upsample must be an integer >= 1, got {upsample!r}")
    wf = config.waveform
    lam = config.geometry.wavelength_m
    shape = np.shape(points_m)[:-1]
    pts = np.reshape(np.asarray(points_m, np.float64), (-1, 3))
    m = wf.samples_per_shot
    fs = wf.sample_rate_hz
    t = sample_times_s(wf)
    lo = geometry.lo_range_m(wf, channel)
    length = m * upsample
    out = np.zeros(len(pts), np.complex128)
    d = np.asarray(data, np.complex128)
    total = 0.0
    for i, shot in enumerate(d):
        n = start + i
        w = np.ones(m) if weights is None else np.broadcast_to(weights[i], (m,))
        total += float(np.sum(w))
        # profile(ν) = Σ_m x_m e^{-2πi ν t_m} on ν = q fs/length: an FFT with t_0 = -M/(2fs).
        prof = sfft.fft(shot * w, length) * np.exp(
            -2j * math.pi * np.mod(np.arange(length) / length * t[0] * fs, 1.0)
        )
        r = geometry.half_path_m(pts, [n], channel)[0]
        c0, f = echo_cycles(r, lo, wf, lam)
        q = np.mod(f / fs * length, length)  # matched filter e^{-2πi f t}: read profile at ν = f
        q0 = np.floor(q).astype(np.int64)
        frac = q - q0
        val = prof[q0 % length] * (1 - frac) + prof[(q0 + 1) % length] * frac
        out += val * np.exp(-2j * math.pi * c0)
    return (out / total).reshape(shape)
