"""Coherent detection on a bias with a spatial carrier: real mask, charge per exposure, readout.

Psaltis & Wagner 1981 ("Description of the processor", "Performance characteristics"): the CCD
detects intensity, so the range-compressed pulse is "detected coherently ... by introducing a
spatial carrier in the SAR image in either the range or azimuth direction", on a bias, and the
mask in front of the CCD is a real, non-negative transmittance holding the azimuth chirp.  This
module derives what a pixel collects and what the readout must do to recover the complex image
of Psaltis eq. (5) (rtsar.ccd eq. 1, g_i = Σ_m line[i + m] mask[m]), and builds the arrays the
emulation uses.  All phases below are whole quarter cycles, so they are exact.

Notation.  h[m, r] = N·mask[m, r] = w e^{iψ} (rtsar.ccd.design_mask; m < N pulses, r < B cells);
ĥ = h / max|h|.  The CCD has R = E·N rows and W = K·B columns:

* carrier in range:   E = 1 exposure per pulse,  K = 2 columns per range cell;
* carrier in azimuth: E = 2 exposures per pulse, K = 1 column per range cell.

Exposure e = E·p + f (f < E) shows pulse p; column c images cell r = c // K.  Row k of the
mask belongs to aperture pulse m = k // E.

1. Charge per exposure.  The focused pulse, field s_e[c] = γ·line[p(e), r(c)], interferes with a
   reference (bias) beam of amplitude β and phase 2π(e + c_r)/4; c_r = c for the range carrier
   (the reference is tilted a quarter fringe per column) and 0 for the azimuth carrier.  The
   quarter cycle per exposure is the AO drive carrier beating with the reference at the laser
   rate (carrier / laser rate ≡ 1/4 mod 1).  Per unit quantum efficiency, pixel (k, c) collects

       q_e[k, c] = T[k, c] · I_e[c],
       I_e[c] = β² + 2β·Re{ s_e[c] · (-i)^((e + c_r) mod 4) } + |s_e[c]|²,                (P1)
       T[k, c] = ½ |ĥ[m, r]| (1 + cos(arg ĥ[m, r] + πk/2))  ∈ [0, 1]                      (P2)

   (P2 is the real, non-negative mask: the azimuth chirp of eq. 5 on an offset carrier of a
   quarter cycle per row, matching the reference's quarter cycle per exposure).

2. Accumulation.  Charge packet j enters row 0 at exposure j and leaves row R - 1 after exposure
   j + R - 1, so it holds Q_j[c] = Σ_k T[k, c] I_{j+k}[c].  With (P1), (P2):

       Q_j[c] = C[c] + P_j[c] + 2β·Re{ (-i)^((j + c_r) mod 4) · S_j[c] },                   (P3)
       C[c]    = β² Σ_k T[k, c]                  the bias frame (known: it is subtracted),
       P_j[c]  = Σ_k T[k, c] |s_{j+k}[c]|²       the signal's own intensity,
       S_j[c]  = Σ_k T[k, c] (-i)^k s_{j+k}[c]                                               (P4)
               = ¼ Σ_k ĥ_m s_{j+k}  +  ½ Σ_k |ĥ_m| (-i)^k s_{j+k}  +  ¼ Σ_k ĥ*_m (-1)^k s_{j+k}
                     wanted             bias × signal           conjugate chirp

   For packets aligned with pulses (j = E·i) the wanted term is (E γ N / (4 max|h|)) · g_i.  The
   bias × signal term only passes azimuth frequencies near 1/4 cycle per exposure and the
   conjugate term near 1/2; with two exposures per pulse (azimuth carrier) the conjugate term
   cancels pairwise in aligned packets and the bias term moves to 1/2 cycle per pulse.  A scene
   whose azimuth band is clear of these (the presets: < 0.04 cycle per pulse) keeps only their
   leakage through the mask's edges: up to about 2√2/N of the peak with the rectangular window
   (0.4 % rms at N = 128), far less with a taper (1e-5 with Hann).  No real mask does better: a
   pixel delivers Re{Σ_k s_{j+k} T_k e^{-iθ_{j+k}}}, and no real T and phases θ make this
   Re{e^{-iφ_j} Σ_k ĥ_k s_{j+k}} for a chirp ĥ (its phase ψ(k) is not a function of j plus one
   of j + k), so these terms can be moved in frequency but not cancelled.  With the azimuth
   carrier the odd packets straddle two pulses (rows 2m-1, 2m hold the mask of pulses m-1, m):
   an error of first order in the chirp's phase step per pulse, 5.6e-4 rms at N = 128 of
   psaltis-jpl, 3 % for the steeper chirp of the `tiny` preset.  The paper's range cells (W/2
   with the range carrier) and doubled ρA (N/2 pulses with the azimuth carrier) hold here; that
   the mask is real costs the offset carrier, which the paper does not mention.

3. Readout.  The bias frame C is subtracted from each packet read out, then
   * carrier in range (the two columns of a cell are a quarter cycle apart):
         z_j[r] = i^(j + 2r) · ((Q_j[2r] - C) + i (Q_j[2r+1] - C)) = 2β S_j + (1+i) i^(j+2r) P_j;
   * carrier in azimuth (consecutive packets are a quarter cycle apart):
         z_j[r] = 2 i^j (Q_j[r] - C) = 2β S_j + 2β (-1)^j S*_j + 2 i^j P_j.
   The image sits near 0 cycle per packet, the signal's intensity P (and any fixed offset, e.g.
   dark charge or a bias-frame error) at 1/4 and the conjugate image at 1/2: the symmetric filter
   READOUT_TAPS = [-3, 4, 11, 8, 11, 4, -3] / 32 along azimuth (unit gain at 0, zeros at 1/4 and
   1/2, flat to fourth order: gain ≥ 0.9995 below 0.03 cycle per packet, 0.996 at 0.05) removes
   them; its noise gain is √356/32 = 0.59.  Output line i = ẑ_{E·i} / e_u, with
   e_u = β E γ N / (2 max|h|) the charge swing (e-) of a unit image amplitude.  A line leaves 3
   packets after its last exposure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .settings import CARRIERS

READOUT_TAPS = np.array([-3.0, 4.0, 11.0, 8.0, 11.0, 4.0, -3.0]) / 32.0
READOUT_HALF = 3  # taps each side of the centre: a line waits 3 packets


def layout(carrier: str) -> tuple[int, int]:
    """(exposures per pulse E, CCD columns per range cell K) of a carrier."""
    if carrier == "range":
        return 1, 2
    if carrier == "azimuth":
        return 2, 1
    raise ValueError(f"carrier must be one of {CARRIERS}, got {carrier!r}")


def range_cells(ccd_columns: int, carrier: str) -> int:
    """Complex range cells a CCD of ``ccd_columns`` holds (halved with the range carrier)."""
    return ccd_columns // layout(carrier)[1]


def pulses_integrated(ccd_rows: int, carrier: str) -> int:
    """Pulses N that ``ccd_rows`` rows integrate (halved with the azimuth carrier)."""
    return ccd_rows // layout(carrier)[0]


@dataclass(frozen=True, eq=False)
class CarrierPlan:
    """The CCD layout and real mask of one carrier (module docstring, eqs. P1-P2)."""

    carrier: str
    exposures_per_pulse: int  # E
    columns_per_cell: int  # K
    pulses: int  # N
    cells: int  # B
    transmittance: np.ndarray  # float64[R, W], eq. (P2)
    mask_peak: float  # max |h| = max |N · design_mask|
    column_quarters: np.ndarray  # int64[W]: c_r, the reference's quarter cycles per column

    @property
    def ccd_rows(self) -> int:
        return self.exposures_per_pulse * self.pulses

    @property
    def ccd_columns(self) -> int:
        return self.columns_per_cell * self.cells


def make_carrier_plan(mask: np.ndarray, carrier: str) -> CarrierPlan:
    """Real transmittance T[k, c] of eq. (P2) from an ideal mask[m, r] (rtsar.ccd.design_mask).

    The phase arg ĥ comes from the float64 mask (already reduced mod 2π) plus a whole number of
    quarter cycles, reduced mod 2π before the cosine.
    """
    e, k = layout(carrier)
    h = np.asarray(mask, dtype=np.complex128)
    if h.ndim != 2 or h.shape[0] < 2 or not np.all(np.isfinite(h)):
        raise ValueError("mask must be a finite [N >= 2, range_bins] array")
    n, b = h.shape
    h = h * n
    peak = float(np.abs(h).max())
    if peak == 0:
        raise ValueError("mask is all zero")
    rows = np.arange(e * n)
    m = rows // e
    cols = np.arange(k * b) // k
    hn = h[m][:, cols] / peak
    phase = np.mod(np.angle(hn) + 0.5 * np.pi * (rows % 4)[:, None], 2.0 * np.pi)
    t = 0.5 * np.abs(hn) * (1.0 + np.cos(phase))
    quarters = np.arange(k * b) if carrier == "range" else np.zeros(k * b, np.int64)
    return CarrierPlan(carrier, e, k, n, b, np.ascontiguousarray(t), peak, quarters)


# (-i)^q for q = 0..3: the reference's phase factor e^{-iπq/2}, exactly.
_MINUS_I_POW = np.array([1.0, -1j, -1.0, 1j])


def exposure_intensity(
    lines: np.ndarray, plan: CarrierPlan, first_exposure: int, beta: float, gamma: float
) -> np.ndarray:
    """I_e[c] of eq. (P1) for the exposures of ``lines[pulse, cell]`` (float64[P·E, W]).

    ``first_exposure`` is the index e of the first pulse's first exposure (it sets the
    reference's phase; only its value mod 4 matters).
    """
    e_per, k = plan.exposures_per_pulse, plan.columns_per_cell
    s = gamma * np.asarray(lines, dtype=np.complex128)
    if k > 1:
        s = np.repeat(s, k, axis=1)
    if e_per > 1:
        s = np.repeat(s, e_per, axis=0)
    e = (first_exposure + np.arange(s.shape[0])) % 4
    q = (e[:, None] + plan.column_quarters[None, :]) % 4
    cross = (s * _MINUS_I_POW[q]).real
    return beta * beta + 2.0 * beta * cross + (s.real * s.real + s.imag * s.imag)


def demodulate(charge: np.ndarray, first_packet: int, plan: CarrierPlan) -> np.ndarray:
    """z_j[r] of the readout (module docstring, section 3) from bias-subtracted packets.

    charge: float64[packets, W], Q_j - C for packets j = first_packet, first_packet + 1, ...
    """
    charge = np.asarray(charge, dtype=np.float64)
    j = first_packet + np.arange(charge.shape[0])
    if plan.carrier == "range":
        r = np.arange(plan.cells)
        q = (j[:, None] + 2 * r[None, :]) % 4
        return (1j**q) * (charge[:, 0::2] + 1j * charge[:, 1::2])
    return 2.0 * (1j ** (j % 4))[:, None] * charge


def readout_filter(z: np.ndarray) -> np.ndarray:
    """READOUT_TAPS along axis 0, 'valid' part: output n is centred on input n + READOUT_HALF."""
    z = np.asarray(z)
    n = z.shape[0] - 2 * READOUT_HALF
    if n <= 0:
        return np.zeros((0, *z.shape[1:]), np.complex128)
    out = READOUT_TAPS[0] * z[0:n]
    for t in range(1, len(READOUT_TAPS)):
        out = out + READOUT_TAPS[t] * z[t : t + n]
    return out
