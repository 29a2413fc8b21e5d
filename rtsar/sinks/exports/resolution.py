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

A window weights the band and widens the response by its own factor
(rtsar.windows.impulse_response_width, computed from the taper itself).
"""

from __future__ import annotations

from dataclasses import dataclass

from ...params import C_M_PER_S, Config
from ...windows import impulse_response_width


@dataclass(frozen=True)
class Resolution:
    """One image axis: its spatial-frequency support and the window over it."""

    bandwidth_cycles_per_m: float
    window: str

    @property
    def irw_m(self) -> float:
        """-3 dB impulse-response width (m)."""
        return impulse_response_width(self.window) / self.bandwidth_cycles_per_m


def range_resolution(cfg: Config) -> Resolution:
    """The range (SICD Row) axis: support 2B/c, the processor's range window."""
    return Resolution(2.0 * cfg.waveform.bandwidth_hz / C_M_PER_S, cfg.processor.range_window)


def azimuth_resolution(cfg: Config, range_m: float) -> Resolution:
    """The azimuth (SICD Col) axis at closest-approach range ``range_m``: support 2Nd/(λR)."""
    g, p = cfg.geometry, cfg.processor
    aperture_m = p.aperture_pulses * g.along_track_step_m
    return Resolution(2.0 * aperture_m / (g.wavelength_m * range_m), p.azimuth_window)
