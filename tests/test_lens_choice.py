"""--lens auto: the OpenCL lens where a kernel builds, else the NumPy lens, said out loud."""

import re
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
    from rtsar.lens import cl_devices  # pyopencl is a core dependency: never skipped for it
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
    from rtsar.lens import cl_devices  # pyopencl is a core dependency: never skipped for it

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
        f"OpenCL lens on {best.short_label} (asked for: {cl_devices.ENV_DEVICE}={best.index})"
    )


def test_a_device_name_matching_several_says_so(opencl, monkeypatch):
    """From a cold review: `--device 3.1` matched Intel (platform "OpenCL 3.1") and PoCL 3.1
    and the fastest ran without a word. The line names every match and how to pick one."""
    from rtsar.lens import cl_devices

    monkeypatch.delenv(cl_devices.ENV_DEVICE, raising=False)
    reports = cl_devices.survey()
    if len(reports) < 2:  # a failure under CI=true (ci_rule.py): PyPI's, Debian's PoCL are two
        pytest.skip("one OpenCL device here: no name can match several")
    # a name part every device shares: the device's own name (the CPU) or "/"
    lens = base.make_lens(make_plan(preset("tiny")), "opencl", device="/")
    assert lens.choice.startswith(f"OpenCL lens on {lens.device_label} (--lens opencl; asked ")
    assert f"--device /, which names {len(reports)} devices ([" in lens.choice
    assert "`rtsar devices` lists their indexes, for --device N" in lens.choice
    single = base.make_lens(make_plan(preset("tiny")), "opencl", device=str(reports[0].index))
    assert single.choice.endswith(f"(--lens opencl; asked for: --device {reports[0].index})")


def test_lens_opencl_says_which_device_and_why_in_process_too(opencl, tmp_path, capsys):
    """From a cold review: `--lens opencl` named the device without its driver version or why,
    and `rtsar process --lens opencl` printed no lens line at all."""
    from rtsar.lens import cl_devices

    best, why = cl_devices.default_device()
    rec, scene = tmp_path / "r.h5", tmp_path / "s.toml"
    scene.write_text('preset = "tiny"\n[[targets]]\nalong_track_m = 0.0\nslant_range_m = 2000.0\n')
    assert main(["simulate", str(scene), "-o", str(rec), "--pulses", "200"]) == 0
    capsys.readouterr()
    assert main(["process", str(rec), "-o", str(tmp_path / "i.h5"), "--lens", "opencl"]) == 0
    err = capsys.readouterr().err
    assert f"rtsar: lens: OpenCL lens on {best.short_label} (--lens opencl; {why})" in err
    assert main(["process", str(rec), "-o", str(tmp_path / "j.h5"), "--lens", "numpy",
                 "--device", "0"]) == 2  # fmt: skip
    assert "--device names an OpenCL device; --lens numpy runs no OpenCL" in capsys.readouterr().err


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
    assert (
        f"rtsar: lens: OpenCL lens on {best.short_label} ({why}); faster for this plan: mean "
        "5.00 µs per pulse against NumPy's 10.00 µs"
    ) in out


def test_probe_reports_a_driver_that_cannot_build(monkeypatch, opencl):
    from rtsar.lens import cl_devices, cl_loader

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
    assert "{auto,opencl,numpy,hybrid}" in out and "auto (default" in out


def test_a_small_recording_is_not_worth_a_first_device_survey(monkeypatch):
    """Issue 37, item 2: the first `rtsar process` of 2,048 demo shots took 11.5 s, of which
    the OpenCL survey was most; its lens work on NumPy is a fraction of a second.  Unsurveyed,
    a job under SURVEY_WORTH_S of NumPy time runs on NumPy and says why; a big job, a known
    survey or a device asked for choose as before."""
    from rtsar.lens import auto, cl_devices

    monkeypatch.delenv(cl_devices.ENV_DEVICE, raising=False)
    plan = make_plan(preset("psaltis-jpl"))
    monkeypatch.setattr(cl_devices, "survey_is_known", lambda: False)
    why = auto.survey_not_worth(plan, "complex64", 64, 2048)
    assert why.startswith("NumPy lens: this job's range compression takes it about")
    assert "2,048 shots" in why and "`rtsar devices`" in why and "--lens opencl" in why
    assert " 0.0 s" not in why  # a job of 50 ms says so (the walkthrough read "about 0.0 s")
    tiny = auto.survey_not_worth(plan, "complex64", 64, 2)
    assert re.search(r"takes it about \d+ ms \(2 shots", tiny), tiny
    assert auto.survey_not_worth(plan, "complex64", 64, 10**9) is None  # hours on NumPy
    monkeypatch.setenv(cl_devices.ENV_DEVICE, "anything")
    assert auto.survey_not_worth(plan, "complex64", 64, 2048) is None
    monkeypatch.delenv(cl_devices.ENV_DEVICE)
    monkeypatch.setattr(cl_devices, "survey_is_known", lambda: True)
    assert auto.survey_not_worth(plan, "complex64", 64, 2048) is None


def test_process_of_a_small_recording_on_a_new_machine_surveys_nothing(
    tmp_path, capsys, monkeypatch
):
    """In an empty cache (a new machine), `process` of a small recording runs the NumPy lens,
    says why, and leaves no survey behind (nothing was probed)."""
    from rtsar.lens import cl_devices

    (tmp_path / "s.toml").write_text('preset = "tiny"\npulses = 96\n')
    assert main(["simulate", str(tmp_path / "s.toml"), "-o", str(tmp_path / "r.h5")]) == 0
    cache = tmp_path / "cache"
    monkeypatch.setenv("RTSAR_CACHE_DIR", str(cache))
    monkeypatch.delenv(cl_devices.ENV_DEVICE, raising=False)
    monkeypatch.setattr(cl_devices, "_survey", None)  # this process's survey forgotten
    assert main(["process", str(tmp_path / "r.h5"), "-o", str(tmp_path / "i.h5")]) == 0
    err = capsys.readouterr().err
    assert "rtsar: lens: NumPy lens: this job's range compression takes it about" in err
    assert not (cache / "opencl-devices.json").exists()
