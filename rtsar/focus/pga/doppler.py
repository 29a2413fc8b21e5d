"""The Doppler-centroid anchor: the linear phase PGA cannot see, set by the antenna beam.

PGA estimates a block's error up to a constant and a slope (a slope only moves the block image),
and the stitching (rtsar.focus.pga.blocks) continues the previous block's slope, so the corrected
stream keeps one slope of the error's own: the whole image moves along track.  In a strip-map
the real antenna beam is an absolute reference: broadside (rtsar's geometry has no squint) the
clutter's azimuth spectrum is the two-way pattern, symmetric about zero Doppler, whatever the
scene.  A residual slope s rad/pulse shifts that spectrum by s/2π cycles per pulse.

Estimator (Madsen 1989, "Estimating the Doppler centroid of SAR data", IEEE Trans. AES 25(2),
the correlation Doppler estimator): the lag-one correlation of the corrected pulses
y = x·e^{-iφ̂} over clutter rows,

    z = Σ_r Σ_p y*(p, r) y(p+1, r) = Σ_p e^{-i(φ̂(p+1) - φ̂(p))} Σ_r x*(p, r) x(p+1, r),     (1)

has the angle 2π f_dc / PRF: the residual slope s = arg z.  Only clutter rows take part:
energy at most ``CLUTTER_FACTOR`` × the median row's, and coherence with either neighbouring
row at most ``MAX_ROW_COHERENCE`` (speckle decorrelates across range cells, a point's range
sidelobes do not).  A bright point's Doppler, and that of its sidelobes in a scene without
clutter, is its own position in the block, not the beam's centre (measured: a clutter-free
zhao-insal point scene anchored on its sidelobes moved by up to 1.9 rad/pulse).  The lag
products Σ_r x* x are formed once per block (``centroid_lags``); (1) is then one weighted sum
for any φ̂.

When the antenna sets nothing.  The two-way power pattern sinc⁴(D sinθ/λ) of an aperture D,
with f = 2d sinθ/λ cycles per pulse, has the lag-one coherence ρ(1) = B₃(2d/D)/B₃(0)
(``antenna_coherence``: the transform of sinc⁴ is the cubic B-spline B₃, support |x| < 2):
0.72 for D = 4d, and exactly 0 for d ≥ D/2 — at crouch-sal (d = D = 10 µm) the beam's Doppler
band is twice the PRF, the folded clutter spectrum is flat and no centroid exists to measure.
Madsen's estimate has the standard deviation sqrt((1 - ρ²)/(2Kρ²)) rad for K independent lag
products (``centroid_std_rad``); the anchor is used only when the measured coherence is at least
``min_doppler_coherence`` and half the antenna's ρ(1) (clutter, not noise, fills the rows) and
at most ρ(1) + ``MAX_EXCESS_COHERENCE`` (nothing but a point's history is more coherent than
the beam's clutter: 0.95 measured on a clutter-free psaltis-jpl scene where ρ(1) = 0.25).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...params import Config
from ...phase import phasor

#: Rows whose energy is at most this many times the median row's are clutter ...
CLUTTER_FACTOR = 1.5
#: ... unless their coherence with a neighbouring row exceeds this (measured: speckle 0.2,
#: the range sidelobes of isolated points 0.98-0.999).
MAX_ROW_COHERENCE = 0.8
#: Clutter rows more coherent than ρ(1) + this hold points, not clutter (no anchor).
MAX_EXCESS_COHERENCE = 0.1


def antenna_coherence(config: Config) -> float:
    """ρ(1) of the clutter: lag-one coherence of the two-way beam's Doppler spectrum (Crouch
    eq. 4.9 aperture D, step d): B₃(2d/D)/B₃(0), B₃ the centred cubic B-spline; 0 for d ≥ D/2."""
    g = config.geometry
    x = abs(2.0 * g.along_track_step_m / g.antenna_length_m)
    if x <= 1.0:
        b = 2.0 / 3.0 - x * x + 0.5 * x**3
    elif x < 2.0:
        b = (2.0 - x) ** 3 / 6.0
    else:
        b = 0.0
    return b / (2.0 / 3.0)


def centroid_std_rad(coherence: float, samples: float) -> float:
    """Madsen's estimator's standard deviation sqrt((1 - ρ²)/(2Kρ²)) (inf for ρ = 0 or K = 0)."""
    if not (coherence > 0 and samples > 0):
        return math.inf
    rho = min(coherence, 1.0)
    return math.sqrt((1.0 - rho * rho) / (2.0 * samples * rho * rho))


@dataclass(frozen=True)
class CentroidLags:
    """The clutter rows' lag products of one block: lag[p] = Σ_r x*(p, r) x(p+1, r) (eq. 1),
    their energy Σ_r Σ_p |x|², the number of rows, and the antenna's expected coherence."""

    lag: np.ndarray
    energy: float
    rows: int
    expected_coherence: float

    def residual(self, phase_rad: np.ndarray) -> tuple[float, float]:
        """(residual slope arg z in rad/pulse, coherence |z|/energy) after correcting with φ̂."""
        z = complex(np.sum(self.lag * phasor(-np.diff(phase_rad))))
        coherence = abs(z) / self.energy if self.energy > 0 else 0.0
        return math.atan2(z.imag, z.real), coherence


def centroid_lags(config: Config, lines: np.ndarray) -> CentroidLags:
    """Eq. (1)'s lag products over the clutter rows of a block ``lines[pulse, bin]`` (float64).

    NaN/Inf pulses count as zero.  With fewer than two pulses the sums are empty.
    """
    x = np.asarray(lines, dtype=np.complex128)
    x = np.where(np.isfinite(x).all(axis=1)[:, None], x, 0)
    power = x.real**2 + x.imag**2
    energy_rows = power.sum(axis=0)
    med = float(np.median(energy_rows)) if x.size else 0.0
    clutter = energy_rows <= CLUTTER_FACTOR * med
    # Speckle decorrelates from one range cell to the next; a point's range sidelobes carry
    # its one history in every row: rows coherent with a neighbour are not clutter.
    if x.shape[1] > 1 and x.shape[0] > 0:
        cross = np.abs(np.sum(x[:, :-1] * np.conj(x[:, 1:]), axis=0))
        norm = np.sqrt(energy_rows[:-1] * energy_rows[1:])
        coh = np.divide(cross, norm, out=np.zeros_like(cross), where=norm > 0)
        near = np.maximum(np.pad(coh, (1, 0)), np.pad(coh, (0, 1)))
        clutter &= near <= MAX_ROW_COHERENCE
    c = x[:, clutter]
    lag = np.sum(np.conj(c[:-1]) * c[1:], axis=1) if len(c) > 1 else np.zeros(0, np.complex128)
    # R(0) over the same pulse pairs: the coherence |z| / energy estimates ρ(1).
    pc = power[:, clutter]
    energy = float(0.5 * np.sum(pc[:-1] + pc[1:])) if len(c) > 1 else 0.0
    return CentroidLags(lag, energy, int(np.count_nonzero(clutter)), antenna_coherence(config))
