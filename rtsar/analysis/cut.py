"""One cut through an impulse response: peak position, IRW, PSLR and ISLR.

One implementation serves the tests and the reports, so both measure the same thing.

Conventions
-----------
* Interpolation is band-limited: the samples are taken as one period of a periodic, band-limited
  signal (FFT zero-padding; the Nyquist bin of an even length is split in two halves), about
  a gap in the band where the band straddles that split (interpolation.band_centre_cycles).
  Values between samples are evaluated exactly from the DFT, so peak positions and values are not
  limited to the upsampled grid.  The wrap-around stretch after the last sample (interpolated
  between the last and the first sample) is not data and is never analysed.
* Powers are ``|x|**2``.  The *mainlobe* runs from the first minimum (null) on the left of the
  peak to the first minimum on its right, each searched outward from the half-power crossing;
  *sidelobes* are everything of the cut outside it.
* IRW (impulse response width) is the -3 dB width: the distance between the two points where
  ``|x|**2`` falls to half of the (interpolated) peak power, linearly interpolated between the
  samples of the upsampled cut.  For a sinc of bandwidth ``B`` it is ``0.8859 / B``.
* PSLR (peak sidelobe ratio) is ``10 log10(max sidelobe power / peak power)`` in dB (-13.26 dB for
  a sinc); ISLR (integrated sidelobe ratio) is ``10 log10(sidelobe energy / mainlobe energy)``
  in dB with the sidelobe energy taken within ``islr_extent`` IRWs of the peak (clipped to the
  cut).  Both are ``-inf`` when the cut holds no sidelobe at all, never NaN.
* Positions in metres are ``origin_m + index * spacing_m`` with ``index`` in (fractional) samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import fft as _fft

from .interpolation import band_centre_cycles, check_factor, refine_max, upsample


@dataclass(frozen=True)
class CutMetrics:
    """Impulse-response metrics of one 1-D cut (conventions in the module docstring).

    Attributes
    ----------
    peak_index : float
        Sub-sample peak position in samples of the analysed cut (for a
        :class:`PointTargetReport`: in pixels of the image along that axis).
    peak_position_m : float
        ``origin_m + peak_index * spacing_m``.
    peak_amplitude : float
        ``|x|`` at the interpolated peak.
    peak_phase_rad : float
        Phase (rad, in (-pi, pi]) of the complex value at the interpolated peak.
    irw_m : float
        -3 dB impulse response width (m), width of the mainlobe where ``|x|**2 >= peak/2``;
        ``inf`` when the half-power level is not crossed within the cut on both sides.
    pslr_db : float
        Peak sidelobe ratio (dB): highest sidelobe power outside the null-to-null mainlobe,
        anywhere in the cut, over the peak power; ``-inf`` if the cut has no sidelobe.
    islr_db : float
        Integrated sidelobe ratio (dB): sidelobe energy within ``islr_extent`` IRWs of the peak
        over the null-to-null mainlobe energy; ``-inf`` if there is no sidelobe energy.
    """

    peak_index: float
    peak_position_m: float
    peak_amplitude: float
    peak_phase_rad: float
    irw_m: float
    pslr_db: float
    islr_db: float


def _as_cut(cut) -> np.ndarray:
    x = np.asarray(cut)
    if x.ndim != 1:
        raise ValueError(f"a cut must be 1-D, got shape {x.shape}")
    if x.size == 0:
        raise ValueError("cannot analyse an empty cut")
    if not np.issubdtype(x.dtype, np.number):
        raise ValueError(f"a cut must be numeric, got dtype {x.dtype}")
    if not np.all(np.isfinite(x)):
        raise ValueError("cut contains non-finite values (NaN or inf)")
    x = x.astype(np.complex128)
    if not np.any(x):
        raise ValueError("cut is all zero: there is no peak to analyse")
    return x


def finite_number(value, name: str, nonzero: bool = False) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a real number, got {value!r}") from None
    if not math.isfinite(value) or (nonzero and value == 0.0):
        need = "a finite non-zero" if nonzero else "a finite"
        raise ValueError(f"{name} must be {need} number, got {value!r}")
    return value


def _half_power_crossings(p: np.ndarray, i_peak: int, half: float):
    """Left/right half-power crossings (fractional indices) and the bracketing samples.

    Returns ``(u_left, j_left, u_right, j_right)``: ``j_left`` is the last sample below half power
    left of the peak and ``j_right`` the first one right of it; ``None`` where there is none.
    """
    below_left = np.flatnonzero(p[:i_peak] < half)
    if below_left.size:
        j_left = int(below_left[-1])
        a, b = p[j_left], p[j_left + 1]
        u_left = j_left + (half - a) / (b - a)
    else:
        j_left, u_left = None, None
    below_right = np.flatnonzero(p[i_peak + 1 :] < half)
    if below_right.size:
        j_right = i_peak + 1 + int(below_right[0])
        a, b = p[j_right - 1], p[j_right]
        u_right = (j_right - 1) + (a - half) / (a - b)
    else:
        j_right, u_right = None, None
    return u_left, j_left, u_right, j_right


def _first_nulls(p: np.ndarray, start_left: int, start_right: int):
    """First local minima walking outward from ``start_left`` (leftward) / ``start_right``.

    A sample is the null when the next sample outward is not lower.  ``None`` on a side where the
    power keeps falling up to the end of the cut (no null, hence no sidelobe, on that side).
    """
    seg = p[: start_left + 1]
    rising = np.flatnonzero(seg[:-1] >= seg[1:])
    null_left = int(rising[-1]) + 1 if rising.size else None
    seg = p[start_right:]
    rising = np.flatnonzero(seg[1:] >= seg[:-1])
    null_right = start_right + int(rising[0]) if rising.size else None
    return null_left, null_right


def mainlobe(p: np.ndarray, i_peak: int, peak_power: float):
    """``(irw_samples, null_left, null_right)`` of a finely sampled power response ``p``.

    IRW from the half-power crossings (linear interpolation between samples, ``inf`` when one
    is missing); the nulls are the first minima searched outward from those crossings
    (module docstring), ``None`` on a side where the power falls to the end of the cut.
    """
    last = p.size - 1
    u_left, j_left, u_right, j_right = _half_power_crossings(p, i_peak, 0.5 * peak_power)
    irw_samples = math.inf if u_left is None or u_right is None else u_right - u_left
    null_left, null_right = _first_nulls(
        p,
        j_left if j_left is not None else 0,
        j_right if j_right is not None else last,
    )
    if j_left is None:
        null_left = None
    if j_right is None:
        null_right = None
    return irw_samples, null_left, null_right


def lobe_metrics(
    p: np.ndarray,
    i_peak: int,
    t_peak: float,
    peak_power: float,
    islr_extent: float,
    refine_sidelobe=None,
    pslr_extent: float | None = None,
) -> tuple[float, float, float]:
    """IRW (in samples of ``p``), PSLR and ISLR (dB) of a finely sampled power response ``p``.

    ``i_peak`` is the grid maximum, ``t_peak`` the (fractional) peak position and ``peak_power``
    the peak power; ``refine_sidelobe(i)``, if given, returns the refined power of the local
    maximum at grid sample ``i``; ``pslr_extent``, if given, confines the PSLR's search to
    within that many IRWs of the peak (a neighbouring target further out is not a sidelobe).
    """
    last = p.size - 1
    irw_samples, null_left, null_right = mainlobe(p, i_peak, peak_power)
    lo = null_left if null_left is not None else 0
    hi = null_right if null_right is not None else last

    sidelobe = np.zeros(p.size, dtype=bool)
    if null_left is not None:
        sidelobe[:null_left] = True
    if null_right is not None:
        sidelobe[null_right + 1 :] = True

    distance = np.abs(np.arange(p.size) - t_peak)
    searched = sidelobe
    if pslr_extent is not None and math.isfinite(irw_samples):
        searched = sidelobe & (distance <= pslr_extent * irw_samples)
    # PSLR: the highest sidelobe (refined like the peak when it is an interior local maximum).
    if searched.any():
        candidates = np.flatnonzero(searched)
        i_side = int(candidates[np.argmax(p[candidates])])
        side_power = p[i_side]
        interior = 0 < i_side < last and sidelobe[i_side - 1] and sidelobe[i_side + 1]
        local_max = interior and p[i_side - 1] <= side_power >= p[i_side + 1]
        if local_max and refine_sidelobe is not None:
            side_power = max(side_power, refine_sidelobe(i_side))
        pslr_db = 10.0 * math.log10(side_power / peak_power) if side_power > 0 else -math.inf
    else:
        pslr_db = -math.inf

    # ISLR: sidelobe energy within +-islr_extent IRWs of the peak over the mainlobe energy.
    main_energy = float(np.sum(p[lo : hi + 1]))
    side_energy = float(np.sum(p[sidelobe & (distance <= islr_extent * irw_samples)]))
    islr_db = 10.0 * math.log10(side_energy / main_energy) if side_energy > 0 else -math.inf
    return irw_samples, pslr_db, islr_db


def analyse_cut(
    cut: np.ndarray,
    spacing_m: float,
    origin_m: float = 0.0,
    upsample_factor: int = 16,
    *,
    islr_extent: float = 10.0,
    peak_near: float | None = None,
    pslr_extent: float | None = None,
    centre_cycles: float | None = None,
) -> CutMetrics:
    """Measure peak, IRW, PSLR and ISLR of a 1-D complex impulse response.

    Parameters
    ----------
    cut : np.ndarray
        Complex (or real) 1-D samples through the response, uniformly spaced.
    spacing_m : float
        Sample spacing (m); may be negative for a decreasing axis (widths use ``|spacing_m|``).
    origin_m : float, optional
        Position (m) of sample 0.
    upsample_factor : int, optional
        Band-limited upsampling applied before the measurements (default 16).  The peak itself
        is then refined exactly (band-limited evaluation), so its accuracy does not depend on it.
    islr_extent : float, optional
        Half-width of the ISLR sidelobe region in IRWs from the peak (default 10).
    peak_near : float or None, optional
        The response's peak is the local maximum within one sample of this (fractional)
        sample index, not the cut's largest value (a brighter neighbour on the cut is then a
        sidelobe: PSLR > 0 dB).  Default: the largest value.
    pslr_extent : float or None, optional
        Half-width, in IRWs from the peak, of the region where the PSLR's sidelobe is sought
        (default: the whole cut).
    centre_cycles : float or None, optional
        The cut's spectral centre, cycles a sample, where the caller knows it (0: baseband);
        None: a band that straddles the DFT's split is found (interpolation.band_centre_cycles).
        The cut is interpolated about it and the peak's phase put back.

    Returns
    -------
    CutMetrics
        See the module docstring for the conventions.  When a side has no null within the cut
        (e.g. a tapered response with no sidelobe before the cut ends), that side contributes no
        sidelobe: PSLR and ISLR are computed from the other side, or are ``-inf`` if no sidelobe
        exists at all.  IRW is ``inf`` if the half-power level is not crossed on both sides.

    Raises
    ------
    ValueError
        For an empty, all-zero, non-finite or non-1-D cut, or invalid parameters.
    """
    x = _as_cut(cut)
    spacing_m = finite_number(spacing_m, "spacing_m", nonzero=True)
    origin_m = finite_number(origin_m, "origin_m")
    factor = check_factor(upsample_factor)
    islr_extent = finite_number(islr_extent, "islr_extent")
    if islr_extent <= 0:
        raise ValueError(f"islr_extent must be > 0, got {islr_extent!r}")

    n = x.size
    # A band across the DFT's split (a squinted image's range cut) is interpolated about its
    # own centre, and the peak's phase put back (rtsar.analysis.interpolation).
    centre = band_centre_cycles(x) if centre_cycles is None else float(centre_cycles)
    if centre:
        x = x * np.exp(-2j * np.pi * centre * np.arange(n))
    spectrum = _fft.fft(x)
    # Keep only the stretch [0, n-1] samples: beyond it the interpolant wraps to sample 0.
    y = upsample(x, factor)[: (n - 1) * factor + 1]
    p = y.real**2 + y.imag**2
    last = p.size - 1

    # Peak: best grid sample, then exact band-limited refinement within one grid step.
    if peak_near is None:
        i_peak = int(np.argmax(p))
    else:
        near = finite_number(peak_near, "peak_near") * factor
        lo = min(max(int(math.floor(near)) - factor, 0), last)
        hi = min(max(int(math.ceil(near)) + factor, 0), last)
        i_peak = lo + int(np.argmax(p[lo : hi + 1]))
    t_peak, v_peak = refine_max(
        spectrum,
        max(i_peak - 1, 0) / factor,
        min(i_peak + 1, last) / factor,
        i_peak / factor,
    )
    peak_power = abs(v_peak) ** 2
    v_peak *= complex(np.exp(2j * np.pi * centre * t_peak))

    def refine_sidelobe(i_side: int) -> float:
        _, v_side = refine_max(
            spectrum, (i_side - 1) / factor, (i_side + 1) / factor, i_side / factor, 1e-6
        )
        return abs(v_side) ** 2

    irw_up, pslr_db, islr_db = lobe_metrics(
        p, i_peak, t_peak * factor, peak_power, islr_extent, refine_sidelobe, pslr_extent
    )
    irw_samples = irw_up / factor

    return CutMetrics(
        peak_index=float(t_peak),
        peak_position_m=origin_m + t_peak * spacing_m,
        peak_amplitude=abs(v_peak),
        peak_phase_rad=math.atan2(v_peak.imag, v_peak.real),
        irw_m=float(irw_samples * abs(spacing_m)),
        pslr_db=pslr_db,
        islr_db=islr_db,
    )
