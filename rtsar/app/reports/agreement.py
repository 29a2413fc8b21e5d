"""Agreement of the fast stages with their float64 NumPy references, per preset (relative rms).

    python tools/agreement.py [--presets psaltis-max,crouch-sal]

Lens: AOLens (OpenCL, complex64) vs compress_reference (complex128) on simulated noisy shots.
Correlators: DirectCorrelator and FFTCorrelator (complex64) vs correlate_reference (complex128)
on the lens output of the same stream.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ...analysis import relative_rms
from ...ccd.base import correlate_reference, design_mask
from ...ccd.direct import DirectCorrelator
from ...ccd.fft import FFTCorrelator
from ...lens.base import compress_reference
from ...lens.opencl import AOLens
from ...lens.plan import make_plan
from ...presets import PRESETS, preset
from ...scene import Simulator, point_scene


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--presets", default=",".join(PRESETS))
    args = ap.parse_args(argv)
    print(f"{'preset':12} {'lens':>10} {'direct':>10} {'fft':>10}   (relative rms vs float64)")
    for name in args.presets.split(","):
        cfg = preset(name)
        plan = make_plan(cfg)
        n = cfg.processor.aperture_pulses
        rng = np.random.default_rng(5)
        xs = rng.uniform(-0.5, 0.5, 8) * cfg.synthetic_aperture_m
        rs = rng.uniform(plan.range_m[0], plan.range_m[-1], 8)
        scene = point_scene(
            cfg,
            xs,
            rs,
            effects=[("noise", {"snr_db": 0.0})],
            seed=2,
            pulses=n + 300,
            start_along_track_m=-0.5 * cfg.synthetic_aperture_m,
        )
        shots = Simulator(scene).block(scene.pulses)
        ref_lines = compress_reference(plan, shots)
        lines = AOLens(plan).compress(shots)
        lens_err = relative_rms(lines, ref_lines)
        mask = design_mask(cfg, plan.range_m)
        ref_img = correlate_reference(lines, mask)
        errs = []
        for corr in (DirectCorrelator(mask), FFTCorrelator(mask)):
            b = cfg.processor.micro_batch
            out = [corr.push(lines[i : i + b]) for i in range(0, len(lines), b)] + [corr.flush()]
            errs.append(relative_rms(np.concatenate(out), ref_img))
        print(f"{name:12} {lens_err:10.2e} {errs[0]:10.2e} {errs[1]:10.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
