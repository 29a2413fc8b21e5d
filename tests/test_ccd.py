"""The shifting CCD: direct, FFT and partitioned correlators against the float64 batch reference."""

import numpy as np
import pytest
from conftest import crandn
from naive import correlate_loops

from rtsar.analysis import relative_rms
from rtsar.ccd import make_correlator
from rtsar.ccd.base import aperture_offsets_m, correlate_reference, design_mask
from rtsar.ccd.direct import DirectCorrelator
from rtsar.ccd.fft import FFTCorrelator
from rtsar.ccd.partitioned import PartitionedCorrelator
from rtsar.lens.plan import make_plan
from rtsar.presets import preset

TOL = 1e-5  # float32 accumulation of N terms: ~sqrt(N)·6e-8 ≪ 1e-5


def test_reference_equals_naive_loops(rng):
    lines, mask = crandn(rng, 40, 5), crandn(rng, 9, 5)
    np.testing.assert_allclose(
        correlate_reference(lines, mask), correlate_loops(lines, mask), rtol=1e-12, atol=1e-12
    )


def _stream(corr, lines, sizes):
    out, i = [], 0
    for b in sizes:
        out.append(corr.push(lines[i : i + b]))
        i += b
    assert i == len(lines)
    out.append(corr.flush())
    return np.concatenate(out)


@pytest.mark.parametrize("cls", [DirectCorrelator, FFTCorrelator, PartitionedCorrelator])
def test_streaming_equals_batch_reference(cls, rng):
    n, nr, p = 64, 23, 700
    mask = crandn(rng, n, nr) / n
    lines = crandn(rng, p, nr, dtype=np.complex64)
    ref = correlate_reference(lines, mask)
    sizes = [1, 2, 61, 64, 65, 127, 3, 200, 177]
    got = _stream(cls(mask), lines, sizes)
    assert got.shape == ref.shape == (p - n + 1, nr)
    assert relative_rms(got, ref) < TOL


def test_fft_block_length_is_a_knob(rng):
    n, nr = 32, 7
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, 300, nr, dtype=np.complex64)
    ref = correlate_reference(lines, mask)
    for m in (32, 45, 48, 64, 75, 256):  # any product of 2, 3 and 5 >= N
        corr = FFTCorrelator(mask, fft_length=m)
        assert corr.block_lines == m - n + 1
        assert relative_rms(_stream(corr, lines, [300]), ref) < TOL
    assert FFTCorrelator(mask, fft_length=np.int64(45)).fft_length == 45  # NumPy's integers
    for m in (30, 49, 66):  # below N; 7²; 2·3·11
        with pytest.raises(ValueError, match="product of 2, 3 and 5"):
            FFTCorrelator(mask, fft_length=m)


@pytest.mark.parametrize("m", [32, 45, 64])
def test_fft_skip_zeros_is_pushing_zeros_without_the_transforms(m, rng):
    """skip_zeros(k) (the granularity's fill): the counters and the lines that follow are
    push(zeros(k))'s, bit for bit, in pieces of any size; refused once real lines came."""
    n, nr = 32, 5
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, 90, nr, dtype=np.complex64)
    pushed, skipped = FFTCorrelator(mask, fft_length=m), FFTCorrelator(mask, fft_length=m)
    want = [len(pushed.push(np.zeros((k, nr), np.complex64))) for k in (7, 1, 33, 19)]
    assert [skipped.skip_zeros(k) for k in (7, 1, 33, 19)] == want
    assert (skipped.pulses_in, skipped.lines_out) == (pushed.pulses_in, pushed.lines_out)
    np.testing.assert_array_equal(skipped.push(lines), pushed.push(lines))
    np.testing.assert_array_equal(skipped.flush(), pushed.flush())
    with pytest.raises(RuntimeError, match="other than zeros"):
        skipped.skip_zeros(1)


def test_no_line_before_the_aperture_is_full(rng):
    n = 16
    corr = DirectCorrelator(crandn(rng, n, 3))
    assert len(corr.push(crandn(rng, n - 1, 3))) == 0
    assert len(corr.push(crandn(rng, 1, 3))) == 1
    assert corr.pulses_in == n and corr.lines_out == 1


