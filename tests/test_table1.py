"""Table 1 report (rtsar.physical.table1): numbers from the emulation, checked against physics.

The full report runs the psaltis presets (about half a minute); here the same code runs on the
small `tiny` preset with a 64 × 64 CCD, and the measured quantities are compared with what the
device must give: c/2B and L/N widths, √(bias + read² + lsb²/12) per pixel, no overflow at the
strongest "undistorted" target and an overflow just above it.
"""

import argparse
import json
import math

import numpy as np
import pytest

from rtsar.app import table1 as t1
from rtsar.physical import paper_ccd
from rtsar.presets import preset


@pytest.fixture(scope="module")
def small_data():
    return t1.table1_data(
        experimental="tiny", maximum="tiny", ccd=(64, 64), maximum_columns=128, bins=16,
        log=lambda msg: None,
    )  # fmt: skip


def test_cell_counts_come_from_the_emulated_device(small_data):
    ex = small_data["experimental"]
    # 64 columns: the range carrier takes 2 per cell; 64 rows: the azimuth carrier 2 per pulse.
    assert ex["range"]["device"]["range_cells"] == 32
    assert ex["azimuth"]["device"]["range_cells"] == 64
    assert ex["range"]["resolution"]["pulses_integrated"] == 64
    assert ex["azimuth"]["resolution"]["pulses_integrated"] == 32
    assert small_data["maximum"]["range"]["device"]["range_cells"] == 64


def test_measured_resolution_is_c_over_2b_and_l_over_n(small_data):
    for entry in small_data["experimental"].values():
        r = entry["resolution"]
        # Unweighted chirp and aperture: -3 dB width 0.886 of the resolution (sinc²).
        assert r["range_irw_m"] == pytest.approx(0.886 * r["range_resolution_m"], rel=0.05)
        assert r["azimuth_irw_m"] == pytest.approx(0.886 * r["l_over_n_m"], rel=0.05)
    ra = small_data["experimental"]["range"]["resolution"]["azimuth_irw_m"]
    az = small_data["experimental"]["azimuth"]["resolution"]["azimuth_irw_m"]
    assert az / ra == pytest.approx(2.0, rel=0.05)  # the azimuth carrier doubles ρA


def test_pixel_noise_is_bias_shot_noise_plus_read_noise(small_data):
    for entry in small_data["experimental"].values():
        d = entry["dynamic_range"]
        lsb = d["full_well_e"] / (2**12 - 1)
        expect = math.sqrt(d["bias_e"] + 200.0**2 + lsb**2 / 12)  # ≈ 406 e-
        assert d["sigma_pixel_e"] == pytest.approx(expect, rel=0.05)
        assert d["swing_e"] < d["full_well_e"] - d["bias_e"]  # |s|² shares the headroom
        assert abs(d["compression_db"]) < 0.1  # linear up to the well
        assert d["dr_pixel"] == pytest.approx(d["swing_e"] / d["sigma_pixel_e"])
        assert 100 < d["dr_pixel"] < 400


def test_strongest_undistorted_target_is_at_the_well():
    cfg = preset("tiny").with_processor(range_bins=16)
    quiet = t1._quiet(paper_ccd("range"))
    d = t1.measure_dynamic_range(cfg, paper_ccd("range"), bins=16)
    unit, start, _, _ = t1.simulate_lines(cfg, 1.0, 64)
    overflows = []
    for a in (d["a_max"], 1.05 * d["a_max"]):
        _, _, _, dev = t1.focus(cfg, quiet, unit * np.float32(a), start)
        overflows.append(dev.pixel_overflows)
    assert overflows[0] == 0 < overflows[1]


def test_markdown_holds_the_papers_values_and_the_emulated_ones(small_data):
    text = t1.table1_markdown(small_data)
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    assert len(rows) == 6  # header + 5 quantities
    for printed in ("160 or 320", "1200", "N = 512 or 256, ρA ≈ 30-60m", "250-300 : 1", "≈ 227"):
        assert printed in text
    ex = small_data["experimental"]
    assert f"{ex['range']['device']['range_cells']} (carrier in range)" in text
    assert f"{ex['range']['dynamic_range']['dr_pixel']:.0f} : 1 per pixel" in text


def test_run_writes_markdown_and_json(small_data, tmp_path, monkeypatch):
    monkeypatch.setattr(t1, "table1_data", lambda speed=False: small_data)
    parser = argparse.ArgumentParser()
    t1.add_arguments(parser)
    md, js = tmp_path / "t1.md", tmp_path / "t1.json"
    assert t1.run(parser.parse_args(["--out", str(md), "--json", str(js)])) == 0
    assert md.read_text(encoding="utf-8") == t1.table1_markdown(small_data)
    back = json.loads(js.read_text(encoding="utf-8"))
    assert back["experimental"]["range"]["device"]["range_cells"] == 32
    assert back["settings"]["range"]["ccd"]["read_noise"]["sigma_e"] == 200.0
