"""Spatial-amplitude-modulation heights in the stream (INO 3D patent, eqs. 5-7, 13).

The three focused channels S0 (main), S1, S2 (rtsar.instrument.SAM_CHANNELS) arrive line block
by line block from their CCDs; rtsar.topo.sam3d_stream.SamPhaseStream forms the flat-earth-
corrected wrapped phase, its coherence and the masks (eqs. 5-7) as each line's look window
completes; rtsar.topo.strip_unwrap.StripUnwrapper unwraps strips of ``strip_lines`` lines with
``overlap_lines`` of overlap, continuous across strips; eq. 13 turns phase into height.  The
strips are rtsar.topo.stream.HeightStrip, published like InSAL's.

The stream needs an absolute dark floor (pixels with S0 ≈ 0 have no phase): it is calibrated
once, on the first ``strip_lines + 2·overlap_lines`` lines, as ``dark_fraction`` of the 99th
percentile of their look-averaged power <|S0|²> - N0 (the batch rule of
rtsar.topo.sam3d.sam_phase applied to that block), and kept.
"""

from __future__ import annotations

import numpy as np

from ..instrument import SAM_CHANNELS
from .insar import LOW_PERCENTILE
from .looks import box_mean
from .sam3d import ModulationGeometry, height_eq13_m
from .sam3d_stream import SamLines, SamPhaseStream
from .stream import HeightStrip
from .strip_unwrap import StripUnwrapper


class SamHeightStripStage:
    """``process(s0, s1, s2) → [HeightStrip]`` (focused lines [lines, range]); ``flush()``."""

    kind = "sam"  # the 3D method, as --height names it
    channels = SAM_CHANNELS  # the auxiliary channels it reads beside the main one (S0)

    def __init__(
        self,
        geometry: ModulationGeometry,
        range_m,
        *,
        strip_lines: int = 32,
        overlap_lines: int = 8,
        looks=(5, 3),
        min_coherence: float = 0.3,
        noise_power: float = 0.0,
        dark_fraction: float = 0.01,
        method: str = "mcf",
    ):
        if not (isinstance(strip_lines, int) and isinstance(overlap_lines, int)):
            raise ValueError("strip_lines and overlap_lines must be integers")
        if not (1 <= overlap_lines <= strip_lines):
            raise ValueError("need 1 <= overlap_lines <= strip_lines")
        if not (np.isfinite(dark_fraction) and 0 < dark_fraction < 1):
            raise ValueError(f"dark_fraction must be in (0, 1), got {dark_fraction!r}")
        self.geometry = geometry
        self.range_m = np.asarray(range_m, np.float64)
        self.strip_lines, self.overlap_lines = strip_lines, overlap_lines
        self.looks = (int(looks[0]), int(looks[1]))
        self.min_coherence, self.noise_power = float(min_coherence), float(noise_power)
        self.dark_fraction = float(dark_fraction)
        # Eq. 13 grows with the phase (h_2π > 0): the scene's lower part is its low phases.
        self._unwrapper = StripUnwrapper(method, LOW_PERCENTILE)
        self._phase: SamPhaseStream | None = None  # made once the dark floor is calibrated
        self._calibration: list[tuple] = []
        bins = self.range_m.size
        self._wrapped = np.zeros((0, bins))
        self._coherence = np.zeros((0, bins))
        self._valid = np.zeros((0, bins), bool)
        self._first = 0  # line index of the buffers' row 0
        self._next = 0  # first line of the next strip
        self.dark_floor: float | None = None
        self.lines_in = self.strips_out = self.pixels_masked = 0

    @property
    def strips_not_aligned(self) -> int:
        return self._unwrapper.strips_not_aligned

    def process(self, s0, s1, s2) -> list[HeightStrip]:
        self.lines_in += len(s0)
        if self._phase is None:
            self._calibration.append((s0, s1, s2))
            if (
                sum(len(c[0]) for c in self._calibration)
                < self.strip_lines + 2 * self.overlap_lines
            ):
                return []
            self._calibrate()
        else:
            self._add(self._phase.push(s0, s1, s2))
        return self._strips(final=False)

    def flush(self) -> list[HeightStrip]:
        """The last strips at the end of the stream."""
        if self._phase is None:
            if not self._calibration:
                return []
            self._calibrate()
        self._add(self._phase.flush())
        return self._strips(final=True)

    def _calibrate(self) -> None:
        s0 = np.concatenate([np.asarray(c[0], np.complex128) for c in self._calibration])
        power = box_mean(np.abs(s0) ** 2, self.looks) - self.noise_power
        top = float(np.percentile(power, 99)) if power.size else 0.0
        self.dark_floor = self.dark_fraction * top if top > 0 else 1e-30
        self._phase = SamPhaseStream(
            self.geometry,
            self.range_m,
            self.dark_floor,
            "geometry",
            self.looks,
            self.min_coherence,
            self.noise_power,
        )
        blocks, self._calibration = self._calibration, []
        for c in blocks:
            self._add(self._phase.push(*c))

    def _add(self, lines: SamLines) -> None:
        self._wrapped = np.concatenate([self._wrapped, lines.wrapped_rad])
        self._coherence = np.concatenate([self._coherence, lines.coherence])
        self._valid = np.concatenate([self._valid, lines.valid])

    def _strips(self, final: bool) -> list[HeightStrip]:
        out, o = [], self.overlap_lines
        ready = self._first + len(self._wrapped)
        while self._next < ready:
            stop = self._next + self.strip_lines
            if not final and ready < stop + o:
                break
            out.append(self._strip(self._next, min(stop, ready), ready))
            self._next = min(stop, ready)
        drop = max(0, self._next - o - self._first)
        self._wrapped, self._coherence = self._wrapped[drop:], self._coherence[drop:]
        self._valid = self._valid[drop:]
        self._first += drop
        return out

    def _strip(self, start: int, stop: int, ready: int) -> HeightStrip:
        o = self.overlap_lines
        u0, u1 = max(0, start - o), min(ready, stop + o)
        rows = slice(u0 - self._first, u1 - self._first)
        valid, coherence = self._valid[rows], self._coherence[rows]
        unw, aligned = self._unwrapper.unwrap(self._wrapped[rows], valid, coherence, start - u0)
        height = np.where(valid, height_eq13_m(unw, self.geometry), 0.0)
        e0, e1 = start - u0, stop - u0
        self._unwrapper.keep(unw[max(e1 - o, 0) : e1], valid[max(e1 - o, 0) : e1])
        self.strips_out += 1
        self.pixels_masked += int(valid[e0:e1].size - valid[e0:e1].sum())
        return HeightStrip(start, height[e0:e1], valid[e0:e1], coherence[e0:e1], aligned)

    @property
    def stats(self) -> dict:
        return {
            "lines_in": self.lines_in,
            "strips_out": self.strips_out,
            "strips_not_aligned": self.strips_not_aligned,
            "pixels_masked": self.pixels_masked,
            "dark_floor": self.dark_floor or 0.0,
        }
