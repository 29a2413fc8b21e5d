"""Extended scenes drawn from pictures, and the fast tone synthesis that simulates them live."""

import math
import subprocess
import sys

import numpy as np
import pytest

from rtsar.lens.plan import range_axis_m, receive_window_open_s
from rtsar.params import C_M_PER_S, PulsedChirp
from rtsar.presets import preset
from rtsar.scene import Simulator, load_scene, point_scene, scene_from_dict
from rtsar.scene.effects import load_effects
from rtsar.scene.files import scene_from_table
from rtsar.scene.picture import picture_levels, picture_targets, text_rows
from rtsar.scene.surfaces import resolution_cell_m
from rtsar.stream.engine import process_block


def naive_echo(cfg, range_m, gain):
    """The simulator's formula (rtsar.scene.simulator docstring), one exponential per scatterer
    and sample, float64 phases reduced mod 1 cycle."""
    wf, lam = cfg.waveform, cfg.geometry.wavelength_m
    n = np.arange(wf.samples_per_shot)
    out = np.zeros(n.size, np.complex128)
    for r, g in zip(range_m, gain, strict=True):
        tau = 2 * r / C_M_PER_S
        if isinstance(wf, PulsedChirp):
            t = receive_window_open_s(cfg) + n / wf.sample_rate_hz
            u = t - tau - wf.pulse_duration_s / 2
            inside = (t >= tau - 1e-15) & (t < tau + wf.pulse_duration_s)
            cyc = -2 * r / lam + 0.5 * wf.chirp_rate_hz_per_s * u * u
            out += np.where(inside, g * np.exp(2j * np.pi * np.mod(cyc, 1.0)), 0)
        else:
            t = (n - n.size / 2) / wf.sample_rate_hz
            r_lo = wf.reference_range_m
            tau_ref, dtau = 2 * r_lo / C_M_PER_S, 2 * (r - r_lo) / C_M_PER_S
            k = wf.chirp_rate_hz_per_s
            cyc = -2 * (r - r_lo) / lam - k * dtau * t + 0.5 * k * dtau * (tau + tau_ref)
            out += g * np.exp(2j * np.pi * np.mod(cyc, 1.0))
    return out


@pytest.mark.parametrize("name", ["psaltis-jpl", "tiny", "zhao-insal", "crouch-sal"])
def test_tone_synthesis_equals_the_formula(name):
    """The factored tones (one multiply-add per sample) give the formula's samples to 1e-9 of the
    summed amplitudes, also for returns cut by the window's edges and zero gains."""
    cfg = preset(name)
    rm = range_axis_m(cfg)
    rng = np.random.default_rng(5)
    span = rm[-1] - rm[0]
    r = rng.uniform(rm[0] - 0.4 * span, rm[-1] + 0.4 * span, 60)  # some partly outside
    g = rng.standard_normal(60) + 1j * rng.standard_normal(60)
    g[::7] = 0
    sim = Simulator(point_scene(cfg, [0.0], [rm[0]], pulses=1))
    fast, direct, ref = sim.echo(r, g), sim.direct_echo(r, g), naive_echo(cfg, r, g)
    scale = np.abs(g).sum()
    assert np.abs(fast - ref).max() <= 1e-9 * scale
    assert np.abs(direct - ref).max() <= 1e-9 * scale
    assert np.abs(ref).max() > 0.05 * scale  # the returns are in the window


def test_main_lobe_only_skips_unseen_scatterers_without_changing_a_sample():
    """With the antenna's main lobe only, the simulator synthesises only the scatterers in the
    beam; every shot equals the formula over all scatterers with the antenna's gains."""
    cfg = preset("tiny")
    rm = range_axis_m(cfg)
    rng = np.random.default_rng(2)
    x = rng.uniform(-300, 300, 400)
    r = rng.uniform(rm[0], rm[-1], 400)
    a = np.exp(2j * np.pi * rng.random(400))
    effects = [("antenna_pattern", {"antenna_length_m": 4.0, "main_lobe_only": True})]
    scene = point_scene(cfg, x, r, a, effects=effects, pulses=40, start_along_track_m=-10.0)
    sim = Simulator(scene)
    assert sim._seen is not None  # the shortcut is taken
    shots = sim.block(40)
    antenna = load_effects(effects, cfg)[0]
    for p in (0, 17, 39):
        offset = x - scene.along_track_of(p)
        rp = np.sqrt(r**2 + offset**2)
        gain = a * antenna.target_gain(p, offset, rp)
        assert 0 < np.count_nonzero(gain) < len(x) // 2  # the beam sees some, not all
        ref = naive_echo(cfg, rp, gain)
        assert np.abs(shots[p] - ref).max() <= 1e-6 * np.abs(ref).max()


