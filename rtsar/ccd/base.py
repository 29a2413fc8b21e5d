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

from ..params import Config
from ..samples import precision_dtype
from ..windows import window


def aperture_offsets_m(cfg: Config) -> np.ndarray:
    """Along-track offset of each aperture row from the aperture centre, x_k = (k-(N-1)/2)·d."""
    n = cfg.processor.aperture_pulses
    return (np.arange(n) - 0.5 * (n - 1)) * cfg.geometry.along_track_step_m


def design_mask(cfg: Config, range_m: np.ndarray) -> np.ndarray:
    """Mask[k, r] (complex128): conjugate of the expected azimuth phase history, windowed.

    The expected phase of a scatterer at closest-approach range R seen from offset x_k is
    -4π/λ·(sqrt(R² + x_k²) - R) (exact range history; Psaltis eq. 2 is its parabolic limit
    k1/y0·x²).  With ``per_bin_mask`` each range column uses its own R (the k1/y0 dependence);
    otherwise every column uses the range centre.  Scaled by 1/N, so a unit-amplitude history
    compresses to a unit peak with the rectangular window.  Phase formed in float64, reduced
    mod 2π before the exponential.
    """
    proc = cfg.processor
    x = aperture_offsets_m(cfg)[:, None]
    if proc.per_bin_mask:
        r = np.asarray(range_m, dtype=np.float64)[None, :]
    else:
        centre = proc.range_centre_m or cfg.geometry.slant_range_m
        r = np.full((1, len(range_m)), float(centre))
    # sqrt(R² + x²) - R = x² / (sqrt(R² + x²) + R): no cancellation for x ≪ R.
    excess_m = x * x / (np.sqrt(r * r + x * x) + r)
    cycles = np.mod(2.0 * excess_m / cfg.geometry.wavelength_m, 1.0)
    w = window(proc.azimuth_window, proc.aperture_pulses)[:, None]
    return w * np.exp(2j * math.pi * cycles) / proc.aperture_pulses


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
    cfg: Config, start_along_track_m: float, first_line: int, count: int
) -> np.ndarray:
    """Along-track position of image lines first_line … first_line + count - 1.

    Line j is the line whose N-pulse aperture ends with pulse j + N - 1; it is focused at the
    aperture centre x_0 + (j + (N - 1)/2) d (module docstring, eq. 1).
    """
    n = cfg.processor.aperture_pulses
    j = first_line + np.arange(count)
    return start_along_track_m + (j + 0.5 * (n - 1)) * cfg.geometry.along_track_step_m
