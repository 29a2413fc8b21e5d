"""Phase-error and chirp corrections in the stream, chosen by name, in the order that works.

Crouch (2012, ch. 4-5) calls SAL images "worthless" before phase correction; the INO phase-error
patent advises the reference-region correction first and autofocus for the residual.  The stages:

======================  ======  ===========================================================
name                    where   what (module)
======================  ======  ===========================================================
``hcn``                 raw     start-frequency alignment on the HCN cell (focus.hcn_align)
``linearize``           raw     chirp linearization on the reference interferometer
                                (focus.linearize; with ``hcn`` both in one resampling)
``reference_region``    raw     α/β from the reference region (patent eqs. 5-11,
                                focus.reference_region)
``pra``                 lines   phase-to-retro (Crouch; focus.pra)
``pga``                 lines   phase gradient autofocus (Crouch eqs. 4.14-4.17; focus.pga)
======================  ======  ===========================================================

"raw" stages run on the shots between ingest and the AO lens and see the auxiliary channels;
"lines" stages run on range-compressed pulses between the lens and the shifting CCD.  All keep
pulse order; PGA holds a block of pulses (its latency, ``latency_pulses``) and gives them back at
``flush``.  Each stage keeps its own counters; ``CorrectionChain.counters`` reports them prefixed
with the stage's name, so they appear in the stats beside the pipeline's.
"""

from __future__ import annotations

from dataclasses import asdict, is_dataclass

import numpy as np

from .params import Config

ORDER = ("hcn", "linearize", "reference_region", "pra", "pga")
DOMAIN = {
    "hcn": "raw",
    "linearize": "raw",
    "reference_region": "raw",
    "pra": "lines",
    "pga": "lines",
}
_COUNTER_ATTRS = (
    "pulses_in",
    "shots_not_corrected",
    "nonfinite_lines",
    "pulses_not_estimated",
    "nonfinite_reference",
)


