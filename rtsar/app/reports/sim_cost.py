"""Simulator cost per pulse with and without each effect, measured in one run.

    python tools/sim_cost.py [--preset psaltis-jpl] [--targets 16] [--pulses 2000]

Best of three interleaved rounds.  Shows that an effect the scene does not name costs nothing:
the "none" row is the baseline and each effect row adds only that effect.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from ...lens.plan import range_axis_m
from ...presets import preset
from ...scene import Simulator, point_scene
from ...scene.effects import REGISTRY

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


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--preset", default="psaltis-jpl")
    ap.add_argument("--targets", type=int, default=16)
    ap.add_argument("--pulses", type=int, default=2000)
    args = ap.parse_args(argv)
    cfg = preset(args.preset)
    cases = [("none", [])] + [(n, [(n, PARAMS.get(n, {}))]) for n in REGISTRY]
    cases.append(("all", [(n, PARAMS.get(n, {})) for n in REGISTRY]))
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
