"""A live run's small lens calls on SciPy's FFT (--lens hybrid, rtsar.lens.small_calls): the
route is the documented function of the measured CPU times, a routed call gives the plan's
lines (against compress_reference, which shares no code with either lens), the engine and the
granularity carry the route to the run, and the banner says it.  No verdict depends on this
machine's speed: where a route is chosen here, the times are given."""

import numpy as np
import pytest

from rtsar.app import live_granularity
from rtsar.app.live_granularity import GranularityRequest, small_calls_words
from rtsar.lens import make_plan
from rtsar.lens.base import compress_reference
from rtsar.lens.numpy_lens import NumpyLens
from rtsar.lens.small_calls import TIMED_UP_TO, SmallCallsOnCPU, cpu_limit
from rtsar.presets import preset
from rtsar.stream.engine import StreamProcessor
from rtsar.stream.granularity import StageCosts
from rtsar.stream.settings import PipelineSettings

US = 1e-6


@pytest.mark.parametrize(
    "cpu_s, limit",
    [
        # (OpenCL, SciPy) CPU seconds a call: SciPy cheaper at 1, 2 and 4, OpenCL from 8
        ({1: (400, 100), 2: (400, 150), 4: (420, 200), 8: (460, 500)}, 8),
        ({1: (100, 200), 2: (110, 300)}, 1),  # OpenCL cheaper everywhere: no route
        ({1: (400, 100), 2: (420, 180), 4: (430, 250), 8: (460, 300)}, 9),  # SciPy throughout
        # SciPy cheaper at 4 only: the least size from which OpenCL is no dearer at every
        # larger size is 8, so 1 and 2 go to SciPy's too (one limit, not a set of sizes)
        ({1: (100, 200), 2: (100, 200), 4: (400, 100), 8: (200, 300)}, 8),
        ({1: (100, 100)}, 1),  # a tie: OpenCL, the design's lens
        ({}, 1),
    ],
)
def test_the_route_is_the_documented_function_of_the_cpu_times(cpu_s, limit):
    assert cpu_limit({b: (o * US, s * US) for b, (o, s) in cpu_s.items()}) == limit


class _Counting:
    """A stand-in for the OpenCL lens: the reference's lines, each call's size recorded."""

    backend = "opencl"
    device_label = "a counting lens"
    choice = "OpenCL lens on a counting lens"

    def __init__(self, plan):
        self.plan, self.dtype, self.precision, self.calls = plan, np.complex64, "complex64", []

    def compress(self, shots, out=None):
        self.calls.append(("compress", len(shots)))
        lines = compress_reference(self.plan, shots).astype(np.complex64)
        if out is not None:
            out[...] = lines
        return lines if out is None else out

    def submit(self, shots, out=None):
        self.calls.append(("submit", len(shots)))
        lines = self.compress(shots, out)
        self.calls.pop()
        return type("Job", (), {"wait": lambda self: lines})()


def _shots(plan, pulses, seed=0):
    rng = np.random.default_rng(seed)
    shape = (pulses, plan.samples_per_shot)
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)


def _rel_rms(a, b):
    return float(np.sqrt(np.mean(np.abs(a - b) ** 2) / np.mean(np.abs(b) ** 2)))


@pytest.mark.parametrize("name", ["psaltis-jpl", "psaltis-max", "crouch-sal"])
def test_calls_under_the_limit_go_to_the_cpu_and_give_the_plan_s_lines(name):
    """Calls of fewer than ``below`` pulses never reach the wrapped lens, by compress or
    submit; the others do; every call's lines are the plan's (relative RMS 1e-5 against the
    float64 reference, the lenses' single-precision tolerance)."""
    plan = make_plan(preset(name))
    inner = _Counting(plan)
    lens = SmallCallsOnCPU(inner, NumpyLens(plan, "scipy"), 4)
    for pulses in (1, 3, 4, 9):
        shots = _shots(plan, pulses, pulses)
        reference = compress_reference(plan, shots)
        assert _rel_rms(lens.compress(shots), reference) < 1e-5
        assert _rel_rms(lens.submit(shots).wait(), reference) < 1e-5
    assert inner.calls == [("compress", 4), ("submit", 4), ("compress", 9), ("submit", 9)]
    for pulses in (2, 5):  # ``out``, as the OpenCL lens takes it, on either route
        shots = _shots(plan, pulses, 10 + pulses)
        out = np.empty((pulses, plan.bin_count), np.complex64)
        assert lens.compress(shots, out) is out and lens.submit(shots, out).wait() is out
        assert _rel_rms(out, compress_reference(plan, shots)) < 1e-5
    assert lens.backend == "opencl" and lens.device_label == "a counting lens"
    assert lens.choice.startswith("OpenCL lens on a counting lens; lens calls under 4 pulses")


def test_the_cpu_lens_must_be_the_same_plan_and_precision():
    plan = make_plan(preset("psaltis-jpl"))
    with pytest.raises(ValueError, match="same plan in the same precision"):
        SmallCallsOnCPU(_Counting(plan), NumpyLens(make_plan(preset("tiny")), "scipy"), 4)
    with pytest.raises(ValueError, match="same plan in the same precision"):
        SmallCallsOnCPU(_Counting(plan), NumpyLens(plan, "scipy", "complex128"), 4)


