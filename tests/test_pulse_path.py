"""tools/pulse_path.py (rtsar.app.reports.pulse_path): one pulse's path through the pipeline's
own stages, part by part; the figures are the machine's, so only their form is checked."""

from __future__ import annotations

import math

from rtsar.app.reports import pulse_path


def test_each_part_of_the_path_is_timed_and_the_sum_is_said(capsys):
    r = pulse_path.measure("tiny", 1.0, 40, "numpy", "nonuniform")
    parts = r["per_pulse_s"]
    assert list(parts) == list(pulse_path.PARTS)
    assert all(math.isfinite(s) and s > 0 for s in parts.values())
    assert math.isclose(r["total_s"], sum(parts.values()), rel_tol=1e-9)
    assert r["block_lines"] >= 1 and 0 < r["model_utilisation"]
    pulse_path.print_path(r)
    out = capsys.readouterr().out
    assert "the path" in out and "where the granularity's figures gave" in out


def test_bad_arguments_are_one_line_and_status_2(capsys):
    assert pulse_path.main(["--pulses", "0"]) == 2
    assert "--pulses must be >= 1" in capsys.readouterr().err
