"""``rtsar devices``: every OpenCL device the loader sees, its probe result and lens throughput.

Each device is probed in a child process of its own (:func:`rtsar.lens.cl_devices.measure`):
the lens kernel of the preset built, 8 pulses compared with the float64 reference; then the
devices that pass and the NumPy lens of the same plan are timed together, interleaved, at each
batch size.  Measured on ``psaltis-max`` at batch 64 (the defaults), the result also becomes the
survey the default device is chosen from.
"""

from __future__ import annotations

import json
import sys

from ..lens.cache import cache_dir, write_json
from ..lens.numpy_lens import NumpyLens
from ..lens.plan import make_plan
from ..presets import PRESETS, preset
from ..sinks.io import check_writable


def add_arguments(s) -> None:
    s.add_argument(
        "--preset",
        default="psaltis-max",
        choices=sorted(PRESETS),
        help="whose lens plan is built and timed (default: psaltis-max, the survey's)",
    )
    s.add_argument(
        "--batches",
        default="16,64,256",
        help="pulses per launch to time, comma-separated (default: 16,64,256)",
    )
    s.add_argument(
        "--seconds", type=float, default=0.3, help="timing per device and batch (default 0.3)"
    )
    s.add_argument("--json", metavar="F", help="also write the table as JSON to F")


def _batches(text: str) -> list[int]:
    try:
        values = [int(v) for v in text.split(",") if v.strip()]
    except ValueError:
        values = []
    if not values or min(values) < 1 or max(values) > 65536:
        raise ValueError(f"--batches needs whole numbers of pulses 1..65536, got {text!r}")
    return values


def run(args) -> int:
    batches = _batches(args.batches)
    if not 0 < args.seconds <= 60:
        raise ValueError(f"--seconds must be in (0, 60], got {args.seconds}")
    if args.json:
        check_writable(args.json)
    try:
        from ..lens import cl_devices, cl_vendors
        from ..lens.cl_probe import throughput
    except ImportError as exc:
        print(f"rtsar devices: pyopencl cannot be imported ({exc})", file=sys.stderr)
        return 1
    out = sys.stdout
    print(
        f"rtsar devices: every OpenCL device, probed in its own process with the lens of "
        f"{args.preset} (lines against the float64 reference, refused beyond "
        f"{cl_devices.TOLERANCE:g} of the peak); pulses/s at batch {', '.join(map(str, batches))}",
        file=out,
    )
    reg = cl_vendors.registration()
    if reg is not None:
        print(f"drivers installed with pip: {reg.note}", file=out)
    replaces = args.preset == cl_devices.SURVEY_PRESET  # the survey later runs choose from
    kept = cl_devices.default_device()[0] if replaces and cl_devices.survey_is_known() else None
    try:
        reports, numpy_rates = cl_devices.measure(
            args.preset, batches, args.seconds, say=lambda m: print(m + " …", file=out, flush=True)
        )
    except RuntimeError as exc:  # no platform at all
        print(f"rtsar devices: {exc}", file=out)
        reports, numpy_rates = [], {}
    if not numpy_rates:  # no device was timed: the NumPy lens alone, here
        numpy_lens = NumpyLens(make_plan(preset(args.preset)))
        numpy_rates = {str(b): throughput(numpy_lens, b, args.seconds) for b in batches}

    head = f"{'#':>2}  {'device':<58} {'type':<4} {'error':>8} " + " ".join(
        f"{b:>9}" for b in batches
    )
    print("\n" + head, file=out)
    for r in reports:
        name = r.short_label if len(r.short_label) <= 58 else r.short_label[:55] + "..."
        if r.reason is None and not r.rates:
            print(f"{r.index:>2}  {name:<58} {r.kind:<4} {r.error:>8.1e}  {r.note}", file=out)
        elif r.reason is None:
            rates = " ".join(f"{r.rates.get(str(b), 0):>9,.0f}" for b in batches)
            print(f"{r.index:>2}  {name:<58} {r.kind:<4} {r.error:>8.1e} {rates}", file=out)
        else:
            print(f"{r.index:>2}  {name:<58} {r.kind:<4}  refused: {r.reason}", file=out)
    rates = " ".join(f"{numpy_rates.get(str(b), 0):>9,.0f}" for b in batches)
    print(f"{'':>2}  {'NumPy lens (the same plan)':<58} {'CPU':<4} {'':>8} {rates}", file=out)

    best, why = (None, "no OpenCL platform") if not reports else cl_devices.default_device()
    if best is None:
        print(f"\ndefault: the NumPy lens: {why}", file=out)
    else:
        print(f"\ndefault: [{best.index}] {best.short_label}: {why}", file=out)
        print(
            "another: --device INDEX or a part of its name (also RTSAR_OPENCL_DEVICE); "
            f"the survey is kept in {cache_dir()} and measured again when devices change",
            file=out,
        )
    if reports and replaces:
        # --lens auto's per-plan timings were made against the old survey: measure them again
        write_json("lens-choice.json", {})
        if kept is not None:  # say what changes for later runs
            now = "the NumPy lens" if best is None else f"[{best.index}] {best.short_label}"
            if best is not None and best.full_label == kept.full_label:
                change = f"their default stays {now}"
            else:
                change = f"their default was [{kept.index}] {kept.short_label}, is now {now}"
            print(f"this survey replaces the one later runs chose from: {change}", file=out)
    if args.json:
        default_index = None if best is None else best.index
        doc = {
            "preset": args.preset,
            "batches": batches,
            "tolerance": cl_devices.TOLERANCE,
            "devices": [
                {**r.__dict__, "label": r.full_label, "default": r.index == default_index}
                for r in reports
            ],
            "numpy_pulses_per_s": numpy_rates,
            "default_reason": why,
        }
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(doc, f, indent=1)
    return 0 if best is not None else 1
