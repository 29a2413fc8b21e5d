"""``rtsar tradeoff``: what accuracy costs in time, every processor knob measured in one run.

Each knob is varied alone from the preset's defaults, on a scene whose targets stress it:

* ``instrument`` (psaltis-jpl, the experimental processor of Psaltis & Wagner's Table 1): targets
  at the swath centre and near both range edges.  Knobs: precision, correlator mode, its block
  (FFT length M, partition L), micro-batch, aperture N, windows, lens variants (OpenCL / NumPy,
  range oversampling), physical vs ideal CCD.
* ``curvature`` (crouch-sal): the same three targets where range curvature is 0.7 range cell
  across the aperture and the azimuth chirp rate changes by ±0.9 % across the swath (283 rad of
  phase at the aperture edge), so the per-range-bin mask and range-migration handling matter.

Scenes with injected errors (``phase errors``, ``chirp``: each correction's cost and what it
gives back) are measured against the float64 image of the same scene simulated without the
errors, after the best complex gain (a constant phase is not observable).

Quality, per variant, against a float64 reference of the same geometry (the AO lens in
complex128, ``compress_reference``; the azimuth correlation by complex128 FFT convolution with
the ideal mask — per range bin, migration handled when the processor has that knob): relative RMS
image error, largest peak-phase error, and the point-target figures of every target (worst case
reported): IRW against theory (ρR = c/2B, ρA = λR/2L broadened by the window), PSLR, ISLR and
position error in resolution cells.

Cost: pulses/s of the engine (lens + correlator, best of two runs after a warm-up), and the
latency of every image line in a trace-driven replay at the preset's PRF: pulse p arrives at p/PRF,
a micro-batch starts when its last pulse has arrived and the previous batch has finished, and takes
the service time measured for it; a line's latency is the end of the batch that emitted it minus
the arrival of its last pulse.  This is the latency the same computation would have live, without
waiting for the stream in real time.

A variant is on the Pareto front when no other variant of its scene is at least as good on every
one of µs per pulse, median latency, image error, azimuth IRW and azimuth PSLR, and better on one
(resolution and sidelobes are what the aperture and the windows buy).
"""

from __future__ import annotations

import json
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy import signal

from .acceptance import SINC_IRW, acceptance_targets, azimuth_weights
from .ccd import design_mask
from .engine import StreamProcessor
from .lens_plan import compress_reference, make_plan
from .metrics import analyse_point_target, relative_rms, theoretical_irw_factor
from .params import Config, Processor, preset
from .scene import Simulator, point_scene
from .windows import window


# ---- variants ----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Variant:
    """One setting of one knob; every other setting is the preset's default."""

    knob: str
    value: str
    processor: dict = field(default_factory=dict)  # Processor field changes
    lens_backend: str = "opencl"
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


def _az_irw_m(cfg: Config, r: float) -> float:
    w = azimuth_weights(cfg, r, antenna=False)
    return SINC_IRW * cfg.azimuth_resolution_m(r) * theoretical_irw_factor(w)


def _chip_lines(cfg: Config, r: float) -> int:
    """Azimuth half-chip in lines: ±12 IRW of sidelobes (the ISLR extent is ±10 IRW)."""
    return max(64, int(math.ceil(12 * _az_irw_m(cfg, r) / cfg.geometry.along_track_step_m)))


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
    margin = max(_chip_lines(c, r) for c in cfgs for _, _, r in scene.targets) + 8
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


# ---- reference and measurement -----------------------------------------------------------------
def reference_image(cfg: Config, shots: np.ndarray, migration_taps: int = 0) -> np.ndarray:
    """Float64 image of the same geometry: compress_reference, then exact FFT correlation.

    g[j, r] = Σ_k line[j + k, r] · mask[k, r] (ccd.py eq. 1) is the convolution of the lines with
    the reversed mask, evaluated with complex128 FFTs (error ~1e-15 of the peak); always the
    per-range-bin mask.  ``migration_taps`` > 0: range migration handled by that many taps
    (rtsar.migration's float64 reference), for scenes where curvature matters.
    """
    ideal = cfg.with_processor(
        per_bin_mask=True, precision="complex128", range_migration_taps=migration_taps
    )
    plan = make_plan(ideal)
    lines = compress_reference(plan, shots)
    if migration_taps:
        from .migration import correlate_migration_reference, design_migration_mask

        return correlate_migration_reference(lines, design_migration_mask(ideal, plan.range_m))
    mask = design_mask(ideal, plan.range_m)
    n = mask.shape[0]
    full = signal.fftconvolve(lines, mask[::-1], axes=0)
    return full[n - 1 : lines.shape[0]]


