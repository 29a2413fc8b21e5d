"""What `rtsar bench` prints (issue 31): one definition per figure, the same number wherever it
is the same measurement, and labels that say which figure is which.

The measurements are replaced by stand-ins (this is about the report, not the machine): every
correlator-alone measurement returns a new number, so a figure measured twice would print two
different numbers; the pipeline runs return fixed figures, a paced run dropping shots.
"""

from __future__ import annotations

import argparse
import itertools
import json
import re

import numpy as np
import pytest

import rtsar.app.bench as bench
import rtsar.app.bench_alone as ba
import rtsar.app.bench_pipeline as bp
from rtsar.lens import make_lens
from rtsar.stream.granularity import MOST_STRIP_LINES


@pytest.fixture
def stand_ins(monkeypatch):
    counter = itertools.count(1)
    measured = []

    def alone(cfg, batch, seconds):
        value = 1000.0 * next(counter) + 7
        measured.append((cfg.processor.correlator, batch, value))
        return value

    def stream_run(cfg, shots, seconds, rate, settings, **kw):
        out = {
            "rate": rate,
            "correlator": cfg.processor.correlator,
            "max_batch": settings.take_cap(cfg.processor.micro_batch, paced=rate != "max"),
            "pulses": 900,
            "pulses_per_s": 1180.0,
            "real_time_factor": 2.36,
            "dropped_pulses": 0,
            "latency_median_ms": 3.0,
            "latency_p99_ms": 9.0,
            "stage_busy_s": {"ccd": 0.5},
            "ccd_stage_pulses_per_s": 1800.0,
        }
        if rate != "max":
            del out["real_time_factor"]
            out.update(
                bp.paced_figures(1000, 1000, 100),  # 100 dropped, their slots zero-filled
                pulses=1000,
                dropped_pulses=100,
                achieved_prf_hz=500.0,
                prf_error=0.0,
            )
        return out

    monkeypatch.setattr(ba, "_correlator_alone", alone)
    # The pipeline's lens: the NumPy plan (as the table's with no OpenCL); a lens measured
    # again here, not taken from the table, would print 7,777.
    monkeypatch.setattr(ba, "make_lens", lambda plan, backend, batch: make_lens(plan, "numpy"))
    monkeypatch.setattr(ba, "rate_per_s", lambda call, n, seconds: 7777.0)
    monkeypatch.setattr(bp, "stream_run", stream_run)
    monkeypatch.setattr(bp, "bench_shots", lambda cfg, n: np.zeros((4, 8), np.complex64))
    monkeypatch.setattr(bp, "bench_numpy_range_doppler", lambda cfg, shots: 4000.0)
    monkeypatch.setattr(bench, "rate_per_s", lambda call, n, seconds: 5000.0)
    monkeypatch.setattr(bench, "opencl_unavailable", lambda: "stand-in: no OpenCL")
    # The recorder's row (measured for real in tests/test_record.py): 4 s of paced writing
    # a test here, for a report line these tests do not read.
    paced = dict(stream_mb_per_s=1.0, stream_seconds=2.0, record_written=9, pulses=9,
                 record_dropped=0, close_seconds=0.1, written_mb_per_s=1.0)  # fmt: skip
    fast = dict(page_cache_mb_per_s=2.0, disk_mb_per_s=1.0, mb=1.0)
    monkeypatch.setattr(
        bench, "bench_recording", lambda *a, **k: dict(folder=".", paced=paced, as_fast=fast)
    )
    return measured


def run_bench(tmp_path, capsys, **kw):
    args = argparse.Namespace(
        preset="tiny", seconds=0.01, real_seconds=1.0, repeats=1, device=None,
        json=str(tmp_path / "bench.json"),
    )  # fmt: skip
    vars(args).update(kw)
    assert bench.run_bench(args) == 0
    return capsys.readouterr().out, json.loads((tmp_path / "bench.json").read_text())


def test_a_correlator_alone_is_measured_once_and_printed_as_one_number(stand_ins, tmp_path, capsys):
    out, data = run_bench(tmp_path, capsys)
    # Each (correlator, batch) measured once (3 rounds, its best): the table's figures are the
    # ratios' figures.
    assert len({(k, b) for k, b, _ in stand_ins}) == 4 and len(stand_ins) == 12
    table = {k: v for k, _, v in stand_ins}
    for kind in ("partitioned", "nonuniform", "fft"):
        figure = f"{table[kind]:,.0f}"
        assert re.search(rf"\b{kind} {figure}\b", out), f"{kind} alone not in the table"
        ratio_line = next(ln for ln in out.splitlines() if f"CCD stage in the '{kind}:" in ln)
        assert f"{kind} alone, batches of 64: {figure} pulses/s" in ratio_line  # a replay's
        assert "the correlator table above" in ratio_line
    row = data["correlator"][0]
    for top, bottom in (("fft", "direct"), ("partitioned", "fft"), ("nonuniform", "partitioned")):
        quotient = row[f"{top}_pulses_per_s"] / row[f"{bottom}_pulses_per_s"]
        assert row[f"{top}_over_{bottom}"] == pytest.approx(quotient, rel=1e-12)
    runs = data["pipeline"][0]["runs"]
    for kind in ("partitioned", "nonuniform", "fft"):
        top = next(r for r in runs if r["label"] == f"{kind}: max rate")
        assert top["isolated_correlator_pulses_per_s"] == row[f"{kind}_pulses_per_s"]


