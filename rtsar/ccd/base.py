"""The shifting CCD with mask: azimuth compression as a time-integrating correlator.

Psaltis & Wagner 1981, "Description of the processor" and eq. 5: every range-compressed pulse is
multiplied by a mask whose transmittance along the shift direction is the azimuth chirp (its rate
k1/y0 depends on range, so the mask is two-dimensional), added into the CCD, and the charge
shifts one row per pulse; the row that reaches the readout register after N pulses is a finished
image line.  Here a circular row index replaces the physical shift:

    g[p, r] = Σ_{k=0}^{N-1} line[p - N + 1 + k, r] · mask[k, r]            (1)

line p is the pulse at aperture position k = N-1 of the line that completes with it.  Output line
j = p - (N - 1) (p ≥ N - 1) is focused at the aperture centre, along-track
x = x_0 + (j + (N - 1)/2) d.  Each output sums exactly N terms from a zeroed row, so nothing can
drift however long the stream runs.

Three implementations of (1) behind one interface (push lines, get finished lines):
DirectCorrelator (the emulation: a numba shift register, O(N) per pixel per pulse, one line per
pulse), FFTCorrelator (overlap-save blocks, O(log N), lines leave in blocks of about N) and
PartitionedCorrelator (uniformly partitioned overlap-save, O(N/L) per pixel per pulse, lines leave
in blocks of L ≪ N).  correlate_reference is the NumPy float64 batch version all are tested
against.

Precision (``Processor.precision``): every correlator takes ``precision="complex64"`` (default:
float32 lines, mask and sums) or ``"complex128"`` (float64 throughout).  Measured relative RMS
error against correlate_reference (tests/test_precision.py: N = 2048, 64 range bins, a
unit-modulus mask / N, complex Gaussian lines; the tested tolerance in brackets): complex64
direct 8.1e-7, fft 1.5e-7, partitioned 1.9e-7 [1e-5]; complex128 direct 0 (the reference's
summation order), fft and partitioned 1.6e-15 [1e-12].  Range-migration correction (a
mask with a third, range-tap axis) lives in rtsar.ccd.migration; the physical CCD in
rtsar.ccd.physical; rtsar.ccd.make_correlator builds any of them.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from ..lens.plan import range_axis_m
from ..params import Config
from ..samples import precision_dtype
from ..windows import window, window_at


def aperture_offsets_m(cfg: Config) -> np.ndarray:
    """Platform offset u_k of each aperture row from the closest approach of the scatterer the
    line focuses: u_k = (k - (N-1)/2)·d + u_mid.

    Broadside u_mid = 0: the aperture is centred on closest approach.  A squinted beam (Doppler
    centroid f_dc, sin θ = -λ f_dc / 2V) sees a scatterer of closest-approach range R0 around
    u_c = R0 tan θ; u_mid is u_c at the processor's range centre, so that the rows follow the
    beam and the line still lands on the scatterer's zero-Doppler position (line_azimuth_m).
    """
    n = cfg.processor.aperture_pulses
    return (np.arange(n) - 0.5 * (n - 1)) * cfg.geometry.along_track_step_m + beam_look_back_m(cfg)


def _range_centre_m(cfg: Config) -> float:
    return cfg.processor.range_centre_m or cfg.geometry.slant_range_m


def beam_look_back_m(cfg: Config) -> float:
    """u_mid: the squinted beam's centre offset R0 tan θ at the processor's range centre, by
    which a line's zero-Doppler position trails its aperture centre (0 broadside)."""
    return cfg.geometry.beam_centre_offset_m(_range_centre_m(cfg))


def squint_cos_less_one(cfg: Config) -> float:
    """cos θ - 1 of the beam's squint (Geometry.squint_sin), formed without cancellation as
    -sin²θ / (1 + cos θ): what the range spectrum's centre 2 (cos θ - 1) / λ cycles a metre
    of a squinted image takes (rtsar.analysis.point_target, the SICD export)."""
    s = cfg.geometry.squint_sin
    return -s * s / (1.0 + math.sqrt(1.0 - s * s))