@dataclass
class Timing:
    pulses_per_s: float
    realtime_factor: float  # PRF-paced time of the shots / processing time
    latency_p50_ms: float
    latency_p99_ms: float
    keeps_up: bool


def trace_latency_s(service_s, lines_per_batch, batch: int, pulses: int, n: int, prf_hz: float):
    """Latency of every line in a replay at the PRF with the measured service times (see top)."""
    arrival = np.arange(pulses) / prf_hz
    finish, lat, line = 0.0, [], 0
    for b, (s, count) in enumerate(zip(service_s, lines_per_batch, strict=True)):
        last = min((b + 1) * batch, pulses) - 1
        finish = max(arrival[last], finish) + s
        if count:
            j = line + np.arange(count)
            lat.append(finish - arrival[j + n - 1])
            line += count
    return np.concatenate(lat) if lat else np.zeros(0)


def run_engine(
    cfg: Config,
    shots: np.ndarray,
    lens_backend: str,
    device=None,
    start_m=0.0,
    variant=None,
    scene=None,
):
    """One timed pass of the engine → (image, azimuth_m, range_m, service_s, lines per batch)."""
    corrections = physical = None
    aux = scene.aux if scene is not None else {}
    if variant is not None and variant.corrections:
        from .corrections import CorrectionChain

        corrections = CorrectionChain.from_specs(
            list(variant.corrections), cfg, scene.scene, start_m
        )
    if variant is not None and variant.physical:
        from .physical import paper_ccd

        # The brightest target at half of full scale, below the largest undistorted signal of
        # the emulated CCD (0.705, rtsar table1): no well overflows with three targets.
        peak = scene.image_peak if scene is not None else 1.0
        physical = replace(paper_ccd(variant.physical), full_scale_amplitude=peak / 0.5)
    eng = StreamProcessor(cfg, lens_backend, device, start_m, corrections, physical)
    b = cfg.processor.micro_batch
    service, counts, parts = [], [], []
    for i in range(0, len(shots), b):
        batch_aux = {k: v[i : i + b] for k, v in aux.items()}
        t0 = time.perf_counter()
        out = eng.push(shots[i : i + b], batch_aux)
        service.append(time.perf_counter() - t0)
        counts.append(len(out.lines))
        parts.append(out.lines)
    parts.append(eng.flush().lines)
    image = np.concatenate(parts)
    return image, eng.azimuth_m(0, len(image)), eng.range_m, service, counts


def measure_cost(
    cfg: Config,
    shots: np.ndarray,
    lens_backend: str,
    repeats: int = 2,
    device=None,
    start_m=0.0,
    variant=None,
    scene=None,
):
    """Warm-up, then the best of ``repeats`` timed passes → (image, az, rg, Timing)."""
    warm = min(len(shots), 2 * cfg.processor.aperture_pulses + 2 * cfg.processor.micro_batch)
    run_engine(cfg, shots[:warm], lens_backend, device, start_m, variant, scene)  # JIT, builds
    best = None
    for _ in range(repeats):
        result = run_engine(cfg, shots, lens_backend, device, start_m, variant, scene)
        if best is None or sum(result[3]) < sum(best[3]):
            best = result
    image, az, rg, service, counts = best
    p = cfg.processor
    prf = cfg.geometry.prf_hz
    total = sum(service)
    lat = trace_latency_s(service, counts, p.micro_batch, len(shots), p.aperture_pulses, prf)
    timing = Timing(
        len(shots) / total,
        len(shots) / prf / total,
        1e3 * float(np.median(lat)),
        1e3 * float(np.percentile(lat, 99)),
        total < len(shots) / prf,
    )
    return image, az, rg, timing


