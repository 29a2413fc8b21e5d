"""A first run (issue 37, item 2): what numba compiles, which lens is built, what the ETA reads.

numba compiles every kernel on first use (``cache=True`` keeps it for later runs): a command
must compile only the kernels it runs, each once, and no code that formats error messages; the
OpenCL lens is built only where it runs or is measured; and a progress line's ETA never
extrapolates from a first batch that held a compilation (a fake clock stands for the time).
"""

import importlib
import io
import json
import os
import subprocess
import sys
from types import SimpleNamespace

import numba
import numpy as np
import pytest

from rtsar.analysis import relative_rms
from rtsar.app import progress
from rtsar.app.cli import main
from rtsar.ccd import correlate_reference
from rtsar.ccd import partitioned as part
from rtsar.lens.cache import cache_dir
from rtsar.scene import tones

SCENE = """
preset = "tiny"
seed = 4
pulses = {pulses}
[processor]
correlator = "partitioned"
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
"""

# Runs an rtsar command in a fresh interpreter with an empty numba cache and prints what numba
# compiled (function, argument types), in order, as JSON on the last line.
COMPILES = """
import json, sys
from numba.core import event

compiled = []

class Listener(event.Listener):
    def on_start(self, ev):
        pass

    def on_end(self, ev):
        f = ev.data["dispatcher"].py_func
        compiled.append([f"{f.__module__}.{f.__qualname__}", str(ev.data["args"])])

event.register("numba:compile", Listener())
from rtsar.app.cli import main
status = main(sys.argv[1:])
print(json.dumps([status, compiled]))
"""


def compiled_by(args, tmp_path):
    """(exit status, [(function, argument types) numba compiled]) of ``rtsar ARGS`` run cold."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    env["RTSAR_CACHE_DIR"] = str(tmp_path / "rtsar-cache")
    done = subprocess.run(
        [sys.executable, "-c", COMPILES, *args],
        capture_output=True, text=True, env=env, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    status, compiled = json.loads(done.stdout.splitlines()[-1])
    return status, [tuple(c) for c in compiled]


def test_process_compiles_each_kernel_it_runs_once_and_nothing_else(tmp_path):
    """Before: the partitioned correlator's delay-line copy (a slice assignment) compiled
    numba's shape-mismatch message, its str() of integers and string concatenation (37
    compiles of numba's own code, half of the kernel's time), and its two threaded kernels
    compiled the parfor machinery for a CCD one thread handles in a millisecond a block."""
    (tmp_path / "s.toml").write_text(SCENE.format(pulses=96))
    rec = tmp_path / "rec.h5"
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(rec)]) == 0
    status, compiled = compiled_by(
        ["process", str(rec), "-o", str(tmp_path / "img.h5"), "--lens", "numpy"], tmp_path
    )
    assert status == 0
    names = sorted(name for name, _ in compiled)
    kernels = ["_enter_and_correlate", "_gather_lines"]  # (_enter_group, _mac_group inlined)
    assert names == [f"rtsar.ccd.partitioned.{k}" for k in kernels]
    # complex64 C arrays, none read-only (one specialisation serves every push)
    assert all(
        "complex64" in t and "'A'" not in t and "True, aligned" not in t for _, t in compiled
    )


def test_simulate_compiles_the_tone_kernels_once_before_the_first_shot(tmp_path):
    (tmp_path / "s.toml").write_text(SCENE.format(pulses=40))
    status, compiled = compiled_by(
        ["simulate", str(tmp_path / "s.toml"), "-o", str(tmp_path / "rec.h5")], tmp_path
    )
    assert status == 0
    ours = sorted(name for name, _ in compiled if name.startswith("rtsar."))
    assert ours == [f"rtsar.scene.tones.{k}" for k in ("_phasor", "_pulsed_tones", "_tone_sum")]
    # numba's own helpers for max() and min() of two integers, nothing that formats a message
    assert all(name.startswith(("rtsar.", "numba.cpython.builtins.ol_m")) for name, _ in compiled)


def test_the_tone_kernels_have_one_specialisation_whatever_the_callers_scalars():
    """Integers, float32 and read-only arrays from a caller are cast at the boundary: before,
    an integer sample rate compiled a second _pulsed_tones."""
    q = tones.quadratic_phasor(64, 1e-3)
    r = np.array([2000.0, 2000.5])
    r.flags.writeable = False
    k, lam = np.float32(1e11), np.float32(0.03)
    a = tones.pulsed_returns(64, r, np.ones(2), 1.3e-5, 5e6, float(k), 4e-6, float(lam), 3e8, q)
    b = tones.pulsed_returns(
        np.int64(64), [2000.0, 2000.5], [1, 1], 1.3e-5, 5_000_000, k, 4e-6, lam, 300_000_000, q
    )
    assert len(tones._pulsed_tones.signatures) == 1
    assert len(tones._tone_sum.signatures) == 1
    assert np.array_equal(a, b) and np.abs(a).max() > 0
    # no tones: the kernel still runs (so Simulator.prepare compiles the FMCW path too)
    assert not tones.tone_sum(8, [], [], [], [], []).any()
    assert len(tones._tone_sum.signatures) == 1


@pytest.mark.parametrize("bins, threaded", [(320, False), (1200, True)])
def test_the_partitioned_correlator_shares_its_groups_among_threads_only_on_large_plans(
    bins, threaded
):
    """psaltis-jpl (512 x 320: 0.33 M multiply-adds a block) runs on one thread, psaltis-max
    (512 x 1200: 1.2 M) on numba's threads."""
    mask = np.full((512, bins), 1e-3, np.complex64)
    corr = part.PartitionedCorrelator(mask, 16)
    assert corr.threaded is threaded
    kernel = part._enter_and_correlate_threads if threaded else part._enter_and_correlate
    assert corr._kernel is kernel


