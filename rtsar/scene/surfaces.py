"""Diffuse surfaces (speckle) and bright points (retro-reflectors): realistic autofocus scenes.

A diffuse surface is many scatterers with independent uniform random phases scattered uniformly
over a region of the (along-track, slant-range) plane, at a stated mean number per resolution
cell ρA × ρR (ρA = λR/2L, Crouch eq. 4.8; ρR = c/2B, Crouch eq. 3.6).  Its reflectivity is the
mean power per resolution cell, σ_cell = density · E|a|².  The focused image of such a surface
is speckle: the sum of many random phasors in each cell (Crouch ch. 4, "Residual Phase Error";
INO phase-error patent, remark on speckle).  With Rayleigh magnitudes every pixel is a circular
complex Gaussian whatever the density, so the intensity is exponentially distributed (contrast
std/mean = 1); with unit magnitudes the speckle is fully developed once a cell holds several
scatterers.  Because an unweighted impulse response with unit peak integrates to
∫|h|² dA = ρA·ρR, the mean image intensity over the surface equals σ_cell.

Bright points are isolated strong scatterers (retro-reflectors, Crouch's Ohara glass spheres)
whose power is stated relative to one resolution cell of the surface: ``to_cell_db`` =
10 log10(|a|² / σ_cell), the signal-to-clutter ratio of the point in a focused image.

Everything is seeded (``numpy.random.default_rng(seed)``) and returns
:class:`rtsar.scene.model.Targets`; :func:`surface_scene` wraps them in a Scene via
:func:`rtsar.scene.model.point_scene`.
"""

from __future__ import annotations

import math

import numpy as np

from ..params import Config
from .model import Scene, Targets, point_scene

MAGNITUDES = ("rayleigh", "unit")


def resolution_cell_m(config: Config, slant_range_m: float | None = None) -> tuple[float, float]:
    """(ρA, ρR) in metres: λR/2L (Crouch eq. 4.8) and c/2B (Crouch eq. 3.6), unweighted."""
    return config.azimuth_resolution_m(slant_range_m), config.waveform.range_resolution_m


def _interval(value, name: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair (low_m, high_m), got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise ValueError(f"{name} must be finite with high > low, got {value!r}")
    return lo, hi


def _finite_positive(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")
    return float(value)


def diffuse_surface(
    config: Config,
    along_track_m: tuple[float, float],
    slant_range_m: tuple[float, float],
    density_per_cell: float = 2.0,
    cell_power: float = 1.0,
    magnitude: str = "rayleigh",
    seed: int = 0,
) -> Targets:
    """Random-phase scatterers over a rectangle of the (along-track, slant-range) plane.

    Parameters
    ----------
    config : Config
        Instrument; sets the resolution cell ρA × ρR at the rectangle's mid range.
    along_track_m, slant_range_m : (float, float)
        Extent of the surface (closest-approach positions), metres.
    density_per_cell : float
        Mean number of scatterers per resolution cell; the count is
        round(density · area / (ρA ρR)) (at least 1), positions uniform over the rectangle.
    cell_power : float
        Reflectivity σ_cell, the mean scattered power per resolution cell (amplitude² units of a
        point target); each scatterer has E|a|² = σ_cell / density.
    magnitude : {"rayleigh", "unit"}
        "rayleigh": circular complex Gaussian amplitudes (exponential speckle at any density);
        "unit": constant magnitude, uniform phase.
    seed : int
        Seed of the generator (positions, magnitudes, phases).

    Returns
    -------
    Targets
        Scatterers with complex128 amplitudes.

    Raises
    ------
    ValueError
        For an empty or non-finite extent, non-positive density or power, or an unknown
        magnitude model.
    """
    x0, x1 = _interval(along_track_m, "along_track_m")
    r0, r1 = _interval(slant_range_m, "slant_range_m")
    if r0 <= 0:
        raise ValueError("slant_range_m must be > 0")
    density = _finite_positive(density_per_cell, "density_per_cell")
    power = _finite_positive(cell_power, "cell_power")
    if magnitude not in MAGNITUDES:
        raise ValueError(f"magnitude must be one of {MAGNITUDES}, got {magnitude!r}")
    rho_a, rho_r = resolution_cell_m(config, 0.5 * (r0 + r1))
    cells = (x1 - x0) * (r1 - r0) / (rho_a * rho_r)
    count = max(1, int(round(density * cells)))
    rng = np.random.default_rng(seed)
    x = rng.uniform(x0, x1, count)
    r = rng.uniform(r0, r1, count)
    mean_power = power / density  # E|a|² per scatterer
    if magnitude == "rayleigh":
        g = rng.standard_normal((2, count))
        amp = math.sqrt(0.5 * mean_power) * (g[0] + 1j * g[1])
    else:
        amp = math.sqrt(mean_power) * np.exp(2j * math.pi * rng.random(count))
    return Targets(x, r, amp.astype(np.complex128))


def bright_points(
    along_track_m,
    slant_range_m,
    to_cell_db: float | np.ndarray = 20.0,
    cell_power: float = 1.0,
    seed: int = 0,
) -> Targets:
    """Bright points (retro-reflectors) with power ``to_cell_db`` above one surface cell.

    |a|² = σ_cell · 10^(to_cell_db / 10); phases uniform random (seeded).  ``to_cell_db`` may be
    one value or one per point.
    """
    x = np.atleast_1d(np.asarray(along_track_m, dtype=np.float64))
    r = np.atleast_1d(np.asarray(slant_range_m, dtype=np.float64))
    db = np.broadcast_to(np.asarray(to_cell_db, dtype=np.float64), x.shape)
    if x.shape != r.shape or x.ndim != 1:
        raise ValueError("along_track_m and slant_range_m must be 1-D of one length")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(r)) and np.all(np.isfinite(db))):
        raise ValueError("bright points: positions and to_cell_db must be finite")
    if np.any(r <= 0):
        raise ValueError("bright points: slant_range_m must be > 0")
    power = _finite_positive(cell_power, "cell_power")
    phase = 2 * math.pi * np.random.default_rng(seed).random(x.size)
    amp = np.sqrt(power * 10.0 ** (db / 10.0)) * np.exp(1j * phase)
    return Targets(x.copy(), r.copy(), amp.astype(np.complex128))