@dataclass
class Quality:
    image_error: float  # relative RMS against the float64 reference
    peak_phase_error_rad: float  # largest |arg(peak / reference peak)| over the targets
    az_irw_m: float  # centre target
    az_irw_ratio: float  # worst (largest) over the targets, measured / theory
    rg_irw_ratio: float
    az_pslr_db: float  # worst (highest)
    rg_pslr_db: float
    az_islr_db: float
    rg_islr_db: float
    position_error_cells: float  # worst, in resolution cells (either axis)


def _reports(cfg: Config, image, az, rg, targets):
    """Point-target analysis of each target on a range crop that excludes the other targets (they
    share the azimuth position, so a full-width range cut would count them as sidelobes)."""
    rho_r = cfg.waveform.range_resolution_m
    spacing = abs(rg[1] - rg[0])
    ranges = np.array([r for _, _, r in targets])
    out = []
    for _, x, r in targets:
        others = np.abs(np.delete(ranges, np.flatnonzero(ranges == r)[0]) - r)
        half = int(min(64, 0.5 * others.min() / spacing)) if len(others) else 64
        centre = int(np.argmin(np.abs(rg - r)))
        crop = slice(max(0, centre - half), min(len(rg), centre + half + 1))
        out.append(
            analyse_point_target(
                image[:, crop],
                az,
                rg[crop],
                near_azimuth_m=x,
                near_range_m=r,
                search_radius_m=(3 * cfg.azimuth_resolution_m(r), 3 * rho_r),
                chip=_chip_lines(cfg, r),
            )
        )
    return out


def gain_fitted_error(image: np.ndarray, reference: np.ndarray) -> float:
    """‖c·image − reference‖ / ‖reference‖ with the best complex gain c: the error that remains
    once an unobservable constant phase (and scale) is allowed — what a phase correction can
    restore, measured against the error-free image."""
    a = np.asarray(image, np.complex128).ravel()
    b = np.asarray(reference, np.complex128).ravel()
    aa = np.vdot(a, a).real
    c = np.vdot(a, b) / aa if aa > 0 else 0.0
    return float(np.linalg.norm(c * a - b) / np.linalg.norm(b))


def measure_quality(cfg: Config, image, az, rg, reference, targets, gain_fit=False) -> Quality:
    reps = _reports(cfg, image, az, rg, targets)
    refs = _reports(cfg, reference, az, rg, targets)
    rho_r = cfg.waveform.range_resolution_m
    rw = window(
        cfg.processor.range_window,
        cfg.waveform.pulse_samples
        if cfg.waveform.kind == "pulsed"
        else cfg.waveform.samples_per_shot,
    )
    rg_theory = SINC_IRW * rho_r * theoretical_irw_factor(rw)
    az_ratio, pos, phase = [], [], []
    for (_, x, r), rep, ref in zip(targets, reps, refs, strict=True):
        az_ratio.append(rep.azimuth.irw_m / _az_irw_m(cfg, r))
        pos.append(
            max(abs(rep.azimuth_m - x) / cfg.azimuth_resolution_m(r), abs(rep.range_m - r) / rho_r)
        )
        phase.append(abs(np.angle(rep.peak_value / ref.peak_value)))
    centre = len(targets) // 2
    return Quality(
        gain_fitted_error(image, reference) if gain_fit else relative_rms(image, reference),
        float(max(phase)),
        reps[centre].azimuth.irw_m,
        float(max(az_ratio)),
        float(max(rep.range.irw_m for rep in reps) / rg_theory),
        float(max(rep.azimuth.pslr_db for rep in reps)),
        float(max(rep.range.pslr_db for rep in reps)),
        float(max(rep.azimuth.islr_db for rep in reps)),
        float(max(rep.range.islr_db for rep in reps)),
        float(max(pos)),
    )


# ---- the sweep ---------------------------------------------------------------------------------
FRONT_KEYS = ("us_per_pulse", "latency_p50_ms", "image_error", "az_irw_m", "az_pslr_db")


