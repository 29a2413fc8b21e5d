"""Physical mode: real mask and intensity detection on a carrier (rtsar.physical) against
plain NumPy float64 references and physical truth.

References written here, independently of the module: the charge register as a physical array
of rows that shift down (with the full well and blooming spelled out), and the detected charge
as |reference + signal|² through the real mask (Psaltis & Wagner 1981, "Description of the
processor"), demodulated and filtered with np.convolve.
"""

import math

import numpy as np
import pytest

from rtsar.analysis import relative_rms
from rtsar.ccd.base import correlate_reference, design_mask
from rtsar.ccd.physical import PhysicalCCD
from rtsar.lens.base import compress_reference
from rtsar.lens.plan import make_plan
from rtsar.physical import (
    AOCell,
    PhysicalSettings,
    paper_ccd,
    pulses_integrated,
    range_cells,
    settings_from_dict,
)
from rtsar.physical.register import ShiftRegister
from rtsar.physical.settings import (
    AmplifierNoise,
    Bandwidth,
    Blooming,
    DiffractionSaturation,
    FixedPattern,
    Quantization,
    ReadNoise,
    ShotNoise,
    TimeAperture,
)
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene

TAPS = np.array([-3, 4, 11, 8, 11, 4, -3]) / 32.0  # the readout filter the docstring specifies


def small_config(n=64, bins=16, window="hann"):
    """psaltis-jpl geometry (azimuth band < 0.005 cycle per pulse), a small CCD."""
    return preset("psaltis-jpl").with_processor(
        aperture_pulses=n, range_bins=bins, azimuth_window=window, micro_batch=16
    )