def parse_spec(text: str) -> tuple[str, dict]:
    """``"name"`` or ``"name:key=value,key=value"`` (numbers as floats) → (name, params)."""
    name, _, rest = text.partition(":")
    name = name.strip().replace("-", "_")
    if name not in ORDER:
        raise ValueError(f"unknown correction {name!r}; choose from {', '.join(ORDER)}")
    params = {}
    for item in filter(None, (s.strip() for s in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise ValueError(f"correction {name}: expected key=value, got {item!r}")
        try:
            params[key.strip()] = float(value)
        except ValueError:
            params[key.strip()] = value.strip()
    return name, params


def _scene_effect(scene, name: str):
    """The instantiated effect ``name`` of the scene (its geometry/delay settings), or None."""
    if scene is None or name not in [n for n, _ in scene.effects]:
        return None
    from .scene.effects import load_effects

    specs = [(n, p) for n, p in scene.effects if n == name]
    return load_effects(specs, scene.config)[0]


def make_stage(
    name: str,
    config: Config,
    params: dict,
    scene=None,
    start_along_track_m=0.0,
    with_hcn: bool = False,
):
    """One correction stage (see the table above); ``scene`` supplies geometry where needed."""
    params = dict(params)
    if name == "hcn":
        from .focus.hcn_align import HCNAligner

        return HCNAligner(config, **params)
    if name == "linearize":
        from .focus.hcn_align import HCNAligner
        from .focus.linearize import ChirpLinearizer

        ri = _scene_effect(scene, "reference_interferometer")
        if ri is not None and "delay_s" not in params:
            params["delay_s"] = getattr(ri, "delay_s", None)
        aligner = HCNAligner(config) if with_hcn else None
        return ChirpLinearizer(config, aligner=aligner, **params)
    if name == "reference_region":
        from .focus.reference_region import ReferenceGeometry, ReferenceRegionCorrector

        effect = _scene_effect(scene, "reference_region")
        if effect is None:
            raise ValueError(
                "the reference_region correction needs the patent geometry (d, D, the region): "
                "use a scene with the reference_region effect"
            )
        return ReferenceRegionCorrector(config, ReferenceGeometry.from_effect(effect), **params)
    if name == "pra":
        from .focus.pra import PhaseToRetro

        if "along_track_m" not in params or "range_m" not in params:
            if scene is None or not len(scene.targets):
                raise ValueError("pra needs the retro-reflector: pra:along_track_m=X,range_m=R")
            k = int(np.argmax(np.abs(scene.targets.amplitude)))  # the brightest point
            params.setdefault("along_track_m", float(scene.targets.along_track_m[k]))
            params.setdefault("range_m", float(scene.targets.slant_range_m[k]))
        x, r = params.pop("along_track_m"), params.pop("range_m")
        return PhaseToRetro(config, x, r, start_along_track_m, **params)
    if name == "pga":
        from .focus.pga import PGASettings, PGAStage

        ints = {
            "block_pulses",
            "hop_pulses",
            "initial_window_bins",
            "min_window_bins",
            "max_iterations",
            "max_range_bins",
            "segments",
            "min_pulses",
        }
        settings = PGASettings(**{k: int(v) if k in ints else v for k, v in params.items()})
        return PGAStage(config, settings)
    raise ValueError(f"unknown correction {name!r}")  # pragma: no cover - parse_spec checks


def _counters(name: str, stage) -> dict:
    c = getattr(stage, "counters", None)
    if is_dataclass(c):
        c = asdict(c)
    if not isinstance(c, dict):
        c = {a: getattr(stage, a) for a in _COUNTER_ATTRS if hasattr(stage, a)}
    out = {}
    for k, v in c.items():
        if isinstance(v, dict):
            out.update({f"{name}.{k}.{kk}": int(vv) for kk, vv in v.items()})
        elif isinstance(v, (int, np.integer)):
            out[f"{name}.{k}"] = int(v)
    return out


class CorrectionChain:
    """The chosen stages in ORDER: ``raw`` before the lens, ``lines`` after it, ``flush`` at end."""

    def __init__(self, named_stages: list[tuple[str, object]]):
        """(name, stage) pairs, run in the given order (``from_specs`` sorts them by ORDER); a
        stage whose name is not in DOMAIN says where it runs by its ``domain`` attribute."""
        self.named = list(named_stages)
        where = {n: DOMAIN.get(n, getattr(s, "domain", None)) for n, s in self.named}
        bad = [n for n, d in where.items() if d not in ("raw", "lines")]
        if bad:
            raise ValueError(f"corrections {bad}: a stage's domain is 'raw' or 'lines'")
        self.raw_stages = [s for n, s in self.named if where[n] == "raw"]
        self.line_stages = [s for n, s in self.named if where[n] == "lines"]

    @classmethod
    def from_specs(cls, specs, config: Config, scene=None, start_along_track_m=0.0):
        """Build from ``["pga", "pra:along_track_m=0,range_m=1.5", ...]``."""
        parsed = [parse_spec(s) if isinstance(s, str) else s for s in specs]
        names = [n for n, _ in parsed]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"correction named twice: {sorted(dup)}")
        both = "hcn" in names and "linearize" in names  # one resampling does both
        stages = [
            (n, make_stage(n, config, p, scene, start_along_track_m, with_hcn=both))
            for n, p in sorted(parsed, key=lambda np_: ORDER.index(np_[0]))
            if not (both and n == "hcn")
        ]
        return cls(stages)

    def __bool__(self) -> bool:
        return bool(self.named)

    @property
    def names(self) -> list[str]:
        return [n for n, _ in self.named]

    @property
    def latency_pulses(self) -> int:
        return int(sum(getattr(s, "latency_pulses", 0) for _, s in self.named))

    def raw(self, samples: np.ndarray, aux: dict) -> np.ndarray:
        for stage in self.raw_stages:
            out = stage.process(samples, aux)
            if len(out) != len(samples):
                raise RuntimeError(f"{type(stage).__name__} changed the pulse count")
            samples = out
        return samples

    def lines(self, lines: np.ndarray, aux: dict) -> np.ndarray:
        """Range-compressed pulses through the line stages (a stage may hold some back)."""
        for stage in self.line_stages:
            lines = stage.process(lines, aux)
        return lines

    def flush(self, bins: int) -> np.ndarray:
        """The pulses the line stages still hold, through the stages after them."""
        carry = np.zeros((0, bins), np.complex64)
        for stage in self.line_stages:
            parts = [stage.process(carry, {})] if len(carry) else []
            if hasattr(stage, "flush"):
                parts.append(stage.flush())
            parts = [p for p in parts if len(p)]
            carry = np.concatenate(parts) if parts else np.zeros((0, bins), np.complex64)
        return carry

    def counters(self) -> dict:
        out = {}
        for n, s in self.named:
            out.update(_counters(n, s))
        return out
