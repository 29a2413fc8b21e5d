"""rtsar.analysis.chirp_sign: the contrast that tells a chirp's sign from the echoes."""

from __future__ import annotations

import numpy as np
import pytest

from rtsar.analysis.chirp_sign import (
    FLIPPED_SHARPER,
    chirp_sign_contrasts,
    chirp_sign_warning,
    compression_contrast,
)


def test_speckle_has_a_contrast_of_two_and_a_point_far_more():
    rng = np.random.default_rng(1)
    speckle = rng.standard_normal((64, 4096)) + 1j * rng.standard_normal((64, 4096))
    assert compression_contrast(speckle) == pytest.approx(2.0, abs=0.05)  # E|z|⁴ = 2 (E|z|²)²
    point = np.zeros((4, 1000), complex)
    point[:, 10] = 1.0
    assert compression_contrast(point) == pytest.approx(1000.0)  # all power in 1 of 1000
    assert compression_contrast(np.zeros((2, 8))) == 0.0


class _MatchedFilter:
    """A lens of one up-chirp (rate > 0), written here: correlation with exp(iπ k t²)."""

    def __init__(self, samples: int, chirp: np.ndarray):
        self.n, self.ref = samples, np.conj(np.fft.fft(chirp, samples))

    def compress(self, x):
        return np.fft.ifft(np.fft.fft(x, self.n, axis=1) * self.ref, axis=1)


def test_the_sign_of_the_echoes_chirp_is_told_and_only_then():
    t = np.arange(256) - 128.0
    up = np.exp(1j * np.pi * 0.002 * t**2)  # 0.002 cycles/sample² over 256 samples
    rng = np.random.default_rng(2)
    shots = 0.3 * (rng.standard_normal((32, 2048)) + 1j * rng.standard_normal((32, 2048)))
    for at, amp in ((300, 4.0), (900, 2.0), (1500, 3.0)):  # three points, up-chirped echoes
        shots[:, at : at + 256] += amp * up
    lens = _MatchedFilter(2048, up)
    given, flipped = chirp_sign_contrasts(lens, shots)
    assert given > FLIPPED_SHARPER * flipped  # the right sign compresses sharper
    assert chirp_sign_warning(given, flipped, "k") is None
    wrong = np.conj(shots)  # down-chirped echoes (or conjugated samples) under an up-chirp
    g2, f2 = chirp_sign_contrasts(lens, wrong)
    assert (g2, f2) == pytest.approx((flipped, given), rel=1e-4)
    said = chirp_sign_warning(g2, f2, "radar.chirp_rate_hz_per_s")
    assert said is not None and "radar.chirp_rate_hz_per_s" in said
    # speckle alone: no sign to tell, nothing said
    noise = rng.standard_normal((32, 2048)) + 1j * rng.standard_normal((32, 2048))
    assert chirp_sign_warning(*chirp_sign_contrasts(lens, noise), "k") is None
