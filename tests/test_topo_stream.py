"""Height strips in the stream: streaming equals batch, continuity across strip boundaries."""

import json
import math

import numpy as np
import pytest

from rtsar.scene.relief import default_spacing_m, ridge, surface_scene, zhao_config
from rtsar.scene.simulator import Simulator
from rtsar.stream.engine import StreamProcessor
from rtsar.stream.strips import StripSink
from rtsar.topo.insar import height_map
from rtsar.topo.insar_geometry import InsalGeometry
from rtsar.topo.registration import Registration, estimate_registration
from rtsar.topo.stream import HeightStripStage

GEO = InsalGeometry(1.55e-6, 2.4 * math.cos(math.atan(math.sqrt(2))), 1.6e-3)


def random_splits(rng, n, most=9):
    edges, i = [0], 0
    while i < n:
        i = min(n, i + int(rng.integers(0, most + 1)))  # empty batches too
        edges.append(i)
    return list(zip(edges[:-1], edges[1:], strict=True))


def run_stage(stage, main, slave, splits):
    strips = []
    for a, b in splits:
        strips += stage.process(main[a:b], slave[a:b])
    strips += stage.flush()
    return strips


def stitch(strips):
    first = [s.first_line for s in strips]
    assert first == sorted(first) and first[0] == 0
    for s, t in zip(strips[:-1], strips[1:], strict=True):
        assert s.first_line + len(s) == t.first_line  # no gap, no repeat
    return np.concatenate([s.height_m for s in strips]), np.concatenate([s.valid for s in strips])


@pytest.fixture(scope="module")
def ridge_lines():
    """Zhao's ridge (scaled) seen by two receivers, focused by two streaming engines."""
    cfg = zhao_config(sample_rate_hz=640.0, aperture_pulses=48, range_bins=48)
    ss = surface_scene(
        cfg,
        ridge(2.5e-3, 4e-3),
        64,
        seed=5,
        spacing_m=default_spacing_m(cfg, 2.0),
        effects=[("noise", {"snr_db": 5.0}), ("interferometric_receivers", {"snr_db": 5.0})],
    )
    shots, aux = Simulator(ss.scene).block_with_aux(ss.scene.pulses)
    engines = [
        StreamProcessor(cfg, "numpy", start_along_track_m=ss.scene.start_along_track_m)
        for _ in range(2)
    ]
    rng = np.random.default_rng(2)
    pairs = []  # line blocks as two engines deliver them, in stream order
    for a, b in random_splits(rng, len(shots), 13):
        pairs.append((engines[0].push(shots[a:b]).lines, engines[1].push(aux["rx1"][a:b]).lines))
    pairs.append((engines[0].flush().lines, engines[1].flush().lines))
    main = np.concatenate([p[0] for p in pairs])
    slave = np.concatenate([p[1] for p in pairs])
    assert main.shape == (64, 48)
    return cfg, engines[0].range_m, pairs, main, slave


def test_streaming_equals_batch_on_the_ridge(ridge_lines, rng):
    cfg, rg, pairs, main, slave = ridge_lines
    reg = estimate_registration(main, slave)
    kw = dict(strip_lines=16, overlap_lines=4, method="mcf")
    # As delivered by the engines (unequal, sometimes empty blocks), and one line at a time.
    stage = HeightStripStage(GEO, rg, reg, **kw)
    delivered = []
    for m, s in pairs:
        delivered += stage.process(m, s)
    delivered += stage.flush()
    h1, v1 = stitch(delivered)
    h2, v2 = stitch(
        run_stage(HeightStripStage(GEO, rg, reg, **kw), main, slave, random_splits(rng, 64))
    )
    assert np.array_equal(h1, h2) and np.array_equal(v1, v2)
    # The float64 batch reference: the whole-image chain with the same registration.
    ref = height_map(main, slave, GEO, rg, registration=reg, method="mcf")
    assert np.array_equal(v1, ref.valid)
    assert np.max(np.abs(h1 - ref.height_m)) < 1e-9
    assert v1.mean() > 0.8
    # Continuity: the step across a boundary is no larger than steps inside strips, no slip.
    assert stage.strips_out == 4 and stage.strips_not_aligned == 0
    assert stage.max_boundary_jump_m <= max(stage.max_interior_step_m, 1e-6)
    assert stage.max_boundary_jump_m < float(GEO.ambiguity_height_m(2.4)) / 10
    assert stage.max_overlap_mismatch_m < 1e-9


