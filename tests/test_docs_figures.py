"""The figures two guide pages quote are what their reports give today (issue 37).

3d.md's InSAL table is ``python tools/insal_report.py`` at its defaults (96 lines x 96 bins,
10 dB SNR, seed 1); corrections.md's rows for the uncorrected chirp defects are
``python tools/chirp_report.py``.  Both are deterministic, so the page's rounding must be the
run's.  The sine row is also held to the physics: a sinusoidal phase error of index β splits the
response into paired echoes of amplitude J_n(β) (Jacobi-Anger) without widening the one at the
target, so its IRW is the error-free one and its PSLR the brightest echo over J_0.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.special import jv

from rtsar.app.reports import chirp, insal
from rtsar.lens.plan import make_plan
from rtsar.params import C_M_PER_S
from rtsar.scene.relief import zhao_config
from rtsar.topo.insar_geometry import InsalGeometry

GUIDE = Path(__file__).resolve().parents[1] / "docs" / "pages" / "guide"


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")]


def _rows(page: str, first: str) -> list[list[str]]:
    text = (GUIDE / page).read_text(encoding="utf-8")
    return [_cells(ln) for ln in text.splitlines() if ln.startswith(f"| {first}")]


@pytest.fixture(scope="module")
def insal_rows():
    """{(scene, flat earth label): row} of the report at its documented defaults."""
    args = argparse.Namespace(lines=96, range_bins=96, per_cell=2.0, snr_db=10.0, seed=1)
    cfg = zhao_config(sample_rate_hz=1280.0, aperture_pulses=160, range_bins=96)
    geo = InsalGeometry.from_config(cfg, 1.6e-3)
    out = {}
    for scene in ("ridge", "pin"):
        rep = insal.scene_report(scene, cfg, geo, args, None)
        for row in rep["rows"]:
            if row["method"] == "mcf":
                out[(scene, row["flat_earth"])] = row | {
                    "geometric": rep["geometric_fringe_cycles_per_bin"]
                }
    return out


PAGE_SCENES = {"ridge 2.5 mm": "ridge", "ridge": "ridge", "drawing pin 1.5 mm": "pin",
               "drawing pin": "pin"}  # fmt: skip
PAGE_FLAT = {"geometry": "geometry", "estimated fringes, mean phase step": "fringes (gradient)",
             "estimated fringes, spectral peak": "fringes (peak)"}  # fmt: skip


def test_insal_table_is_the_reports_run(insal_rows):
    rows = [r for r in _rows("3d.md", "") if r[0] in PAGE_SCENES and r[-1] == "164 µm"]
    assert len(rows) == 6
    for scene, flat, rms, _ in rows:
        label = next(v for k, v in PAGE_FLAT.items() if flat.startswith(k))
        got = insal_rows[(PAGE_SCENES[scene], label)]
        if got["pass"]:
            assert rms == f"{got['rms_um']:.1f} µm", (scene, flat)
        else:
            assert rms == f"{got['rms_um']:.0f} µm: fails", (scene, flat)


def test_the_spectral_peak_fails_where_the_target_fills_the_window(insal_rows):
    """The page says why: the peak method finds a slope's fringes, not the flat earth's, and
    quotes the rates the report prints; the mean phase step stays within 2 % of the geometry."""
    text = " ".join((GUIDE / "3d.md").read_text(encoding="utf-8").split())
    for scene in ("ridge", "pin"):
        peak = insal_rows[(scene, "fringes (peak)")]
        mean = insal_rows[(scene, "fringes (gradient)")]
        geometric = peak["geometric"]
        assert not peak["pass"] and mean["pass"]
        assert abs(peak["fringe_cycles_per_bin"] - geometric) > 0.1 * abs(geometric)
        assert abs(mean["fringe_cycles_per_bin"] - geometric) < 0.02 * abs(geometric)
        assert f"−{abs(peak['fringe_cycles_per_bin']):.4f} ({scene})" in text
    assert f"against the geometry's −{abs(geometric):.4f}" in text


@pytest.fixture(scope="module")
def chirp_cases():
    cfg = chirp.config_for("crouch-sal", None)
    runs = {
        "free": chirp.run_case(cfg, [], None),
        "sine": chirp.run_case(cfg, [chirp.SINE, chirp.RI], None),
        "quad": chirp.run_case(cfg, [chirp.QUAD, chirp.RI], None),
    }
    return cfg, runs


def test_uncorrected_chirp_rows_are_the_reports_run(chirp_cases):
    _, runs = chirp_cases
    irw = {k: runs[k]["rg_irw_m"] / runs["free"]["rg_irw_m"] for k in ("sine", "quad")}
    (sine,) = _rows("corrections.md", "1 % sinusoidal non-linearity")
    pslr = runs["sine"]["rg_pslr_db"]
    assert sine[3].startswith(f"range IRW {irw['sine']:.3f} → 1.007, PSLR +{pslr:.1f} → −13.2 dB")
    (quad,) = _rows("corrections.md", "1 % quadratic non-linearity")
    assert quad[3] == f"range IRW {irw['quad']:.1f} → 1.006"


def test_uncorrected_sine_is_paired_echoes(chirp_cases):
    """β = 2π τ · 0.01 B at the target (τ from the reference range); echoes every 5 cells (five
    periods over the chirp) inside the analysed chip.  The response at the target keeps the
    error-free width; its PSLR is the brightest J_n over J_0 (sinc tails of the neighbours
    shift it by a few tenths of a dB)."""
    cfg, runs = chirp_cases
    m, wf = runs["sine"], cfg.waveform
    tau_s = 2 * (m["target_range_m"] - wf.reference_range_m) / C_M_PER_S
    beta = 2 * math.pi * tau_s * 0.01 * wf.bandwidth_hz
    assert beta == pytest.approx(14.0, abs=0.1)
    chip = max(32, math.ceil(12 * 0.886 * cfg.azimuth_resolution_m(m["target_range_m"])
                             / cfg.geometry.along_track_step_m))  # fmt: skip
    assert abs(np.diff(make_plan(cfg).range_m)[0]) == pytest.approx(
        C_M_PER_S / (2 * wf.bandwidth_hz), rel=1e-6
    )  # one range bin per cell c/2B: the echoes are 5 bins apart
    echoes = np.arange(1, chip // 5 + 1)
    predicted_db = 20 * math.log10(np.max(np.abs(jv(echoes, beta))) / abs(jv(0, beta)))
    assert m["rg_irw_m"] / runs["free"]["rg_irw_m"] == pytest.approx(1.0, abs=0.005)
    assert m["rg_pslr_db"] > 0.0
    assert m["rg_pslr_db"] == pytest.approx(predicted_db, abs=0.5)
    text = " ".join((GUIDE / "corrections.md").read_text(encoding="utf-8").split())
    assert f"the J_n alone predict +{predicted_db:.1f} dB" in text
    assert f"J₀(14)² ≈ {round(100 * jv(0, beta) ** 2)} % of the energy" in text