def combine_targets(*parts: Targets) -> Targets:
    """Concatenate target sets (slant-range positions; 3-D fields kept only if all have them)."""
    if not parts:
        raise ValueError("combine_targets needs at least one Targets")
    with_3d = [p.ground_range_m is not None and p.height_m is not None for p in parts]
    ground = height = None
    if all(with_3d):
        ground = np.concatenate([p.ground_range_m for p in parts])
        height = np.concatenate([p.height_m for p in parts])
    elif any(with_3d):
        raise ValueError("combine_targets: mix of targets with and without ground range/height")
    return Targets(
        np.concatenate([p.along_track_m for p in parts]),
        np.concatenate([p.slant_range_m for p in parts]),
        np.concatenate([np.asarray(p.amplitude, np.complex128) for p in parts]),
        ground,
        height,
    )


def surface_scene(
    config: Config,
    along_track_m: tuple[float, float],
    slant_range_m: tuple[float, float],
    density_per_cell: float = 2.0,
    cell_power: float = 1.0,
    points: Targets | None = None,
    magnitude: str = "rayleigh",
    effects=(),
    seed: int = 0,
    pulses: int | None = None,
    start_along_track_m: float | None = None,
    name: str = "surface",
) -> Scene:
    """A diffuse surface (seeded by ``seed``) plus optional bright points, as a Scene.

    The simulator's effects use the same ``seed``.  ``pulses``/``start_along_track_m`` default to
    a scan that images the whole surface (see :func:`rtsar.scene.model.point_scene`).
    """
    surface = diffuse_surface(
        config, along_track_m, slant_range_m, density_per_cell, cell_power, magnitude, seed
    )
    targets = surface if points is None else combine_targets(surface, points)
    return point_scene(
        config,
        targets.along_track_m,
        targets.slant_range_m,
        targets.amplitude,
        effects=effects,
        seed=seed,
        pulses=pulses,
        start_along_track_m=start_along_track_m,
        name=name,
    )


__all__ = [
    "MAGNITUDES",
    "bright_points",
    "combine_targets",
    "diffuse_surface",
    "resolution_cell_m",
    "surface_scene",
]
