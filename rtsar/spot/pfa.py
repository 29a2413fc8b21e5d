"""Polar format algorithm with chirp-z spectral zoom (Crouch ch. 9, "Polar Format Implementation").

After motion compensation to the scene centre, shot n sample m holds the scene's spectrum at
wavenumber ρ = g_n k_m along the direction ψ_n (rtsar.spot.geometry.look_vectors; k_m = 2π(f0 +
K t_m)/c), i.e. at (k_x, k_y) = ρ (sin ψ_n, cos ψ_n): a polar grid (Crouch ch. 4, "Polar
Formatting and Quadratic Phase Errors": the quadratic range migration).  The image is formed on a
frame turned by α (the look direction of the middle shot, ψ = φ - α), in three zooms:

1. range, per shot, as the shot arrives: the band-limited interpolant of the shot (DFT, then a
   chirp-z zoom with start and spacing of that shot) evaluated at k_y = ky_j / cos ψ_n on one
   uniform k_y grid common to every shot (the inscribed rectangle's k_y extent): the keystone;
2. azimuth, per k_y row: Σ_n G[n, j] W(k_x) exp(i ky_j tan ψ_n x) straight onto the image's x
   pixels by a chirp-z zoom in n.  tan ψ_n of an arc with equal angle steps is not uniform; its
   departure δ_n from the best straight line is carried exactly by a Taylor series
   exp(i ky δ x) = Σ_p (i ky δ)^p x^p / p!, terms added until the next is below ``tolerance``
   (a few terms at Crouch's 5°; none for a uniform track);
3. range: Σ_j Z[j] W_r(ky_j) exp(i ky_j y) onto the image's y pixels (chirp-z zoom).

The image is returned at baseband: multiplied by exp(-i(k_x,c x + k_y,c y)) with (k_x,c, k_y,c)
the centre of the spectral rectangle, so its spectrum sits at zero frequency as the strip-map
images' do (the phase at a scatterer then is arg a - k_c·position; ``baseband`` applies the same
factor to exact-phase values such as a backprojection).

Only the inscribed rectangle of the polar annulus is used (k_x limits common to every k_y row),
so the point response is separable: -3 dB widths 0.886·2π/Δk_x ≈ 0.886 λ/(2Δθ) (eq. 9.5) and
0.886·2π/Δk_y ≈ 0.886 c/2B, times the window factor.  What PFA still approximates: the planar
wavefront (the path difference taken linear in the position, error growing with the distance
from the centre) and the range interpolation of a finite record; rtsar.spot.backprojection is the
exact reference.  Image axes: image[x, y] (cross-range, range), the rtsar image[azimuth, range].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from ..focus.resample import resample
from ..params import Config
from ..samples import zero_nonfinite_rows
from ..windows import window_at
from .czt import zoom_dtft
from .geometry import SpotlightGeometry, echo_cycles, sample_times_s, wavenumbers

MAX_TAYLOR_TERMS = 40
ROW_CHUNK = 64  # rows per chirp-z batch (bounded memory)
MAX_PIXELS = 1 << 25
DEFAULT_AXIS_PIXELS = 4096


@dataclass(frozen=True)
class PfaSettings:
    """oversampling: pixels per natural resolution cell (2π/Δk) along each axis;
    extent_m: (cross-range, range) image extent (None: the alias-free extents, λ/(2·step
    angle) and the range window, each cut to 4096 pixels); windows: rtsar.params.WINDOWS over
    k_x and k_y;
    tolerance: the last Taylor term kept in the azimuth zoom (relative);
    curvature_phase: remove the wavefront-curvature phase of each pixel at the middle shot and
    centre frequency (exact path minus its planar approximation; without it a pixel at x from
    the centre keeps a phase ≈ k·x²/R₀ against the exact image);
    range_interpolation: "czt" (the DFT interpolant of the whole shot evaluated by a chirp-z
    zoom, Crouch's and Sandia's choice) or "sinc" (a 24-tap Kaiser-windowed sinc,
    rtsar.focus.resample: local, so the record's ends disturb only their neighbourhood)."""

    oversampling: float = 2.0
    extent_m: tuple[float, float] | None = None
    range_window: str = "rect"
    azimuth_window: str = "rect"
    tolerance: float = 1e-7
    curvature_phase: bool = True
    range_interpolation: str = "czt"

    def __post_init__(self):
        if not (math.isfinite(self.oversampling) and 0.5 <= self.oversampling <= 64):
            raise ValueError(f"PFA oversampling must be in [0.5, 64], got {self.oversampling!r}")
        if self.extent_m is not None and not all(math.isfinite(e) and e > 0 for e in self.extent_m):
            raise ValueError(f"PFA extent_m must be two positive lengths, got {self.extent_m!r}")
        if self.range_interpolation not in ("czt", "sinc"):
            raise ValueError(
                f"range_interpolation must be czt or sinc, got {self.range_interpolation!r}"
            )
        if not (0 < self.tolerance < 1):
            raise ValueError("PFA tolerance must be in (0, 1)")


class PolarFormatPlan:
    """Everything fixed by the planned collection: the frame, the k_y grid, the image grid.

    ``look``: "exact" (the channel's own geometry: monostatic, or the bistatic bisector of
    Crouch eq. 9.4b) or "monostatic" (a bistatic channel processed as if monostatic: the
    uncorrected image).
    """

    def __init__(
        self,
        config: Config,
        geometry: SpotlightGeometry,
        channel: str = "main",
        settings: PfaSettings | None = None,
        look: str = "exact",
    ):
        if look not in ("exact", "monostatic"):
            raise ValueError(f"look must be 'exact' or 'monostatic', got {look!r}")
        self.config, self.geometry, self.channel = config, geometry, channel
        self.look = look
        self.settings = s = settings or PfaSettings()
        wf = config.waveform
        lam = config.geometry.wavelength_m
        self.samples = m = wf.samples_per_shot
        self.t_s = sample_times_s(wf)
        self.k_c, self.dk = wavenumbers(wf, lam)
        phi, g = geometry.look_vectors(None, channel if look == "exact" else "main")
        self.alpha_rad = float(
            phi[len(phi) // 2]
            if len(phi) % 2
            else 0.5 * (phi[len(phi) // 2 - 1] + phi[len(phi) // 2])
        )
        self.psi = phi - self.alpha_rad
        self.g = g
        if np.any(np.diff(self.psi) <= 0):
            raise ValueError("PFA needs look angles increasing from shot to shot")
        self.tan_psi = np.tan(self.psi)
        # Motion compensation: the exact echo of the scene centre of every planned shot.
        centre = geometry.half_path_m(np.zeros((1, 3)), None, channel)[:, 0]
        self.lo_m = geometry.lo_range_m(wf, channel)
        self.c0, self.f0 = echo_cycles(centre, self.lo_m, wf, lam)
        k_min = self.k_c - self.dk * 0.5 * m
        k_max = self.k_c + self.dk * (0.5 * m - 1)
        scale = g * np.cos(self.psi)
        self.ky_lo = float(np.max(scale * k_min))
        self.ky_hi = float(np.min(scale * k_max))
        if self.ky_hi <= self.ky_lo:
            raise ValueError("PFA: the polar annulus has no inscribed rectangle (sweep too wide)")
        self.rows = m
        self.dky = (self.ky_hi - self.ky_lo) / (self.rows - 1)
        self.ky = self.ky_lo + self.dky * np.arange(self.rows)
        # Image grid (rotated frame): natural cells 2π/Δk of the full planned aperture.
        cell_x, cell_y = self.cell_m()
        self.dx, self.dy = cell_x / s.oversampling, cell_y / s.oversampling
        if s.extent_m is None:  # alias-free extents, at most DEFAULT_AXIS_PIXELS per axis
            step = float(np.median(np.diff(self.tan_psi)))
            ext = (
                min(2 * math.pi / (self.ky_lo * step), DEFAULT_AXIS_PIXELS * self.dx),
                min(2 * math.pi / self.dky, DEFAULT_AXIS_PIXELS * self.dy),
            )
        else:
            ext = s.extent_m
        nx = max(2, int(math.ceil(ext[0] / self.dx)))
        ny = max(2, int(math.ceil(ext[1] / self.dy)))
        if nx * ny > MAX_PIXELS:
            raise ValueError(f"PFA image of {nx} x {ny} pixels exceeds {MAX_PIXELS}: give extent_m")
        self.x_m = (np.arange(nx) - nx // 2) * self.dx
        self.y_m = (np.arange(ny) - ny // 2) * self.dy
        self._curvature = None
        self.range_weights = window_at(
            s.range_window, (self.ky - self.ky_lo) / (self.ky_hi - self.ky_lo)
        )

    @property
    def ky_centre(self) -> float:
        return 0.5 * (self.ky_lo + self.ky_hi)

    def baseband(self, values: np.ndarray, start: int, stop: int, pixels=None) -> np.ndarray:
        """Exact scene-phase values (e.g. backprojection) at the image pixels ``pixels`` (a
        pair of slices; None: all) brought to the PFA image's baseband: ·exp(-i(kx_c x + ky_c y))
        with the spectral centre of shots start…stop-1."""
        sl = (slice(None), slice(None)) if pixels is None else pixels
        xx, yy = np.meshgrid(self.x_m[sl[0]], self.y_m[sl[1]], indexing="ij")
        kx_c = 0.5 * sum(self.kx_limits(start, stop))
        phase = np.mod(kx_c * xx + self.ky_centre * yy, 2 * math.pi)
        return np.asarray(values) * np.exp(-1j * phase)

    def cell_m(self, shots: int | None = None) -> tuple[float, float]:
        """(x, y) resolution cells 2π/Δk of the inscribed rectangle an image of the first
        ``shots`` shots (all: None) is formed from: λ/(gΔφ) and c/(gB) as the sweep and band
        narrow to it (at 5° and 3 THz around 193 THz the rectangle keeps 94 % of the band)."""
        lo, hi = self.kx_limits(0, len(self.psi) if shots is None else max(2, int(shots)))
        return 2 * math.pi / (hi - lo), 2 * math.pi / (self.ky_hi - self.ky_lo)

    def kx_limits(self, start: int, stop: int) -> tuple[float, float]:
        """k_x extent common to every k_y row for shots start…stop-1 (the inscribed rectangle)."""
        t0, t1 = self.tan_psi[start], self.tan_psi[stop - 1]
        return max(self.ky_lo * t0, self.ky_hi * t0), min(self.ky_lo * t1, self.ky_hi * t1)

    def compensate(self, data: np.ndarray, start: int) -> np.ndarray:
        """Motion compensation to the scene centre: data · conj(echo of the centre), float64."""
        n = np.arange(start, start + len(data))
        cycles = self.c0[n, None] + np.outer(self.f0[n], self.t_s)
        return np.asarray(data, np.complex128) * np.exp(-2j * math.pi * np.mod(cycles, 1.0))

    def range_step(self, data: np.ndarray, start: int) -> np.ndarray:
        """Step 1 for shots start…: G[n, j], the shot's spectrum at k_y = ky_j (keystone)."""
        d = self.compensate(np.atleast_2d(data), start)
        n = np.arange(start, start + len(d))
        m = self.samples
        scale = self.g[n] * np.cos(self.psi[n])
        a = (self.ky_lo / scale - self.k_c) / self.dk + 0.5 * m  # fractional sample of ky_0
        b = self.dky / (scale * self.dk)  # samples per k_y step
        pos = a[:, None] + b[:, None] * np.arange(self.rows)[None, :]
        if self.settings.range_interpolation == "sinc":
            return resample(d, np.clip(pos, 0.0, m - 1.0))[0]
        spec = sfft.fftshift(sfft.fft(d, axis=1), axes=1)
        out = zoom_dtft(spec, 2 * math.pi * a / m, 2 * math.pi * b / m, self.rows)
        return out * np.exp(-1j * math.pi * np.mod(pos, 2.0)) / m

    def weights(self, start: int, stop: int) -> np.ndarray:
        """W[n, j]: the azimuth window over the inscribed k_x extent of shots start…stop-1."""
        lo, hi = self.kx_limits(start, stop)
        if hi <= lo:
            raise ValueError(
                f"shots {start}…{stop - 1} span no k_x extent common to every k_y row (too few "
                "shots for their squint): no image yet"
            )
        kx = self.tan_psi[start:stop, None] * self.ky[None, :]
        return window_at(self.settings.azimuth_window, (kx - lo) / (hi - lo))

    def form(self, g_rows: np.ndarray, start: int = 0) -> np.ndarray:
        """Steps 2-3: the image [x, y] (complex128) of the keystoned shots start…start+n-1,
        normalised so that a unit scatterer at the centre peaks at 1."""
        n = len(g_rows)
        stop = start + n
        w = self.weights(start, stop)
        t = self.tan_psi[start:stop]
        idx = np.arange(n, dtype=np.float64)
        slope, t0 = np.polyfit(idx, t, 1) if n > 1 else (0.0, t[0])
        delta = t - (t0 + slope * idx)
        x, y, ky = self.x_m, self.y_m, self.ky
        bound = float(np.max(np.abs(ky)) * np.max(np.abs(x)) * np.max(np.abs(delta)))
        terms = 1
        mag = 1.0
        while terms < MAX_TAYLOR_TERMS:
            mag *= bound / terms
            if mag < self.settings.tolerance:
                break
            terms += 1
        weighted = (np.asarray(g_rows, np.complex128) * w).T  # [j, n]
        z = np.zeros((self.rows, len(x)), np.complex128)
        for r0 in range(0, self.rows, ROW_CHUNK):
            rows = slice(r0, r0 + ROW_CHUNK)
            kyr = ky[rows]
            part = weighted[rows]
            acc = np.zeros((len(kyr), len(x)), np.complex128)
            factor = np.ones(len(x))
            for p in range(terms):
                term = zoom_dtft(part, kyr * slope * x[0], kyr * slope * self.dx, len(x))
                acc += term * factor[None, :]
                part = part * (1j * kyr[:, None] * delta[None, :])
                factor = factor * x / (p + 1)
            phase = np.mod(np.outer(kyr, t0 * x), 2 * math.pi)
            z[rows] = acc * np.exp(1j * phase)
        zr = z.T * self.range_weights[None, :]  # [i, j]
        img = np.empty((len(x), len(y)), np.complex128)
        for c0 in range(0, len(x), ROW_CHUNK):
            cols = slice(c0, c0 + ROW_CHUNK)
            img[cols] = zoom_dtft(zr[cols], self.dky * y[0], self.dky * self.dy, len(y))
        # the k_y sum started at ky_lo; the image is returned at baseband (module docstring)
        img *= np.exp(1j * np.mod((self.ky_lo - self.ky_centre) * y, 2 * math.pi))[None, :]
        kx_centre = 0.5 * sum(self.kx_limits(start, stop))
        img *= np.exp(-1j * np.mod(kx_centre * x, 2 * math.pi))[:, None]
        if self.settings.curvature_phase:
            img *= np.exp(1j * self.curvature_rad)
        return img / np.sum(w * self.range_weights[None, :])

    @property
    def curvature_rad(self) -> np.ndarray:
        """k_c·(L_p - L_c - g (e·p)) per pixel at the middle shot: the planar wavefront's phase
        error (Crouch ch. 4, the quadratic terms dropped from eq. 4.2), [x, y]."""
        if self._curvature is None:
            mid = len(self.psi) // 2
            pts = self.scene_points()
            flat = pts.reshape(-1, 3)
            half = self.geometry.half_path_m(flat, [mid], self.channel)[0]
            centre = self.geometry.half_path_m(np.zeros((1, 3)), [mid], self.channel)[0, 0]
            xx, yy = np.meshgrid(self.x_m, self.y_m, indexing="ij")
            planar = self.g[mid] * (xx * math.sin(self.psi[mid]) + yy * math.cos(self.psi[mid]))
            excess = 2.0 * (half - centre).reshape(xx.shape) - planar
            self._curvature = np.mod(self.k_c * excess, 2 * math.pi)
        return self._curvature

    def polar_weights(self, start: int, stop: int) -> np.ndarray:
        """The same aperture on the polar samples [n, m] (for the backprojection reference)."""
        lo, hi = self.kx_limits(start, stop)
        n = np.arange(start, stop)
        rho = self.g[n, None] * (
            self.k_c + self.dk * (np.arange(self.samples) - 0.5 * self.samples)
        )
        kx = rho * np.sin(self.psi[n, None])
        ky = rho * np.cos(self.psi[n, None])
        wr = window_at(self.settings.range_window, (ky - self.ky_lo) / (self.ky_hi - self.ky_lo))
        return window_at(self.settings.azimuth_window, (kx - lo) / (hi - lo)) * wr

    def scene_points(self) -> np.ndarray:
        """Scene coordinates [x, y, 3] of the image pixels (the frame turned by α)."""
        ca, sa = math.cos(self.alpha_rad), math.sin(self.alpha_rad)
        xx, yy = np.meshgrid(self.x_m, self.y_m, indexing="ij")
        return np.stack([xx * ca + yy * sa, -xx * sa + yy * ca, 0 * xx], -1)

    def to_frame(self, points_m: np.ndarray) -> np.ndarray:
        """Scene points [n, ≥2] → (x, y) in the image frame."""
        p = np.atleast_2d(points_m)
        ca, sa = math.cos(self.alpha_rad), math.sin(self.alpha_rad)
        return np.stack([p[:, 0] * ca - p[:, 1] * sa, p[:, 0] * sa + p[:, 1] * ca], -1)


def polar_format(data: np.ndarray, plan: PolarFormatPlan) -> np.ndarray:
    """Batch PFA of every shot of the plan: image [x, y] complex128 (shots holding NaN/Inf are
    zeroed, as the stream does; count them with rtsar.samples.nonfinite_rows)."""
    if len(data) != len(plan.psi):
        raise ValueError(f"{len(data)} shots for a plan of {len(plan.psi)}")
    data = zero_nonfinite_rows(data)[0]
    return plan.form(plan.range_step(data, 0), 0)


class ProgressivePolarFormat:
    """Streaming PFA: the range zoom as each block of shots arrives, an image of the aperture so
    far on demand (its cross-range resolution λ/(2Δθ_so_far)); the last equals the batch one."""

    def __init__(self, plan: PolarFormatPlan):
        self.plan = plan
        self.rows = np.zeros((len(plan.psi), plan.rows), np.complex128)
        self.count = 0
        self.nonfinite_shots = 0  # shots holding NaN/Inf, zeroed (their angle kept), counted

    def push(self, data: np.ndarray, start: int | None = None) -> None:
        data = np.atleast_2d(data)
        start = self.count if start is None else start
        if start != self.count or start + len(data) > len(self.rows):
            raise ValueError(f"shots {start}… arrive out of order (expected {self.count})")
        data, bad = zero_nonfinite_rows(data)
        self.nonfinite_shots += int(bad.sum())
        self.rows[start : start + len(data)] = self.plan.range_step(data, start)
        self.count += len(data)

    def sweep_rad(self) -> float:
        """Look-angle span of the shots so far."""
        return float(self.plan.psi[self.count - 1] - self.plan.psi[0]) if self.count else 0.0

    def ready(self) -> bool:
        """True once the shots so far span a k_x extent common to every k_y row."""
        if self.count < 2:
            return False
        lo, hi = self.plan.kx_limits(0, self.count)
        return hi > lo

    def image(self) -> np.ndarray:
        if self.count < 2:
            raise ValueError("a progressive image needs at least two shots")
        return self.plan.form(self.rows[: self.count], 0)