def test_the_opencl_lens_s_small_calls_give_the_plan_s_lines(opencl):
    """The real OpenCL lens wrapped as a live run wraps it (StreamProcessor): both routes
    within the lenses' tolerance of the reference."""
    cfg = preset("psaltis-jpl")
    engine = StreamProcessor(cfg, "opencl", live=PipelineSettings(lens_cpu_below=3))
    assert isinstance(engine.lens, SmallCallsOnCPU) and engine.lens.below == 3
    for pulses in (1, 2, 3, 16):
        shots = _shots(engine.plan, pulses, pulses)
        got = engine.compress(shots)
        assert _rel_rms(got, compress_reference(engine.plan, shots)) < 1e-5


def test_the_numpy_lens_is_never_wrapped():
    engine = StreamProcessor(preset("tiny"), "numpy", live=PipelineSettings(lens_cpu_below=8))
    assert isinstance(engine.lens, NumpyLens)


def test_the_granularity_carries_the_route_to_the_run_and_says_it(monkeypatch):
    """measure_costs' route (here given) reaches the run's settings and its banner line."""
    route = {1: (210 * US, 420 * US, 110 * US, 110 * US), 2: (200 * US, 400 * US, 180 * US,
             180 * US), 4: (200 * US, 400 * US, 420 * US, 420 * US)}  # fmt: skip
    blocks = (1, 2, 4, 8)
    costs = StageCosts(
        lens_s={b: (100 + 5 * b) * US for b in blocks},
        block_s={b: (100 + 10 * b) * US for b in blocks},
        strip_s=100 * US,
        lens_cpu_below=cpu_limit({b: (c[1], c[3]) for b, c in route.items()}),
        lens_route_s=route,
    )
    monkeypatch.setattr(live_granularity, "measure_costs", lambda *a, **k: costs)
    cfg = preset("psaltis-jpl")
    _, settings, _, words = GranularityRequest(1600.0).apply(cfg, PipelineSettings())
    assert settings.lens_cpu_below == 4
    said = small_calls_words(costs)
    assert said in words
    # the largest size routed, its figures: 2 pulses, 180 µs (180 of CPU) against 200 (400)
    assert "2 pulses take it 180 µs (180 µs of CPU), the OpenCL lens 200 µs (400 µs" in said


class _Stub:
    """An OpenCL-like lens (backend "opencl") that gives zeros: what make_lens returned."""

    backend, precision, dtype = "opencl", "complex64", np.complex64

    def __init__(self, plan):
        self.plan = plan

    def compress(self, shots, out=None):
        return np.zeros((len(shots), self.plan.bin_count), np.complex64)


@pytest.mark.parametrize(
    "backend, copies, timed_route",
    [
        ("hybrid", 1, True),
        ("auto", 1, False),
        ("opencl", 1, False),
        ("numpy", 1, False),
        ("hybrid", 2, False),
    ],
)
def test_only_a_hybrid_lens_of_one_receiver_is_timed_for_the_route(
    monkeypatch, backend, copies, timed_route
):
    """--lens hybrid that chose OpenCL is timed both ways; auto (the default: the design's
    OpenCL lens for every call), opencl and numpy run as asked, and with --height (copies > 1:
    the receivers' engines keep their own lenses) no route is chosen."""
    timed = []

    def route(lens, sizes, noise):
        timed.append(sizes)
        return lens, {1: (1e-4, 2e-4, 5e-5, 5e-5)}

    plan = make_plan(preset("tiny"))
    monkeypatch.setattr(live_granularity, "make_lens", lambda *a, **k: _Stub(plan))
    monkeypatch.setattr(live_granularity, "small_calls_route", route)
    monkeypatch.setattr(live_granularity, "path_costs_s", lambda *a, **k: (1e-4,) * 4)
    cfg = preset("tiny").with_processor(correlator="nonuniform")
    settings = PipelineSettings(lens_backend=backend)
    costs = live_granularity.measure_costs(cfg, settings, 500.0, [1, 2], copies)
    assert bool(timed) == timed_route
    assert bool(costs.lens_route_s) == timed_route


def test_swath_workers_keep_their_lenses(monkeypatch):
    """A run whose workers compress (--swath-workers) gets no route: its coordinator's lens
    never runs a call."""
    costs = StageCosts({1: 1e-4}, {1: 1e-4}, 1e-4, lens_cpu_below=4, lens_route_s={1: (1,) * 4})
    monkeypatch.setattr(live_granularity, "measure_costs", lambda *a, **k: costs)
    cfg = preset("psaltis-jpl").with_processor(correlator="nonuniform")
    _, settings, _, _ = GranularityRequest(1600.0, 1).apply(cfg, PipelineSettings(swath_workers=2))
    assert settings.lens_cpu_below == 0


def test_the_sizes_timed_are_the_candidate_calls_up_to_the_cap(monkeypatch):
    """Each candidate block up to TIMED_UP_TO pulses (and 1) is timed both ways, no other."""
    seen = []

    class Lens:
        backend, precision = "opencl", "complex64"

        def __init__(self):
            self.plan = make_plan(preset("tiny"))

    def route(lens, sizes, noise):
        seen.extend(sizes)
        return lens, {}

    monkeypatch.setattr(live_granularity, "make_lens", lambda *a, **k: Lens())
    monkeypatch.setattr(live_granularity, "small_calls_route", route)
    monkeypatch.setattr(live_granularity, "path_costs_s", lambda *a, **k: (1e-4,) * 4)
    cfg = preset("tiny").with_processor(correlator="nonuniform")
    settings = PipelineSettings(lens_backend="hybrid")
    live_granularity.measure_costs(cfg, settings, 500.0, [2, 4, 8, 16, 32])
    assert seen == sorted({1, 2, 4, 8, min(16, TIMED_UP_TO), min(32, TIMED_UP_TO)})
