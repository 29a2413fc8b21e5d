"""Scene files (TOML, docs/pages/guide/scenes.md): point targets, or a surface for 3D imaging.

A ``[surface]`` table replaces ``[[targets]]``: the scene's scatterers are the surface's speckle
(rtsar.scene.relief.surface_scene: several per resolution cell, circular Gaussian amplitudes)
over ``lines`` image lines, so a 3D scene (Zhao 2014's ridge and drawing pin, a slanted plane,
Crouch's coin relief) can be simulated, recorded and processed from the command line::

    [surface]
    shape = "ridge"          # ridge | drawing_pin | slanted_plane | coin
    height_m = 2.5e-3        # shape parameters, as rtsar.scene.relief names them (a key the
                             # shape does not take is an error that lists the accepted keys)
    lines = 96               # image lines to cover (the scene simulates lines + N - 1 pulses)
    scatterers_per_cell = 2.0
"""

from __future__ import annotations

import inspect
import sys
from dataclasses import replace
from pathlib import Path

from .model import MAX_TARGETS, Scene, Targets, scan_extent, scene_from_dict, scene_settings
from .picture import picture_levels, picture_targets, text_rows
from .relief import (
    SurfaceScene,
    default_spacing_m,
    penny_relief,
    ridge,
    slanted_plane,
    sphere_cap,
    surface_scene,
)
from .surfaces import combine_targets

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

SHAPES = {
    "ridge": ridge,
    "drawing_pin": sphere_cap,
    "slanted_plane": slanted_plane,
    "coin": penny_relief,
}
_SURFACE_KEYS = {"shape", "lines", "scatterers_per_cell"}
_PICTURE_KEYS = {
    "text",
    "rows",
    "along_track_m",
    "slant_range_m",
    "cell_power",
    "cells_per_scatterer",
    "magnitude",
}


def scene_from_table(d: dict, name: str = "scene") -> Scene:
    """A Scene from a parsed scene file: point targets and pictures, or a ``[surface]``."""
    if "pictures" in d:
        return _with_pictures(d, name)
    if "surface" not in d:
        return scene_from_dict(d, name)
    return surface_from_table(d, name).scene


def surface_from_table(d: dict, name: str = "scene") -> SurfaceScene:
    """The SurfaceScene of a parsed scene file with a ``[surface]`` (its truth: ``.truth``)."""
    table = d["surface"]
    if not isinstance(table, dict):
        raise ValueError("'surface' must be a table: write [surface]")
    for key in ("targets", "pulses", "start_along_track_m"):
        if key in d:
            raise ValueError(f"a [surface] scene sets its own {key} (from the surface's lines)")
    rest = {k: v for k, v in d.items() if k != "surface"}
    unknown = set(rest) - {"preset", "seed", "waveform", "geometry", "processor", "effects", "name"}
    if unknown:
        raise ValueError(f"scene: unknown keys {sorted(unknown)}")
    cfg, effects, seed = scene_settings(rest)
    if not cfg.geometry.platform_height_m > 0:
        raise ValueError(
            "a [surface] scene needs the platform's height above the surface's reference plane: "
            "set platform_height_m > 0 in [geometry] (e.g. 1.386 for zhao-insal: 2.4 m seen "
            "54.7° from the vertical, as the built-in insal-ridge)"
        )
    shape = table.get("shape")
    if shape not in SHAPES:
        raise ValueError(f"surface.shape must be one of {sorted(SHAPES)}, got {shape!r}")
    lines = table.get("lines", 96)
    if isinstance(lines, bool) or not isinstance(lines, int) or not 1 <= lines <= 100_000:
        raise ValueError(f"surface.lines must be an integer in 1..100000, got {lines!r}")
    per_cell = table.get("scatterers_per_cell", 2.0)
    if (
        isinstance(per_cell, bool)
        or not isinstance(per_cell, (int, float))
        or not 0 < per_cell <= 50
    ):
        raise ValueError(f"surface.scatterers_per_cell must be in (0, 50], got {per_cell!r}")
    params = {k: v for k, v in table.items() if k not in _SURFACE_KEYS}
    accepted = sorted(_SURFACE_KEYS) + list(inspect.signature(SHAPES[shape]).parameters)
    unknown = sorted(set(params) - set(accepted))
    if unknown:
        raise ValueError(f"surface ({shape}): unknown keys {unknown}; accepted keys: {accepted}")
    try:
        surface = SHAPES[shape](**params)
    except TypeError as exc:
        raise ValueError(f"surface ({shape}): {exc}") from None
    return surface_scene(  # (its grid bounded by MAX_GRID_POINTS before it is made)
        cfg,
        surface,
        lines,
        spacing_m=default_spacing_m(cfg, float(per_cell)),
        seed=seed,
        effects=effects,
        name=d.get("name", name),
    )