def test_paced_runs_say_what_was_kept_not_a_real_time_factor(stand_ins, tmp_path, capsys):
    out, data = run_bench(tmp_path, capsys)
    paced = [ln for ln in out.splitlines() if ": paced" in ln and "dropped" in ln]  # pipeline
    assert paced and all("kept 900 of 1,000 shots (90.0 %), dropped 100" in ln for ln in paced)
    assert not any("real time" in ln for ln in paced)
    capacity = [ln for ln in out.splitlines() if ": max rate" in ln and "capacity" in ln]
    assert capacity and all("capacity   2.36x real time" in ln for ln in capacity)
    assert "x RT" not in out  # every factor says what it is a factor of
    for r in data["pipeline"][0]["runs"]:
        assert ("real_time_factor" in r) == (r["rate"] == "max")
        assert ("kept_fraction" in r) == (r["rate"] != "max")


def test_rounds_keep_the_labels(stand_ins, tmp_path, capsys):
    out, data = run_bench(tmp_path, capsys, repeats=2)
    # alone figures are not measured again in the second round
    assert len(stand_ins) == 12
    summary = out.split("median [min–max] over 2 rounds:")[1]
    assert "kept 90.0 %, dropped 100 at most" in summary and "capacity 2.36x real time" in summary
    assert data["pipeline"][0]["summary"]["fft: max rate"]["real_time_factor"][0] == 2.36


def test_zero_pulses_standing_in_for_dropped_shots_are_not_kept_shots():
    """A paced run processes a zero pulse in each dropped shot's slot: kept = processed less
    those (the first report said "kept 30,000 of 30,000 shots, dropped 1,488")."""
    figures = bp.paced_figures(offered=30_000, processed=30_000, gap_filled=1_488)
    assert figures["kept_pulses"] == 28_512 and figures["kept_fraction"] == pytest.approx(0.9504)


def test_the_two_core_ideal_is_the_stages_taking_turns():
    """The issue's figures: lens alone 187.7k, nonuniform alone 47.7k pulses/s → 38.0k."""
    run, said = {"pulses_per_s": 27_100.0}, []
    run["label"] = "nonuniform: max rate"
    ba.against_ideal(run, {"pulses_per_s": 187_700.0}, 47_700.0, said.append)
    assert run["two_core_ideal_pulses_per_s"] == pytest.approx(38_034, rel=1e-4)
    assert run["over_two_core_ideal"] == pytest.approx(0.7125, rel=1e-3)
    assert said == [
        "    nonuniform: max rate: 0.71 of its stages' two-core ideal 1/(1/187,700 + 1/47,700) "
        "= 38,034 pulses/s"
    ]


def test_the_lens_alone_is_the_lens_tables_figure_and_each_ideal_sits_under_its_run(
    stand_ins, tmp_path, capsys
):
    """From a cold review: the lens table printed OpenCL at batch 64 as 65,005 pulses/s and the
    pipeline section "the pipeline's lens alone (opencl), batches of 64: 21,936" (measured
    again, once); and each "of its stages' two-core ideal" line came after the paced run, under
    the wrong row."""
    out, data = run_bench(tmp_path, capsys)
    batch = data["pipeline"][0]["lens_alone"]["batch"]
    row = next(r for r in data["lens"] if r["batch"] == batch)
    assert row["numpy_fft_pulses_per_s"] == 5000.0
    assert (
        f"the pipeline's lens alone (numpy), batches of {batch}: 5,000 pulses/s (the AO lens "
        "table above)"
    ) in out
    assert "7,777" not in out and data["pipeline"][0]["lens_alone"]["pulses_per_s"] == 5000.0
    lines = out.splitlines()
    for kind in ("partitioned", "nonuniform", "fft"):
        k = next(i for i, ln in enumerate(lines) if ln.strip().startswith(f"{kind}: max rate "))
        assert lines[k + 1].strip().startswith(f"{kind}: max rate: ")
        assert "of its stages' two-core ideal" in lines[k + 1]


def test_the_lens_rows_carry_the_two_thread_fft_pair_yardstick():
    """Issue 38: the bench prints each lens's share of a bare two-thread FFT pair of its size."""
    from rtsar.app.bench import _fft_pair, bench_lens
    from rtsar.lens import make_plan
    from rtsar.presets import preset

    cfg = preset("tiny")
    (row,) = bench_lens(cfg, batches=(4,), seconds=0.05, rounds=1, opencl=False)
    pair = row["fft_pair_two_threads_pulses_per_s"]
    assert pair > 0 and row["numpy_share_of_fft_pair"] == row["numpy_fft_pulses_per_s"] / pair
    assert row["opencl_share_of_fft_pair"] is None  # no OpenCL lens asked for
    nfft = make_plan(cfg).nfft
    x = np.arange(8, dtype=np.complex64).reshape(2, 4)
    np.testing.assert_allclose(_fft_pair(x, nfft)[:, :4], x, atol=1e-5)  # the pair round-trips


def test_the_pipeline_runs_cut_strips_as_a_live_run_does(stand_ins, tmp_path, capsys, monkeypatch):
    """Every pipeline run of the bench publishes strips of 16 lines with the lines that wait
    going out together, up to MOST_STRIP_LINES, as a live run's granularity has them
    (rtsar.stream.granularity), not strips of exactly 16 however far behind the strip stage is."""
    seen = []
    fake = bp.stream_run

    def stream_run(cfg, shots, seconds, rate, settings, **kw):
        seen.append((rate, settings.strip_lines, settings.strip_most_lines))
        return fake(cfg, shots, seconds, rate, settings, **kw)

    monkeypatch.setattr(bp, "stream_run", stream_run)
    run_bench(tmp_path, capsys)
    warm_up = seen[0]  # the warm-up run (not recorded)
    runs = [s for s in seen[1:] if s[1] == 16]
    assert len(runs) >= 10 and warm_up[0] == "max"
    assert all(most == MOST_STRIP_LINES for _, _, most in runs), runs
