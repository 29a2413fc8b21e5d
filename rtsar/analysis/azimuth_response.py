"""The azimuth impulse response of the shifting-CCD correlator itself, and what it measures.

The mask slides along the data (rtsar.ccd.base, eq. 1): image line X (the aperture centre)
sums pulse k, taken at platform offset X + x_k, times mask[k].  A scatterer at along track
X_t and closest-approach range R therefore gives, on the line Δ = X - X_t away from it,

    s(Δ) = Σ_k m_k · g(Δ + x_k) · exp(-j 4π/λ (sqrt(R² + (Δ + x_k)²) - R))        (1)

with m_k the mask column of range R (the processor's window w_k, its 1/N and the conjugate
expected phase; Psaltis & Wagner 1981 eq. 5) and g the two-way antenna gain (Crouch eq. 4.9)
at the scatterer-to-platform offset.  The window belongs to the mask offset x_k, the gain to
the offset Δ + x_k: the weights a line sees, w_k·g(Δ + x_k), change from line to line, so the
response is not |DFT(w·g)| (a fixed taper on the aperture) unless the beam is much wider than
the aperture.  For the demo (a 58.75 m antenna, nulls ±80 m, an 80 m aperture, Taylor) the
fixed taper predicts a 39.1 m IRW; (1) gives 32.9 m, as the image measures.  Without a beam,
(1) is the windowed chirp's own response: the fixed taper's figures to 0.1 %.

(1) is summed exactly (float64, phases reduced mod 2π) on a grid of IRW/32 and measured with
the cut rules of rtsar.analysis.cut (half-power IRW, first-minimum nulls, PSLR anywhere in the
cut), over the span the image's cuts use.  Range migration is not modelled (the range
column is taken to hold the whole history).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..ccd.base import aperture_offsets_m, design_mask
from ..params import Config
from ..windows import window
from .cut import lobe_metrics, mainlobe
from .theory import theoretical_irw_factor

SINC_IRW = 0.8859  # half-power width of sinc(x)² in units of its first-null distance
SAMPLES_PER_IRW = 32
_BLOCK_ELEMENTS = 1 << 20  # deltas × aperture evaluated at once (bounded memory: 16 MiB)


@dataclass(frozen=True)
class AzimuthTheory:
    """Metrics of (1) at one range.

    ``pslr_db`` is ``-inf`` when the response has no sidelobe within the span (a beam that ends
    inside the synthetic aperture can leave none); ``region_over_main`` is the energy within
    ±``islr_extent`` IRWs over the null-to-null mainlobe's (for the 2-D ISLR theory).
    """

    irw_m: float
    pslr_db: float
    region_over_main: float


def antenna_gain(effect):
    """``gain(offset_m, slant_range_m)`` of a scene's antenna_pattern effect (its target_gain)."""
    return lambda offset_m, range_m: effect.target_gain(0, offset_m, range_m)


def azimuth_response(
    cfg: Config, slant_range_m: float, deltas_m: np.ndarray, gain=None
) -> np.ndarray:
    """s(Δ) of eq. (1) (complex128) at the line offsets ``deltas_m`` from the scatterer.

    ``gain(offset_m, instantaneous_range_m)``: the two-way antenna gain (None: a flat beam),
    called as the simulator calls it, with the scatterer-to-platform offset -(Δ + x_k).
    """
    r = float(slant_range_m)
    mask = design_mask(cfg, np.array([r]))[:, 0]
    x = aperture_offsets_m(cfg)
    lam = cfg.geometry.wavelength_m
    deltas = np.asarray(deltas_m, np.float64)
    out = np.empty(deltas.size, np.complex128)
    step = max(1, _BLOCK_ELEMENTS // x.size)
    for i in range(0, deltas.size, step):
        d = deltas[i : i + step, None] + x[None, :]  # platform minus scatterer, along track
        excess = d * d / (np.sqrt(r * r + d * d) + r)  # sqrt(R² + d²) - R without cancellation
        terms = mask * np.exp(-2j * math.pi * np.mod(2.0 * excess / lam, 1.0))
        if gain is not None:
            terms = terms * gain(-d, r + excess)
        out[i : i + step] = terms.sum(axis=1)
    return out


def _measure(cfg, r, gain, irw_guess_m, span_irw, islr_extent):
    """(irw_m, pslr_db, power, peak index, irw in samples) of (1) sampled at irw_guess/32 over
    ±span_irw guesses."""
    dx = irw_guess_m / SAMPLES_PER_IRW
    half = math.ceil(span_irw * SAMPLES_PER_IRW)
    s = azimuth_response(cfg, r, dx * np.arange(-half, half + 1), gain)
    p = s.real**2 + s.imag**2
    i_peak = int(np.argmax(p))
    if p[i_peak] <= 0:
        raise ValueError("the correlator's azimuth response is zero: no theory")
    irw, pslr_db, _ = lobe_metrics(p, i_peak, float(i_peak), float(p[i_peak]), islr_extent)
    return irw * dx, pslr_db, p, i_peak, irw


def azimuth_theory(
    cfg: Config,
    slant_range_m: float,
    gain=None,
    span_irw: float = 12.0,
    islr_extent: float = 10.0,
) -> AzimuthTheory:
    """IRW, PSLR and the ISLR energy ratio of eq. (1) at ``slant_range_m``, measured over
    ±``span_irw`` of its own IRW (the span of the image's cuts)."""
    flat = SINC_IRW * cfg.azimuth_resolution_m(slant_range_m)
    guess = flat * theoretical_irw_factor(
        window(cfg.processor.azimuth_window, cfg.processor.aperture_pulses)
    )
    irw_m = math.inf
    for _ in range(6):  # a narrow beam widens the response: widen the look until it is seen
        irw_m = _measure(cfg, slant_range_m, gain, guess, 4.0, islr_extent)[0]
        if math.isfinite(irw_m):
            break
        guess *= 4.0
    if not math.isfinite(irw_m):
        raise ValueError("the correlator's azimuth response has no -3 dB width")
    irw_m, pslr_db, p, i_peak, irw_samples = _measure(
        cfg, slant_range_m, gain, irw_m, span_irw, islr_extent
    )
    _, lo, hi = mainlobe(p, i_peak, float(p[i_peak]))
    lo, hi = (0 if lo is None else lo), (p.size - 1 if hi is None else hi)
    region = np.abs(np.arange(p.size) - i_peak) <= islr_extent * irw_samples
    ratio = float(p[region].sum()) / float(p[lo : hi + 1].sum())
    return AzimuthTheory(float(irw_m), float(pslr_db), ratio)
