"""The squinted beam's walk taken out before the CCD (rtsar.ccd.walk_deskew): the turning mask
against a direct float64 sum, the walk against the squint's geometry, and the focus against the
exact two-dimensional mask (M2) on RADARSAT-1's plan."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from point_focus import focus_points, whole_and_in_pieces

from rtsar.ccd import make_ccd
from rtsar.ccd.nonuniform import NonUniformCorrelator
from rtsar.ccd.walk_deskew import WalkDeskewCorrelator, fit_walk, walk_block_lines
from rtsar.lens import make_plan
from rtsar.params import Processor
from rtsar.presets import preset
from rtsar.scene import Simulator
from rtsar.scene.model import point_scene
from rtsar.stream.granularity import live_correlator
from rtsar.stream.growth import why_fixed

C = 299_792_458.0


def turned_reference(lines, mask, segments, w, q):
    """Each segment's block serving line p reads mask column (c + shift) mod W, shift =
    Q·round(w·m / Q) at the middle m of the block's lines (the rule nonuniform documents),
    summed directly in float64: out[p] = Σ_s Σ_{t<T_s} h[D_s + t, c + shift] · line[p - D_s - t],
    h[t] = mask[N - 1 - t]."""
    n, width = mask.shape
    h = mask[::-1].astype(np.complex128)
    cols = np.arange(width)
    out = np.zeros((len(lines) - n + 1, width), np.complex128)
    for i in range(len(out)):
        p = i + n - 1
        for d, taps, b in segments:
            k = (p - d) // b
            shift = int(q * np.round(w * (k * b + d + 0.5 * (b - 1)) / q))
            for t in range(taps):
                out[i] += h[d + t, (cols + shift) % width] * lines[p - d - t]
    return out


@pytest.mark.parametrize(
    "bins, w, q",
    [(64, 0.37, 1), (64, -0.11, 4), (4128, 0.9, 1)],  # 4128: two tiles of 2064, runs across them
)
def test_a_turning_mask_is_the_direct_sum_with_each_blocks_turn(bins, w, q):
    rng = np.random.default_rng(bins)
    n = 48
    mask = rng.standard_normal((n, bins)) + 1j * rng.standard_normal((n, bins))
    lines = rng.standard_normal((160, bins)) + 1j * rng.standard_normal((160, bins))
    ccd = NonUniformCorrelator(mask, 4, 16, "complex128", mask_rotation=(w, q))
    got = np.concatenate([ccd.push(lines[:37]), ccd.push(lines[37:]), ccd.flush()])
    ccd.close()
    want = turned_reference(lines, mask, ccd.segments, w, q)
    assert got.shape == want.shape
    assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()


def test_a_turning_mask_needs_the_tiles_width():
    with pytest.raises(ValueError, match="tiles' width"):
        NonUniformCorrelator(np.ones((8, 2100), complex), 4, 8, mask_rotation=(0.1, 1))


def test_the_walk_is_the_squints_slant_range_rate():
    """w = V sin θ / (PRF δR) bins a pulse, sin θ = -λ f_dc / 2V (the squint of the Doppler
    centroid, Cumming & Wong 2005 eq. 4.34), from the geometry alone; the curvature left is a
    fraction of a cell (RADARSAT-1: under half a cell at the aperture's ends)."""
    cfg = preset("radarsat1")
    g = cfg.geometry
    range_m = make_plan(cfg).range_m
    walk = fit_walk(cfg, range_m)
    sin_theta = -g.wavelength_m * g.doppler_centroid_hz / (2.0 * g.speed_mps)
    step_m = (range_m[-1] - range_m[0]) / (len(range_m) - 1)
    expect = g.speed_mps * sin_theta / (g.prf_hz * step_m)
    assert walk.bins_per_pulse == pytest.approx(expect, rel=2e-3)
    assert walk.curvature_max_bins < 0.5 and walk.curvature_rms_bins < 0.1
    assert walk_block_lines(walk.bins_per_pulse, 1, 128) == 32
    assert walk_block_lines(0.0, 4, 128) == 128 and walk_block_lines(0.5, 16, 128) == 16


@pytest.fixture(scope="module")
def scene():
    cfg = preset("radarsat1")
    # near both swath edges (the ring's guard) and inside, at azimuths that meet the mask's
    # turns and the tail's blocks at different pulses (a cold review found a start pulse where
    # one point moved 0.15 cell before the mask's constant phase was taken out)
    rs = make_plan(cfg).range_m[[30, 700, 1500, 1100, 2020]] + np.array([0.3, 0.6, 2.3, 0.0, 1.1])
    xs = np.array([1800.0, 2071.9, 2600.0, 2328.1, 2300.0])
    sc = point_scene(cfg, xs, rs, effects=[("antenna_pattern", {"main_lobe_only": True})])
    return cfg, sc, Simulator(sc).block(sc.pulses), xs, rs


def test_streaming_equals_one_push(scene):
    cfg, _, shots, *_ = scene
    cfg = cfg.with_processor(correlator="nonuniform", range_migration_domain="walk")
    kind, a, b, lines = whole_and_in_pieces(cfg, shots)
    assert issubclass(kind, WalkDeskewCorrelator)
    assert np.array_equal(a, b) and len(a) == len(lines) - cfg.processor.aperture_pulses + 1


@pytest.mark.slow
def test_the_walks_ring_focuses_as_the_exact_time_domain_mask(scene):
    """Against (M2), correlate_migration_reference's model: the curvature the ring leaves out
    and the mask's turn in steps cost RADARSAT-1's points at most 0.025 cell of azimuth and
    0.08 of range (measured 0.069 at the near edge, whose aperture the swath cuts; 0.017
    inside: the exact mask's 0.001), 0.1 rad of phase (measured 0.06), 1 % of azimuth width,
    10 % of range width (6.3 % at the near edge, 0.2-3.8 % elsewhere; more taps do not narrow
    it: 32 taps, 5.5 %) and 6 % of peak (the edge point; 1-2 % inside).  Measured about
    zero, the range band straddling the DFT's split, the range had read within 0.05 cell."""
    cfg, sc, shots, xs, rs = scene
    step, cell = cfg.geometry.along_track_step_m, C / (2 * cfg.waveform.sample_rate_hz)
    start = sc.start_along_track_m
    exact = focus_points(cfg, shots, start, xs, rs, range_migration_domain="time")
    walk = focus_points(
        cfg, shots, start, xs, rs, range_migration_domain="walk", correlator="nonuniform"
    )
    for t, d, x, r in zip(exact, walk, xs, rs, strict=True):
        assert abs(d.azimuth_m - x) / step < 0.025 and abs(d.range_m - r) / cell < 0.08
        assert abs(np.angle(d.peak_value / t.peak_value)) < 0.1
        assert d.azimuth.irw_m == pytest.approx(t.azimuth.irw_m, rel=0.01)
        assert d.range.irw_m == pytest.approx(t.range.irw_m, rel=0.10)
        assert abs(d.peak_value) == pytest.approx(abs(t.peak_value), rel=0.06)
        assert d.azimuth.pslr_db < -38.0


@pytest.mark.slow
def test_a_point_at_the_near_edge_of_a_forward_squint_keeps_its_mask():
    """The other squint's sign (f_dc = +6900 Hz), a point 1.2 bins from the near edge: its
    aperture turns the mask below column 0, into the guard's upper half, which holds the
    columns below the swath (a cold review: it held the far edge's, azimuth PSLR -11.5 dB
    against (M2)'s -20.5 dB)."""
    cfg = preset("radarsat1")
    cfg = replace(cfg, geometry=replace(cfg.geometry, doppler_centroid_hz=6900.0))
    plan = make_plan(cfg)
    xs, rs = np.array([2200.0]), plan.range_m[[0]] + 1.2 * (plan.range_m[1] - plan.range_m[0])
    step = cfg.geometry.along_track_step_m
    plain = point_scene(cfg, xs, rs)  # its extent, widened: the forward beam sees it earlier
    sc = point_scene(
        cfg,
        xs,
        rs,
        effects=[("antenna_pattern", {"main_lobe_only": True})],
        start_along_track_m=plain.start_along_track_m - 150 * step,
        pulses=plain.pulses + 300,
    )
    shots = Simulator(sc).block(sc.pulses)
    start = sc.start_along_track_m
    (t,) = focus_points(cfg, shots, start, xs, rs, range_migration_domain="time")
    (d,) = focus_points(
        cfg, shots, start, xs, rs, range_migration_domain="walk", correlator="nonuniform"
    )
    assert d.azimuth.pslr_db < t.azimuth.pslr_db + 2.0
    assert abs(d.peak_value) == pytest.approx(abs(t.peak_value), rel=0.05)


def test_live_runs_take_the_walk_where_the_doppler_read_holds_lines():
    cfg = preset("radarsat1")
    live, words = live_correlator(cfg)
    p = live.processor
    assert (p.correlator, p.range_migration_domain) == ("nonuniform", "walk")
    assert "curvature" in words
    assert live_correlator(cfg, given="fft")[0] is cfg  # --correlator fft keeps fft
    assert why_fixed(p) == "the walk's ring turns from the stream's first pulse"
    with pytest.raises(ValueError, match="'walk' needs correlator = 'nonuniform'"):
        Processor(8, 8, correlator="fft", range_migration_taps=4, range_migration_domain="walk")
    assert math.isfinite(fit_walk(live, make_plan(live).range_m).bins_per_pulse)


def test_the_memory_estimate_counts_one_correlator_on_the_ring():
    """The memory check (rtsar.stream.memory) counted the walk as T + 2 correlators, as the
    time-domain taps are (RADARSAT-1: 10x what it holds, enough to refuse a run on a small
    machine); the estimate now lies between what the ring's correlator holds and 3x that."""
    from rtsar.stream.memory import estimate_bytes

    cfg = preset("radarsat1").with_processor(correlator="nonuniform", range_migration_domain="walk")
    ccd = make_ccd(cfg, make_plan(cfg).range_m)
    inner = ccd.inner
    groups = [inner._head, inner._tail.group]
    held = sum(a.nbytes for g in groups for a in g.arrays)
    held += sum(a.nbytes for ring in (inner._hist, inner._acc, inner._head_out) for a in ring)
    ccd.close()
    estimate = estimate_bytes(cfg)
    assert held <= estimate <= 3 * held


def test_the_ring_refuses_a_curvature_it_would_drop():
    """A broadside lidar with a long aperture (crouch-sal, range oversampled 4x: 1.87 bins of
    curvature) is refused with the domains that keep it, not imaged with the curvature
    silently dropped (a cold review)."""
    cfg = preset("crouch-sal").with_processor(
        range_migration_taps=4,
        range_oversampling=4,
        correlator="nonuniform",
        range_migration_domain="walk",
    )
    with pytest.raises(ValueError, match=r"curvature, here 1\.87 bins.*-domain time"):
        make_ccd(cfg, make_plan(cfg).range_m)


def test_the_read_out_reaches_any_offset_the_columns_have():
    """_read_rows against a plain mod-W read (interpolation_weights of rtsar.ccd.migration) at
    offsets of up to ±3.5 bins, positions on the weight table's grid; a cold review found reads
    below the pad's start for offsets under 1 - T/2 (wrapped indices, wrong values)."""
    from rtsar.ccd.migration import interpolation_weights
    from rtsar.ccd.walk_deskew import _read_rows, weight_table

    rng = np.random.default_rng(3)
    width, bins, taps = 40, 32, 4
    ring = (rng.standard_normal((3, width)) + 1j * rng.standard_normal((3, width))).astype(
        np.complex128
    )
    offset = np.round(np.linspace(-3.5, 3.5, bins) * 256) / 256
    margin = taps + 4 + 2
    span = bins + 2 * margin + taps
    out = np.empty((3, bins), np.complex128)
    w, first_line = 0.25, 9  # turns 2.25, 2.5, 2.75: on the table's grid
    _read_rows(
        ring,
        first_line,
        w,
        offset,
        np.ascontiguousarray(weight_table(taps, np.float64).T),
        np.ones(span, np.complex128),
        np.zeros(span),
        0.0,
        np.zeros(span, np.complex128),
        np.empty(bins, np.int64),
        np.empty(bins, np.int64),
        out,
    )
    for i in range(3):
        pos = np.arange(bins) + offset - w * (first_line + i)
        first, wt = interpolation_weights(pos, taps)
        idx = (first[:, None] + np.arange(taps)) % width
        want = (ring[i][idx] * wt).sum(axis=1)
        np.testing.assert_allclose(out[i], want, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "argv, domain",
    [
        (["--correlator", "nonuniform"], "walk"),  # the live run's: its image made again
        (["--correlator", "partitioned"], "time"),
        (["--correlator", "fft"], "doppler"),
        ([], "doppler"),
        (["--correlator", "nonuniform", "--range-migration-domain", "time"], "time"),
    ],
)
def test_the_command_lines_correlator_takes_its_migration_domain(argv, domain):
    """`rtsar process rs1.h5 --correlator nonuniform`, as the live banner names it, was refused
    (the file's Doppler-domain read is fft's, and no option set the domain: a new user could
    not make the live image again); now each kind takes the domain it reads in, and
    --range-migration-domain names one outright."""
    from rtsar.app.cli import build_parser
    from rtsar.app.cli.options import processor_changes
    from rtsar.stream.granularity import migration_words

    args = build_parser("process").parse_args(["process", "r.h5", "-o", "i.h5", *argv])
    p = processor_changes(args, preset("radarsat1")).processor
    assert p.range_migration_domain == domain
    words = {"walk": "walk's ring", "time": "exact 2-D mask", "doppler": "azimuth spectrum"}
    assert migration_words(p).startswith("; range migration 16 taps, read ")
    assert words[domain] in migration_words(p)
    bad = ["--correlator", "nonuniform", "--range-migration-domain", "doppler"]
    args = build_parser("process").parse_args(["process", "r.h5", "-o", "i.h5", *bad])
    with pytest.raises(ValueError, match="'doppler' needs correlator = 'fft'"):
        processor_changes(args, preset("radarsat1"))


@pytest.mark.slow
def test_the_banner_says_the_walks_block_does_not_grow():
    """A live run on the walk's ring keeps its block when behind (why_fixed); the banner's
    granularity line said nothing of it, where it names the blocks a run may grow to."""
    from rtsar.app.live_granularity import GranularityRequest
    from rtsar.stream.pipeline import PipelineSettings

    cfg = preset("radarsat1")
    chosen, _, _, words = GranularityRequest(1256.98).apply(cfg, PipelineSettings("numpy"))
    assert chosen.processor.range_migration_domain == "walk"
    assert "the block does not grow when behind (the walk's ring turns from" in words


def test_a_plan_whose_curvature_the_ring_would_drop_keeps_its_read():
    """RADARSAT-1 at twice the wavelength, the same squint and twice the aperture (1.45 bins of
    curvature): a live run and --correlator nonuniform took the walk's ring, which refuses it,
    so a run that named nothing failed (a cold review); now the live run keeps fft's
    Doppler-domain read and --correlator nonuniform takes the time domain."""
    from rtsar.ccd.migration import walk_leaves_bins
    from rtsar.stream.granularity import migration_domain_for

    cfg = preset("radarsat1")
    g = cfg.geometry
    g2 = replace(g, wavelength_m=2 * g.wavelength_m, doppler_centroid_hz=g.doppler_centroid_hz / 2)
    cfg2 = replace(cfg, geometry=g2).with_processor(aperture_pulses=1432)
    assert walk_leaves_bins(cfg2) > 1.0 > walk_leaves_bins(cfg)
    assert live_correlator(cfg2) == (cfg2, "")
    assert migration_domain_for(cfg2, "nonuniform") == "time"
    assert migration_domain_for(cfg, "nonuniform") == "walk"


@pytest.mark.slow
def test_one_range_for_every_columns_mask_turns_no_phase():
    """per_bin_mask = False: design_mask gives every column the range centre's phase, so the
    ring takes out and gives back that one φ0, not each column's own (a cold review: a sawtooth
    of -0.27 to +0.14 rad, the peak -0.10 rad off the exact (M2)'s)."""
    cfg = preset("radarsat1").with_processor(per_bin_mask=False)
    xs, rs = np.array([2300.0]), make_plan(cfg).range_m[[1100]]
    sc = point_scene(cfg, xs, rs, effects=[("antenna_pattern", {"main_lobe_only": True})])
    shots = Simulator(sc).block(sc.pulses)
    start = sc.start_along_track_m
    (t,) = focus_points(cfg, shots, start, xs, rs, range_migration_domain="time")
    (d,) = focus_points(
        cfg, shots, start, xs, rs, range_migration_domain="walk", correlator="nonuniform"
    )
    assert abs(np.angle(d.peak_value / t.peak_value)) < 0.03
    assert abs(d.peak_value) == pytest.approx(abs(t.peak_value), rel=0.03)
