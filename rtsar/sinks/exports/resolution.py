"""What an rtsar strip-map image resolves: the bandwidths and -3 dB widths the exports declare.

Both follow from the processor that made the image, not from the instrument's antenna:

* Range (SICD Row): the AO lens keeps the chirp band B (pulsed: the matched filter's taper spans
  the band, rtsar.lens.plan; FMCW: the window spans the S beat samples of one sweep, Crouch
  eqs. 3.5-3.6), so the two-way spatial-frequency support is 2B/c cycles per metre and the
  unweighted width 0.886·c/(2B).
* Azimuth (SICD Col): the shifting CCD sums N pulses d apart (rtsar.ccd.base, eq. 1).  A
  scatterer at closest range R has the azimuth phase -2π x²/(λR), whose spatial frequency
  2x/(λR) spans 2Nd/(λR) over the aperture: the width is 0.886·λR/(2Nd) (Crouch eq. 4.8 with the
  synthetic aperture L = Nd), whatever the antenna's footprint λR/D.

A window weights the band and widens the response.  The weighting is described as it is
applied, a sequence of equal cells across the band (what SICD's WgtFunct holds and what its
readers derive the width from): the azimuth mask's N taps (rtsar.ccd.base: window(name, N), a
Hann's first and last 0), an FMCW range window's S beat samples (rtsar.lens.plan), a pulsed
chirp's spectral taper sampled at the centres of WEIGHT_CELLS cells (it is continuous over the
band).  A sequence longer than MAX_WEIGHTS (SICD readers warn) is resampled at WEIGHT_CELLS
cell centres, where it differs from the taper by less than 1e-4 of the width.  The declared
width is the one of that sequence (rtsar.windows.band_response_width), but for the windows
SICD readers size by name alone (NAMED_WIDTH: UNIFORM, HAMMING with coefficient 0.54, whatever
WgtFunct holds): there it is the continuous window's, which a 64-tap Hamming mask (tiny's N)
exceeds by 1.0 % (above 256 taps by < 0.3 %).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...ccd.base import squint_aperture_pulses
from ...params import C_M_PER_S, Config, FMCWChirp
from ...windows import band_response_width, impulse_response_width, window, window_at

WEIGHT_CELLS = 512  # SICD's recommended WgtFunct length
MAX_WEIGHTS = 1024  # longer: SICD readers warn; resampled to WEIGHT_CELLS
NAMED_WIDTH = ("rect", "hamming")  # sized by SICD readers from the window's name


def band_weights(name: str, taps: int | None = None) -> tuple[float, ...]:
    """The weighting of window ``name`` across the band: its ``taps`` samples as applied, or
    (None, or more than MAX_WEIGHTS) the taper at WEIGHT_CELLS cell centres."""
    if taps is not None and taps <= MAX_WEIGHTS:
        return tuple(float(v) for v in window(name, taps))
    u = (np.arange(WEIGHT_CELLS) + 0.5) / WEIGHT_CELLS
    return tuple(float(v) for v in window_at(name, u))


@dataclass(frozen=True)
class Resolution:
    """One image axis: its spatial-frequency support and the weighting over it."""

    bandwidth_cycles_per_m: float
    window: str
    weights: tuple[float, ...]  # the band's weighting as applied (band_weights)

    @property
    def irw_m(self) -> float:
        """-3 dB impulse-response width (m) of the weighted band."""
        if self.window in NAMED_WIDTH:
            return impulse_response_width(self.window) / self.bandwidth_cycles_per_m
        return band_response_width(self.weights) / self.bandwidth_cycles_per_m


def range_resolution(cfg: Config) -> Resolution:
    """The range (SICD Row) axis: support 2B/c, the processor's range window."""
    name = cfg.processor.range_window
    taps = cfg.waveform.samples_per_shot if isinstance(cfg.waveform, FMCWChirp) else None
    bw = 2.0 * cfg.waveform.bandwidth_hz / C_M_PER_S
    return Resolution(bw, name, band_weights(name, taps))


def azimuth_resolution(cfg: Config, range_m: float) -> Resolution:
    """The azimuth (SICD Col) axis at closest-approach range ``range_m``: support 2Nd/(λR), N
    the rows a range column's window covers (rtsar.ccd.base.squint_aperture_pulses: all the
    CCD's rows broadside, fewer where a squinted beam's centre walks across the swath)."""
    g, p = cfg.geometry, cfg.processor
    rows = squint_aperture_pulses(cfg)
    bw = 2.0 * rows * g.along_track_step_m / (g.wavelength_m * range_m)
    return Resolution(bw, p.azimuth_window, band_weights(p.azimuth_window, rows))
