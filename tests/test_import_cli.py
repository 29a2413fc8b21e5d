"""`rtsar import` as a user meets it: a small instrument file and its .npy array, the one-line
errors (exit 2) naming the key or the file, the Doppler centroid's sources, inputs never
overwritten."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from rtsar.app.cli import main

TOML = """
[radar]
carrier_hz = 10e9
sample_rate_hz = 10e6
chirp_rate_hz_per_s = {rate}
pulse_length_s = 1.6e-6
prf_hz = 1000.0

[geometry]
effective_velocity_m_per_s = 100.0
window_start_s = 1e-4
antenna_length_m = 20.0
{doppler}

[data]
file = "block.npy"
first_range_cell = 7
"""


def _instrument(tmp_path, data, doppler="doppler_centroid_hz = 0.0", rate="-5e12"):
    np.save(tmp_path / "block.npy", data)
    path = tmp_path / "inst.toml"
    path.write_text(TOML.format(doppler=doppler, rate=rate))
    return path


def _noise(pulses=300, samples=64, dc=0.25 - 0.5j):
    rng = np.random.default_rng(5)
    x = rng.standard_normal((pulses, samples)) + 1j * rng.standard_normal((pulses, samples))
    return (x + dc).astype(np.complex64)


def test_import_writes_a_recording_process_takes(tmp_path, capsys):
    toml = _instrument(tmp_path, _noise())
    rec, img = tmp_path / "rec.h5", tmp_path / "img.h5"
    assert main(["import", str(toml), "-o", str(rec)]) == 0
    out = capsys.readouterr()
    assert "DC offset +0.26" in out.out and "-0.49" in out.out  # removed and reported
    assert "kept as provenance, not read: [data] first_range_cell" in out.err
    with h5py.File(rec, "r") as f:
        assert f["shots"].shape == (300, 64)
        assert abs(np.asarray(f["shots"]).mean()) < 0.02
        assert json.loads(f.attrs["config"])["geometry"]["doppler_centroid_hz"] == 0.0
        assert f.attrs["doppler_centroid_source"] == "the instrument file's"
    assert main(["process", str(rec), "-o", str(img), "--lens", "numpy"]) == 0


def _scene_at(doppler_hz, pulses=300, samples=64):
    """One fixed range profile seen at a Doppler of ``doppler_hz`` (no walk), plus a little
    noise: what the estimator needs to find the fraction and no ambiguity."""
    rng = np.random.default_rng(8)
    profile = rng.standard_normal(samples) + 1j * rng.standard_normal(samples)
    p = np.arange(pulses)[:, None]
    x = profile[None, :] * np.exp(2j * np.pi * doppler_hz * p / 1000.0)
    return (x + 0.1 * _noise(pulses, samples, 0)).astype(np.complex64)


def test_the_estimate_is_used_when_the_file_has_none_or_when_asked(tmp_path, capsys):
    toml = _instrument(tmp_path, _scene_at(120.0, pulses=600), doppler="")
    assert main(["import", str(toml), "-o", str(tmp_path / "a.h5")]) == 0
    assert "Doppler centroid used:" in capsys.readouterr().err
    with h5py.File(tmp_path / "a.h5", "r") as f:
        assert f.attrs["doppler_centroid_source"] == "estimated"
        f_dc = json.loads(f.attrs["config"])["geometry"]["doppler_centroid_hz"]
    assert f_dc == pytest.approx(120.0, abs=2.0)
    toml = _instrument(tmp_path, _scene_at(120.0, pulses=600))
    assert main(["import", str(toml), "-o", str(tmp_path / "b.h5"), "--estimate-doppler"]) == 0
    with h5py.File(tmp_path / "b.h5", "r") as f:
        assert f.attrs["doppler_centroid_source"] == "estimated"


@pytest.mark.parametrize(
    "doppler, rate, data, says",
    [
        ("", "-5e12", np.zeros((300, 64), np.complex64), "geometry.doppler_centroid_hz"),
        ("", "-5e12", _noise(), "geometry.doppler_centroid_hz"),
        ("doppler_centroid_hz = 0.0", "-5e12", _noise(pulses=100), "fewer than the aperture"),
        ("doppler_centroid_hz = 0.0", "-9e12", _noise(), "chirp"),
        ("doppler_centroid_hz = 0.0", "-5e12", _noise()[:, :8], "pulse"),
        ("dopler_centroid_hz = 0.0", "-5e12", _noise(), "dopler_centroid_hz"),
    ],
)
def test_bad_instruments_are_one_line_naming_the_key_or_file(
    tmp_path, capsys, doppler, rate, data, says
):
    toml = _instrument(tmp_path, data, doppler=doppler, rate=rate)
    assert main(["import", str(toml), "-o", str(tmp_path / "x.h5")]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("rtsar: error:") and says in err
    assert not (tmp_path / "x.h5").exists()


def test_all_zero_data_with_the_files_centroid_imports_and_says_why_no_estimate(tmp_path, capsys):
    toml = _instrument(tmp_path, np.zeros((300, 64), np.complex64))
    assert main(["import", str(toml), "-o", str(tmp_path / "z.h5")]) == 0
    assert "no Doppler centroid from the data" in capsys.readouterr().err


def test_import_never_overwrites_what_it_reads(tmp_path, capsys):
    toml = _instrument(tmp_path, _noise())
    for target in (toml, tmp_path / "block.npy"):
        before = target.read_bytes()
        assert main(["import", str(toml), "-o", str(target)]) == 2
        assert "would replace what it reads" in capsys.readouterr().err
        assert target.read_bytes() == before
    assert main(["import", str(toml), "-o", str(tmp_path / "x.png")]) == 2


def test_run_takes_the_instrument_file_for_a_live_link(tmp_path, capsys):
    """`rtsar run --zmq-in … --instrument FILE`: the instrument's processor, its shots' length;
    a link that stays silent ends the run as any live run (no shot is needed to check the
    configuration), and an instrument file without a centroid is refused by name."""
    from conftest import free_port

    toml = _instrument(tmp_path, _noise(), doppler="doppler_centroid_hz = 0.0")
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    args = ["run", "--zmq-in", endpoint, "--instrument", str(toml), "--duration", "0.5"]
    assert main(args + ["--endpoint", f"tcp://127.0.0.1:{free_port()}"]) == 0
    # the aperture λR/(D d) at mid-window: c/10 GHz, R = c (1e-4 s + 32/10 MHz)/2, 20 m, 0.1 m
    c = 299_792_458.0
    rows = round(c / 10e9 * 0.5 * c * (1e-4 + 32 / 10e6) / (20.0 * 0.1))
    assert f"CCD {rows} x 64" in capsys.readouterr().out
    toml = _instrument(tmp_path, _noise(), doppler="")
    assert main(args) == 2
    assert "geometry.doppler_centroid_hz: a live run needs it" in capsys.readouterr().err
    assert main(["run", "--instrument", str(toml)]) == 2  # a simulated run has its scene
