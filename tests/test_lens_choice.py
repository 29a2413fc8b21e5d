"""--lens auto: the OpenCL lens where a kernel builds, else the NumPy lens, said out loud."""

import warnings

import numpy as np
import pytest

from rtsar.app.cli import main
from rtsar.lens import base, make_plan
from rtsar.lens.numpy_lens import NumpyLens
from rtsar.presets import preset

REASON = "PoCL's compiler does not know this CPU model (error: unknown target CPU 'generic')"


def test_auto_falls_back_to_numpy_with_a_warning(monkeypatch):
    monkeypatch.setattr(base, "opencl_unavailable", lambda device=None: REASON)
    plan = make_plan(preset("tiny"))
    with pytest.warns(RuntimeWarning, match="using the NumPy lens.*unknown target CPU"):
        lens = base.make_lens(plan, "auto")
    assert isinstance(lens, NumpyLens) and lens.backend == "numpy"
    assert lens.fallback_reason == REASON
    # The fallback computes the same lines as the NumPy lens asked for by name.
    x = np.ones((3, plan.samples_per_shot), np.complex64)
    np.testing.assert_array_equal(lens.compress(x), NumpyLens(plan).compress(x))


def test_explicit_numpy_never_probes_or_warns(monkeypatch):
    def boom(device=None):
        raise AssertionError("probed OpenCL for --lens numpy")

    monkeypatch.setattr(base, "opencl_unavailable", boom)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lens = base.make_lens(make_plan(preset("tiny")), "numpy")
    assert lens.backend == "numpy" and lens.fallback_reason is None


def test_auto_uses_opencl_when_it_works(opencl):
    lens = base.make_lens(make_plan(preset("tiny")), "auto")
    assert lens.backend == "opencl" and lens.fallback_reason is None


def test_run_banner_names_the_lens_in_use(monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(base, "opencl_unavailable", lambda device=None: REASON)
    status = main(["run", "--duration", "0.3", "--endpoint", "ipc://" + str(tmp_path / "s")])
    out, err = capsys.readouterr()
    assert status == 0
    assert "NumPy lens (OpenCL unavailable" in out
    assert "rtsar: warning: OpenCL lens unavailable" in err and "unknown target CPU" in err


def test_probe_reports_a_driver_that_cannot_build(monkeypatch):
    cl_loader = pytest.importorskip("rtsar.lens.cl_loader")

    class Broken:
        def __init__(self, *a, **k):
            pass

        def build(self, *a, **k):
            raise cl_loader.cl.RuntimeError(
                "clBuildProgram failed\nerror: unknown target CPU 'generic'\n"
            )

    monkeypatch.setattr(cl_loader.cl, "Program", Broken)
    monkeypatch.setattr(cl_loader, "_probes", {})
    reason = cl_loader.probe()
    assert reason.startswith("PoCL's compiler does not know this CPU model")
    assert "unknown target CPU 'generic'" in reason


def test_lens_option_offers_auto_by_default(capsys):
    with pytest.raises(SystemExit):
        main(["process", "--help"])
    out = capsys.readouterr().out
    assert "{auto,opencl,numpy}" in out and "auto (default" in out
