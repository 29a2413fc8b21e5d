"""Scene files, the simulator's exact range history, and opt-in effects."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

from rtsar.lens.base import compress_reference
from rtsar.lens.plan import make_plan
from rtsar.presets import preset
from rtsar.scene import DEMO_SCENE, Simulator, load_scene, point_scene, scene_from_dict
from rtsar.scene import effects as effects_pkg
from rtsar.scene.effects.base import Effect


def _peak_phase(cfg, scene, pulse):
    sim = Simulator(scene)
    shots = sim.block(pulse + 1)
    line = compress_reference(make_plan(cfg), shots[-1:])[0]
    k = np.argmax(np.abs(line))
    return np.angle(line[k]), k


@pytest.mark.parametrize("name, offset_m", [("tiny", 200.0), ("crouch-sal", 0.1)])
def test_phase_follows_exact_range_history(name, offset_m):
    """The compressed peak phase is -4π·sqrt(R² + x²)/λ, not the parabolic approximation."""
    cfg = preset(name)
    plan = make_plan(cfg)
    lam = cfg.geometry.wavelength_m
    r0 = plan.range_m[plan.bin_count // 2]

    def wrap(a):
        return np.angle(np.exp(1j * a))

    # The same target seen from broadside and from along-track offset x (one pulse each).
    broadside, _ = _peak_phase(
        cfg, point_scene(cfg, [0.0], [r0], start_along_track_m=0.0, pulses=1), 0
    )
    seen, _ = _peak_phase(
        cfg, point_scene(cfg, [0.0], [r0], start_along_track_m=offset_m, pulses=1), 0
    )
    exact = -4 * np.pi * (np.hypot(r0, offset_m) - r0) / lam
    parabolic = -4 * np.pi * offset_m**2 / (2 * r0) / lam
    assert abs(wrap(seen - broadside - exact)) < 0.02
    # On this geometry the two models differ by more than half a radian: the test can tell.
    assert abs(wrap(exact - parabolic)) > 0.5


def test_scene_toml_errors(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('preset = "tiny"\n[[targets]]\nalong_track_m = 0\nslant_rnge_m = 2000\n')
    with pytest.raises(ValueError, match="slant_rnge_m"):
        load_scene(bad)
    bad.write_text('preset = "tiny"\n[geometry]\nwavelenght_m = 1\n')
    with pytest.raises(ValueError, match="wavelenght_m"):
        load_scene(bad)
    bad.write_text('preset = "tiny"\n[[effects]]\nname = "fog"\n')
    with pytest.raises(ValueError, match="fog"):
        Simulator(load_scene(bad))
    bad.write_text("preset = ")
    with pytest.raises(ValueError, match="TOML"):
        load_scene(bad)
    with pytest.raises(ValueError, match="not found"):
        load_scene(tmp_path / "missing.toml")


def test_demo_scene_loads():
    scene = load_scene(DEMO_SCENE)
    assert scene.config.processor.aperture_pulses == 512
    assert {n for n, _ in scene.effects} == {"noise", "antenna_pattern"}


def test_ground_range_with_height():
    d = {
        "preset": "tiny",
        "geometry": {"platform_height_m": 1000.0},
        "targets": [{"along_track_m": 0.0, "ground_range_m": 1700.0, "height_m": 20.0}],
    }
    scene = scene_from_dict(d)
    assert scene.targets.slant_range_m[0] == pytest.approx(np.hypot(1700.0, 980.0))


class _Spy(Effect):
    calls = 0
    made = 0

    def __init__(self, config, **params):
        type(self).made += 1

    def target_gain(self, pulse, along_offset_m, slant_range_m):
        type(self).calls += 1
        return np.ones_like(slant_range_m)

    def apply_to_shot(self, pulse, samples, rng):
        type(self).calls += 1


def test_unnamed_effect_is_never_called(monkeypatch):
    monkeypatch.setitem(effects_pkg.REGISTRY, "spy", f"{__name__}:_Spy")
    cfg = preset("tiny")
    plain = point_scene(cfg, [0.0], [2000.0], pulses=20)
    _Spy.calls = _Spy.made = 0
    list(Simulator(plain).shots())
    assert _Spy.made == 0 and _Spy.calls == 0
    named = point_scene(cfg, [0.0], [2000.0], pulses=20, effects=[("spy", {})])
    list(Simulator(named).shots())
    assert _Spy.made == 1 and _Spy.calls == 40  # both hooks, every pulse


def test_unnamed_effect_is_not_even_imported():
    code = textwrap.dedent("""
        import sys
        from rtsar.presets import preset
        from rtsar.scene import Simulator, point_scene
        list(Simulator(point_scene(preset("tiny"), [0.0], [2000.0], pulses=5)).shots())
        print(sorted(m for m in sys.modules if m.startswith("rtsar.scene.effects.")))
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['rtsar.scene.effects.base']"


