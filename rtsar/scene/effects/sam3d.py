"""Spatial amplitude modulation of the return by its return angle (INO 3D patent, eqs. 1-4).

A mask in the receiver's back focal plane transmits the field focused at y_M = f φ with the
amplitude T(y_M) = a + b cos(2π y_M / P_y - n π/2) (patent eq. 1); with P_φ = P_y / f the
cosine (n = 0) and sine (n = 1) channels are

    S1 = S0 [a + b cos(2π φ / P_φ)],   S2 = S0 [a + b sin(2π φ / P_φ)]      (patent eqs. 3-4)

per scatterer, S0 being the unmodulated return (the simulator's main channel); a lateral offset
of the masks adds a phase θ_mask to 2πφ/P_φ.  Coherent (heterodyne) detection keeps the term
2|E_LO||E_T| cos θ, proportional to T (patent eq. 2), so each scatterer's complex gain in a
modulated channel is its main-channel gain times T(φ).

The return angle φ of a scatterer is the angle between the vertical and its line of sight, in
the plane perpendicular to the track (patent Fig. 3 and eq. 9): cos φ = (H0 - h) / R with
R = sqrt(r² + (H0 - h)²), r its ground range, h its height and H0 the platform height
(``geometry.platform_height_m``).  The mask phase 2πφ/P_φ is referred to the nadir, as in the
patent's flat-earth phase (eq. 7).  Assumed: the receiver's diffraction spot λf/D_rx is small
against the mask period P_y (P_φ ≫ λ/D_rx), so each scatterer sees T at one point.

This is the one-pass system with three detectors (patent [0038] case II, Fig. 10): the three
channels share every pulse, so platform and chirp errors are common to S0, S1, S2.  The split of
the return power between detectors is not modelled; ``snr_db`` (and the ``noise`` effect on
S0) can express it.  The scatterers' heights come from Targets.ground_range_m / height_m.
"""

from __future__ import annotations

import math

import numpy as np

from ...instrument import SAM_CHANNELS
from .base import Effect

CHANNELS = SAM_CHANNELS  # auxiliary channel names: cosine mask, sine mask


