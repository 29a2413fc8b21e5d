"""Measure ``rtsar batch`` with 1 and 2 Dask workers on the same recordings (not a test).

Simulates COUNT recordings of a preset (different seeds and target positions), focuses them with
``rtsar batch --workers 1`` and ``--workers 2`` (wall time of each, and the ratio, from this one
run) and checks that both give the images ``rtsar process`` gives, bit for bit.

    python tools/batch_scaling.py [--preset psaltis-jpl] [--pulses 6000] [--count 8]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
import time
from pathlib import Path

import numpy as np

from rtsar.app.cli import main as rtsar
from rtsar.sinks.image_file import read_image

SCENE = """
preset = "{preset}"
seed = {seed}
pulses = {pulses}
[[targets]]
along_track_m = {x}
slant_range_m = {r}
[[effects]]
name = "noise"
snr_db = 0.0
"""


def quiet(argv: list[str]) -> int:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return rtsar(argv)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--preset", default="psaltis-jpl", help="instrument preset (default psaltis-jpl)"
    )
    ap.add_argument("--pulses", type=int, default=6000, help="shots per recording (default 6000)")
    ap.add_argument("--count", type=int, default=8, help="recordings (default 8)")
    args = ap.parse_args(argv)

    from rtsar.presets import preset

    cfg = preset(args.preset)
    r0 = cfg.geometry.slant_range_m
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "recs"
        folder.mkdir()
        t = time.perf_counter()
        for i in range(args.count):
            scene = Path(tmp) / f"s{i}.toml"
            x = (i - args.count / 2) * 2 * cfg.azimuth_resolution_m()
            scene.write_text(
                SCENE.format(preset=args.preset, seed=i, pulses=args.pulses, x=x, r=r0)
            )
            assert quiet(["simulate", str(scene), "-o", str(folder / f"rec{i}.h5")]) == 0
        print(
            f"simulated {args.count} × {args.pulses} shots of {args.preset} in "
            f"{time.perf_counter() - t:.1f} s"
        )
        walls = {}
        for workers in (1, 2):
            out = Path(tmp) / f"w{workers}"
            t = time.perf_counter()
            status = quiet(["batch", str(folder), "--out-dir", str(out), "--workers", str(workers)])
            walls[workers] = time.perf_counter() - t
            assert status == 0, f"batch --workers {workers} failed"
            print(
                f"batch --workers {workers}: {walls[workers]:.1f} s wall (cluster start included)"
            )
        same = True
        for rec in sorted(folder.glob("*.h5")):
            ref = Path(tmp) / f"{rec.stem}-ref.h5"
            assert quiet(["process", str(rec), "-o", str(ref)]) == 0
            want = read_image(ref)[0]
            for workers in (1, 2):
                got = read_image(Path(tmp) / f"w{workers}" / f"{rec.stem}-img.h5")[0]
                same &= got.shape == want.shape and bool(np.array_equal(got, want))
        print(
            f"speed-up 2 workers ÷ 1: {walls[1] / walls[2]:.2f}×; images identical to "
            f"`rtsar process`: {'yes' if same else 'NO'}"
        )
        return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
