"""The swath-process model's numbers (rtsar.app.reports.swath_model), from chosen per-pulse
costs worked out by hand with the formulas of its docstring:

    one process  c / (t_lens + t_ccd(1))
    K workers    min(c / (t_lens + t_ccd(1/K) + t_in + t_out(1/K)), 1 / (K (t_in + t_out(1/K))))
    one host     c / (K (t_lens + t_ccd(1/K) + t_in + t_out(1/K)))

Its measurement (a lens survey, minutes) is not run: main is fed these costs instead.
"""

from __future__ import annotations

import json
import os

import pytest

from rtsar.app.reports import swath_model as report

US = 1e-6
# t_lens 3 µs, the correlator 8 µs split K ways, 0.5 µs in, 1/K µs out
COSTS = {"t_lens": 3 * US, "t_in": 0.5 * US}
for _k in (1, 2, 4, 8):
    COSTS[f"t_ccd(1/{_k})"] = 8 * US / _k
    COSTS[f"t_out(1/{_k})"] = 1 * US / _k

# By hand, 2 cores: one process 2/(3 + 8) µs = 181,818/s.
#   K=2: worker 3 + 4 + 0.5 + 0.5 = 8 µs → 250,000/s; coordinator 2·1 µs → 500,000/s
#   K=4: worker 3 + 2 + 0.5 + 0.25 = 5.75 µs → 347,826/s; coordinator 4·0.75 = 3 µs → 333,333/s
#   K=8: worker 3 + 1 + 0.5 + 0.125 = 4.625 µs → 432,432/s; coordinator 8·0.625 = 5 µs → 200,000/s
EXPECTED = {  # workers: (separate hosts, one host)
    1: (2 / 11e-6, 2 / 11e-6),
    2: (250_000.0, 2 / (2 * 8e-6)),
    4: (1 / 3e-6, 2 / (4 * 5.75e-6)),
    8: (200_000.0, 2 / (8 * 4.625e-6)),
}


def test_model_by_hand():
    rows = report.model(COSTS, cores=2)
    assert [r["workers"] for r in rows] == [1, 2, 4, 8]
    one = 2 / 11e-6
    for r in rows:
        hosts, host = EXPECTED[r["workers"]]
        assert r["separate_hosts"] == pytest.approx(hosts, rel=1e-12)
        assert r["one_host"] == pytest.approx(host, rel=1e-12)
        assert r["over_one_process"] == pytest.approx(hosts / one, rel=1e-12)
    # 4 workers are held by the coordinator, 8 even more so: the best K is 4, not 8
    best = max(rows, key=lambda r: r["separate_hosts"])
    assert best["workers"] == 4
    assert all(r["one_host"] <= one for r in rows)


def test_model_scales_with_cores():
    """Twice the cores: twice one process and each worker, the coordinator (one core) not."""
    two, four = report.model(COSTS, cores=2), report.model(COSTS, cores=4)
    assert four[0]["separate_hosts"] == pytest.approx(2 * two[0]["separate_hosts"])
    assert four[1]["separate_hosts"] == pytest.approx(500_000.0)  # now the coordinator's
    assert four[3]["separate_hosts"] == pytest.approx(two[3]["separate_hosts"])


def test_main_prints_the_crossover(monkeypatch, tmp_path, capsys):
    """main with the costs above: K = 2 is the first K on separate hosts to beat one process;
    the JSON holds the rows; the one-thread settings do not override what is already set."""
    for name in ("RTSAR_CACHE_DIR", "NUMBA_NUM_THREADS", "POCL_MAX_PTHREAD_COUNT",
                 "OMP_NUM_THREADS"):  # fmt: skip
        monkeypatch.setenv(name, str(tmp_path) if name == "RTSAR_CACHE_DIR" else "2")

    def measured(args):
        return {"preset": args.preset, "correlator": args.correlator, "micro_batch": 64,
                "lens": "NumPy lens", "seconds_per_pulse": dict(COSTS)}  # fmt: skip

    monkeypatch.setattr(report, "measure", measured)
    out = tmp_path / "m.json"
    assert report.main(["--preset", "tiny", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "crossover: K = 2 workers on separate hosts beat one process" in text
    assert "  t_lens            3.00 µs/pulse" in text
    assert "   2      250,000      125,000                   1.38" in text
    saved = json.loads(out.read_text())
    assert saved["crossover"].startswith("K = 2 workers")
    assert [r["workers"] for r in saved["model_2_cores"]] == [1, 2, 4, 8]
    assert os.environ["NUMBA_NUM_THREADS"] == "2"  # setdefault: the caller's choice stands


def test_no_crossover_when_transfers_cost_more_than_the_correlator():
    slow = dict(COSTS, t_in=20 * US)
    rows = report.model(slow)
    assert all(r["over_one_process"] < 1 for r in rows[1:])
