"""Range-cell-migration correction: the shifting CCD with a two-dimensional mask.

The correlator of rtsar.ccd evaluates Psaltis & Wagner 1981, eq. 5: the separable form of the
image integral eq. 3, range compression first and then, in each range column, an azimuth
correlation.  Separability assumes that a scatterer stays in its range cell for the whole
aperture.  It does not: seen from the aperture row k (along-track offset x_k) a scatterer at
closest-approach range R is at sqrt(R² + x_k²), so its compressed return sits

    Δr_k(R) = (sqrt(R² + x_k²) - R) / δR            range bins further out            (M1)

(δR the bin spacing of the lens output, rtsar.lens_plan.LensPlan.range_m, which includes the
range oversampling).  Psaltis & Wagner list this range curvature among the limits of the range
resolution (Table 1).  Eq. 3 does not need separability: its kernel h(ξ, η) may bend with ξ.
Sampled, the bent kernel is a mask with a third axis across range bins:

    g[p, r] = Σ_k Σ_t line[p - N + 1 + k, r + o_t] · mask[k, r, t]                       (M2)

    mask[k, r, t] = mask_1D[k, r] · w_T(o_t - Δr_k(r))

with mask_1D the azimuth mask of rtsar.ccd.design_mask, o_t integer bin offsets and w_T a
T-tap interpolator that reads the line at the fractional position r + Δr_k(r): T = 1 the
nearest bin, T = 2 linear, T ≥ 3 a Lanczos kernel sinc(x)·sinc(x/a), a = T/2, on the T bins
nearest to r + Δr_k(r), its weights normalised to sum 1 (unit gain at zero frequency).  The
offsets o_t cover every row's T bins, so there are T + (whole bins spanned by Δr) of them.

(M2) is a sum of ordinary correlations (rtsar.ccd eq. 1), one per offset o_t, each fed lines
moved by o_t bins (zeros beyond the swath): MigrationCorrelator runs one correlator of any kind
(direct, partitioned) per offset and adds their outputs, at about len(offsets) times the cost.
FFTMigrationCorrelator shares the transforms instead: moving lines across range commutes with
the azimuth DFT, so per overlap-save block

    Y[f, r] = Σ_t X[f, r + o_t] · H_t[f, r],      H_t = DFT of mask[N-1-q, r, t] along q     (M3)

one forward and one inverse transform, len(offsets) spectral multiply-adds.  Near a swath edge
the taps that fall outside the swath read zeros.
correlate_migration_reference is the NumPy float64 batch version of (M2).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from ..lens.plan import range_axis_m, squint_label_offset_m
from ..params import Config
from .base import Correlator, aperture_offsets_m, design_mask, mask_window
from .fft import FFTCorrelator


@dataclass(frozen=True, eq=False)
class MigrationMask:
    """The three-dimensional mask of (M2): taps[k, r, t] multiplies line[., r + offsets[t]]."""

    taps: np.ndarray  # complex128[N, range_bins, T_total]
    offsets: np.ndarray  # int64[T_total], consecutive bin offsets
    shift_bins: np.ndarray  # float64[N, range_bins], Δr_k(r) of (M1)

    def __post_init__(self):
        if self.taps.ndim != 3 or self.taps.shape[2] != len(self.offsets):
            raise ValueError("taps must be [N, range_bins, len(offsets)]")

    @property
    def aperture(self) -> int:
        return self.taps.shape[0]

    @property
    def range_bins(self) -> int:
        return self.taps.shape[1]

    def tap_masks(self) -> list[np.ndarray]:
        """The 2-D mask of each offset: taps[:, :, t] (C-contiguous complex128)."""
        return [np.ascontiguousarray(self.taps[:, :, t]) for t in range(len(self.offsets))]


def migration_bins(cfg: Config, range_m: np.ndarray) -> np.ndarray:
    """Δr_k(r) of (M1): the range migration of row k, column r, in bins of ``range_m``.

    Uses each column's own range when ``per_bin_mask`` (as design_mask does), otherwise the
    range centre.  The excess range is formed as x²/(sqrt(R² + x²) + R), free of cancellation.
    """
    range_m = np.asarray(range_m, dtype=np.float64)
    if range_m.ndim != 1 or len(range_m) < 2:
        raise ValueError("range_m must hold at least two bins")
    step_m = (range_m[-1] - range_m[0]) / (len(range_m) - 1)
    if not (step_m != 0 and np.allclose(np.diff(range_m), step_m, rtol=1e-9, atol=0)):
        raise ValueError("range_m must be uniformly spaced for range-migration correction")
    proc = cfg.processor
    if proc.per_bin_mask:
        r = range_m[None, :]
    else:
        centre = proc.range_centre_m or cfg.geometry.slant_range_m
        r = np.full((1, len(range_m)), float(centre))
    x = aperture_offsets_m(cfg)[:, None]
    excess_m = x * x / (np.sqrt(r * r + x * x) + r)
    # A squinted beam: the lens labels bin r with R0 but its echoes lie R_c - R0 further out
    # (rtsar.lens.plan.squint_label_offset_m, taken at the middle bin): the rows read there.
    return (excess_m - squint_label_offset_m(cfg)) / step_m


def interpolation_weights(frac_bins: np.ndarray, taps: int) -> tuple[np.ndarray, np.ndarray]:
    """T-tap weights reading a sampled line at fractional positions (the w_T of (M2)).

    Parameters
    ----------
    frac_bins : ndarray of float
        Positions u, in bins, relative to the column.
    taps : int
        T >= 1: 1 nearest bin, 2 linear, >= 3 Lanczos with a = T/2.

    Returns
    -------
    first : ndarray of int, like ``frac_bins``
        Offset of the first of the T bins nearest to u: ceil(u - T/2).
    weights : ndarray of float64, ``frac_bins.shape + (T,)``
        Weight of bin first + j, normalised to sum 1.
    """
    if not (isinstance(taps, int) and taps >= 1):
        raise ValueError(f"taps must be an integer >= 1, got {taps!r}")
    u = np.asarray(frac_bins, dtype=np.float64)
    if not np.isfinite(u).all():
        raise ValueError("fractional positions must be finite")
    if taps == 1:
        return np.floor(u + 0.5).astype(np.int64), np.ones(u.shape + (1,))
    first = np.ceil(u - 0.5 * taps).astype(np.int64)
    x = first[..., None] + np.arange(taps) - u[..., None]  # tap position - u, |x| <= T/2
    if taps == 2:
        w = np.clip(1.0 - np.abs(x), 0.0, None)
    else:
        a = 0.5 * taps
        w = np.sinc(x) * np.sinc(x / a) * (np.abs(x) < a)
    return first, w / w.sum(axis=-1, keepdims=True)


#: The tap counts taps_for_band chooses from (the fewest first), and the loss it allows at the
#: band's edge.  RADARSAT-1's samples cover its chirp 1.07 times over (edge 0.467 cycle a bin):
#: 8 taps lose 3.1 dB there and widened its Taylor range response 2.0 % (PSLR -31.3 dB),
#: 16 taps lose 1.8 dB: 0.6 % and -33.5 dB, for 1.2-1.4x the correlator's time (measured).
TAP_CHOICES = (8, 12, 16, 24, 32, 48, 64)
EDGE_LOSS_DB = 2.0


def edge_gain_db(taps: int, edge_cycles: float, phases: int = 64) -> float:
    """The T-tap interpolator's gain (dB) at ``edge_cycles`` cycles a bin, its magnitude
    averaged over ``phases`` fractional positions: |Σ_j w_j exp(-2πi f (o_j - u))| of
    interpolation_weights, whose gain at zero frequency is 1."""
    u = np.arange(phases) / phases
    first, w = interpolation_weights(u, taps)
    x = first[:, None] + np.arange(taps) - u[:, None]
    gain = np.abs((w * np.exp(-2j * np.pi * edge_cycles * x)).sum(axis=1)).mean()
    return float(20.0 * np.log10(gain))


def taps_for_band(band_of_sample_rate: float) -> int:
    """The fewest TAP_CHOICES whose gain at the band's edge (band_of_sample_rate / 2 cycles a
    bin: B / f_s of a pulsed lens's lines) is within EDGE_LOSS_DB.  Where none is (a band
    over 0.99 of the sample rate, whose edge no Lanczos read keeps), the fewest within
    0.5 dB of the best: more taps would cost without keeping more."""
    edge = 0.5 * float(band_of_sample_rate)
    if not 0.0 < edge <= 0.5:
        raise ValueError(f"a band of {band_of_sample_rate:g} of the sample rate: not in (0, 1]")
    gains = [edge_gain_db(taps, edge) for taps in TAP_CHOICES]
    for taps, gain in zip(TAP_CHOICES, gains, strict=True):
        if gain >= -EDGE_LOSS_DB:
            return taps
    best = max(gains)
    return next(t for t, g in zip(TAP_CHOICES, gains, strict=True) if g >= best - 0.5)


def design_migration_mask(
    cfg: Config, range_m: np.ndarray, taps: int | None = None
) -> MigrationMask:
    """The mask of (M2) for ``Processor.range_migration_taps`` (or ``taps``) interpolation taps.

    Azimuth part: design_mask (window, exact hyperbolic phase, 1/N).  Range part:
    interpolation_weights at Δr_k(r) of migration_bins.  Returns a MigrationMask (complex128).
    """
    taps = cfg.processor.range_migration_taps if taps is None else taps
    if not (isinstance(taps, int) and taps >= 1):
        raise ValueError(f"range-migration taps must be an integer >= 1, got {taps!r}")
    base = design_mask(cfg, range_m)  # [N, Nr]
    shift = migration_bins(cfg, range_m)  # [N, Nr]
    first, w = interpolation_weights(shift, taps)
    lo, hi = int(first.min()), int(first.max()) + taps - 1
    offsets = np.arange(lo, hi + 1)
    out = np.zeros(base.shape + (len(offsets),), np.complex128)
    rows, cols = np.indices(base.shape)
    for j in range(taps):
        out[rows, cols, first - lo + j] = base * w[..., j]
    return MigrationMask(out, offsets, shift)


def shift_lines(lines: np.ndarray, offset: int) -> np.ndarray:
    """moved[p, r] = lines[p, r + offset], zero where r + offset leaves the swath."""
    out = np.zeros_like(lines)
    n = lines.shape[1]
    if offset >= 0:
        out[:, : max(0, n - offset)] = lines[:, offset:]
    else:
        out[:, -offset:] = lines[:, : n + offset]
    return out


def correlate_migration_reference(lines: np.ndarray, mask: MigrationMask) -> np.ndarray:
    """Float64 batch evaluation of (M2): lines[P, Nr] → image[P-N+1, Nr] (complex128)."""
    lines = np.asarray(lines, dtype=np.complex128)
    n, bins, _ = mask.taps.shape
    if lines.ndim != 2 or lines.shape[1] != bins:
        raise ValueError(f"lines must be [pulses, {bins}], got {lines.shape}")
    out = np.zeros((max(0, len(lines) - n + 1), bins), np.complex128)
    if not len(out):
        return out
    for t, offset in enumerate(mask.offsets):
        moved = np.lib.stride_tricks.sliding_window_view(shift_lines(lines, offset), n, axis=0)
        out += np.einsum("prk,kr->pr", moved, mask.taps[:, :, t])
    return out


class MigrationCorrelator(Correlator):
    """(M2) streamed: one inner correlator per bin offset, each fed moved lines, outputs summed.

    Built by rtsar.ccd.make_correlator from a MigrationMask; ``inner[t]`` correlates with
    ``mask.taps[:, :, t]`` in the wanted kind and precision.  Output timing (first line,
    blocks, flush) is that of the inner kind; memory and work are len(offsets) times theirs.
    Float32 error: that of the inner kind plus the rounding of the sum over offsets; relative
    RMS against correlate_migration_reference on crouch-sal echoes (T = 4, tests/
    test_hard_cases.py) 6.1e-8 fft, 1.5e-7 partitioned, 8.2e-7 direct; tested to 1e-5 (and
    complex128 to 1e-12, tests/test_migration.py).
    """

    def __init__(self, mask: MigrationMask, inner: list[Correlator]):
        if len(inner) != len(mask.offsets) or not inner:
            raise ValueError("one inner correlator per bin offset is needed")
        super().__init__(mask.taps[:, :, 0], inner[0].precision)
        for c in inner:
            if (c.aperture, c.range_bins, c.dtype) != (self.aperture, self.range_bins, self.dtype):
                raise ValueError("inner correlators must share aperture, range bins and precision")
        self.mask = mask
        self.offsets = np.asarray(mask.offsets)
        self.inner = list(inner)

    @property
    def taps(self) -> int:
        return len(self.inner)

    def _sum(self, outs: list[np.ndarray]) -> np.ndarray:
        total = outs[0]
        for o in outs[1:]:
            if o.shape != total.shape:  # pragma: no cover - the inner kinds are deterministic
                raise RuntimeError("inner correlators fell out of step")
            total = total + o
        self.lines_out += len(total)
        return total

    def push(self, lines: np.ndarray) -> np.ndarray:
        lines = self._check(lines)
        self.pulses_in += len(lines)
        pairs = zip(self.inner, self.offsets, strict=True)
        return self._sum([c.push(shift_lines(lines, int(o))) for c, o in pairs])

    def flush(self) -> np.ndarray:
        return self._sum([c.flush() for c in self.inner])

    def close(self) -> None:
        for c in self.inner:
            c.close()


class FFTMigrationCorrelator(FFTCorrelator):
    """(M2) by overlap-save, filtering each block's spectrum with every range tap (M3).

    Same interface, block length (``fft_length``) and timing as FFTCorrelator; per block one
    forward and one inverse transform and len(offsets) multiply-adds per spectral sample, where
    MigrationCorrelator would run len(offsets) whole FFT correlators.
    """

    def __init__(
        self, mask: MigrationMask, fft_length: int | None = None, precision: str = "complex64"
    ):
        super().__init__(mask.taps[:, :, 0], fft_length, precision)
        n, m = self.aperture, self.fft_length
        self.mask = mask
        self.offsets = np.asarray(mask.offsets)
        h = np.zeros((m, self.range_bins), np.complex128)
        self._H_taps = []
        for t in range(len(self.offsets)):
            h[:n] = mask.taps[::-1, :, t]
            self._H_taps.append(sfft.fft(h, axis=0).astype(self.dtype))
        self._H = None  # replaced by the taps
        self._out = np.zeros((m, self.range_bins), self.dtype)
        self._tmp = np.zeros_like(self._out)

    @property
    def taps(self) -> int:
        return len(self.offsets)

    def _filter(self, spec: np.ndarray) -> np.ndarray:
        out, tmp = self._out, self._tmp  # kept between blocks: no page faults per block
        out[:] = 0
        bins = self.range_bins
        for o, h in zip(self.offsets.tolist(), self._H_taps, strict=True):
            # out[:, r] += spec[:, r + o] · H_t[:, r] where r + o is inside the swath
            lo, hi = max(0, -o), min(bins, bins - o)
            if lo < hi:
                np.multiply(spec[:, lo + o : hi + o], h[:, lo:hi], out=tmp[:, lo:hi])
                out[:, lo:hi] += tmp[:, lo:hi]
        return out


@dataclass(frozen=True)
class Walk:
    """The fit (W1) of rtsar.ccd.walk_deskew: w bins a pulse, c(r) per column, and the
    curvature it leaves."""

    bins_per_pulse: float
    offset_bins: np.ndarray  # c(r), float64[bins]
    curvature_max_bins: float  # max |ε| over the rows the window weighs
    curvature_rms_bins: float  # RMS of ε over the window's energy

    @property
    def offset_mid_bins(self) -> float:
        return float(self.offset_bins[len(self.offset_bins) // 2])


def fit_walk(cfg, range_m: np.ndarray) -> Walk:
    """(W1) for the configuration's mask on the lens's range axis ``range_m``."""
    shift = migration_bins(cfg, range_m)  # [N, bins], (M1)
    energy = mask_window(cfg, range_m) ** 2  # design_mask's |·|², but its 1/N² and phase
    energy = energy / np.maximum(energy.sum(axis=0, keepdims=True), np.finfo(float).tiny)
    k = np.arange(shift.shape[0], dtype=np.float64)[:, None]
    k_mean = (energy * k).sum(axis=0)
    d_mean = (energy * shift).sum(axis=0)
    var = (energy * (k - k_mean) ** 2).sum(axis=0)
    cov = (energy * (k - k_mean) * (shift - d_mean)).sum(axis=0)
    slopes = cov / np.maximum(var, np.finfo(float).tiny)
    w = float(np.average(slopes))  # the walk is one slope: the squint is one angle
    offset = d_mean - w * k_mean
    eps = shift - w * k - offset
    weighed = energy > 0
    return Walk(
        bins_per_pulse=w,
        offset_bins=offset,
        curvature_max_bins=float(np.abs(eps[weighed]).max()),
        curvature_rms_bins=float(np.sqrt((energy * eps * eps).sum(axis=0).max())),
    )


MOST_CURVATURE_BINS = 1.0  # the curvature the walk's ring may leave out (RADARSAT-1's: 0.45)


@functools.lru_cache(maxsize=16)
def walk_leaves_bins(cfg: Config) -> float:
    """The curvature, in bins, that the walk's ring (rtsar.ccd.walk_deskew) would leave out of
    ``cfg``'s plan: fit_walk's largest residual on the lens's range axis (0.1-0.3 s for
    RADARSAT-1's, so kept for the configurations a run asks about again)."""
    return fit_walk(cfg, range_axis_m(cfg)).curvature_max_bins