def synthetic_pair(rng, rows, cols, phase):
    """Main speckle M and slave S with arg(M S*) = phase exactly."""
    m = rng.standard_normal((rows, cols)) + 1j * rng.standard_normal((rows, cols)) + 0.5
    return m, m * np.exp(-1j * phase)


def test_strips_follow_phase_across_many_fringes(rng):
    """1.4 fringes per strip along track: each strip alone would pick another 2π cycle."""
    rows, cols = 96, 24
    i, j = np.mgrid[0:rows, 0:cols]
    phase = 2 * np.pi * (0.09 * i + 0.02 * j) + 1.5 * np.sin(j / 5.0)
    main, slave = synthetic_pair(rng, rows, cols, phase)
    rg = 2.4 + (np.arange(cols) - cols // 2) * 170e-6
    stage = HeightStripStage(
        GEO,
        rg,
        Registration(0.0, 0.0),
        strip_lines=16,
        overlap_lines=4,
        looks=(1, 1),
        coherence_min=0.0,
        method="mcf",
        flat_earth=np.ones(cols),
    )
    h, v = stitch(run_stage(stage, main, slave, random_splits(rng, rows, 20)))
    assert v.all()
    got = GEO.phase_rad(rg[None, :], h) - GEO.phase_rad(rg[None, :], 0.0)
    cycles = (got - phase) / (2 * np.pi)
    assert np.max(np.abs(cycles - np.round(cycles[0, 0]))) < 1e-6  # one global cycle
    # Each strip's own median phase moves by > 1 cycle: without alignment they would slip.
    medians = [np.median(phase[s : s + 16]) / (2 * np.pi) for s in range(0, rows, 16)]
    assert np.min(np.diff(medians)) > 1.0
    assert stage.strips_not_aligned == 0 and stage.max_overlap_mismatch_m < 1e-9


def test_gaps_and_bad_lines_are_masked_and_counted(rng):
    rows, cols = 80, 16
    i, j = np.mgrid[0:rows, 0:cols]
    main, slave = synthetic_pair(rng, rows, cols, 2 * np.pi * 0.03 * i)
    main[30:52] = slave[30:52] = 0  # no return over more than a strip
    main[70, 3] = np.nan
    rg = 2.4 + np.arange(cols) * 170e-6
    stage = HeightStripStage(
        GEO,
        rg,
        Registration(0.0, 0.0),
        strip_lines=8,
        overlap_lines=2,
        looks=(3, 3),
        method="mcf",
        flat_earth=np.ones(cols),
    )
    h, v = stitch(run_stage(stage, main, slave, random_splits(rng, rows)))
    assert np.isfinite(h).all() and np.all(h[~v] == 0)
    assert not v[31:51].any() and not v[70].any()
    assert stage.nonfinite_lines == 1
    assert stage.strips_not_aligned >= 1
    assert stage.pixels_masked == int((~v).sum())


def test_registration_estimated_once_from_the_first_lines(ridge_lines):
    cfg, rg, pairs, main, slave = ridge_lines
    stage = HeightStripStage(GEO, rg, None, strip_lines=16, overlap_lines=4)
    run_stage(stage, main, slave, [(0, 10), (10, 64)])
    ref = estimate_registration(main[:24], slave[:24])
    assert stage.registration == ref
    assert abs(stage.registration.range_px - (-1.6e-3 * math.sqrt(2 / 3) / 2 / 170e-6)) < 0.15


def test_memory_is_bounded_and_misuse_is_refused(rng):
    cols = 8
    stage = HeightStripStage(
        GEO,
        2.4 + np.arange(cols) * 1.7e-4,
        Registration(0.3, 0.0),
        strip_lines=8,
        overlap_lines=2,
        method="ls",
        flat_earth=np.ones(cols),
    )
    bound = 8 + 2 * (2 + stage.margin) + 7
    for _ in range(60):
        m = rng.standard_normal((7, cols)) + 1j
        stage.process(m, m)
        assert stage.buffered_lines <= bound
    stage.flush()
    with pytest.raises(RuntimeError):
        stage.process(m, m)
    with pytest.raises(ValueError):
        HeightStripStage(GEO, np.arange(cols) + 2.4, strip_lines=4, overlap_lines=5)
    with pytest.raises(ValueError):
        HeightStripStage(GEO, np.arange(cols) + 2.4).process(np.ones((2, 3)), np.ones((2, 3)))


class HeightSink(StripSink):
    """In-process sink keeping image and height strips."""

    def __init__(self):
        self.strips, self.heights, self.final = [], [], None

    def strip(self, strip, pipeline):
        self.strips.append(strip)

    def height(self, strip, seq, pipeline):
        assert seq == len(self.heights)
        self.heights.append(strip)

    def stats(self, d, pipeline):
        pass

    def end(self, d, pipeline):
        self.final = d


def test_pipeline_publishes_height_strips_equal_to_the_batch_chain(ridge_lines):
    from rtsar.sinks.wire import decode, height_header
    from rtsar.sources.replay import ReplaySource
    from rtsar.stream.pipeline import Pipeline, PipelineSettings
    from rtsar.stream.strips import StreamInfo

    cfg = zhao_config(sample_rate_hz=640.0, aperture_pulses=48, range_bins=48)
    ss = surface_scene(
        cfg,
        ridge(2.5e-3, 4e-3),
        64,
        seed=5,
        spacing_m=default_spacing_m(cfg, 2.0),
        effects=[("noise", {"snr_db": 5.0}), ("interferometric_receivers", {"snr_db": 5.0})],
    )
    shots, aux = Simulator(ss.scene).block_with_aux(ss.scene.pulses)
    _, rg, _, main, slave = ridge_lines
    reg = estimate_registration(main, slave)
    kw = dict(strip_lines=16, overlap_lines=4, method="mcf")
    seq = np.arange(len(shots))

    class AuxReplay(ReplaySource):
        def __iter__(self):
            for batch in super().__iter__():
                batch.aux = {"rx1": aux["rx1"][batch.seq]}
                yield batch

    source = AuxReplay(shots, seq, seq / cfg.geometry.prf_hz, cfg.geometry.prf_hz, "max", 7)
    sink = HeightSink()
    stage = HeightStripStage(GEO, rg, reg, **kw)
    Pipeline(
        cfg,
        source,
        [sink],
        PipelineSettings(lens_backend="numpy", max_batch=8),
        ss.scene.start_along_track_m,
        height=stage,
    ).run()
    h, v = stitch(sink.heights)
    ref = height_map(main, slave, GEO, rg, registration=reg, method="mcf")
    assert np.array_equal(v, ref.valid) and np.max(np.abs(h - ref.height_m)) < 1e-9
    assert sink.final["counters"]["height_strips_published"] == len(sink.heights) == 4
    assert sink.final["height"]["strips_not_aligned"] == 0

    # The wire format round-trips (float32 heights, validity mask).
    info = StreamInfo("x", cfg, "test", "numpy", rg, 0.0, 0.0)  # what height_header reads
    s0 = sink.heights[1]
    header = height_header(s0, 1, info)
    frames = [
        b"height",
        json.dumps(header).encode(),
        s0.height_m.astype("<f4").tobytes(),
        s0.valid.astype(np.uint8).tobytes(),
        s0.coherence.astype("<f4").tobytes(),
    ]
    msg = decode(frames)
    assert np.array_equal(msg.valid, s0.valid)
    np.testing.assert_allclose(msg.lines, s0.height_m, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(msg.coherence, s0.coherence, rtol=1e-6, atol=1e-7)
    # A version 1 message (no coherence frame) still decodes; a frame count that does not fit
    # the version is refused.
    v1 = [frames[0], json.dumps({**header, "version": 1}).encode(), frames[2], frames[3]]
    old = decode(v1)
    assert old.coherence is None and np.array_equal(old.valid, s0.valid)
    with pytest.raises(ValueError, match="has 5 frames"):
        decode(frames[:4])
