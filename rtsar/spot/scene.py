"""Spotlight scenes (TOML): instrument, arc, optional bistatic receiver, 3-D scatterers, rotation.

A spotlight scene is its own scene type: the strip-map scene model (rtsar.scene.model) places
scatterers by along-track position and closest-approach range, which a spotlight arc has not.
The instrument tables (preset, [waveform], [geometry], [processor]) and the effects are read by
the strip-map model's own ``scene_settings``, so presets and overrides behave the same.

Format (every key optional)::

    preset = "crouch-spotlight"   # default
    seed = 0
    name = "spot"
    [spotlight]
    sweep_deg = 5.0               # or pulses = N; the arc step is geometry.along_track_step_m
    centre_angle_deg = 0.0
    bistatic_range_m = 4.6        # a fixed bistatic receiver (Crouch Fig. 36), with:
    bistatic_angle_deg = 8.0
    rotation_deg = 0.0            # rotation stage: targets turned about the beam axis (y)
    [[targets]]
    x_m = 0.0                     # cross-range; y_m down-range; z_m out of plane
    y_m = 0.0
    z_m = 0.0
    amplitude = 1.0
    phase_rad = 0.0
    [[effects]]                   # only effects that act on a finished shot (noise, piston)
    name = "noise"
    snr_db = 20.0

The rotation stage (Crouch ch. 8, Fig. 33) turns the scatterers by ``rotation_deg`` about the
beam axis through the scene centre, (x, z) → (x cos φ - z sin φ, x sin φ + z cos φ): a quarter
turn puts z where x was, which projective SAL exploits.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from ..params import Config, FMCWChirp
from ..presets import preset
from ..scene.model import scene_settings
from .geometry import SpotlightGeometry

_TOP = {"preset", "seed", "name", "waveform", "geometry", "processor", "spotlight", "targets"}
_TOP |= {"effects"}
_SPOT = {
    "sweep_deg",
    "pulses",
    "centre_angle_deg",
    "bistatic_range_m",
    "bistatic_angle_deg",
    "bistatic_lo_range_m",
    "rotation_deg",
}
_TARGET = {"x_m", "y_m", "z_m", "amplitude", "phase_rad"}
DEFAULT_SWEEP_DEG = 5.0  # Crouch: "At 5 degrees, the cross range resolution is below 10 microns"
MAX_SPOT_TARGETS = 100_000


@dataclass(frozen=True, eq=False)
class SpotScene:
    """Everything a spotlight simulation needs (positions in the frame of rtsar.spot.geometry)."""

    config: Config
    geometry: SpotlightGeometry
    position_m: np.ndarray  # float64 [target, 3], before the rotation stage
    amplitude: np.ndarray  # complex128 [target]
    rotation_rad: float = 0.0
    seed: int = 0
    effects: tuple = ()
    name: str = "spot"

    def __post_init__(self):
        if not isinstance(self.config.waveform, FMCWChirp):
            raise ValueError("spotlight scenes need an FMCW waveform (Crouch's chirp)")
        p = np.asarray(self.position_m)
        if p.ndim != 2 or p.shape[1] != 3 or len(p) != len(self.amplitude):
            raise ValueError("spotlight targets: position_m [n, 3] and amplitude [n] expected")
        if len(p) > MAX_SPOT_TARGETS:
            raise ValueError(f"spotlight scene: more than {MAX_SPOT_TARGETS} targets")
        if not (np.isfinite(p).all() and np.isfinite(self.amplitude).all()):
            raise ValueError("spotlight targets: positions and amplitudes must be finite")
        if not math.isfinite(self.rotation_rad):
            raise ValueError("spotlight rotation must be finite")

    def rotated_m(self) -> np.ndarray:
        """Target positions after the rotation stage (turned about the y axis)."""
        c, s = math.cos(self.rotation_rad), math.sin(self.rotation_rad)
        p = np.asarray(self.position_m, np.float64)
        return np.stack([c * p[:, 0] - s * p[:, 2], p[:, 1], s * p[:, 0] + c * p[:, 2]], -1)

    def with_rotation(self, rotation_rad: float) -> SpotScene:
        return replace(self, rotation_rad=float(rotation_rad))

    def to_dict(self) -> dict:
        """Round-trippable description (written into recordings and images)."""
        return {
            "name": self.name,
            "seed": self.seed,
            **self.config.to_dict(),
            "spotlight_geometry": self.geometry.to_dict(),
            "rotation_rad": self.rotation_rad,
            "targets": [
                {"position_m": [float(v) for v in p], "amplitude": [float(a.real), float(a.imag)]}
                for p, a in zip(self.position_m, self.amplitude, strict=True)
            ],
            "effects": [{"name": n, **p} for n, p in self.effects],
        }


def _num(t: dict, key: str, where: str, default: float) -> float:
    v = t.get(key, default)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"{where}.{key} must be a finite number, got {v!r}")
    return float(v)


def spot_scene_from_dict(d: dict, name: str = "spot") -> SpotScene:
    """Build and validate a spotlight scene from its parsed TOML mapping (module docstring)."""
    if not isinstance(d, dict):
        raise ValueError("a spotlight scene is a table of settings")
    unknown = set(d) - _TOP
    if unknown:
        raise ValueError(f"spotlight scene: unknown keys {sorted(unknown)}; known {sorted(_TOP)}")
    d = {"preset": "crouch-spotlight", **d}
    sub = {k: v for k, v in d.items() if k not in ("spotlight", "targets", "name")}
    cfg, effects, seed = scene_settings(sub)
    sp = d.get("spotlight", {})
    if not isinstance(sp, dict) or set(sp) - _SPOT:
        raise ValueError(f"[spotlight]: unknown keys {sorted(set(sp) - _SPOT)}; known {_SPOT}")
    g = cfg.geometry
    if "pulses" in sp and "sweep_deg" in sp:
        raise ValueError("[spotlight]: give pulses or sweep_deg, not both")
    if "pulses" in sp:
        pulses = sp["pulses"]
        if not isinstance(pulses, int):
            raise ValueError("[spotlight].pulses must be an integer")
    else:
        sweep = math.radians(_num(sp, "sweep_deg", "[spotlight]", DEFAULT_SWEEP_DEG))
        pulses = int(round(sweep * g.slant_range_m / g.along_track_step_m)) + 1
    bi = {}
    if "bistatic_range_m" in sp or "bistatic_angle_deg" in sp:
        bi = {
            "bistatic_range_m": _num(sp, "bistatic_range_m", "[spotlight]", g.slant_range_m),
            "bistatic_angle_rad": math.radians(_num(sp, "bistatic_angle_deg", "[spotlight]", 8.0)),
        }
        if "bistatic_lo_range_m" in sp:
            bi["bistatic_lo_range_m"] = _num(sp, "bistatic_lo_range_m", "[spotlight]", 0.0)
    geo = SpotlightGeometry(
        g.slant_range_m,
        g.along_track_step_m,
        pulses,
        math.radians(_num(sp, "centre_angle_deg", "[spotlight]", 0.0)),
        **bi,
    )
    rows = d.get("targets", [])
    if not isinstance(rows, list) or not all(isinstance(r, dict) for r in rows):
        raise ValueError("'targets' must be an array of tables: write [[targets]]")
    pos, amp = [], []
    for i, t in enumerate(rows):
        bad = set(t) - _TARGET
        if bad:
            raise ValueError(f"targets[{i}]: unknown keys {sorted(bad)}; known {sorted(_TARGET)}")
        w = f"targets[{i}]"
        pos.append([_num(t, k, w, 0.0) for k in ("x_m", "y_m", "z_m")])
        amp.append(_num(t, "amplitude", w, 1.0) * np.exp(1j * _num(t, "phase_rad", w, 0.0)))
    return SpotScene(
        cfg,
        geo,
        np.array(pos, np.float64).reshape(-1, 3),
        np.array(amp, np.complex128),
        math.radians(_num(sp, "rotation_deg", "[spotlight]", 0.0)),
        seed,
        effects,
        str(d.get("name", name)),
    )


def spot_points(
    config: Config, geometry: SpotlightGeometry, position_m, amplitude=None, **kw
) -> SpotScene:
    """Programmatic spotlight scene of point targets (tests, reports)."""
    p = np.asarray(position_m, np.float64).reshape(-1, 3)
    a = np.ones(len(p), np.complex128) if amplitude is None else np.asarray(amplitude, complex)
    return SpotScene(config, geometry, p, a, **kw)


def default_spot_scene() -> SpotScene:
    """The built-in spotlight scene: crouch-spotlight, 5° sweep, five points over the spot."""
    pts = [
        {"x_m": 0.0, "y_m": 0.0},
        {"x_m": 4e-3, "y_m": 2e-3, "amplitude": 0.8},
        {"x_m": -6e-3, "y_m": -3e-3, "amplitude": 0.8},
        {"x_m": 7e-3, "y_m": -6e-3, "amplitude": 0.6},
        {"x_m": -8e-3, "y_m": 7e-3, "amplitude": 0.6},
    ]
    return spot_scene_from_dict({"targets": pts}, name="spotlight-scene")


def reduced_spotlight(
    samples: int = 64, extent_m: float = 3.2e-3, sweep_deg: float = 5.0, **bistatic
) -> tuple[Config, SpotlightGeometry]:
    """crouch-spotlight scaled down for tests and measurements: the same chirp rate, carrier
    and arc, ``samples`` per shot (range window samples·c/2B) and a step angle λ/(2·extent_m)
    (alias-free cross-range extent), so ``sweep_deg`` takes a few hundred shots, not 8030."""
    base = preset("crouch-spotlight")
    wf = replace(base.waveform, sample_rate_hz=samples / base.waveform.chirp_duration_s)
    lam, r0 = base.geometry.wavelength_m, base.geometry.slant_range_m
    step_rad = lam / (2.0 * extent_m)
    geo_cfg = replace(base.geometry, along_track_step_m=step_rad * r0)
    cfg = Config(wf, geo_cfg, replace(base.processor, aperture_pulses=2, range_bins=samples))
    pulses = int(round(math.radians(sweep_deg) / step_rad)) + 1
    return cfg, SpotlightGeometry(r0, step_rad * r0, pulses, **bistatic)


BUILT_IN_SPOT_SCENES = ("spotlight-scene",)


def load_spot_scene(source: str | Path | None) -> SpotScene:
    """A spotlight scene from a TOML file, or the built-in "spotlight-scene" (None: that one)."""
    if source is None or str(source) in BUILT_IN_SPOT_SCENES:
        return default_spot_scene()
    path = Path(source)
    try:
        with path.open("rb") as f:
            d = tomllib.load(f)
    except OSError as exc:
        raise ValueError(f"{path}: cannot read the spotlight scene ({exc.strerror})") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML ({exc})") from None
    try:
        return spot_scene_from_dict(d, name=path.stem)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
