"""Reference-region phase-error correction (INO phase-error patent, eqs. 5-11): a stream stage.

Two reference receivers see a uniform reference region lit by a collimated beam: receiver 1
(the main channel's receiver, S1r) and the collimated transceiver (S2r), spaced by D.  Over the
reference range bins t_i their range-compressed phases carry, beside the speckle,

    S1r ∝ exp(-i 2π/λ (2α - Dβ)),     S2r ∝ exp(-i 2π/λ (2α - 2Dβ))           (eqs. 5a, 5b)

The patent estimates the azimuth phase gradient of each channel (eqs. 6-7: FFT derivative over
the whole aperture), averages it over the reference bins to beat the speckle, integrates it along
track (eq. 8) and solves for α and β (eq. 9).  In the stream the gradient over one pulse step is
taken causally, as the phase of the lag-one product summed over the reference bins (the discrete
form of Im[S' S*]/|S|² integrated over Δx, with the bins' products summed, i.e. weighted by their
power: the minimum-variance combination the patent calls for):

    ΔΦ_c(n) = arg Σ_i S_c(t_i, n) S_c*(t_i, n-1),       Φ_c(n) = Σ_{m≤n} ΔΦ_c(m)       (eqs. 6-8)

(``weighting="uniform"``: the mean over bins of each bin's own phase step, as eq. 7 written per
bin).  With rtsar's sign (phase -2π/λ × path), Φ1 = -2π/λ (2α - Dβ), Φ2 = -2π/λ (2α - 2Dβ), so

    α = -λ/(4π) (2Φ1 - Φ2),    β = -λ/(2πD) (Φ1 - Φ2)                                  (eq. 9)

(the patent's eq. 9 with its sign convention), and the target channel is corrected with the
d, D geometry:

    φ1t = -2π/λ (2α + dβ),     Ŝ1t = S1t · exp(-i φ1t)                          (eqs. 10, 11)

α and β are relative to the first pulse (the integration constant of eq. 8).  The Φ_c are
unbounded float64 sums (β needs Φ1 - Φ2 unwrapped: d/D is not an integer); the correction phase
is reduced mod 2π before the exponential.  A step whose lag-one coherence
|Σ S_n S*_{n-1}| / sqrt(Σ|S_n|² Σ|S_{n-1}|²) is below ``min_coherence`` (or whose reference
data are not finite) adds ΔΦ = 0 (that channel's estimate holds) and is counted in
``pulses_not_estimated``.  Like any gradient estimate it needs the error sampled: |ΔΦ_c| < π
per pulse, i.e. the round-trip path error of each reference channel must change by less than λ/2
from one pulse to the next (a faster error aliases by 2π and β then slips by λ/D).

Place: between ingest and the AO lens.  ``process(shots, aux)`` takes raw main shots and the raw
reference channels (their own LO delay, ``ReferenceGeometry.lo_range_m``); the stage range-
compresses the reference bins itself (NumPy, float64).  The correction is one phase per pulse,
so it may equally be applied to range-compressed main lines.  Causal, no latency beyond the
micro-batch, memory: the previous pulse's reference bins.  ``reference_region_reference`` is
the float64 per-pulse reference the stage is tested against.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..instrument import REFERENCE_CHANNELS
from ..lens.base import compress_reference
from ..lens.numpy_lens import NumpyLens
from ..lens.plan import make_plan
from ..params import Config, FMCWChirp
from ..phase import phasor
from .stage import CorrectionStage

CHANNELS = REFERENCE_CHANNELS
WEIGHTINGS = ("power", "uniform")


@dataclass(frozen=True)
class ReferenceGeometry:
    """The patent's spacings (Fig. 3) and where the reference region sits in range.

    d_m: target transmitter ↔ first receiver; D_m: first receiver ↔ collimated transceiver;
    region_range_m, region_depth_m: slant-range centre and extent of the lit reference region
    (seen from the transceiver); lo_range_m: the reference receivers' LO delay as a range
    (None: region_range_m).
    """

    d_m: float
    D_m: float
    region_range_m: float
    region_depth_m: float
    lo_range_m: float | None = None

    def __post_init__(self):
        for name in ("d_m", "D_m", "region_range_m", "region_depth_m"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"ReferenceGeometry.{name} must be finite and >= 0, got {v!r}")
        if self.D_m <= 0 or self.region_range_m <= 0 or self.region_depth_m <= 0:
            raise ValueError("ReferenceGeometry: D_m, region_range_m, region_depth_m must be > 0")
        if self.lo_range_m is not None and not (
            math.isfinite(self.lo_range_m) and self.lo_range_m > 0
        ):
            raise ValueError("ReferenceGeometry.lo_range_m must be > 0")

    @property
    def lo_m(self) -> float:
        return self.region_range_m if self.lo_range_m is None else float(self.lo_range_m)

    @classmethod
    def from_effect(cls, effect) -> ReferenceGeometry:
        """The geometry of a ``reference_region`` scene effect (any object with its fields)."""
        return cls(
            float(effect.d_m),
            float(effect.D_m),
            float(effect.region_range_m),
            float(effect.region_depth_m),
            float(effect.lo_range_m),
        )

    def channel_centres_m(self) -> tuple[float, float]:
        """Effective (half-path) range of the region centre in S1r and S2r (eqs. 2b, 2d)."""
        r = self.region_range_m
        return 0.5 * (r + math.hypot(r, self.D_m)), r


def reference_plan(config: Config, geometry: ReferenceGeometry):
    """AO-lens plan of the reference receivers: their LO delay, bins spanning both channels'
    region (rectangular window, no oversampling: independent bins).  → (plan, masks[2, bins])."""
    wf = config.waveform
    if not isinstance(wf, FMCWChirp):
        raise ValueError("the reference-region correction needs an FMCW waveform")
    rho = wf.range_resolution_m
    c1, c2 = geometry.channel_centres_m()
    half = 0.5 * geometry.region_depth_m
    lo_m, hi_m = min(c1, c2) - half - 2 * rho, max(c1, c2) + half + 2 * rho
    bins = int(math.ceil((hi_m - lo_m) / rho)) + 1
    cfg = replace(
        config,
        waveform=replace(wf, reference_range_m=geometry.lo_m),
        processor=replace(
            config.processor,
            range_bins=bins,
            range_centre_m=0.5 * (lo_m + hi_m),
            range_oversampling=1,
            range_window="rect",
        ),
    )
    plan = make_plan(cfg)
    masks = np.stack([np.abs(plan.range_m - c) <= half for c in (c1, c2)])
    if masks.sum(axis=1).min() < 2:
        raise ValueError("the reference region spans fewer than 2 range bins")
    return plan, masks


def solve_alpha_beta(phi1_rad, phi2_rad, wavelength_m: float, D_m: float):  # noqa: N803
    """Patent eq. 9 in rtsar's sign convention: (α m, β rad) from the integrated phases."""
    phi1 = np.asarray(phi1_rad, np.float64)
    phi2 = np.asarray(phi2_rad, np.float64)
    alpha = -wavelength_m / (4.0 * math.pi) * (2.0 * phi1 - phi2)
    beta = -wavelength_m / (2.0 * math.pi * D_m) * (phi1 - phi2)
    return alpha, beta


