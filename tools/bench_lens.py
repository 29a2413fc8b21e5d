"""Throughput of the OpenCL AO lens against NumPy's FFT, measured in one run.

For each preset and batch size the same batch of random pulses is compressed by

* ``opencl``      rtsar.lens.AOLens (one kernel launch per batch, copies in and out included),
* ``numpy``       the plan with np.fft in complex64, as compress_reference does it
                  (np.fft.fft for sign -1, np.fft.ifft·nfft for sign +1), and
* ``numpy_ifft``  the same with every DFT done by np.fft.ifft (a sign -1 DFT as
                  conj(ifft(conj x))·nfft), which is faster with some NumPy builds.

Rounds of the three alternate and the best round counts, which keeps the comparison fair on a
busy machine.  Usage::

    python tools/bench_lens.py [--presets psaltis-max crouch-sal] [--batches 16 64 256]
                               [--seconds 1.0] [--device NAME] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

try:
    import rtsar  # noqa: F401
except ImportError:  # run from a source checkout without installing
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rtsar.lens import AOLens  # noqa: E402
from rtsar.lens_plan import LensPlan, compress_reference, make_plan  # noqa: E402
from rtsar.opencl import device_info  # noqa: E402
from rtsar.params import preset  # noqa: E402

DEFAULT_PRESETS = ("psaltis-max", "crouch-sal")
DEFAULT_BATCHES = (16, 64, 256)


class NumpyPlan:
    """The lens plan with NumPy's FFT in single precision (two formulations)."""

    def __init__(self, plan: LensPlan, ifft_only: bool = False):
        self.plan, self.ifft_only = plan, ifft_only
        n = plan.nfft
        self.pre = plan.pre.astype(np.complex64)
        self.idx = (plan.bin_start + np.arange(plan.bin_count)) % n
        contiguous = np.all(np.diff(self.idx) == 1)
        self.cols = slice(int(self.idx[0]), int(self.idx[0]) + plan.bin_count) if contiguous \
            else self.idx
        # scale factors of the unnormalised DFTs folded into the constants
        scale1 = n if (ifft_only or plan.sign1 > 0) else 1
        if plan.two_pass:
            self.spectrum = (plan.spectrum * scale1).astype(np.complex64)
            scale2 = n if (ifft_only or plan.sign2 > 0) else 1
            self.post = (plan.post * scale2).astype(np.complex64)
        else:
            self.spectrum = None
            self.post = (plan.post * scale1).astype(np.complex64)

    def _dft(self, y: np.ndarray, sign: int, n: int | None = None) -> np.ndarray:
        """Unnormalised up to the factor folded into the constants."""
        if sign > 0:
            return np.fft.ifft(y, n, axis=-1)
        if self.ifft_only:
            return np.conj(np.fft.ifft(np.conj(y), n, axis=-1))
        return np.fft.fft(y, n, axis=-1)

    def compress(self, shots: np.ndarray) -> np.ndarray:
        p = self.plan
        y = self._dft(shots * self.pre, p.sign1, p.nfft)
        if self.spectrum is not None:
            y *= self.spectrum
            y = self._dft(y, p.sign2)
        return y[:, self.cols] * self.post


def _best_rates(funcs: dict, pulses: int, seconds: float, rounds: int = 7) -> dict:
    """Pulses per second of each function: best of `rounds` alternating rounds.

    Each function gets about seconds / rounds per round (at least two calls).
    """
    best = dict.fromkeys(funcs, np.inf)
    slot = seconds / rounds
    for _ in range(rounds):
        for name, f in funcs.items():
            calls, t0 = 0, time.perf_counter()
            while True:
                f()
                calls += 1
                dt = time.perf_counter() - t0
                if dt >= slot and calls >= 2:
                    break
            best[name] = min(best[name], dt / calls)
    return {name: pulses / t for name, t in best.items()}


def bench(presets=DEFAULT_PRESETS, batches=DEFAULT_BATCHES, seconds=1.0, device=None) -> list:
    rows = []
    rng = np.random.default_rng(0)
    for name in presets:
        plan = make_plan(preset(name))
        lens = AOLens(plan, device=device)
        np_lens, np_alt = NumpyPlan(plan), NumpyPlan(plan, ifft_only=True)
        for b in batches:
            shots = (rng.standard_normal((b, plan.samples_per_shot))
                     + 1j * rng.standard_normal((b, plan.samples_per_shot))).astype(np.complex64)
            ref = compress_reference(plan, shots)
            funcs = {
                "opencl": lambda s=shots, f=lens.compress: f(s),
                "numpy": lambda s=shots, f=np_lens.compress: f(s),
                "numpy_ifft": lambda s=shots, f=np_alt.compress: f(s),
            }
            errors = {k: float(np.linalg.norm(f() - ref) / np.linalg.norm(ref))
                      for k, f in funcs.items()}
            rates = _best_rates(funcs, b, seconds)
            rows.append({
                "preset": name, "batch": b, "samples": plan.samples_per_shot, "nfft": plan.nfft,
                "two_pass": plan.two_pass, "bins": plan.bin_count, "kernel": lens.kernel_name,
                **{f"{k}_pulses_per_s": v for k, v in rates.items()},
                "opencl_over_numpy": rates["opencl"] / rates["numpy"],
                "opencl_over_numpy_ifft": rates["opencl"] / rates["numpy_ifft"],
                **{f"{k}_rel_rms_error": v for k, v in errors.items()},
            })
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--presets", nargs="+", default=list(DEFAULT_PRESETS))
    ap.add_argument("--batches", nargs="+", type=int, default=list(DEFAULT_BATCHES))
    ap.add_argument("--seconds", type=float, default=1.0,
                    help="measuring time per alternative and row (default 1)")
    ap.add_argument("--device", default=None, help="OpenCL device name substring")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = ap.parse_args(argv)
    rows = bench(args.presets, args.batches, args.seconds, args.device)
    info = device_info(args.device)
    if args.json:
        print(json.dumps({"device": info, "numpy": np.__version__, "rows": rows}, indent=2))
        return 0
    print(f"device: {info}\nnumpy {np.__version__}; pulses/s, best of alternating rounds\n")
    print(f"{'preset':12s} {'batch':>5s} {'opencl':>10s} {'numpy':>10s} {'np-ifft':>10s} "
          f"{'cl/numpy':>9s} {'cl/np-ifft':>10s} {'cl error':>9s}")
    for r in rows:
        print(f"{r['preset']:12s} {r['batch']:5d} {r['opencl_pulses_per_s']:10,.0f} "
              f"{r['numpy_pulses_per_s']:10,.0f} {r['numpy_ifft_pulses_per_s']:10,.0f} "
              f"{r['opencl_over_numpy']:9.2f} {r['opencl_over_numpy_ifft']:10.2f} "
              f"{r['opencl_rel_rms_error']:9.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