def point_lines(cfg, extra=120):
    """Float64 range-compressed lines of three point targets (simulator + lens reference)."""
    plan = make_plan(cfg)
    rm, d = plan.range_m, cfg.geometry.along_track_step_m
    n = cfg.processor.aperture_pulses
    scene = point_scene(
        cfg,
        [0.0, 9 * d, -20 * d],
        [rm[len(rm) // 2] + 0.3, rm[3] + 1.1, rm[-4] - 0.7],
        amplitude=[1.0, 0.6, 0.3],
        pulses=n + extra,
        start_along_track_m=-(0.5 * n + 0.5 * extra) * d,
    )
    return compress_reference(plan, Simulator(scene).block(scene.pulses)), rm


def stream(dev, lines, sizes):
    out, i = [], 0
    for b in sizes:
        out.append(dev.push(lines[i : i + b]))
        i += b
    out.append(dev.push(lines[i:]))
    out.append(dev.flush())
    return np.concatenate(out)


# ---- the charge register ---------------------------------------------------------------------
def naive_register(t, inten, well, bloom, prefill):
    """Rows k = 0 (top) … R-1 (bottom, read out); every exposure adds T·I, then the overflow
    rule; the bottom row is read and everything moves down one row."""
    rows, cols = t.shape
    q = np.cumsum(np.vstack([np.zeros((1, cols)), t[:-1]]), axis=0) * prefill
    out = np.zeros_like(inten)
    overflows = drained = bloomed = 0.0
    for e in range(len(inten)):
        q += t * inten[e]
        for c in range(cols):
            col = q[:, c]
            overflows += np.count_nonzero(col > well)
            if bloom:
                for _ in range(4 * rows):
                    moved = False
                    for k in range(rows - 1, -1, -1):  # bottom row first
                        if col[k] > well:
                            ex = col[k] - well
                            col[k] = well
                            bloomed += ex
                            moved = True
                            for nb in (k + 1, k - 1):
                                if 0 <= nb < rows:
                                    col[nb] += ex / 2
                                else:
                                    drained += ex / 2
                    if not moved:
                        break
            over = col > well
            drained += np.sum(col[over] - well)
            col[over] = well
        out[e] = q[-1]
        q[1:] = q[:-1].copy()
        q[0] = 0
    return out, overflows, drained, bloomed


@pytest.mark.parametrize("bloom", [False, True])
def test_register_matches_naive_rows(bloom, rng):
    rows, cols = 12, 5
    t = rng.uniform(0, 1, (rows, cols))
    inten = rng.uniform(0, 30, (60, cols))
    inten[20:23, 2] = 400.0  # a bright burst: wells overflow
    reg = ShiftRegister(t, 150.0, bloom, prefill_e=2.0)
    got = np.concatenate([reg.expose(inten[:7])[0], reg.expose(inten[7:])[0]])
    ref, overflows, drained, bloomed = naive_register(t, inten, 150.0, bloom, 2.0)
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-9)
    assert reg.stats[:, 0].sum() == overflows > 0
    assert reg.stats[:, 1].sum() == pytest.approx(drained, rel=1e-12)
    assert reg.stats[:, 2].sum() == pytest.approx(bloomed, rel=1e-12, abs=1e-12)


def test_blooming_conserves_charge(rng):
    rows, cols = 10, 3
    t = rng.uniform(0.2, 1, (rows, cols))
    inten = rng.uniform(0, 40, (40, cols))
    inten[15, 1] = 900.0
    reg = ShiftRegister(t, 200.0, True)
    out = np.concatenate([reg.expose(inten)[0], reg.expose(np.zeros((rows, cols)))[0]])
    collected = float((inten * t.sum(axis=0)).sum())
    assert reg.stats[:, 2].sum() > 0  # charge did bloom
    # Everything collected leaves through the readout or is counted as drained at the ends.
    assert out.sum() + reg.stats[:, 1].sum() == pytest.approx(collected, rel=1e-12)


# ---- the detector against the derivation and the ideal correlator -----------------------------
def naive_physical(lines, mask, carrier, well, bias_fraction, full_scale):
    """The physical CCD of rtsar.physical.carrier written out in float64, without its code."""
    n, b = mask.shape
    e_per, k_per = (1, 2) if carrier == "range" else (2, 1)
    h = n * mask.astype(np.complex128)
    peak = np.abs(h).max()
    hn = h / peak
    rows, cols = e_per * n, k_per * b
    k = np.arange(rows)[:, None]
    cell = hn[k[:, 0] // e_per][:, np.arange(cols) // k_per]
    t = 0.5 * np.abs(cell) * (1 + np.cos(np.angle(cell) + 0.5 * np.pi * k))
    beta = math.sqrt(bias_fraction * well / t.sum(axis=0).max())
    e_u = (1 - bias_fraction) * well / full_scale
    gamma = 2 * e_u * peak / (beta * e_per * n)
    p = len(lines)
    first, last = -3, p * e_per + 3 + rows - 1  # reference light alone before and after
    e = np.arange(first, last)
    quarters = (e[:, None] + (np.arange(cols) if carrier == "range" else 0)) % 4
    field = np.zeros((len(e), cols), np.complex128)
    inside = (e >= 0) & (e < p * e_per)
    field[inside] = gamma * lines[e[inside] // e_per][:, np.arange(cols) // k_per]
    intensity = np.abs(beta * np.exp(0.5j * np.pi * quarters) + field) ** 2
    packets = np.array(
        [(t * intensity[j : j + rows]).sum(axis=0) for j in range(len(e) - rows + 1)]
    )  # packet index -3, -2, …
    y = packets - beta**2 * t.sum(axis=0)
    j = np.arange(len(y)) - 3
    if carrier == "range":
        z = 1j ** ((j[:, None] + 2 * np.arange(b)) % 4) * (y[:, 0::2] + 1j * y[:, 1::2])
    else:
        z = 2 * (1j ** (j % 4))[:, None] * y
    zf = np.array([np.convolve(z[:, r], TAPS, mode="valid") for r in range(b)]).T
    centre = j[3 : len(j) - 3]
    lines_out = zf[(centre >= 0) & (centre % e_per == 0)]
    return lines_out[: p - n + 1] / e_u


@pytest.mark.parametrize("carrier", ["range", "azimuth"])
def test_detector_equals_derivation_at_full_scale(carrier, rng):
    """Random, full-band lines at 0.3 of full scale (the |s|² term is large): the emulation is
    the derivation, eqs. P1-P4 and the readout, to float rounding."""
    cfg = small_config(n=16, bins=6, window="rect")
    rm = make_plan(cfg).range_m
    mask = design_mask(cfg, rm)
    lines = 0.3 * (rng.standard_normal((70, 6)) + 1j * rng.standard_normal((70, 6))) / 3
    settings = PhysicalSettings(carrier=carrier, full_well_e=1e9)
    got = stream(PhysicalCCD(cfg, rm, settings), lines, [1, 4, 17, 3])
    ref = naive_physical(lines, mask, carrier, 1e9, 0.5, 1.0)
    assert got.shape == ref.shape == (70 - 16 + 1, 6)
    assert relative_rms(got, ref) < 1e-6  # complex64 output


@pytest.mark.parametrize(
    "carrier, tol",
    # Measured: range 1.4e-5 (the Hann mask's leakage at 1/4 cycle per pulse), azimuth 5.6e-4
    # (odd packets straddle two pulses: an error of first order in the chirp's phase step).
    [("range", 5e-5), ("azimuth", 2e-3)],
)
def test_noiseless_detector_agrees_with_correlate_reference(carrier, tol):
    """With every effect off and a small signal (the |s|² term negligible), the physical CCD
    gives the ideal correlator's image: same lines, same scale (Psaltis eq. 5)."""
    cfg = small_config(n=128, bins=16)
    lines, rm = point_lines(cfg)
    ideal = correlate_reference(lines, design_mask(cfg, rm))
    settings = PhysicalSettings(carrier=carrier, full_scale_amplitude=1e4)
    got = stream(PhysicalCCD(cfg, rm, settings), lines, [5, 64, 1, 100])
    assert got.shape == ideal.shape
    assert relative_rms(got, ideal) < tol


def test_signal_intensity_term_is_filtered_out():
    """At 0.6 of full scale the |s|² term is 60 % of the swing at the peak; the readout filter
    removes it: the error stays that of a small signal."""
    cfg = small_config(n=128, bins=16)
    lines, rm = point_lines(cfg)
    ideal = correlate_reference(lines, design_mask(cfg, rm))
    err = {}
    for fs in (1e4, 1.0 / 0.6):
        dev = PhysicalCCD(cfg, rm, PhysicalSettings(full_scale_amplitude=fs))
        err[fs] = relative_rms(stream(dev, lines, [300]), ideal)
        assert dev.pixel_overflows == 0
    assert err[1.0 / 0.6] < 1e-4 and err[1e4] < 5e-5  # measured 3.3e-5 and 1.4e-5


def test_rectangular_mask_leaks_bias_times_signal():
    """A real mask with hard edges leaks the bias × signal term (module docstring): about
    2√2/N of the image, against ≪ with a taper."""
    errs = {}
    for window in ("rect", "hann"):
        cfg = small_config(n=128, bins=16, window=window)
        lines, rm = point_lines(cfg)
        ideal = correlate_reference(lines, design_mask(cfg, rm))
        dev = PhysicalCCD(cfg, rm, PhysicalSettings(full_scale_amplitude=1e4))
        errs[window] = relative_rms(stream(dev, lines, [300]), ideal)
    assert 1e-3 < errs["rect"] < 2 * math.sqrt(2) / 128
    assert errs["hann"] < errs["rect"] / 100


def test_device_geometry_follows_the_carrier():
    cfg = small_config(n=64, bins=16)
    rm = make_plan(cfg).range_m
    r = PhysicalCCD(cfg, rm, PhysicalSettings(carrier="range"))
    a = PhysicalCCD(cfg, rm, PhysicalSettings(carrier="azimuth"))
    assert (r.ccd_rows, r.ccd_columns, r.range_cells, r.pulses_integrated) == (64, 32, 16, 64)
    assert (a.ccd_rows, a.ccd_columns, a.range_cells, a.pulses_integrated) == (128, 16, 16, 64)
    assert (r.latency_pulses, a.latency_pulses) == (3, 2)
    # Psaltis & Wagner, Table 1: a 512 × 320 CCD holds 160 or 320 range cells, N = 512 or 256.
    assert (range_cells(320, "range"), range_cells(320, "azimuth")) == (160, 320)
    assert (pulses_integrated(512, "range"), pulses_integrated(512, "azimuth")) == (512, 256)
    assert 0 <= r.plan.transmittance.min() and r.plan.transmittance.max() <= 1
    assert r.bias_e.max() == pytest.approx(125_000)  # images on a bias: half the well


def test_lines_appear_with_the_stated_latency(rng):
    cfg = small_config(n=32, bins=4)
    rm = make_plan(cfg).range_m
    lines = rng.standard_normal((60, 4)) * 0.01 + 0j
    for carrier in ("range", "azimuth"):
        dev = PhysicalCCD(cfg, rm, PhysicalSettings(carrier=carrier))
        counts = [len(dev.push(lines[p : p + 1])) for p in range(60)]
        # Line 0 covers pulses 0..31 and leaves latency_pulses after pulse 31.
        assert np.flatnonzero(counts)[0] == 31 + dev.latency_pulses
        assert sum(counts) + len(dev.flush()) == 60 - 32 + 1
        assert len(dev.flush()) == 0  # nothing given twice


def test_nonfinite_lines_are_refused():
    cfg = small_config(n=16, bins=4)
    dev = PhysicalCCD(cfg, make_plan(cfg).range_m)
    bad = np.zeros((3, 4), np.complex64)
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        dev.push(bad)
    with pytest.raises(ValueError, match="lines must be"):
        dev.push(np.zeros((3, 5), np.complex64))


# ---- CCD effects ------------------------------------------------------------------------------
def test_read_noise_reaches_the_image_through_the_readout_filter(rng):
    """Read noise σ per pixel → per quadrature σ·√Σa² / e_u (range carrier: one pixel per
    quadrature), √Σa² = √356/32."""
    cfg = small_config(n=32, bins=16)
    rm = make_plan(cfg).range_m
    s = PhysicalSettings(ccd=(ReadNoise(500.0),), seed=4)
    dev = PhysicalCCD(cfg, rm, s)
    img = stream(dev, np.zeros((32 + 1500, 16)), [])
    expect = 500.0 * math.sqrt(356) / 32 / dev.electrons_per_unit
    assert np.std(img.real) == pytest.approx(expect, rel=0.06)
    assert np.std(img.imag) == pytest.approx(expect, rel=0.06)
    assert abs(img.mean()) < 0.1 * expect


def test_shot_noise_is_poisson_of_the_packet(rng):
    cfg = small_config(n=32, bins=8)
    rm = make_plan(cfg).range_m
    dev = PhysicalCCD(cfg, rm, PhysicalSettings(ccd=(ShotNoise(),), full_well_e=2e4))
    dev.keep_raw = True
    dev.push(np.zeros((800, 8)))
    raw = dev.last_raw_e
    assert np.allclose(raw, np.rint(raw))  # whole electrons
    assert raw.var(axis=0).mean() == pytest.approx(dev.bias_e.mean(), rel=0.05)


def test_adc_codes_and_clipping():
    cfg = small_config(n=32, bins=8)
    rm = make_plan(cfg).range_m
    s = PhysicalSettings(ccd=(Quantization(bits=6, full_scale_e=100_000.0),))
    dev = PhysicalCCD(cfg, rm, s)
    dev.keep_raw = True
    dev.push(np.zeros((40, 8)))
    lsb = 100_000.0 / 63
    assert np.allclose(dev.last_raw_e / lsb, np.rint(dev.last_raw_e / lsb))
    assert dev.last_raw_e.max() == pytest.approx(100_000.0)  # the bias (125 000) is over range
    assert dev.adc_clipped > 0


def test_the_adc_has_two_to_the_bits_levels_and_counts_clips_at_both_ends():
    """A b-bit ADC spanning 0 … full scale F has 2^b codes, 0 … 2^b − 1, a step F / (2^b − 1);
    a charge that rounds below code 0 or above the top is clipped, and counted, at either end.
    The read-out step alone, on charges placed here about those codes (bits 6, F = 1e5 e-)."""
    cfg = small_config(n=32, bins=8)
    rm = make_plan(cfg).range_m
    dev = PhysicalCCD(cfg, rm, PhysicalSettings(ccd=(Quantization(bits=6, full_scale_e=1e5),)))
    lsb = 1e5 / 63
    steps = np.array([-2.0, -0.4, 0.4, 10.3, 62.6, 63.4, 65.0])  # in steps of the true lsb
    codes = np.array([0, 0, 0, 10, 63, 63, 63])  # rint, then 0 … 63
    charge = np.tile(steps[:, None] * lsb, (1, dev.ccd_columns))
    out = dev._read(charge) + dev.bias_e  # the read-out step, its bias frame added back
    np.testing.assert_allclose(out, np.tile(codes[:, None] * lsb, (1, dev.ccd_columns)))
    assert dev.adc_clipped == 2 * dev.ccd_columns  # -2 and 65 steps: one below, one above


def test_a_target_above_the_well_is_counted_not_hidden():
    cfg = small_config(n=64, bins=16)
    lines, rm = point_lines(cfg)
    for ccd in ((), (Blooming(),)):
        dev = PhysicalCCD(cfg, rm, PhysicalSettings(full_scale_amplitude=0.3, ccd=ccd))
        out = stream(dev, lines, [50])
        assert dev.pixel_overflows > 0 and dev.saturated_lines > 0
        assert np.all(np.isfinite(out))
        if ccd:
            assert dev.bloomed_e > 0
        else:
            assert dev.drained_e > 0 and dev.bloomed_e == 0


def test_dark_charge_pattern_is_removed_by_the_carrier():
    """A fixed dark charge per pixel sums to a constant per column: after demodulation it sits
    at 1/4 cycle per packet, a zero of the readout filter."""
    cfg = small_config(n=64, bins=16)
    lines, rm = point_lines(cfg)
    clean = stream(PhysicalCCD(cfg, rm, PhysicalSettings()), lines, [40])
    s = PhysicalSettings(ccd=(FixedPattern(gain_rms=0.0, dark_e=300.0, dark_rms_e=80.0),))
    dark = stream(PhysicalCCD(cfg, rm, s), lines, [40])
    assert relative_rms(dark, clean) < 1e-9


def test_pixel_gain_pattern_is_averaged_by_the_shift():
    """Each packet crosses all N rows: a responsivity pattern of rms σ perturbs the mask by
    T·δg, the image by about σ·rms(T)/(¼√N) ≈ 2.4σ/√N (measured 1.9σ/√N), not by σ."""
    cfg = small_config(n=128, bins=16)
    lines, rm = point_lines(cfg)
    clean = stream(PhysicalCCD(cfg, rm, PhysicalSettings()), lines, [40])
    s = PhysicalSettings(ccd=(FixedPattern(gain_rms=0.05),), seed=2)
    err = relative_rms(stream(PhysicalCCD(cfg, rm, s), lines, [40]), clean)
    assert 0.05 / math.sqrt(128) < err < 4 * 0.05 / math.sqrt(128)


# ---- the AO cell -------------------------------------------------------------------------------
def test_ao_cell_off_costs_nothing(rng):
    cfg = preset("tiny")
    shots = (rng.standard_normal((3, cfg.waveform.samples_per_shot)) + 0j).astype(np.complex64)
    assert AOCell(cfg).apply(shots) is shots


def test_ao_bandwidth_is_minus_3_db_at_half_the_band():
    cfg = preset("tiny")
    wf = cfg.waveform
    n = np.arange(wf.samples_per_shot)
    s = PhysicalSettings(ao=(Bandwidth(20e6),))
    for f_hz, gain in ((0.0, 1.0), (10e6, 1 / math.sqrt(2))):
        tone = np.exp(2j * np.pi * f_hz * n / wf.sample_rate_hz)[None, :]
        out = AOCell(cfg, s).apply(tone)
        mid = slice(40, -40)  # away from the shot's edges
        assert np.abs(out[0, mid]) == pytest.approx(gain, rel=2e-3)


def test_ao_diffraction_saturates():
    cfg = preset("tiny")
    s = PhysicalSettings(ao=(DiffractionSaturation(2.0),))
    amp = np.array([1e-3, 1.0, 2.0, 3.0])
    shots = np.tile(amp[:, None], (1, cfg.waveform.samples_per_shot)) * np.exp(0.7j)
    out = AOCell(cfg, s).apply(shots)[:, 0]
    # a_sat·(2/π)·sin(π a / (2 a_sat)), phase kept
    expect = 2.0 * 2 / np.pi * np.sin(np.pi * amp / 4.0)
    np.testing.assert_allclose(np.abs(out), expect, rtol=1e-6)
    np.testing.assert_allclose(np.angle(out), 0.7, atol=1e-6)


def test_ao_time_aperture_and_attenuation():
    cfg = preset("tiny")
    wf = cfg.waveform  # 4 µs at 48 MHz: 192 samples
    s = PhysicalSettings(ao=(TimeAperture(aperture_s=2e-6, attenuation_db=6.0),))
    out = AOCell(cfg, s).apply(np.ones((1, wf.samples_per_shot)))[0]
    held = np.flatnonzero(out)
    assert len(held) == 96 and held[0] == 48
    assert abs(out[held[0]]) == pytest.approx(10 ** (-6 / 20), rel=1e-6)  # the oldest sample
    assert abs(out[held[-1]]) == pytest.approx(1.0, rel=1e-6)


def test_ao_amplifier_noise_level():
    cfg = preset("tiny")
    s = PhysicalSettings(ao=(AmplifierNoise(0.5),), seed=9)
    out = AOCell(cfg, s).apply(np.zeros((200, cfg.waveform.samples_per_shot)))
    assert np.sqrt(np.mean(np.abs(out) ** 2)) == pytest.approx(0.5, rel=0.02)
    with pytest.raises(ValueError, match="NaN"):
        AOCell(cfg, s).apply(np.full((1, cfg.waveform.samples_per_shot), np.nan))


# ---- settings ----------------------------------------------------------------------------------
def test_settings_from_table_round_trip():
    table = {
        "carrier": "azimuth",
        "full_well_e": 2e5,
        "ccd": {"read_noise": {"sigma_e": 150.0}, "shot_noise": {}, "blooming": None},
        "ao": {"bandwidth": {"bandwidth_hz": 30e6}},
    }
    s = settings_from_dict(table)
    assert s.carrier == "azimuth" and s.ccd_effect("read_noise").sigma_e == 150.0
    assert s.ccd_effect("quantization") is None and s.ao_effect("bandwidth").bandwidth_hz == 30e6
    assert settings_from_dict(s.to_dict()) == s
    assert paper_ccd().ccd_effect("read_noise").sigma_e == 200.0


@pytest.mark.parametrize(
    "table, match",
    [
        ({"carrier": "diagonal"}, "carrier"),
        ({"bias_fraction": 1.0}, "bias_fraction"),
        ({"full_well_e": float("nan")}, "full_well_e"),
        ({"colour": 1}, "unknown keys"),
        ({"ccd": {"cosmic_rays": {}}}, "unknown physical.ccd effect"),
        ({"ccd": {"read_noise": {"sigma": 1}}}, "unknown parameters"),
        ({"ccd": {"quantization": {"bits": 0}}}, "bits"),
        ({"ao": {"bandwidth": {"bandwidth_hz": -1.0}}}, "bandwidth_hz"),
    ],
)
def test_settings_refuse_bad_tables(table, match):
    with pytest.raises(ValueError, match=match):
        settings_from_dict(table)
