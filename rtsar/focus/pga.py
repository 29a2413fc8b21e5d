"""Phase gradient autofocus (PGA) of range-compressed pulses, in blocks of the strip-map stream.

The error: a phase φ(p) common to every range bin of pulse p (piston, Crouch eq. 4.12).  Pulse p
is taken to carry exp(+iφ(p)); the correction multiplies it by exp(-iφ̂(p)).  Constant and linear
phase are invisible to PGA (a constant changes nothing, a slope only shifts the image), so PGA
removes both, and residuals are quoted with both removed (``residual_rms_rad``).

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

Streaming.  Blocks of P pulses start every H (default P/2).  Each block's estimate is aligned to
the previous one over their P - H common pulses (constant and slope, ``_align``) and commits the
H pulses in its middle, s_b + E … s_b + E + H, E = (P - H)/2 (block 0 from pulse 0): a pulse
leaves (P + H)/2 pulses after arriving.  ``flush`` runs one last block over the final P pulses; a
stream shorter than ``min_pulses`` is passed through ("short_block").  Memory: P + H lines.
``pga_batch`` is the float64 reference of the same layout on a recording; ``estimate_block`` is
Crouch's single-block PGA (batch mode on one recorded block).  Placement: between the AO lens and
the CCD; a per-pulse phase commutes with range compression, so raw shots could take it as well.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..lens_plan import make_plan
from ..params import Config

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


def residual_rms_rad(
    estimate_rad: np.ndarray, truth_rad: np.ndarray, window_pulses: int | None = None
) -> float:
    """Rms of the residual (estimate - truth), radians, with constant and slope removed.

    The figure of merit of a correction against the injected truth.  Constant and linear phase
    are unobservable by autofocus (module docstring); they are fitted as phasor averages
    (``_align``) so a 2π step changes nothing, and the rms is of the residual wrapped to
    (-π, π].  ``window_pulses`` None: one fit over the whole record.  ``window_pulses`` = N (the
    aperture): a fit per window of N pulses (windows every N/2 pulses), the rms over all
    windows — what decides focus, since each image line sees N pulses and a slope left in one
    aperture only shifts that line.
    """
    e = np.asarray(estimate_rad, np.float64)
    t = np.asarray(truth_rad, np.float64)
    if e.shape != t.shape or e.ndim != 1:
        raise ValueError(f"estimate and truth must be 1-D of one length, got {e.shape}, {t.shape}")
    n = e.size if window_pulses is None else int(window_pulses)
    if n < 1:
        raise ValueError(f"window_pulses must be >= 1, got {window_pulses!r}")
    if e.size == 0:
        return 0.0
    n = min(n, e.size)
    starts = range(0, e.size - n + 1, max(1, n // 2))
    squares = []
    for s in starts:
        d = e[s : s + n] - t[s : s + n]
        a, c = _align(d)
        r = np.angle(np.exp(1j * (d - a - c * np.arange(n))))
        squares.append(float(np.mean(r * r)))
    return math.sqrt(sum(squares) / len(squares))


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
        g = g0 * np.exp(-1j * np.mod(phi, 2 * math.pi))[:, None]
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
        range_m = make_plan(config).range_m
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
    after = _sharpness(np.fft.fft(g0 * np.exp(-1j * np.mod(phi, 2 * math.pi))[:, None], axis=0))
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
    z = complex(np.sum(lag * np.exp(-1j * np.mod(np.diff(phi), 2 * math.pi))))
    total = float(energy @ clutter)
    if not total > 0 or abs(z) < settings.min_doppler_coherence * total:
        return None
    return math.atan2(z.imag, z.real)


# ---- block layout and stitching (shared by the stream and the batch reference) -------------
def _align(delta: np.ndarray) -> tuple[float, float]:
    """Constant a and slope c with δ_i ≈ a + c·i (mod 2π), i = 0, 1, … (a phase difference).

    The slope is first found as the peak of the periodogram of e^{iδ}
    (zero-padded 16×; the maximum-likelihood frequency of a phasor in noise, insensitive to 2π
    steps), then refined with the constant by least squares on the unwrapped remainder.
    """
    delta = np.asarray(delta, np.float64)
    n = delta.size
    if n == 0:
        return 0.0, 0.0
    i = np.arange(n)
    z = np.exp(1j * delta)
    nfft = 16 * (1 << max(0, (n - 1).bit_length()))
    k = int(np.argmax(np.abs(np.fft.fft(z, nfft))))
    c = 2 * math.pi * (k if k < nfft // 2 else k - nfft) / nfft
    a = float(np.angle(np.sum(z * np.exp(-1j * c * i))))
    rest = np.unwrap(np.angle(z * np.exp(-1j * (a + c * i))))
    if n >= 2:
        t = i - 0.5 * (n - 1)
        dc = float(np.dot(t, rest) / np.dot(t, t))
        a += float(rest.mean()) - dc * 0.5 * (n - 1)
        c += dc
    return a, c


class _Stitcher:
    """Turns block estimates into one continuous per-pulse phase (the layout of the docstring)."""

    def __init__(self, block: int, hop: int, doppler_gain: float):
        self.block, self.hop = block, hop
        self.margin = (block - hop) // 2
        self.doppler_gain = doppler_gain
        self.committed = 0  # pulses whose phase is final
        self.last_phase = 0.0  # phase of the last committed pulse (held on failure)
        self.prev_start = None  # previous block's first pulse and its aligned phase
        self.prev_phase = None
        self.prev_estimated = False

    def next_start(self, index: int) -> int:
        return index * self.hop

    def add(self, start: int, phase: np.ndarray, report: BlockReport, stop: int) -> np.ndarray:
        """Align a block's phase to the previous block's; return phases of [committed, stop).

        Over the common pulses δ = previous - phase is fitted by a + c·i (``_align``).  A block
        anchored on its own Doppler centroid keeps (1 - doppler_gain)·c of the slope (the rest
        is its centroid's); the constant is refitted for the slope kept.
        """
        n = phase.size
        if not report.estimated:
            aligned = np.full(n, self.last_phase)
        elif self.prev_start is None:
            aligned = phase.copy()
        elif self.prev_start + self.prev_phase.size <= start:  # no overlap (hop = block)
            aligned = phase - phase[0] + self.last_phase
        else:
            delta = (
                self.prev_phase[start - self.prev_start :]
                - phase[: self.prev_start + self.prev_phase.size - start]
            )
            a, c = _align(delta)
            if report.doppler_anchored:
                # After a block that could not be estimated the overlap holds a constant, not a
                # slope: take the centroid's slope whole.
                c *= (1.0 - self.doppler_gain) if self.prev_estimated else 0.0
                i = np.arange(delta.size)
                a = float(np.angle(np.sum(np.exp(1j * (delta - c * i)))))
            aligned = phase + a + c * np.arange(n)
        self.prev_estimated = report.estimated
        self.prev_start, self.prev_phase = start, aligned
        return self.extend(stop)

    def extend(self, stop: int) -> np.ndarray:
        """Commit pulses [committed, stop) from the last block's aligned phase."""
        out = self.prev_phase[self.committed - self.prev_start : stop - self.prev_start]
        self.committed = stop
        if out.size:
            self.last_phase = float(out[-1])
        return out


def _wrap(phase_rad: np.ndarray) -> np.ndarray:
    return np.mod(phase_rad, 2 * math.pi)


def pga_batch(
    config: Config,
    lines: np.ndarray,
    range_m: np.ndarray | None = None,
    settings: PGASettings | None = None,
) -> tuple[np.ndarray, np.ndarray, list[BlockReport]]:
    """Float64 reference: PGA over a whole recording in the stream's block layout.

    Returns (corrected lines complex128 [pulse, bin], phase_rad float64 [pulse] (the phase
    removed from each pulse), block reports).  ``PGAStage`` fed the same lines in any
    micro-batches returns the same phases and (in complex64) the same lines.
    """
    settings = settings or PGASettings()
    x = np.asarray(lines)
    if x.ndim != 2:
        raise ValueError(f"lines must be [pulses, range_bins], got {x.shape}")
    x = x.astype(np.complex128)
    x[~np.isfinite(x).all(axis=1)] = 0
    if range_m is None:
        range_m = make_plan(config).range_m
    block, hop, _ = settings.resolved(config.processor.aperture_pulses)
    total = x.shape[0]
    st = _Stitcher(block, hop, settings.doppler_gain)
    phases, reports = [], []
    b = 0
    while st.next_start(b) + block <= total:
        s = st.next_start(b)
        stop = s + st.margin + hop
        phi, rep = estimate_block(config, x[s : s + block], range_m, settings, s)
        phases.append(st.add(s, phi, rep, stop))
        reports.append(rep)
        b += 1
    if st.committed < total:
        s = max(0, total - block)
        if s == st.prev_start:  # the last regular block already covers the end
            phases.append(st.extend(total))
        else:
            phi, rep = estimate_block(config, x[s:], range_m, settings, s)
            phases.append(st.add(s, phi, rep, total))
            reports.append(rep)
    phase = np.concatenate(phases) if phases else np.zeros(0)
    return x * np.exp(-1j * _wrap(phase))[:, None], phase, reports


# ---- the stream stage -------------------------------------------------------------------------
@dataclass
class PGACounters:
    pulses_in: int = 0
    pulses_out: int = 0
    blocks_estimated: int = 0
    blocks_not_estimated: int = 0
    blocks_converged: int = 0
    nonfinite_pulses: int = 0  # pulses holding NaN/Inf: zeroed, never reach the output
    reasons: dict = field(default_factory=lambda: {r: 0 for r in REASONS})


class PGAStage:
    """Streaming PGA between the AO lens and the CCD: ``process(lines)`` → corrected lines.

    Lines leave in pulse order, (P + H)/2 pulses after they arrived (block 0: P); ``flush()``
    returns the rest at the end of a stream.  ``last_phase_rad`` holds the phase removed from the
    lines of the last ``process``/``flush`` call; ``reports`` the last ``keep_reports`` block
    reports; ``counters`` the totals.  Memory: one block of lines.  Output complex64.
    """

    def __init__(
        self,
        config: Config,
        settings: PGASettings | None = None,
        range_m: np.ndarray | None = None,
        keep_reports: int = 64,
    ):
        self.config = config
        self.settings = settings or PGASettings()
        self.range_m = (
            make_plan(config).range_m if range_m is None else np.asarray(range_m, np.float64)
        )
        self.block, self.hop, _ = self.settings.resolved(config.processor.aperture_pulses)
        self.bins = self.range_m.size
        # The block being filled plus the hop before it: the last block at flush may start up
        # to H pulses before the next regular block.
        self._buf = np.zeros((self.block + self.hop, self.bins), np.complex128)
        self._buf_start = 0  # stream index of _buf[0]
        self._buf_len = 0
        self._stitch = _Stitcher(self.block, self.hop, self.settings.doppler_gain)
        self._next_block = 0
        self.reports: deque[BlockReport] = deque(maxlen=keep_reports)
        self.counters = PGACounters()
        self.last_phase_rad = np.zeros(0)
        self._flushed = False

    @property
    def latency_pulses(self) -> int:
        """Pulses a line waits in this stage in steady state: (P + H)/2."""
        return self.block - self._stitch.margin

    def _count(self, rep: BlockReport) -> None:
        c = self.counters
        c.reasons[rep.reason] += 1
        if rep.estimated:
            c.blocks_estimated += 1
        else:
            c.blocks_not_estimated += 1
        c.blocks_converged += rep.converged
        self.reports.append(rep)

    def _release(self, stop: int, phase: np.ndarray) -> np.ndarray:
        """Correct and drop buffered pulses [committed_before, stop) with ``phase``."""
        lo = stop - phase.size
        rows = self._buf[lo - self._buf_start : stop - self._buf_start]
        out = (rows * np.exp(-1j * _wrap(phase))[:, None]).astype(np.complex64)
        self.counters.pulses_out += len(out)
        return out

    def _trim(self, keep_from: int) -> None:
        drop = keep_from - self._buf_start
        if drop > 0:
            self._buf[: self._buf_len - drop] = self._buf[drop : self._buf_len]
            self._buf_len -= drop
            self._buf_start = keep_from

    def process(self, lines: np.ndarray, aux: dict | None = None) -> np.ndarray:
        """Add range-compressed lines [pulse, bin]; return the lines whose correction is final.

        ``aux`` (auxiliary channels) is accepted for the stage interface and not used.
        """
        if self._flushed:
            raise ValueError("PGAStage was flushed: a new stream needs a new stage")
        x = np.asarray(lines)
        if x.ndim != 2 or x.shape[1] != self.bins:
            raise ValueError(f"lines must be [pulses, {self.bins}], got {x.shape}")
        outs, phases = [], []
        i = 0
        while i < len(x):
            s = self._stitch.next_start(self._next_block)
            need = s + self.block - (self._buf_start + self._buf_len)
            take = min(need, len(x) - i)
            chunk = x[i : i + take].astype(np.complex128)
            bad = ~np.isfinite(chunk).all(axis=1)
            if bad.any():
                chunk[bad] = 0
                self.counters.nonfinite_pulses += int(bad.sum())
            self._buf[self._buf_len : self._buf_len + take] = chunk
            self._buf_len += take
            self.counters.pulses_in += take
            i += take
            if take == need:  # block complete
                block = self._buf[s - self._buf_start : s - self._buf_start + self.block]
                phi, rep = estimate_block(self.config, block, self.range_m, self.settings, s)
                self._count(rep)
                stop = s + self._stitch.margin + self.hop
                ph = self._stitch.add(s, phi, rep, stop)
                outs.append(self._release(stop, ph))
                phases.append(ph)
                self._next_block += 1
                self._trim(s)  # keep this block: the last one at flush may reach back to it
        return self._finish(outs, phases)

    def flush(self) -> np.ndarray:
        """At the end of a stream: estimate a last block over the final pulses, release all."""
        self._flushed = True
        outs, phases = [], []
        total = self._buf_start + self._buf_len
        if self._stitch.committed < total:
            s = max(0, total - self.block)
            if s == self._stitch.prev_start:  # the last regular block already covers the end
                ph = self._stitch.extend(total)
            else:
                block = self._buf[s - self._buf_start : self._buf_len]
                phi, rep = estimate_block(self.config, block, self.range_m, self.settings, s)
                self._count(rep)
                ph = self._stitch.add(s, phi, rep, total)
            outs.append(self._release(total, ph))
            phases.append(ph)
        self._buf_len = 0
        self._buf_start = total
        return self._finish(outs, phases)

    def _finish(self, outs, phases) -> np.ndarray:
        self.last_phase_rad = np.concatenate(phases) if phases else np.zeros(0)
        if outs:
            return np.concatenate(outs)
        return np.zeros((0, self.bins), np.complex64)


__all__ = [
    "ESTIMATED",
    "REASONS",
    "BlockReport",
    "PGACounters",
    "PGASettings",
    "PGAStage",
    "deramp_cycles",
    "estimate_block",
    "pga_batch",
    "remove_linear",
    "residual_rms_rad",
]
