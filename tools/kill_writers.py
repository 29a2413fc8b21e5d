"""Kill `rtsar run -o` and `rtsar subscribe -o` with SIGKILL at random moments; open every file.

    python tools/kill_writers.py [--kills 20] [--seed 0] [--max-delay 3.0]

Each kill starts a fresh writer on the built-in demo scene (at its real PRF), waits until its
image file has taken its name, lets it stream for a random 0 .. --max-delay seconds, and kills
it with SIGKILL (what an OOM kill or a power cut does to a process).  Kills alternate between
`run -o IMG` and `subscribe -o IMG` (fed by a `run` on a private ipc:// endpoint).  Every file
must open with `rtsar.sinks.image_file.read_image`, hold whole lines with finite positions, and say
`complete = False`; no temporary file may be left (the writer's empty claim mark, which the next
writer of the name removes, may).  Prints one line per kill and a summary;
exit status 1 if any file failed.  Not a test (tests/test_crash_safe.py is the fast one).
"""

from __future__ import annotations

import argparse
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from rtsar.sinks.image_file import read_image


def rtsar(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "rtsar", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def wait_for(path: Path, timeout_s: float = 60.0) -> bool:
    t0 = time.monotonic()
    while not path.exists():
        if time.monotonic() - t0 > timeout_s:
            return False
        time.sleep(0.02)
    return True


def one_kill(folder: Path, k: int, mode: str, delay_s: float) -> dict:
    out, ep = folder / f"img{k}.h5", f"ipc://{folder}/pub{k}"
    pub = None
    if mode == "run":
        writer = rtsar("run", "--duration", "120", "--endpoint", ep, "-o", str(out))
    else:
        pub = rtsar("run", "--duration", "120", "--endpoint", ep)
        writer = rtsar("subscribe", ep, "-o", str(out))
    try:
        if not wait_for(out):
            return {"mode": mode, "ok": False, "why": "the file never appeared"}
        time.sleep(delay_s)
        writer.send_signal(signal.SIGKILL)
        writer.wait(30)
    finally:
        for p in (writer, pub):
            if p is not None and p.poll() is None:
                p.send_signal(signal.SIGINT)
                p.wait(30)
    row = {"mode": mode, "delay_s": delay_s}
    try:
        image, az, rg, attrs = read_image(out)
    except ValueError as exc:
        return {**row, "ok": False, "why": str(exc)}
    # The writer's claim on the name (an empty `-writing` mark, unlocked by its death) stays
    # for the next writer of the name to remove; a data temporary must not.
    leftovers = [
        p.name
        for p in folder.iterdir()
        if p.name.startswith(f".img{k}.h5") and not p.name.endswith("-writing")
    ]
    good = (
        len(image) == len(az)
        and bool(np.isfinite(az).all())
        and not attrs["complete"]
        and not leftovers
    )
    why = "" if good else f"lines {len(image)}/{len(az)}, complete {attrs['complete']}, {leftovers}"
    return {**row, "ok": good, "lines": len(image), "why": why}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--kills", type=int, default=20, help="writers to kill (default 20)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--max-delay", type=float, default=3.0, help="longest stream before a kill")
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)
    rows = []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rtsar-kill-") as tmp:
        for k in range(args.kills):
            mode = ("run", "subscribe")[k % 2]
            row = one_kill(Path(tmp), k, mode, rng.uniform(0.0, args.max_delay))
            rows.append(row)
            print(
                f"kill {k + 1:3d} {mode:9s} after {row.get('delay_s', 0):4.2f} s: "
                + (f"opens, {row['lines']} lines, complete=False" if row["ok"] else row["why"]),
                flush=True,
            )
    ok = [r for r in rows if r["ok"]]
    lines = [r["lines"] for r in ok] or [0]
    print(
        f"{len(ok)}/{len(rows)} files open, incomplete-marked, no temporary left "
        f"({sum(r['mode'] == 'run' for r in ok)} run -o, "
        f"{sum(r['mode'] == 'subscribe' for r in ok)} subscribe -o); lines kept min "
        f"{min(lines)}, median {statistics.median(lines):.0f}, max {max(lines)}; "
        f"{time.perf_counter() - t0:.0f} s"
    )
    return 0 if len(ok) == len(rows) else 1


if __name__ == "__main__":
    sys.exit(main())
