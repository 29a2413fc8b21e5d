"""Height strips in the stream: InSAL (Zhao 2014, Fig. 2, II-VI) on the lines of two engines.

Two engines (one per receiver) emit finished image lines; HeightStripStage takes them in stream
order, pairs them by line index and emits height strips of ``strip_lines`` lines:

* strip k holds lines [s, s + L), s = kL.  Its interferogram is formed on a block with
  ``margin`` more lines each side (registration FIR and multilook window), so every emitted
  pixel is computed exactly as rtsar.topo.insar.height_map computes it on the whole image;
* it is unwrapped on [s - O, s + L + O) (O = ``overlap_lines``): the emitted lines sit inside
  the unwrapping domain on both sides, and its first O lines are the previous strip's last
  lines, already unwrapped;
* the new strip's 2π cycle is the one that best matches the previous strip's unwrapped phase on
  those O shared lines (median of the difference), so heights stay continuous across strip
  boundaries.  A strip without a valid shared pixel falls back to the absolute rule of the first
  strip (the scene's lowest 10 % of heights within ±h_2π/2 of the reference plane:
  rtsar.topo.insar.absolute_cycle_shift, low_scene_percentile)
  and is counted in ``strips_not_aligned``.

Latency: a strip leaves L + O + margin lines after its first line.  Memory: the two line buffers
hold at most L + 2(O + margin) lines plus the last input batch, and O lines of phase.
The integrator publishes the strips on the ZeroMQ topic "height"; they come after the CCD.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..instrument import SECOND_RECEIVER
from .insar import form_interferogram, low_scene_percentile
from .insar_geometry import InsalGeometry
from .registration import Registration, estimate_registration
from .strip_unwrap import StripUnwrapper


@dataclass(frozen=True)
class HeightStrip:
    """Heights of lines first_line … first_line + len - 1: height_m[line, range_bin]."""

    first_line: int
    height_m: np.ndarray  # float64, 0.0 where not valid (never NaN)
    valid: np.ndarray  # bool
    coherence: np.ndarray  # float64
    aligned: bool  # False: the 2π cycle came from the absolute rule, not the previous strip

    def __len__(self):
        return len(self.height_m)


class HeightStripStage:
    """Stateful: ``process(main_lines, slave_lines) → [HeightStrip]``; ``flush()`` at the end.

    ``registration``: the slave's offset (rtsar.topo.insar.Registration); None estimates it once
    on the first ``strip_lines + 2·overlap_lines`` lines (``subpixel`` as estimate_registration)
    and keeps it.  ``flat_earth``: phasor per range bin (default: the geometry's reference plane).
    """

    kind = "insal"  # the 3D method, as --height names it
    channels = (SECOND_RECEIVER,)  # the auxiliary channel it reads beside the main one

    def __init__(
        self,
        geometry: InsalGeometry,
        range_m,
        registration: Registration | None = None,
        *,
        strip_lines: int = 32,
        overlap_lines: int = 8,
        looks=(5, 3),
        coherence_min: float = 0.3,
        intensity_floor: float | None = None,
        method: str = "mcf",
        flat_earth: np.ndarray | None = None,
        subpixel: str = "both",
        taps: int = 16,
    ):
        if not (isinstance(strip_lines, int) and isinstance(overlap_lines, int)):
            raise ValueError("strip_lines and overlap_lines must be integers")
        if not (1 <= overlap_lines <= strip_lines):
            raise ValueError("need 1 <= overlap_lines <= strip_lines")
        self.geometry = geometry
        self.range_m = np.asarray(range_m, np.float64)
        self.registration = registration
        self.strip_lines = strip_lines
        self.overlap_lines = overlap_lines
        self.looks = tuple(looks)
        self.coherence_min = coherence_min
        self.intensity_floor = intensity_floor
        self.method = method
        self.subpixel = subpixel
        self.taps = taps
        self._unwrapper = StripUnwrapper(method, low_scene_percentile(geometry, self.range_m))
        fe = geometry.flat_earth_phasor(self.range_m) if flat_earth is None else flat_earth
        self.flat_earth = np.asarray(fe, np.complex128).reshape(1, -1)
        bins = len(self.range_m)
        self._main = np.zeros((0, bins), np.complex128)
        self._slave = np.zeros((0, bins), np.complex128)
        self._main_ok = np.zeros(0, bool)  # False: the line held NaN/Inf (zeroed)
        self._slave_ok = np.zeros(0, bool)
        self._first = 0  # global line index of the buffers' row 0
        self._slave_in = 0
        self._next = 0  # first line of the next strip
        self._prev_last = None  # (height, valid) of line next - 1
        self._done = False
        self.lines_in = 0
        self.nonfinite_lines = 0  # lines holding NaN/Inf (zeroed; their pixels come out masked)
        self.strips_out = 0
        self.pixels_masked = 0
        self.max_boundary_jump_m = 0.0  # max |h(first line) - h(line before)| at strip boundaries
        self.max_interior_step_m = 0.0  # the same between neighbouring lines inside strips
        self.max_overlap_mismatch_m = 0.0  # max |Δh| on lines unwrapped by two strips

    @property
    def margin(self) -> int:
        az = 0.0 if self.registration is None else abs(self.registration.azimuth_px)
        return self.looks[0] // 2 + math.ceil(az) + self.taps // 2 + 1

    @property
    def buffered_lines(self) -> int:
        """Lines held in the larger of the two channel buffers."""
        return max(len(self._main), len(self._slave))

    def _clean(self, lines) -> tuple[np.ndarray, np.ndarray]:
        x = np.asarray(getattr(lines, "lines", lines))
        if x.ndim != 2 or x.shape[1] != len(self.range_m):
            raise ValueError(f"lines must be [count, {len(self.range_m)}], got {x.shape}")
        x = x.astype(np.complex128)
        bad = ~np.isfinite(x).all(axis=1)
        if bad.any():
            x[bad] = 0
            self.nonfinite_lines += int(bad.sum())
        return x, ~bad

    def process(self, main_lines, slave_lines) -> list[HeightStrip]:
        """Append lines of the two receivers (any counts, in order); emit the strips now ready."""
        if self._done:
            raise RuntimeError("process() after flush()")
        (m, m_ok), (s, s_ok) = self._clean(main_lines), self._clean(slave_lines)
        self._main = np.concatenate([self._main, m])
        self._slave = np.concatenate([self._slave, s])
        self._main_ok = np.concatenate([self._main_ok, m_ok])
        self._slave_ok = np.concatenate([self._slave_ok, s_ok])
        self.lines_in += len(m)
        self._slave_in += len(s)
        return self._run(final=False)

    def flush(self) -> list[HeightStrip]:
        """Emit the remaining lines (the last strip may be shorter); the stage is then closed."""
        out = self._run(final=True)
        self._done = True
        return out

    # -- internals ------------------------------------------------------------------------
    def _run(self, final: bool) -> list[HeightStrip]:
        paired = self._first + min(len(self._main), len(self._slave))
        if self.registration is None:
            need = self.strip_lines + 2 * self.overlap_lines
            if paired < need and not final:
                return []
            if paired < 2:  # nothing to register: the lines come out as they are
                self.registration = Registration(0.0, 0.0)
            else:
                k = min(need, paired) - self._first
                self.registration = estimate_registration(
                    self._main[:k], self._slave[:k], self.subpixel, taps=self.taps
                )
        out = []
        o, m = self.overlap_lines, self.margin
        while self._next < paired:
            stop = self._next + self.strip_lines
            if not final and paired < stop + o + m:
                break
            out.append(self._strip(self._next, min(stop, paired), paired, final))
            self._next = min(stop, paired)
        drop = max(0, self._next - o - m - self._first)
        self._main, self._slave = self._main[drop:], self._slave[drop:]
        self._main_ok, self._slave_ok = self._main_ok[drop:], self._slave_ok[drop:]
        self._first += drop
        return out

    def _strip(self, start: int, stop: int, paired: int, final: bool) -> HeightStrip:
        o, m = self.overlap_lines, self.margin
        u0, u1 = max(0, start - o), min(paired, stop + o)
        b0 = max(0, u0 - m)
        b1 = min(paired, u1 + m) if not final else paired
        rows = slice(b0 - self._first, b1 - self._first)
        ifg = form_interferogram(
            self._main[rows],
            self._slave[rows],
            self.registration,
            self.flat_earth,
            self.looks,
            self.coherence_min,
            self.intensity_floor,
            self.taps,
            self._main_ok[rows],
            self._slave_ok[rows],
        )
        dom = slice(u0 - b0, u1 - b0)
        valid = ifg.valid[dom]
        coherence = ifg.coherence[dom]
        n = start - u0  # lines shared with the previous strip
        prev_unw, prev_valid = self._unwrapper.prev_unw, self._unwrapper.prev_valid
        unw, aligned = self._unwrapper.unwrap(ifg.wrapped_rad[dom], valid, coherence, n)
        height = np.where(valid, self.geometry.height_from_phase(self.range_m[None, :], unw), 0.0)
        e0, e1 = start - u0, stop - u0
        if aligned:
            both = prev_valid[-n:] & valid[:n]
            prev_h = self.geometry.height_from_phase(self.range_m[None, :], prev_unw[-n:])
            self.max_overlap_mismatch_m = max(
                self.max_overlap_mismatch_m, float(np.max(np.abs(prev_h - height[:n])[both]))
            )
        h_out, v_out = height[e0:e1], valid[e0:e1]
        if self._prev_last is not None:
            ph, pv = self._prev_last
            both = pv & v_out[0]
            if both.any():
                jump = float(np.max(np.abs(h_out[0] - ph)[both]))
                self.max_boundary_jump_m = max(self.max_boundary_jump_m, jump)
        if len(h_out) > 1:
            both = v_out[1:] & v_out[:-1]
            if both.any():
                step = float(np.max(np.abs(np.diff(h_out, axis=0))[both]))
                self.max_interior_step_m = max(self.max_interior_step_m, step)
        keep = slice(max(e1 - o, 0), e1)
        self._unwrapper.keep(unw[keep], valid[keep])
        self._prev_last = (h_out[-1], v_out[-1])
        self.strips_out += 1
        self.pixels_masked += int(v_out.size - v_out.sum())
        return HeightStrip(start, h_out, v_out, coherence[e0:e1], aligned)

    @property
    def strips_not_aligned(self) -> int:
        return self._unwrapper.strips_not_aligned

    @property
    def stats(self) -> dict:
        return {
            "lines_in": self.lines_in,
            "strips_out": self.strips_out,
            "strips_not_aligned": self.strips_not_aligned,
            "nonfinite_lines": self.nonfinite_lines,
            "pixels_masked": self.pixels_masked,
            "max_boundary_jump_m": self.max_boundary_jump_m,
            "max_interior_step_m": self.max_interior_step_m,
            "max_overlap_mismatch_m": self.max_overlap_mismatch_m,
        }
