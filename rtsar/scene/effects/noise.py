"""Receiver noise: circular complex white Gaussian noise at a stated per-sample SNR."""

from __future__ import annotations

import math

from .base import Effect


class ReceiverNoise(Effect):
    """Thermal (or LO shot) noise of the receiver.

    ``snr_db`` is the per-sample signal-to-noise ratio of a unit-amplitude scatterer before any
    compression: noise variance σ² = 10^(-snr_db/10), split equally between I and Q.  Range and
    azimuth compression then add their coherent gains (time-bandwidth product, N).
    """

    name = "noise"

    def __init__(self, config, snr_db: float):
        if not math.isfinite(snr_db):
            raise ValueError("noise.snr_db must be finite")
        self.snr_db = float(snr_db)
        self.sigma = math.sqrt(0.5 * 10.0 ** (-self.snr_db / 10.0))

    def apply_to_shot(self, pulse, samples, rng):
        noise = rng.standard_normal((2, samples.shape[-1]))
        samples += self.sigma * (noise[0] + 1j * noise[1])
