"""Projective SAL: two images of one object, a quarter turn apart about the beam axis → 3-D points.

A SAL image is the projection of the scene onto the plane of the aperture and the beam (Crouch
ch. 8, Fig. 31): it measures cross-range x and range y; the out-of-plane z is lost.  Turning the
object by φ about the beam axis (a rotation stage) makes the second image's cross-range
x_φ = x cos φ - z sin φ.  With images at φ_a and φ_b (φ_b - φ_a = 90°: Fig. 32) each scatterer
seen in both gives

    [x_a, x_b]ᵀ = [[cos φ_a, -sin φ_a], [cos φ_b, -sin φ_b]] · [x, z]ᵀ,  y from both ranges.

The two images must be told which scatterer is which: the only coordinate they share is range.
Two association rules, as Crouch used them for simple objects:

* ``points``: the 2-D peaks of each image; a peak pairs with the one peak of the other image
  within ``range_tolerance_m`` in range, and only when that pairing is mutual and unique; a range
  cell holding several peaks in either image is reported ambiguous (several 3-D solutions fit),
  never guessed.
* ``line``: one scatterer per range cell (a stick, Crouch's toothpick): in every range column
  the brightest cross-range position of each image; a column whose second peak is within
  ``second_peak_db`` of the first in either image is ambiguous and left out.

Positions are refined to sub-pixel by a parabola through the peak's power and its neighbours.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Reconstruction:
    """3-D points [n, 3] (x, y, z in the image frame, metres), their peak power (dB re the
    brightest), and the ranges (m) that could not be resolved with what was in each image."""

    points_m: np.ndarray
    power_db: np.ndarray
    ambiguous: list = field(default_factory=list)  # (range_m, peaks in a, peaks in b)
    rule: str = "points"

    def summary(self) -> str:
        return (
            f"{len(self.points_m)} 3-D points ({self.rule} rule); "
            f"{len(self.ambiguous)} range cells ambiguous"
        )


def _parabola(p_minus: float, p0: float, p_plus: float) -> float:
    den = p_minus - 2 * p0 + p_plus
    return 0.0 if den >= 0 else float(np.clip(0.5 * (p_minus - p_plus) / den, -0.5, 0.5))


def image_peaks(image: np.ndarray, x_m, y_m, threshold_db: float) -> np.ndarray:
    """2-D local maxima of |image|² above ``threshold_db`` re the brightest: [n, 3] (x, y, dB)."""
    p = np.abs(np.asarray(image)) ** 2
    top = float(p.max())
    if not top > 0:
        return np.zeros((0, 3))
    pad = np.pad(p, 1, constant_values=-1.0)
    core = pad[1:-1, 1:-1]
    is_max = core >= top * 10 ** (threshold_db / 10)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            if di or dj:
                nb = pad[1 + di : pad.shape[0] - 1 + di, 1 + dj : pad.shape[1] - 1 + dj]
                is_max &= core > nb if (di, dj) < (0, 0) else core >= nb
    out = []
    dx, dy = x_m[1] - x_m[0], y_m[1] - y_m[0]
    for i, j in zip(*np.nonzero(is_max), strict=True):
        fi = _parabola(*pad[i : i + 3, j + 1]) if 0 < i < p.shape[0] - 1 else 0.0
        fj = _parabola(*pad[i + 1, j : j + 3]) if 0 < j < p.shape[1] - 1 else 0.0
        out.append((x_m[i] + fi * dx, y_m[j] + fj * dy, 10 * math.log10(p[i, j] / top)))
    return np.array(out).reshape(-1, 3)


def _solve(xa, xb, phi_a, phi_b):
    m = _matrix(phi_a, phi_b)
    return np.linalg.solve(m, np.stack([np.atleast_1d(xa), np.atleast_1d(xb)]))


def _matrix(phi_a, phi_b):
    m = np.array([[math.cos(phi_a), -math.sin(phi_a)], [math.cos(phi_b), -math.sin(phi_b)]])
    if abs(np.linalg.det(m)) < 0.1:
        raise ValueError("the two rotations must differ by about a quarter turn (got parallel)")
    return m


def reconstruct_points(
    a, b, x_m, y_m, phi_a: float, phi_b: float, threshold_db=-10.0, range_tolerance_m=None
) -> Reconstruction:
    """The ``points`` rule (module docstring); images a, b [x, y] on the same axes."""
    _matrix(phi_a, phi_b)
    tol = abs(y_m[1] - y_m[0]) * 1.5 if range_tolerance_m is None else range_tolerance_m
    pa, pb = image_peaks(a, x_m, y_m, threshold_db), image_peaks(b, x_m, y_m, threshold_db)
    pts, power, ambiguous, seen = [], [], [], set()
    for i, (xa, ya, da) in enumerate(pa):
        near_b = np.flatnonzero(np.abs(pb[:, 1] - ya) <= tol)
        near_a = np.flatnonzero(np.abs(pa[:, 1] - ya) <= tol)
        if len(near_b) == 1 and len(near_a) == 1:
            xb, yb, db = pb[near_b[0]]
            x, z = _solve(xa, xb, phi_a, phi_b)[:, 0]
            pts.append((x, 0.5 * (ya + yb), z))
            power.append(min(da, db))
        elif i not in seen:
            seen.update(near_a.tolist())
            ambiguous.append((float(ya), len(near_a), len(near_b)))
    return Reconstruction(np.array(pts).reshape(-1, 3), np.array(power), ambiguous, "points")


def _column_peak(col: np.ndarray, second_db: float):
    """(index + sub-pixel, power, unambiguous?) of the brightest entry of a power column."""
    i = int(np.argmax(col))
    frac = _parabola(col[i - 1], col[i], col[i + 1]) if 0 < i < len(col) - 1 else 0.0
    rest = col.copy()
    lo, hi = max(i - 2, 0), i + 3  # the mainlobe ± 2 cells (oversampled image)
    rest[lo:hi] = 0
    # a second local maximum elsewhere within second_db: another scatterer in this range cell
    unique = rest.max() < col[i] * 10 ** (second_db / 10)
    return i + frac, col[i], unique


def reconstruct_line(
    a, b, x_m, y_m, phi_a: float, phi_b: float, threshold_db=-15.0, second_peak_db=-6.0
) -> Reconstruction:
    """The ``line`` rule (module docstring): one 3-D point per range column seen in both."""
    _matrix(phi_a, phi_b)
    pa, pb = np.abs(np.asarray(a)) ** 2, np.abs(np.asarray(b)) ** 2
    floor_a = pa.max() * 10 ** (threshold_db / 10)
    floor_b = pb.max() * 10 ** (threshold_db / 10)
    dx = x_m[1] - x_m[0]
    pts, power, ambiguous = [], [], []
    for j, y in enumerate(y_m):
        ia, va, ua = _column_peak(pa[:, j], second_peak_db)
        ib, vb, ub = _column_peak(pb[:, j], second_peak_db)
        if va < floor_a or vb < floor_b:
            continue
        if not (ua and ub):
            ambiguous.append((float(y), 1 if ua else 2, 1 if ub else 2))
            continue
        x, z = _solve(x_m[0] + ia * dx, x_m[0] + ib * dx, phi_a, phi_b)[:, 0]
        pts.append((x, y, z))
        power.append(10 * math.log10(min(va / pa.max(), vb / pb.max())))
    return Reconstruction(np.array(pts).reshape(-1, 3), np.array(power), ambiguous, "line")


def line_distance_m(points_m: np.ndarray, p0, p1) -> np.ndarray:
    """Distance of each point to the infinite line through p0 and p1."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    u = (p1 - p0) / np.linalg.norm(p1 - p0)
    d = np.asarray(points_m) - p0
    return np.linalg.norm(d - np.outer(d @ u, u), axis=1)
