"""tools/lens_beside_load.py (rtsar.app.reports.lens_load): a lens call's time alone and beside
a busy core; the figures are the machine's, so their form is checked, and the busy thread."""

from __future__ import annotations

import math
import threading
import time

from rtsar.app.reports import lens_load


def test_every_lens_and_size_is_timed_alone_and_beside_a_busy_core(capsys):
    rows = lens_load.measure("tiny", [1, 4], calls=5, rounds=2)
    assert [(r["lens"].split()[0], r["pulses_a_call"]) for r in rows] == [
        ("OpenCL", 1), ("OpenCL", 4), ("SciPy", 1), ("SciPy", 4),
    ]  # fmt: skip
    for r in rows:
        figures = [v for k, v in r.items() if k.endswith("_s")]
        assert len(figures) == 4 and all(math.isfinite(v) and v > 0 for v in figures)
        assert r["alone_median_s"] <= r["alone_p99_s"] and r["beside_median_s"] <= r["beside_p99_s"]
    lens_load.print_rows("tiny", rows)
    out = capsys.readouterr().out
    assert out.count("a call: alone") == 4 and "p99 x" in out


def test_the_busy_core_spins_until_the_with_ends():
    with lens_load.BusyCore() as busy:
        deadline = time.monotonic() + 30
        while busy.rounds < 3 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert busy.rounds >= 3 and busy._thread.is_alive()
    assert not busy._thread.is_alive()
    done = busy.rounds
    time.sleep(0.05)
    assert busy.rounds == done
    assert not [t for t in threading.enumerate() if t.name == "rtsar-busy-core"]


def test_bad_arguments_are_one_line_and_status_2(capsys):
    assert lens_load.main(["--sizes", "0,2"]) == 2
    assert lens_load.main(["--sizes", "a"]) == 2
    assert lens_load.main(["--calls", "0"]) == 2
    assert "--sizes takes whole numbers" in capsys.readouterr().err
