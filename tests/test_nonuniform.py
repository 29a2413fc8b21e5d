"""The non-uniformly partitioned correlator: the float64 reference, push sizes, flush, threads."""

import numpy as np
import pytest
from conftest import crandn

from rtsar.analysis import relative_rms
from rtsar.ccd import make_ccd, make_correlator
from rtsar.ccd.base import correlate_reference
from rtsar.ccd.nonuniform import NonUniformCorrelator, plan_segments
from rtsar.ccd.partitioned import PartitionedCorrelator
from rtsar.params import Processor

TOL = 1e-5  # float32 sums of N terms, as the other correlators (test_ccd.py)


def _stream(corr, lines, sizes, flush_every=None):
    out, i = [], 0
    for k, b in enumerate(sizes):
        out.append(corr.push(lines[i : i + b]))
        i += b
        if flush_every and k % flush_every == 0:
            out.append(corr.flush())
    assert i == len(lines)
    out.append(corr.flush())
    return np.concatenate(out)


@pytest.mark.parametrize(
    "n, head, tail",
    [(512, 16, 128), (512, 8, 64), (64, 4, 16), (100, 8, 32), (37, 4, 8), (16, 16, 16), (2, 1, 1)],
)
@pytest.mark.parametrize("rule", ["optimal", "doubling"])
def test_plan_covers_the_mask_and_every_tail_block_is_early_enough(n, head, tail, rule):
    segs = plan_segments(n, head, min(tail, n), rule)
    assert segs[0][0] == 0 and segs[0][2] == head
    first = 0
    for s, (d, t, b) in enumerate(segs):
        assert d == first and t >= 1
        # A tail block completes a block's time before the last pulse of the lines it serves
        # arrives: computed meanwhile, it keeps the head from waiting for it.
        assert s == 0 or d >= 2 * b
        first += t
    assert first == n


@pytest.mark.parametrize("threaded", [False, True])
@pytest.mark.parametrize(
    # (96, 8, 128): N below the tail block and no power of two (refused before a cold review);
    # 40 range bins: more than one tile of columns, the last one partly used
    "n, head, tail, bins, rule",
    [
        (128, 4, 16, 9, "optimal"),  # a tail: 64 taps gave one segment with the lead
        (64, 4, 16, 40, "doubling"),
        (100, 8, 32, 5, "doubling"),
        (37, 2, 8, 3, "doubling"),
        (96, 8, 128, 4, "doubling"),
        (512, 16, 128, 3, "optimal"),
    ],
)
def test_matches_the_float64_reference(n, head, tail, bins, rule, threaded, rng):
    mask = crandn(rng, n, bins) / n
    lines = crandn(rng, 7 * n + 5, bins, dtype=np.complex64)
    ref = correlate_reference(lines, mask)
    corr = NonUniformCorrelator(mask, head, tail, threaded=threaded, rule=rule)
    got = _stream(corr, lines, [len(lines)])
    assert got.shape == ref.shape and got.dtype == np.complex64
    assert relative_rms(got, ref) < TOL
    assert corr.pulses_in == len(lines) and corr.lines_out == len(ref)
    corr.close()


@pytest.mark.parametrize("rule", ["optimal", "doubling"])
def test_output_is_bit_identical_whatever_the_pushes_and_the_thread(rule, rng):
    n, nr, p = 128, 7, 901  # a tail under both rules (64 taps: one segment, with the lead)
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, p, nr, dtype=np.complex64)
    first = NonUniformCorrelator(mask, 4, 32, threaded=False, rule=rule)
    assert len(first.segments) > 1  # a tail, whose thread and sums are what is tested
    one = _stream(first, lines, [p])
    sizes = [1] * 40 + [5, 3, 200, 1, 7, 131] + [1] * 10
    sizes.append(p - sum(sizes))
    for threaded in (False, True):
        corrs = [NonUniformCorrelator(mask, 4, 32, threaded=threaded, rule=rule) for _ in "ab"]
        by_line = _stream(corrs[0], lines, [1] * p)
        odd = _stream(corrs[1], lines, sizes)
        assert np.array_equal(by_line, one) and np.array_equal(odd, one)


