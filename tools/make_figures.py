"""The pictures of the demos (README.md, docs/pages/guide/start.md), made again by one command.

    python tools/make_figures.py [--out-dir figures] [--duration 10]
    python tools/make_figures.py --refresh     # over the repository's docs/pages/figures/

By default the PNGs go to ./figures (or --out-dir), so a run never touches the files git
tracks; --refresh writes them over the repository's own figures, to be committed.

Runs what a user runs, with this interpreter's rtsar:

1. ``rtsar run --duration 10 -o demo.h5`` (the built-in demo streamed live at 1600 Hz) while
   ``rtsar view --png demo-waterfall.png --lines L`` records a snapshot of the live waterfall;
2. the quicklook of demo.h5 (dB re peak, axes in metres) → ``demo-quicklook.png``;
3. ``rtsar simulate sal-demo`` + ``rtsar process`` + the quicklook at true aspect →
   ``sal-demo.png``.

The PNGs are re-encoded in 64 grey levels (the figures are grey scale) to stay small.  Takes
about a minute; the recordings are written to a temporary folder and removed.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from PIL import Image

from rtsar.app.quicklook import save_quicklook
from rtsar.sinks.image_file import read_image

REPOSITORY_FIGURES = Path(__file__).resolve().parents[1] / "docs" / "pages" / "figures"
FIGURE_NAMES = ("demo-quicklook.png", "demo-waterfall.png", "sal-demo.png")


def rtsar(*args: str, **kw) -> subprocess.CompletedProcess:
    """Run ``python -m rtsar ARGS`` with this interpreter; raise on failure."""
    done = subprocess.run([sys.executable, "-m", "rtsar", *args], text=True, **kw)
    if done.returncode != 0:
        raise SystemExit(f"make_figures: rtsar {' '.join(args)} failed ({done.returncode})")
    return done


def shrink(png: Path, levels: int = 64) -> int:
    """Re-encode a grey-scale figure with ``levels`` grey levels; returns its size in bytes."""
    step = 256 // levels
    with Image.open(png) as im:
        grey = im.convert("L").point(lambda v: min(255, (v // step) * step + step // 2))
    grey.save(png, optimize=True)
    return png.stat().st_size


def quicklook(image_h5: Path, png: Path, title: str, true_aspect: bool = False) -> None:
    image, az, rg, _ = read_image(image_h5)
    save_quicklook(png, image, az, rg, 50.0, title=title, true_aspect=true_aspect)


def live_demo(work: Path, out: Path, duration_s: float, lines: int, port: int) -> None:
    endpoint = f"tcp://127.0.0.1:{port}"
    waterfall = out / "demo-waterfall.png"
    view = subprocess.Popen(
        [sys.executable, "-m", "rtsar", "view", endpoint, "--png", str(waterfall)]
        + ["--lines", str(lines), "--timeout", "60"],
        text=True,
    )
    time.sleep(2.0)  # the viewer subscribes before the first strip
    rtsar("run", "--duration", f"{duration_s:g}", "--endpoint", endpoint, "-o", str(work / "d.h5"))
    if view.wait(timeout=120) != 0:
        raise SystemExit("make_figures: rtsar view wrote no snapshot")
    quicklook(
        work / "d.h5",
        out / "demo-quicklook.png",
        f"rtsar run: the demo scene live at 1600 Hz ({duration_s:g} s), dB re peak",
    )


def sal_demo(work: Path, out: Path) -> None:
    rtsar("simulate", "sal-demo", "-o", str(work / "s.h5"))
    rtsar("process", str(work / "s.h5"), "-o", str(work / "si.h5"))
    quicklook(
        work / "si.h5",
        out / "sal-demo.png",
        "sal-demo: Zhao's 1.55 µm bench (zhao-insal), dB re peak",
        true_aspect=True,
    )


def parse_args(argv=None) -> argparse.Namespace:
    """The options, with ``out_dir`` resolved: ./figures, --out-dir, or with --refresh the
    repository's docs/pages/figures."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    where = ap.add_mutually_exclusive_group()
    where.add_argument(
        "--out-dir",
        type=Path,
        default=Path("figures"),
        help="folder for the PNGs (default ./figures)",
    )
    where.add_argument(
        "--refresh",
        action="store_true",
        help=f"write over the repository's own figures ({REPOSITORY_FIGURES})",
    )
    ap.add_argument("--duration", type=float, default=10.0, help="live run, s (default 10)")
    ap.add_argument("--lines", type=int, default=8192, help="waterfall lines (default 8192)")
    ap.add_argument("--port", type=int, default=5565, help="loopback port (default 5565)")
    args = ap.parse_args(argv)
    if args.refresh:
        args.out_dir = REPOSITORY_FIGURES
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        live_demo(work, args.out_dir, args.duration, args.lines, args.port)
        sal_demo(work, args.out_dir)
    for name in FIGURE_NAMES:
        size = shrink(args.out_dir / name)
        print(f"wrote {args.out_dir / name} ({size / 1024:.0f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
