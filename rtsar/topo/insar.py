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

TWO_PI = 2.0 * math.pi
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
        return np.exp(1j * np.mod(self.phase_rad(slant_range_m, 0.0), TWO_PI))

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


# ---- step II: registration ------------------------------------------------------------------
@dataclass(frozen=True)
class Registration:
    """Slave line i + azimuth_px, bin j + range_px shows what the main shows at (i, j)."""

    azimuth_px: float
    range_px: float
    coherence: float | None = None  # mean local coherence after resampling (None: not measured)


def integer_offset(main: np.ndarray, slave: np.ndarray) -> tuple[int, int]:
    """Peak of the cross-correlation of the two intensity images (mean removed, zero padded)."""
    a = np.abs(np.asarray(main, np.complex128)) ** 2
    b = np.abs(np.asarray(slave, np.complex128)) ** 2
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"images must be 2-D and of one shape, got {a.shape} and {b.shape}")
    shape = (2 * a.shape[0], 2 * a.shape[1])
    spec = np.conj(np.fft.fft2(a - a.mean(), shape)) * np.fft.fft2(b - b.mean(), shape)
    c = np.fft.ifft2(spec).real  # c[d] = Σ_i a[i] b[i + d]
    i, j = np.unravel_index(int(np.argmax(c)), c.shape)
    return (
        int(i - shape[0]) if i >= shape[0] // 2 else int(i),
        int(j - shape[1]) if j >= shape[1] // 2 else int(j),
    )