@pytest.mark.parametrize("threaded", [False, True])
def test_the_tail_works_only_on_pushes_that_complete_one_of_its_blocks(threaded, rng):
    """A push of one line completes a tail block only every few lines (blocks of 4 here):
    the tail's thread is given a job (woken) only then, and the lines stay exact."""
    n, nr, p = 128, 5, 700
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, p, nr, dtype=np.complex64)
    corr = NonUniformCorrelator(mask, 1, 16, threaded=threaded)
    tail_blocks = [b for _, _, b in corr.segments[1:]]
    assert min(tail_blocks) == 4  # the plan this test reasons about
    jobs = []
    work = corr._tail._work
    corr._tail._work = lambda job: (jobs.append(job[0]), work(job))
    got = _stream(corr, lines, [1] * p)
    corr.close()
    # one job at each pulse count that ends a tail block, none at the others
    assert jobs == [end for end in range(1, p + 1) if any(end % b == 0 for b in tail_blocks)]
    assert relative_rms(got, correlate_reference(lines, mask)) < TOL


def test_flush_gives_every_complete_line_and_the_stream_goes_on(rng):
    n, nr = 128, 5
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, 500, nr, dtype=np.complex64)
    ref = correlate_reference(lines, mask)
    corr = NonUniformCorrelator(mask, 4, 16)
    assert len(corr.segments) > 1  # the tail's part of flush, too
    assert len(corr.push(lines[: n - 1])) == 0 and len(corr.flush()) == 0
    sizes = [3, 50, 1, 1, 2, 77, 9, 300 - n + 1]
    sizes.append(len(lines) - (n - 1) - sum(sizes))
    got = _stream(corr, lines[n - 1 :], sizes, flush_every=1)
    assert got.shape == ref.shape and corr.lines_out == len(ref)
    assert relative_rms(got, ref) < TOL


def test_lines_leave_in_head_blocks(rng):
    """The head block sets the latency: a line leaves once its head block is complete, as in
    the uniform correlator with that block."""
    n, nr, head = 64, 3, 8
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, 300, nr, dtype=np.complex64)
    nonuni, uni = NonUniformCorrelator(mask, head, 32), PartitionedCorrelator(mask, head)
    for p in range(len(lines)):
        a, b = nonuni.push(lines[p : p + 1]), uni.push(lines[p : p + 1])
        assert len(a) == len(b), p
        if len(a):
            assert relative_rms(a, b) < TOL


def test_fewer_multiply_adds_than_the_uniform_partition(rng):
    mask = crandn(rng, 512, 2) / 512
    doubling = NonUniformCorrelator(mask, 16, 128, rule="doubling")
    assert doubling.partitions == 10  # 4 × 16, 2 × (32, 64), 128 × 2 (the rest): 20 MACs a line
    optimal = NonUniformCorrelator(mask, 16, 128)
    assert optimal.segments == [(0, 128, 16), (128, 384, 64)]  # 8 × 16 + 6 × 64: 28 MACs
    assert PartitionedCorrelator(crandn(rng, 512, 2), 16).partitions == 32  # 2·32 = 64


