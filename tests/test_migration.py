"""Range-migration correction (rtsar.migration): the 2-D mask, its streaming correlator, physics.

Tolerances: the float64 reference against plain loops 1e-12; streaming against the reference
1e-5 in complex64 (measured ~2e-7) and 1e-12 in complex128; on crouch-sal (35 µm = 0.7 range
cell of migration at the aperture edge) the range bias of a point target must fall from the
measured 0.23 cell to below 0.02 cell and the azimuth IRW to within 1 % of theory.
"""

import numpy as np
import pytest
from conftest import crandn

from rtsar.analysis import analyse_point_target, relative_rms
from rtsar.analysis.acceptance import SINC_IRW, acceptance_targets
from rtsar.ccd import CORRELATORS, make_correlator
from rtsar.ccd.base import aperture_offsets_m, correlate_reference, design_mask
from rtsar.ccd.fft import FFTCorrelator
from rtsar.ccd.migration import (
    EDGE_LOSS_DB,
    FFTMigrationCorrelator,
    MigrationCorrelator,
    MigrationMask,
    correlate_migration_reference,
    design_migration_mask,
    edge_gain_db,
    interpolation_weights,
    migration_bins,
    shift_lines,
    taps_for_band,
)
from rtsar.lens.plan import make_plan
from rtsar.params import Processor
from rtsar.presets import preset
from rtsar.scene import Simulator, point_scene
from rtsar.stream.engine import StreamProcessor, process_block

TOL = {"complex64": 1e-5, "complex128": 1e-12}


def lanczos(x, a):
    """sin(πx) sin(πx/a) / (π² x² / a), 1 at x = 0: written out, not through np.sinc."""
    x = np.asarray(x, float)
    out = np.ones_like(x)
    nz = x != 0
    out[nz] = a * np.sin(np.pi * x[nz]) * np.sin(np.pi * x[nz] / a) / (np.pi * x[nz]) ** 2
    return np.where(np.abs(x) < a, out, 0.0)


def migration_loops(lines, taps, offsets):
    """(M2) by its definition: g[p, r] = Σ_k Σ_t line[p-N+1+k, r+o_t] mask[k, r, t]."""
    n, bins, _ = taps.shape
    out = np.zeros((len(lines) - n + 1, bins), complex)
    for p in range(out.shape[0]):
        for k in range(n):
            for r in range(bins):
                for t, o in enumerate(offsets):
                    if 0 <= r + o < bins:
                        out[p, r] += lines[p + k, r + o] * taps[k, r, t]
    return out


def test_interpolation_weights():
    u = np.array([0.0, 0.4, 0.6, -0.6, 0.25, 1.3])
    first, w = interpolation_weights(u, 1)  # nearest bin
    np.testing.assert_array_equal(first, [0, 0, 1, -1, 0, 1])
    np.testing.assert_array_equal(w[..., 0], 1.0)
    first, w = interpolation_weights(np.array([0.25, -0.75]), 2)  # linear
    np.testing.assert_array_equal(first, [0, -1])
    np.testing.assert_allclose(w, [[0.75, 0.25], [0.75, 0.25]], atol=1e-15)
    for taps in (3, 4, 5, 8):
        first, w = interpolation_weights(u, taps)
        np.testing.assert_allclose(w.sum(axis=-1), 1.0, atol=1e-14)
        pos = first[:, None] + np.arange(taps)
        assert np.all(np.abs(pos - u[:, None]) <= taps / 2)  # the T bins nearest to u
        # An integer position reads that bin alone (Lanczos vanishes at the other integers).
        np.testing.assert_allclose(w[0], (pos[0] == 0).astype(float), atol=1e-15)
        x = pos - u[:, None]
        expected = lanczos(x, taps / 2)
        np.testing.assert_allclose(w, expected / expected.sum(axis=1, keepdims=True), atol=1e-14)
    with pytest.raises(ValueError):
        interpolation_weights(np.array([np.nan]), 4)
    with pytest.raises(ValueError):
        interpolation_weights(u, 0)