def target_phase_rad(alpha_m, beta_rad, wavelength_m: float, d_m: float) -> np.ndarray:
    """Patent eq. 10: φ1t = -2π/λ (2α + dβ), the phase the errors add to the target channel."""
    return -2.0 * math.pi / wavelength_m * (2.0 * np.asarray(alpha_m) + d_m * np.asarray(beta_rad))


def _check_weighting(weighting: str, min_coherence: float):
    if weighting not in WEIGHTINGS:
        raise ValueError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    if not (math.isfinite(min_coherence) and 0 <= min_coherence < 1):
        raise ValueError("min_coherence must be in [0, 1)")


def reference_region_reference(
    samples: np.ndarray,
    aux: dict,
    config: Config,
    geometry: ReferenceGeometry,
    weighting: str = "power",
    min_coherence: float = 0.2,
) -> dict:
    """Float64 batch reference, pulse by pulse, of the whole correction (eqs. 6-11).

    samples[pulse, :] main shots (raw or compressed); aux: {"reference_rx1", "reference_rx2"}
    raw shots.  Returns {"corrected" complex128, "alpha_m", "beta_rad", "target_phase_rad",
    "estimated" bool per pulse}.
    """
    _check_weighting(weighting, min_coherence)
    plan, masks = reference_plan(config, geometry)
    lam = config.geometry.wavelength_m
    main = np.asarray(samples, np.complex128)
    n = len(main)
    phi = np.zeros((2, n))
    estimated = np.ones(n, bool)
    for c, name in enumerate(CHANNELS):
        raw = np.asarray(aux[name], np.complex128)
        if raw.shape[0] != n:
            raise ValueError(f"aux {name!r} has {raw.shape[0]} pulses, samples {n}")
        total, prev = 0.0, None
        for p in range(n):
            line = None
            if np.all(np.isfinite(raw[p])):
                line = compress_reference(plan, raw[p : p + 1])[0][masks[c]]
            step_ok = False
            if line is not None and prev is not None:
                prod = line * np.conj(prev)
                norm = math.sqrt(np.sum(np.abs(line) ** 2) * np.sum(np.abs(prev) ** 2))
                if norm > 0 and abs(np.sum(prod)) >= min_coherence * norm:
                    step = (
                        np.angle(np.sum(prod)) if weighting == "power" else np.mean(np.angle(prod))
                    )
                    total += float(step)
                    step_ok = True
            if p > 0 and not step_ok:
                estimated[p] = False
            phi[c, p] = total
            prev = line
    alpha, beta = solve_alpha_beta(phi[0], phi[1], lam, geometry.D_m)
    phase = target_phase_rad(alpha, beta, lam, geometry.d_m)
    corrected = main * phasor(-phase)[:, None]
    return {
        "corrected": corrected,
        "alpha_m": alpha,
        "beta_rad": beta,
        "target_phase_rad": phase,
        "estimated": estimated,
    }


