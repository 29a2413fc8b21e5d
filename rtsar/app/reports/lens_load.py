"""A lens call's time alone and beside a busy core: what a live run's other threads cost the
AO lens (issue 38, goal 3: where the time of a launch goes, threads included).

    python tools/lens_beside_load.py [--preset radarsat1] [--sizes 1,2,8] [--calls 400]

A CPU OpenCL driver runs a call on worker threads of its own while the calling thread waits;
in a live run the correlator's tail thread, the strip thread and the source share the same
cores.  Each lens (the OpenCL lens on the default device, or on each ``--device`` named, and
the same plan on SciPy's FFT in the calling thread) is timed at each call size, ``calls``
calls alone and then ``calls`` beside one thread that keeps a core busy without Python's lock
(NumPy's ufuncs on a 4 MB array, as the correlator's numba kernels hold a core), in
``rounds`` alternated rounds; each figure is the median and the 99th percentile of every call
of its rounds.  2-core Intel Xeon (KVM), 2026-11-30, 3 rounds of 300 calls, µs (median / p99),
alone against beside the busy core:

* radarsat1, Intel's runtime: 197 / 292 against 209 / 3,678 at 1 pulse a call, 246 / 548
  against 352 / 3,166 at 8; SciPy's: 108 / 235 against 109 / 264, 349 / 552 against 360 / 647;
* psaltis-max, Intel's runtime: 129 / 242 against 108 / 1,890 at 1, 157 / 225 against
  172 / 2,697 at 8; SciPy's: 56 / 149 against 56 / 121, 221 / 316 against 237 / 341.

(PoCL 3.1 alike: radarsat1 at 8 pulses, p99 621 against 3,081.)  A worker thread the
scheduler puts aside costs the call up to a time slice; a call in the calling thread does not
wait on another.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

import numpy as np

from ...lens import make_plan
from ...lens.numpy_lens import NumpyLens
from ...lens.opencl import AOLens
from ...presets import PRESETS, preset

BUSY_FLOATS = 1 << 20  # the busy thread's array: 4 MB, beyond the caches it shares


class BusyCore:
    """A thread that keeps one core busy without Python's lock until the ``with`` ends."""

    def __enter__(self) -> BusyCore:
        self.rounds = 0  # passes over the array so far
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name="rtsar-busy-core", daemon=True)
        self._thread.start()
        return self

    def _spin(self) -> None:
        a = np.linspace(1.0, 2.0, BUSY_FLOATS, dtype=np.float32)
        while not self._stop.is_set():
            np.sqrt(a, out=a)
            np.square(a, out=a)  # (back where it was: no value drifts to 0 or inf)
            self.rounds += 1

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def call_times_s(lens, shots: np.ndarray, calls: int) -> np.ndarray:
    """Seconds of each of ``calls`` calls of ``lens.compress(shots)``, after one untimed."""
    lens.compress(shots)
    out = np.empty(calls)
    clock = time.perf_counter
    for k in range(calls):
        t0 = clock()
        lens.compress(shots)
        out[k] = clock() - t0
    return out


def lenses_of(plan, devices) -> dict:
    """Label → lens: the OpenCL lens on each device asked for (None: the default device) and
    the plan on SciPy's FFT."""
    found = {}
    for device in devices:
        lens = AOLens(plan, device=device)
        found[f"OpenCL {lens.device_label}"] = lens
    found["SciPy (calling thread)"] = NumpyLens(plan, "scipy", "complex64")
    return found


def measure(preset_name: str, sizes, calls: int, rounds: int, devices=(None,)) -> list[dict]:
    """One row a lens and call size: median and p99 seconds alone and beside a busy core."""
    plan = make_plan(preset(preset_name))
    lenses = lenses_of(plan, devices)
    rng = np.random.default_rng(0)
    shots = {
        b: (rng.standard_normal((b, plan.samples_per_shot)) + 0j).astype(np.complex64)
        for b in sizes
    }
    spent = {(name, b, busy): [] for name in lenses for b in sizes for busy in (False, True)}
    for _ in range(rounds):
        for b in sizes:
            for name, lens in lenses.items():
                spent[name, b, False].append(call_times_s(lens, shots[b], calls))
                with BusyCore():
                    spent[name, b, True].append(call_times_s(lens, shots[b], calls))
    rows = []
    for name in lenses:
        for b in sizes:
            alone, beside = (np.concatenate(spent[name, b, busy]) for busy in (False, True))
            rows.append(
                {
                    "lens": name,
                    "pulses_a_call": b,
                    "alone_median_s": float(np.median(alone)),
                    "alone_p99_s": float(np.percentile(alone, 99)),
                    "beside_median_s": float(np.median(beside)),
                    "beside_p99_s": float(np.percentile(beside, 99)),
                }
            )
    return rows


def print_rows(preset_name: str, rows: list[dict]) -> None:
    print(f"{preset_name}: µs a lens call, alone and beside a busy core (median / p99)")
    for r in rows:
        us = {k: v * 1e6 for k, v in r.items() if k.endswith("_s")}
        print(
            f"  {r['lens'][:60]:60} {r['pulses_a_call']:4d} a call: alone "
            f"{us['alone_median_s']:8.1f} / {us['alone_p99_s']:8.1f}, beside "
            f"{us['beside_median_s']:8.1f} / {us['beside_p99_s']:8.1f}  (p99 x"
            f"{r['beside_p99_s'] / r['alone_p99_s']:.1f})"
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--preset", default="radarsat1", choices=sorted(PRESETS))
    ap.add_argument("--sizes", default="1,2,8", help="pulses a call (default 1,2,8)")
    ap.add_argument("--calls", type=int, default=400, help="calls a round (default 400)")
    ap.add_argument("--rounds", type=int, default=3, help="alternated rounds (default 3)")
    ap.add_argument(
        "--device",
        action="append",
        help="an OpenCL device (a part of its name, or its index in `rtsar devices`); "
        "repeat for several (default: the default device)",
    )
    args = ap.parse_args(argv)
    try:
        sizes = [int(s) for s in args.sizes.split(",")]
    except ValueError:
        sizes = []
    if not sizes or min(sizes) < 1 or args.calls < 1 or args.rounds < 1:
        print(
            "lens_beside_load: --sizes takes whole numbers >= 1 (e.g. 1,2,8); --calls and "
            "--rounds must be >= 1",
            file=sys.stderr,
        )
        return 2
    rows = measure(args.preset, sizes, args.calls, args.rounds, args.device or [None])
    print_rows(args.preset, rows)
    return 0