@pytest.mark.parametrize("taps, tol", [(2, 0.15), (4, 0.05), (6, 0.015), (8, 0.005)])
def test_interpolation_reads_a_half_band_line(taps, tol):
    """A line oversampled by 2 (range_oversampling = 2), tones spread over the whole half band,
    is read between its bins to ``tol`` (relative RMS; measured 0.11, 0.038, 0.011, 0.004).
    The worst case: a point target's response is concentrated at low frequencies."""
    rng = np.random.default_rng(1)
    f = rng.uniform(-0.25, 0.25, 12)  # cycles per bin: half of the band
    a = rng.standard_normal(12) + 1j * rng.standard_normal(12)

    def line(pos):
        return (a * np.exp(2j * np.pi * f * np.asarray(pos)[..., None])).sum(axis=-1)

    samples = line(np.arange(-40, 41))
    u = rng.uniform(-3, 3, 200)
    first, w = interpolation_weights(u, taps)
    got = (samples[first[:, None] + np.arange(taps) + 40] * w).sum(axis=1)
    assert relative_rms(got, line(u)) < tol


def test_migration_bins_follow_the_range_hyperbola():
    cfg = preset("crouch-sal")
    rm = make_plan(cfg).range_m
    shift = migration_bins(cfg, rm)
    x = aperture_offsets_m(cfg)
    for col in (0, 255, 511):
        expected = (np.hypot(rm[col], x) - rm[col]) / (rm[1] - rm[0])
        # hypot(R, x) - R cancels: it is good to R·eps/δR ≈ 3e-12 bins only.
        np.testing.assert_allclose(shift[:, col], expected, rtol=1e-9, atol=1e-10)
    # Crouch: 35 µm of curvature at the edge of the 20 mm aperture, 0.7 of a 50 µm bin.
    assert 0.69 < shift.max() < 0.71 and shift.min() < 1e-4
    # Oversampled range bins are half as wide: the migration doubles in bins.
    rm2 = make_plan(cfg.with_processor(range_oversampling=2, range_bins=1024)).range_m
    assert migration_bins(cfg, rm2).max() == pytest.approx(2 * shift.max(), rel=1e-3)
    with pytest.raises(ValueError, match="uniformly"):
        migration_bins(cfg, np.array([1.5, 1.50005, 1.5002]))


def test_design_is_the_azimuth_mask_spread_over_range_taps():
    cfg = preset("crouch-sal").with_processor(range_bins=16, range_migration_taps=4)
    rm = make_plan(cfg).range_m
    mm = design_migration_mask(cfg, rm)
    plain = design_mask(cfg, rm)
    # u in (0, 0.71]: the 4 nearest bins start at ceil(u - 2) = -1: offsets -1 .. 2, and the
    # cost is 4 correlators.
    np.testing.assert_array_equal(mm.offsets, np.arange(-1, 3))
    np.testing.assert_allclose(mm.taps.sum(axis=2), plain, atol=1e-15)  # unit gain per row
    centre = cfg.processor.aperture_pulses // 2  # x = d/2: u = 2e-8, all on offset 0
    np.testing.assert_allclose(mm.taps[centre, :, 1], plain[centre], rtol=1e-6)
    # At the aperture edge (u ≈ 0.7) the bin one further out carries more than the own bin.
    assert np.all(np.abs(mm.taps[0, :, 2]) > np.abs(mm.taps[0, :, 1]))
    # Without measurable migration and T = 1, the 2-D mask is the 1-D mask.
    tiny = preset("tiny")
    one = design_migration_mask(tiny, make_plan(tiny).range_m, taps=1)
    np.testing.assert_array_equal(one.offsets, [0])
    np.testing.assert_array_equal(one.taps[:, :, 0], design_mask(tiny, make_plan(tiny).range_m))


def test_shift_lines():
    lines = np.arange(12.0).reshape(2, 6) + 0j
    np.testing.assert_array_equal(shift_lines(lines, 2)[0], [2, 3, 4, 5, 0, 0])
    np.testing.assert_array_equal(shift_lines(lines, -1)[1], [0, 6, 7, 8, 9, 10])
    np.testing.assert_array_equal(shift_lines(lines, 0), lines)
    np.testing.assert_array_equal(shift_lines(lines, 7), 0)


