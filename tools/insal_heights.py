"""Heights from the command path against the truth: `rtsar process --height insal|sam` on
Zhao's ridge and drawing pin, every strip size, scored against the surface's height on the image
grid.

    python tools/insal_heights.py [--lines 96] [--range-bins 96] [--strips 8,16,32,48,64,96]
                                  [--methods insal,sam] [--scenes ridge,pin]

Each scene is simulated once per method (Zhao 2014's bench: 2.4 m, look angle atan √2; insal: a
second receiver 1.6 mm away, h_2π = 3.29 mm; sam: the INO 3D patent's masks with h_2π = 3.3 mm;
10 dB per-sample SNR in every channel), recorded with its channels, then processed by the
`process` command with each --height-strip-lines.  Prints rms / bias of the valid heights on the
scored pixels (rtsar.topo.insar.height_error), coverage, and the limit h_2π/20.  Not a test
(tests/test_height_commands.py is the fast one).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rtsar.app.cli import main as rtsar
from rtsar.scene.correction_context import insal_geometry, modulation_geometry
from rtsar.scene.relief import default_spacing_m, ridge, sphere_cap, surface_scene, zhao_config
from rtsar.scene.simulator import Simulator
from rtsar.sinks.image_file import read_heights, read_image
from rtsar.sinks.io import RecordingWriter
from rtsar.topo.insar import height_error

SURFACES = {"ridge": lambda: ridge(2.5e-3, 8e-3), "pin": lambda: sphere_cap(5e-3, 1.5e-3)}


def score(name: str, method: str, args, folder: Path) -> list[str]:
    cfg = zhao_config(sample_rate_hz=1280.0, aperture_pulses=160, range_bins=args.range_bins)
    g = cfg.geometry
    period = 3.3e-3 / (g.slant_range_m * math.sin(math.acos(g.platform_height_m / g.slant_range_m)))
    extra = (
        ("interferometric_receivers", {"snr_db": 10.0})
        if method == "insal"
        else ("amplitude_modulation_3d", {"angular_period_rad": period, "snr_db": 10.0})
    )
    effects = [("noise", {"snr_db": 10.0}), extra]
    ss = surface_scene(
        cfg,
        SURFACES[name](),
        args.lines,
        seed=1,
        spacing_m=default_spacing_m(cfg, 2.0),
        effects=effects,
    )
    scene = ss.scene
    t0 = time.perf_counter()
    shots, aux = Simulator(scene).block_with_aux(scene.pulses)
    idx = np.arange(scene.pulses)
    rec = folder / f"{name}-{method}.h5"
    with RecordingWriter(rec, cfg, scene.to_dict()) as w:
        w.write(shots, idx, idx / cfg.geometry.prf_hz, scene.along_track_of(idx), aux)
    out = [
        f"{name}, {method}: {scene.pulses} shots, {len(scene.targets)} scatterers, simulated in "
        f"{time.perf_counter() - t0:.1f} s"
    ]
    for strip in args.strips:
        img = folder / f"{name}-{method}-{strip}.h5"
        cmd = ["process", str(rec), "-o", str(img), "--lens", "numpy", "--height", method]
        if rtsar(cmd + ["--height-strip-lines", str(strip)]) != 0:
            out.append(f"  strip {strip}: process failed")
            continue
        _, az, rg, _ = read_image(img)
        h, v = read_heights(img)
        truth = ss.truth(az, rg)
        e = height_error(h, v, truth.height_m, truth.scored)
        if method == "insal":
            limit = float(insal_geometry(scene).ambiguity_height_m(float(np.mean(rg)))) / 20
        else:
            limit = modulation_geometry(scene).elevation_resolution_m  # eq. 14
        rms = e["rms_m"]
        if rms is None:  # no valid pixel on the scored area
            out.append(f"  strip {strip:3d}: no valid height on the surface: FAIL")
            continue
        out.append(
            f"  strip {strip:3d}: rms {rms * 1e6:6.1f} µm, bias {e['bias_m'] * 1e6:6.1f} µm, "
            f"coverage {e['coverage']:.2f}, limit {limit * 1e6:.0f} µm: "
            + ("pass" if rms <= limit else "FAIL")
        )
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--lines", type=int, default=96)
    ap.add_argument("--range-bins", type=int, default=96)
    ap.add_argument(
        "--strips",
        type=lambda t: [int(x) for x in t.split(",")],
        default=[8, 16, 32, 48, 64, 96],
        help="--height-strip-lines values (default 8,16,32,48,64,96)",
    )
    ap.add_argument("--scenes", default="ridge,pin")
    ap.add_argument("--methods", default="insal,sam")
    args = ap.parse_args(argv)
    failed = False
    with tempfile.TemporaryDirectory(prefix="rtsar-insal-") as tmp:
        for name in args.scenes.split(","):
            for method in args.methods.split(","):
                for line in score(name, method, args, Path(tmp)):
                    print(line, flush=True)
                    failed |= line.endswith("FAIL") or line.endswith("failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
