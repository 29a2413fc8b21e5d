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

The spotlight rows (``spotlight``): polar format variants and fast backprojection against the
exact backprojection, error by ring around the scene centre and time per image.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np

from ...lens.base import opencl_unavailable
from ...sinks.io import write_text_when_complete
from .measure import measure_costs, measure_quality, reference_image, trace_latency_s
from .report import markdown, pareto_front, plot
from .scenes import TradeoffScene, Variant, default_scenes, make_scene, simulate
from .spotlight import run_spotlight, spotlight_markdown

__all__ = [
    "TradeoffScene",
    "Variant",
    "add_arguments",
    "default_scenes",
    "make_scene",
    "markdown",
    "pareto_front",
    "plot",
    "reference_image",
    "run",
    "run_tradeoff",
    "trace_latency_s",
]


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
        configs = [scene.config_of(v) for v in scene.variants]
        for v, cfg in zip(scene.variants, configs, strict=True):
            if v.default:  # its peak sets the physical mode's full scale (run_engine)
                ref = _reference(scene, cfg, refs)
                scene.image_peak = float(np.abs(ref).max())
        t0 = time.perf_counter()
        costs = measure_costs(
            configs,
            scene.variants,
            scene.shots,
            repeats,
            device,
            scene.start_along_track_m,
            scene,
        )
        log(
            f"[{scene.key}] timed {len(configs)} variants, {repeats} interleaved passes each, "
            f"in {time.perf_counter() - t0:.1f} s"
        )
        for v, cfg, (image, az, rg, timing) in zip(scene.variants, configs, costs, strict=True):
            done += 1
            quality = measure_quality(
                cfg,
                image,
                az,
                rg,
                _reference(scene, cfg, refs),
                scene.targets,
                gain_fit=bool(scene.effects),
                extra=[(t[0], t[1]) for t in scene.extra_targets],
                moves=any(c.split(":")[0] == "pga" for c in v.corrections),
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
                f"{timing.pulses_per_s:,.0f} pulses/s (passes ±{100 * timing.spread:.0f} %), "
                f"latency {timing.latency_p50_ms:.1f} ms, error {quality.image_error:.2e}"
            )
    return pareto_front(rows)


def _reference(scene: TradeoffScene, cfg, refs: dict) -> np.ndarray:
    """The float64 reference image of a variant's geometry, made once per geometry."""
    key = (
        scene.reference_migration_taps,
        cfg.processor.aperture_pulses,
        cfg.processor.range_window,
        cfg.processor.azimuth_window,
        cfg.processor.range_oversampling,
        cfg.processor.range_bins,
    )
    if key not in refs:
        refs[key] = reference_image(cfg, scene.reference_shots, scene.reference_migration_taps)
    return refs[key]


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
        "--repeats",
        type=int,
        help="timed passes per variant, interleaved with the scene's other variants, the best "
        "kept and the spread reported (default 2; with --quick 5: its passes are short)",
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
    if args.repeats is None:
        args.repeats = 5 if args.quick else 2
    if args.repeats < 1:
        raise ValueError("--repeats must be >= 1")
    scenes = default_scenes(args.quick, not getattr(args, "no_corrections", False))
    reason = None if args.lens_numpy or args.device else opencl_unavailable()
    if reason is not None:
        print(f"tradeoff: OpenCL unavailable ({reason}): every row on the NumPy lens", flush=True)
    if args.lens_numpy or reason is not None:
        for s in scenes:
            s.variants = [v for v in s.variants if v.knob != "lens"]
            s.variants = [replace(v, lens_backend="numpy") for v in s.variants]
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = run_tradeoff(scenes, device=args.device, repeats=args.repeats)
    spot_rows, spot_scene = run_spotlight(
        args.quick, args.repeats, lambda m: print(m, file=sys.stderr, flush=True)
    )
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
        "spotlight": {**spot_scene, "rows": spot_rows},
    }
    write_text_when_complete(out / "tradeoff.json", json.dumps(doc, indent=1, default=float))
    write_text_when_complete(
        out / "tradeoff.md",
        markdown(rows, scenes) + "\n" + spotlight_markdown(spot_rows, spot_scene),
    )
    plot(rows, scenes, out / "tradeoff.png")
    print(markdown(rows, scenes))
    print(spotlight_markdown(spot_rows, spot_scene))
    off = [f"{r['scene']}" for r in rows if r["default"] and not r["front"]]
    print(f"defaults on the Pareto front: {'yes' if not off else 'NO (' + ', '.join(off) + ')'}")
    print(
        f"wrote {out / 'tradeoff.json'}, {out / 'tradeoff.md'}, {out / 'tradeoff.png'} "
        f"in {time.perf_counter() - t0:.0f} s"
    )
    return 0
