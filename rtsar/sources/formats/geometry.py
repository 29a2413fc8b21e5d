"""rtsar's local frame on the Earth: the positions CPHD and SICD need (ECF, WGS-84).

rtsar works in a local frame: x along track, y cross-track towards the scene, z up, the
reference plane z = 0 (rtsar.scene.relief).  The exports place that frame on the WGS-84
ellipsoid at a reference latitude/longitude (default 0°, 0°) with the track heading
``heading_deg`` clockwise from north (default 80°, east by north), y to its right (heading
+ 90°), z up: the platform looks to its right (the usual side, and SICD's columns then run with
time).  The default heading is no cardinal direction on purpose: due east, the scene lies due
south and the bearing of the platform seen from it is north, 0°/360°, the wrap of SICD's
SCPCOA angles, where round-off decided on which side sarpy's and sarkit's checks computed it
(files written before carry no heading and were east, 90°).  The placement is a mirror image
(x, y, z is left-handed): it keeps every distance, so every range and every sample is
unchanged.  A recording without a platform height (the
slant-plane geometry of the papers) is placed at ``DEFAULT_HEIGHT_FRACTION`` of its centre range
above the plane: every slant range, and so every sample, is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WGS84_A_M = 6378137.0
WGS84_F = 1.0 / 298.257223563
DEFAULT_HEIGHT_FRACTION = 0.5  # platform height / centre range where a recording has none
DEFAULT_HEADING_DEG = 80.0  # the track's heading (module docstring)
EAST_HEADING_DEG = 90.0  # the heading of files written before the heading was recorded


def geodetic_to_ecf(lat_deg: float, lon_deg: float, height_m: float) -> np.ndarray:
    """WGS-84 geodetic → Earth-centred, Earth-fixed (ECF) metres (NIMA TR8350.2, eq. 4-14)."""
    lat, lon = np.radians(lat_deg), np.radians(lon_deg)
    e2 = WGS84_F * (2 - WGS84_F)
    n = WGS84_A_M / np.sqrt(1 - e2 * np.sin(lat) ** 2)
    return np.array(
        [
            (n + height_m) * np.cos(lat) * np.cos(lon),
            (n + height_m) * np.cos(lat) * np.sin(lon),
            (n * (1 - e2) + height_m) * np.sin(lat),
        ]
    )


@dataclass(frozen=True)
class LocalFrame:
    """The local frame's origin (ECF) and its axes (ECF unit vectors, rows of ``axes``):
    x along the heading, y to its right, z up."""

    lat_deg: float = 0.0
    lon_deg: float = 0.0
    heading_deg: float = DEFAULT_HEADING_DEG

    @property
    def origin_ecf(self) -> np.ndarray:
        return geodetic_to_ecf(self.lat_deg, self.lon_deg, 0.0)

    @property
    def axes(self) -> np.ndarray:
        lat, lon = np.radians(self.lat_deg), np.radians(self.lon_deg)
        east = np.array([-np.sin(lon), np.cos(lon), 0.0])
        north = np.array([-np.sin(lat) * np.cos(lon), -np.sin(lat) * np.sin(lon), np.cos(lat)])
        up = [np.cos(lat) * np.cos(lon), np.cos(lat) * np.sin(lon), np.sin(lat)]
        h = np.radians(self.heading_deg)
        along = np.sin(h) * east + np.cos(h) * north
        right = np.cos(h) * east - np.sin(h) * north  # the heading + 90°
        return np.array([along, right, up])

    def to_ecf(self, xyz_m: np.ndarray) -> np.ndarray:
        """Local points [..., 3] → ECF [..., 3]."""
        return self.origin_ecf + np.asarray(xyz_m, np.float64) @ self.axes

    def vectors_to_ecf(self, v: np.ndarray) -> np.ndarray:
        """Local vectors (velocities, unit vectors) [..., 3] → ECF."""
        return np.asarray(v, np.float64) @ self.axes

    def from_ecf(self, ecf_m: np.ndarray) -> np.ndarray:
        """ECF points [..., 3] → local [..., 3]."""
        return (np.asarray(ecf_m, np.float64) - self.origin_ecf) @ self.axes.T


def platform_height_m(slant_range_m: float, recorded_height_m: float) -> float:
    """The platform height the exports use: the recorded one, else a fraction of the range."""
    return recorded_height_m if recorded_height_m > 0 else DEFAULT_HEIGHT_FRACTION * slant_range_m


def platform_positions_m(
    along_track_m: np.ndarray, height_m: float, position_m: np.ndarray | None = None
) -> np.ndarray:
    """Per-pulse platform positions [pulse, 3] in the local frame: ``position_m`` where the
    recording has it, else (x_p, 0, height)."""
    if position_m is not None:
        return np.asarray(position_m, np.float64)
    along = np.asarray(along_track_m, np.float64)
    return np.stack([along, np.zeros_like(along), np.full_like(along, height_m)], axis=-1)
