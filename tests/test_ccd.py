"""The shifting CCD: direct and FFT correlators against the float64 batch reference."""

import numpy as np
import pytest
from conftest import crandn
from naive import correlate_loops

from rtsar.ccd import (
    DirectCorrelator,
    FFTCorrelator,
    aperture_offsets_m,
    correlate_reference,
    design_mask,
)
from rtsar.lens_plan import make_plan
from rtsar.metrics import relative_rms
from rtsar.params import preset

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


@pytest.mark.parametrize("cls", [DirectCorrelator, FFTCorrelator])
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
    for m in (32, 64, 256):
        corr = FFTCorrelator(mask, fft_length=m)
        assert corr.block_lines == m - n + 1
        assert relative_rms(_stream(corr, lines, [300]), ref) < TOL
    with pytest.raises(ValueError):
        FFTCorrelator(mask, fft_length=48)


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
