"""The tradeoff's scenes and the knob variants measured on each (see rtsar.app.tradeoff)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...analysis import theoretical_irw_factor
from ...analysis.acceptance import SINC_IRW, acceptance_targets, azimuth_weights
from ...lens.plan import range_axis_m
from ...params import Config, Processor
from ...presets import preset
from ...scene import Simulator, point_scene


# ---- variants ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Variant:
    """One setting of one knob; every other setting is the preset's default."""

    knob: str
    value: str
    processor: dict = field(default_factory=dict)  # Processor field changes
    lens_backend: str = "auto"
    default: bool = False
    corrections: tuple = ()  # rtsar.corrections specs, e.g. ("pga",)
    physical: str | None = None  # physical mode with the paper's CCD: carrier "range"/"azimuth"


def instrument_variants(cfg: Config, quick: bool = False) -> list[Variant]:
    """The knobs swept on the instrument scene (defaults first in each group)."""
    p = cfg.processor
    n = p.aperture_pulses
    m = p.fft_length or 2 * n
    v = [Variant("defaults", "preset", default=True)]
    v += [Variant("precision", "complex128", {"precision": "complex128"})]
    v += [
        Variant("correlator", c, {"correlator": c})
        for c in Processor.CORRELATORS
        if c != p.correlator
    ]
    v += [Variant("fft length M", str(k * m), {"fft_length": k * m}) for k in (2, 4)]
    v += [
        Variant("partition L", str(L), {"correlator": "partitioned", "partition_lines": L})
        for L in ((8, 32) if not quick else (8,))
        if L <= n
    ]
    v += [
        Variant("micro-batch", str(b), {"micro_batch": b}) for b in (16, 256) if b != p.micro_batch
    ]
    v += [Variant("aperture N", str(k), {"aperture_pulses": k}) for k in (n // 2, 2 * n)]
    v += [
        Variant("windows", w, {"range_window": w, "azimuth_window": w}) for w in ("hann", "taylor")
    ]
    v += [Variant("physical CCD", f"carrier in {c}", physical=c) for c in ("range",)]
    return v + lens_variants(cfg)


def lens_variants(cfg: Config) -> list[Variant]:
    """The AO lens on NumPy instead of OpenCL; for FMCW, the range FFT zero-padded ×2 (a pulsed
    lens is already oversampled by its sample rate, so that knob does not exist there)."""
    v = [Variant("lens", "numpy", lens_backend="numpy")]
    if cfg.waveform.kind == "fmcw":
        bins = 2 * cfg.processor.range_bins
        v.append(Variant("lens", "oversampling 2", {"range_oversampling": 2, "range_bins": bins}))
    return v


def curvature_variants(cfg: Config, quick: bool = False) -> list[Variant]:
    """The knobs that only matter where the azimuth chirp changes across the swath."""
    v = [Variant("defaults", "preset", default=True)]
    v += [Variant("mask", "one for the swath", {"per_bin_mask": False})]
    bins = 2 * cfg.processor.range_bins  # the same swath, sampled twice as finely
    v += [
        Variant(
            "range migration",
            f"{t} taps, oversampling 2",
            {"range_migration_taps": t, "range_oversampling": 2, "range_bins": bins},
        )
        for t in ((4, 8) if not quick else (4,))
    ]
    v += [Variant("precision", "complex128", {"precision": "complex128"})]
    return v + lens_variants(cfg)


# ---- scenes ------------------------------------------------------------------------------------
@dataclass
class TradeoffScene:
    key: str
    description: str
    config: Config  # the defaults
    variants: list[Variant]
    targets: list[tuple[str, float, float]]  # (label, along_track_m, slant_range_m)
    start_along_track_m: float = 0.0
    shots: np.ndarray | None = None
    aux: dict = field(default_factory=dict)
    effects: tuple = ()  # errors injected into the shots (the reference is simulated without)
    extra_targets: tuple = ()  # (along_track_m, slant_range_m, amplitude): e.g. a retro
    reference_shots: np.ndarray | None = None
    reference_migration_taps: int = 0  # the float64 reference handles migration with this
    min_pulses: int = 0  # at least this many shots (block stages such as PGA need room)
    scene: object = None  # the rtsar Scene simulated (geometry for the corrections)
    image_peak: float = 1.0  # largest |pixel| of the float64 image (physical mode's full scale)

    def config_of(self, v: Variant) -> Config:
        return self.config.with_processor(**v.processor)


def az_irw_m(cfg: Config, r: float) -> float:
    w = azimuth_weights(cfg)  # no antenna pattern here: the window is the taper
    return SINC_IRW * cfg.azimuth_resolution_m(r) * theoretical_irw_factor(w)


def chip_lines(cfg: Config, r: float) -> int:
    """Azimuth half-chip in lines: ±12 IRW of sidelobes (the ISLR extent is ±10 IRW)."""
    return max(64, int(math.ceil(12 * az_irw_m(cfg, r) / cfg.geometry.along_track_step_m)))


def make_scene(key: str, cfg: Config, variants: list[Variant], description: str) -> TradeoffScene:
    """Point targets of the acceptance set, simulated once for every variant of the scene."""
    targets = acceptance_targets(cfg)
    scene = TradeoffScene(key, description, cfg, variants, targets)
    step = cfg.geometry.along_track_step_m
    n_max, margin = _extent(scene)
    scene.start_along_track_m = min(x for _, x, _ in targets) - (0.5 * (n_max - 1) + margin) * step
    return scene


def _extent(scene: TradeoffScene) -> tuple[int, int]:
    """(largest N, azimuth margin in lines) over the scene's variants."""
    cfgs = [scene.config_of(v) for v in scene.variants]
    margin = max(chip_lines(c, r) for c in cfgs for _, _, r in scene.targets) + 8
    return max(c.processor.aperture_pulses for c in cfgs), margin


def simulate(scene: TradeoffScene) -> None:
    """The scene's shots (with its effects) and, when it has effects, the error-free shots."""
    xs = [x for _, x, _ in scene.targets] + [t[0] for t in scene.extra_targets]
    rs = [r for _, _, r in scene.targets] + [t[1] for t in scene.extra_targets]
    amps = [1.0] * len(scene.targets) + [t[2] for t in scene.extra_targets]

    def run(effects):
        s = point_scene(
            scene.config,
            xs,
            rs,
            amps,
            effects=effects,
            seed=5,
            start_along_track_m=scene.start_along_track_m,
            pulses=_pulses(scene),
        )
        return Simulator(s).block_with_aux(s.pulses), s

    (scene.shots, scene.aux), scene.scene = run(list(scene.effects))
    scene.reference_shots = run([])[0][0] if scene.effects else scene.shots


def _pulses(scene: TradeoffScene) -> int:
    n_max, margin = _extent(scene)
    step = scene.config.geometry.along_track_step_m
    far = max(x for _, x, _ in scene.targets) - scene.start_along_track_m
    return max(scene.min_pulses, int(math.ceil(far / step + 0.5 * n_max + margin)) + 1)


def correction_scenes(quick: bool = False) -> list[TradeoffScene]:
    """Crouch-size errors injected, each correction's cost and how much focus it gives back.

    ``phase errors``: crouch-sal with a 512-pulse aperture, a piston error (random walk and
    vibration, hundreds of radians over the record) and a retro-reflector 10× brighter than the
    targets; phase-to-retro and PGA against no correction.  ``chirp``: the same geometry with a
    1 % non-linear chirp and 10 GHz start-frequency jitter, the reference-interferometer and HCN
    channels; linearization (and with HCN alignment) against none.  Quality is measured against
    the float64 image of the error-free shots.
    """
    n = 256 if quick else 512
    cfg = preset("crouch-sal").with_processor(aperture_pulses=n, range_bins=256, micro_batch=64)
    rm = range_axis_m(cfg)
    retro = (3 * cfg.geometry.along_track_step_m, float(rm[len(rm) // 2 + 40]), 10.0)
    phase = make_scene(
        "phase errors",
        cfg,
        [
            Variant("corrections", "none", default=True),
            Variant("corrections", "pra", corrections=("pra",)),
            Variant("corrections", "pga", corrections=("pga",)),
        ],
        f"crouch-sal, N = {n}: piston error (random walk + vibration) and a retro-reflector",
    )
    phase.effects = (("piston", {"random_walk_rad": 4.0, "vibration_rad": 3.0, "seed": 3}),)
    phase.extra_targets = (retro,)
    phase.min_pulses = 4 * n
    chirp = make_scene(
        "chirp",
        cfg,
        [
            Variant("corrections", "none", default=True),
            Variant("corrections", "linearize", corrections=("linearize",)),
            Variant("corrections", "linearize + hcn", corrections=("linearize", "hcn")),
        ],
        f"crouch-sal, N = {n}: 1 % chirp non-linearity, 10 GHz start-frequency jitter",
    )
    chirp.effects = (
        ("chirp_nonlinearity", {"poly_fraction": [0.0, 0.0, 0.015]}),
        ("start_frequency_jitter", {"std_hz": 10e9, "seed": 4}),
        ("reference_interferometer", {}),
        ("hcn_cell", {}),
    )
    return [phase, chirp] + pga_scenes(quick)


#: The piston error of the PGA scenes (Crouch size: a few hundred radians over the record).
PGA_PISTON = {"random_walk_rad": 0.3, "drift_rad": 1e-3, "vibration_rad": 3.0,
              "vibration_hz": 0.13, "white_rad": 0.1, "seed": 12}  # fmt: skip


def pga_scenes(quick: bool = False) -> list[TradeoffScene]:
    """PGA on the papers' presets (issue 14): no correction against ``pga``, the acceptance
    targets (PGA needs no retro-reflector), Crouch's piston error; ≥ 3N shots so the stream has
    whole blocks.

    ``pga crouch-sal``: N = 2048 (quick 128), 512 bins (quick 64): points walk ~3 range cells
    inside a 2N block.  ``pga zhao-insal``: N = 160, 64 bins.  ``pga psaltis-jpl``: N = 512,
    320 bins (quick 64).  None of these point scenes has clutter, so the Doppler
    anchor has nothing to measure and the error's own slope stays: the position error column.
    crouch-sal also has ``pga:follow_walk=0`` (PGA without its walk-following second pass).
    """
    specs = [
        ("crouch-sal", 128 if quick else 2048, 64 if quick else 512),
        ("zhao-insal", 160, 64),
        ("psaltis-jpl", 512, 64 if quick else 320),
    ]
    out = []
    for name, n, bins in specs:
        cfg = preset(name).with_processor(aperture_pulses=n, range_bins=bins, micro_batch=64)
        # What PGA's walk-following second pass costs where points migrate (crouch-sal).
        walk = ("pga:follow_walk=0",) if name == "crouch-sal" else ()
        walk_variant = [Variant("corrections", w, corrections=(w,)) for w in walk]
        scene = make_scene(
            f"pga {name}",
            cfg,
            [
                Variant("corrections", "none", default=True),
                Variant("corrections", "pga", corrections=("pga",)),
                *walk_variant,
            ],
            f"{name}, N = {n}, {bins} bins: piston error (Crouch size), no retro-reflector; PGA",
        )
        scene.effects = (("piston", PGA_PISTON),)
        scene.min_pulses = 3 * n
        out.append(scene)
    return out


def default_scenes(quick: bool = False, corrections: bool = True) -> list[TradeoffScene]:
    if quick:  # small and fast: for tests and a first look
        tiny = preset("tiny")
        return [
            make_scene(
                "instrument",
                tiny,
                instrument_variants(tiny, quick=True),
                "tiny preset (a reduced psaltis-jpl): centre and swath-edge targets",
            )
        ]
    jpl, crouch = preset("psaltis-jpl"), preset("crouch-sal")
    curvature = make_scene(
        "curvature",
        crouch,
        curvature_variants(crouch),
        "crouch-sal (2048 × 512, 0.7-cell range curvature, ±0.9 % chirp-rate change across the "
        "swath): centre and swath-edge targets; reference with range migration (16 taps)",
    )
    curvature.reference_migration_taps = 16
    scenes = [
        make_scene(
            "instrument",
            jpl,
            instrument_variants(jpl),
            "psaltis-jpl (512 × 320 CCD, 1600 Hz): centre and swath-edge targets",
        ),
        curvature,
    ]
    return scenes + (correction_scenes() if corrections else [])