def squint_aperture_pulses(cfg: Config) -> int:
    """Rows of the mask each range column uses: all N broadside; with squint, N less the rows
    the beam centre u_c = R0 tan θ moves across the swath (the mask of each column follows its
    own beam, so every line of the image is one zero-Doppler time; Psaltis & Wagner's mask is
    two-dimensional already)."""
    n = cfg.processor.aperture_pulses
    g = cfg.geometry
    if not g.squinted:
        return n
    r = range_axis_m(cfg)
    span = abs(g.beam_centre_offset_m(float(r[-1] - r[0]))) / g.along_track_step_m
    rows = n - math.ceil(span) - 1
    if rows < 2:
        raise ValueError(
            f"aperture_pulses {n} leaves no aperture: the squinted beam's centre moves "
            f"{span:.1f} rows across the swath"
        )
    return rows


def azimuth_cell_m(cfg: Config, slant_range_m: float | None = None) -> float:
    """λR/(2L), unweighted (Crouch eq. 4.8), with L the aperture each range column uses:
    squint_aperture_pulses rows (Config.azimuth_resolution_m takes all N; a squinted plan's
    CCD holds N = aperture + the rows its beam centre walks, RADARSAT-1 668 + 48)."""
    g = cfg.geometry
    r = g.slant_range_m if slant_range_m is None else slant_range_m
    return g.wavelength_m * r / (2.0 * squint_aperture_pulses(cfg) * g.along_track_step_m)


def mask_window(cfg: Config, range_m: np.ndarray) -> np.ndarray:
    """The azimuth window of each mask column, float64[N, len(range_m)].

    Broadside: Processor.azimuth_window over the N rows, the same for every column.  Squinted:
    the window over squint_aperture_pulses rows centred on the column's beam centre
    u_c(R0) = R0 tan θ (evaluated at the exact row positions), zero elsewhere.
    """
    proc = cfg.processor
    n = proc.aperture_pulses
    g = cfg.geometry
    if not g.squinted:
        return np.broadcast_to(window(proc.azimuth_window, n)[:, None], (n, len(range_m)))
    rows = squint_aperture_pulses(cfg)
    d = g.along_track_step_m
    u = aperture_offsets_m(cfg)[:, None]
    centre = g.beam_centre_offset_m(np.asarray(range_m, np.float64))[None, :]
    # position within the column's aperture, 0 … 1 across its rows (window_at's convention)
    pos = (u - centre) / (d * (rows - 1)) + 0.5
    inside = (pos >= 0.0) & (pos <= 1.0)
    return np.where(inside, window_at(proc.azimuth_window, np.clip(pos, 0.0, 1.0)), 0.0)


def design_mask(cfg: Config, range_m: np.ndarray) -> np.ndarray:
    """Mask[k, r] (complex128): conjugate of the expected azimuth phase history, windowed.

    The expected phase of a scatterer at closest-approach range R seen from offset u_k is
    -4π/λ·(sqrt(R² + u_k²) - R) (exact range history; Psaltis eq. 2 is its parabolic limit
    k1/y0·x²; u_k of aperture_offsets_m, which follows a squinted beam, so the mask carries the
    Doppler centroid and the range-dependent FM rate of the hyperbola at each bin).  With
    ``per_bin_mask`` each range column uses its own R (the k1/y0 dependence); otherwise every
    column uses the range centre.  Windowed by mask_window; scaled by 1/(rows used), so a
    unit-amplitude history compresses to a unit peak with the rectangular window.  Phase formed
    in float64, reduced mod 2π before the exponential.
    """
    proc = cfg.processor
    x = aperture_offsets_m(cfg)[:, None]
    if proc.per_bin_mask:
        r = np.asarray(range_m, dtype=np.float64)[None, :]
    else:
        r = np.full((1, len(range_m)), float(_range_centre_m(cfg)))
    # sqrt(R² + x²) - R = x² / (sqrt(R² + x²) + R): no cancellation for x ≪ R.
    excess_m = x * x / (np.sqrt(r * r + x * x) + r)
    cycles = np.mod(2.0 * excess_m / cfg.geometry.wavelength_m, 1.0)
    w = mask_window(cfg, range_m)
    return w * np.exp(2j * math.pi * cycles) / squint_aperture_pulses(cfg)