def pareto_front(rows: list[dict], keys=FRONT_KEYS):
    """Marks rows[i]["front"]: no other row of its scene is ≤ on every key and < on one."""
    for a in rows:
        a["front"] = not any(
            b is not a
            and b["scene"] == a["scene"]
            and all(b[k] <= a[k] for k in keys)
            and any(b[k] < a[k] for k in keys)
            for b in rows
        )
    return rows


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
    rm = make_plan(cfg).range_m
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
    return [phase, chirp]


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


def run_tradeoff(
    scenes: list[TradeoffScene], log=None, device=None, repeats: int = 2
) -> list[dict]:
    """Measure every variant of every scene → rows (dicts) with quality, cost and the front."""
    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    rows = []
    total = sum(len(s.variants) for s in scenes)
    done = 0
    for scene in scenes:
        t0 = time.perf_counter()
        simulate(scene)
        log(f"[{scene.key}] simulated {len(scene.shots)} shots in {time.perf_counter() - t0:.1f} s")
        refs: dict = {}
        for v in scene.variants:
            done += 1
            cfg = scene.config_of(v)
            key = (
                scene.reference_migration_taps,
                cfg.processor.aperture_pulses,
                cfg.processor.range_window,
                cfg.processor.azimuth_window,
                cfg.processor.range_oversampling,
                cfg.processor.range_bins,
            )
            if key not in refs:
                refs[key] = reference_image(
                    cfg, scene.reference_shots, scene.reference_migration_taps
                )
                if v.default:
                    scene.image_peak = float(np.abs(refs[key]).max())
            t0 = time.perf_counter()
            image, az, rg, timing = measure_cost(
                cfg,
                scene.shots,
                v.lens_backend,
                repeats,
                device,
                scene.start_along_track_m,
                v,
                scene,
            )
            quality = measure_quality(
                cfg, image, az, rg, refs[key], scene.targets, gain_fit=bool(scene.effects)
            )
            rows.append(
                {
                    "scene": scene.key,
                    "knob": v.knob,
                    "value": v.value,
                    "default": v.default,
                    "lens": v.lens_backend,
                    "processor": v.processor,
                    "us_per_pulse": 1e6 / timing.pulses_per_s,
                    **asdict(timing),
                    **asdict(quality),
                }
            )
            log(
                f"[{done}/{total}] {scene.key}: {v.knob} = {v.value}: "
                f"{timing.pulses_per_s:,.0f} pulses/s, latency {timing.latency_p50_ms:.1f} ms, "
                f"error {quality.image_error:.2e} ({time.perf_counter() - t0:.1f} s)"
            )
    return pareto_front(rows)


def markdown(rows: list[dict], scenes: list[TradeoffScene]) -> str:
    out = []
    for scene in scenes:
        out.append(f"**{scene.key}**: {scene.description}\n")
        out.append(
            "| knob | value | pulses/s | × RT | latency p50 / p99 [ms] | image error | "
            "peak phase [mrad] | az. IRW [m] | az. / rg. IRW ratio | az. / rg. PSLR [dB] | "
            "az. / rg. ISLR [dB] | pos. error [cells] | front |"
        )
        out.append("|" + "---|" * 13)
        for r in (r for r in rows if r["scene"] == scene.key):
            name = f"**{r['value']}**" if r["default"] else r["value"]
            out.append(
                f"| {r['knob']} | {name} | {r['pulses_per_s']:,.0f} | "
                f"{r['realtime_factor']:.1f} | {r['latency_p50_ms']:.1f} / "
                f"{r['latency_p99_ms']:.1f}{'' if r['keeps_up'] else ' (falls behind)'} | "
                f"{r['image_error']:.1e} | {1e3 * r['peak_phase_error_rad']:.2f} | "
                f"{r['az_irw_m']:.4g} | {r['az_irw_ratio']:.3f} / {r['rg_irw_ratio']:.3f} | "
                f"{r['az_pslr_db']:.1f} / {r['rg_pslr_db']:.1f} | "
                f"{r['az_islr_db']:.1f} / {r['rg_islr_db']:.1f} | "
                f"{r['position_error_cells']:.3f} | {'●' if r['front'] else ''} |"
            )
        out.append("")
    return "\n".join(out)


