"""Height-map scenes for 3D imaging: surfaces, their speckle scatterers, truth on the image grid.

Coordinates of a surface: x along track and y ground range, both from the scene centre (the point
of the reference plane at the processor's centre slant range, broadside of along-track 0), and
height h(x, y) above the reference plane.  The surfaces follow the papers' targets:

* slanted_plane: the flat-earth case (a plane at an angle to the reference plane; Crouch ch. 6)
* ridge: Zhao 2014 Fig. 3, a roof of 2.5 mm total elevation
* sphere_cap: Zhao 2014 Fig. 4, a drawing pin (a spherical dome)
* penny_relief: Crouch 2012 ch. 7, a coin face with 150-200 µm relief, no return around it

A diffuse surface is a jittered grid of scatterers, several per resolution cell, each with a
circular complex Gaussian amplitude (fully developed speckle); outside a surface's support there
is no scatterer at all (no return).  The truth height of a pixel is the height of the surface
point at that pixel's along-track position and slant range; where the surface folds over in
range (layover: a slope facing the sensor steeper than tanθ, θ the look angle from the vertical),
the pixel is flagged and not scored.  The simulator models no shadowing: keep slopes facing away
from the sensor below cotθ (0.71 at Zhao's geometry), as all the shapes here do by default.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..lens.plan import make_plan
from ..params import Config, FMCWChirp
from ..presets import preset
from ..topo.insar_geometry import ZHAO_LOOK_ANGLE_RAD
from .model import MAX_GRID_POINTS, Scene, Targets

HeightFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True, eq=False)
class Surface:
    """h(x, y) in metres and where the surface returns light (None: everywhere)."""

    name: str
    height: HeightFn
    returns: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None

    def returns_at(self, x, y) -> np.ndarray:
        x, y = np.broadcast_arrays(np.asarray(x, np.float64), np.asarray(y, np.float64))
        return np.ones(x.shape, bool) if self.returns is None else self.returns(x, y)


def slanted_plane(slope_cross: float = 0.0, slope_along: float = 0.0) -> Surface:
    """h = slope_cross·y + slope_along·x (0, 0: the reference plane itself)."""
    return Surface(
        "slanted_plane",
        lambda x, y: slope_cross * np.asarray(y, np.float64) + slope_along * np.asarray(x),
    )


def ridge(
    height_m: float = 2.5e-3,
    half_width_m: float = 8e-3,
    crest: str = "along_track",
    no_return_outside: bool = False,
) -> Surface:
    """A roof: h = height·max(0, 1 - |u|/half_width), u = y (crest along track) or x (across).

    Zhao 2014 Fig. 3: retro-reflective sheet on a bent plate, 2.5 mm total elevation.  With
    ``no_return_outside`` nothing returns beyond the roof's base.
    """
    if crest not in ("along_track", "cross_track"):
        raise ValueError("crest must be 'along_track' or 'cross_track'")
    axis = 1 if crest == "along_track" else 0

    def height(x, y):
        u = np.abs(np.asarray((x, y)[axis], np.float64))
        return height_m * np.maximum(0.0, 1.0 - u / half_width_m)

    def inside(x, y):
        return np.abs(np.asarray((x, y)[axis], np.float64)) <= half_width_m

    return Surface("ridge", height, inside if no_return_outside else None)


def sphere_cap(
    radius_m: float = 5e-3,
    cap_height_m: float = 1.5e-3,
    centre_m: tuple[float, float] = (0.0, 0.0),
    no_return_outside: bool = False,
) -> Surface:
    """A spherical dome of base radius a and height c: Zhao 2014 Fig. 4's drawing pin.

    Sphere radius ρ = (a² + c²)/(2c); h = sqrt(ρ² - r²) - (ρ - c) for r ≤ a, else 0.
    """
    if not (0 < cap_height_m <= radius_m):
        raise ValueError("cap_height_m must be in (0, radius_m]")
    rho = (radius_m**2 + cap_height_m**2) / (2.0 * cap_height_m)

    def r2(x, y):
        return (np.asarray(x) - centre_m[0]) ** 2 + (np.asarray(y) - centre_m[1]) ** 2

    def height(x, y):
        q = r2(x, y)
        return np.where(
            q <= radius_m**2, np.sqrt(np.maximum(rho**2 - q, 0.0)) - (rho - cap_height_m), 0.0
        )

    return Surface(
        "sphere_cap", height, (lambda x, y: r2(x, y) <= radius_m**2) if no_return_outside else None
    )


def penny_relief(relief_m: float = 180e-6, radius_m: float = 9.5e-3) -> Surface:
    """A coin face (Crouch 2012 ch. 7, the Lincoln penny): raised rim and bust, no return off it.

    Face at h = 0; rim 0.8 mm wide at 0.8·relief; bust a Gaussian of height ``relief`` (σ 0.2 and
    0.3 of the radius) a quarter radius off centre.  Crouch measured ≈200 µm (callipers) and
    imaged ≈150 µm.
    """

    def height(x, y):
        x = np.asarray(x, np.float64)
        y = np.asarray(y, np.float64)
        r = np.hypot(x, y)
        rim = np.where((r >= radius_m - 0.8e-3) & (r <= radius_m), 0.8 * relief_m, 0.0)
        bust = relief_m * np.exp(
            -0.5 * (((x + 0.25 * radius_m) / (0.2 * radius_m)) ** 2 + (y / (0.3 * radius_m)) ** 2)
        )
        return np.where(r <= radius_m, np.maximum(rim, bust), 0.0)

    return Surface("penny_relief", height, lambda x, y: np.hypot(x, y) <= radius_m)


def zhao_config(
    look_angle_rad: float = ZHAO_LOOK_ANGLE_RAD, sample_rate_hz: float | None = None, **processor
) -> Config:
    """Preset zhao-insal with the 3D geometry: platform height H = R cosθ above the reference plane.

    θ is the look angle from the vertical at the scene centre (default atan √2, where a horizontal
    1.6 mm baseline gives Zhao's 2π per 3.3 mm; rtsar.topo.insar.InsalGeometry).  ``processor``
    overrides Processor fields (aperture_pulses, range_bins, windows, ...); ``sample_rate_hz``
    shortens the FMCW shot (fewer samples, a narrower unambiguous window, same resolution) for
    fast tests.
    """
    cfg = preset("zhao-insal")
    g = cfg.geometry
    cfg = replace(
        cfg, geometry=replace(g, platform_height_m=g.slant_range_m * math.cos(look_angle_rad))
    )
    if sample_rate_hz is not None:
        cfg = replace(cfg, waveform=replace(cfg.waveform, sample_rate_hz=float(sample_rate_hz)))
    return cfg.with_processor(**processor) if processor else cfg


@dataclass(frozen=True, eq=False)
class TruthMap:
    """The surface seen on the image grid [azimuth line, range bin]."""

    height_m: np.ndarray  # float64, 0 where the surface does not return
    returns: np.ndarray  # bool: the pixel sees the surface
    layover: np.ndarray  # bool: several surface points share the pixel's slant range

    @property
    def scored(self) -> np.ndarray:
        return self.returns & ~self.layover


@dataclass(frozen=True, eq=False)
class SurfaceScene:
    scene: Scene
    surface: Surface
    centre_ground_range_m: float  # y of the scene centre (surface coordinate y = 0)

    @property
    def config(self) -> Config:
        return self.scene.config

    def truth(self, azimuth_m, range_m, step_m: float = 2e-6) -> TruthMap:
        """Surface height at each pixel (along-track azimuth_m[i], slant range range_m[j])."""
        return truth_on_grid(
            self.surface,
            self.config.geometry.platform_height_m,
            self.centre_ground_range_m,
            azimuth_m,
            range_m,
            step_m,
        )


def truth_on_grid(
    surface, platform_height_m, centre_ground_range_m, azimuth_m, range_m, step_m=2e-6
) -> TruthMap:
    """Invert R(y) = hypot(y, H - h(x, y)) along each image line on a fine ground grid."""
    az = np.asarray(azimuth_m, np.float64)
    rg = np.asarray(range_m, np.float64)
    big_h = float(platform_height_m)
    margin = 5e-3
    y = np.arange(
        math.sqrt(max(rg[0] - margin, big_h) ** 2 - big_h**2) - margin,
        math.sqrt((rg[-1] + margin) ** 2 - big_h**2) + margin,
        step_m,
    )
    height = np.zeros((len(az), len(rg)))
    returns = np.zeros(height.shape, bool)
    layover = np.zeros(height.shape, bool)
    half_bin = 0.5 * abs(rg[1] - rg[0]) if len(rg) > 1 else 0.0
    for i, x in enumerate(az):
        u = y - centre_ground_range_m
        r = np.hypot(y, big_h - surface.height(np.full_like(u, x), u))
        ahead = np.maximum.accumulate(r)
        behind = np.minimum.accumulate(r[::-1])[::-1]
        unique = (r >= ahead) & (r <= behind)
        if not unique.all():  # folded spans: every range some other surface point shares
            bad = ~unique
            edges = np.flatnonzero(np.diff(np.concatenate(([0], bad.astype(np.int8), [0]))))
            for lo, hi in zip(edges[::2], edges[1::2], strict=True):
                span = r[max(lo - 1, 0) : hi + 1]
                layover[i] |= (rg >= span.min() - half_bin) & (rg <= span.max() + half_bin)
        ru, yu = r[unique], y[unique]
        keep = np.concatenate(([True], np.diff(ru) > 0))
        ru, yu = ru[keep], yu[keep]
        inside = (rg >= ru[0]) & (rg <= ru[-1])
        yp = np.interp(rg, ru, yu) - centre_ground_range_m
        xs = np.full_like(yp, x)
        returns[i] = inside & surface.returns_at(xs, yp)
        height[i] = np.where(returns[i], surface.height(xs, yp), 0.0)
    return TruthMap(height, returns, layover & returns)


def default_spacing_m(cfg: Config, per_cell: float = 4.0) -> tuple[float, float]:
    """Scatterer grid (along track, ground range): ``per_cell`` scatterers per resolution cell.

    Resolution cell: λR/(2L) along track (Crouch eq. 4.8) by c/2B / sinθ in ground range.
    """
    g = cfg.geometry
    sin_theta = math.sqrt(1.0 - (g.platform_height_m / g.slant_range_m) ** 2)
    ground = cfg.waveform.range_resolution_m / sin_theta
    along = cfg.azimuth_resolution_m()
    # Keep the two spacings alike in cells: per_cell = (along/dx)·(ground/dy).
    k = math.sqrt(per_cell)
    return along / k, ground / k


def surface_scene(
    cfg: Config,
    surface: Surface,
    lines: int,
    *,
    spacing_m: tuple[float, float] | None = None,
    seed: int = 0,
    effects=(),
    bright_points=(),
    jitter: float = 0.5,
    name: str | None = None,
) -> SurfaceScene:
    """A scene of ``lines`` image lines centred on along-track 0, covered by the surface's speckle.

    Scatterers: a grid of ``spacing_m`` (default default_spacing_m) jittered by ±jitter·spacing,
    over the lines' along-track extent plus two azimuth resolutions and over the range window
    plus three bins (kept inside an FMCW waveform's unambiguous window), dropped where the
    surface does not return; amplitude circular complex Gaussian of unit power.
    ``bright_points``: extra (x_m, y_m, amplitude) scatterers on the surface (retro-reflectors).
    The scene simulates lines + N - 1 pulses, so the engine focuses exactly ``lines`` lines.
    A grid of more than rtsar.scene.model.MAX_GRID_POINTS points is refused (ValueError)
    before it is made.
    """
    g = cfg.geometry
    if not g.platform_height_m > 0:
        raise ValueError(
            "surface scenes need a platform height above the reference plane "
            f"(geometry.platform_height_m > 0, got {g.platform_height_m!r})"
        )
    if not (isinstance(lines, int) and lines >= 1):
        raise ValueError("lines must be an integer >= 1")
    n = cfg.processor.aperture_pulses
    step = g.along_track_step_m
    big_h = g.platform_height_m
    plan = make_plan(cfg)
    bin_m = abs(plan.range_m[1] - plan.range_m[0])
    r_lo, r_hi = plan.range_m[0] - 3 * bin_m, plan.range_m[-1] + 3 * bin_m
    wf = cfg.waveform
    if isinstance(wf, FMCWChirp):
        half = 0.5 * wf.unambiguous_range_m - bin_m
        r_lo = max(r_lo, wf.reference_range_m - half)
        r_hi = min(r_hi, wf.reference_range_m + half)
    centre_r = cfg.processor.range_centre_m or g.slant_range_m
    y_c = math.sqrt(centre_r**2 - big_h**2)
    dx, dy = spacing_m or default_spacing_m(cfg)
    x_half = 0.5 * (lines - 1) * step + 2.0 * cfg.azimuth_resolution_m()
    margin = 5e-3
    y_lo = math.sqrt(max(r_lo - margin, big_h) ** 2 - big_h**2) - y_c
    y_hi = math.sqrt((r_hi + margin) ** 2 - big_h**2) - y_c
    # The grid's points (np.arange's counts), known before it is made; NaN or inf fail too.
    nx, ny = (2 * x_half + dx) / dx, (y_hi - y_lo) / dy
    if nx <= MAX_GRID_POINTS and ny <= MAX_GRID_POINTS:
        nx, ny = math.ceil(nx), max(math.ceil(ny), 0)
    if not nx * ny <= MAX_GRID_POINTS:
        raise ValueError(
            f"a surface grid of {nx:.4g} x {ny:.4g} scatterers exceeds {MAX_GRID_POINTS:,} "
            "points: fewer lines or a wider spacing (a lower scatterers_per_cell)"
        )
    xg, yg = np.meshgrid(
        np.arange(-x_half, x_half + dx, dx), np.arange(y_lo, y_hi, dy), indexing="ij"
    )
    rng = np.random.default_rng(seed)
    x = xg.ravel() + jitter * dx * rng.uniform(-1, 1, xg.size)
    y = yg.ravel() + jitter * dy * rng.uniform(-1, 1, yg.size)
    amp = (rng.standard_normal(x.size) + 1j * rng.standard_normal(x.size)) / math.sqrt(2.0)
    for bx, by, ba in bright_points:
        x, y, amp = np.append(x, bx), np.append(y, by), np.append(amp, complex(ba))
    h = surface.height(x, y)
    r = np.hypot(y + y_c, big_h - h)
    keep = surface.returns_at(x, y) & (r >= r_lo) & (r <= r_hi)
    targets = Targets(
        x[keep],
        r[keep],
        amp[keep].astype(np.complex128),
        ground_range_m=y[keep] + y_c,
        height_m=h[keep],
    )
    start = -(0.5 * (lines - 1) + 0.5 * (n - 1)) * step
    scene = Scene(
        cfg,
        targets,
        lines + n - 1,
        start,
        seed,
        tuple((e, dict(p)) for e, p in effects),
        name or surface.name,
        extends_past_window=True,  # the 3 bins and the margin above, on purpose
    )
    return SurfaceScene(scene, surface, y_c)
