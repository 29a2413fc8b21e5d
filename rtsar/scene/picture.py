"""Pictures drawn in diffuse scatterers: a scene a person recognises (docs/pages/guide/scenes.md).

A picture is a small grid of grey levels — rows of characters, or text set in the 5 × 7 font
below — laid over a rectangle of the (along-track, slant-range) plane: picture rows run along
track (the image's lines), columns across slant range.  The rectangle is filled with a regular
grid of scatterers spaced ``cells_per_scatterer`` resolution cells apart (ρA = λR/2L, Crouch eq.
4.8; ρR = c/2B, Crouch eq. 3.6; spacings ≥ 1 cell), each taking the level of the picture pixel
under it.  Every scatterer has an independent uniform random phase (seeded), so the focused
picture is speckle (Crouch ch. 4): mean power per resolution cell = level · ``cell_power`` /
(cells per scatterer), with Rayleigh or unit magnitudes (rtsar.scene.surfaces.MAGNITUDES).

Characters of ``rows``: ``' '`` or ``'.'`` → 0 (no scatterer), ``':'`` → 0.1, ``'+'`` → 0.3,
``'o'`` → 0.6, ``'#'`` → 1.
"""

from __future__ import annotations

import math

import numpy as np

from ..params import Config
from .model import MAX_GRID_POINTS, Targets
from .surfaces import MAGNITUDES, resolution_cell_m

LEVELS = {" ": 0.0, ".": 0.0, ":": 0.1, "+": 0.3, "o": 0.6, "#": 1.0}

# 5 × 7 glyphs (rows top to bottom); '#' on.
FONT = {
    "A": (".###.", "#...#", "#...#", "#####", "#...#", "#...#", "#...#"),
    "C": (".###.", "#...#", "#....", "#....", "#....", "#...#", ".###."),
    "D": ("####.", "#...#", "#...#", "#...#", "#...#", "#...#", "####."),
    "E": ("#####", "#....", "#....", "####.", "#....", "#....", "#####"),
    "I": (".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."),
    "L": ("#....", "#....", "#....", "#....", "#....", "#....", "#####"),
    "M": ("#...#", "##.##", "#.#.#", "#.#.#", "#...#", "#...#", "#...#"),
    "N": ("#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#", "#...#"),
    "O": (".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."),
    "R": ("####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#"),
    "S": (".####", "#....", "#....", ".###.", "....#", "....#", "####."),
    "T": ("#####", "..#..", "..#..", "..#..", "..#..", "..#..", "..#.."),
    " ": (".....",) * 7,
}


def text_rows(text: str) -> list[str]:
    """The rows of ``text`` set in FONT (one blank column between letters; upper case)."""
    if not isinstance(text, str) or not text:
        raise ValueError("picture.text must be a non-empty string")
    missing = sorted({c for c in text.upper() if c not in FONT})
    if missing:
        raise ValueError(f"picture.text: no glyph for {missing}; the font has {sorted(FONT)}")
    glyphs = [FONT[c] for c in text.upper()]
    return [".".join(g[row] for g in glyphs) for row in range(7)]


def picture_levels(rows) -> np.ndarray:
    """Grey levels [row, column] of a picture given as rows of characters (LEVELS)."""
    if not isinstance(rows, (list, tuple)) or not rows or not all(isinstance(r, str) for r in rows):
        raise ValueError("picture.rows must be a non-empty list of strings")
    width = max(len(r) for r in rows)
    bad = sorted({c for r in rows for c in r if c not in LEVELS})
    if bad or width == 0:
        raise ValueError(f"picture.rows: characters {bad} are not levels; use {sorted(LEVELS)}")
    return np.array([[LEVELS[c] for c in r.ljust(width)] for r in rows], np.float64)


