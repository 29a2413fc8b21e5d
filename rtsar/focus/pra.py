"""Phase-to-retro (Crouch 2012, ch. 4 "Phase to Retro Algorithm", Appendix A): a stream stage.

A cooperative retro-reflector is the brightest scatterer of its range cells.  In every
range-compressed line the retro's peak is found and the phase of the shot is adjusted so that
the phase at the retro follows what an error-free shot would give; Crouch's script makes that
phase *constant* and then focuses by a plain FFT, but the shifting CCD applies the exact azimuth
matched filter, so here the retro phase is set to its expected history

    ψ(n) = -4π/λ · sqrt(R_r² + (x_n - x_r)²)                       (rtsar.params convention)

with (x_r, R_r) the retro's surveyed along-track position and closest-approach range and x_n the
nominal platform position of pulse n.  The estimated phase error of pulse n (the phase added to
the shot, piston-like: one value per shot, Crouch eq. 4.12) is

    ε(n) = arg( Σ_{k=l-1}^{l+1} line_n[k] ) - ψ(n),   l = argmax_k |line_n[k]| in the search window

(the three bins around the peak, as Crouch's script keeps), and the stage outputs
line_n · exp(-i ε(n)).  A wrong x_r shifts the image (a linear residual), a wrong R_r adds a
negligible quadratic.  Where the retro is not found (peak-to-median power in the window below
``min_contrast``, or a non-finite line) the last good ε is held (0 before the first) and the
pulse is counted in ``shots_not_corrected``; non-finite lines leave as zeros (``nonfinite_lines``).

Place: between the AO lens and the shifting CCD (range-compressed lines).  Causal, per pulse, no
look-ahead; state = one float and counters.  ``phase_to_retro_reference`` is the float64
per-pulse reference the stage is tested against.
"""

from __future__ import annotations

import math

import numpy as np

from ..lens.plan import range_axis_m
from ..params import Config
from ..samples import zero_nonfinite_rows
from .stage import CorrectionStage


def retro_phase_history_rad(
    config: Config,
    pulses,
    retro_along_track_m: float,
    retro_range_m: float,
    start_along_track_m: float = 0.0,
) -> np.ndarray:
    """ψ(n) mod 2π: expected phase of the retro in line n (exact range history, float64).

    -4π/λ sqrt(R² + x²) = -4π/λ [R + x²/(sqrt(R² + x²) + R)]; the constant R term is dropped
    (a constant phase does not matter) so no large phase is ever formed.
    """
    g = config.geometry
    x = start_along_track_m + np.asarray(pulses, np.float64) * g.along_track_step_m
    off = x - retro_along_track_m
    excess = off * off / (np.sqrt(retro_range_m**2 + off * off) + retro_range_m)
    cycles = np.mod(-2.0 * excess / g.wavelength_m, 1.0)
    return 2.0 * math.pi * cycles


def _window(range_m: np.ndarray, retro_range_m: float, radius_m: float) -> slice:
    inside = np.flatnonzero(np.abs(range_m - retro_range_m) <= radius_m)
    if inside.size < 5:
        raise ValueError(
            f"the retro search window ({retro_range_m:g} ± {radius_m:g} m) holds {inside.size} "
            "range bins; it needs at least 5 (widen pra:search_radius_m, or check the retro's "
            "range, pra:range_m, against the swath)"
        )
    return slice(int(inside[0]), int(inside[-1]) + 1)


def _settings(config, range_m, retro_range_m, search_radius_m, min_contrast):
    range_m = range_axis_m(config) if range_m is None else np.asarray(range_m, np.float64)
    if not (math.isfinite(retro_range_m) and retro_range_m > 0):
        raise ValueError("retro_range_m must be finite and > 0")
    if search_radius_m is None:  # a few resolution cells plus the retro's range migration
        search_radius_m = 4.0 * config.waveform.range_resolution_m + config.range_curvature_m
    if not (math.isfinite(min_contrast) and min_contrast >= 1):
        raise ValueError("min_contrast must be >= 1")
    return range_m, _window(range_m, retro_range_m, search_radius_m)


