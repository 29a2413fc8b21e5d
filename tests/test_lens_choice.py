"""--lens auto: the OpenCL lens where a kernel builds, else the NumPy lens, said out loud."""

import warnings

import numpy as np
import pytest

from rtsar.app.cli import main
from rtsar.lens import base, make_plan
from rtsar.lens.numpy_lens import NumpyLens
from rtsar.presets import preset

REASON = "the driver's compiler does not know this CPU model (error: unknown target CPU 'generic')"


def no_device_builds(monkeypatch):
    """The survey of a machine where PyPI's PoCL 3.0 is the only driver and cannot build."""
    cl_devices = pytest.importorskip("rtsar.lens.cl_devices")
    from rtsar.lens.cl_probe import DeviceReport

    refused = DeviceReport(0, "Portable Computing Language", "OpenCL 3.0 PoCL 3.0-rc2",
                           "pthread-AMD EPYC", "3.0-rc2", "CPU", reason=REASON)  # fmt: skip
    monkeypatch.setattr(cl_devices, "survey", lambda say=None: [refused])
    monkeypatch.delenv(cl_devices.ENV_DEVICE, raising=False)


def test_auto_falls_back_to_numpy_with_a_warning(monkeypatch):
    no_device_builds(monkeypatch)
    plan = make_plan(preset("tiny"))
    with pytest.warns(RuntimeWarning, match="using the NumPy lens.*unknown target CPU"):
        lens = base.make_lens(plan, "auto")
    assert isinstance(lens, NumpyLens) and lens.backend == "numpy"
    assert REASON in lens.fallback_reason
    # The fallback computes the same lines as the NumPy lens asked for by name.
    x = np.ones((3, plan.samples_per_shot), np.complex64)
    np.testing.assert_array_equal(lens.compress(x), NumpyLens(plan).compress(x))


def test_explicit_numpy_never_probes_or_warns(monkeypatch):
    cl_devices = pytest.importorskip("rtsar.lens.cl_devices")

    def boom(say=None):
        raise AssertionError("probed OpenCL for --lens numpy")

    monkeypatch.setattr(cl_devices, "survey", boom)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lens = base.make_lens(make_plan(preset("tiny")), "numpy")
    assert lens.backend == "numpy" and lens.fallback_reason is None


def test_auto_uses_a_device_asked_for(opencl, monkeypatch):
    from rtsar.lens import cl_devices

    best, _ = cl_devices.default_device()
    monkeypatch.setenv(cl_devices.ENV_DEVICE, str(best.index))
    lens = base.make_lens(make_plan(preset("tiny")), "auto")
    assert lens.backend == "opencl" and lens.fallback_reason is None
    assert lens.choice == (
        f"OpenCL lens on {best.label} (asked for: {cl_devices.ENV_DEVICE}={best.index})"
    )


def test_run_banner_names_the_lens_in_use(monkeypatch, capsys, tmp_path):
    no_device_builds(monkeypatch)
    status = main(["run", "--duration", "0.3", "--endpoint", "ipc://" + str(tmp_path / "s")])
    out, err = capsys.readouterr()
    assert status == 0
    assert "NumPy lens (OpenCL unavailable" in out
    assert "rtsar: lens: NumPy lens (no OpenCL: no OpenCL device builds the lens" in out
    assert "rtsar: warning: OpenCL lens unavailable" in err and "unknown target CPU" in err


def test_run_banner_names_the_opencl_device_and_why(monkeypatch, capsys, tmp_path, opencl):
    from rtsar.lens import auto, cl_devices

    monkeypatch.delenv(cl_devices.ENV_DEVICE, raising=False)
    monkeypatch.setattr(
        auto, "plan_rates", lambda a, b, sizes, key=None: {
            "opencl": dict.fromkeys(sizes, 2e5), "numpy": dict.fromkeys(sizes, 1e5)}
    )  # fmt: skip
    best, why = cl_devices.default_device()
    status = main(["run", "--duration", "0.3", "--endpoint", "ipc://" + str(tmp_path / "s")])
    out = capsys.readouterr().out
    assert status == 0
    assert f"rtsar: lens: OpenCL lens on {best.short_label} ({why}); for this plan 200,000" in out


def test_probe_reports_a_driver_that_cannot_build(monkeypatch, opencl):
    cl_loader = pytest.importorskip("rtsar.lens.cl_loader")
    from rtsar.lens import cl_devices

    best, _ = cl_devices.default_device()

    class Broken:
        def __init__(self, *a, **k):
            pass

        def build(self, *a, **k):
            raise cl_loader.cl.RuntimeError(
                "clBuildProgram failed\nerror: unknown target CPU 'generic'\n"
            )

    monkeypatch.setattr(cl_loader.cl, "Program", Broken)
    monkeypatch.setattr(cl_loader, "_probes", {})
    reason = cl_loader.probe(str(best.index))
    assert reason.startswith("the driver's compiler does not know this CPU model")
    assert "unknown target CPU 'generic'" in reason


def test_lens_option_offers_auto_by_default(capsys):
    with pytest.raises(SystemExit):
        main(["process", "--help"])
    out = capsys.readouterr().out
    assert "{auto,opencl,numpy}" in out and "auto (default" in out
