"""Real-aperture antenna pattern along track (two-way), Crouch eq. 4.9."""

from __future__ import annotations

import numpy as np

from .base import Effect


class AntennaPattern(Effect):
    """Two-way field pattern of a uniform aperture of length D along track.

    One way, the far field of a uniform aperture is sinc(D sinθ/λ) (first null at λ/D, so the
    footprint between the half-nulls is λR/D); transmit and receive through the same aperture give
    sinc²(D sinθ/λ), with sinθ = (x_target - x_platform)/R the along-track look angle.
    ``antenna_length_m`` overrides the geometry's D.  ``main_lobe_only``: the gain is 0 from the
    first nulls on (|D sinθ/λ| ≥ 1; the sidelobes, ≤ −27 dB two-way, are not simulated), so a
    scatterer is seen only while it is in the main lobe and the simulator skips it otherwise —
    what makes a scene of thousands of scatterers affordable live.
    """

    name = "antenna_pattern"

    def __init__(self, config, antenna_length_m: float | None = None, main_lobe_only: bool = False):
        g = config.geometry
        self.d_over_lambda = (antenna_length_m or g.antenna_length_m) / g.wavelength_m
        if not self.d_over_lambda > 0:
            raise ValueError("antenna_pattern.antenna_length_m must be > 0")
        if not isinstance(main_lobe_only, bool):
            raise ValueError("antenna_pattern.main_lobe_only must be true or false")
        self.main_lobe_only = main_lobe_only
        self.squint_sin = g.squint_sin

    def target_gain(self, pulse, along_offset_m, slant_range_m):
        # A squinted beam (Geometry.doppler_centroid_hz) points at sin θ = -λ f_dc / 2V behind
        # broadside for f_dc < 0: its centre is where (x_target - x_platform)/R = -sin θ.
        x = self.d_over_lambda * (along_offset_m / slant_range_m + self.squint_sin)
        gain = np.sinc(x) ** 2
        if self.main_lobe_only:
            gain = np.where(np.abs(x) < 1.0, gain, 0.0)
        return gain

    def along_track_support_m(self, max_slant_range_m):
        """First-null offset at the largest closest-approach range R: sinθ = λ/D with
        sinθ = x/sqrt(R² + x²), so |x| < R s/sqrt(1 - s²), s = λ/D (None: no bound)."""
        s = 1.0 / self.d_over_lambda + abs(self.squint_sin)  # the lobe's far edge
        if not self.main_lobe_only or s >= 1.0:
            return None
        return max_slant_range_m * s / np.sqrt(1.0 - s * s)