def phase_to_retro_reference(
    lines: np.ndarray,
    config: Config,
    retro_along_track_m: float,
    retro_range_m: float,
    start_along_track_m: float = 0.0,
    range_m: np.ndarray | None = None,
    search_radius_m: float | None = None,
    min_contrast: float = 10.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Float64 batch reference, pulse by pulse: → (corrected lines complex128, ε(n) rad, found).

    ``lines[pulse, range_bin]`` from pulse 0 of a scan starting at ``start_along_track_m``;
    ``range_m`` the bins' slant ranges (default: the AO lens plan of ``config``).
    """
    x = np.asarray(lines, np.complex128)
    _, win = _settings(config, range_m, retro_range_m, search_radius_m, min_contrast)
    psi = retro_phase_history_rad(
        config, np.arange(len(x)), retro_along_track_m, retro_range_m, start_along_track_m
    )
    eps = np.zeros(len(x))
    found = np.zeros(len(x), bool)
    held = 0.0
    out = np.zeros_like(x)
    for n, line in enumerate(x):
        if not np.all(np.isfinite(line)):
            eps[n] = held
            continue  # leaves as zeros
        w = line[win]
        power = np.abs(w) ** 2
        l_peak = int(np.argmax(power))
        median = float(np.median(power))
        if power[l_peak] > 0 and power[l_peak] >= min_contrast * median:
            z = np.sum(w[max(l_peak - 1, 0) : l_peak + 2])
            held = float(np.angle(z * np.exp(-1j * psi[n])))
            found[n] = True
        eps[n] = held
        out[n] = line * np.exp(-1j * held)
    return out, eps, found


class PhaseToRetro(CorrectionStage):
    """Phase-to-retro correction in the stream (after the AO lens, before the shifting CCD).

    ``process(lines)`` takes a micro-batch lines[pulse, range_bin] in pulse order and returns
    the corrected lines (same dtype); ``last_phase_error_rad`` holds ε(n) of that batch.
    Counters: ``pulses_in``, ``shots_not_corrected`` (retro not found: previous ε held),
    ``nonfinite_lines`` (zeroed).  Memory: O(1) between batches.
    """

    domain = "lines"
    counter_names = ("pulses_in", "shots_not_corrected", "nonfinite_lines")

    def __init__(
        self,
        config: Config,
        retro_along_track_m: float,
        retro_range_m: float,
        start_along_track_m: float = 0.0,
        range_m: np.ndarray | None = None,
        search_radius_m: float | None = None,
        min_contrast: float = 10.0,
    ):
        self.config = config
        self.retro_along_track_m = float(retro_along_track_m)
        self.retro_range_m = float(retro_range_m)
        self.start_along_track_m = float(start_along_track_m)
        self.range_m, self._win = _settings(
            config, range_m, self.retro_range_m, search_radius_m, min_contrast
        )
        self.min_contrast = float(min_contrast)
        self.pulses_in = 0
        self.shots_not_corrected = 0
        self.nonfinite_lines = 0
        self._held = 0.0
        self.last_phase_error_rad = np.zeros(0)

    def process(self, lines: np.ndarray, aux: dict | None = None) -> np.ndarray:
        """Correct a micro-batch of range-compressed lines; ``aux`` is ignored."""
        lines = np.asarray(lines)
        if lines.ndim != 2 or lines.shape[1] != len(self.range_m):
            raise ValueError(f"lines must be [pulses, {len(self.range_m)}], got {lines.shape}")
        if not np.iscomplexobj(lines):
            raise ValueError("lines must be complex")
        count = len(lines)
        lines, bad = zero_nonfinite_rows(lines)
        self.nonfinite_lines += int(bad.sum())
        w = lines[:, self._win].astype(np.complex128)
        power = w.real**2 + w.imag**2
        peak = np.argmax(power, axis=1) if count else np.zeros(0, int)
        rows = np.arange(count)
        peak_power = power[rows, peak]
        found = ~bad & (peak_power > 0)
        found &= peak_power >= self.min_contrast * np.median(power, axis=1)
        # Sum of the bins peak-1 .. peak+1 (clipped to the window).
        z = w[rows, peak].copy()
        left, right = peak > 0, peak < w.shape[1] - 1
        z[left] += w[rows[left], peak[left] - 1]
        z[right] += w[rows[right], peak[right] + 1]
        psi = retro_phase_history_rad(
            self.config,
            self.pulses_in + rows,
            self.retro_along_track_m,
            self.retro_range_m,
            self.start_along_track_m,
        )
        measured = np.angle(z * np.exp(-1j * psi))
        # Hold the last good estimate across misses (forward fill, carried between batches).
        last_good = np.maximum.accumulate(np.where(found, rows, -1)) if count else rows
        eps = np.where(last_good >= 0, measured[np.maximum(last_good, 0)], self._held)
        if count:
            self._held = float(eps[-1])
        self.pulses_in += count
        self.shots_not_corrected += int(count - found.sum())
        self.last_phase_error_rad = eps
        dtype = np.complex64 if lines.dtype == np.complex64 else np.complex128
        phasor = np.exp(-1j * eps).astype(dtype)  # eps is in (-π, π]: reduced before the cast
        return lines.astype(dtype, copy=False) * phasor[:, None]

    def flush(self) -> np.ndarray:
        """Nothing is held back: per-pulse stage."""
        return np.zeros((0, len(self.range_m)), np.complex64)