def test_the_threaded_partitioned_kernel_gives_the_one_threads_lines(monkeypatch):
    rng = np.random.default_rng(11)
    n, bins = 64, 37
    mask = ((rng.standard_normal((n, bins)) + 1j * rng.standard_normal((n, bins))) / n).astype(
        np.complex64
    )
    lines = (rng.standard_normal((300, bins)) + 1j * rng.standard_normal((300, bins))).astype(
        np.complex64
    )
    one = part.PartitionedCorrelator(mask, 8)
    monkeypatch.setattr(part, "PARALLEL_MACS", 0)
    threads = part.PartitionedCorrelator(mask, 8)
    assert not one.threaded and threads.threaded
    got = [
        np.concatenate([c.push(lines[:123]), c.push(lines[123:]), c.flush()])
        for c in (one, threads)
    ]
    assert np.array_equal(got[0], got[1])  # the same sums in the same order, group by group
    assert relative_rms(got[1], correlate_reference(lines, mask)) < 1e-5


def test_resample_has_one_specialisation_whatever_the_samples_type():
    """complex64 shots (HCN alignment), complex128 spectra (polar format) and a read-only index
    run one compiled kernel: before, each compiled its own."""
    rs = importlib.import_module("rtsar.focus.resample")
    rng = np.random.default_rng(3)
    x = rng.standard_normal((3, 40)) + 1j * rng.standard_normal((3, 40))
    u = np.sort(rng.uniform(0, 39, (3, 25)), axis=1)
    u.flags.writeable = False
    single = x.astype(np.complex64)
    a, _ = rs.resample(single, u)
    b, _ = rs.resample(single.astype(np.complex128), u)
    c, _ = rs.resample(x, np.array(u))
    assert np.array_equal(a, b) and relative_rms(a, c) < 1e-6
    assert len(rs._resample_rows.signatures) == 1


