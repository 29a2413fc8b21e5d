import os
import random
import socket

import numpy as np
import pytest

# Under CI=true a skip is a failure (tests/ci_rule.py): its hooks, registered for this suite.
from ci_rule import in_ci, pytest_make_collect_report, pytest_runtest_makereport  # noqa: F401


def _ephemeral_ports() -> range:
    """The ports the system gives outgoing connections (Linux's range; the usual elsewhere)."""
    try:
        low, high = map(int, open("/proc/sys/net/ipv4/ip_local_port_range").read().split())
    except (OSError, ValueError):
        low, high = 32768, 65535
    return range(low, high + 1)


def free_port(span: int = 1) -> int:
    """A loopback port, with the ``span - 1`` after it, free now and outside the ephemeral
    range.  Not ``bind(0)``'s port: that one is ephemeral, and a client that connects to it
    before its server listens (ZeroMQ retrying every 0.1 s, a serial socket:// waiting for its
    instrument) may be given that very port as its own source port and connect to itself, so
    the server's bind then fails "Address already in use" (seen once in a full run)."""
    ephemeral = _ephemeral_ports()
    rng = random.Random()
    for _ in range(1000):
        port = rng.randrange(10000, 30000)
        ports = range(port, port + span)
        if any(q in ephemeral for q in ports):
            continue
        try:
            for q in ports:
                with socket.socket() as s:
                    s.bind(("127.0.0.1", q))
        except OSError:
            continue
        return port
    raise RuntimeError("no free loopback port found outside the ephemeral range")


def _free_loopback_endpoint() -> str:
    return f"tcp://127.0.0.1:{free_port()}"


# Commands run by the tests with the default endpoint publish on a port of this session's own
# (rtsar.sinks.endpoint reads $RTSAR_ENDPOINT), not on 5555: a demo running on this machine, or
# a second test session, would make them fail with "Address already in use". Set before any
# rtsar module is imported; child processes inherit it.
def _own_cache_dir() -> None:
    """The tests' rtsar cache: a copy of the user's, in a folder of this test run.  The suite
    runs the device survey and --lens auto's choice itself, on a machine it loads: written to
    the user's cache, those figures chose the user's next lens (a PoCL survey taken beside
    four test workers made `rtsar run` leave Intel's runtime).  Read from the copy, the user's
    cached choices still spare the run a survey.  Set before workers start: they share it."""
    import atexit
    import shutil
    import tempfile

    from rtsar.lens.cache import cache_dir

    users = cache_dir()
    ours = tempfile.mkdtemp(prefix="rtsar-test-cache-")
    atexit.register(shutil.rmtree, ours, True)
    try:
        for entry in os.scandir(users):  # choices and cached scenes; no file of 64 MB or more
            if entry.is_file() and entry.stat().st_size < 64 << 20:
                shutil.copy2(entry.path, ours)
    except OSError:  # no cache yet
        pass
    os.environ["RTSAR_CACHE_DIR"] = ours


if not os.environ.get("PYTEST_XDIST_WORKER"):  # the controller, or a run without -n
    _own_cache_dir()

# Under pytest -n each worker takes its own (they inherit the controller's environment).
if os.environ.get("PYTEST_XDIST_WORKER") or "RTSAR_ENDPOINT" not in os.environ:
    os.environ["RTSAR_ENDPOINT"] = _free_loopback_endpoint()