def test_reference_equals_loops(rng):
    n, bins, pulses = 6, 5, 15
    offsets = np.array([-1, 0, 1, 2])
    taps = crandn(rng, n, bins, len(offsets))
    lines = crandn(rng, pulses, bins)
    mm = MigrationMask(taps, offsets, np.zeros((n, bins)))
    got = correlate_migration_reference(lines, mm)
    np.testing.assert_allclose(got, migration_loops(lines, taps, offsets), rtol=1e-12, atol=1e-12)
    # One tap at offset 0 is the 1-D correlation of rtsar.ccd.
    one = MigrationMask(taps[:, :, :1], np.array([0]), np.zeros((n, bins)))
    np.testing.assert_allclose(
        correlate_migration_reference(lines, one), correlate_reference(lines, taps[:, :, 0])
    )


@pytest.mark.parametrize("precision", list(TOL))
@pytest.mark.parametrize("kind", CORRELATORS)
def test_streaming_equals_reference(kind, precision):
    cfg = preset("crouch-sal").with_processor(
        range_bins=12, range_oversampling=2, range_migration_taps=4
    )
    mm = design_migration_mask(cfg, make_plan(cfg).range_m)
    rng = np.random.default_rng(21)
    lines = crandn(rng, 2300, 12)
    ref = correlate_migration_reference(lines, mm)
    corr = make_correlator(kind, mm, partition_lines=32, precision=precision)
    # u in (0, 1.41] bins: first bins ceil(u - 2) ∈ {-1, 0}, offsets -1 .. 3.
    assert corr.taps == len(mm.offsets) == 5
    if kind == "fft":  # shared transforms (M3)
        assert isinstance(corr, FFTMigrationCorrelator)
    else:  # one inner correlator per offset
        assert isinstance(corr, MigrationCorrelator)
        assert all(c.dtype == corr.dtype for c in corr.inner)
    parts = [corr.push(lines[i : i + 333]) for i in range(0, len(lines), 333)]
    got = np.concatenate([*parts, corr.flush()])
    assert got.shape == ref.shape and got.dtype == corr.dtype
    assert corr.pulses_in == len(lines) and corr.lines_out == len(ref)
    assert relative_rms(got, ref) < TOL[precision]


def test_generic_wrapper_around_fft_correlators_equals_the_shared_transforms(rng):
    """MigrationCorrelator of FFT correlators (one per offset) and FFTMigrationCorrelator
    compute the same (M2): both against the reference to 1e-12 in double."""
    n, bins = 32, 9
    mm = MigrationMask(crandn(rng, n, bins, 3) / n, np.array([-2, 0, 1]), np.zeros((n, bins)))
    lines = crandn(rng, 300, bins)
    ref = correlate_migration_reference(lines, mm)
    generic = MigrationCorrelator(mm, [FFTCorrelator(m, 64, "complex128") for m in mm.tap_masks()])
    shared = FFTMigrationCorrelator(mm, 64, "complex128")
    for corr in (generic, shared):
        got = np.concatenate([corr.push(lines[:150]), corr.push(lines[150:]), corr.flush()])
        assert relative_rms(got, ref) < 1e-12


def test_wrapper_checks_its_inner_correlators(rng):
    mm = MigrationMask(crandn(rng, 8, 3, 2), np.array([0, 1]), np.zeros((8, 3)))
    with pytest.raises(ValueError, match="one inner correlator"):
        MigrationCorrelator(mm, [FFTCorrelator(mm.tap_masks()[0])])
    inner = [FFTCorrelator(m, precision=p) for m, p in zip(mm.tap_masks(), TOL, strict=True)]
    with pytest.raises(ValueError, match="precision"):
        MigrationCorrelator(mm, inner)


def test_processor_knob_and_engine():
    for bad in (-1, 65, 2.0, True, None):
        with pytest.raises(ValueError, match="range_migration_taps"):
            Processor(aperture_pulses=8, range_bins=8, range_migration_taps=bad)
    assert Processor(aperture_pulses=8, range_bins=8).range_migration_taps == 0
    cfg = preset("tiny").with_processor(range_migration_taps=4, correlator="direct")
    eng = StreamProcessor(cfg, lens_backend="numpy")
    assert isinstance(eng.correlator, MigrationCorrelator)
    assert isinstance(eng.correlator.mask, MigrationMask)
    eng = StreamProcessor(cfg.with_processor(correlator="fft"), lens_backend="numpy")
    assert isinstance(eng.correlator, FFTMigrationCorrelator)
    off = StreamProcessor(preset("tiny"), lens_backend="numpy")
    assert not isinstance(off.correlator, MigrationCorrelator)


