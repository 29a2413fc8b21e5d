"""Scene files (TOML): which instrument, which scatterers, which effects.

Format (every key optional unless marked)::

    preset = "psaltis-jpl"        # one of rtsar.params.PRESETS; or give all three tables below
    seed = 1                      # RNG seed of the effects (noise, ...)
    pulses = 4096                 # shots to simulate (default: enough to image every target)
    start_along_track_m = -40.0   # position of shot 0 (default: first target - A/2 - margin)

    [waveform]    # overrides of the preset's fields (kind = "pulsed" | "fmcw" when no preset)
    [geometry]    # wavelength_m, slant_range_m, along_track_step_m, prf_hz, antenna_length_m, ...
    [processor]   # aperture_pulses, range_bins, windows, correlator, micro_batch, ...

    [[targets]]                   # point scatterers
    along_track_m = 0.0           # required
    slant_range_m = 20000.0       # closest-approach slant range, or:
    # ground_range_m = ...; height_m = 0.0   (needs geometry.platform_height_m > 0)
    amplitude = 1.0               # |a|
    phase_rad = 0.0               # arg a

    [[effects]]                   # simulated only when named here, in this order
    name = "noise"                # see rtsar.scene.effects.REGISTRY
    snr_db = 10.0                 # the effect's own parameters

Unknown keys are errors (a typo must not silently fall back to a default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from ..lens.plan import range_axis_m
from ..params import Config, Geometry, Processor, waveform_from_dict
from ..presets import preset
from .effects import load_effects

_TOP_KEYS = {
    "preset",
    "seed",
    "pulses",
    "start_along_track_m",
    "waveform",
    "geometry",
    "processor",
    "targets",
    "effects",
    "name",
}
_TARGET_KEYS = {
    "along_track_m",
    "slant_range_m",
    "ground_range_m",
    "height_m",
    "amplitude",
    "phase_rad",
}
DEMO_SCENE = Path(__file__).with_name("scenes") / "demo.toml"
MAX_PULSES = 1_000_000_000
MAX_TARGETS = 100_000
# The grid a [[pictures]] table or a [surface] lays out, blank or dropped points included: a
# scene file declaring more is refused before any point is made (the kept ones: MAX_TARGETS).
MAX_GRID_POINTS = 1_000_000


@dataclass(frozen=True, eq=False)
class Targets:
    """Point scatterers: closest-approach position and complex amplitude (arrays of equal size)."""

    along_track_m: np.ndarray
    slant_range_m: np.ndarray
    amplitude: np.ndarray  # complex128
    # Optional 3D position (None when a scene gives slant ranges only): horizontal distance from
    # the track and height above the reference plane, for receivers off the main one (3D effects).
    ground_range_m: np.ndarray | None = None
    height_m: np.ndarray | None = None

    def __post_init__(self):
        n = len(self.along_track_m)
        for name in ("slant_range_m", "amplitude", "ground_range_m", "height_m"):
            value = getattr(self, name)
            if value is not None and len(value) != n:
                raise ValueError(f"Targets.{name} has {len(value)} entries, expected {n}")

    def __len__(self):
        return len(self.along_track_m)


@dataclass(frozen=True, eq=False)
class Scene:
    config: Config
    targets: Targets
    pulses: int
    start_along_track_m: float
    seed: int = 0
    effects: tuple = ()  # ((name, {params}), ...)
    name: str = "scene"
    # A surface's speckle is laid out a few bins past the range window on purpose (the edge
    # bins then see a whole neighbourhood): those scatterers are not "outside the swath".
    extends_past_window: bool = False

    def targets_outside_swath(self) -> list[int]:
        """Indices of targets whose range lies outside the processor's range window (none for
        a surface, whose scatterers reach past it on purpose: ``extends_past_window``)."""
        if self.extends_past_window:
            return []
        rm = range_axis_m(self.config)
        margin = self.config.waveform.range_resolution_m
        r = self.targets.slant_range_m
        return [int(i) for i in np.flatnonzero((r < rm[0] - margin) | (r > rm[-1] + margin))]

    def along_track_of(self, pulse: np.ndarray | int):
        return (
            self.start_along_track_m + np.asarray(pulse) * self.config.geometry.along_track_step_m
        )

    def to_dict(self) -> dict:
        """Round-trippable description (written next to every output)."""
        return {
            "name": self.name,
            "seed": self.seed,
            "pulses": self.pulses,
            "start_along_track_m": self.start_along_track_m,
            **self.config.to_dict(),
            "targets": [
                {
                    "along_track_m": float(x),
                    "slant_range_m": float(r),
                    "amplitude": float(abs(a)),
                    "phase_rad": float(np.angle(a)),
                }
                for x, r, a in zip(
                    self.targets.along_track_m,
                    self.targets.slant_range_m,
                    self.targets.amplitude,
                    strict=True,
                )
            ],
            "effects": [{"name": n, **p} for n, p in self.effects],
        }


def _override(obj, table: dict, what: str):
    names = {f.name for f in fields(obj) if f.init}
    unknown = set(table) - names - {"kind"}
    if unknown:
        raise ValueError(f"[{what}] unknown keys {sorted(unknown)}; known: {sorted(names)}")
    if "kind" in table and table["kind"] != obj.kind:
        raise ValueError(f"[{what}] kind {table['kind']!r} differs from the preset's {obj.kind!r}")
    return replace(obj, **{k: v for k, v in table.items() if k != "kind"})


def _config(d: dict) -> Config:
    if "preset" in d:
        base = preset(d["preset"])
        wf = _override(base.waveform, d.get("waveform", {}), "waveform")
        geo = _override(base.geometry, d.get("geometry", {}), "geometry")
        proc = _override(base.processor, d.get("processor", {}), "processor")
        return Config(wf, geo, proc)
    missing = [k for k in ("waveform", "geometry", "processor") if k not in d]
    if missing:
        raise ValueError(f"scene needs a preset or the tables {missing}")
    return Config(
        waveform_from_dict(d["waveform"]), Geometry(**d["geometry"]), Processor(**d["processor"])
    )


def _number(table: dict, key: str, where: str, default=None) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{where}.{key} must be a number, got {value!r}")
    return float(value)


def _table_list(d: dict, key: str) -> list:
    rows = d.get(key, [])
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise ValueError(f"'{key}' must be an array of tables: write [[{key}]], not [{key}]")
    return rows


def _targets(rows: list, cfg: Config) -> Targets:
    if len(rows) > MAX_TARGETS:
        raise ValueError(
            f"scene: {len(rows)} targets exceed {MAX_TARGETS} (each costs a phase per sample per "
            "pulse; build extended scenes with rtsar.scene.surfaces)"
        )
    xs, rs, amps, grounds, heights = [], [], [], [], []
    for i, t in enumerate(rows):
        unknown = set(t) - _TARGET_KEYS
        if unknown:
            raise ValueError(
                f"targets[{i}]: unknown keys {sorted(unknown)}; known: {sorted(_TARGET_KEYS)}"
            )
        if "along_track_m" not in t:
            raise ValueError(f"targets[{i}]: along_track_m is required")
        if ("slant_range_m" in t) == ("ground_range_m" in t):
            raise ValueError(f"targets[{i}]: give exactly one of slant_range_m, ground_range_m")
        where = f"targets[{i}]"
        if "slant_range_m" in t:
            if "height_m" in t:
                raise ValueError(f"{where}: height_m goes with ground_range_m")
            r = _number(t, "slant_range_m", where)
            grounds.append(None)
            heights.append(0.0)
        else:
            h_platform = cfg.geometry.platform_height_m
            if h_platform <= 0:
                raise ValueError(f"{where}: ground_range_m needs geometry.platform_height_m > 0")
            ground = _number(t, "ground_range_m", where)
            height = _number(t, "height_m", where, 0.0)
            r = math.hypot(ground, h_platform - height)
            grounds.append(ground)
            heights.append(height)
        amp = _number(t, "amplitude", where, 1.0) * np.exp(1j * _number(t, "phase_rad", where, 0.0))
        values = (_number(t, "along_track_m", where), r, amp.real, amp.imag)
        if not all(math.isfinite(v) for v in values) or r <= 0:
            raise ValueError(f"{where}: positions and amplitude must be finite, range > 0")
        xs.append(values[0])
        rs.append(r)
        amps.append(amp)
    targets = Targets(np.array(xs, float), np.array(rs, float), np.array(amps, np.complex128))
    if all(g is None for g in grounds):
        return targets
    # Some targets are given on the ground: keep their 3D position for off-track receivers (the
    # others sit on the reference plane, h = 0, at the ground range their slant range implies).
    h = cfg.geometry.platform_height_m
    ground = [
        math.sqrt(max(r * r - h * h, 0.0)) if g is None else g
        for g, r in zip(grounds, rs, strict=True)
    ]
    return replace(targets, ground_range_m=np.array(ground), height_m=np.array(heights))


def scan_extent(cfg: Config, targets: Targets, start, pulses) -> tuple[float, int]:
    """Default scan: from A/2 plus a margin before the first target to as far after the last."""
    step = cfg.geometry.along_track_step_m
    n = cfg.processor.aperture_pulses
    # Past the first/last target: half an aperture plus 8 azimuth resolutions (at least 8 lines),
    # so the outermost targets' mainlobes and first sidelobes are inside the image.
    margin_m = 0.5 * n * step + max(8 * step, 8 * cfg.azimuth_resolution_m())
    # A squinted beam sees a target from around its closest approach plus u_c = R0 tan θ at its
    # own range; the image's lines trail their apertures by u_mid, u_c at the range centre
    # (rtsar.ccd.base.line_azimuth_m).  Both must hold the target with the margin: a target at
    # a swath edge, u_c - u_mid over a hundred metres at RADARSAT-1's squint, was cut off.
    g = cfg.geometry
    u_mid = g.beam_centre_offset_m(cfg.processor.range_centre_m or g.slant_range_m)
    seen = np.concatenate(
        [
            targets.along_track_m + g.beam_centre_offset_m(targets.slant_range_m),
            targets.along_track_m + u_mid,
        ]
    )
    lo = float(seen.min()) if len(targets) else 0.0
    hi = float(seen.max()) if len(targets) else 0.0
    start = float(lo - margin_m if start is None else start)
    if not math.isfinite(start):
        raise ValueError("scene: start_along_track_m must be finite")
    if pulses is None:
        pulses = int(math.ceil((hi + margin_m - start) / step)) + 1
    if not (isinstance(pulses, int) and pulses >= 1):
        raise ValueError(f"scene: pulses must be an integer >= 1, got {pulses!r}")
    if pulses > MAX_PULSES:
        raise ValueError(f"scene: pulses = {pulses} exceeds {MAX_PULSES} (a day at 10 kHz)")
    return start, pulses


def scene_from_dict(d: dict, name: str = "scene") -> Scene:
    """Build and validate a Scene from the parsed TOML mapping."""
    unknown = set(d) - _TOP_KEYS
    if unknown:
        # [[pictures]] and [surface] are read by rtsar.scene.files before it comes here.
        known = sorted(_TOP_KEYS | {"pictures", "surface"})
        raise ValueError(f"scene: unknown keys {sorted(unknown)}; known: {known}")
    cfg, effects, seed = scene_settings(d)
    targets = _targets(_table_list(d, "targets"), cfg)
    start, pulses = scan_extent(cfg, targets, d.get("start_along_track_m"), d.get("pulses"))
    return Scene(cfg, targets, pulses, start, seed, effects, d.get("name", name))


def recorded_scene(d: dict | None, source) -> Scene | None:
    """The scene a recording carries (None when it has none); ValueError naming ``source``
    when it does not parse."""
    if not d:
        return None
    if isinstance(d, dict) and "spotlight" in d:  # rtsar.app.spotlight's recordings
        raise ValueError(
            f"{source} is a spotlight recording: form its image with `rtsar spotlight {source}`"
        )
    try:
        return scene_from_dict(d, name=d.get("name", "scene"))
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{source}: the recorded scene does not parse ({exc})") from None


def scene_settings(d: dict) -> tuple[Config, tuple, int]:
    """The configuration, effects and seed of a scene mapping, validated (everything a scene
    has besides its scatterers; rtsar.scene.files builds surface scenes from it)."""
    cfg = _config(d)
    effects = []
    for i, e in enumerate(_table_list(d, "effects")):
        if "name" not in e:
            raise ValueError(f"effects[{i}]: name is required")
        params = {k: v for k, v in e.items() if k != "name"}
        effects.append((e["name"], params))
    load_effects(effects, cfg)  # validates names and parameters now, so errors name the file
    seed = d.get("seed", 0)
    if not isinstance(seed, int):
        raise ValueError("scene: seed must be an integer")
    return cfg, tuple(effects), seed


def point_scene(
    cfg: Config,
    along_track_m,
    slant_range_m,
    amplitude=None,
    effects=(),
    seed=0,
    pulses=None,
    start_along_track_m=None,
    name="points",
) -> Scene:
    """Programmatic scene of point targets (used by tests and reports)."""
    x = np.atleast_1d(np.asarray(along_track_m, dtype=float))
    r = np.atleast_1d(np.asarray(slant_range_m, dtype=float))
    a = (
        np.ones(x.shape, np.complex128)
        if amplitude is None
        else np.asarray(amplitude, np.complex128)
    )
    if not (x.shape == r.shape == a.shape):
        raise ValueError("along_track_m, slant_range_m and amplitude must have one length")
    targets = Targets(x, r, a)
    start, pulses = scan_extent(cfg, targets, start_along_track_m, pulses)
    return Scene(cfg, targets, pulses, start, seed, tuple((n, dict(p)) for n, p in effects), name)


__all__ = [
    "recorded_scene",
    "Scene",
    "Targets",
    "scene_from_dict",
    "scene_settings",
    "point_scene",
    "DEMO_SCENE",
]