def pytest_configure(config):
    """Under ``pytest -n`` several workers share the cores: OpenBLAS's threads, one a core in
    each, busy-wait for one another (a PGA test: 5 s alone, 44 s beside three workers, 14 s with
    one BLAS thread).  One BLAS thread a worker (rtsar's own kernels keep their threads)."""
    if getattr(config.option, "numprocesses", None):
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def pytest_collection_modifyitems(config, items):
    """Under ``pytest -n``, the tests marked slow first (a stable sort: each worker collects
    the same order), so that no worker is left with a long test at the end of the run."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        items.sort(key=lambda item: item.get_closest_marker("slow") is None)


@pytest.hookimpl(optionalhook=True)  # a hook of xdist: unknown under -p no:xdist
def pytest_xdist_make_scheduler(config, log):
    """Under ``pytest -n``, idle workers take tests queued for busy ones (xdist's worksteal).
    The default ``load`` scheduling hands each worker a quarter of the suite up front and never
    takes it back: one worker, given several long tests, ran alone for the last 110 s of a
    333 s run.  An explicit ``--dist`` on the command line is kept."""
    if any(arg.startswith("--dist") for arg in config.invocation_params.args):
        return None  # xdist's own hook chooses what was asked
    from xdist.scheduler import WorkStealingScheduling

    return WorkStealingScheduling(config, log)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_auto_num_workers(config):
    """``pytest -n auto``: three workers for two cores.  Many tests wait on a subprocess, a
    socket or a paced clock, so a worker more than the cores keeps them busy; each worker also
    collects the whole suite (about 15 s of CPU).  The whole suite on 2 quiet cores, worksteal
    scheduling, one run each: 342 s with 2 workers, 251 s with 3, 269 s with 4."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return cores + max(1, cores // 2)


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


def crandn(rng, *shape, dtype=np.complex128):
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(dtype)


def opencl_unavailable_here() -> str | None:
    """Why the OpenCL lens cannot run on this machine (None when it can), probed once."""
    from rtsar.lens import opencl_unavailable

    return opencl_unavailable()


def opencl_required() -> bool:
    """In CI (CI=true, as CI services set it) or with RTSAR_REQUIRE_OPENCL=1, the OpenCL lens
    must run: a test of it that cannot build its kernels fails instead of skipping."""
    return in_ci() or os.environ.get("RTSAR_REQUIRE_OPENCL") == "1"


def skip_or_fail_without_opencl(reason: str):
    if opencl_required():
        pytest.fail(f"OpenCL required here (CI=true or RTSAR_REQUIRE_OPENCL=1): {reason}")
    pytest.skip(f"OpenCL unavailable here: {reason}")


@pytest.fixture(scope="session")
def opencl():
    """For tests of the OpenCL kernels themselves: skipped, with the driver's reason, where no
    OpenCL device can build the lens (`rtsar devices` says why); a failure instead in CI
    (CI=true) and with RTSAR_REQUIRE_OPENCL=1, where a skipped core path is not a pass."""
    reason = opencl_unavailable_here()
    if reason is not None:
        skip_or_fail_without_opencl(reason)


def surveyed_devices() -> list:
    """Every device of the survey, each with its probe result (none without pyopencl)."""
    try:
        from rtsar.lens import cl_devices

        return cl_devices.survey()
    except (ImportError, RuntimeError):
        return []


def working_devices() -> list:
    """The survey's devices that build the lens and compute it right."""
    return [r for r in surveyed_devices() if r.reason is None]


# Why a driver may refuse the lens without a fault of rtsar's (a device refused for any other
# reason, wrong lines among them, fails tests/test_devices.py in CI).
KNOWN_DRIVER_LIMITS = ("does not know this CPU model",)


def pytest_generate_tests(metafunc):
    """``cl_device``: a test runs once on every OpenCL device that builds the lens here."""
    if "cl_device" in metafunc.fixturenames:
        found = working_devices()
        metafunc.parametrize(
            "cl_device",
            found or [None],
            ids=[f"{r.index}-{r.short_label}" for r in found] or ["no-device"],
            indirect=True,  # through the fixture below: no device skips (fails in CI)
        )


@pytest.fixture
def cl_device(request):
    if request.param is None:
        skip_or_fail_without_opencl(opencl_unavailable_here() or "no device builds the lens")
    return request.param


# The documentation blocks' outcomes (tests/test_docs.py records each in its test's report).
DOCS_OUTCOMES: list[tuple[str, str, str]] = []


def pytest_runtest_logreport(report):
    """Collect the docs blocks' outcomes from the reports: in this process, or, under
    ``pytest -n``, from the workers' reports as they reach the controller."""
    if report.when == "call":
        DOCS_OUTCOMES.extend(tuple(v) for k, v in report.user_properties if k == "docs_block")


def _page_then_line(outcome) -> tuple[str, int]:
    page, _, line = outcome[0].rpartition(":")
    return page, int(line) if line.isdigit() else 0


def pytest_terminal_summary(terminalreporter):
    """Which OpenCL device ran the lens in this test run, and every device's probe result;
    the documentation blocks run and skipped (with the reason) by tests/test_docs.py."""
    if DOCS_OUTCOMES:
        outcomes = sorted(DOCS_OUTCOMES, key=_page_then_line)
        ran = [o for o in outcomes if o[1] == "ran"]
        seconds = sum(float(o[2].split()[0]) for o in ran)
        terminalreporter.write_sep("-", "documentation blocks")
        terminalreporter.write_line(
            f"{len(ran)} ran as written ({seconds:.0f} s), "
            f"{sum(o[1] == 'skipped' for o in outcomes)} skipped, "
            f"{sum(o[1] == 'FAILED' for o in outcomes)} failed"
        )
        for where, outcome, why in outcomes:
            terminalreporter.write_line(f"  {outcome} {where}: {why}")
    try:
        from rtsar.lens import cl_devices

        best, why = cl_devices.default_device()
        reports = cl_devices.survey()
    except (ImportError, RuntimeError) as exc:
        terminalreporter.write_sep("-", "OpenCL lens")
        terminalreporter.write_line(f"no OpenCL here: {exc}")
        return
    terminalreporter.write_sep("-", "OpenCL lens")
    if best is None:
        terminalreporter.write_line(f"no OpenCL device builds the lens: {why}")
    else:
        terminalreporter.write_line(
            f"default OpenCL device (--lens opencl, and --lens auto where OpenCL is chosen): "
            f"[{best.index}] {best.short_label}: {why}"
        )
    for r in reports:
        state = "refused: " + r.reason if r.reason else f"builds, error {r.error:.1e}"
        terminalreporter.write_line(f"  [{r.index}] {r.short_label} ({r.kind}): {state}")


def fmcw_scene_with_reference(pulses: int, aperture_pulses: int, range_bins: int) -> str:
    """A small crouch-sal scene file: one point and the reference interferometer's channel
    (a recording with an auxiliary channel, for the export and batch tests)."""
    return f"""
preset = "crouch-sal"
pulses = {pulses}
seed = 2
[processor]
aperture_pulses = {aperture_pulses}
range_bins = {range_bins}
[geometry]
along_track_step_m = 50e-6
[[targets]]
along_track_m = 0.0
slant_range_m = 1.5002
[[effects]]
name = "reference_interferometer"
"""


TINY_EXPORTS_SCENE = """
preset = "tiny"
pulses = 72
[processor]
aperture_pulses = 32
range_bins = 32
[[targets]]
along_track_m = 0.0
slant_range_m = 2000.0
"""


@pytest.fixture(scope="session")
def tiny_exports(tmp_path_factory):
    """A small recording (72 shots, aperture 32), its image and its CPHD and SigMF exports:
    the sound files the hostile-file and export tests read and edit copies of."""
    from rtsar.app.cli import main

    d = tmp_path_factory.mktemp("tiny-exports")
    (d / "s.toml").write_text(TINY_EXPORTS_SCENE)
    assert main(["simulate", str(d / "s.toml"), "-o", str(d / "rec.h5")]) == 0
    assert main(["process", str(d / "rec.h5"), "-o", str(d / "img.h5"), "--lens", "numpy"]) == 0
    assert main(["export", str(d / "rec.h5"), "--cphd", str(d / "rec.cphd")]) == 0
    assert main(["export", str(d / "rec.h5"), "--sigmf", str(d / "sig")]) == 0
    return d
