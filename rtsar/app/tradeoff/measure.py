"""Quality against the float64 reference and cost (pulses/s, trace-driven latency) of one
variant (see rtsar.app.tradeoff)."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from ...analysis import analyse_point_target, relative_rms, theoretical_irw_factor
from ...analysis.acceptance import SINC_IRW
from ...analysis.image_error import gain_fitted_error
from ...ccd.base import design_mask
from ...ccd.migration import correlate_migration_reference, design_migration_mask
from ...focus.chain import CorrectionChain
from ...lens.base import compress_reference
from ...lens.plan import make_plan
from ...params import Config
from ...physical import paper_ccd
from ...scene.correction_context import correction_context
from ...stream.engine import StreamProcessor
from ...windows import window
from .scenes import az_irw_m, chip_lines


# ---- reference and measurement -----------------------------------------------------------------
def reference_image(cfg: Config, shots: np.ndarray, migration_taps: int = 0) -> np.ndarray:
    """Float64 image of the same geometry: compress_reference, then exact FFT correlation.

    g[j, r] = Σ_k line[j + k, r] · mask[k, r] (ccd.py eq. 1) is the convolution of the lines with
    the reversed mask, evaluated with complex128 FFTs (error ~1e-15 of the peak); always the
    per-range-bin mask.  ``migration_taps`` > 0: range migration handled by that many taps
    (rtsar.ccd.migration's float64 reference), for scenes where curvature matters.
    """
    ideal = cfg.with_processor(
        per_bin_mask=True, precision="complex128", range_migration_taps=migration_taps
    )
    plan = make_plan(ideal)
    lines = compress_reference(plan, shots)
    if migration_taps:
        return correlate_migration_reference(lines, design_migration_mask(ideal, plan.range_m))
    from scipy.signal import fftconvolve  # here: scipy.signal costs ~1 s at every CLI start

    mask = design_mask(ideal, plan.range_m)
    n = mask.shape[0]
    full = fftconvolve(lines, mask[::-1], axes=0)
    return full[n - 1 : lines.shape[0]]


@dataclass
class Timing:
    pulses_per_s: float  # the best of the timed passes
    realtime_factor: float  # PRF-paced time of the shots / processing time
    latency_p50_ms: float
    latency_p99_ms: float
    keeps_up: bool
    passes: int = 1  # timed passes, interleaved with the scene's other variants
    spread: float = 0.0  # (second fastest − fastest) / fastest pass: this row's timing noise


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
        corrections = CorrectionChain.from_specs(
            list(variant.corrections), cfg, correction_context(scene.scene, start_m)
        )
    if variant is not None and variant.physical:
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


def measure_costs(
    configs: list[Config],
    variants: list,
    shots: np.ndarray,
    repeats: int = 2,
    device=None,
    start_m=0.0,
    scene=None,
    engine=None,
):
    """The cost of each variant of a scene → [(image, az, rg, Timing)], in ``variants`` order.

    Every variant is warmed up first (JIT, kernel builds); then ``repeats`` rounds each time
    every variant once, in an order rotated by one each round, so a change in the machine's
    load (these machines' speed swings 2x from hour to hour) falls on every variant alike
    rather than on whichever ran during it.  A variant's cost is its fastest pass; its
    ``spread`` (second fastest − fastest, over the fastest) is how well that floor repeats,
    the noise its comparisons must beat (:func:`cost_ratio`); passes slowed by a busy moment
    lie above the floor and widen it only when they are all but one.  ``engine``: the pass
    to time (default :func:`run_engine`).
    """
    engine = engine or run_engine
    for cfg, v in zip(configs, variants, strict=True):
        p = cfg.processor
        warm = min(len(shots), 2 * p.aperture_pulses + 2 * p.micro_batch)
        engine(cfg, shots[:warm], v.lens_backend, device, start_m, v, scene)  # JIT, builds
    best: list = [None] * len(variants)
    totals: list[list[float]] = [[] for _ in variants]
    for r in range(repeats):
        order = list(range(len(variants)))
        order = order[r % len(order) :] + order[: r % len(order)]
        for i in order:
            v = variants[i]
            result = engine(configs[i], shots, v.lens_backend, device, start_m, v, scene)
            totals[i].append(sum(result[3]))
            if best[i] is None or sum(result[3]) < sum(best[i][3]):
                best[i] = result
    out = []
    for cfg, result, passes in zip(configs, best, totals, strict=True):
        image, az, rg, service, counts = result
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
            len(passes),
            _floor_spread(passes),
        )
        out.append((image, az, rg, timing))
    return out


def _floor_spread(passes: list[float]) -> float:
    if len(passes) < 2:
        return 0.0
    fastest, second = sorted(passes)[:2]
    return (second - fastest) / fastest


def cost_ratio(row: dict, base: dict) -> str:
    """This row's time per pulse over ``base``'s, or "≈" where the difference is within the
    two rows' timing noise (the larger spread of their passes, at least 5 %)."""
    ratio = row["us_per_pulse"] / base["us_per_pulse"]
    noise = max(row.get("spread", 0.0), base.get("spread", 0.0), 0.05)
    return "≈" if abs(ratio - 1.0) <= noise else f"{ratio:.2f}×"


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


MOVED_CELLS = 8.0  # along track: where a correction blind to linear phase may move a point
LEAST_CROP = 4  # bins each side of a target, whatever stands beside it


def _reports(cfg: Config, image, az, rg, targets, extra=(), azimuth_cells=3.0):
    """Point-target analysis of each target on a range crop that excludes the other targets and
    the scene's extra points ``extra`` (along track, range m) within the azimuth chip (a
    retro-reflector: a range cut reaching it would count it as a sidelobe; the phase-errors
    scene's retro 40 bins away read as a range PSLR of +19 dB), at least LEAST_CROP bins each
    way.  Each point is looked for within ``azimuth_cells`` resolution cells along track of
    where it should be (and 3 in range)."""
    rho_r = cfg.waveform.range_resolution_m
    spacing = abs(rg[1] - rg[0])
    ranges = np.array([r for _, _, r in targets])
    out = []
    for _, x, r in targets:
        others = np.abs(np.delete(ranges, np.flatnonzero(ranges == r)[0]) - r)
        reach_m = chip_lines(cfg, r) * cfg.geometry.along_track_step_m
        beside = [abs(er - r) for ex, er in extra if abs(ex - x) <= reach_m]
        others = np.concatenate([others, np.asarray(beside, float)])
        half = int(min(64, 0.5 * others.min() / spacing)) if len(others) else 64
        half = max(half, LEAST_CROP)
        centre = int(np.argmin(np.abs(rg - r)))
        crop = slice(max(0, centre - half), min(len(rg), centre + half + 1))
        out.append(
            analyse_point_target(
                image[:, crop],
                az,
                rg[crop],
                near_azimuth_m=x,
                near_range_m=r,
                search_radius_m=(azimuth_cells * cfg.azimuth_resolution_m(r), 3 * rho_r),
                chip=chip_lines(cfg, r),
            )
        )
    return out


def measure_quality(
    cfg: Config, image, az, rg, reference, targets, gain_fit=False, extra=(), moves=False
) -> Quality:
    """The quality of ``image`` against ``reference``.  ``gain_fit`` (a scene of injected
    errors): the error after the best complex gain.  ``moves`` (a correction that cannot see
    a linear phase, PGA, which moves the image by a few cells): each point looked for within
    MOVED_CELLS along track, its focus measured where it went and the move its position
    error (within 3 cells the tradeoff measured the crouch-sal PGA row off the point, a review:
    IRW 0.63, PSLR +8.5 dB, where the point, 4.5 cells on, had 1.00 and -12.9 dB); other rows
    look within 3 cells (a wider look finds a defocused image's brightest blob at its edge).
    ``extra``: the scene's other points, (along track, range) m."""
    reps = _reports(cfg, image, az, rg, targets, extra, MOVED_CELLS if moves else 3.0)
    refs = _reports(cfg, reference, az, rg, targets, extra)
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
        az_ratio.append(rep.azimuth.irw_m / az_irw_m(cfg, r))
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
