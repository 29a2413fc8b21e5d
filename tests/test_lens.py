"""The OpenCL AO lens (rtsar.lens.AOLens) against the float64 reference compress_reference."""

import math

import numpy as np
import pytest

from rtsar.lens import cl_loader  # pyopencl is a core dependency: never skipped for it
from rtsar.lens.base import compress_reference
from rtsar.lens.opencl import KERNELS, AOLens, group_layout
from rtsar.lens.plan import LensPlan, make_plan, pulsed_replica
from rtsar.params import FMCWChirp, PulsedChirp
from rtsar.presets import preset

PRESETS = ("psaltis-max", "psaltis-jpl", "crouch-sal", "zhao-insal", "tiny")
TOL = 1e-5

_lenses: dict = {}


def lens_for(name: str, kernel: str) -> AOLens:
    """One AOLens per (preset, kernel), shared by the tests of this module."""
    key = (name, kernel)
    if key not in _lenses:
        _lenses[key] = AOLens(make_plan(preset(name)), kernel=kernel)
    return _lenses[key]


def rel_rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


def noise(rng, pulses: int, samples: int) -> np.ndarray:
    return (
        rng.standard_normal((pulses, samples)) + 1j * rng.standard_normal((pulses, samples))
    ).astype(np.complex64)


def chirp_echoes(name: str, pulses: int, rng) -> np.ndarray:
    """Simulated-like shots: a few point echoes per pulse plus weak noise."""
    wf = preset(name).waveform
    S = wf.samples_per_shot
    x = np.zeros((pulses, S), np.complex128)
    for p in range(pulses):
        for _ in range(3):
            amp = rng.uniform(0.2, 1.0) * np.exp(2j * math.pi * rng.uniform())
            if isinstance(wf, PulsedChirp):
                rep = pulsed_replica(wf)
                start = int(rng.integers(0, S - rep.size + 1))
                x[p, start : start + rep.size] += amp * rep
            else:
                assert isinstance(wf, FMCWChirp)
                f = rng.uniform(-0.4, 0.4)  # beat frequency in cycles per sample
                x[p] += amp * np.exp(2j * math.pi * f * np.arange(S))
    x += 0.01 * noise(rng, pulses, S)
    return x.astype(np.complex64)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("name", PRESETS)
def test_presets_match_reference(name, kernel, opencl):
    lens = lens_for(name, kernel)
    rng = np.random.default_rng(2024)
    for pulses in (1, 7, 64):
        x = noise(rng, pulses, lens.plan.samples_per_shot)
        y = lens.compress(x)
        assert y.shape == (pulses, lens.plan.bin_count) and y.dtype == np.complex64
        assert rel_rms(y, compress_reference(lens.plan, x)) <= TOL, (name, kernel, pulses)


@pytest.mark.parametrize("kernel", KERNELS)
@pytest.mark.parametrize("name", PRESETS)
def test_chirp_echoes_match_reference(name, kernel, opencl):
    lens = lens_for(name, kernel)
    x = chirp_echoes(name, 9, np.random.default_rng(7))
    ref = compress_reference(lens.plan, x)
    y = lens.compress(x)
    assert rel_rms(y, ref) <= TOL
    np.testing.assert_array_equal(np.argmax(abs(y), axis=1), np.argmax(abs(ref), axis=1))


def synthetic_plan(S, nfft, sign1, two_pass, bin_start, bin_count, seed=0) -> LensPlan:
    rng = np.random.default_rng(seed)

    def c(n):
        return rng.standard_normal(n) + 1j * rng.standard_normal(n)

    return LensPlan(
        S,
        nfft,
        c(S),
        sign1,
        c(nfft) if two_pass else None,
        -sign1,
        bin_start,
        bin_count,
        c(bin_count),
        np.arange(bin_count, dtype=float),
    )


@pytest.mark.parametrize(
    "S, nfft, sign1, two_pass, bin_start, bin_count",
    [
        (2, 2, -1, True, 0, 2),  # a single radix-2 stage
        (13, 16, +1, True, -5, 11),  # radix 8 + 2, odd sizes, wrapping bins
        (30, 32, -1, False, 29, 7),  # radix 8 + 4, bins wrap past nfft
        (501, 512, +1, True, -300, 513),  # radix 8 only, more bins than half the line
    ],
)
@pytest.mark.parametrize("kernel", KERNELS)
def test_odd_plans(kernel, opencl, S, nfft, sign1, two_pass, bin_start, bin_count):
    plan = synthetic_plan(S, nfft, sign1, two_pass, bin_start, bin_count)
    lens = AOLens(plan, kernel=kernel)
    x = noise(np.random.default_rng(3), 11, S)
    assert rel_rms(lens.compress(x), compress_reference(plan, x)) <= TOL