def plot(rows: list[dict], scenes: list[TradeoffScene], path: Path) -> None:
    """Pareto plot: image error against µs per pulse and against median latency, per scene."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(scenes), 2, figsize=(12, 4.8 * len(scenes)), squeeze=False)
    knobs = sorted({r["knob"] for r in rows})
    colours = {k: plt.cm.tab10(i % 10) for i, k in enumerate(knobs)}
    for row_axes, scene in zip(axes, scenes, strict=True):
        sel = [r for r in rows if r["scene"] == scene.key]
        for ax, xkey, xlabel in zip(
            row_axes,
            ("us_per_pulse", "latency_p50_ms"),
            ("cost [µs per pulse]", "median line latency at the PRF [ms]"),
            strict=True,
        ):
            for r in sel:
                ax.scatter(
                    r[xkey],
                    r["image_error"],
                    s=140 if r["default"] else 50,
                    marker="*" if r["default"] else "o",
                    color=colours[r["knob"]],
                    edgecolors="black" if r["front"] else "none",
                    linewidths=1.2,
                    zorder=3,
                )
                ax.annotate(
                    f"{r['value']}",
                    (r[xkey], r["image_error"]),
                    fontsize=7,
                    xytext=(4, 3),
                    textcoords="offset points",
                )
            xs = [r[xkey] for r in sel]
            if max(xs) > 3 * min(xs):  # a log axis only where the values span a range
                ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(xlabel)
            ax.set_ylabel("image error vs float64 reference (relative RMS)")
            ax.set_title(f"{scene.key}: black outline = Pareto front, ★ = defaults", fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
        handles = [
            plt.Line2D([], [], marker="o", ls="", color=colours[k], label=k)
            for k in knobs
            if any(r["knob"] == k for r in sel)
        ]
        row_axes[1].legend(handles=handles, fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- command -----------------------------------------------------------------------------------
def add_arguments(parser) -> None:
    parser.add_argument(
        "--out-dir",
        default="tradeoff",
        metavar="DIR",
        help="folder for tradeoff.json, tradeoff.md and tradeoff.png (default ./tradeoff)",
    )
    parser.add_argument(
        "--quick",
        action="store_true",
        help="a small scene (tiny preset) and fewer variants: a first look in "
        "seconds, not the figures to quote",
    )
    parser.add_argument(
        "--repeats", type=int, default=2, help="timed passes per variant, best kept (default 2)"
    )
    parser.add_argument(
        "--lens-numpy",
        action="store_true",
        help="use the NumPy lens for every variant (no OpenCL device needed)",
    )
    parser.add_argument("--device", help="OpenCL platform/device name substring")
    parser.add_argument(
        "--no-corrections",
        action="store_true",
        help="leave out the phase-error and chirp-correction scenes",
    )


def run(args) -> int:
    if args.repeats < 1:
        raise ValueError("--repeats must be >= 1")
    scenes = default_scenes(args.quick, not getattr(args, "no_corrections", False))
    if args.lens_numpy:
        for s in scenes:
            s.variants = [v for v in s.variants if v.knob != "lens"]
            s.variants = [replace(v, lens_backend="numpy") for v in s.variants]
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = run_tradeoff(scenes, device=args.device, repeats=args.repeats)
    doc = {
        "generated_by": "rtsar tradeoff" + (" --quick" if args.quick else ""),
        "seconds": time.perf_counter() - t0,
        "scenes": {
            s.key: {
                "description": s.description,
                "defaults": s.config.to_dict(),
                "targets": s.targets,
            }
            for s in scenes
        },
        "rows": rows,
    }
    (out / "tradeoff.json").write_text(json.dumps(doc, indent=1, default=float))
    (out / "tradeoff.md").write_text(markdown(rows, scenes))
    plot(rows, scenes, out / "tradeoff.png")
    print(markdown(rows, scenes))
    off = [f"{r['scene']}" for r in rows if r["default"] and not r["front"]]
    print(f"defaults on the Pareto front: {'yes' if not off else 'NO (' + ', '.join(off) + ')'}")
    print(
        f"wrote {out / 'tradeoff.json'}, {out / 'tradeoff.md'}, {out / 'tradeoff.png'} "
        f"in {time.perf_counter() - t0:.0f} s"
    )
    return 0
