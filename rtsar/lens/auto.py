"""``--lens auto``: the OpenCL lens unless the NumPy plan is clearly faster for the run.

The rule, measured rather than assumed (a CPU OpenCL driver's launch costs tens of microseconds,
so on small plans and batches NumPy's FFT can win):

1. the default OpenCL device (:func:`rtsar.lens.cl_devices.default_device`: the fastest that
   builds the lens), none → the NumPy lens, with a warning naming what to install;
2. the run's own plan timed on that device and on NumPy's FFT at its configuration's
   ``micro_batch`` (what a run falling behind uses) and at 16 or fewer (what a live run keeping
   up uses), interleaved in 3 rounds, each its best: the backend with the shorter mean time per
   pulse over these sizes runs (where each wins at one size, the banner says so), except that
   OpenCL within TIE (10 %) of NumPy's time still runs, said so: the design's AO lens is kept
   where the difference is the machine's noise.  The timings
   are cached, so one configuration gets one choice (two runs of it give the same lines bit for
   bit) even where two backends' timings are close enough to swap places between measurements.

The timings are kept in the cache folder (:mod:`rtsar.lens.cache`) per plan shape, device and
survey, so a run pays them once (about 0.4 s); where they say NumPy, later runs build no
OpenCL lens at all.  The choice and its figures are the lens's ``choice`` line, which the
run's banner prints.  A device asked for (``--device``, ``RTSAR_OPENCL_DEVICE``) is used as
asked, never replaced.
"""

from __future__ import annotations

import hashlib
import json
import os

import numpy as np

from . import cl_devices
from .cache import rates_or_none, read_json, write_json
from .cl_probe import best_rates, throughput
from .numpy_lens import NumpyLens
from .opencl import AOLens
from .plan import LensPlan

__all__ = [
    "SMALL_BATCH",
    "SURVEY_WORTH_S",
    "batch_sizes",
    "choose",
    "plan_rates",
    "survey_not_worth",
]

SMALL_BATCH = 16
_CACHE = "lens-choice.json"
_SECONDS = 0.03  # per backend, batch size and round
_ROUNDS = 3  # each backend keeps its best round
_memo: dict = {}


def batch_sizes(batch: int | None) -> tuple[int, ...]:
    """The batch sizes the choice is measured at for a run whose largest batch is ``batch``."""
    b = max(1, int(batch or 64))
    return tuple(sorted({min(SMALL_BATCH, b), b}))


def _key(plan: LensPlan, precision: str, sizes, device_label: str, survey_key: str) -> str:
    shape = [
        plan.samples_per_shot,
        plan.nfft,
        plan.bin_count,
        bool(plan.two_pass),
        precision,
        list(sizes),
        device_label,
        survey_key,  # the devices, their libraries, cores and speed settings (cl_devices)
        np.__version__,  # the NumPy lens's speed is its FFT's
    ]
    return hashlib.sha256(json.dumps(shape).encode()).hexdigest()[:24]


class _Refused(Exception):
    """The device did not build this plan's lens (the cause: the driver's error)."""


class _Deferred:
    """One device's OpenCL lens, built when first needed: where the cached figures of the plan
    say NumPy is faster, no OpenCL context is made and no kernel is built (0.05-0.25 s a run
    on this machine's three CPU drivers, 2.5 s on PoCL with its kernel cache empty)."""

    def __init__(self, plan: LensPlan, device, precision: str):
        self._args, self.built = (plan, device, precision), None

    def lens(self) -> AOLens:
        if self.built is None:
            plan, device, precision = self._args
            try:
                self.built = AOLens(plan, device=device, precision=precision)
            except (RuntimeError, ValueError) as exc:  # the survey's plan built, this not
                raise _Refused(str(exc).splitlines()[0]) from exc
        return self.built


def plan_rates(cl_lens, np_lens, sizes, key: str | None = None) -> dict:
    """``{"opencl": {b: pulses/s}, "numpy": {b: pulses/s}}`` for the two lenses (cached by key;
    ``cl_lens`` may be a deferred lens, built only to be measured)."""
    if key in _memo:  # one choice per plan in a process, even where nothing can be cached
        return _memo[key]
    cache = read_json(_CACHE) if key else {}
    hit = cache.get(key) if key else None
    if isinstance(hit, dict) and set(hit) == {"opencl", "numpy"}:
        found = {k: rates_or_none(d, sizes) for k, d in hit.items()}
        if all(v is not None for v in found.values()):
            _memo[key] = found
            return found
    if isinstance(cl_lens, _Deferred):
        cl_lens = cl_lens.lens()
    rates = best_rates({"opencl": cl_lens, "numpy": np_lens}, sizes, _SECONDS, _ROUNDS)
    if key:
        cache = read_json(_CACHE)
        if len(cache) > 200:  # plans come and go; keep the file small
            cache = {}
        cache[key] = {k: {str(b): round(v, 1) for b, v in d.items()} for k, d in rates.items()}
        write_json(_CACHE, cache)
        _memo[key] = rates
    return rates


TIE = 1.10  # OpenCL this much slower than NumPy, or less, still runs: the design's path


def _opencl_runs(rates: dict) -> bool:
    """The OpenCL lens runs where it is faster, or within TIE of NumPy's time (a difference
    the machine's noise can make either way: the AO lens of the design is then kept)."""
    return _mean_time(rates["opencl"]) <= TIE * _mean_time(rates["numpy"])


def _mean_time(rates: dict) -> float:
    return sum(1.0 / max(r, 1e-9) for r in rates.values()) / len(rates)


def _figures(rates: dict) -> str:
    return ", ".join(f"{rates[b]:,.0f}" for b in sorted(rates))