def test_pictures_make_a_seeded_speckle_grid_of_the_drawing():
    cfg = preset("tiny")
    levels = picture_levels(["#.", ".o"])
    assert levels.tolist() == [[1.0, 0.0], [0.0, 0.6]]
    rho_a, rho_r = resolution_cell_m(cfg, 2000.0)
    box = ((0.0, 40 * rho_a), (2000.0 - 20 * rho_r, 2000.0 + 20 * rho_r))
    t = picture_targets(cfg, levels, *box, cell_power=2.0, cells_per_scatterer=(1.0, 1.0), seed=4)
    # 40 x 40 grid points, one quadrant of level 1 and one of level 0.6
    assert len(t) == 2 * 20 * 20
    top = t.along_track_m < 20 * rho_a
    assert np.all(t.slant_range_m[top] < 2000.0) and np.all(t.slant_range_m[~top] > 2000.0)
    assert np.diff(np.unique(t.along_track_m)).min() >= rho_a * 0.999
    power = np.abs(t.amplitude) ** 2
    assert power[top].mean() == pytest.approx(2.0, rel=0.15)  # Rayleigh: E|a|² = level·power
    assert power[~top].mean() == pytest.approx(1.2, rel=0.15)
    again = picture_targets(cfg, levels, *box, cell_power=2.0, seed=4)
    assert np.array_equal(again.amplitude, t.amplitude)
    assert not np.array_equal(picture_targets(cfg, levels, *box, seed=5).amplitude, t.amplitude)
    with pytest.raises(ValueError, match="cells_per_scatterer"):
        picture_targets(cfg, levels, *box, cells_per_scatterer=(0.5, 1.0))
    with pytest.raises(ValueError, match="glyph"):
        text_rows("SAR?")
    with pytest.raises(ValueError, match="levels"):
        picture_levels(["#x"])


def test_a_drawn_picture_is_what_the_processor_shows():
    """A '+' drawn in speckle on the tiny preset, focused by the engine: the arms are ≥ 10 dB
    brighter than the picture's empty corners."""
    cfg = preset("tiny")
    rho_a, rho_r = resolution_cell_m(cfg, 2000.0)
    x0, x1 = 0.0, 24 * rho_a
    d = {
        "preset": "tiny",
        "seed": 1,
        "pictures": [
            {
                "rows": [".#.", "###", ".#."],
                "along_track_m": [x0, x1],
                "slant_range_m": [2000.0 - 12 * rho_r, 2000.0 + 12 * rho_r],
                "cell_power": 1.0,
            }
        ],
    }
    scene = scene_from_table(d)
    shots = Simulator(scene).block(scene.pulses)
    image, az, rg = process_block(cfg, shots, "numpy", scene.start_along_track_m)
    power = np.abs(image) ** 2

    def mean_in(a0, a1, r0, r1):
        rows = (az >= a0) & (az < a1)
        cols = (rg >= r0) & (rg < r1)
        return power[np.ix_(rows, cols)].mean()

    third_a, third_r = (x1 - x0) / 3, 8 * rho_r
    r_lo = 2000.0 - 12 * rho_r
    centre = mean_in(x0 + third_a, x1 - third_a, r_lo + third_r, r_lo + 2 * third_r)
    corner = mean_in(x0 + 0.25 * third_a, x0 + 0.75 * third_a, r_lo, r_lo + 0.5 * third_r)
    assert 10 * math.log10(centre / corner) > 10


def test_scene_files_with_pictures(tmp_path):
    demo = load_scene("demo")
    assert len(demo.targets) > 1000 and demo.pulses == 16000
    assert {n for n, _ in demo.effects} == {"noise", "antenna_pattern"}
    # A recorded scene description lists every scatterer and reads back the same.
    back = scene_from_dict(demo.to_dict())
    assert np.allclose(back.targets.amplitude, demo.targets.amplitude, rtol=1e-12, atol=1e-15)
    sal = load_scene("sal-demo")
    assert sal.config.waveform.kind == "fmcw" and len(sal.targets) > 1000
    bad = tmp_path / "bad.toml"
    bad.write_text('preset = "tiny"\n[[pictures]]\ntext = "SAR"\nalong_track_m = [0, 10]\n')
    with pytest.raises(ValueError, match=r"bad.toml: pictures\[0\]: slant_range_m"):
        load_scene(bad)
    bad.write_text(
        'preset = "tiny"\n[[pictures]]\ntext = "A"\nrows = ["#"]\n'
        "along_track_m = [0, 10]\nslant_range_m = [1990, 2010]\n"
    )
    with pytest.raises(ValueError, match="exactly one of text, rows"):
        load_scene(bad)
    bad.write_text(
        'preset = "tiny"\n[[pictures]]\ntext = "A"\ncolour = 1\n'
        "along_track_m = [0, 10]\nslant_range_m = [1990, 2010]\n"
    )
    with pytest.raises(ValueError, match="colour"):
        load_scene(bad)


def test_a_simulated_source_readies_its_kernels_before_the_schedule():
    """SimSource.prepare (called by `rtsar run` while it says "preparing …") leaves the tone
    kernels compiled or loaded, so the first live shot does not wait for numba."""
    code = (
        "from rtsar.scene import load_scene, tones\n"
        "from rtsar.sources.sim import SimSource\n"
        "src = SimSource(load_scene('demo'), 16)\n"
        "assert not tones._tone_sum.signatures\n"
        "src.prepare()\n"
        "assert tones._tone_sum.signatures and tones._pulsed_tones.signatures\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