def test_noise_has_the_stated_snr():
    cfg = preset("tiny")
    scene = point_scene(cfg, [], [], pulses=400, effects=[("noise", {"snr_db": 6.0})], seed=1)
    shots = Simulator(scene).block(400)
    power = np.mean(np.abs(shots.astype(np.complex128)) ** 2)
    assert power == pytest.approx(10 ** (-0.6), rel=0.02)
    again = Simulator(scene).block(400)
    np.testing.assert_array_equal(shots, again)  # seeded: deterministic


def test_antenna_pattern_two_way_sinc_squared():
    cfg = preset("tiny")
    from rtsar.scene.effects.antenna import AntennaPattern

    ap = AntennaPattern(cfg)
    lam, d = cfg.geometry.wavelength_m, cfg.geometry.antenna_length_m
    r = np.array([2000.0, 2000.0])
    off = np.array([0.0, lam * 2000.0 / d])  # on axis and at the first null
    np.testing.assert_allclose(ap.target_gain(0, off, r), [1.0, 0.0], atol=1e-12)


def test_shots_come_in_order():
    sim = Simulator(point_scene(preset("tiny"), [0.0], [2000.0], pulses=4))
    sim.shot(0)
    with pytest.raises(ValueError, match="in order"):
        sim.shot(2)


def test_scene_errors_name_the_key(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text('preset = "tiny"\n[targets]\nalong_track_m = 0\n')
    with pytest.raises(ValueError, match=r"\[\[targets\]\]"):
        load_scene(f)
    f.write_text('preset = "tiny"\n[[targets]]\nalong_track_m = 0\nslant_range_m = "far"\n')
    with pytest.raises(ValueError, match=r"targets\[0\]\.slant_range_m"):
        load_scene(f)
    f.write_text('preset = "tiny"\n[[effects]]\nname = "noise"\nsnr = 3\n')
    with pytest.raises(ValueError, match=r"s\.toml.*'snr'.*snr_db"):
        load_scene(f)


def test_targets_outside_the_swath_are_reported():
    cfg = preset("tiny")
    scene = point_scene(cfg, [0.0, 0.0], [2000.0, 20000.0])
    assert scene.targets_outside_swath() == [1]


def test_ground_targets_keep_their_3d_position():
    from rtsar.scene.model import scene_from_dict

    d = {
        "preset": "zhao-insal",
        "geometry": {"platform_height_m": 1.386},
        "targets": [
            {"along_track_m": 0.0, "ground_range_m": 1.96, "height_m": 0.002},
            {"along_track_m": 0.001, "slant_range_m": 2.4},
        ],
    }
    t = scene_from_dict(d).targets
    np.testing.assert_allclose(t.height_m, [0.002, 0.0])
    # the slant-range target sits on the reference plane at the ground range it implies
    np.testing.assert_allclose(t.ground_range_m, [1.96, (2.4**2 - 1.386**2) ** 0.5])
    np.testing.assert_allclose(t.slant_range_m[0], (1.96**2 + (1.386 - 0.002) ** 2) ** 0.5)
