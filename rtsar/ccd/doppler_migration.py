"""Range migration in the overlap-save block's azimuth spectrum: one shift per frequency.

rtsar.ccd.migration evaluates the two-dimensional mask (M2) exactly: per block, every range-tap
offset o_t filters the spectrum, Y[f, r] = Σ_t X[f, r + o_t] · H_t[f, r] (M3), with as many
offsets as bins the range history spans.  A squinted beam's walk spans tens of bins (RADARSAT-1:
22 + the taps), so (M3) costs tens of spectral multiply-adds per sample.  But each H_t is the
azimuth DFT of the mask's tap-t slice, and by stationary phase the azimuth frequency f of a
hyperbolic history belongs to one platform offset u, u / sqrt(R0² + u²) = -λ f / 2V: at f the
whole history sits at one range,

    R(f) = R0 / D(f),   D(f) = sqrt(1 - (λ f / 2V)²),
    Δ(f, r) = (R(f) - R0 - ΔR_label) / δR  bins beyond column r                            (M4)

(ΔR_label the squint label offset of rtsar.lens.plan.squint_label_offset_m), and (M3) collapses
to one fractional read per frequency and column:

    Y[f, r] = H[f, r] · Σ_j w_T(first + j - Δ(f, r)) · X[f, r + first + j],   first = ⌈Δ - T/2⌉

with H the azimuth mask's spectrum (rtsar.ccd.fft) and w_T the T-tap Lanczos interpolator of
rtsar.ccd.migration: T multiply-adds per sample whatever the walk — the range cell migration
correction of the range-Doppler algorithm, done inside the shifting CCD's block form.  The
frequency f of DFT bin k is k·PRF/M brought within PRF/2 of the Doppler centroid.  The weights
come from a table of PHASES fractional positions (the read is off by at most 1/(2·PHASES) bin).
Exact where the history is long (time-bandwidth product ≫ 1: RADARSAT-1's ~500); checked
against the time-domain (M2) in tests/test_doppler_migration.py.
"""

from __future__ import annotations

import numba
import numpy as np

from ..lens.plan import squint_label_offset_m
from ..params import Config
from .base import design_mask
from .fft import FFTCorrelator
from .migration import interpolation_weights

PHASES = 256  # fractional positions of the weight table (uint8 index)


def doppler_migration_bins(cfg: Config, range_m: np.ndarray, fft_length: int) -> np.ndarray:
    """Δ(f, r) of (M4), float64[fft_length, len(range_m)]: row k is DFT bin k of the block."""
    g = cfg.geometry
    range_m = np.asarray(range_m, np.float64)
    step_m = (range_m[-1] - range_m[0]) / (len(range_m) - 1)
    f = np.fft.fftfreq(fft_length, d=1.0 / g.prf_hz)
    f_dc = g.doppler_centroid_hz
    f = f_dc + np.mod(f - f_dc + 0.5 * g.prf_hz, g.prf_hz) - 0.5 * g.prf_hz
    s = g.wavelength_m * f / (2.0 * g.speed_mps)
    if np.any(np.abs(s) >= 1.0):
        raise ValueError("the Doppler band reaches the end-fire direction: no range migration")
    # R0 (1/D - 1) = R0 s² / (D (1 + D)): no cancellation for small s
    d = np.sqrt(1.0 - s * s)
    excess = (s * s / (d * (1.0 + d)))[:, None] * range_m[None, :]
    return (excess - squint_label_offset_m(cfg)) / step_m


@numba.njit(parallel=True, nogil=True, cache=True)
def _gather(spec, h, first, phase, table, out):  # pragma: no cover - compiled
    # out[f, r] = h[f, r] · Σ_j table[phase[f, r], j] · spec[f, r + first[f, r] + j]
    rows, bins = spec.shape
    taps = table.shape[1]
    for f in numba.prange(rows):
        for r in range(bins):
            base = r + first[f, r]
            w = table[phase[f, r]]
            acc = 0j
            for j in range(taps):
                c = base + j
                if 0 <= c < bins:
                    acc += w[j] * spec[f, c]
            out[f, r] = acc * h[f, r]


class DopplerMigrationCorrelator(FFTCorrelator):
    """(M4) by overlap-save: FFTCorrelator's blocks and timing, the range read per frequency.

    ``Processor.range_migration_domain = "doppler"`` with the "fft" correlator builds it
    (rtsar.ccd.make_ccd); ``taps`` is Processor.range_migration_taps.
    """

    def __init__(
        self,
        cfg: Config,
        range_m: np.ndarray,
        taps: int,
        fft_length: int | None = None,
        precision: str = "complex64",
    ):
        super().__init__(design_mask(cfg, range_m), fft_length, precision)
        shift = doppler_migration_bins(cfg, range_m, self.fft_length)
        # reads first + j, j < T, first = ⌈Δ - T/2⌉; q = (first + T/2 - Δ)·PHASES in [0, PHASES]
        first = np.ceil(shift - 0.5 * taps)
        q = np.round((first + 0.5 * taps - shift) * PHASES).astype(np.int64)
        carry = q == PHASES  # Δ = first + T/2 - 1 exactly: the same reads from one bin lower
        self._first = (first - carry).astype(np.int32)
        self._phase = np.where(carry, 0, q).astype(np.uint8)
        # table[q]: the T weights at Δ - first = T/2 - q / PHASES (interpolation_weights' first
        # read is then 0, so its weights are the table's row)
        _, table = interpolation_weights(0.5 * taps - np.arange(PHASES) / PHASES, taps)
        real = np.float32 if self.dtype == np.complex64 else np.float64
        self._table = table.astype(real)
        self.taps = taps
        self._moved = np.zeros((self.fft_length, self.range_bins), self.dtype)

    def _filter(self, spec: np.ndarray) -> np.ndarray:
        _gather(spec, self._H, self._first, self._phase, self._table, self._moved)
        return self._moved
