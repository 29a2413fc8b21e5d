"""An independent image former reads rtsar's CPHD: FastSAR (PyPI ``fastsar``) against rtsar.

    python tools/fastsar_check.py                    # the built-in scene (tiny preset, 3 targets)
    python tools/fastsar_check.py --scene S.toml     # point targets of your own scene
    python tools/fastsar_check.py --venv DIR         # where FastSAR's environment lives

Steps: simulate the scene (``rtsar simulate``), export it as CPHD 1.0.1 (``rtsar export
--cphd``), focus the recording with ``rtsar process`` (timed), and form the CPHD with FastSAR's
``form_cphd`` (spotlight backprojection over the whole track on a grid of half a line spacing
by a sixth of the range resolution; timed twice: the first call includes its one-time
compilation) in a virtual
environment of its own (created at ``--venv`` with ``pip install fastsar sarpy`` when missing:
FastSAR is never a dependency of rtsar).  Each target is then located in both images (rtsar's
point-target analysis, band-limited peak refinement): FastSAR's ground-plane peak is taken back
through ECF to rtsar's local frame and to slant range, and the two positions are compared in
rtsar's cells (line spacing along track, range bin spacing).  Exit status 0 when every target
agrees within ``--tolerance-cells`` (default 1/8), 1 otherwise, 2 when FastSAR cannot run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rtsar.analysis.point_target import analyse_point_target
from rtsar.app.cli import main as rtsar
from rtsar.scene import load_scene
from rtsar.sinks.image_file import read_image
from rtsar.sources.formats.geometry import LocalFrame, platform_height_m

SCENE = """
name = "fastsar-check"
preset = "tiny"
seed = 3
pulses = 400
start_along_track_m = -20.0
[[targets]]
along_track_m = 20.3
slant_range_m = 1950.7
[[targets]]
along_track_m = 60.1
slant_range_m = 2001.2
amplitude = 0.8
[[targets]]
along_track_m = 100.4
slant_range_m = 2060.4
amplitude = 0.6
"""

HELPER = r"""
import sys, time, numpy as np, fastsar
path, out = sys.argv[1], sys.argv[2]
spacing = (float(sys.argv[3]), float(sys.argv[4]))
times = []
for _ in range(2):  # the first call compiles FastSAR's kernels
    t0 = time.perf_counter()
    r = fastsar.form_cphd(path, backend="cpu", spacing=spacing)
    times.append(time.perf_counter() - t0)
m = r["meta"]
np.savez(out, image=r["image"], origin=r["origin"], e1=r["e1"], e2=r["e2"], spx=r["spx"],
         spy=r["spy"], R=m["R"], origin_ecf=m["origin"], seconds=np.array(times))
print(r["mode"], r["image"].shape, "notes:", "; ".join(r.get("notes") or []))
"""

DEFAULT_VENV = Path.home() / ".cache" / "rtsar" / "fastsar-venv"


def fastsar_python(venv: Path) -> Path:
    """FastSAR's interpreter, creating its environment (fastsar + sarpy) when missing."""
    python = venv / "bin" / "python"
    if (
        python.exists()
        and subprocess.run(
            [str(python), "-c", "import fastsar, sarpy"], capture_output=True
        ).returncode
        == 0
    ):
        return python
    print(f"creating FastSAR's environment in {venv} (pip install fastsar sarpy) …", flush=True)
    venv.parent.mkdir(parents=True, exist_ok=True)
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    t0 = time.perf_counter()
    subprocess.run([str(python), "-m", "pip", "install", "-q", "fastsar", "sarpy"], check=True)
    print(f"installed in {time.perf_counter() - t0:.0f} s", flush=True)
    return python


