"""The simulator-cost report's numbers (rtsar.app.reports.sim_cost), its clocks replaced by
ones whose readings are chosen here: what is checked is what the code controls (which scene it
times, over which pulses, how it divides and groups), never this machine's speed.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from rtsar.app.reports import sim_cost as report
from rtsar.lens.plan import range_axis_m
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene
from rtsar.scene.effects import REGISTRY


class Clock:
    """A clock that moves only when the simulator below says so."""

    def __init__(self):
        self.now = 100.0
        self.cpu = 7.0

    def perf_counter(self):
        return self.now

    def thread_time(self):
        return self.cpu


@pytest.fixture
def timed(monkeypatch):
    """The report's clock and simulator: each simulated pulse costs ``cost_s(scene)`` seconds of
    CPU (and twice that of wall time); every block asked of the simulator is recorded."""
    clock = Clock()
    log = SimpleNamespace(scenes=[], blocks=[], cost_s=lambda scene: 1e-5)

    class Timed(Simulator):
        def __init__(self, scene):
            super().__init__(scene)
            log.scenes.append(scene)

        def block(self, n):
            log.blocks.append(n)
            cost_s = log.cost_s(self.scene)
            clock.cpu += n * cost_s
            clock.now += 2 * n * cost_s
            return super().block(n)

    monkeypatch.setattr(report, "time", clock)
    monkeypatch.setattr(report, "Simulator", Timed)
    return log


@pytest.mark.parametrize("targets", [1, 32])
def test_cost_per_pulse_of_n_targets(timed, targets):
    """cost_us builds a scene of ``targets`` random points inside the aperture's reach and the
    range swath, warms up on 16 pulses, and divides the rest's time by their count."""
    cfg = preset("tiny")
    timed.cost_s = lambda scene: 1e-6 * len(scene.targets)  # a simulator linear in targets
    cost = report.cost_us(cfg, targets, 48, [("noise", {"snr_db": 0.0})])
    (scene,) = timed.scenes
    assert len(scene.targets) == targets
    assert [tuple(e) for e in scene.effects] == [("noise", {"snr_db": 0.0})]
    rm = range_axis_m(cfg)
    assert np.all(np.abs(scene.targets.along_track_m) <= cfg.synthetic_aperture_m)
    assert np.all((scene.targets.slant_range_m >= rm[0]) & (scene.targets.slant_range_m <= rm[-1]))
    assert timed.blocks == [16, 32]
    assert cost == pytest.approx(2 * targets)  # wall µs per pulse: 2 × 1 µs × targets


def test_scene_cost_per_second_of_flight(timed):
    """A 500 Hz scene of 1200 pulses is timed in seconds of flight (500, 500, 200 pulses); the
    first second (numba's load) is reported apart from the steady mean and the worst second."""
    cfg = preset("tiny")
    assert cfg.geometry.prf_hz == 500.0
    scene = point_scene(cfg, [0.0, 3.0], [2000.0, 2005.0], pulses=1200, start_along_track_m=0.0)
    per_block = iter([5e-3 / 500, 5e-3 / 500, 5e-3 / 200])  # 5 ms of CPU per block
    timed.cost_s = lambda s: next(per_block)
    c = report.scene_cost(scene)
    assert timed.blocks == [500, 500, 200]
    assert c["scatterers"] == 2 and c["pulses"] == 1200
    assert c["period_us"] == pytest.approx(2000.0)
    assert c["first_second_cpu_us_per_pulse"] == pytest.approx(10.0)
    assert c["cpu_us_per_pulse"] == pytest.approx((10.0 + 25.0) / 2)
    assert c["worst_second_cpu_us_per_pulse"] == pytest.approx(25.0)
    assert c["wall_us_per_pulse"] == pytest.approx(2 * 17.5)
    timed.blocks.clear()
    timed.cost_s = lambda s: 1e-5
    assert report.scene_cost(scene, 700)["pulses"] == 700
    assert timed.blocks == [500, 200]


def test_print_scene_cost_shares_of_the_period(capsys):
    report.print_scene_cost({
        "scene": "s", "scatterers": 2, "pulses": 1200, "prf_hz": 500.0, "period_us": 2000.0,
        "first_second_cpu_us_per_pulse": 90.0, "cpu_us_per_pulse": 500.0,
        "worst_second_cpu_us_per_pulse": 1500.0, "wall_us_per_pulse": 700.0,
    })  # fmt: skip
    out = capsys.readouterr().out
    assert "500.0 µs/pulse  (25 % of the period; worst second 1500.0 µs, 75 %)" in out
    assert "(period 2000.0 µs)" in out


def test_effects_table_on_a_pulsed_preset(timed, capsys):
    """The default preset (psaltis-jpl, a pulsed radar): every effect it can take has a row
    adding that effect alone, 'all' adds them together, the ratios are to 'none' (each effect
    costs one more µs per pulse here); the FMCW-only channels are listed apart with the
    reason, not a traceback (before the fix: ValueError from reference_interferometer)."""
    timed.cost_s = lambda scene: 1e-6 * (1 + len(scene.effects))
    assert report.main(["--targets", "2", "--pulses", "20"]) == 0
    out = capsys.readouterr().out
    rows = {ln.split()[0]: ln for ln in out.splitlines()[1:]}
    assert rows["none"].endswith("( 1.00x)") and rows["noise"].endswith("( 2.00x)")
    assert rows["antenna_pattern"].endswith("( 2.00x)")
    left_out = [n for n in REGISTRY if "left out:" in rows.get(n, "")]
    timed_rows = [n for n in REGISTRY if n in rows and n not in left_out]
    assert "reference_interferometer" in left_out and "hcn_cell" in left_out
    assert "needs an FMCW waveform" in rows["hcn_cell"]
    assert rows["all"].endswith(f"({1 + len(timed_rows):5.2f}x)")
    singles = [s.effects for s in timed.scenes if len(s.effects) == 1]
    assert sorted(e[0][0] for e in singles) == sorted(timed_rows * 3)  # three rounds


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--scene", "no-such-scene"], "no-such-scene"),
        (["--preset", "no-such-preset"], "no-such-preset"),
        (["--pulses", "16"], "--pulses must be at least 17"),
        (["--scene", "demo", "--pulses", "0"], "--pulses must be at least 1"),
    ],
)
def test_bad_input_is_one_line(argv, words, capsys):
    assert report.main(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("sim_cost: ") and words in err and err.count("\n") == 1
