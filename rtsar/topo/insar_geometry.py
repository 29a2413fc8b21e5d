"""The interferometric geometry of two receivers: phase of a height, flat earth, h_2π (Zhao 2014).

Zhao's eq. 1 lacks a π and is per fixed ground position; per image pixel h_2π = λR sinθ/B⊥
(InsalGeometry.ambiguity_height_m; docs/pages/guide/3d.md explains the 3.286 mm decision).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..phase import TWO_PI, phasor

# Zhao's side-looking angle makes his eq. 1 give 2π per 3.3 mm; see InsalGeometry.
ZHAO_LOOK_ANGLE_RAD = math.atan(math.sqrt(2.0))


@dataclass(frozen=True)
class InsalGeometry:
    """Cross-track geometry of a two-receiver interferometer and its phase-height relation.

    Frame (as rtsar.scene.effects.receivers): y horizontal cross-track, z up from the reference
    plane; main antenna (transmitter and receiver 0) at (0, H); the second phase centre at
    (0, H) + B (cos α, sin α).  A scatterer at slant range R (from the main antenna) and height h
    lies at ground range y = sqrt(R² - (H - h)²).  The interferogram arg(M·S*) holds

        φ(R, h) = (2π p / λ) (R_rx - R_tx),   p = passes (1: one transmitter, 2: two passes)

    Ambiguity height.  R_rx - R_tx ≈ -b·l̂ (l̂ the line of sight), so moving the scatterer by δ
    changes it by -(b_⊥·δ_⊥)/R: only the baseline component B_⊥ = B |cos(θ - α)| across the line
    of sight counts (θ the look angle from the vertical).  A pixel is a fixed slant range; there,
    raising the scatterer by h moves it across the line of sight by h / sinθ, so

        δφ = 2π p B_⊥ h / (λ R sinθ),      h_2π = λ R sinθ / (p B_⊥).

    Zhao 2014 eq. 1, φ = -2π B (y0 sinΦ - z0 cosΦ)/(λ0 L0), gives at fixed y0 2π per
    λ0 L0 / (B cosΦ) = √2 λ0 L0 / B = 3.29 mm for L0 = 2.4 m, B = 1.6 mm, λ0 = 1.55 µm, Φ = 45°.
    With a horizontal baseline (α = 0, B_⊥ = B cosθ) the per-pixel h_2π = λ R tanθ / B takes that
    same value at tanθ = √2 (θ = 54.7°, ZHAO_LOOK_ANGLE_RAD): our "Zhao geometry".
    """

    wavelength_m: float
    platform_height_m: float
    baseline_m: float
    baseline_angle_deg: float = 0.0
    passes: int = 1

    def __post_init__(self):
        for name in ("wavelength_m", "platform_height_m", "baseline_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"InsalGeometry.{name} must be finite and > 0, got {value!r}")
        if not math.isfinite(self.baseline_angle_deg):
            raise ValueError("InsalGeometry.baseline_angle_deg must be finite")
        if self.passes not in (1, 2):
            raise ValueError("InsalGeometry.passes must be 1 (one pass) or 2 (two passes)")

    @classmethod
    def from_config(cls, config, baseline_m, baseline_angle_deg=0.0, passes=1) -> InsalGeometry:
        g = config.geometry
        return cls(g.wavelength_m, g.platform_height_m, baseline_m, baseline_angle_deg, passes)

    @property
    def baseline_yz_m(self) -> tuple[float, float]:
        a = math.radians(self.baseline_angle_deg)
        return self.baseline_m * math.cos(a), self.baseline_m * math.sin(a)

    def _depth(self, slant_range_m, height_m):
        r = np.asarray(slant_range_m, np.float64)
        depth = self.platform_height_m - np.asarray(height_m, np.float64)
        if np.any(r <= np.abs(depth)):
            raise ValueError("slant range must exceed the platform height above the scatterer")
        return r, depth

    def ground_range_m(self, slant_range_m, height_m=0.0) -> np.ndarray:
        r, depth = self._depth(slant_range_m, height_m)
        return np.sqrt(r * r - depth * depth)

    def look_angle_rad(self, slant_range_m, height_m=0.0) -> np.ndarray:
        """θ, the angle of the line of sight from the vertical."""
        r, depth = self._depth(slant_range_m, height_m)
        return np.arccos(depth / r)

    def path_difference_m(self, slant_range_m, height_m) -> np.ndarray:
        """R_rx - R_tx, formed as (R_rx² - R_tx²)/(R_rx + R_tx) (no cancellation)."""
        r, depth = self._depth(slant_range_m, height_m)
        y = np.sqrt(r * r - depth * depth)
        by, bz = self.baseline_yz_m
        r_rx = np.sqrt((y - by) ** 2 + (depth + bz) ** 2)
        return (-2.0 * y * by + by * by + 2.0 * depth * bz + bz * bz) / (r_rx + r)

    def phase_rad(self, slant_range_m, height_m) -> np.ndarray:
        """φ(R, h) = 2π p (R_rx - R_tx)/λ, float64, not reduced (thousands of radians)."""
        return (
            TWO_PI
            * self.passes
            * self.path_difference_m(slant_range_m, height_m)
            / (self.wavelength_m)
        )

    def flat_earth_phasor(self, slant_range_m) -> np.ndarray:
        """exp(i φ(R, 0)): the reference plane's interferogram (phase reduced mod 2π first)."""
        return phasor(self.phase_rad(slant_range_m, 0.0))

    def height_sensitivity_rad_per_m(self, slant_range_m, height_m=0.0) -> np.ndarray:
        """∂φ/∂h at fixed slant range (central difference of the exact phase, step 10 µm)."""
        step = 1e-5
        hi = self.phase_rad(slant_range_m, np.asarray(height_m) + step)
        lo = self.phase_rad(slant_range_m, np.asarray(height_m) - step)
        return (hi - lo) / (2.0 * step)

    def ambiguity_height_m(self, slant_range_m) -> np.ndarray:
        """Height per 2π of interferometric phase at a pixel, from the exact geometry."""
        return TWO_PI / np.abs(self.height_sensitivity_rad_per_m(slant_range_m))

    def perpendicular_baseline_m(self, slant_range_m) -> np.ndarray:
        """B_⊥ = B |cos(θ - α)|, the baseline across the line of sight."""
        theta = self.look_angle_rad(slant_range_m)
        return self.baseline_m * np.abs(np.cos(theta - math.radians(self.baseline_angle_deg)))

    def ambiguity_height_closed_form_m(self, slant_range_m) -> np.ndarray:
        """h_2π = λ R sinθ / (p B_⊥) (class docstring; first order in B/R)."""
        r = np.asarray(slant_range_m, np.float64)
        theta = self.look_angle_rad(r)
        return (
            self.wavelength_m * r * np.sin(theta) / (self.passes * self.perpendicular_baseline_m(r))
        )

    def height_from_phase(self, slant_range_m, phase_rad, iterations: int = 4) -> np.ndarray:
        """Invert φ(R, h) - φ(R, 0) = phase for h (Newton from h = phase/∂φ/∂h)."""
        r = np.asarray(slant_range_m, np.float64)
        target = np.asarray(phase_rad, np.float64)
        r, target = np.broadcast_arrays(r, target)
        base = self.phase_rad(r, 0.0)
        h = target / self.height_sensitivity_rad_per_m(r)
        for _ in range(iterations):
            h = h - (self.phase_rad(r, h) - base - target) / self.height_sensitivity_rad_per_m(r, h)
        return h


def zhao_ambiguity_height_m(wavelength_m, range_m, baseline_m, side_looking_angle_rad) -> float:
    """Zhao 2014 eq. 1 at fixed y0: 2π of φ_inf per λ0 L0 / (B cosΦ) of elevation z0."""
    return wavelength_m * range_m / (baseline_m * math.cos(side_looking_angle_rad))
