"""Simulator cost per pulse with and without each effect, or of a whole scene against its PRF.

    python tools/sim_cost.py [--preset psaltis-jpl] [--targets 16] [--pulses 2000]
    python tools/sim_cost.py --scene demo [--pulses N]

Without ``--scene``: best of three interleaved rounds; shows that an effect the scene does not
name costs nothing (the "none" row is the baseline, each effect row adds only that effect).  An
effect that cannot be made on the preset with no parameters (an FMCW-only channel on a pulsed
preset, a 3D receiver without a platform height) is left out, listed with the reason.  With
``--scene``: the scene's shots in order (all of them, or the first N), timed per second of
flight in the simulating thread's CPU time (what the live source spends, whatever else the
machine runs) and in wall time; the cost per pulse against the PRF's period says whether the
scene can be simulated live, and what share of one core it takes.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ...lens.plan import range_axis_m
from ...presets import preset
from ...scene import Simulator, load_scene, point_scene
from ...scene.effects import REGISTRY, load_effects

PARAMS = {"noise": {"snr_db": 0.0}, "antenna_pattern": {}}


def cost_us(cfg, n_targets, pulses, effects) -> float:
    rng = np.random.default_rng(0)
    rm = range_axis_m(cfg)
    xs = rng.uniform(-1, 1, n_targets) * cfg.synthetic_aperture_m
    rs = rng.uniform(rm[0], rm[-1], n_targets)
    scene = point_scene(cfg, xs, rs, effects=effects, pulses=pulses, start_along_track_m=0.0)
    sim = Simulator(scene)
    sim.block(16)  # warm-up
    t0 = time.perf_counter()
    sim.block(pulses - 16)
    return 1e6 * (time.perf_counter() - t0) / (pulses - 16)


def scene_cost(scene, pulses: int | None = None) -> dict:
    """Cost of simulating ``scene``'s first ``pulses`` shots (all by default), per second of
    flight: thread CPU µs/pulse (mean, worst second) and wall µs/pulse, against 1/PRF."""
    prf = scene.config.geometry.prf_hz
    total = scene.pulses if pulses is None else min(pulses, scene.pulses)
    sim = Simulator(scene)
    second = max(1, int(round(prf)))
    cpu, wall, done = [], [], 0
    while done < total:
        count = min(second, total - done)
        t0, c0 = time.perf_counter(), time.thread_time()
        sim.block(count)
        cpu.append(1e6 * (time.thread_time() - c0) / count)
        wall.append(1e6 * (time.perf_counter() - t0) / count)
        done += count
    # The first second includes numba's load from its cache; report it apart.
    steady = cpu[1:] or cpu
    return {
        "scene": scene.name,
        "scatterers": len(scene.targets),
        "pulses": total,
        "prf_hz": prf,
        "period_us": 1e6 / prf,
        "first_second_cpu_us_per_pulse": cpu[0],
        "cpu_us_per_pulse": float(np.mean(steady)),
        "worst_second_cpu_us_per_pulse": float(np.max(steady)),
        "wall_us_per_pulse": float(np.mean(wall[1:] or wall)),
    }


def print_scene_cost(c: dict) -> None:
    share = c["cpu_us_per_pulse"] / c["period_us"]
    worst = c["worst_second_cpu_us_per_pulse"] / c["period_us"]
    print(
        f"simulator cost, scene {c['scene']!r}: {c['scatterers']} scatterers, "
        f"{c['pulses']} pulses at {c['prf_hz']:g} Hz (period {c['period_us']:.1f} µs)"
    )
    print(
        f"  CPU   {c['cpu_us_per_pulse']:9.1f} µs/pulse  ({100 * share:.0f} % of the period; "
        f"worst second {c['worst_second_cpu_us_per_pulse']:.1f} µs, {100 * worst:.0f} %)"
    )
    print(f"  wall  {c['wall_us_per_pulse']:9.1f} µs/pulse  (with what else the machine runs)")
    print(f"  first second {c['first_second_cpu_us_per_pulse']:.1f} µs/pulse CPU (numba load)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    ap.add_argument("--preset", default="psaltis-jpl", help="preset (default psaltis-jpl)")
    ap.add_argument("--targets", type=int, default=16, help="random point targets (default 16)")
    ap.add_argument(
        "--pulses",
        type=int,
        help="pulses timed (default 2000; with --scene all of the scene's)",
    )
    ap.add_argument("--scene", help="a scene file or built-in scene name: its cost against its PRF")
    args = ap.parse_args(argv)
    least = 1 if args.scene else 17  # (without --scene the first 16 pulses warm up)
    if args.pulses is not None and args.pulses < least:
        print(f"sim_cost: --pulses must be at least {least}, got {args.pulses}", file=sys.stderr)
        return 2
    if args.scene:
        try:
            scene = load_scene(args.scene)
        except ValueError as exc:
            print(f"sim_cost: {exc}", file=sys.stderr)
            return 2
        print_scene_cost(scene_cost(scene, args.pulses))
        return 0
    args.pulses = args.pulses or 2000
    try:
        cfg = preset(args.preset)
    except ValueError as exc:
        print(f"sim_cost: {exc}", file=sys.stderr)
        return 2
    cases, not_here = [("none", [])], []
    for name in REGISTRY:  # (module docstring: some cannot be made on every preset)
        spec = [(name, PARAMS.get(name, {}))]
        try:
            load_effects(spec, cfg)
        except ValueError as exc:
            not_here.append(f"  {name:16s} left out: {exc}")
            continue
        cases.append((name, spec))
    cases.append(("all", [spec[0] for _, spec in cases[1:]]))
    print(
        f"simulator cost, {args.preset}, {args.targets} targets, "
        f"{cfg.waveform.samples_per_shot} samples/shot"
    )
    # Three interleaved rounds, best of three: the machine is shared and noisy.
    best = {label: float("inf") for label, _ in cases}
    for _ in range(3):
        for label, effects in cases:
            best[label] = min(best[label], cost_us(cfg, args.targets, args.pulses, effects))
    for label, _ in cases:
        print(f"  {label:16s} {best[label]:9.1f} µs/pulse   ({best[label] / best['none']:5.2f}x)")
    if not_here:
        print("\n".join(not_here))
    return 0


if __name__ == "__main__":
    sys.exit(main())