def picture_targets(
    config: Config,
    levels: np.ndarray,
    along_track_m: tuple[float, float],
    slant_range_m: tuple[float, float],
    cell_power: float = 1.0,
    cells_per_scatterer: tuple[float, float] = (1.0, 1.0),
    magnitude: str = "rayleigh",
    seed=0,
) -> Targets:
    """Scatterers on a grid over the rectangle, each with the level of the pixel under it.

    Parameters
    ----------
    config : Config
        Instrument: the resolution cell ρA × ρR at the rectangle's mid range sets the grid.
    levels : float array [row, column]
        Grey levels in [0, 1] (picture_levels, text_rows); row 0 at ``along_track_m[0]``,
        column 0 at ``slant_range_m[0]``.
    along_track_m, slant_range_m : (low, high)
        The rectangle the picture covers, metres (closest-approach positions).
    cell_power : float
        Mean power per resolution cell where the level is 1, when one scatterer sits in every
        cell (amplitude² units of a unit point target).
    cells_per_scatterer : (along, range)
        Grid spacing in resolution cells, each ≥ 1.
    magnitude : "rayleigh" | "unit"
        Circular Gaussian amplitudes, or constant magnitude; the phase is uniform either way.
    seed : int or sequence of int
        Seed of the magnitudes and phases (numpy.random.default_rng).

    Returns
    -------
    Targets
        One scatterer per grid point with a non-zero level (complex128 amplitudes).

    Raises
    ------
    ValueError
        For a grid of more than rtsar.scene.model.MAX_GRID_POINTS points (blank ones
        included), before any is made; for levels, extents or parameters out of range.
    """
    levels = np.asarray(levels, np.float64)
    if levels.ndim != 2 or 0 in levels.shape:
        raise ValueError("picture levels must be a non-empty 2-D array")
    if not (np.isfinite(levels).all() and levels.min() >= 0 and levels.max() <= 1):
        raise ValueError("picture levels must lie in [0, 1]")
    (x0, x1), (r0, r1) = (
        _pair(along_track_m, "along_track_m"),
        _pair(slant_range_m, "slant_range_m"),
    )
    if r0 <= 0:
        raise ValueError("picture.slant_range_m must be > 0")
    if not (math.isfinite(cell_power) and cell_power > 0):
        raise ValueError(f"picture.cell_power must be finite and > 0, got {cell_power!r}")
    step_a, step_r = _pair(cells_per_scatterer, "cells_per_scatterer", ordered=False)
    if step_a < 1 or step_r < 1:
        raise ValueError("picture.cells_per_scatterer must be >= 1 in both directions")
    if magnitude not in MAGNITUDES:
        raise ValueError(f"picture.magnitude must be one of {MAGNITUDES}, got {magnitude!r}")
    rho_a, rho_r = resolution_cell_m(config, 0.5 * (r0 + r1))
    dx, dr = step_a * rho_a, step_r * rho_r
    # Grid points at cell centres of a spacing that divides the rectangle evenly; counted
    # before any is made (a NaN or infinite count fails the test too).
    nx, nr = (x1 - x0) / dx, (r1 - r0) / dr
    if nx <= MAX_GRID_POINTS and nr <= MAX_GRID_POINTS:
        nx, nr = max(1, round(nx)), max(1, round(nr))
    if not nx * nr <= MAX_GRID_POINTS:
        raise ValueError(
            f"a grid of {nx:.4g} x {nr:.4g} scatterers ({step_a:g} x {step_r:g} cells apart) "
            f"exceeds {MAX_GRID_POINTS:,} points: a smaller rectangle or a wider "
            "cells_per_scatterer"
        )
    x = x0 + (np.arange(nx) + 0.5) * (x1 - x0) / nx
    r = r0 + (np.arange(nr) + 0.5) * (r1 - r0) / nr
    rows = np.minimum((np.arange(nx) + 0.5) * levels.shape[0] / nx, levels.shape[0] - 1)
    cols = np.minimum((np.arange(nr) + 0.5) * levels.shape[1] / nr, levels.shape[1] - 1)
    level = levels[rows.astype(int)[:, None], cols.astype(int)[None, :]]
    xs, rs = np.meshgrid(x, r, indexing="ij")
    on = level > 0
    count = int(on.sum())
    mean_power = level[on] * cell_power  # E|a|²; per resolution cell ÷ (step_a · step_r)
    rng = np.random.default_rng(seed)
    phase = np.exp(2j * math.pi * rng.random(count))
    if magnitude == "rayleigh":
        mag = np.sqrt(rng.exponential(1.0, count))
    else:
        mag = np.ones(count)
    amp = np.sqrt(mean_power) * mag * phase
    return Targets(xs[on].copy(), rs[on].copy(), amp.astype(np.complex128))


def _pair(value, name: str, ordered: bool = True) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"picture.{name} must be a pair of numbers, got {value!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or (ordered and not hi > lo):
        raise ValueError(f"picture.{name} must be finite with high > low, got {value!r}")
    return lo, hi


__all__ = ["FONT", "LEVELS", "picture_levels", "picture_targets", "text_rows"]
