"""Real-aperture antenna pattern along track (two-way), Crouch eq. 4.9."""

from __future__ import annotations

import numpy as np

from .base import Effect


class AntennaPattern(Effect):
    """Two-way field pattern of a uniform aperture of length D along track.

    One way, the far field of a uniform aperture is sinc(D sinθ/λ) (first null at λ/D, so the
    footprint between the half-nulls is λR/D); transmit and receive through the same aperture give
    sinc²(D sinθ/λ), with sinθ = (x_target - x_platform)/R the along-track look angle.
    ``antenna_length_m`` overrides the geometry's D.
    """

    name = "antenna_pattern"

    def __init__(self, config, antenna_length_m: float | None = None):
        g = config.geometry
        self.d_over_lambda = (antenna_length_m or g.antenna_length_m) / g.wavelength_m
        if not self.d_over_lambda > 0:
            raise ValueError("antenna_pattern.antenna_length_m must be > 0")

    def target_gain(self, pulse, along_offset_m, slant_range_m):
        sin_theta = along_offset_m / slant_range_m
        return np.sinc(self.d_over_lambda * sin_theta) ** 2
