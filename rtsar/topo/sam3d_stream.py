"""Spatial-amplitude-modulation 3D in the stream: per-pixel phase lines as S0, S1, S2 arrive."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .looks import box_mean
from .sam3d import (
    ModulationGeometry,
    check_thresholds,
    classify,
    modulation_phasor,
    resolve_flat_earth,
)


@dataclass
class SamLines:
    """Finished lines of ``SamPhaseStream``: the ``SamPhase`` fields of lines first_line..."""

    first_line: int
    wrapped_rad: np.ndarray  # [lines, range]
    coherence: np.ndarray
    valid: np.ndarray


class SamPhaseStream:
    """Eqs. 5-7 and the looks on image strips as the CCD finishes them (after the azimuth stage).

    ``push(s0, s1, s2)`` takes the next lines of the three focused channels [lines, range] and
    returns the lines whose azimuth look window is complete, (looks[0] - 1)/2 lines behind;
    ``flush()`` returns the rest.  The result equals ``sam_phase`` on the whole image given the
    same ``dark_floor`` (absolute: a percentile would need the future), ``noise_power`` and a
    flat-earth phase that depends on range only.  Memory: looks[0] - 1 lines of phasor and
    intensity.  Counters: lines_in, lines_out, masked_dark, masked_incoherent, masked_geometry.
    """

    def __init__(
        self,
        geometry: ModulationGeometry,
        range_m,
        dark_floor: float,
        flat_earth: str | tuple[np.ndarray, np.ndarray] = "geometry",
        looks: tuple[int, int] = (5, 3),
        min_coherence: float = 0.3,
        noise_power: float = 0.0,
    ):
        if dark_floor is None:
            raise ValueError("the stream needs an absolute dark_floor")
        check_thresholds(dark_floor, min_coherence, noise_power)
        self.noise_power = float(noise_power)
        box_mean(np.zeros((1, 1)), looks)  # validates looks
        self.geometry = geometry
        self.range_m = np.asarray(range_m, np.float64)
        phase, valid = resolve_flat_earth(flat_earth, self.range_m, geometry)
        if phase.size != self.range_m.size or valid.size != self.range_m.size:
            raise ValueError("the stream's flat-earth phase must depend on range only")
        sign_b = math.copysign(1.0, geometry.mask_depth_b)
        self._derotate = sign_b * np.exp(-1j * phase.reshape(-1))
        self._fe_valid = valid.reshape(-1)
        self.dark_floor = float(dark_floor)
        self.min_coherence = float(min_coherence)
        self.looks = (int(looks[0]), int(looks[1]))
        self._half = (self.looks[0] - 1) // 2
        bins = self.range_m.size
        self._z = np.zeros((0, bins), np.complex128)  # range-averaged rows not yet released
        self._p = np.zeros((0, bins))
        self._first_held = 0  # line index of self._z[0]
        self.lines_in = self.lines_out = 0
        self.masked_dark = self.masked_incoherent = self.masked_geometry = 0

    def push(self, s0, s1, s2) -> SamLines:
        z = modulation_phasor(s0, s1, s2, self.geometry.mask_offset_a, self.noise_power)
        if z.ndim != 2 or z.shape[1] != self.range_m.size:
            raise ValueError(f"lines must be [lines, {self.range_m.size}], got {z.shape}")
        la, lr = self.looks
        rows_z = box_mean(z * self._derotate, (1, lr))
        rows_p = box_mean(np.abs(np.asarray(s0, np.complex128)) ** 2, (1, lr))
        self._z = np.concatenate([self._z, rows_z])
        self._p = np.concatenate([self._p, rows_p])
        self.lines_in += len(z)
        return self._release(self.lines_in - self._half)

    def flush(self) -> SamLines:
        """Release the last lines (their look windows cut at the end of the image)."""
        return self._release(self.lines_in)

    def _release(self, stop: int) -> SamLines:
        start = self.lines_out
        count = max(0, stop - start)
        bins = self.range_m.size
        z_ml = np.zeros((count, bins), np.complex128)
        p_ml = np.zeros((count, bins))
        for k, j in enumerate(range(start, start + count)):
            lo = max(0, j - self._half) - self._first_held
            hi = min(self.lines_in, j + self._half + 1) - self._first_held
            z_ml[k] = self._z[lo:hi].sum(axis=0) / (hi - lo)
            p_ml[k] = self._p[lo:hi].sum(axis=0) / (hi - lo)
        coherence, geometric, dark, incoherent, valid = classify(
            z_ml,
            p_ml,
            self.noise_power,
            np.broadcast_to(self._fe_valid, z_ml.shape),
            self.geometry.mask_depth_b,
            self.dark_floor,
            self.min_coherence,
        )
        self.masked_dark += int(dark.sum())
        self.masked_incoherent += int(incoherent.sum())
        self.masked_geometry += int(geometric.sum())
        self.lines_out += count
        keep_from = max(0, self.lines_out - self._half) - self._first_held
        self._z, self._p = self._z[keep_from:], self._p[keep_from:]
        self._first_held += keep_from
        return SamLines(
            start,
            np.where(valid, np.angle(z_ml), 0.0),
            np.where(valid, coherence, 0.0),
            valid,
        )