@pytest.mark.parametrize(
    "S, nfft, sign1, two_pass, bin_start, bin_count",
    [
        (2, 2, -1, True, 0, 2),  # a work-group of one item
        (13, 16, +1, True, -5, 11),  # radix 8 + 2, two items, two passes
        (100, 256, -1, True, 7, 200),  # radix 8, 8, 4, two passes
        (30, 32, -1, False, 29, 7),  # radix 8 + 4
        (3000, 4096, +1, True, -900, 2500),  # radarsat1's length: 64 KiB of lines
    ],
)
@pytest.mark.parametrize("precision", ["complex64", "complex128"])
@pytest.mark.parametrize("scratch", ["local", "global"])
def test_group_kernel_with_the_line_local_or_global(
    scratch, precision, opencl, S, nfft, sign1, two_pass, bin_start, bin_count
):
    """The group kernel, the line's two buffers in local memory or in the pulse's rows of a
    global scratch buffer (before, a device whose local memory was too small refused the
    plan: NVIDIA's H200, 48 KiB, refused radarsat1's 4096 points), the buffers grown between
    calls; against the float64 reference."""
    plan = synthetic_plan(S, nfft, sign1, two_pass, bin_start, bin_count, seed=nfft)
    try:
        lens = AOLens(plan, kernel="group", scratch=scratch, precision=precision)
    except ValueError as exc:  # no double (PoCL's CPU has it: CI runs this); local memory
        short = scratch == "local" and "scratch='global' keeps the lines" in str(exc)
        assert short or ("cl_khr_fp64" in str(exc) and precision == "complex128"), exc
        return
    assert lens.scratch == scratch
    tol = TOL if precision == "complex64" else 1e-12
    rng = np.random.default_rng(5)
    for pulses in (3, 40, 1):  # grown, then smaller
        x = noise(rng, pulses, S).astype(lens.dtype)
        err = rel_rms(lens.compress(x), compress_reference(plan, x))
        assert err <= tol, (pulses, err)


def test_a_group_kernel_over_local_memory_once_built_is_built_with_global_lines(
    opencl, monkeypatch
):
    """The lines fit the device's local memory, the built kernel (with what its compiler
    keeps there) does not: built again with global lines, not failed at its first launch."""
    monkeypatch.setattr(AOLens, "_local_used", lambda self: 1 << 40)
    plan = synthetic_plan(13, 16, +1, True, -5, 11)
    lens = AOLens(plan, kernel="group")
    assert lens.scratch == "global"
    x = noise(np.random.default_rng(4), 5, 13)
    assert rel_rms(lens.compress(x), compress_reference(plan, x)) <= TOL
    assert AOLens(plan, kernel="group", scratch="local").scratch == "local"  # asked for


def test_the_group_kernel_s_lines_go_global_where_local_memory_is_too_small():
    """group_layout: 4·real_bytes·nfft bytes of local memory for the line's two buffers, else
    global; work-groups of up to 256 items and nfft/8."""
    h200 = 48 * 1024  # NVIDIA's local memory (H200, as its OpenCL driver reports it)
    assert group_layout(4096, 4, h200, 1024) == (256, "global")  # radarsat1: 64 KiB
    assert group_layout(2048, 4, h200, 1024) == (256, "local")  # psaltis-max: 32 KiB
    assert group_layout(2048, 8, h200, 1024) == (256, "global")  # in double
    assert group_layout(4096, 4, 64 * 1024, 1024) == (256, "local")  # AMD's 64 KiB
    assert group_layout(16, 4, h200, 1024) == (2, "local")
    assert group_layout(4, 4, h200, 1024) == (1, "local")
    assert group_layout(4096, 4, h200, 200) == (200, "global")
    assert group_layout(512, 4, h200, 1024, scratch="global") == (64, "global")
    with pytest.raises(ValueError, match="scratch must be"):
        group_layout(4096, 4, h200, 1024, scratch="shared")


def test_lanes_and_buffer_reuse(opencl):
    plan = make_plan(preset("tiny"))
    rng = np.random.default_rng(11)
    for lanes in (1, 2, 4, 8, "copy"):
        lens = AOLens(plan, kernel="lanes", lanes=8 if lanes == "copy" else lanes)
        if lanes == "copy":  # the path of devices that do not read host memory in place
            lens._zero_copy = False
        for pulses in (64, 3, 65, 8, 130):  # shrink, grow, exact multiple, grow again
            x = noise(rng, pulses, plan.samples_per_shot)
            assert rel_rms(lens.compress(x), compress_reference(plan, x)) <= TOL, (lanes, pulses)


def test_complex128_out_and_empty(opencl):
    lens = lens_for("tiny", "lanes")
    S, bins = lens.plan.samples_per_shot, lens.plan.bin_count
    x = noise(np.random.default_rng(5), 5, S).astype(np.complex128)
    out = np.empty((5, bins), np.complex64)
    y = lens(x, out=out)
    assert y is out
    assert rel_rms(y, compress_reference(lens.plan, x)) <= TOL
    assert lens.compress(np.zeros((0, S), np.complex64)).shape == (0, bins)
    x_strided = noise(np.random.default_rng(6), 8, 2 * S)[:, ::2]
    assert rel_rms(lens.compress(x_strided), compress_reference(lens.plan, x_strided)) <= TOL


