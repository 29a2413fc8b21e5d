"""Interferometric SAL: two focused complex images → a height map (Zhao 2014, Fig. 2, steps II-VI).

Step I (focusing each receiver's channel) is the engine's; this module does the rest:

II   registration: integer offset from the peak of the intensity cross-correlation (Crouch ch. 6,
     "Image Registration"), sub-pixel offset by maximising the mean local coherence; the slave is
     resampled by a Fourier shift along range and a windowed-sinc FIR along azimuth
III  interferogram  I = M · conj(S)
IV   flat-earth removal: from geometry (the exact phase of the reference plane at each slant range,
     InsalGeometry) or from the fringe frequency (mean phase step, or the refined peak of the 2-D
     spectrum; Crouch ch. 6, "Flat Earth Effect")
V    multilook (boxcar sum of I, no decimation), coherence |ΣMS*|/sqrt(Σ|M|²Σ|S|²), mask by
     coherence and intensity
VI   2-D unwrapping (rtsar.topo.unwrap contract) and phase → height through the exact geometry.

Axes: image[azimuth line, range bin] (the engine's); heights in metres above the reference plane,
0.0 where masked (never NaN; ``valid`` says which).  Phases are formed in float64 and reduced
mod 2π before they become complex exponentials.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from ..phase import TWO_PI, wrap
from .insar_geometry import InsalGeometry
from .looks import box_sum
from .registration import Registration, estimate_registration, shift_image
from .unwrap import unwrap_quality

# ---- step II: registration ------------------------------------------------------------------


# ---- steps III-V: interferogram, flat earth, multilook, coherence, mask ------------------------
@dataclass(frozen=True)
class FringeRamp:
    """A linear phase 2π (f_az·line + f_rg·bin) + φ0 (Crouch ch. 6: Fourier analysis of fringes)."""

    azimuth_cycles_per_line: float
    range_cycles_per_bin: float
    phase_rad: float = 0.0

    def phasor(self, lines: np.ndarray, bins: np.ndarray) -> np.ndarray:
        cycles = (
            np.mod(self.azimuth_cycles_per_line * np.asarray(lines, np.float64), 1.0)[:, None]
            + np.mod(self.range_cycles_per_bin * np.asarray(bins, np.float64), 1.0)[None, :]
            + self.phase_rad / TWO_PI
        )
        return np.exp(1j * TWO_PI * np.mod(cycles, 1.0))


def _dominant_phase(x: np.ndarray, bins: int = 72) -> float:
    """Most common phase of the non-zero pixels (circular histogram peak, refined by the mean)."""
    phase = np.angle(x[np.abs(x) > 0])
    if phase.size == 0:
        return 0.0
    counts, edges = np.histogram(phase, bins, (-math.pi, math.pi))
    smooth = counts + np.roll(counts, 1) + np.roll(counts, -1)
    k = int(np.argmax(smooth))
    centre = 0.5 * (edges[k] + edges[k + 1])
    near = phase[np.abs(wrap(phase - centre)) < 3 * TWO_PI / bins]
    return float(np.angle(np.sum(np.exp(1j * near)))) if near.size else centre


def estimate_fringe_ramp(
    ifg: np.ndarray, valid: np.ndarray | None = None, method: str = "gradient", pad: int = 4
) -> FringeRamp:
    """Flat-earth fringe frequency of an interferogram (Crouch ch. 6: "Fourier analysis of the
    interferogram fringes could also make an estimate of the phase ramp").

    method "gradient": the mean of the wrapped phase steps between valid neighbours along each
    axis (give a multilooked interferogram).  Their sum telescopes to the phase change across the
    scene, so a target whose base lies at one height at both ends of the image does not bias it.
    method "peak": the peak of |DFT| zero padded ``pad`` times, refined by maximising
    |Σ I exp(-i2π(f_az i + f_rg j))|, the least-squares frequency of one complex sinusoid: best
    on a plane, pulled by the fringes of a target that fills much of the image.
    The constant is the most common residual phase, so the scene's largest flat area (its base)
    comes out at height 0.  Remove the ramp with ifg * conj(ramp.phasor(lines, bins)).
    """
    x = np.asarray(ifg, np.complex128)
    ok = np.abs(x) > 0 if valid is None else (np.asarray(valid, bool) & (np.abs(x) > 0))
    x = np.where(ok, x, 0)
    rows, cols = x.shape
    li, lj = np.arange(rows), np.arange(cols)
    if method == "gradient":
        p = np.angle(x)
        f = []
        for axis in (0, 1):
            step = wrap(np.diff(p, axis=axis))
            pair = ok[1:] & ok[:-1] if axis == 0 else ok[:, 1:] & ok[:, :-1]
            f.append(float(np.mean(step[pair])) / TWO_PI if pair.any() else 0.0)
    elif method == "peak":
        spec = np.abs(np.fft.fft2(x, (pad * rows, pad * cols)))
        i, j = np.unravel_index(int(np.argmax(spec)), spec.shape)
        f0 = np.array([np.fft.fftfreq(pad * rows)[i], np.fft.fftfreq(pad * cols)[j]])

        def total(f):
            return np.sum(x * np.conj(FringeRamp(f[0], f[1]).phasor(li, lj)))

        step = np.array([0.5 / (pad * rows), 0.5 / (pad * cols)])
        res = optimize.minimize(
            lambda f: -abs(total(f)),
            f0,
            method="Nelder-Mead",
            options={
                "initial_simplex": [f0, f0 + [step[0], 0], f0 + [0, step[1]]],
                "xatol": 1e-7,
                "fatol": 1e-12 * max(1.0, abs(total(f0))),
            },
        )
        f = res.x if -res.fun >= abs(total(f0)) else f0
    else:
        raise ValueError("method must be 'gradient' or 'peak'")
    ramp = FringeRamp(float(f[0]), float(f[1]))
    return FringeRamp(
        ramp.azimuth_cycles_per_line,
        ramp.range_cycles_per_bin,
        _dominant_phase(x * np.conj(ramp.phasor(li, lj))),
    )


@dataclass(frozen=True)
class Interferogram:
    """Flat-earth-free, multilooked interferogram of a block of lines (steps III-V)."""

    filtered: np.ndarray  # complex128: Σ over the looks window of M S* exp(-iφ_flat)
    coherence: np.ndarray  # float64 in [0, 1]
    intensity: np.ndarray  # float64: window mean of (|M|² + |S|²)/2
    valid: np.ndarray  # bool: registered, full enough window, coherent and bright enough

    @property
    def wrapped_rad(self) -> np.ndarray:
        return np.angle(self.filtered)


def form_interferogram(
    main,
    slave,
    registration: Registration,
    flat_earth: np.ndarray,
    looks=(5, 3),
    coherence_min: float = 0.3,
    intensity_floor: float | None = None,
    taps: int = 16,
    main_line_ok: np.ndarray | None = None,
    slave_line_ok: np.ndarray | None = None,
) -> Interferogram:
    """Zhao steps III-V on one block: I = M conj(S_reg) · conj(flat_earth), boxcar, coherence, mask.

    ``flat_earth``: phasor exp(iφ_flat) broadcastable to the image (per range bin from
    InsalGeometry.flat_earth_phasor, or a FringeRamp's phasor).  A pixel is valid when it and at
    least half of its window were registered, coherence ≥ coherence_min and (if given) the window
    mean intensity ≥ intensity_floor.  ``*_line_ok`` (bool per line): lines known bad (e.g.
    zeroed for NaN) take no part and their pixels are not valid.
    """
    m = np.asarray(main, np.complex128)
    s, ok = shift_image(slave, registration.azimuth_px, registration.range_px, taps)
    rows = m.shape[0]
    if main_line_ok is not None:
        ok &= np.asarray(main_line_ok, bool)[:, None]
    if slave_line_ok is not None:  # slave line i + d lands on main line i
        src = np.arange(rows) + int(round(registration.azimuth_px))
        inside = (src >= 0) & (src < rows)
        ok &= (inside & np.asarray(slave_line_ok, bool)[np.clip(src, 0, rows - 1)])[:, None]
    w = ok.astype(np.float64)
    ifg = m * np.conj(s) * np.conj(flat_earth) * w
    count = box_sum(w, looks)
    filtered = box_sum(ifg, looks)
    pm = box_sum(np.abs(m) ** 2 * w, looks)
    ps = box_sum(np.abs(s) ** 2 * w, looks)
    den = np.sqrt(pm * ps)
    with np.errstate(invalid="ignore", divide="ignore"):
        coherence = np.where(den > 0, np.abs(filtered) / np.where(den > 0, den, 1.0), 0.0)
        intensity = np.where(count > 0, 0.5 * (pm + ps) / np.maximum(count, 1.0), 0.0)
    coherence = np.minimum(coherence, 1.0)
    valid = ok & (count >= 0.5 * looks[0] * looks[1]) & (coherence >= coherence_min)
    if intensity_floor is not None:
        valid &= intensity >= intensity_floor
    return Interferogram(filtered, coherence, intensity, valid)


# ---- step VI: unwrap, phase → height ------------------------------------------------------
LOW_PERCENTILE = 10.0  # the absolute 2π cycle rule without reference pixels (see below)


def absolute_cycle_shift(unwrapped, mask, percentile: float = LOW_PERCENTILE) -> float:
    """The multiple of 2π that puts the ``percentile``-th percentile of the unwrapped phase of
    ``mask`` in [-π, π).

    InSAL measures heights modulo h_2π: the absolute cycle is not in the data (Zhao 2014 reads
    relative heights).  With pixels known to lie on the reference plane, their median (50) fixes
    it.  Without them rtsar assumes that the scene's lower part (its lowest 10 % of heights,
    low_scene_percentile: the plate or ground an object stands on) lies within ±h_2π/2 of the
    reference plane.  A median over the
    whole scene would put every pixel one cycle low wherever the raised part covers most of the
    image (a 2.5 mm ridge filling a narrow range window: median above h_2π/2 = 1.65 mm).
    """
    if not mask.any():
        return 0.0
    level = float(np.percentile(unwrapped[mask], percentile))
    return -TWO_PI * math.floor(level / TWO_PI + 0.5)


def low_scene_percentile(geometry, range_m) -> float:
    """The phase percentile of the scene's lower part: LOW_PERCENTILE where phase grows with
    height, 100 - LOW_PERCENTILE where it falls (the sign of the geometry's phase-height law)."""
    r = float(np.mean(range_m))
    rises = geometry.height_from_phase(r, 1.0) > geometry.height_from_phase(r, 0.0)
    return LOW_PERCENTILE if rises else 100.0 - LOW_PERCENTILE


@dataclass(frozen=True)
class HeightMap:
    height_m: np.ndarray  # float64[azimuth, range], 0.0 where not valid
    valid: np.ndarray  # bool
    coherence: np.ndarray
    wrapped_rad: np.ndarray
    unwrapped_rad: np.ndarray
    registration: Registration
    fringe_ramp: FringeRamp | None  # the estimated flat earth (None: from geometry)

    @property
    def masked_pixels(self) -> int:
        return int(self.valid.size - self.valid.sum())


def height_map(
    main,
    slave,
    geometry: InsalGeometry,
    range_m,
    *,
    registration: Registration | None = None,
    subpixel: str = "both",
    looks=(5, 3),
    flat_earth: str = "geometry",
    coherence_min: float = 0.3,
    intensity_floor: float | None = None,
    method: str = "mcf",
    reference_mask: np.ndarray | None = None,
    fringe_method: str = "gradient",
) -> HeightMap:
    """The whole chain (Zhao Fig. 2, II-VI) on two focused images [azimuth, range].

    flat_earth: "geometry" (exact reference-plane phase per slant range) or "fringes" (a ramp
    estimated by estimate_fringe_ramp(method=fringe_method) on the multilooked interferogram:
    heights are then relative to the scene's largest flat area).  The absolute 2π cycle
    puts the median unwrapped phase over ``reference_mask`` (pixels on the reference plane) in
    [-π, π); without a mask, the lowest 10 % of heights over every valid pixel
    (absolute_cycle_shift).  This is the float64 batch reference of
    rtsar.topo.stream.HeightStripStage.
    """
    m = np.asarray(main, np.complex128)
    s = np.asarray(slave, np.complex128)
    r = np.asarray(range_m, np.float64)
    if m.shape != s.shape or m.ndim != 2 or m.shape[1] != len(r):
        raise ValueError(f"images {m.shape}, {s.shape} and range axis {r.shape} do not match")
    if not (np.isfinite(m).all() and np.isfinite(s).all()):
        raise ValueError("images hold NaN or Inf")
    reg = registration or estimate_registration(m, s, subpixel)
    ramp = None
    fe = geometry.flat_earth_phasor(r)[None, :]
    if flat_earth == "fringes":
        raw = form_interferogram(m, s, reg, np.ones(1), looks, coherence_min, intensity_floor)
        ramp = estimate_fringe_ramp(raw.filtered, raw.valid, fringe_method)
        fe = ramp.phasor(np.arange(m.shape[0]), np.arange(m.shape[1]))
    elif flat_earth != "geometry":
        raise ValueError("flat_earth must be 'geometry' or 'fringes'")
    ifg = form_interferogram(m, s, reg, fe, looks, coherence_min, intensity_floor)
    wrapped = np.where(ifg.valid, ifg.wrapped_rad, 0.0)
    unw = unwrap_quality(wrapped, ifg.valid, method, ifg.coherence)
    if reference_mask is None:
        shift = absolute_cycle_shift(unw, ifg.valid, low_scene_percentile(geometry, r))
    else:
        shift = absolute_cycle_shift(unw, ifg.valid & reference_mask, percentile=50.0)
    unw = np.where(ifg.valid, unw + shift, 0.0)
    h = np.where(ifg.valid, geometry.height_from_phase(r[None, :], unw), 0.0)
    return HeightMap(h, ifg.valid, ifg.coherence, wrapped, unw, reg, ramp)


def height_error(height_m, valid, truth_m, score_mask) -> dict:
    """RMS, bias and max |error| of the valid estimated heights on ``score_mask``, and coverage.

    With no valid pixel on the mask the error entries are None (coverage 0), never NaN.
    """
    use = valid & score_mask
    n = int(score_mask.sum())
    if not use.any():
        return {"rms_m": None, "bias_m": None, "max_abs_m": None, "coverage": 0.0, "pixels": 0}
    e = height_m[use] - truth_m[use]
    return {
        "rms_m": float(np.sqrt(np.mean(e * e))),
        "bias_m": float(np.mean(e)),
        "max_abs_m": float(np.max(np.abs(e))),
        "coverage": float(use.sum() / max(n, 1)),
        "pixels": int(use.sum()),
    }
