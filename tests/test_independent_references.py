"""rtsar's lens, simulator and focused image against references that share none of its code
(tests/independent.py: the papers' equations, the documented conventions), issue 39, item 1.

The references the other tests use are built from rtsar's own pieces (``compress_reference``
from ``make_plan``, ``correlate_reference`` from ``design_mask``, the simulator's timing from
``rtsar/lens/plan.py``), so a fault in those pieces passes them; here every expected value comes
from the chirp's definition, τ = 2R/c and R(t) = sqrt(R0² + (v t)²).

Cases: the ``tiny`` preset (pulsed LFM; for the simulator also with a fixed receive window) and
crouch-sal (FMCW dechirp) cut to a 256-pulse aperture and 64 range bins (for the lens also with
the DFT zero-padded twice).  Tolerances, with what was measured when they were set:

* lens, any target: lines within 1e-3 of the peak (pulsed: 5.5e-4, rtsar's lens keeps the band
  on its 256-point transform grid, 213 bins, not the continuous band |f| <= B/2) or 1e-5 (FMCW:
  6e-8, complex64); peak position within 0.002 cell of the reference's (6e-5) and 0.02 cell of
  the target's range (0.005 here, up to 0.010 over a sweep of offsets: a gate of whole samples
  moves a fractionally delayed echo's response, and a 64-bin cut interpolates with a bias);
  -3 dB width within 0.2 % (0.05 %); the phase of a target on a bin within 1e-3 rad of the
  convention (4e-9 pulsed, 7e-7 FMCW: its residual video phase);
* simulator: the same samples gated, delay within 1e-3 sample (pulsed) or 1e-3 range cell
  (FMCW), phase within 1e-3 rad (both below 1e-8), each sample within 1e-5 (4e-8: complex64);
* image: within 1e-3 (pulsed, 5.2e-4) or 1e-5 (FMCW, 1.3e-7) of the peak; peak position within
  0.01 cell of the reference's (2e-5), IRW within 1 % (4e-4); the reference's own peak within
  0.02 cell of the target (0.008) and its azimuth IRW within 1 % of 0.886 λR/(2Nd) (0.15 %).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from independent import (
    azimuth_axis_m,
    compress,
    echo,
    focus,
    peak_and_width,
    point_shots,
    range_axis_m,
    range_centre_m,
)

from rtsar.lens import make_lens, make_plan
from rtsar.presets import preset
from rtsar.scene.model import point_scene
from rtsar.scene.simulator import Simulator
from rtsar.stream.engine import process_block


def _tiny():
    return preset("tiny")


def _crouch_small():
    return preset("crouch-sal").with_processor(aperture_pulses=256, range_bins=64)


def _tiny_fixed_window():
    """tiny as an instrument with a fixed receive window: first sample 13.3 µs after the
    pulse centre (the scene centre's echo, 13.34 µs, begins inside it)."""
    cfg = _tiny()
    return replace(cfg, waveform=replace(cfg.waveform, window_start_s=1.33e-5))


def _crouch_small_oversampled():
    """The dechirp DFT zero-padded twice: bins at c/4B (and no phase step of whole cycles)."""
    return _crouch_small().with_processor(range_oversampling=2)


CASES = {"tiny": _tiny, "crouch-sal-small": _crouch_small}
LENS_CASES = {**CASES, "crouch-sal-small-oversampled": _crouch_small_oversampled}
LINE_TOL = {"pulsed": 1e-3, "fmcw": 1e-5}  # of the peak; see the module docstring
OFFSETS_CELLS = (3.0, 0.37, -5.21, 7.9)  # the first on a bin


def _cell_m(cfg) -> float:
    axis = range_axis_m(cfg)
    return float(axis[1] - axis[0])


def _carrier_rad(cfg, range_m: float) -> float:
    """The phase a return compresses to: -4πR/λ (pulsed), -4π(R - R_ref)/λ (FMCW, whose
    residual video phase, below 1e-6 rad here, is left out)."""
    wf, lam = cfg.waveform, cfg.geometry.wavelength_m
    path = range_m if wf.kind == "pulsed" else range_m - wf.reference_range_m
    return -4.0 * math.pi * math.fmod(path / lam, 1.0)


def _wrap(rad):
    return np.angle(np.exp(1j * np.asarray(rad)))


# ---- (1) the lens --------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(LENS_CASES))
def test_lens_declares_the_range_axis_of_the_documented_rules(name):
    cfg = LENS_CASES[name]()
    declared = make_plan(cfg).range_m
    assert np.abs(declared - range_axis_m(cfg)).max() < 1e-6 * _cell_m(cfg)


@pytest.mark.parametrize("name", sorted(LENS_CASES))
def test_lens_compresses_an_independent_echo_like_the_matched_filter(name):
    """One shot per target (on a bin, then off), through rtsar's lens in complex64; against the
    reference lens (matched filter over the chirp band, or dechirp DFT) on the reference axis."""
    cfg = LENS_CASES[name]()
    cell = _cell_m(cfg)
    ranges = range_centre_m(cfg) + np.array(OFFSETS_CELLS) * cell
    shots = np.stack([echo(cfg, r) for r in ranges])
    lines = make_lens(make_plan(cfg), "numpy").compress(shots.astype(np.complex64))
    assert lines.dtype == np.complex64
    expected = compress(cfg, shots)
    middle = cfg.processor.range_bins // 2
    for row, (r, offset) in enumerate(zip(ranges, OFFSETS_CELLS, strict=True)):
        got, ref = lines[row].astype(np.complex128), expected[row]
        peak = np.abs(ref).max()
        error = np.abs(got - ref).max() / peak
        assert error < LINE_TOL[cfg.waveform.kind], (r, error)
        got_at, got_width = peak_and_width(got)
        ref_at, ref_width = peak_and_width(ref)
        assert abs(got_at - ref_at) < 0.002, (r, got_at, ref_at)
        assert abs(got_at - (middle + offset)) < 0.02, (r, got_at, middle + offset)
        assert abs(got_width / ref_width - 1.0) < 2e-3, (r, got_width, ref_width)
    on_bin = middle + int(OFFSETS_CELLS[0])
    phase = np.angle(lines[0, on_bin].astype(np.complex128))
    assert abs(_wrap(phase - _carrier_rad(cfg, ranges[0]))) < 1e-3
    assert np.argmax(np.abs(lines[0])) == on_bin


# ---- (2) the simulator ---------------------------------------------------------------------


def _phase_fit(sim, mine, time_s):
    """(constant phase, slope in rad/s) of angle(sim / mine) over the samples both hold, by least
    squares about their mean time."""
    both = (np.abs(sim) > 0.5) & (np.abs(mine) > 0.5)
    t = time_s[both] - time_s[both].mean()
    d = np.angle(sim[both] * np.conj(mine[both]))
    slope, constant = np.polyfit(t, d, 1)
    return constant, slope


SIM_CASES = {**CASES, "tiny-fixed-window": _tiny_fixed_window}


@pytest.mark.parametrize("name", sorted(SIM_CASES))
def test_simulator_echo_has_the_delay_2r_over_c_and_the_carrier_phase(name):
    """A point 0.37 cell beyond the range centre, off the line grid by 0.3 pulse: rtsar's
    simulator against the echo built here from τ = 2R/c and the chirp, pulse by pulse."""
    cfg = SIM_CASES[name]()
    wf = cfg.waveform
    d = cfg.geometry.along_track_step_m
    pulses, start = 72, -0.25  # tiny: its whole 64-pulse aperture and more
    u = start + 0.5 * (pulses - 1) * d + 0.3 * d
    r0 = range_centre_m(cfg) + 0.37 * wf.range_resolution_m
    scene = point_scene(cfg, [u], [r0], pulses=pulses, start_along_track_m=start)
    sim = Simulator(scene).block(pulses).astype(np.complex128)
    mine = point_shots(cfg, u, r0, start, pulses)
    gated = np.abs(mine) > 0.5
    assert gated.any(axis=1).all()
    assert np.array_equal(np.abs(sim) > 0.5, gated)  # the same samples hold the echo
    sample_s = np.arange(wf.samples_per_shot) / wf.sample_rate_hz
    if wf.kind == "pulsed":
        k = wf.chirp_rate_hz_per_s
        unit = wf.sample_rate_hz  # a delay in samples
    else:
        k = wf.bandwidth_hz / wf.chirp_duration_s
        unit = wf.bandwidth_hz  # a delay in range cells, 2 δR / c · B
    for p in range(pulses):
        constant, slope = _phase_fit(sim[p], mine[p], sample_s)
        delay_s = -slope / (2.0 * math.pi * k)  # a delay δ adds -2πKδ·t to the chirp phase
        assert abs(delay_s * unit) < 1e-3, (p, delay_s * unit)
        assert abs(constant) < 1e-3, (p, constant)
    assert np.abs(sim - mine).max() < 1e-5  # and every sample, to complex64's rounding


# ---- (3) the focused image -----------------------------------------------------------------

IMAGE_LINES = {"tiny": 129, "crouch-sal-small": 257}  # about 10 and 6 azimuth IRWs


@pytest.mark.parametrize("name", sorted(CASES))
def test_image_of_a_point_matches_the_azimuth_correlation_of_its_range_history(name):
    """The independent echo of a point through rtsar's engine (lens + CCD, NumPy) against the
    reference chain: the matched filter, then the correlation with exp(+i4π(R(t) - R0)/λ) over
    each line's N pulses."""
    cfg = CASES[name]()
    g, n = cfg.geometry, cfg.processor.aperture_pulses
    d, cell = g.along_track_step_m, _cell_m(cfg)
    lines_count = IMAGE_LINES[name]
    pulses, start = n + lines_count - 1, -1.0
    azimuth = azimuth_axis_m(cfg, start, lines_count)
    ranges = range_axis_m(cfg)
    j0, r0_bin = lines_count // 2, cfg.processor.range_bins // 2
    u, r0 = azimuth[j0] + 0.3 * d, ranges[r0_bin] + 0.37 * cell
    shots = point_shots(cfg, u, r0, start, pulses)
    image, azimuth_m, range_m = process_block(cfg, shots.astype(np.complex64), "numpy", start)
    reference = focus(cfg, compress(cfg, shots))
    assert image.shape == reference.shape == (lines_count, cfg.processor.range_bins)
    assert np.abs(azimuth_m - azimuth).max() < 1e-6 * d  # the declared axes
    assert np.abs(range_m - ranges).max() < 1e-6 * cell
    peak = np.abs(reference).max()
    error = np.abs(image - reference).max() / peak
    assert error < LINE_TOL[cfg.waveform.kind], error
    j, r = np.unravel_index(np.argmax(np.abs(reference)), reference.shape)
    assert (j, r) == (j0, r0_bin)
    cuts = {
        "azimuth": (image[:, r], reference[:, r], j0 + 0.3),
        "range": (image[j, :], reference[j, :], r0_bin + 0.37),
    }
    for axis, (got, ref, truth) in cuts.items():
        got_at, got_width = peak_and_width(got)
        ref_at, ref_width = peak_and_width(ref)
        assert abs(got_at - ref_at) < 0.01, (axis, got_at, ref_at)
        assert abs(got_width / ref_width - 1.0) < 0.01, (axis, got_width, ref_width)
        assert abs(ref_at - truth) < 0.02, (axis, ref_at, truth)
        if axis == "azimuth":
            theory = 0.886 * g.wavelength_m * r0 / (2.0 * n * d) / d  # lines
            assert abs(ref_width / theory - 1.0) < 0.01, (ref_width, theory)