def choose(plan: LensPlan, precision: str = "complex64", batch: int | None = None, device=None):
    """The lens for ``--lens auto`` (see the module docstring).

    Returns a lens whose ``choice`` says what runs and why; ``fallback_reason`` is set (and a
    RuntimeWarning given by the caller) only where OpenCL could not run at all.  The OpenCL
    lens is built only where it runs or is measured (:class:`_Deferred`).
    """
    if device is not None or os.environ.get(cl_devices.ENV_DEVICE, "").strip():
        lens = AOLens(plan, device=device, precision=precision)  # never replaced: errors raise
        lens.choice = f"OpenCL lens on {lens.device_label} ({lens.selection_reason})"
        return lens
    try:
        best, why = cl_devices.default_device()
    except RuntimeError as exc:  # no platform at all
        best, why = None, str(exc)
    np_lens = NumpyLens(plan, precision=precision)
    sizes = batch_sizes(batch)
    if best is not None:  # the fastest device that builds this plan (double, local memory)
        devices, refused = cl_devices.list_devices(), []
        for report in cl_devices.ranked(cl_devices.survey()):
            cl_lens = _Deferred(plan, devices[report.index], precision)
            key = _key(plan, precision, sizes, report.full_label, cl_devices.survey_fingerprint())
            try:
                rates = plan_rates(cl_lens, np_lens, sizes, key)
                if _opencl_runs(rates):
                    cl_lens.lens()  # it runs: built now (where it was not to be measured)
            except _Refused as exc:
                refused.append(f"{report.short_label}: {exc}")
                continue
            if report.index != best.index:
                why = f"the fastest that builds this plan ({'; '.join(refused)})"
            return _chosen(cl_lens.built, np_lens, report, why, rates, sizes)
        why = f"no OpenCL device builds this plan ({'; '.join(refused)})"
    np_lens.fallback_reason = why
    np_lens.choice = f"NumPy lens (no OpenCL: {why})"
    return np_lens


SURVEY_WORTH_S = 2.0  # a job whose whole lens work takes NumPy less runs on it unsurveyed


def survey_not_worth(plan: LensPlan, precision: str, batch: int | None, pulses: int):
    """Why a job of ``pulses`` shots (a recording to process) runs on the NumPy lens without
    surveying the OpenCL devices first; None: choose as :func:`choose` does.

    The first OpenCL choice on a machine probes every device (a second or two each, after
    pyopencl's start: 5-10 s here for three CPU drivers).  A recording whose whole range
    compression takes NumPy under SURVEY_WORTH_S cannot win that back (the first `rtsar
    process` of 2,048 demo shots took 11.5 s, 1.6 s once the survey was cached).  Where a
    survey is known, or a device is asked for, the choice is the usual one."""
    if os.environ.get(cl_devices.ENV_DEVICE, "").strip() or cl_devices.survey_is_known():
        return None
    rate = throughput(NumpyLens(plan, precision=precision), max(1, int(batch or 64)), 0.02)
    seconds = pulses / rate
    if seconds >= SURVEY_WORTH_S:
        return None
    took = f"{seconds:.1f} s" if seconds >= 0.1 else f"{1e3 * seconds:.0f} ms"  # never "0.0 s"
    return (
        f"NumPy lens: this job's range compression takes it about {took} ({pulses:,} "
        f"shots at {rate:,.0f} pulses/s), less than the survey of the OpenCL devices that a "
        "first choice of one costs (a few seconds, once: `rtsar devices` runs it, and later "
        "runs choose from it); `--lens opencl` to use OpenCL now"
    )


def _chosen(cl_lens, np_lens, best, why: str, rates: dict, sizes):
    """The faster of the two lenses by ``rates``, its ``choice`` line set."""
    cl_us, np_us = 1e6 * _mean_time(rates["opencl"]), 1e6 * _mean_time(rates["numpy"])
    figures = (
        f"mean {{}} µs per pulse against {{}}'s {{}} µs over batch{'es' if len(sizes) > 1 else ''} "
        f"{', '.join(map(str, sizes))} (OpenCL {_figures(rates['opencl'])} pulses/s, NumPy "
        f"{_figures(rates['numpy'])}{_split(rates)})"
    )
    if cl_us <= np_us:
        cl_lens.choice = (
            f"OpenCL lens on {best.short_label} ({why}); faster for this plan: "
            + figures.format(f"{cl_us:.2f}", "NumPy", f"{np_us:.2f}")
        )
        return cl_lens
    if _opencl_runs(rates):
        cl_lens.choice = (
            f"OpenCL lens on {best.short_label} ({why}); within {100 * (TIE - 1):.0f} % of "
            "NumPy's time for this plan, so the design's AO lens runs: "
            + figures.format(f"{cl_us:.2f}", "NumPy", f"{np_us:.2f}")
            + "; `--lens numpy` for NumPy's"
        )
        return cl_lens
    np_lens.choice = (
        f"NumPy lens: faster for this plan than OpenCL on {best.short_label}: "
        + figures.format(f"{np_us:.2f}", "OpenCL", f"{cl_us:.2f}")
        + "; `--lens opencl` to use it anyway"
    )
    return np_lens


def _split(rates: dict) -> str:
    """Where the two backends each win at some batch size: which wins where."""
    cl_wins = [b for b in sorted(rates["opencl"]) if rates["opencl"][b] > rates["numpy"][b]]
    np_wins = [b for b in sorted(rates["numpy"]) if b not in cl_wins]
    if not cl_wins or not np_wins:
        return ""
    return (
        f"; OpenCL faster at batch {', '.join(map(str, cl_wins))}, NumPy at "
        f"{', '.join(map(str, np_wins))}"
    )