def test_crouch_point_target_loses_its_range_bias():
    """crouch-sal, centre acceptance target, range oversampling 2, T = 4 taps (5 offsets).

    Measured without correction: range error 0.227 cell, azimuth IRW 1.022 × theory; with it:
    0.001 cell and 1.001 ×, azimuth PSLR -13.43 dB (theory -13.26 dB).
    """
    cfg = preset("crouch-sal").with_processor(range_oversampling=2, range_bins=128)
    label, x, r = acceptance_targets(cfg)[1]
    assert label == "centre"
    n, step = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    margin = 72
    start = x - (0.5 * (n - 1) + margin) * step
    scene = point_scene(cfg, [x], [r], pulses=n + 2 * margin, start_along_track_m=start)
    shots = Simulator(scene).block(scene.pulses)
    rho_a, rho_r = cfg.azimuth_resolution_m(r), cfg.waveform.range_resolution_m
    found = {}
    for taps in (0, 4):
        c = cfg.with_processor(range_migration_taps=taps)
        img, az, rg = process_block(c, shots, lens_backend="numpy", start_along_track_m=start)
        rep = analyse_point_target(img, az, rg, x, r, (3 * rho_a, 3 * rho_r), chip=64)
        found[taps] = (
            abs(rep.range_m - r) / rho_r,
            rep.azimuth.irw_m / (SINC_IRW * rho_a),  # rect window: factor 1
            rep.azimuth.pslr_db,
            abs(rep.azimuth_m - x) / rho_a,
        )
    (bias0, irw0, _, _), (bias4, irw4, pslr4, az4) = found[0], found[4]
    assert 0.2 < bias0 < 0.26  # the uncorrected curvature bias (test_focus predicts 0.23)
    assert bias4 < 0.02  # tolerance: a tenth of the bias
    assert abs(irw4 - 1) < 0.01 and abs(irw4 - 1) < abs(irw0 - 1)
    assert abs(pslr4 - -13.26) < 0.4
    assert az4 < 1 / 32


def test_taps_for_a_band_are_the_fewest_that_keep_its_edge():
    """The gain taps_for_band weighs is the interpolator's own: a tone at the band's edge read
    between its samples through the weights comes out that much smaller (averaged over the
    fractional positions).  RADARSAT-1's 30.1 MHz sampled at 32.317 MHz needs 16 taps (8 lose
    3.1 dB at its edge); a band 1.2x over, or less, keeps 8."""
    edge = 0.5 * 30.1e6 / 32.317e6
    n = np.arange(-64, 65)
    tone = np.exp(2j * np.pi * edge * n)
    for taps in (8, 16):
        gains = []
        for u in np.arange(64) / 64:
            first, w = interpolation_weights(np.array([u]), taps)
            read = np.sum(w[0] * tone[64 + first[0] + np.arange(taps)])
            gains.append(abs(read / np.exp(2j * np.pi * edge * u)))
        assert 20 * np.log10(np.mean(gains)) == pytest.approx(edge_gain_db(taps, edge), abs=1e-9)
    assert edge_gain_db(8, edge) < -EDGE_LOSS_DB <= edge_gain_db(16, edge)
    assert taps_for_band(2 * edge) == 16
    assert taps_for_band(1 / 1.2) == taps_for_band(0.5) == 8
    with pytest.raises(ValueError, match="not in"):
        taps_for_band(1.1)


def test_a_band_no_lanczos_read_keeps_takes_the_cheapest_near_the_best():
    """Over 0.99 of the sample rate no choice loses under 2 dB at the edge: 64 taps lose 3.5 dB
    where 8 lose 3.9; the fewest within 0.5 dB of the best, not 8x the read for nothing."""
    gains = {t: edge_gain_db(t, 0.4975) for t in (8, 64)}
    assert gains[64] < -EDGE_LOSS_DB and gains[64] - gains[8] < 0.5
    assert taps_for_band(0.995) == 8
    assert taps_for_band(0.97) == 48  # 1.2 dB: the rule's own choice