@pytest.mark.parametrize("n, head, tail", [(512, 16, 128), (2048, 16, 512), (300, 4, 64)])
def test_the_optimal_plan_costs_no_more_than_any_other(n, head, tail):
    """Garcia 2002's search against plans built by hand: the doubling, the uniform partition
    and every two-segment plan."""
    from rtsar.ccd.nonuniform import transform_cost

    def cost(segs):
        return sum(transform_cost(b) + -(-t // b) for _, t, b in segs)

    best = cost(plan_segments(n, head, tail))
    others = [plan_segments(n, head, tail, "doubling"), [(0, n, head)]]
    for b in (2**i for i in range(20) if head < 2**i <= tail):
        for d in range(max(2 * b, head), n, head):  # the tail's lead (TAIL_LEAD)
            others.append([(0, d, head), (d, n - d, b)])
    assert all(best <= cost(o) + 1e-9 for o in others)
    with pytest.raises(ValueError, match="rule"):
        plan_segments(n, head, tail, "greedy")


def test_chosen_by_the_configuration(rng):
    from rtsar.lens.plan import make_plan
    from rtsar.presets import preset

    cfg = preset("tiny")
    proc = Processor(
        **{**cfg.processor.__dict__, "correlator": "nonuniform", "tail_block_lines": 16}
    )
    cfg = type(cfg)(**{**cfg.__dict__, "processor": proc})
    ccd = make_ccd(cfg, make_plan(cfg).range_m)
    assert isinstance(ccd, NonUniformCorrelator) and ccd.segments[-1][2] <= 16
    with pytest.raises(ValueError, match="tail_block_lines"):
        Processor(aperture_pulses=64, range_bins=8, tail_block_lines=3)
    assert isinstance(make_correlator("nonuniform", crandn(rng, 32, 2)), NonUniformCorrelator)


def test_a_failing_tail_is_reported_not_hung(rng):
    corr = NonUniformCorrelator(crandn(rng, 128, 3) / 128, 4, 16, threaded=True)
    assert len(corr.segments) > 1  # a tail to fail

    def broken(lines):
        raise MemoryError("no room")

    corr._tail._run = broken  # the kernel call of the tail's blocks
    with pytest.raises(RuntimeError, match="tail thread failed: no room"):
        corr.push(crandn(rng, 200, 3, dtype=np.complex64))


def test_every_correlator_has_a_memory_estimate_and_runs_in_the_pipeline():
    """Found by running the pipeline: the memory check knew only the older correlators."""
    from rtsar.params import Processor
    from rtsar.presets import preset
    from rtsar.scene import Simulator
    from rtsar.scene.model import point_scene
    from rtsar.sources.replay import ReplaySource
    from rtsar.stream.engine import process_block
    from rtsar.stream.memory import estimate_bytes
    from rtsar.stream.pipeline import Pipeline, PipelineSettings
    from rtsar.stream.strips import StripSink

    cfg = preset("tiny")
    for kind in Processor.CORRELATORS:
        assert estimate_bytes(cfg.with_processor(correlator=kind)) > 0
    r0 = cfg.geometry.slant_range_m
    scene = point_scene(cfg, [0.0, 4.0], [r0, r0 + 25.0])
    shots = Simulator(scene).block(scene.pulses)
    ref, _, _ = process_block(cfg.with_processor(correlator="direct"), shots, "numpy")

    class Collect(StripSink):
        lines: list = []

        def strip(self, strip, info):
            self.lines.append(strip.lines)

    seq = np.arange(len(shots))
    src = ReplaySource(shots, seq, seq / cfg.geometry.prf_hz, cfg.geometry.prf_hz, "max", 16)
    nonuni = cfg.with_processor(correlator="nonuniform", partition_lines=8, tail_block_lines=32)
    sink = Collect()
    Pipeline(nonuni, src, [sink], PipelineSettings(lens_backend="numpy")).run()
    got = np.concatenate(sink.lines)
    assert got.shape == ref.shape and relative_rms(got, ref) < TOL


@pytest.mark.slow
def test_a_process_that_never_closes_it_exits_cleanly():
    """Its tail thread used to die in the OpenMP runtime at interpreter exit (SIGABRT: 4 runs in
    10 of `rtsar run --correlator nonuniform`; this pattern, pushes from a non-main thread as the
    pipeline makes them, aborted about 1 run in 5 before the fix).  It is now ended at exit."""
    import subprocess
    import sys

    code = (
        "import threading, numpy as np\n"
        "from rtsar.ccd.nonuniform import NonUniformCorrelator as C\n"
        "def work():\n"
        "    c = C(np.ones((512, 1200), np.complex64) / 512, 16, 128, threaded=True)\n"
        "    for _ in range(30): c.push(np.ones((64, 1200), np.complex64))\n"
        "    work.c = c\n"
        "t = threading.Thread(target=work); t.start(); t.join()\n"
    )
    for _ in range(4):
        run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert run.returncode == 0, run.stderr[-500:]


def test_pushing_after_close_is_an_error_not_a_hang(rng):
    corr = NonUniformCorrelator(crandn(rng, 32, 3) / 32, 4, 8, threaded=True)
    corr.push(crandn(rng, 40, 3, dtype=np.complex64))
    corr.close()
    with pytest.raises(RuntimeError, match="closed"):
        corr.push(crandn(rng, 40, 3, dtype=np.complex64))


def test_tiled_transforms_and_spectra_against_numpy(rng):
    """The split-format kernels: the DIF transform gives the DFT in bit-reversed order, the
    inverse gives the second half of the inverse DFT, tile_spectra the bit-reversed /2B DFT."""
    from rtsar.ccd import tiled

    for n, cols in ((2, 5), (8, 48), (64, 16)):  # any row width: the kernels read it
        x = crandn(rng, n, cols)
        re, im = x.real.copy(), x.imag.copy()
        twr, twi = tiled.twiddles(2 * n, np.float64)  # stride 2: the table of a larger size
        tiled._dif(re, im, twr, twi, 2)
        want = np.fft.fft(x, axis=0)[tiled.bit_reversed(n)]
        assert np.allclose(re + 1j * im, want, atol=1e-12)
        y_re, y_im = np.zeros((n // 2, len(x[0]))), np.zeros((n // 2, len(x[0])))
        tiled._dit_second_half(re.copy(), im.copy(), twr, twi, 2, y_re, y_im)
        assert np.allclose(y_re + 1j * y_im, n * x[n // 2 :], atol=1e-12)
    taps = crandn(rng, 6, 3)
    hr, hi = tiled.tile_spectra(taps, 4, 2, np.float64)  # P = 2 partitions, tiles of 2 columns
    padded = np.zeros((2, 8, 4), complex)
    padded[0, :4, :3], padded[1, :2, :3] = taps[:4], taps[4:]
    want = (np.fft.fft(padded, axis=1) / 8)[:, tiled.bit_reversed(8)]
    got = (hr + 1j * hi).transpose(2, 1, 0, 3).reshape(2, 8, 4)  # [p, f, tile·C + c]
    assert np.allclose(got, want, atol=1e-12) and hr.shape == (2, 8, 2, 2)


def test_complex128_reaches_the_float64_reference(rng):
    mask = crandn(rng, 128, 5) / 128
    lines = crandn(rng, 300, 5)
    ref = correlate_reference(lines, mask)
    corr = NonUniformCorrelator(mask, 4, 16, precision="complex128", threaded=False)
    assert len(corr.segments) > 1
    got = _stream(corr, lines, [7] * 42 + [6])
    assert got.dtype == np.complex128 and relative_rms(got, ref) < 1e-12


def test_a_tile_holds_every_range_bin_up_to_the_widest():
    """tile_columns: one tile of all the bins (rounded up to whole AVX-512 registers) up to
    MOST_TILE_COLUMNS, equal tiles beyond; the correlator's rings have that width.  Tiles of 32
    columns spent more on the kernels' loop costs than on the arithmetic (tiled.tile_columns)."""
    from rtsar.ccd import tiled

    lanes, most = tiled.LANES, tiled.MOST_TILE_COLUMNS
    for bins in (1, 5, 16, 64, 320, 1200, most, most + 1, 3 * most, 3 * most + 7):
        tile = tiled.tile_columns(bins)
        tiles = -(-bins // tile)
        assert tile % lanes == 0 and tile <= most
        assert tiles == -(-bins // most)  # as few tiles as the widest allows
        assert tiles * tile - bins < tiles * lanes  # padding: under a register a tile
    assert tiled.tile_columns(1200) == 1200 and tiled.tile_columns(5) == 16
    with pytest.raises(ValueError, match="bins must be >= 1"):
        tiled.tile_columns(0)
    rng = np.random.default_rng(3)
    corr = NonUniformCorrelator(crandn(rng, 16, 40) / 16, 2, 8, threaded=False)
    assert corr._hist[0].shape[0] == 1 and corr._hist[0].shape[2] == 48