class AmplitudeModulation3D(Effect):
    """Cosine- and sine-masked receive channels S1, S2 beside the unmodulated main channel S0.

    Parameters
    ----------
    angular_period_rad
        P_φ = P_y / f, the angular period of the mask (patent eqs. 3-4).
    mask_offset_a, mask_depth_b
        The constants a, b of patent eq. 1 (a ≥ |b| for a passive transmission mask; the
        defaults a = b = 0.5 transmit between 0 and 1).
    mask_phase_rad
        θ, phase of the mask pattern at φ = 0: a lateral shift Δy of the masks gives
        θ = 2πΔy/P_y, so T1 = a + b cos(2πφ/P_φ + θ) (the patent's θ = 0).  Unknown to a
        processor that does not calibrate (patent eq. 15).
    snr_db
        Optional per-sample SNR of a unit-amplitude scatterer in each modulated channel
        (independent circular Gaussian noise, as the ``noise`` effect puts on the main channel);
        None: noise-free.
    """

    name = "amplitude_modulation_3d"

    def __init__(
        self,
        config,
        angular_period_rad: float,
        mask_offset_a: float = 0.5,
        mask_depth_b: float = 0.5,
        mask_phase_rad: float = 0.0,
        snr_db: float | None = None,
    ):
        for label, value in (
            ("angular_period_rad", angular_period_rad),
            ("mask_offset_a", mask_offset_a),
            ("mask_depth_b", mask_depth_b),
            ("mask_phase_rad", mask_phase_rad),
        ):
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"amplitude_modulation_3d.{label} must be a number, got {value!r}")
            if not math.isfinite(value):
                raise ValueError(f"amplitude_modulation_3d.{label} must be finite")
        if not angular_period_rad > 0:
            raise ValueError("amplitude_modulation_3d.angular_period_rad must be > 0")
        if mask_depth_b == 0:
            raise ValueError("amplitude_modulation_3d.mask_depth_b must be non-zero")
        if snr_db is not None and not (
            isinstance(snr_db, (int, float))
            and not isinstance(snr_db, bool)
            and math.isfinite(snr_db)
        ):
            raise ValueError("amplitude_modulation_3d.snr_db must be a finite number or None")
        self.platform_height_m = float(config.geometry.platform_height_m)
        if not self.platform_height_m > 0:
            raise ValueError(
                "amplitude_modulation_3d needs geometry.platform_height_m > 0 (the return angle "
                "is measured from the vertical)"
            )
        self.angular_period_rad = float(angular_period_rad)
        self.a = float(mask_offset_a)
        self.b = float(mask_depth_b)
        self.mask_phase_rad = float(mask_phase_rad)
        self.noise_sigma = None if snr_db is None else math.sqrt(0.5 * 10.0 ** (-snr_db / 10.0))
        self._cache: tuple[object, np.ndarray, np.ndarray] | None = None

    # -- the injected truth ---------------------------------------------------------------
    def return_angle_rad(self, targets) -> np.ndarray:
        """Return angle φ of every scatterer from the vertical (patent eq. 9), float64.

        Uses ``targets.ground_range_m`` and ``height_m`` when given (their slant range must
        agree with ``targets.slant_range_m``); without them the scatterers lie on the reference
        plane h = 0 and φ = arccos(H0 / R).
        """
        h0 = self.platform_height_m
        r_slant = np.asarray(targets.slant_range_m, np.float64)
        if targets.ground_range_m is None:
            if targets.height_m is not None and np.any(np.asarray(targets.height_m) != 0):
                raise ValueError("amplitude_modulation_3d: height_m needs ground_range_m")
            if np.any(r_slant < h0):
                raise ValueError(
                    "amplitude_modulation_3d: a scatterer's slant range is below the platform "
                    "height, so it cannot lie on the ground plane"
                )
            return np.arccos(h0 / r_slant)
        ground = np.asarray(targets.ground_range_m, np.float64)
        height = (
            np.zeros_like(ground)
            if targets.height_m is None
            else np.asarray(targets.height_m, np.float64)
        )
        below = h0 - height
        if np.any(below <= 0) or np.any(ground < 0):
            raise ValueError(
                "amplitude_modulation_3d: scatterers must lie below the platform, ground_range >= 0"
            )
        mismatch = np.abs(np.hypot(ground, below) - r_slant)
        if np.any(mismatch > 1e-9 * r_slant + 1e-12):
            raise ValueError(
                "amplitude_modulation_3d: Targets.slant_range_m disagrees with "
                f"hypot(ground_range_m, H0 - height_m) by up to {mismatch.max():.3g} m"
            )
        return np.arctan2(ground, below)

    def mask_gains(self, return_angle_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Amplitude transmissions (T1, T2) of the cosine and sine masks (patent eqs. 1, 3-4).

        T1 = a + b cos(2πφ/P_φ + θ), T2 = a + b sin(2πφ/P_φ + θ); the mask phase is formed in
        cycles in float64 and reduced to one period before the cos/sin.
        """
        cycles = np.mod(
            np.asarray(return_angle_rad, np.float64) / self.angular_period_rad
            + self.mask_phase_rad / (2.0 * math.pi),
            1.0,
        )
        phase = 2.0 * math.pi * cycles
        return self.a + self.b * np.cos(phase), self.a + self.b * np.sin(phase)

    def _gains_for(self, targets) -> tuple[np.ndarray, np.ndarray]:
        if self._cache is None or self._cache[0] is not targets:
            t1, t2 = self.mask_gains(self.return_angle_rad(targets))
            self._cache = (targets, t1, t2)
        return self._cache[1], self._cache[2]

    # -- simulator hook -------------------------------------------------------------------
    def aux_channels(self, ctx) -> dict[str, np.ndarray]:
        t1, t2 = self._gains_for(ctx.targets)
        out = {}
        for name, t in zip(CHANNELS, (t1, t2), strict=True):
            samples = ctx.echo(ctx.slant_range_m, ctx.gain * t)
            if self.noise_sigma is not None:
                noise = ctx.rng.standard_normal((2, samples.shape[-1]))
                samples = samples + self.noise_sigma * (noise[0] + 1j * noise[1])
            out[name] = samples
        return out