def test_bad_input_raises(opencl):
    lens = lens_for("tiny", "lanes")
    S, bins = lens.plan.samples_per_shot, lens.plan.bin_count
    with pytest.raises(ValueError, match="shape"):
        lens.compress(np.zeros(S, np.complex64))
    with pytest.raises(ValueError, match="shape"):
        lens.compress(np.zeros((4, S + 1), np.complex64))
    with pytest.raises(ValueError, match="shape"):
        lens.compress(np.zeros((2, 4, S), np.complex64))
    with pytest.raises(ValueError, match="complex64"):
        lens.compress(np.zeros((4, S), np.float32))
    with pytest.raises(ValueError, match="out"):
        lens.compress(np.zeros((4, S), np.complex64), out=np.empty((4, bins + 1), np.complex64))
    with pytest.raises(ValueError, match="kernel"):
        AOLens(lens.plan, kernel="fastest")
    with pytest.raises(ValueError, match="lanes"):
        AOLens(lens.plan, kernel="lanes", lanes=3)


def test_kernels_found_by_loader():
    folder = cl_loader.kernels_dir()
    assert folder.joinpath("lens.cl").is_file()
    source = cl_loader.kernel_source("lens.cl")
    assert "lens_lanes" in source and "lens_group" in source
    with pytest.raises(FileNotFoundError):
        cl_loader.kernel_source("no-such-kernel.cl")


def test_program_cache_and_devices(monkeypatch, opencl):
    queue = cl_loader.default_queue()
    assert queue is cl_loader.default_queue()
    defines = {
        "NFFT": 8,
        "LOG2_NFFT": 3,
        "S": 8,
        "BIN_COUNT": 8,
        "BIN_OFFSET": 0,
        "SIGN1": -1,
        "LANES": 1,
    }
    prog = cl_loader.build_program(queue.context, "lens.cl", defines)
    assert prog is cl_loader.build_program(queue.context, "lens.cl", dict(defines))
    assert isinstance(cl_loader.device_info(), str) and cl_loader.device_info(queue)
    monkeypatch.setenv(cl_loader.ENV_DEVICE, "no-such-device-anywhere")
    with pytest.raises(RuntimeError, match="no OpenCL device matches"):
        cl_loader.select_device()
    label = queue.device.name.strip()
    assert cl_loader.select_device(label[:6]).name == queue.device.name


def test_no_platform_message(monkeypatch):
    from rtsar.lens import cl_devices, cl_probe, cl_vendors

    monkeypatch.setattr(cl_loader.cl, "get_platforms", lambda: [])
    monkeypatch.setattr(cl_probe, "_found", None)
    monkeypatch.setattr(cl_vendors, "find_pip_drivers", lambda: {})
    monkeypatch.setattr(cl_devices._platform, "machine", lambda: "x86_64")
    monkeypatch.setattr(cl_devices.sys, "platform", "linux")
    with pytest.raises(RuntimeError, match=r"no OpenCL platform.*pip install intel-opencl-rt"):
        cl_loader.select_device()


def test_launches_release_the_gil_and_match_pyopencls(opencl, monkeypatch):
    """The lens launches its kernel through ctypes, which releases the GIL (pyopencl held it
    through PoCL's 14-150 µs enqueue, stalling the pipeline's other threads); the lines are bit
    for bit those of pyopencl's launch, which stays the fallback."""
    import ctypes

    from rtsar.lens import cl_launch

    plan = make_plan(preset("psaltis-max"))
    x = noise(np.random.default_rng(5), 64, plan.samples_per_shot)
    lens = AOLens(plan, kernel="lanes")
    assert lens._enqueue is not None  # a Linux loader is found (pyopencl's own)
    # A CDLL function, not a PyDLL one: ctypes releases the GIL for the call.
    assert not cl_launch._enqueue._flags_ & ctypes._FUNCFLAG_PYTHONAPI
    real, calls = cl_launch._enqueue, []
    monkeypatch.setattr(cl_launch, "_enqueue", lambda *a: calls.append(a) or real(*a))
    got = AOLens(plan, kernel="lanes").compress(x)
    assert len(calls) == 1  # launched through cl_launch
    monkeypatch.setenv("RTSAR_CL_GIL_FREE", "Off")  # 0, false, no, off: any case
    monkeypatch.setattr(cl_launch, "_resolved", False)
    fallback = AOLens(plan, kernel="lanes")
    assert fallback._enqueue is None
    np.testing.assert_array_equal(got, fallback.compress(x))
    np.testing.assert_array_equal(lens.compress(x), got)
