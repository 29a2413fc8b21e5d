"""A cached lens measurement is advice: a damaged entry is measured again, never fatal.

Issue 36, item 8: ``{"opencl": {}, "numpy": {}}`` in ``lens-choice.json`` raised
ZeroDivisionError in every run of its plan, and NaN, negative or infinite rates were trusted.
"""

import json
import math

import pytest

from rtsar.lens import auto
from rtsar.lens.cache import rates_or_none, read_json

KEY = "0123456789abcdef01234567"
SIZES = (16, 64)
MEASURED = {"opencl": {16: 200.0, 64: 400.0}, "numpy": {16: 300.0, 64: 300.0}}

DAMAGED = [
    {"opencl": {}, "numpy": {}},
    {"opencl": {"16": "nan", "64": 1.0}, "numpy": {"16": 1.0, "64": 1.0}},
    {"opencl": {"16": -5.0, "64": 1.0}, "numpy": {"16": 1.0, "64": 1.0}},
    {"opencl": {"16": "inf", "64": 1.0}, "numpy": {"16": 1.0, "64": 1.0}},
    {"opencl": {"16": 0, "64": 1.0}, "numpy": {"16": 1.0, "64": 1.0}},
    {"opencl": {"16": [1], "64": 1.0}, "numpy": {"16": 1.0, "64": 1.0}},
    {"opencl": {"x": 1.0, "64": 1.0}, "numpy": {"16": 1.0, "64": 1.0}},
    {"opencl": {"64": 1.0}, "numpy": {"64": 1.0}},  # a batch size asked for is missing
    {"opencl": [1, 2], "numpy": {"16": 1.0, "64": 1.0}},
]


@pytest.fixture
def measuring(monkeypatch, tmp_path):
    monkeypatch.setenv("RTSAR_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(auto, "_memo", {})
    calls = []

    def best_rates(lenses, sizes, seconds, rounds):
        calls.append(tuple(sizes))
        return MEASURED

    monkeypatch.setattr(auto, "best_rates", best_rates)
    return tmp_path, calls


@pytest.mark.parametrize("entry", DAMAGED, ids=range(len(DAMAGED)))
def test_a_damaged_entry_is_measured_again(measuring, entry):
    folder, calls = measuring
    (folder / "lens-choice.json").write_text(json.dumps({KEY: entry}))
    rates = auto.plan_rates(None, None, SIZES, KEY)
    assert calls == [SIZES] and rates == MEASURED
    # and the measurement replaced the damaged entry in the file
    kept = read_json("lens-choice.json")[KEY]
    assert kept == {k: {str(b): v for b, v in d.items()} for k, d in MEASURED.items()}
    assert all(math.isfinite(1e6 / r) for d in rates.values() for r in d.values())


def test_a_sound_entry_is_used_without_measuring(measuring):
    folder, calls = measuring
    entry = {"opencl": {"16": 10.0, "64": 20.0}, "numpy": {"16": 30.0, "64": 40.0}}
    (folder / "lens-choice.json").write_text(json.dumps({KEY: entry}))
    assert auto.plan_rates(None, None, SIZES, KEY) == {
        "opencl": {16: 10.0, 64: 20.0},
        "numpy": {16: 30.0, 64: 40.0},
    }
    assert calls == []


def test_rates_or_none_takes_only_finite_positive_rates_for_every_size():
    assert rates_or_none({"16": 1.5, "64": 2}, SIZES) == {16: 1.5, 64: 2.0}
    for bad in ({}, None, "x", {"16": float("nan")}, {"16": -1.0}, {"-16": 1.0}, {"16": 1.0}):
        assert rates_or_none(bad, SIZES) is None


@pytest.mark.parametrize("bad", ["nan", -3.0, "inf", "fast"])
def test_a_damaged_device_survey_is_probed_again(monkeypatch, tmp_path, bad):
    from rtsar.lens import cl_devices  # pyopencl is a core dependency
    from rtsar.lens.cl_probe import DeviceReport

    monkeypatch.setenv("RTSAR_CACHE_DIR", str(tmp_path))
    monkeypatch.setattr(cl_devices, "_survey", None)
    one = DeviceReport(0, "Some Platform", "OpenCL 3.0", "some CPU", "1.0", "CPU")
    monkeypatch.setattr(cl_devices, "list_devices", lambda: ["device"])
    monkeypatch.setattr(cl_devices, "describe", lambda i, d: DeviceReport(**one.__dict__))
    probed = []

    def probe_all(reports, preset_name, batches, seconds):
        probed.append(1)
        for r in reports:
            r.rates = {str(b): 1000.0 for b in batches}
        return reports, {str(b): 500.0 for b in batches}

    monkeypatch.setattr(cl_devices, "probe_all", probe_all)
    key = cl_devices.fingerprint([one])
    device = {**one.__dict__, "rates": {str(cl_devices.SURVEY_BATCH): bad}}
    (tmp_path / "opencl-devices.json").write_text(
        json.dumps({"fingerprint": key, "devices": [device]})
    )
    found = cl_devices.survey()
    assert probed == [1]
    assert found[0].rate() == 1000.0


def test_where_a_cache_lives_is_not_a_new_survey(monkeypatch):
    """From the cold-start work: NUMBA_CACHE_DIR made a new fingerprint (a full new probe);
    a speed setting (threads) still does."""
    from rtsar.lens import cl_devices
    from rtsar.lens.cl_probe import DeviceReport

    one = [DeviceReport(0, "P", "OpenCL 3.0", "cpu", "1.0", "CPU")]
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    base = cl_devices.fingerprint(one)
    monkeypatch.setenv("NUMBA_CACHE_DIR", "/somewhere/else")
    monkeypatch.setenv("POCL_CACHE_DIR", "/another")
    assert cl_devices.fingerprint(one) == base
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")
    assert cl_devices.fingerprint(one) != base


def test_the_test_run_measures_into_a_cache_of_its_own_not_the_users():
    """The suite surveys devices and chooses lenses on a machine it loads: those figures stay
    in a copy of the user's cache, made for this run (tests/conftest.py), and the user's next
    `rtsar run` chooses from the user's own."""
    import os
    import tempfile
    from pathlib import Path

    from rtsar.lens.cache import cache_dir

    here = cache_dir()
    assert here.name.startswith("rtsar-test-cache-"), here
    assert Path(os.path.commonpath([here, tempfile.gettempdir()])) == Path(tempfile.gettempdir())
