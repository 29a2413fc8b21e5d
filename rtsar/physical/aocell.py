"""The acousto-optic cell as hardware: bandwidth, time aperture, saturating diffraction, noise.

Psaltis & Wagner 1981, "Description of the processor": the received signal, heterodyned to the
transducer's centre frequency, drives the AO cell; "for weak modulation, the amplitude of the
light diffracted to the first order is proportional to S_R(t - x/v)"; the experimental cell has
40 MHz bandwidth and a 10 µs aperture; Table 1 lists AO bandwidth, AO linearity and amplifier
noise among the limiting factors.  AOCell.apply maps raw shots (complex baseband, the
transducer's centre at 0 Hz) to the light amplitude the lens focuses, with the named effects in
the order of the hardware:

* amplifier_noise: circular complex Gaussian noise of the drive amplifier, ``rms`` per sample;
* bandwidth: the transducer's response, |H(f)|² = exp(-ln 2 · (2f / B)²) (-3 dB at ±B/2),
  applied as a linear (zero-padded) filter per shot;
* diffraction_saturation: Bragg diffraction, amplitude a_sat·(2/π)·sin(π|s| / (2 a_sat)) with
  the phase of s, i.e. s · sinc(|s| / (2 a_sat)); linear for |s| ≪ a_sat, at most (2/π)·a_sat;
* time_aperture: the cell holds ``aperture_s`` of signal (centred in the shot; outside, no
  light) and the acoustic wave loses ``attenuation_db`` from the transducer to the far end: the
  oldest sample, farthest from the transducer, the most.

Effects not named are not computed: with none, apply returns its input (as complex64) untouched.
"""

from __future__ import annotations

import math

import numpy as np

from ..lens.plan import next_pow2
from ..params import Config
from .settings import PhysicalSettings


class AOCell:
    """The AO cell stage on raw shots[pulse, sample] (complex64 in, complex64 out)."""

    def __init__(self, config: Config, settings: PhysicalSettings | None = None):
        settings = settings or PhysicalSettings()
        wf = config.waveform
        self.samples_per_shot = s = wf.samples_per_shot
        fs = wf.sample_rate_hz
        self.enabled = bool(settings.ao)
        seed = np.random.SeedSequence([settings.seed, 0xA0C3])
        self._rng = np.random.default_rng(seed)
        noise = settings.ao_effect("amplifier_noise")
        self._noise_rms = 0.0 if noise is None else noise.rms
        self._response = None
        bw = settings.ao_effect("bandwidth")
        if bw is not None:
            self._nfft = next_pow2(2 * s)
            f = np.fft.fftfreq(self._nfft, d=1.0 / fs)
            self._response = np.exp(-0.5 * math.log(2.0) * (2.0 * f / bw.bandwidth_hz) ** 2)
        sat = settings.ao_effect("diffraction_saturation")
        self._a_sat = None if sat is None else sat.saturation_amplitude
        self._aperture = None
        ap = settings.ao_effect("time_aperture")
        if ap is not None:
            held = min(s, max(1, int(round(ap.aperture_s * fs))))
            start = (s - held) // 2
            gain = np.zeros(s)
            # Sample n of the window is received n samples after the oldest one, which has run
            # the whole cell: attenuation falls linearly in dB from attenuation_db to 0.
            frac = np.arange(held) / max(held - 1, 1)
            gain[start : start + held] = 10.0 ** (-ap.attenuation_db * (1.0 - frac) / 20.0)
            self._aperture = gain

    def apply(self, shots: np.ndarray) -> np.ndarray:
        """Light amplitude diffracted by the cell for each shot (complex64[pulse, sample])."""
        x = np.asarray(shots)
        if x.ndim != 2 or x.shape[1] != self.samples_per_shot:
            raise ValueError(f"shots must be [pulses, {self.samples_per_shot}], got {x.shape}")
        if not self.enabled:
            return x.astype(np.complex64, copy=False)
        if not np.all(np.isfinite(x)):
            raise ValueError("shots hold NaN or Inf: the AO cell cannot be driven by them")
        y = x.astype(np.complex128)
        if self._noise_rms:
            g = self._rng.standard_normal((2, *y.shape))
            y = y + (self._noise_rms / math.sqrt(2.0)) * (g[0] + 1j * g[1])
        if self._response is not None:
            spec = np.fft.fft(y, self._nfft, axis=1) * self._response
            y = np.fft.ifft(spec, axis=1)[:, : self.samples_per_shot]
        if self._a_sat is not None:
            y = y * np.sinc(np.abs(y) / (2.0 * self._a_sat))
        if self._aperture is not None:
            y = y * self._aperture
        return y.astype(np.complex64)