def test_long_run_has_no_drift():
    """A stationary target's line after 10⁶ pulses equals its line after the first aperture."""
    n, nr, total = 64, 4, 1_000_000
    rng = np.random.default_rng(3)
    mask = (crandn(rng, n, nr) / n).astype(np.complex64)
    history = crandn(rng, n, nr, dtype=np.complex64)  # the target's periodic history
    corr = DirectCorrelator(mask)
    block = np.tile(history, (5, 1))  # 320 pulses: 10⁶ is a whole number of blocks
    first = last = None
    pushed = 0
    while pushed < total:
        out = corr.push(block)
        pushed += len(block)
        if first is None and len(out):
            first = out[0].copy()
        last = out[-1]
    # Output lines with the same phase of the period are identical: after a multiple of n.
    assert pushed % n == 0 and corr.lines_out == total - n + 1
    expected = correlate_reference(history, mask)[0]
    assert relative_rms(first, expected) < TOL
    np.testing.assert_array_equal(last, first)  # bit-identical: each line sums exactly N terms


@pytest.mark.parametrize(
    "n, block, bins",
    [(64, 16, 23), (64, 1, 5), (64, 64, 5), (50, 16, 7), (37, 8, 40), (2, 1, 3), (2, 2, 3)],
)
def test_partitioned_matches_reference(n, block, bins, rng):
    """L = 1, L = N, N not a multiple of L (a zero-padded last partition) and range bins not a
    multiple of the column group (zero-padded columns) included."""
    mask = crandn(rng, n, bins) / n
    lines = crandn(rng, 5 * n + 3, bins, dtype=np.complex64)
    ref = correlate_reference(lines, mask)
    corr = PartitionedCorrelator(mask, block)
    assert corr.partitions == -(-n // block)
    got = _stream(corr, lines, [len(lines)])
    assert got.shape == ref.shape
    assert relative_rms(got, ref) < TOL
    assert corr.pulses_in == len(lines) and corr.lines_out == len(ref)


def test_partitioned_output_does_not_depend_on_push_sizes(rng):
    n, nr, p = 48, 9, 613
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, p, nr, dtype=np.complex64)
    one_push = _stream(PartitionedCorrelator(mask, 8), lines, [p])
    by_line = _stream(PartitionedCorrelator(mask, 8), lines, [1] * p)
    odd = _stream(PartitionedCorrelator(mask, 8), lines, [5, 3, 200, 1, 7, 131, 266])
    for got in (by_line, odd):
        assert got.shape == one_push.shape == (p - n + 1, nr)
        assert relative_rms(got, one_push) < 1e-6  # the same sums, block by block


def test_partitioned_flush_emits_every_complete_line_and_the_stream_goes_on(rng):
    n, nr, block = 32, 5, 16
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, 200, nr, dtype=np.complex64)
    ref = correlate_reference(lines, mask)
    corr = PartitionedCorrelator(mask, block)
    # Before the N-th pulse nothing is complete, flushed or not.
    assert len(corr.push(lines[: n - 1])) == 0 and len(corr.flush()) == 0
    got = [corr.push(lines[n - 1 : 70])]  # 70 pulses: 64 in whole blocks, 6 pending
    assert corr.lines_out == 64 - n + 1
    got.append(corr.flush())  # the 6 pending pulses complete 6 more lines
    assert corr.lines_out == 70 - n + 1 == corr.pulses_in - n + 1
    assert len(corr.flush()) == 0  # nothing twice
    # Flushing does not disturb the stream: the rest equals the batch result.
    got += [corr.push(lines[70:75]), corr.flush(), corr.push(lines[75:]), corr.flush()]
    got = np.concatenate(got)
    assert got.shape == ref.shape and corr.lines_out == len(ref)
    assert relative_rms(got, ref) < TOL


@pytest.mark.parametrize("block", [4, 16])
def test_partitioned_first_line_is_the_first_full_aperture(block, rng):
    n = 16
    corr = PartitionedCorrelator(crandn(rng, n, 3), block)
    assert len(corr.push(crandn(rng, n - 1, 3))) == 0
    assert len(corr.push(crandn(rng, 1, 3))) == 1  # pulse N completes a block and a line
    assert corr.pulses_in == n and corr.lines_out == 1