class ReferenceRegionCorrector(CorrectionStage):
    """The reference-region correction in the stream (before the AO lens).

    ``process(samples, aux)``: samples[pulse, :] (raw shots or compressed lines, any complex
    dtype, returned in that dtype), aux = {"reference_rx1": raw, "reference_rx2": raw} for the
    same pulses.  After each call ``last_alpha_m``, ``last_beta_rad``, ``last_target_phase_rad``
    hold the batch's estimates.  Counters: ``pulses_in``, ``pulses_not_estimated`` (a channel's
    step failed: held), ``nonfinite_reference`` (reference shots holding NaN/Inf).
    """

    domain = "raw"
    channels = CHANNELS
    counter_names = ("pulses_in", "pulses_not_estimated", "nonfinite_reference")

    def __init__(
        self,
        config: Config,
        geometry: ReferenceGeometry,
        weighting: str = "power",
        min_coherence: float = 0.2,
    ):
        _check_weighting(weighting, min_coherence)
        self.config = config
        self.geometry = geometry
        self.weighting = weighting
        self.min_coherence = float(min_coherence)
        self.plan, self.masks = reference_plan(config, geometry)
        self._lens = NumpyLens(self.plan, precision="complex128")
        self.wavelength_m = config.geometry.wavelength_m
        self._phi = np.zeros(2)  # Φ1, Φ2 after the last pulse (float64, unwrapped)
        self._prev: list[np.ndarray | None] = [None, None]  # previous pulse's reference bins
        self.pulses_in = 0
        self.pulses_not_estimated = 0
        self.nonfinite_reference = 0
        self.last_alpha_m = self.last_beta_rad = self.last_target_phase_rad = np.zeros(0)

    def _integrate(self, c: int, raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Φ_c after each pulse of the batch, and which steps were estimated."""
        raw = np.asarray(raw)
        finite = np.isfinite(raw).all(axis=1)
        if not finite.all():
            self.nonfinite_reference += int((~finite).sum())
            raw = np.where(finite[:, None], raw, 0)
        lines = self._lens.compress(raw)[:, self.masks[c]]
        prev = self._prev[c]
        # Row 0 of "before" is the previous batch's last pulse (or a zero row at the start).
        before = np.concatenate(
            [np.zeros_like(lines[:1]) if prev is None else prev[None], lines[:-1]]
        )
        ok_before = np.concatenate([[prev is not None], finite[:-1]])
        prod = lines * np.conj(before)
        z = prod.sum(axis=1)
        norm = np.sqrt((np.abs(lines) ** 2).sum(axis=1) * (np.abs(before) ** 2).sum(axis=1))
        ok = finite & ok_before & (norm > 0) & (np.abs(z) >= self.min_coherence * norm)
        if self.weighting == "power":
            step = np.angle(z)
        else:
            step = np.angle(prod).mean(axis=1)
        phi = self._phi[c] + np.cumsum(np.where(ok, step, 0.0))
        self._prev[c] = lines[-1] if finite[-1] else None
        if len(phi):
            self._phi[c] = phi[-1]
        return phi, ok

    def process(self, samples: np.ndarray, aux: dict) -> np.ndarray:
        """Correct a micro-batch (pulse order); returns the corrected samples."""
        samples = np.asarray(samples)
        if samples.ndim != 2 or not np.iscomplexobj(samples):
            raise ValueError("samples must be a complex array [pulses, samples_or_bins]")
        n = len(samples)
        if aux is None or any(name not in aux for name in CHANNELS):
            raise ValueError(f"aux must hold the reference channels {CHANNELS}")
        for name in CHANNELS:
            shape = np.shape(aux[name])
            if len(shape) != 2 or shape[0] != n or shape[1] != self.plan.samples_per_shot:
                raise ValueError(
                    f"aux {name!r} must be [{n}, {self.plan.samples_per_shot}], got {shape}"
                )
        if n == 0:
            return samples.copy()
        first = self.pulses_in == 0
        phi1, ok1 = self._integrate(0, aux[CHANNELS[0]])
        phi2, ok2 = self._integrate(1, aux[CHANNELS[1]])
        failed = ~(ok1 & ok2)
        if first:
            failed[0] = False  # the first pulse has no step to estimate: it is the origin
        self.pulses_not_estimated += int(failed.sum())
        self.pulses_in += n
        alpha, beta = solve_alpha_beta(phi1, phi2, self.wavelength_m, self.geometry.D_m)
        phase = target_phase_rad(alpha, beta, self.wavelength_m, self.geometry.d_m)
        self.last_alpha_m, self.last_beta_rad, self.last_target_phase_rad = alpha, beta, phase
        dtype = np.complex64 if samples.dtype == np.complex64 else np.complex128
        correction = phasor(-phase).astype(dtype)
        return samples.astype(dtype, copy=False) * correction[:, None]
