"""Small lens calls on the CPU's FFT (``--lens hybrid``): a live run's calls of a few pulses,
where the OpenCL lens takes more of the machine than the plan on SciPy's FFT in the calling
thread (issue 38).  Not the default: the design's lens is the OpenCL one, and a run of small
blocks would then run none of its calls on it (psaltis-jpl at its PRF: blocks of 1-2 pulses,
every call on SciPy's FFT).

A CPU OpenCL driver runs a call on its worker threads and the calling thread together, and its
workers then wait for the next launch spinning: every call holds both cores of a 2-core machine
for its whole time.  Intel's runtime on the 2-core Zen 3 development machine (calls back to
back, 2026-11-29), µs a call, wall / CPU of all threads:

=========================  =============  ============  =============  ============
plan, pulses a call        OpenCL 1       SciPy 1       OpenCL 4       SciPy 4
=========================  =============  ============  =============  ============
psaltis-max (nfft 2048)    209 / 425      114 / 114     210 / 419      194 / 194
psaltis-jpl (nfft 512)     62 / 122       34 / 34       77 / 154       91 / 91
=========================  =============  ============  =============  ============

and in a run at psaltis-jpl's 2,400 pulses/s, calls of 2, the runtime's worker used 3.4-3.7 s
of CPU in 6-7 s, where the kernels' work is a few tenths of a second: what the correlator's
tail, the strips and the source then could not use.  Where the live run's granularity is
chosen (rtsar.app.live_granularity), both lenses are timed at each candidate call size up to
TIMED_UP_TO (8) pulses, and calls of fewer than ``below`` pulses run on the CPU
(``cpu_limit``: where SciPy's FFT takes less CPU); larger calls (larger blocks, a run that
fell behind) go to the OpenCL lens, as ``--lens auto`` would choose it.

The two agree to the lenses' single-precision error (about 1e-7 relative RMS, each against
compress_reference), not bit for bit: a live run's lines then depend on which calls were small.
"""

from __future__ import annotations

import time

import numpy as np

from .numpy_lens import NumpyLens

# The call sizes timed both ways: the candidate blocks up to this many pulses.  Beyond it the
# CPU's wall time grows past the OpenCL lens's (psaltis-max: 16 pulses 516 against 253 µs, for
# the same CPU): the call's own latency, not the machine's share, then counts.
TIMED_UP_TO = 8


class _Done:
    """A call already computed (the ``submit`` of a small call): ``wait()`` gives its lines."""

    __slots__ = ("_lines",)

    def __init__(self, lines: np.ndarray):
        self._lines = lines

    def wait(self) -> np.ndarray:
        return self._lines


class SmallCallsOnCPU:
    """``lens`` (the OpenCL lens) with its calls of fewer than ``below`` pulses computed by
    ``cpu`` (a NumpyLens on SciPy's FFT of the same plan and precision) in the calling thread.

    Everything else is the wrapped lens's: ``backend``, ``device_label``, ``choice`` (with the
    route added), ``plan``, ``dtype``.
    """

    def __init__(self, lens, cpu: NumpyLens, below: int):
        if cpu.plan is not lens.plan or cpu.dtype != lens.dtype:
            raise ValueError("the CPU lens must evaluate the same plan in the same precision")
        self.lens, self.cpu, self.below = lens, cpu, int(below)
        self.plan, self.dtype, self.backend = lens.plan, lens.dtype, lens.backend
        self.choice = f"{getattr(lens, 'choice', None) or lens.backend}; {route_words(self.below)}"

    def __getattr__(self, name):  # what the wrapped lens has and this one does not
        return getattr(self.lens, name)

    def compress(self, shots: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """As the OpenCL lens's ``compress`` (``out``: the array to write the lines into)."""
        if len(shots) >= self.below:
            return self.lens.compress(shots, out)
        lines = self.cpu.compress(shots)
        if out is None:
            return lines
        out[...] = lines  # the shape checked as numpy assigns
        return out

    __call__ = compress

    def submit(self, shots: np.ndarray, out: np.ndarray | None = None):
        """As the OpenCL lens's ``submit``; a small call is computed now (``wait()`` returns)."""
        if len(shots) >= self.below:
            return self.lens.submit(shots, out)
        return _Done(self.compress(shots, out))


def route_words(below: int) -> str:
    """The route, for the lens's choice line and the banner."""
    return f"lens calls under {below} pulses on SciPy's FFT in the calling thread"


def cpu_limit(cpu_s: dict[int, tuple[float, float]]) -> int:
    """The call size from which the OpenCL lens runs: ``cpu_s`` maps pulses a call to (CPU
    seconds of all threads on the OpenCL lens, on SciPy's FFT); calls of fewer pulses than the
    returned size go to SciPy's.  It is the least size measured from which OpenCL takes no more
    at it and at every larger size measured (1: OpenCL for every call); where SciPy's takes
    less at the largest size measured too, one more than that size (larger calls: OpenCL, the
    design's path, as ``--lens auto`` chose it at its own batch sizes)."""
    sizes = sorted(cpu_s)
    limit = sizes[-1] + 1 if sizes else 1
    for b in reversed(sizes):
        opencl, scipy = cpu_s[b]
        if opencl > scipy:
            break
        limit = b
    return limit


def call_cost_s(lens, shots: np.ndarray, round_s: float = 0.01, rounds: int = 3):
    """(wall seconds a call, CPU seconds of all the process's threads a call) of
    ``lens.compress(shots)``, calls back to back: each the median of ``rounds`` rounds of at
    least ``round_s`` and 5 calls, after 3 calls that warm it."""
    for _ in range(3):
        lens.compress(shots)
    walls, cpus = [], []
    for _ in range(rounds):
        calls, w0, c0 = 0, time.perf_counter(), time.process_time()
        while calls < 5 or time.perf_counter() - w0 < round_s:
            lens.compress(shots)
            calls += 1
        walls.append((time.perf_counter() - w0) / calls)
        cpus.append((time.process_time() - c0) / calls)
    return float(np.median(walls)), float(np.median(cpus))