def correlate_reference(lines: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Float64 batch evaluation of eq. (1): lines[P, Nr] → image[P-N+1, Nr] (complex128)."""
    lines = np.asarray(lines, dtype=np.complex128)
    mask = np.asarray(mask, dtype=np.complex128)
    n = mask.shape[0]
    if lines.ndim != 2 or lines.shape[1] != mask.shape[1]:
        raise ValueError(f"lines must be [pulses, {mask.shape[1]}], got {lines.shape}")
    if lines.shape[0] < n:
        return np.zeros((0, mask.shape[1]), np.complex128)
    windows = sliding_window_view(lines, n, axis=0)  # [P-N+1, Nr, N]
    return np.einsum("prk,kr->pr", windows, mask)


class Correlator(ABC):
    """Common interface: push range-compressed lines, receive finished image lines.

    ``precision`` ("complex64" or "complex128", see Processor.precision) sets ``dtype``: the type
    lines are cast to by ``_check`` and the type of every line returned.  Subclasses written
    before the knob existed call ``super().__init__(mask)`` and stay complex64.
    """

    def __init__(self, mask: np.ndarray, precision: str = "complex64"):
        mask = np.asarray(mask)
        if mask.ndim != 2 or mask.shape[0] < 2:
            raise ValueError("mask must be [N >= 2, range_bins]")
        self.aperture = mask.shape[0]
        self.range_bins = mask.shape[1]
        self.precision = precision
        self.dtype = precision_dtype(precision)
        self.pulses_in = 0
        self.lines_out = 0

    def _check(self, lines: np.ndarray) -> np.ndarray:
        lines = np.asarray(lines)
        if lines.ndim != 2 or lines.shape[1] != self.range_bins:
            raise ValueError(f"lines must be [pulses, {self.range_bins}], got {lines.shape}")
        return np.ascontiguousarray(lines, dtype=self.dtype)

    def _no_lines(self) -> np.ndarray:
        return np.zeros((0, self.range_bins), self.dtype)

    @abstractmethod
    def push(self, lines: np.ndarray) -> np.ndarray:
        """Add lines[pulse, range_bin]; return the image lines they completed."""

    def flush(self) -> np.ndarray:
        """Emit every line whose pulses have all arrived (nothing is ever held back after this)."""
        return self._no_lines()

    def close(self) -> None:
        """The stream is over: release what the correlator runs beside it (the nonuniform
        correlator's thread); nothing for the others."""
        return None


def line_azimuth_m(
    cfg: Config,
    start_along_track_m: float,
    first_line: int,
    count: int,
    look_back_m: float | None = None,
) -> np.ndarray:
    """Along-track position of image lines first_line … first_line + count - 1.

    Line j is the line whose N-pulse aperture ends with pulse j + N - 1; it is focused at the
    aperture centre x_0 + (j + (N - 1)/2) d (module docstring, eq. 1), less the squinted
    beam's offset u_mid (aperture_offsets_m): the scatterers' closest approach, zero-Doppler
    geometry.  ``look_back_m``: u_mid where the caller keeps it (beam_look_back_m: a stream
    asks for every strip's lines).
    """
    n = cfg.processor.aperture_pulses
    j = np.arange(first_line, first_line + count)
    step_m = cfg.geometry.along_track_step_m
    u_mid = beam_look_back_m(cfg) if look_back_m is None else look_back_m
    return start_along_track_m + (j + 0.5 * (n - 1)) * step_m - u_mid