def test_all_correlators_agree(rng):
    n, nr = 40, 6
    mask, lines = crandn(rng, n, nr) / n, crandn(rng, 333, nr, dtype=np.complex64)
    sizes = [17, 1, 64, 100, 151]
    outs = {
        kind: _stream(make_correlator(kind, mask, partition_lines=8), lines, sizes)
        for kind in ("direct", "fft", "partitioned")
    }
    for a in outs:
        for b in outs:
            assert relative_rms(outs[a], outs[b]) < 2 * TOL, (a, b)


def test_partitioned_long_run_stays_on_the_reference():
    """10⁵ pulses of a periodic history: every line equals its batch value (nothing drifts)."""
    n, nr, total = 64, 4, 100_003  # 100 003: a partial block is left for flush()
    rng = np.random.default_rng(5)
    mask = (crandn(rng, n, nr) / n).astype(np.complex64)
    history = crandn(rng, n, nr, dtype=np.complex64)
    expected = correlate_reference(np.tile(history, (2, 1)), mask)[:n]  # line j: expected[j % n]
    stream = np.tile(history, (total // n + 1, 1))[:total]
    corr = PartitionedCorrelator(mask, 16)
    pushes = [stream[i : i + 999] for i in range(0, total, 999)]  # blocks straddle pushes
    worst = 0.0
    for push in [*pushes, None]:
        first = corr.lines_out
        out = corr.flush() if push is None else corr.push(push)
        if len(out):
            want = expected[(first + np.arange(len(out))) % n]
            worst = max(worst, relative_rms(out, want))
    assert corr.lines_out == total - n + 1
    assert worst < TOL


def test_partitioned_block_must_be_a_power_of_two_up_to_n(rng):
    mask = crandn(rng, 32, 3)
    for block in (0, 3, 64, 2.0):
        with pytest.raises(ValueError, match="block_lines"):
            PartitionedCorrelator(mask, block)
    assert make_correlator("partitioned", mask, partition_lines=32).block_lines == 32
    with pytest.raises(ValueError, match="partitioned"):
        make_correlator("fourier", mask)


def test_mask_is_conjugate_exact_history_and_per_bin():
    cfg = preset("crouch-sal")
    rng_m = make_plan(cfg).range_m
    mask = design_mask(cfg, rng_m)
    x = aperture_offsets_m(cfg)
    lam = cfg.geometry.wavelength_m
    for r_idx in (0, len(rng_m) // 2, len(rng_m) - 1):
        r = rng_m[r_idx]
        expected_phase = -4 * np.pi / lam * (np.sqrt(r * r + x * x) - r)
        history = np.exp(1j * expected_phase)
        # Mask · history is real and positive: the mask undoes the exact (hyperbolic) phase.
        prod = mask[:, r_idx] * history
        assert np.max(np.abs(np.angle(prod))) < 1e-6
        assert abs(prod.sum() - 1) < 1e-9
    single = design_mask(cfg.with_processor(per_bin_mask=False), rng_m)
    np.testing.assert_allclose(single[:, 0], single[:, -1])
    # The chirp rate depends on range: at the swath edge one mask is off by radians.
    assert np.max(np.abs(np.angle(single[:, 0] / mask[:, 0]))) > 1.0


@pytest.mark.parametrize("kind", ["fft", "partitioned", "nonuniform", "direct"])
@pytest.mark.parametrize("aperture", [64, 80])
def test_first_line_pulses_is_when_the_correlator_emits_its_first_line(kind, aperture):
    """The live hint "the first image line comes after … s" (rtsar run) counted one aperture;
    the FFT mode's first block of M - N + 1 lines came much later (a cold review waited 46 s,
    told 32 s).  first_line_pulses is checked against the correlator itself, pulse by pulse."""
    from rtsar.ccd import first_line_pulses, make_ccd
    from rtsar.lens import make_plan
    from rtsar.presets import preset

    cfg = preset("tiny").with_processor(correlator=kind, aperture_pulses=aperture)
    plan = make_plan(cfg)
    ccd = make_ccd(cfg, plan.range_m)
    line = np.zeros((1, plan.bin_count), np.complex64)
    pulses = 0
    while not len(ccd.push(line)):
        pulses += 1
    ccd.close()
    assert pulses + 1 == first_line_pulses(cfg.processor)
