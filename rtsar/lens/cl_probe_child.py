"""The child process of :mod:`rtsar.lens.cl_probe`: probes or times OpenCL devices, here.

``python -m rtsar.lens.cl_probe_child probe INDEX IDENTITY PRESET``: build the lens of PRESET
on device INDEX (refused if its identity is not IDENTITY) and check 8 pulses against the
float64 reference; ``… time INDICES PRESET BATCHES SECONDS``: time those devices and the NumPy
lens of the same plan, interleaved.  The answer is one JSON line on stdout; a driver's crash
ends only this process.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import asdict

import numpy as np

from ..presets import preset
from .base import compress_reference
from .cl_probe import (
    SURVEY_PRESET,
    TOLERANCE,
    DeviceReport,
    best_rates,
    describe,
    first_line,
    identity,
    list_devices,
)
from .numpy_lens import NumpyLens
from .opencl import AOLens
from .plan import make_plan

_ROUNDS = 3


def _plan(preset_name: str):
    return make_plan(preset(preset_name))


def probe_here(index: int, preset_name: str = SURVEY_PRESET) -> DeviceReport:
    """Build the lens of ``preset_name`` on device ``index`` and check 8 pulses, here."""
    device = list_devices()[index]
    report = describe(index, device)
    plan = _plan(preset_name)
    rng = np.random.default_rng(2024)
    S = plan.samples_per_shot
    try:
        t0 = time.perf_counter()
        lens = AOLens(plan, device=device)
        x = (rng.standard_normal((8, S)) + 1j * rng.standard_normal((8, S))).astype(np.complex64)
        y = lens.compress(x)
        report.build_s = round(time.perf_counter() - t0, 3)
        ref = compress_reference(plan, x)
        report.error = float(np.max(np.abs(y - ref)) / np.max(np.abs(ref)))
        if not np.isfinite(report.error) or report.error > TOLERANCE:
            report.reason = (
                f"wrong lines: {report.error:.1e} of the peak from the float64 reference "
                f"(tolerance {TOLERANCE:g})"
            )
    except Exception as exc:  # any driver failure is this device's reason, not ours
        report.reason = first_line(exc)
    return report


def time_here(indices, preset_name: str, batches, seconds: float) -> dict:
    """``{index or "numpy": {batch: pulses/s}}``: the devices and the NumPy lens of the same
    plan, interleaved for ``_ROUNDS`` rounds of ``seconds / _ROUNDS``, each its best round."""
    devices = list_devices()
    plan = _plan(preset_name)
    lenses = {str(i): AOLens(plan, device=devices[i]) for i in indices}
    lenses["numpy"] = NumpyLens(plan)
    best = best_rates(lenses, batches, seconds / _ROUNDS, _ROUNDS)
    return {name: {str(b): round(r, 1) for b, r in d.items()} for name, d in best.items()}


def _main(argv: list[str]) -> int:
    """Child-process entry: ``probe INDEX IDENTITY PRESET`` or ``time INDICES PRESET BATCHES
    SECONDS``; the answer is one JSON line on stdout."""
    if argv[:1] == ["probe"]:
        index, expected, preset_name = int(argv[1]), json.loads(argv[2]), argv[3]
        devices = list_devices()
        if index >= len(devices) or identity(describe(index, devices[index])) != expected:
            sys.stderr.write("the device list changed during the probe\n")
            return 3
        _answer(asdict(probe_here(index, preset_name)))
        return 0
    if argv[:1] == ["time"]:
        indices = [int(i) for i in argv[1].split(",") if i]
        batches = [int(b) for b in argv[3].split(",")]
        _answer(time_here(indices, argv[2], batches, float(argv[4])))
        return 0
    sys.stderr.write("usage: python -m rtsar.lens.cl_probe_child probe|time …\n")
    return 2


def _answer(doc: dict) -> None:
    """The answer to the parent: one JSON line on stdout (a protocol, not a message to users)."""
    sys.stdout.write(json.dumps(doc) + "\n")
    sys.stdout.flush()


if __name__ == "__main__":
    raise SystemExit(_main(sys.argv[1:]))
