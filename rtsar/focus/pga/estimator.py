"""Phase gradient autofocus (PGA): Crouch's estimator on one block of deramped pulses.

The error: a phase φ(p) common to every range bin of pulse p (piston, Crouch eq. 4.12).  Pulse p
is taken to carry exp(+iφ(p)); the correction multiplies it by exp(-iφ̂(p)).  Constant and linear
phase are invisible to PGA (a constant changes nothing, a slope only shifts the image), so every
block estimate has both removed and PGA never adds one of its own (rtsar.focus.pga.blocks only
continues the previous blocks' phase across the overlap).

Why blocks of deramped pulses.  Crouch's PGA (ch. 4, eqs. 4.14-4.17; App. A ``PGAforSAL``) works
on an image one DFT away from the range-compressed shots (his linearised Fourier kernel, "a SAL
scene that has already had its range migration fixed"), so the error of shot m is a phase of DFT
sample m.  A strip-map CCD has no such image: it correlates with a range-dependent chirp and each
line integrates its own N pulses.  The faithful equivalent is to deramp a block of P pulses with
the conjugate history of a scatterer at the block centre (Psaltis & Wagner eq. 2, exact range):

    exp(+i 4π/λ · ΔR_p),   ΔR_p = sqrt(R_r² + x_p²) - R_r,   x_p = (p - (P-1)/2) d.        (1)

A scatterer u along track from the block centre becomes the tone exp(i 4π u x_p/(λR))·exp(iφ(p)):
Crouch's kernel E_n ∝ exp[-iφ(n)] Σ_j exp(-iμu_j), and the DFT across the block is his image.

Range migration inside a block.  The same ΔR_p moves the echo in range: at crouch-sal (d = 10 µm,
R = 1.5 m, cells of 50 µm) by 0.7 cell over N = 2048 pulses and 2.8 cells over 2N.  A per-bin
history is then cut into pieces, each bin centres its own piece (eq. 4.14) and nothing ties the
pieces' frequencies together: PGA converges to a sharp but wrong, piecewise-linear phase (measured:
hundreds of radians rms off over a 2N block).  Where the block-edge ΔR exceeds
``migration_cells`` of a range cell, each pulse is first moved back by ΔR_p (a sub-cell shift: a
linear phase across the range DFT of the line, zero-padded ×2 so nothing wraps), so a point at the
block centre stays in one bin; one u from it still walks u·x/R, so Crouch's rows become coherent
sums of 2w+1 neighbouring bins (``row_half_width``) that hold a point inside the block's own
extent for the whole block (the range-compressed peak has one phase across its main lobe, so the
sum keeps it).  Crouch's steps then apply unchanged:

* rows with a bright point (his rows ``lr:ur``): the brightest ≤ ``max_range_bins`` whose energy
  is ``bright_threshold_db`` above the median row's in each of ``segments`` stretches, none
  under ``min_row_fill`` of the fullest (the point stays in the row);
* circularly shift each bin's brightest pixel to the centre, keep a window W ξ^-q (eq. 4.14,
  ξ = 1.1, W = the block); inverse DFT (eq. 4.15); phasor sum of the phase differences over the
  bins (eq. 4.16); integrate from φ(0) = 0 (eq. 4.17); remove the slope (as ``PGAforSAL``);
* iterate until the step's peak to peak is below ``stop_rad`` (Crouch π/10; 0.01 here), the
  window falls below ``min_window_bins``, or ``max_iterations``.

Rows of 2w+1 bins carry 2w+1 bins of receiver noise, and the first, whole-window iteration
writes that noise into φ at every frequency the later, narrower windows never revisit (measured
at crouch-sal, -10 dB per sample: 0.25 rad rms, nearly white).  So where the migration is
handled, a second pass (``follow_walk``) starts from the first's φ with the whole window again,
on narrow rows that follow each bright point's walk (rtsar.focus.pga.migration.walking_rows: its
u read from the focused block image, 3 bins' noise): 0.10 rad there, the white part of the
injected error.  It runs only where the wide rows' noise matters (``walk_noise_rad``): at high
SNR the wide rows' estimate is the better one (a cold review measured 0.090 against 0.110 rad
at +20 dB).  The migration handling itself is rtsar.focus.pga.migration.

Returns fixed to the platform (leakage, an internal reflection) are steady; deramped they look
like a defocused point and PGA would fit their deramp chirp (a cold review: 68-184 rad rms off
with one 3× the brightest point).  Where a point's history sweeps over ``FIXED_MIN_CYCLES``
cycles in a block (180 at crouch-sal), each bin's mean over the block, which is then all of a
steady return and ≲ 1/√(2·cycles) of a point's history, is removed before estimating.

Safety (PGA must never harm a focused image; Crouch: it cannot focus scenes without prominent
points).  The block's estimate is not used, and its phase is zero, when: its first step is
already below ``focused_rad`` = π/10 ("nothing_to_correct": the bright points are focused); no
row stands out ("no_bright_points"); or the corrected block image is not sharper by
``min_sharpness_gain`` = 50 % (Σ|G|⁴/(Σ|G|²)², "not_sharper": at crouch-sal a focused block
gains ≤ 7 % from PGA's own noise, an error-free zhao-insal speckle block with one bright row
36 %, a block under hundreds of radians 100× or more).  No step can
make a NaN (empty sums give angle(0) = 0).  INO phase-error patent: remove the bulk with the
reference region first, PGA for the residual.

The block layout of the stream is rtsar.focus.pga.blocks; the stage rtsar.focus.pga.stream;
the float64 reference on a recording rtsar.focus.pga.reference.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...lens.plan import range_axis_m
from ...params import Config
from ...phase import phasor
from .migration import curvature_m, migration_corrected, row_half_width, rows, walking_rows

#: Why a block's iterations stopped (the first three: estimate used) or why it has no estimate.
ESTIMATED = ("converged", "window_floor", "max_iterations")
#: Blocks left as they came: already focused, or nothing PGA can estimate from.
NOTHING_TO_CORRECT = ("nothing_to_correct",)
COULD_NOT_ESTIMATE = ("no_bright_points", "not_sharper", "short_block")
REASONS = (*ESTIMATED, *NOTHING_TO_CORRECT, *COULD_NOT_ESTIMATE)


@dataclass(frozen=True)
class PGASettings:
    """PGA knobs (Crouch ch. 4); ``None`` sizes follow the processor's aperture N.

    block_pulses, hop_pulses  P (default 2N, or 1.1 beam footprints in pulses where shorter,
                        ≥ max(8, N): the range walk inside a block grows as P²) and H
                        (default P/2, ≤ P)
    xi, initial_window_bins, min_window_bins  eq. 4.14: W_q = W/ξ^q (Crouch 1.1), W default P
                        (the whole block: the fastest errors); stop when W_q < min_window_bins
    max_iterations, stop_rad  at most so many iterations; converged when the step's peak to
                        peak is below stop_rad (0.01: finer than Crouch's π/10, which leaves
                        ~0.3 rad rms at crouch-sal)
    focused_rad         a first step below this peak to peak (Crouch's π/10): the block is
                        already focused, "nothing_to_correct"
    max_range_bins, bright_threshold_db, segments  the brightest ≤ max_range_bins rows whose
                        energy is bright_threshold_db above the median row's in every one of
                        ``segments`` stretches of the block, and in none under min_row_fill
                        of the fullest stretch's, take part in eq. 4.16
    migration_cells     range migration is handled (curvature removed, rows of 2w+1 bins) when
                        the block-edge curvature ΔR exceeds this fraction of a range cell
    follow_walk, walk_noise_rad  then, where the 2w+1-bin rows' own noise puts more than
                        walk_noise_rad rms into the estimate (√(N/2S) of the brightest row,
                        N the median row's energy, S its own above it), estimate again on
                        narrow rows that follow each bright point's range walk
                        (``walking_rows``: 2w+1 bins' noise down to 3; at high SNR the wide
                        rows' estimate is the better one); follow_walk False (or 0 in
                        ``--correct pga:follow_walk=0``): never
    min_sharpness_gain  an estimate is used only if it sharpens the block image by this fraction
    min_pulses          a shorter block (end of a short stream) is not estimated (min(P, N))
    doppler_anchor      set the slope PGA cannot see from the clutter's Doppler centroid
                        (rtsar.focus.pga.doppler); False (or 0, as in ``--correct
                        pga:doppler_anchor=0``): the error's own slope stays
    doppler_gain        the first anchored block takes its whole residual centroid slope,
                        later ones this share (a tracking loop over ~1/gain blocks)
    min_doppler_coherence  the clutter's lag-one coherence below which its centroid is not
                        used (also below half the antenna's expected ρ(1))
    """

    block_pulses: int | None = None
    hop_pulses: int | None = None
    xi: float = 1.1
    initial_window_bins: int | None = None
    min_window_bins: int = 8
    max_iterations: int = 30
    stop_rad: float = 0.01
    focused_rad: float = math.pi / 10
    max_range_bins: int = 32
    bright_threshold_db: float = 6.0
    segments: int = 4
    min_row_fill: float = 0.1
    migration_cells: float = 0.1
    follow_walk: bool = True
    walk_noise_rad: float = 0.1
    min_sharpness_gain: float = 0.5
    min_pulses: int | None = None
    doppler_anchor: bool = True
    doppler_gain: float = 0.1
    min_doppler_coherence: float = 0.05

    def __post_init__(self):
        def integer(v, allow_none):
            ok = isinstance(v, int) and not isinstance(v, bool) and v >= 1
            return ok or (allow_none and v is None)

        for name in ("block_pulses", "hop_pulses", "initial_window_bins", "min_pulses"):
            if not integer(getattr(self, name), True):
                raise ValueError(f"PGASettings.{name} must be an integer >= 1 or None")
        for name in ("min_window_bins", "max_iterations", "max_range_bins", "segments"):
            if not integer(getattr(self, name), False):
                raise ValueError(f"PGASettings.{name} must be an integer >= 1")
        checks = {
            "xi": math.isfinite(self.xi) and self.xi >= 1.0,
            "stop_rad": math.isfinite(self.stop_rad) and self.stop_rad > 0,
            "focused_rad": math.isfinite(self.focused_rad) and self.focused_rad >= 0,
            "bright_threshold_db": math.isfinite(self.bright_threshold_db),
            "min_row_fill": 0.0 <= self.min_row_fill <= 1.0,
            "migration_cells": math.isfinite(self.migration_cells) and self.migration_cells >= 0,
            "min_sharpness_gain": math.isfinite(self.min_sharpness_gain)
            and self.min_sharpness_gain >= 0,
            "doppler_gain": 0.0 <= self.doppler_gain <= 1.0,
            "doppler_anchor": self.doppler_anchor in (True, False),  # 0/1 from pga:key=value
            "follow_walk": self.follow_walk in (True, False),
            "walk_noise_rad": math.isfinite(self.walk_noise_rad) and self.walk_noise_rad >= 0,
            "min_doppler_coherence": 0.0 <= self.min_doppler_coherence <= 1.0,
        }
        for name, ok in checks.items():
            if not ok:
                switch = name in ("doppler_anchor", "follow_walk")
                what = "must be 0 or 1" if switch else "out of range"
                raise ValueError(f"PGASettings.{name} {what}: {getattr(self, name)!r}")
        object.__setattr__(self, "doppler_anchor", bool(self.doppler_anchor))
        object.__setattr__(self, "follow_walk", bool(self.follow_walk))

    def resolved(
        self, aperture_pulses: int, footprint_pulses: float | None = None
    ) -> tuple[int, int, int]:
        """(P, H, min_pulses) for a processor aperture N; raises ValueError if inconsistent.

        The default P is 2N, capped at 1.1 × the beam's footprint λR/(D d) in pulses where that
        is shorter (never below N): a point must stay lit across the block to be one of its rows,
        and at ±0.55 λR/D from the beam centre the two-way power sinc⁴ is down to 0.1, the
        ``min_row_fill`` of a quarter block.
        """
        p = self.block_pulses or 2 * aperture_pulses
        if self.block_pulses is None and footprint_pulses is not None:
            p = max(aperture_pulses, min(p, int(round(1.1 * footprint_pulses))))
        if p < max(8, aperture_pulses):
            raise ValueError(f"block_pulses {p} must be >= max(8, aperture_pulses)")
        h = self.hop_pulses or p // 2
        if h > p:
            raise ValueError(f"hop_pulses {h} exceeds block_pulses {p}")
        return p, h, min(self.min_pulses or min(p, aperture_pulses), p)


@dataclass(frozen=True)
class BlockReport:
    """What PGA did on one block: where it was, whether its estimate was used (``estimated``;
    ``reason`` one of REASONS), iterations, range bins in eq. 4.16, the last step's peak to peak
    and the estimate's rms (slope removed) in radians, the block image's sharpness
    Σ|G|⁴/(Σ|G|²)² before and after, the half-width w of the rows (bins) where the range
    migration was handled (0: single bins, no migration correction), and whether the Doppler
    anchor set its slope (rtsar.focus.pga.doppler) with the residual slope it found (rad/pulse),
    and how many narrow walk-following rows gave the estimate (0: the 2w+1-bin rows did;
    ``walk_rows``; iterations and final step are then the second pass's).
    """

    first_pulse: int
    pulses: int
    estimated: bool
    converged: bool
    reason: str
    iterations: int
    range_bins_used: int
    final_step_rad: float
    correction_rms_rad: float
    sharpness_before: float
    sharpness_after: float
    row_half_width: int = 0
    doppler_anchored: bool = False
    doppler_slope_rad: float = 0.0
    walk_rows: int = 0


# ---- the estimator ---------------------------------------------------------------------------
def footprint_pulses(config: Config) -> float:
    """The real beam's footprint λR/D (Crouch eq. 4.9) in pulses of the along-track step."""
    g = config.geometry
    return g.illuminated_length_m / g.along_track_step_m


def deramp_cycles(config: Config, range_m: np.ndarray, pulses: int) -> np.ndarray:
    """Eq. (1) of the module docstring in cycles mod 1: [pulses, bins] float64 (2ΔR_p/λ)."""
    return np.mod(2.0 * curvature_m(config, range_m, pulses) / config.geometry.wavelength_m, 1.0)


def remove_linear(phase_rad: np.ndarray) -> np.ndarray:
    """Phase minus its least-squares constant and slope over the pulse index (float64)."""
    phi = np.asarray(phase_rad, dtype=np.float64)
    n = phi.size
    if n < 2:
        return np.zeros(n)
    t = np.arange(n) - 0.5 * (n - 1)
    slope = float(np.dot(t, phi) / np.dot(t, t))
    return phi - phi.mean() - slope * t


#: Where a point's history sweeps more cycles than this over a block (its mean over the block is
#: then ≲ 1/√(2·cycles) of it), each range bin's mean is removed before estimating: a return
#: fixed to the platform (leakage, an internal reflection) is steady, so it is all mean.
FIXED_MIN_CYCLES = 20.0


def _wide_rows_noisy(power: np.ndarray, bins: np.ndarray, limit_rad: float) -> bool:
    """Whether the rows' noise puts more than ``limit_rad`` rms into the estimate: √(N/2S) of
    the brightest row ``bins[0]``, N the median row's energy (noise and clutter), S its own
    above that (``power[pulse, row]``)."""
    energy = power.sum(axis=0)
    noise = float(np.median(energy))
    signal = float(energy[bins[0]]) - noise
    return signal > 0 and math.sqrt(noise / (2.0 * signal)) > limit_rad


def _sharpness(image: np.ndarray) -> float:
    p = image.real**2 + image.imag**2
    total = float(p.sum())
    return float((p * p).sum()) / (total * total) if total > 0 else 0.0


def _bright_bins(power: np.ndarray, settings: PGASettings) -> np.ndarray:
    """Rows whose energy stands ``bright_threshold_db`` above the median row's in every segment.

    power[pulse, row] = |row|².  The block is cut into ``segments`` stretches of pulses; a row
    qualifies when it is bright in each of them and none holds less than ``min_row_fill`` of the
    fullest's energy, so its point stays in it (lit, and inside the row's range span) across the
    whole block.  Brightest first, at most ``max_range_bins``.
    """
    factor = 10.0 ** (settings.bright_threshold_db / 10.0)
    parts = np.array_split(power, min(settings.segments, power.shape[0]), axis=0)
    energy = np.stack([part.sum(axis=0) for part in parts])  # [segment, row]
    ok = (energy > factor * np.median(energy, axis=1, keepdims=True)).all(axis=0)
    # Its point stays in the row: no stretch holds less than min_row_fill of the fullest's.
    ok &= energy.min(axis=0) >= settings.min_row_fill * energy.max(axis=0)
    candidates = np.flatnonzero(ok)
    order = np.argsort(power[:, candidates].sum(axis=0), kind="stable")[::-1]
    return candidates[order[: settings.max_range_bins]]


def _pga_step(g0: np.ndarray, phi: np.ndarray, width: float) -> np.ndarray:
    """One pass of Crouch eqs. 4.14-4.17 on deramped pulses g0[pulse, bin] corrected by φ."""
    p = g0.shape[0]
    n = np.arange(p)
    centred = np.minimum(n, p - n)  # circular distance of image bin n from bin 0
    image = np.fft.fft(g0 * phasor(-phi)[:, None], axis=0)  # block image G[n, k]
    brightest = np.argmax(image.real**2 + image.imag**2, axis=0)
    rows = (n[:, None] + brightest[None, :]) % p  # circular shift: brightest → bin 0
    shifted = np.take_along_axis(image, rows, axis=0)
    shifted[centred > 0.5 * width] = 0  # eq. 4.14, rect(n ξ^q / W) about the centre
    h = np.fft.ifft(shifted, axis=0)  # eq. 4.15, back to pulses
    dphi = np.angle(np.sum(np.conj(h[:-1]) * h[1:], axis=1))  # eq. 4.16
    return remove_linear(np.concatenate(([0.0], np.cumsum(dphi))))  # eq. 4.17


def _pga_iterations(
    g0: np.ndarray, window_bins: int, settings: PGASettings, phi0: np.ndarray | None = None
):
    """Iterated eqs. 4.14-4.17 → (φ, iterations, last step's peak to peak, reason), from φ0
    (default zero; with φ0 a small first step means converged, not "nothing to correct")."""
    phi = np.zeros(g0.shape[0]) if phi0 is None else phi0.copy()
    width = float(window_bins)
    step_pp = 0.0
    for it in range(1, settings.max_iterations + 1):
        step = _pga_step(g0, phi, width)
        step_pp = float(step.max() - step.min())
        if it == 1 and phi0 is None and step_pp < settings.focused_rad:
            return phi, it, step_pp, "nothing_to_correct"
        if step_pp < settings.stop_rad:
            return phi, it, step_pp, "converged"
        phi += step
        width /= settings.xi
        if width < settings.min_window_bins:
            return phi, it, step_pp, "window_floor"
    return phi, settings.max_iterations, step_pp, "max_iterations"


def estimate_block(
    config: Config,
    lines: np.ndarray,
    range_m: np.ndarray | None = None,
    settings: PGASettings | None = None,
    first_pulse: int = 0,
) -> tuple[np.ndarray, BlockReport]:
    """PGA on one block of range-compressed pulses (Crouch eqs. 4.14-4.17; batch, float64).

    ``lines[pulse, range_bin]`` (NaN/Inf pulses count as zero), ``range_m`` the bins'
    slant ranges (default: the AO lens plan's).  Returns (phase_rad float64[pulses], report):
    the estimated error, constant and slope removed (zeros when not used); correct with
    ``lines * exp(-1j * phase_rad)[:, None]``.
    """
    settings = settings or PGASettings()
    x = np.asarray(lines)
    if x.ndim != 2:
        raise ValueError(f"lines must be [pulses, range_bins], got {x.shape}")
    x = np.asarray(x, dtype=np.complex128)
    finite = np.isfinite(x).all(axis=1)
    if not finite.all():
        x = np.where(finite[:, None], x, 0)
    if range_m is None:
        range_m = range_axis_m(config)
    range_m = np.asarray(range_m, dtype=np.float64)
    if range_m.shape != (x.shape[1],):
        raise ValueError(f"range_m must have {x.shape[1]} entries, got {range_m.shape}")
    pulses = x.shape[0]
    min_pulses = settings.resolved(config.processor.aperture_pulses, footprint_pulses(config))[2]
    window_bins = min(settings.initial_window_bins or pulses, pulses)
    w = row_half_width(config, range_m, pulses, settings.migration_cells)

    def report(reason, iterations=0, bins=0, step=0.0, rms=0.0, before=0.0, after=0.0, walk=0):
        done = (reason in ESTIMATED, reason == "converged", reason, iterations, bins, step, rms)
        return BlockReport(first_pulse, pulses, *done, before, after, w, walk_rows=walk)

    zero = np.zeros(pulses)
    if pulses < max(2, min_pulses):
        return zero, report("short_block")
    # ΔR_p of the swath centre: one per pulse, the curvature varies little with R.
    centre_dr_m = curvature_m(config, range_m[range_m.size // 2 : range_m.size // 2 + 1], pulses)
    if 2.0 * float(centre_dr_m[0, 0]) / config.geometry.wavelength_m > FIXED_MIN_CYCLES:
        # A scene point's history sweeps that many cycles: its mean over the block is tiny,
        # while a return fixed to the platform is all mean.
        x = x - x.mean(axis=0, keepdims=True)
    if w:
        cell_m = range_m[1] - range_m[0]  # signed: an axis may decrease
        xc = migration_corrected(x, centre_dr_m[:, 0] / cell_m)
        x = rows(xc, w)
    power = x.real**2 + x.imag**2
    bins = _bright_bins(power, settings)
    if bins.size == 0:
        return zero, report("no_bright_points")
    g0 = x[:, bins] * np.exp(2j * math.pi * deramp_cycles(config, range_m[bins], pulses))
    phi, iterations, step, reason = _pga_iterations(g0, window_bins, settings)
    if reason == "nothing_to_correct":
        return zero, report(reason, iterations, bins.size, step)
    phi = remove_linear(phi)
    walk = 0
    if w and settings.follow_walk and _wide_rows_noisy(power, bins, settings.walk_noise_rad):
        # Again on narrow rows that follow each point's walk.
        image = np.fft.fft(g0 * phasor(-phi)[:, None], axis=0)
        peaks = np.argmax(image.real**2 + image.imag**2, axis=0)
        energy = power[:, bins].sum(axis=0)
        gw, where = walking_rows(config, xc, range_m, bins, peaks, energy, w)
        if where.size:  # from pass one's φ, with the whole window again: its noise is replaced
            gw *= np.exp(2j * math.pi * deramp_cycles(config, range_m[where], pulses))
            phi2, it2, step2, reason2 = _pga_iterations(gw, window_bins, settings, phi)
            if reason2 in ESTIMATED:
                phi, iterations, step, reason = remove_linear(phi2), it2, step2, reason2
                g0, walk = gw, where.size
    before = _sharpness(np.fft.fft(g0, axis=0))
    after = _sharpness(np.fft.fft(g0 * phasor(-phi)[:, None], axis=0))
    rms = float(np.sqrt(np.mean(phi**2)))
    if not after > before * (1.0 + settings.min_sharpness_gain):
        return zero, report("not_sharper", iterations, bins.size, step, rms, before, after, walk)
    return phi, report(reason, iterations, bins.size, step, rms, before, after, walk)
