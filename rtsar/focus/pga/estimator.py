"""Phase gradient autofocus (PGA): Crouch's estimator on one block of deramped pulses.

The error: a phase φ(p) common to every range bin of pulse p (piston, Crouch eq. 4.12).  Pulse p
is taken to carry exp(+iφ(p)); the correction multiplies it by exp(-iφ̂(p)).  Constant and linear
phase are invisible to PGA (a constant changes nothing, a slope only shifts the image), so PGA
removes both, and residuals are quoted with both removed (rtsar.analysis.phase_residual).

Why blocks of deramped pulses.  Crouch's PGA (ch. 4, eqs. 4.14-4.17; App. A ``PGAforSAL``) works
on an image one DFT away from the range-compressed shots (his linearised Fourier kernel, the
quadratic phase neglected), so the error of shot m is a phase of DFT sample m.  A strip-map CCD
has no such image: it correlates with a range-dependent chirp and each line integrates its own N
pulses.  The faithful equivalent is to deramp a block of P ≥ N pulses with the conjugate history
of a scatterer at the block centre (Psaltis & Wagner eq. 2, exact range; the CCD mask's phase):

    exp(+i 4π/λ · (sqrt(R_r² + x_p²) - R_r)),   x_p = (p - (P-1)/2) d.                    (1)

A scatterer u along track from the block centre becomes the tone exp(i 4π u x_p/(λR))·exp(iφ(p))
(to fourth order in x): Crouch's kernel E_n ∝ exp[-iφ(n)] Σ_j exp(-iμu_j), and the DFT across
the block is a SPECAN image of the whole beam.  Crouch's steps then apply unchanged:

* choose range bins with a bright point (his rows ``lr:ur``): bins whose energy is
  ``bright_threshold_db`` above the median bin in each of ``segments`` stretches of the block
  (the point lit across the block; energy does not depend on the defocus);
* circularly shift each bin's brightest pixel to the centre, keep a window W ξ^-q (eq. 4.14,
  ξ = 1.1, W = the block); inverse DFT (eq. 4.15); phasor sum of the phase differences over the
  bins (eq. 4.16); integrate from φ(0) = 0 (eq. 4.17); remove the slope (as ``PGAforSAL``);
* iterate until the step's peak to peak is below π/10 (Crouch), the window falls below
  ``min_window_bins``, or ``max_iterations``.

The slope PGA cannot see is set by the clutter's Doppler centroid (``_doppler_slope``): in
strip-map a slope moves the image against the antenna beam, so it matters.  Failures are
harmless (Crouch: PGA cannot focus scenes without prominent points): no bin stands out →
"no_bright_points"; the corrected block image is not sharper (Σ|G|⁴/(Σ|G|²)²) → "not_sharper".
Either way the last committed phase is held, the block is counted and its report says why; no
step can make a NaN (empty sums give angle(0) = 0).  INO phase-error patent: remove the bulk with
the reference region first, PGA for the residual — put this stage after that correction.

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

#: Why a block's iterations stopped (the first three: estimate used) or why it has no estimate.
ESTIMATED = ("converged", "window_floor", "max_iterations")
REASONS = (*ESTIMATED, "no_bright_points", "not_sharper", "short_block")


@dataclass(frozen=True)
class PGASettings:
    """PGA knobs (Crouch ch. 4); ``None`` sizes follow the processor's aperture N.

    block_pulses, hop_pulses  P (default 2N, ≥ max(8, N); at most the beam's dwell so points stay
                        lit across a block) and H (default P/2, ≤ P)
    xi, initial_window_bins, min_window_bins  eq. 4.14: W_q = W/ξ^q (Crouch 1.1), W default P
                        (the whole block: the fastest errors); stop when W_q < min_window_bins
    max_iterations, stop_rad  at most so many iterations; converged when the step's peak to
                        peak is below stop_rad (Crouch: π/10)
    max_range_bins, bright_threshold_db, segments  the brightest ≤ max_range_bins bins whose
                        energy is bright_threshold_db above the median bin in every one of
                        ``segments`` stretches of the block take part in eq. 4.16
    require_sharper     discard an estimate that does not sharpen the block image
    min_pulses          a shorter block (end of a short stream) is not estimated (min(P, N))
    doppler_gain        share of each block's Doppler-centroid slope taken (0: slopes follow
                        the overlaps; the centroid sets it on the first block and after a failed
                        one.  > 0 bounds a slow drift of the image position on long runs at the
                        cost of a small slope kink at each block boundary)
    min_doppler_coherence  lag-one coherence |Σ y*(p-1)y(p)|/Σ|y|² of the clutter below which
                        its centroid is not trusted (no clutter, noise only)
    """

    block_pulses: int | None = None
    hop_pulses: int | None = None
    xi: float = 1.1
    initial_window_bins: int | None = None
    min_window_bins: int = 8
    max_iterations: int = 30
    stop_rad: float = math.pi / 10
    max_range_bins: int = 32
    bright_threshold_db: float = 6.0
    segments: int = 4
    require_sharper: bool = True
    min_pulses: int | None = None
    doppler_gain: float = 0.0
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
            "bright_threshold_db": math.isfinite(self.bright_threshold_db),
            "doppler_gain": 0.0 <= self.doppler_gain <= 1.0,
            "min_doppler_coherence": 0.0 <= self.min_doppler_coherence <= 1.0,
        }
        for name, ok in checks.items():
            if not ok:
                raise ValueError(f"PGASettings.{name} out of range: {getattr(self, name)!r}")

    def resolved(self, aperture_pulses: int) -> tuple[int, int, int]:
        """(P, H, min_pulses) for a processor aperture N; raises ValueError if inconsistent."""
        p = self.block_pulses or 2 * aperture_pulses
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
    Σ|G|⁴/(Σ|G|²)² before and after, and the Doppler-centroid slope (rad/pulse) if one was set.
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
    doppler_anchored: bool = False
    doppler_slope_rad: float = 0.0


# ---- the estimator ---------------------------------------------------------------------------
def deramp_cycles(config: Config, range_m: np.ndarray, pulses: int) -> np.ndarray:
    """Eq. (1) of the module docstring in cycles mod 1: [pulses, bins] float64.

    +2/λ · (sqrt(R² + x²) - R), x_p = (p - (P-1)/2)·d: the conjugate of the two-way history of a
    scatterer at the block centre (Psaltis & Wagner eq. 2, exact range), formed in float64.
    """
    g = config.geometry
    x = ((np.arange(pulses) - 0.5 * (pulses - 1)) * g.along_track_step_m)[:, None]
    r = np.asarray(range_m, dtype=np.float64)[None, :]
    excess_m = x * x / (np.sqrt(r * r + x * x) + r)  # no cancellation for x ≪ R
    return np.mod(2.0 * excess_m / g.wavelength_m, 1.0)


def remove_linear(phase_rad: np.ndarray) -> np.ndarray:
    """Phase minus its least-squares constant and slope over the pulse index (float64)."""
    phi = np.asarray(phase_rad, dtype=np.float64)
    n = phi.size
    if n < 2:
        return np.zeros(n)
    t = np.arange(n) - 0.5 * (n - 1)
    slope = float(np.dot(t, phi) / np.dot(t, t))
    return phi - phi.mean() - slope * t


def _sharpness(image: np.ndarray) -> float:
    p = image.real**2 + image.imag**2
    total = float(p.sum())
    return float((p * p).sum()) / (total * total) if total > 0 else 0.0


def _bright_bins(power: np.ndarray, settings: PGASettings) -> np.ndarray:
    """Range bins standing ``bright_threshold_db`` above the median bin in every segment.

    power[pulse, bin] = |line|².  The block is cut into ``segments`` stretches of pulses; a bin
    qualifies when its energy exceeds the median bin's by the threshold in each of them, so its
    bright point is lit (inside the antenna footprint) across the whole block.  Brightest first.
    """
    factor = 10.0 ** (settings.bright_threshold_db / 10.0)
    ok = np.ones(power.shape[1], bool)
    for part in np.array_split(power, min(settings.segments, power.shape[0]), axis=0):
        energy = part.sum(axis=0)
        ok &= (energy > factor * float(np.median(energy))) & (energy > 0)
    candidates = np.flatnonzero(ok)
    order = np.argsort(power[:, candidates].sum(axis=0))[::-1]
    return candidates[order[: settings.max_range_bins]]


def _pga_iterations(g0: np.ndarray, window_bins: int, settings: PGASettings):
    """Crouch eqs. 4.14-4.17 on deramped pulses g0[pulse, bin] → (φ, iterations, step, reason)."""
    p = g0.shape[0]
    phi = np.zeros(p)
    n = np.arange(p)
    centred = np.minimum(n, p - n)  # circular distance of image bin n from bin 0
    width = float(window_bins)
    step_pp, it, reason = 0.0, 0, "max_iterations"
    for it in range(1, settings.max_iterations + 1):
        g = g0 * phasor(-phi)[:, None]
        image = np.fft.fft(g, axis=0)  # block image G[n, k] (Crouch's g(k, n))
        brightest = np.argmax(image.real**2 + image.imag**2, axis=0)
        rows = (n[:, None] + brightest[None, :]) % p  # circular shift: brightest → bin 0
        shifted = np.take_along_axis(image, rows, axis=0)
        shifted[centred > 0.5 * width] = 0  # eq. 4.14, rect(n ξ^q / W) about the centre
        h = np.fft.ifft(shifted, axis=0)  # eq. 4.15, back to pulses
        dphi = np.angle(np.sum(np.conj(h[:-1]) * h[1:], axis=1))  # eq. 4.16
        step = remove_linear(np.concatenate(([0.0], np.cumsum(dphi))))  # eq. 4.17
        phi += step
        step_pp = float(step.max() - step.min())
        if step_pp < settings.stop_rad:
            return phi, it, step_pp, "converged"
        width /= settings.xi
        if width < settings.min_window_bins:
            return phi, it, step_pp, "window_floor"
    return phi, it, step_pp, reason


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
    the estimated error with the Doppler-centroid slope (zeros when not estimated); correct
    with ``lines * exp(-1j * phase_rad)[:, None]``.
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
    min_pulses = settings.resolved(config.processor.aperture_pulses)[2]
    window_bins = min(settings.initial_window_bins or pulses, pulses)

    def report(reason, iterations=0, bins=0, step=0.0, rms=0.0, before=0.0, after=0.0, dc=None):
        done = (reason in ESTIMATED, reason == "converged", reason, iterations, bins, step, rms)
        return BlockReport(first_pulse, pulses, *done, before, after, dc is not None, dc or 0.0)

    zero = np.zeros(pulses)
    if pulses < max(2, min_pulses):
        return zero, report("short_block")
    power = x.real**2 + x.imag**2
    bins = _bright_bins(power, settings)
    if bins.size == 0:
        return zero, report("no_bright_points")
    g0 = x[:, bins] * np.exp(2j * math.pi * deramp_cycles(config, range_m[bins], pulses))
    phi, iterations, step, reason = _pga_iterations(g0, window_bins, settings)
    phi = remove_linear(phi)
    before = _sharpness(np.fft.fft(g0, axis=0))
    after = _sharpness(np.fft.fft(g0 * phasor(-phi)[:, None], axis=0))
    rms = float(np.sqrt(np.mean(phi**2)))
    if settings.require_sharper and not after > before:
        return zero, report("not_sharper", iterations, bins.size, step, rms, before, after)
    dc = _doppler_slope(x, power, phi, settings)
    if dc is not None:
        phi = phi + dc * (np.arange(pulses) - 0.5 * (pulses - 1))
    return phi, report(reason, iterations, bins.size, step, rms, before, after, dc)


def _doppler_slope(x, power, phi, settings: PGASettings) -> float | None:
    """Linear phase (rad/pulse) that centres the clutter's Doppler spectrum on zero, or None.

    PGA cannot see a linear phase (it only shifts the block image), but the antenna beam can:
    broadside, the clutter's Doppler spectrum is symmetric about zero, so the lag-one
    correlation Σ_r Σ_p y*(p-1, r) y(p, r) of the corrected pulses y = x·e^{-iφ} is real and
    positive, and its angle is the residual slope (the correlation Doppler-centroid estimator).
    Only clutter bins (energy at most twice the median bin) take part: a bright point's Doppler
    is its position, not the beam's centre.  None when the coherence is below
    ``min_doppler_coherence`` (no clutter, or noise only).
    """
    energy = power.sum(axis=0)
    clutter = (energy <= 2.0 * float(np.median(energy))).astype(np.float64)
    # Σ_p e^{-i(φ_p - φ_{p-1})} Σ_r x*(p-1, r) x(p, r): the lag products once, then the phase.
    lag = np.einsum("pr,pr,r->p", np.conj(x[:-1]), x[1:], clutter)
    z = complex(np.sum(lag * phasor(-np.diff(phi))))
    total = float(energy @ clutter)
    if not total > 0 or abs(z) < settings.min_doppler_coherence * total:
        return None
    return math.atan2(z.imag, z.real)