@pytest.mark.slow
def test_the_nonuniform_tiles_call_their_block_kernel_with_one_index_type(monkeypatch):
    """run_blocks compiled afresh (not from numba's cache) compiles _block once, for an int64
    tile index: when it was a parallel kernel, its prange index compiled _block a second time
    as uint64, 3-13 s each on a first run here."""
    from rtsar.ccd import nonuniform, tiled

    fresh = numba.njit(nogil=True)(tiled.run_blocks.py_func)
    monkeypatch.setattr(tiled, "run_blocks", fresh)
    rng = np.random.default_rng(5)
    mask = (rng.standard_normal((64, 40)) + 1j * rng.standard_normal((64, 40))).astype(np.complex64)
    lines = (rng.standard_normal((200, 40)) + 1j * rng.standard_normal((200, 40))).astype(
        np.complex64
    )
    corr = nonuniform.NonUniformCorrelator(mask, 8, 32)
    got = np.concatenate([corr.push(lines), corr.flush()])
    corr.close()
    assert fresh.signatures  # compiled here, with _block
    assert [str(sig[0]) for sig in tiled._block.signatures] == ["int64"]
    assert relative_rms(got, correlate_reference(lines, mask)) < 1e-5


class FakeClock:
    def __init__(self):
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def first_eta_s(text: str) -> float:
    line = next(x for x in text.splitlines() if "eta" in x)
    return float(line.split("eta")[1].split()[0])


def on_a_fake_clock(monkeypatch, total: int):
    """(clock, Progress of ``total`` pulses named "x", its output) with time on ``clock``."""
    clock = FakeClock()
    monkeypatch.setattr(progress, "time", SimpleNamespace(perf_counter=clock))
    out = io.StringIO()
    return clock, progress.Progress(total, "x", stream=out), out


def test_the_first_progress_line_does_not_extrapolate_a_first_batch(monkeypatch):
    """A first batch of 100 s (a compilation), then 1 s a batch of 100: 8 batches remain at the
    first line, so its ETA is 8 s (before: 900 s, from the first batch)."""
    clock, prog, out = on_a_fake_clock(monkeypatch, 1000)
    clock.t += 100.0
    prog.update(100)
    for k in range(2, 11):
        clock.t += 1.0
        prog.update(100 * k)
    prog.done(1000)
    assert first_eta_s(out.getvalue()) == pytest.approx(8.0)
    assert out.getvalue().splitlines()[0].startswith("x: 200/1000 pulses ( 20.0 %), 100 pulses/s")
    assert out.getvalue().splitlines()[-1].startswith("x: 1000/1000 pulses (100.0 %), 100 pul")
    assert len(out.getvalue().splitlines()) == 3  # every 5 s of the clock, and the last once


def test_one_batch_gives_one_line_with_the_whole_runs_rate(monkeypatch):
    clock, prog, out = on_a_fake_clock(monkeypatch, 64)
    clock.t += 2.0
    prog.update(64)
    prog.done(64)
    assert out.getvalue() == "x: 64/64 pulses (100.0 %), 32 pulses/s, eta   0.0 s \n"


def test_simulate_compiles_before_its_progress_clock_starts(monkeypatch, tmp_path, capsys):
    """The simulator's kernels compile (100 s of the fake clock) in Simulator.prepare, before
    the first batch; each batch of 16 shots then takes 1 s: the first line's ETA is what is
    left at 1 s a batch, and a line says the compilation happened once."""
    import rtsar.scene
    from rtsar.app.cli.files import simulate_to
    from rtsar.scene import Simulator, load_scene

    clock = FakeClock()
    monkeypatch.setattr(progress, "time", SimpleNamespace(perf_counter=clock))
    kernels = {"compiled": False}

    def compile_once():
        if not kernels["compiled"]:
            clock.t += 100.0
            kernels["compiled"] = True

    class Compiling(Simulator):
        def prepare(self):
            compile_once()
            super().prepare()

        def shots(self, count=None):
            compile_once()
            clock.t += 1.0
            yield from super().shots(count)

    monkeypatch.setattr(rtsar.scene, "Simulator", Compiling)
    monkeypatch.setattr(tones, "kernels_compiled", lambda: 3, raising=False)
    (tmp_path / "s.toml").write_text(SCENE.format(pulses=160))  # 10 batches of 16
    simulate_to(load_scene(tmp_path / "s.toml"), tmp_path / "rec.h5")
    err = capsys.readouterr().err
    assert "simulate: numba compiled the simulator's kernels in" in err
    assert err.index("numba compiled") < err.index("simulate: 32/160")
    assert first_eta_s(err) == pytest.approx(8.0)  # 8 batches left at 1 s