def _sinc_taps(frac: float, taps: int) -> np.ndarray:
    """Lanczos-windowed sinc for x(n + frac), support t = -taps/2 + 1 … taps/2, unit DC gain."""
    t = np.arange(-taps // 2 + 1, taps // 2 + 1) - frac
    h = np.sinc(t) * np.sinc(t / (taps / 2))
    return h / h.sum()


def shift_image(image: np.ndarray, azimuth_px: float, range_px: float, taps: int = 16):
    """out[i, j] = image[i + azimuth_px, j + range_px] → (complex128 out, valid bool).

    Crouch ch. 6 ("Image Registration": Fourier-based shifting).  Range: Fourier shift of each
    line (zero padded to twice its length, so nothing wraps in).
    Azimuth: the integer part by indexing, the fraction by a ``taps``-point windowed sinc (a local
    operation, so a block of lines gives the same rows as the whole image ``taps``/2 lines away
    from the block's ends).  Rows and columns whose sample point falls outside the image are
    zero and not valid.
    """
    x = np.asarray(image, np.complex128)
    rows, cols = x.shape
    valid = np.ones(x.shape, bool)
    if range_px:
        n = 1 << (2 * cols - 1).bit_length()
        ramp = np.exp(1j * np.mod(TWO_PI * np.fft.fftfreq(n) * range_px, TWO_PI))
        x = np.fft.ifft(np.fft.fft(x, n, axis=1) * ramp, axis=1)[:, :cols]
    j = np.arange(cols) + range_px
    valid &= ((j >= 0) & (j <= cols - 1))[None, :]
    whole = math.floor(azimuth_px)
    frac = azimuth_px - whole
    if abs(frac) < 1e-9:
        offsets, h = np.array([whole]), np.ones(1)
    else:
        h = _sinc_taps(frac, taps)
        offsets = whole + np.arange(-taps // 2 + 1, taps // 2 + 1)
    # Near the first and last lines the kernel loses taps: the rest is renormalised to unit
    # gain, and the line stays valid while both neighbours of the sample point are inside.
    i = np.arange(rows)
    out = np.zeros_like(x)
    norm = np.zeros(rows)
    for hk, off in zip(h, offsets, strict=True):
        inside = (i + off >= 0) & (i + off <= rows - 1)
        out[inside] += hk * x[i[inside] + off]
        norm += np.where(inside, hk, 0.0)
    ok = (i + whole >= 0) & (i + whole + (1 if len(h) > 1 else 0) <= rows - 1)
    out[ok] /= norm[ok, None]
    valid &= ok[:, None]
    out[~valid] = 0
    return out, valid


def box_sum(x: np.ndarray, looks: tuple[int, int]) -> np.ndarray:
    """Σ of x over a looks[0] × looks[1] window centred on each pixel (zero outside the array).

    A sum of shifted slices in a fixed order per pixel, so a block of lines gives bit-identical
    rows to the whole image wherever the window fits in the block.
    """
    out = x
    for axis, n in enumerate(looks):
        if n < 1 or n % 2 == 0:
            raise ValueError(f"looks must be odd and >= 1, got {looks}")
        half = n // 2
        padded = np.zeros_like(out)
        size = out.shape[axis]
        for d in range(-half, half + 1):
            lo, hi = max(0, -d), min(size, size - d)
            if hi <= lo:
                continue
            dst = [slice(None)] * out.ndim
            src = [slice(None)] * out.ndim
            dst[axis], src[axis] = slice(lo, hi), slice(lo + d, hi + d)
            padded[tuple(dst)] += out[tuple(src)]
        out = padded
    return out


def mean_coherence(main, slave, valid, window=(5, 5)) -> float:
    """Σ|Σ_w M S*| / Σ sqrt(Σ_w|M|² Σ_w|S|²) over valid pixels (slow fringes do not bias it)."""
    v = valid.astype(np.float64)
    cross = np.abs(box_sum(main * np.conj(slave) * v, window))
    power = np.sqrt(
        box_sum(np.abs(main) ** 2 * v, window) * box_sum(np.abs(slave) ** 2 * v, window)
    )
    den = float(power[valid].sum())
    return float(cross[valid].sum() / den) if den > 0 else 0.0


def estimate_registration(
    main, slave, subpixel: str = "both", window=(5, 5), taps: int = 16
) -> Registration:
    """Zhao step II: pixel offset (intensity correlation), then sub-pixel by coherence.

    ``subpixel``: "none" (Zhao's pixel-level registration), "range" or "both" axes refined, each
    by a bounded Brent search of ±0.6 pixel about the integer offset, two sweeps.
    """
    if subpixel not in ("none", "range", "both"):
        raise ValueError("subpixel must be 'none', 'range' or 'both'")
    m = np.asarray(main, np.complex128)
    s = np.asarray(slave, np.complex128)
    d = [float(v) for v in integer_offset(m, s)]

    def score(da, dr):
        shifted, ok = shift_image(s, da, dr, taps)
        return mean_coherence(m, shifted, ok, window)

    axes = {"none": (), "range": (1,), "both": (1, 0)}[subpixel]
    for _ in range(2 if len(axes) > 1 else 1):
        for axis in axes:
            centre = d[axis]

            def cost(v, axis=axis):
                trial = list(d)
                trial[axis] = v
                return -score(*trial)

            res = optimize.minimize_scalar(
                cost,
                bounds=(centre - 0.6, centre + 0.6),
                method="bounded",
                options={"xatol": 1e-3},
            )
            d[axis] = float(res.x)
    return Registration(d[0], d[1], score(d[0], d[1]))


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
    near = phase[np.abs(np.angle(np.exp(1j * (phase - centre)))) < 3 * TWO_PI / bins]
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
            step = np.angle(np.exp(1j * np.diff(p, axis=axis)))
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
def unwrap_phase(wrapped, mask, method: str = "mcf", weights=None) -> np.ndarray:
    """2-D unwrapping through rtsar.topo.unwrap (contract: masked pixels → 0.0, never NaN)."""
    from .unwrap import unwrap

    if method == "skimage":  # the peer takes no weights
        weights = None
    return unwrap(np.asarray(wrapped, np.float64), method=method, mask=mask, weights=weights)


def absolute_cycle_shift(unwrapped, mask) -> float:
    """The multiple of 2π that puts the median unwrapped phase of ``mask`` in [-π, π)."""
    if not mask.any():
        return 0.0
    return -TWO_PI * math.floor(float(np.median(unwrapped[mask])) / TWO_PI + 0.5)


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
    puts the median unwrapped phase over ``reference_mask`` (default: every valid pixel) in
    [-π, π).  This is the float64 batch reference of rtsar.topo.stream.HeightStripStage.
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
    unw = unwrap_phase(wrapped, ifg.valid, method, ifg.coherence)
    ref = ifg.valid if reference_mask is None else (ifg.valid & reference_mask)
    unw = np.where(ifg.valid, unw + absolute_cycle_shift(unw, ref), 0.0)
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
