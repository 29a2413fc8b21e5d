"""Phase-error and chirp corrections in the stream, chosen by name, in the order that works.

Crouch (2012, ch. 4-5) calls SAL images "worthless" before phase correction; the INO phase-error
patent advises the reference-region correction first and autofocus for the residual.  The stages:

======================  ======  ===========================================================
name                    where   what (module)
======================  ======  ===========================================================
``hcn``                 raw     start-frequency alignment on the HCN cell (focus.hcn_align)
``linearize``           raw     chirp linearization on the reference interferometer
                                (focus.linearize; with ``hcn`` both in one resampling: the
                                stage ``hcn+linearize``, its counters ``hcn_…`` the cell's)
``reference_region``    raw     α/β from the reference region (patent eqs. 5-11,
                                focus.reference_region)
``pra``                 lines   phase-to-retro (Crouch; focus.pra)
``pga``                 lines   phase gradient autofocus (Crouch eqs. 4.14-4.17; focus.pga)
======================  ======  ===========================================================

"raw" stages run on the shots between ingest and the AO lens and see the auxiliary channels;
"lines" stages run on range-compressed pulses between the lens and the shifting CCD.  All keep
pulse order; PGA holds a block of pulses (its latency, ``latency_pulses``) and gives them back at
``flush``.  Every stage implements rtsar.focus.stage.CorrectionStage; ``CorrectionChain.counters``
reports each stage's counters prefixed with its name, so they appear in the stats beside the
pipeline's.  What a stage needs to know of the scene comes in a :class:`CorrectionContext`.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, fields

import numpy as np

from ..params import Config
from .hcn_align import HCNAligner
from .linearize import ChirpLinearizer
from .pga import PGASettings, PGAStage
from .pra import PhaseToRetro
from .reference_region import ReferenceGeometry, ReferenceRegionCorrector
from .spec import ORDER, parse_spec
from .stage import DOMAINS, CorrectionStage


@dataclass(frozen=True)
class CorrectionContext:
    """What the corrections need beyond the configuration, from the scene or the instrument.

    ``start_along_track_m``: platform position of pulse 0; ``retro_m``: (along-track, slant
    range) of the retro-reflector, the default of ``pra``; ``ri_delay_s``: the reference
    interferometer's delay (``linearize``; default: the channel's quarter-rate beat);
    ``reference_geometry``: the INO patent's d, D and region (``reference_region`` needs it).
    rtsar.scene.correction_context derives one from a scene.
    """

    start_along_track_m: float = 0.0
    retro_m: tuple[float, float] | None = None
    ri_delay_s: float | None = None
    reference_geometry: ReferenceGeometry | None = None


# The class each correction (but pga: PGASettings) is made of, and its constructor's arguments
# that are not ``name:key=value`` keys.
_STAGE_CLASSES = {
    "hcn": (HCNAligner, {"config"}),
    "linearize": (ChirpLinearizer, {"config", "aligner"}),
    "reference_region": (ReferenceRegionCorrector, {"config", "geometry"}),
    "pra": (
        PhaseToRetro,
        {"config", "retro_along_track_m", "retro_range_m", "start_along_track_m", "range_m"},
    ),
}


def stage_keys(name: str) -> list[str]:
    """The ``name:key=value`` keys a correction takes (its constructor's or PGASettings')."""
    if name == "pga":
        return [f.name for f in fields(PGASettings)]
    target, skip = _STAGE_CLASSES[name]
    keys = [k for k in inspect.signature(target).parameters if k not in skip]
    return ["along_track_m", "range_m", *keys] if name == "pra" else keys


def _typed_keys(name: str) -> dict[str, str]:
    """Each key of correction ``name`` and its annotation, as text."""
    if name == "pga":
        return {f.name: str(f.type) for f in fields(PGASettings)}
    target, _ = _STAGE_CLASSES[name]
    return {k: str(p.annotation) for k, p in inspect.signature(target).parameters.items()}


def _numeric_keys(name: str) -> set[str]:
    """The keys of correction ``name`` whose values are numbers (by their annotations)."""
    typed = _typed_keys(name)
    numeric = {k for k, t in typed.items() if ("float" in t or "int" in t) and "str" not in t}
    return numeric | ({"along_track_m", "range_m"} if name == "pra" else set())


def _integer_keys(name: str) -> set[str]:
    """The keys of correction ``name`` that take whole numbers (``taps``, ``block_pulses``)."""
    return {k for k, t in _typed_keys(name).items() if "int" in t and "float" not in t}


def make_stage(
    name: str,
    config: Config,
    params: dict,
    context: CorrectionContext | None = None,
    hcn_params: dict | None = None,
) -> CorrectionStage:
    """One correction stage (see the table above); ``context`` supplies geometry where needed.
    ``hcn_params`` (linearize only): anchor the chirp on the HCN cell too, an HCNAligner with
    these ``hcn:`` keys, in the same resampling (the chain names that stage ``hcn+linearize``).

    A key the stage does not take, or a word where it takes a number, is a ValueError naming
    the key."""
    params = dict(params)
    unknown = sorted(set(params) - set(stage_keys(name)))
    if unknown:
        raise ValueError(
            f"correction {name}: unknown key(s) {', '.join(unknown)}; "
            f"it takes {', '.join(stage_keys(name))}"
        )
    numeric, integer = _numeric_keys(name), _integer_keys(name)
    for key, value in params.items():
        if key in numeric and isinstance(value, str):
            raise ValueError(f"correction {name}: {key} must be a number, got {value!r}")
        if key in integer and isinstance(value, float):  # the spec's numbers read as floats
            if not value.is_integer():
                raise ValueError(f"correction {name}: {key} must be a whole number, got {value:g}")
            params[key] = int(value)
    try:
        return _build(name, config, params, context or CorrectionContext(), hcn_params)
    except ValueError as exc:  # a stage's own check of a value: told as this --correct's
        text = str(exc)
        if text.startswith(("correction ", "the reference_region", "pra needs")):
            raise
        for cls in (PGASettings, *(c for c, _ in _STAGE_CLASSES.values())):
            text = text.replace(f"{cls.__name__}.", "")  # "PGASettings.follow_walk …"
        raise ValueError(f"correction {name}: {text}") from None


def _build(name, config, params, context, hcn_params) -> CorrectionStage:
    if name == "hcn":
        return HCNAligner(config, **params)
    if name == "linearize":
        if context.ri_delay_s is not None:
            params.setdefault("delay_s", context.ri_delay_s)
        aligner = None if hcn_params is None else make_stage("hcn", config, hcn_params)
        return ChirpLinearizer(config, aligner=aligner, **params)
    if name == "reference_region":
        if context.reference_geometry is None:
            raise ValueError(
                "the reference_region correction needs the patent geometry (d, D, the region): "
                "use a scene with the reference_region effect"
            )
        return ReferenceRegionCorrector(config, context.reference_geometry, **params)
    if name == "pra":
        if "along_track_m" not in params or "range_m" not in params:
            if context.retro_m is None:
                raise ValueError("pra needs the retro-reflector: pra:along_track_m=X,range_m=R")
            params.setdefault("along_track_m", context.retro_m[0])
            params.setdefault("range_m", context.retro_m[1])
        x, r = params.pop("along_track_m"), params.pop("range_m")
        return PhaseToRetro(config, x, r, context.start_along_track_m, **params)
    if name == "pga":
        return PGAStage(config, PGASettings(**params))
    raise ValueError(f"unknown correction {name!r}")  # pragma: no cover - parse_spec checks


def _spec_text(name: str, params: dict) -> str:
    """``name:key=value,…`` of a parsed spec (numbers to 12 significant digits)."""
    keys = ",".join(
        f"{k}={v:.12g}" if isinstance(v, float) else f"{k}={v}" for k, v in params.items()
    )
    return f"{name}:{keys}" if keys else name


class CorrectionChain:
    """The chosen stages in ORDER: ``raw`` before the lens, ``lines`` after it, ``flush`` at end."""

    def __init__(self, named_stages: list[tuple[str, CorrectionStage]]):
        """(name, stage) pairs, run in the given order (``from_specs`` sorts them by ORDER)."""
        self.named = list(named_stages)
        self.specs = [n for n, _ in self.named]  # what the user gave (from_specs: with keys)
        bad = [
            n
            for n, s in self.named
            if not isinstance(s, CorrectionStage) or getattr(type(s), "domain", None) not in DOMAINS
        ]
        if bad:
            raise ValueError(
                f"corrections {bad}: a stage is a CorrectionStage whose domain is 'raw' or 'lines'"
            )
        self.raw_stages = [s for _, s in self.named if s.domain == "raw"]
        self.line_stages = [s for _, s in self.named if s.domain == "lines"]

    @classmethod
    def from_specs(cls, specs, config: Config, context: CorrectionContext | None = None):
        """Build from ``["pga", "pra:along_track_m=0,range_m=1.5", ...]``."""
        parsed = [parse_spec(s) if isinstance(s, str) else s for s in specs]
        names = [n for n, _ in parsed]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"correction named twice: {sorted(dup)}")
        both = "hcn" in names and "linearize" in names  # one resampling does both
        hcn_params = dict(parsed)["hcn"] if both else None
        resampler = sorted({"taps", "kaiser_beta"} & set(hcn_params or {}))
        if resampler:
            raise ValueError(
                f"hcn with linearize is one resampling, linearize's: give {', '.join(resampler)} "
                "as linearize:KEY=VALUE (hcn's would be ignored)"
            )
        stages = [
            (
                "hcn+linearize" if both and n == "linearize" else n,
                make_stage(n, config, p, context, hcn_params=hcn_params),
            )
            for n, p in sorted(parsed, key=lambda np_: ORDER.index(np_[0]))
            if not (both and n == "hcn")
        ]
        chain = cls(stages)
        given = [s.strip() if isinstance(s, str) else _spec_text(*s) for s in specs]
        retro = (context or CorrectionContext()).retro_m
        for i, (name, params) in enumerate(parsed):  # pra's retro as it ran, from the context
            if name == "pra" and retro is not None:
                where = {"along_track_m": retro[0], "range_m": retro[1]}
                given[i] = _spec_text("pra", {**where, **params})
        pairs = sorted(zip(names, given, strict=True), key=lambda p: ORDER.index(p[0]))
        chain.specs = [g for _, g in pairs]
        return chain

    def __bool__(self) -> bool:
        return bool(self.named)

    @property
    def names(self) -> list[str]:
        return [n for n, _ in self.named]

    @property
    def latency_pulses(self) -> int:
        return int(sum(s.latency_pulses for _, s in self.named))

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
            parts.append(stage.flush())
            parts = [p for p in parts if p is not None and len(p)]
            carry = np.concatenate(parts) if parts else np.zeros((0, bins), np.complex64)
        return carry

    def move_start(self, shift_m: float) -> None:
        """Pulse 0 lies ``shift_m`` further along track than the chain was told (a live stream
        anchored by its first shot, rtsar.stream.pipeline): stages that place pulses (pra)
        follow."""
        for _, stage in self.named:
            if hasattr(stage, "start_along_track_m"):
                stage.start_along_track_m += shift_m

    def counters(self) -> dict:
        """Every stage's counters, prefixed with its name (``pga.pulses_in``, …)."""
        return {f"{n}.{k}": int(v) for n, s in self.named for k, v in s.counter_values().items()}