# --------------------------------------------------------------------------------------------
# --lens auto: no OpenCL lens built where the cached figures say NumPy
# --------------------------------------------------------------------------------------------


@pytest.fixture
def one_fake_device(monkeypatch, tmp_path):
    """One OpenCL device as the survey saw it, an AOLens that counts its builds, the lens
    cache in tmp_path and measurements that return ``measured['rates']``."""
    from rtsar.lens import auto, cl_devices
    from rtsar.lens.cl_probe import DeviceReport

    report = DeviceReport(0, "Fake CL", "OpenCL 3.0 Fake", "cpu", "1.0", "CPU", rates={"64": 1e5})
    monkeypatch.setattr(cl_devices, "default_device", lambda say=None: (report, "the only one"))
    monkeypatch.setattr(cl_devices, "list_devices", lambda: ["device 0"])
    monkeypatch.setattr(cl_devices, "survey", lambda say=None: [report])
    monkeypatch.setattr(cl_devices, "survey_fingerprint", lambda: "fingerprint")
    monkeypatch.delenv(cl_devices.ENV_DEVICE, raising=False)
    monkeypatch.setenv("RTSAR_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(auto, "_memo", {})
    built, measured = [], {"calls": 0}

    class CountedLens:
        backend = "opencl"

        def __init__(self, plan, device=None, precision="complex64"):
            built.append(device)

    def best_rates(lenses, sizes, seconds, rounds):
        measured["calls"] += 1
        assert isinstance(lenses["opencl"], CountedLens)  # built to be measured
        return measured["rates"]

    monkeypatch.setattr(auto, "AOLens", CountedLens)
    monkeypatch.setattr(auto, "best_rates", best_rates)
    return SimpleNamespace(auto=auto, report=report, built=built, measured=measured)


def cache_rates(fake, plan, opencl, numpy):
    sizes = fake.auto.batch_sizes(64)
    key = fake.auto._key(plan, "complex64", sizes, fake.report.full_label, "fingerprint")
    entry = {
        "opencl": dict.fromkeys(map(str, sizes), opencl),
        "numpy": dict.fromkeys(map(str, sizes), numpy),
    }
    (cache_dir() / "lens-choice.json").write_text(json.dumps({key: entry}))


def test_a_cached_numpy_choice_builds_no_opencl_lens(one_fake_device):
    from rtsar.lens import make_plan
    from rtsar.presets import preset

    fake, plan = one_fake_device, make_plan(preset("tiny"))
    cache_rates(fake, plan, opencl=1e4, numpy=3e4)
    lens = fake.auto.choose(plan, batch=64)
    assert lens.backend == "numpy" and lens.fallback_reason is None
    assert lens.choice.startswith("NumPy lens: faster for this plan than OpenCL on Fake CL 1.0")
    assert fake.built == [] and fake.measured["calls"] == 0


def test_a_cached_opencl_choice_builds_the_lens_once(one_fake_device):
    from rtsar.lens import make_plan
    from rtsar.presets import preset

    fake, plan = one_fake_device, make_plan(preset("tiny"))
    cache_rates(fake, plan, opencl=3e4, numpy=1e4)
    lens = fake.auto.choose(plan, batch=64)
    assert lens.backend == "opencl" and lens.choice.startswith("OpenCL lens on Fake CL 1.0")
    assert fake.built == ["device 0"] and fake.measured["calls"] == 0


def test_without_cached_figures_the_lens_is_built_and_measured(one_fake_device):
    from rtsar.lens import make_plan
    from rtsar.presets import preset

    fake, plan = one_fake_device, make_plan(preset("tiny"))
    sizes = fake.auto.batch_sizes(64)
    fake.measured["rates"] = {
        "opencl": dict.fromkeys(sizes, 1e4),
        "numpy": dict.fromkeys(sizes, 3e4),
    }
    lens = fake.auto.choose(plan, batch=64)
    assert lens.backend == "numpy" and fake.built == ["device 0"]
    assert fake.measured["calls"] == 1