def compare(scene, rtsar_image: Path, fs_npz: Path) -> list[dict]:
    """Each target's position in both images, in rtsar's cells."""
    img, az, rg, _ = read_image(rtsar_image)
    fs = np.load(fs_npz)
    cfg = scene.config
    h = platform_height_m(
        cfg.processor.range_centre_m or cfg.geometry.slant_range_m, cfg.geometry.platform_height_m
    )
    frame = LocalFrame()
    image_fs = fs["image"]
    ax = np.arange(image_fs.shape[0]) * float(fs["spx"])
    ay = np.arange(image_fs.shape[1]) * float(fs["spy"])
    d_az, d_rg = float(az[1] - az[0]), float(rg[1] - rg[0])
    rows = []
    t = scene.targets
    for x0, r0 in zip(t.along_track_m, t.slant_range_m, strict=True):
        if not (az.min() <= x0 <= az.max() and rg.min() <= r0 <= rg.max()):
            continue
        mine = analyse_point_target(img, az, rg, x0, r0, (4 * d_az, 4 * d_rg), chip=16)
        y0 = np.sqrt(r0**2 - h**2)  # where FastSAR should find it: its local frame, its grid
        local_fs = (frame.to_ecf([x0, y0, 0.0]) - fs["origin_ecf"]) @ fs["R"].T
        i0, j0 = (local_fs - fs["origin"]) @ fs["e1"], (local_fs - fs["origin"]) @ fs["e2"]
        theirs = analyse_point_target(image_fs, ax, ay, i0, j0, (4.0, 4.0), chip=16)
        p = fs["origin"] + theirs.azimuth_m * fs["e1"] + theirs.range_m * fs["e2"]
        x, y, z = frame.from_ecf(p @ fs["R"] + fs["origin_ecf"])
        r_fs = float(np.sqrt(y**2 + (h - z) ** 2))
        rows.append(
            {
                "target_m": [float(x0), float(r0)],
                "rtsar_m": [mine.azimuth_m, mine.range_m],
                "fastsar_m": [float(x), r_fs],
                "azimuth_cells": (float(x) - mine.azimuth_m) / d_az,
                "range_cells": (r_fs - mine.range_m) / d_rg,
            }
        )
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scene", help="scene file with point targets (default: built in)")
    p.add_argument("--venv", type=Path, default=DEFAULT_VENV, help=f"default {DEFAULT_VENV}")
    p.add_argument("--work", type=Path, help="folder for the files (default: a temporary one)")
    p.add_argument("--tolerance-cells", type=float, default=0.125, help="default 1/8")
    p.add_argument("--json", type=Path, help="also write the figures as JSON")
    args = p.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="rtsar-fastsar-"))
    work.mkdir(parents=True, exist_ok=True)
    scene_path = Path(args.scene) if args.scene else work / "scene.toml"
    if not args.scene:
        scene_path.write_text(SCENE)
    scene = load_scene(scene_path)
    rec, cphd, img = work / "rec.h5", work / "rec.cphd", work / "rtsar.h5"
    if rtsar(["simulate", str(scene_path), "-o", str(rec)]) != 0:
        return 2
    if rtsar(["export", str(rec), "--cphd", str(cphd)]) != 0:
        return 2
    t0 = time.perf_counter()
    if rtsar(["process", str(rec), "-o", str(img), "--lens", "numpy"]) != 0:
        return 2
    rtsar_s = time.perf_counter() - t0
    try:
        python = fastsar_python(args.venv)
    except (subprocess.CalledProcessError, OSError) as exc:
        print(f"FastSAR could not be installed: {exc}", file=sys.stderr)
        return 2
    helper, out = work / "fastsar_form.py", work / "fastsar.npz"
    helper.write_text(HELPER)
    env = dict(os.environ, JAX_PLATFORMS="cpu")
    # A grid finer than both resolutions; a spacing also makes FastSAR use the whole aperture
    # (without one it keeps the central part for square resolution, on a coarser grid).
    geo = scene.config.geometry
    spacing = [geo.along_track_step_m / 2, scene.config.waveform.range_resolution_m / 6]
    run = subprocess.run(
        [str(python), str(helper), str(cphd), str(out), *map(str, spacing)], env=env
    )
    if run.returncode != 0:
        print("FastSAR failed on rtsar's CPHD (its messages above)", file=sys.stderr)
        return 1
    rows = compare(scene, img, out)
    fs_s = np.load(out)["seconds"]
    print(
        f"\n{'target (x, R) m':>22} {'rtsar (x, R) m':>24} {'FastSAR (x, R) m':>24} "
        f"{'d az cells':>10} {'d rg cells':>10}"
    )
    for r in rows:
        print(
            f"{r['target_m'][0]:9.3f} {r['target_m'][1]:11.3f}  "
            f"{r['rtsar_m'][0]:10.4f} {r['rtsar_m'][1]:12.4f}  "
            f"{r['fastsar_m'][0]:10.4f} {r['fastsar_m'][1]:12.4f}  "
            f"{r['azimuth_cells']:10.4f} {r['range_cells']:10.4f}"
        )
    print(
        f"time: rtsar process {rtsar_s:.2f} s (numpy lens, whole command); FastSAR form_cphd "
        f"{fs_s[1]:.2f} s (CPU backend; first call, with compilation, {fs_s[0]:.2f} s)"
    )
    ok = bool(rows) and all(
        abs(r["azimuth_cells"]) <= args.tolerance_cells
        and abs(r["range_cells"]) <= args.tolerance_cells
        for r in rows
    )
    if args.json:
        args.json.write_text(
            json.dumps({"targets": rows, "rtsar_s": rtsar_s, "fastsar_s": fs_s.tolist()}, indent=2)
        )
    print(
        f"{'every' if ok else 'NOT every'} target within {args.tolerance_cells} cell; "
        f"files in {work}"
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