def _with_pictures(d: dict, name: str) -> Scene:
    """Point targets plus ``[[pictures]]`` (rtsar.scene.picture): diffuse scatterers drawn from
    text or rows of characters, seeded by the scene's seed and the picture's index."""
    rest = {k: v for k, v in d.items() if k != "pictures"}
    if "surface" in rest:
        raise ValueError("a scene has [surface] or [[pictures]], not both")
    points = scene_from_dict(rest, name)
    cfg = points.config
    parts = [points.targets]
    tables = d["pictures"]
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise ValueError("'pictures' must be an array of tables: write [[pictures]]")
    for i, t in enumerate(tables):
        unknown = set(t) - _PICTURE_KEYS
        if unknown:
            raise ValueError(f"pictures[{i}]: unknown keys {sorted(unknown)}")
        if ("text" in t) == ("rows" in t):
            raise ValueError(f"pictures[{i}]: give exactly one of text, rows")
        for key in ("along_track_m", "slant_range_m"):
            if key not in t:
                raise ValueError(f"pictures[{i}]: {key} = [low, high] is required")
        try:
            levels = picture_levels(text_rows(t["text"]) if "text" in t else t["rows"])
            power = t.get("cell_power", 1.0)
            if isinstance(power, bool) or not isinstance(power, (int, float)):
                raise ValueError(f"picture.cell_power must be a number, got {power!r}")
            parts.append(
                picture_targets(
                    cfg,
                    levels,
                    t["along_track_m"],
                    t["slant_range_m"],
                    float(power),
                    t.get("cells_per_scatterer", (1.0, 1.0)),
                    t.get("magnitude", "rayleigh"),
                    seed=(points.seed, i),
                )
            )
        except ValueError as exc:
            raise ValueError(f"pictures[{i}]: {exc}") from None
        made = sum(len(p) for p in parts)  # counted after each picture: they never pile up
        if made > MAX_TARGETS:
            raise ValueError(f"scene: {made} scatterers by pictures[{i}] exceed {MAX_TARGETS}")
    targets = combine_targets(*parts)
    start, pulses = scan_extent(cfg, targets, d.get("start_along_track_m"), d.get("pulses"))
    return replace(points, targets=targets, pulses=pulses, start_along_track_m=start)


BUILT_IN = Path(__file__).with_name("scenes")  # demo.toml, insal-ridge.toml, ...


def built_in_scenes() -> list[str]:
    return sorted(p.stem for p in BUILT_IN.glob("*.toml"))


def load_scene(path: str | Path) -> Scene:
    """Read a TOML scene file, or a built-in scene by name (``demo``, ``insal-ridge``); errors
    name the file and the offending key."""
    return _read(path, scene_from_table)


def load_surface_scene(path: str | Path) -> SurfaceScene | None:
    """The ``[surface]`` of a scene file with its truth (None for a scene without one)."""
    return _read(path, lambda d, name: surface_from_table(d, name) if "surface" in d else None)


def load_point_targets(path: str | Path) -> Targets:
    """The scene file's ``[[targets]]`` alone (no pictures, no surface): its point targets."""
    keep = ("preset", "seed", "waveform", "geometry", "processor", "targets", "name")
    return _read(path, lambda d, name: scene_from_dict({k: d[k] for k in keep if k in d}).targets)


def _read(path: str | Path, make):
    path = Path(path)
    if (
        not path.exists()
        and path.parent == Path(".")
        and (BUILT_IN / f"{path.name}.toml").is_file()
    ):
        path = BUILT_IN / f"{path.name}.toml"
    try:
        with path.open("rb") as f:
            d = tomllib.load(f)
    except FileNotFoundError:
        raise ValueError(
            f"scene file not found: {path} (built-in scenes: {', '.join(built_in_scenes())})"
        ) from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    try:
        return make(d, path.stem)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{path}: {exc}") from None
