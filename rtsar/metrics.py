"""Point-target analysis: peak position, IRW, PSLR and ISLR of complex impulse responses.

One implementation serves the tests and the reports, so both measure the same thing.

Conventions
-----------
* Interpolation is band-limited: the samples are taken as one period of a periodic, band-limited
  signal (FFT zero-padding; the Nyquist bin of an even length is split in two halves).  Values
  between samples are evaluated exactly from the DFT, so peak positions and values are not
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
from dataclasses import dataclass, replace

import numpy as np
from scipy import fft as _fft
from scipy import optimize as _opt

__all__ = [
    "CutMetrics",
    "PointTargetReport",
    "analyse_cut",
    "analyse_point_target",
    "relative_rms",
    "theoretical_irw_factor",
    "theoretical_pslr_db",
    "upsample",
]

#: Minimum zero-padding of :func:`theoretical_irw_factor` / :func:`theoretical_pslr_db`.
THEORY_PAD_FACTOR = 64
#: Extent of the local 2-D upsampling around the brightest pixel (pixels each way).
_LOCAL_HALF_WIDTH_PX = 2


# --------------------------------------------------------------------------------------------
# Band-limited interpolation
# --------------------------------------------------------------------------------------------


def _check_factor(factor) -> int:
    if isinstance(factor, bool) or not isinstance(factor, (int, np.integer)) or factor < 1:
        raise ValueError(f"upsample factor must be an integer >= 1, got {factor!r}")
    return int(factor)


def upsample(x: np.ndarray, factor: int, axis: int = -1) -> np.ndarray:
    """Band-limited interpolation by FFT zero-padding.

    Parameters
    ----------
    x : np.ndarray
        Signal (complex or real), one period of a band-limited periodic signal along ``axis``.
    factor : int
        Upsampling factor (>= 1); the output has ``factor`` times as many samples along ``axis``.
    axis : int, optional
        Axis to interpolate along (default last).

    Returns
    -------
    np.ndarray
        ``y`` with ``y.take(range(0, n * factor, factor), axis) == x`` to rounding; complex for
        complex input, real for real input.  The Nyquist bin of an even length is split into
        equal halves at ``+n/2`` and ``-n/2``, which keeps the interpolant real for real input
        and makes it pass through the original samples.

    Raises
    ------
    ValueError
        If ``factor`` is not an integer >= 1 or the axis is empty.
    """
    factor = _check_factor(factor)
    x = np.asarray(x)
    if x.ndim == 0:
        raise ValueError("upsample needs an array with at least one axis")
    axis = axis % x.ndim
    n = x.shape[axis]
    if n == 0:
        raise ValueError("cannot upsample an empty axis")
    if factor == 1:
        return x.copy()
    is_real = not np.iscomplexobj(x)
    spectrum = _fft.fft(x, axis=axis)
    m = n * factor
    out_shape = list(x.shape)
    out_shape[axis] = m
    padded = np.zeros(out_shape, dtype=spectrum.dtype)

    def sl(start, stop):
        index = [slice(None)] * x.ndim
        index[axis] = slice(start, stop)
        return tuple(index)

    n_pos = (n + 1) // 2  # DC and the positive frequencies below Nyquist
    n_neg = (n - 1) // 2  # the negative frequencies above -Nyquist
    padded[sl(0, n_pos)] = spectrum[sl(0, n_pos)]
    if n_neg:
        padded[sl(m - n_neg, m)] = spectrum[sl(n - n_neg, n)]
    if n % 2 == 0:
        nyquist = spectrum[sl(n // 2, n // 2 + 1)] * 0.5
        padded[sl(n // 2, n // 2 + 1)] = nyquist
        padded[sl(m - n // 2, m - n // 2 + 1)] = nyquist
    y = _fft.ifft(padded, axis=axis) * factor
    return y.real.copy() if is_real else y


def _synthesis_vector(n: int, t: float) -> np.ndarray:
    """Row ``v`` with ``x(t) = v @ fft(x) / n``: the band-limited interpolant of :func:`upsample`.

    ``t`` is in samples; the Nyquist term of an even ``n`` is ``cos(pi t)`` (the split bin).
    """
    k = _fft.fftfreq(n, d=1.0 / n)
    v = np.exp(2j * np.pi * k * (t / n))
    if n % 2 == 0:
        v[n // 2] = np.cos(np.pi * t)
    return v


def _evaluate(spectrum: np.ndarray, t: float) -> complex:
    """Band-limited interpolant of a 1-D signal (given by its DFT) at fractional sample ``t``."""
    n = spectrum.size
    return complex(_synthesis_vector(n, t) @ spectrum) / n


def _refine_max(
    spectrum: np.ndarray, t_lo: float, t_hi: float, t_guess: float, xatol: float = 1e-9
):
    """Maximise ``|x(t)|**2`` on ``[t_lo, t_hi]``; return ``(t, x(t))`` (no worse than guess)."""
    value_guess = _evaluate(spectrum, t_guess)
    if t_hi <= t_lo:
        return t_guess, value_guess
    scale = abs(value_guess) ** 2 or 1.0

    def negative_power(dt):  # offset from the guess keeps Brent's relative tolerance tiny
        return -(abs(_evaluate(spectrum, t_guess + dt)) ** 2) / scale

    res = _opt.minimize_scalar(
        negative_power,
        bounds=(t_lo - t_guess, t_hi - t_guess),
        method="bounded",
        options={"xatol": xatol},
    )
    t_best = t_guess + float(res.x)
    value_best = _evaluate(spectrum, t_best)
    if abs(value_best) < abs(value_guess):
        return t_guess, value_guess
    return t_best, value_best


# --------------------------------------------------------------------------------------------
# 1-D cut analysis
# --------------------------------------------------------------------------------------------


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


def _finite_number(value, name: str, nonzero: bool = False) -> float:
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


def _lobe_metrics(
    p: np.ndarray,
    i_peak: int,
    t_peak: float,
    peak_power: float,
    islr_extent: float,
    refine_sidelobe=None,
) -> tuple[float, float, float]:
    """IRW (in samples of ``p``), PSLR and ISLR (dB) of a finely sampled power response ``p``.

    ``i_peak`` is the grid maximum, ``t_peak`` the (fractional) peak position and ``peak_power``
    the peak power; ``refine_sidelobe(i)``, if given, returns the refined power of the local
    maximum at grid sample ``i``.
    """
    last = p.size - 1

    # IRW from the half-power crossings (linear interpolation between samples).
    half = 0.5 * peak_power
    u_left, j_left, u_right, j_right = _half_power_crossings(p, i_peak, half)
    if u_left is None or u_right is None:
        irw_samples = math.inf
    else:
        irw_samples = u_right - u_left

    # Mainlobe between the first nulls, searched outward from the half-power crossings.
    null_left, null_right = _first_nulls(
        p,
        j_left if j_left is not None else 0,
        j_right if j_right is not None else last,
    )
    if j_left is None:
        null_left = None
    if j_right is None:
        null_right = None
    lo = null_left if null_left is not None else 0
    hi = null_right if null_right is not None else last

    sidelobe = np.zeros(p.size, dtype=bool)
    if null_left is not None:
        sidelobe[:null_left] = True
    if null_right is not None:
        sidelobe[null_right + 1 :] = True

    # PSLR: the highest sidelobe (refined like the peak when it is an interior local maximum).
    if sidelobe.any():
        candidates = np.flatnonzero(sidelobe)
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
    distance = np.abs(np.arange(p.size) - t_peak)
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
    spacing_m = _finite_number(spacing_m, "spacing_m", nonzero=True)
    origin_m = _finite_number(origin_m, "origin_m")
    factor = _check_factor(upsample_factor)
    islr_extent = _finite_number(islr_extent, "islr_extent")
    if islr_extent <= 0:
        raise ValueError(f"islr_extent must be > 0, got {islr_extent!r}")

    n = x.size
    spectrum = _fft.fft(x)
    # Keep only the stretch [0, n-1] samples: beyond it the interpolant wraps to sample 0.
    y = upsample(x, factor)[: (n - 1) * factor + 1]
    p = y.real**2 + y.imag**2
    last = p.size - 1

    # Peak: best grid sample, then exact band-limited refinement within one grid step.
    i_peak = int(np.argmax(p))
    t_peak, v_peak = _refine_max(
        spectrum,
        max(i_peak - 1, 0) / factor,
        min(i_peak + 1, last) / factor,
        i_peak / factor,
    )
    peak_power = abs(v_peak) ** 2

    def refine_sidelobe(i_side: int) -> float:
        _, v_side = _refine_max(
            spectrum, (i_side - 1) / factor, (i_side + 1) / factor, i_side / factor, 1e-6
        )
        return abs(v_side) ** 2

    irw_up, pslr_db, islr_db = _lobe_metrics(
        p, i_peak, t_peak * factor, peak_power, islr_extent, refine_sidelobe
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


# --------------------------------------------------------------------------------------------
# 2-D point target
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PointTargetReport:
    """Point-target analysis of an image ``[azimuth, range]``.

    Attributes
    ----------
    azimuth : CutMetrics
        Metrics of the azimuth cut through the 2-D peak (``peak_index`` in image rows).
    range : CutMetrics
        Metrics of the range cut through the 2-D peak (``peak_index`` in image columns).
    azimuth_m : float
        Azimuth position (m) of the 2-D peak on the image's azimuth axis.
    range_m : float
        Range position (m) of the 2-D peak on the image's range axis.
    peak_value : complex
        Complex value at the interpolated 2-D peak.
    """

    azimuth: CutMetrics
    range: CutMetrics
    azimuth_m: float
    range_m: float
    peak_value: complex


def _uniform_axis(axis, n: int, name: str) -> tuple[float, float]:
    """``(origin_m, spacing_m)`` of a uniform 1-D axis of length ``n``."""
    a = np.asarray(axis, dtype=np.float64)
    if a.ndim != 1 or a.size != n:
        raise ValueError(f"{name} must be 1-D with {n} samples (the image's axis), got {a.shape}")
    if n < 2:
        raise ValueError(f"{name} needs at least 2 samples to define a spacing")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} contains non-finite values")
    spacing = (a[-1] - a[0]) / (n - 1)
    if spacing == 0 or np.max(np.abs(np.diff(a) - spacing)) > 1e-6 * abs(spacing):
        raise ValueError(f"{name} must be uniformly spaced (strictly monotonic)")
    return float(a[0]), float(spacing)


def _search_slice(axis_m: np.ndarray, near_m, radius_m: float, name: str) -> slice:
    if near_m is None:
        return slice(0, axis_m.size)
    near_m = _finite_number(near_m, name)
    inside = np.flatnonzero(np.abs(axis_m - near_m) <= radius_m)
    if inside.size == 0:
        raise ValueError(f"no pixel within {radius_m} m of {name}={near_m}")
    return slice(int(inside[0]), int(inside[-1]) + 1)


def analyse_point_target(
    image: np.ndarray,
    azimuth_m: np.ndarray,
    range_m: np.ndarray,
    near_azimuth_m: float | None = None,
    near_range_m: float | None = None,
    search_radius_m: tuple[float, float] | float | None = None,
    chip: int = 64,
    upsample_factor: int = 16,
    *,
    islr_extent: float = 10.0,
) -> PointTargetReport:
    """Locate and measure a point target in a complex image ``[azimuth, range]``.

    Steps: the brightest pixel (globally, or within the search window) is found; a chip of up to
    ``chip`` pixels each way around it (clipped to the image) is cut; the chip is upsampled in 2-D
    (band-limited, by ``upsample_factor``, over +-2 pixels around the brightest one) and the 2-D
    peak is located on that grid, then refined exactly (band-limited evaluation); the azimuth
    and range cuts through the refined peak are interpolated from the chip and measured with
    :func:`analyse_cut` (which upsamples them by ``upsample_factor``).  This is the same as
    taking the row and column of the upsampled chip through the peak, at the upsampled spacing,
    with positions converted back to metres on the image's axes.

    Parameters
    ----------
    image : np.ndarray
        Complex 2-D image ``[azimuth, range]``.
    azimuth_m, range_m : np.ndarray
        Uniform 1-D axes (m) of the image rows and columns (may decrease).
    near_azimuth_m, near_range_m : float or None, optional
        Centre of the search window along each axis; ``None`` searches that whole axis.
    search_radius_m : tuple of float, float or None, optional
        ``(azimuth_radius_m, range_radius_m)`` (or one radius for both) of the search window
        around the ``near_*`` positions; ``None`` means ``chip`` pixels along each axis.
    chip : int, optional
        Chip half-size in pixels (default 64).
    upsample_factor : int, optional
        Upsampling factor for the 2-D peak search and the cuts (default 16).
    islr_extent : float, optional
        ISLR sidelobe region half-width in IRWs (see :func:`analyse_cut`).

    Returns
    -------
    PointTargetReport
        Cut metrics (``peak_index`` in image pixels, positions in metres on the image axes).

    Raises
    ------
    ValueError
        For a non-2-D, empty, non-finite or all-zero (within the window) image, non-uniform or
        mismatched axes, an empty search window or invalid parameters.
    """
    img = np.asarray(image)
    if img.ndim != 2 or img.size == 0:
        raise ValueError(f"image must be a non-empty 2-D array [azimuth, range], got {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("image contains non-finite values (NaN or inf)")
    n_az, n_rg = img.shape
    az_origin, az_spacing = _uniform_axis(azimuth_m, n_az, "azimuth_m")
    rg_origin, rg_spacing = _uniform_axis(range_m, n_rg, "range_m")
    if isinstance(chip, bool) or not isinstance(chip, (int, np.integer)) or chip < 1:
        raise ValueError(f"chip must be an integer >= 1, got {chip!r}")
    factor = _check_factor(upsample_factor)

    if search_radius_m is None:
        radius_az, radius_rg = chip * abs(az_spacing), chip * abs(rg_spacing)
    elif np.ndim(search_radius_m) == 0:
        radius_az = radius_rg = _finite_number(search_radius_m, "search_radius_m")
    else:
        if len(search_radius_m) != 2:
            raise ValueError("search_radius_m must be (azimuth_radius_m, range_radius_m)")
        radius_az = _finite_number(search_radius_m[0], "search_radius_m[0]")
        radius_rg = _finite_number(search_radius_m[1], "search_radius_m[1]")
    az_axis = np.asarray(azimuth_m, dtype=np.float64)
    rg_axis = np.asarray(range_m, dtype=np.float64)
    win_az = _search_slice(az_axis, near_azimuth_m, radius_az, "near_azimuth_m")
    win_rg = _search_slice(rg_axis, near_range_m, radius_rg, "near_range_m")

    window = img[win_az, win_rg]
    magnitude = np.abs(window)  # native precision: argmax only
    flat = int(np.argmax(magnitude))
    if magnitude.flat[flat] == 0:
        raise ValueError("image is all zero within the search window: no target to analyse")
    ia, ir = np.unravel_index(flat, magnitude.shape)
    ia, ir = int(ia) + win_az.start, int(ir) + win_rg.start

    a0, a1 = max(ia - chip, 0), min(ia + chip, n_az - 1) + 1
    r0, r1 = max(ir - chip, 0), min(ir + chip, n_rg - 1) + 1
    chip_img = img[a0:a1, r0:r1].astype(np.complex128)
    na, nr = chip_img.shape
    spectrum_2d = _fft.fft2(chip_img)
    ca, cr = ia - a0, ir - r0

    # 2-D upsampled grid of +-2 pixels around the brightest pixel (within the chip's data).
    def grid(c, n):
        lo = max(c - _LOCAL_HALF_WIDTH_PX, 0) * factor
        hi = min(c + _LOCAL_HALF_WIDTH_PX, n - 1) * factor
        return np.arange(lo, hi + 1) / factor

    ta, tr = grid(ca, na), grid(cr, nr)
    synth_a = np.stack([_synthesis_vector(na, t) for t in ta])
    synth_r = np.stack([_synthesis_vector(nr, t) for t in tr])
    local = synth_a @ spectrum_2d @ synth_r.T / (na * nr)
    ka, kr = np.unravel_index(int(np.argmax(np.abs(local))), local.shape)
    a_star, r_star, value = _refine_peak_2d(spectrum_2d, float(ta[ka]), float(tr[kr]), factor)

    # Cuts through the refined peak, interpolated band-limited across the other axis.
    az_cut = _fft.fft(chip_img, axis=1) @ _synthesis_vector(nr, r_star) / nr
    rg_cut = _synthesis_vector(na, a_star) @ _fft.fft(chip_img, axis=0) / na
    az = analyse_cut(
        az_cut, az_spacing, az_origin + a0 * az_spacing, factor, islr_extent=islr_extent
    )
    rg = analyse_cut(
        rg_cut, rg_spacing, rg_origin + r0 * rg_spacing, factor, islr_extent=islr_extent
    )
    az = replace(az, peak_index=az.peak_index + a0)
    rg = replace(rg, peak_index=rg.peak_index + r0)
    return PointTargetReport(
        azimuth=az,
        range=rg,
        azimuth_m=az_origin + (a0 + a_star) * az_spacing,
        range_m=rg_origin + (r0 + r_star) * rg_spacing,
        peak_value=value,
    )


def _refine_peak_2d(spectrum_2d: np.ndarray, a_guess: float, r_guess: float, factor: int):
    """Maximise the band-limited 2-D interpolant within one upsampled step of the guess."""
    na, nr = spectrum_2d.shape

    def value_at(a, r):
        return complex(
            _synthesis_vector(na, a) @ spectrum_2d @ _synthesis_vector(nr, r) / (na * nr)
        )

    v_guess = value_at(a_guess, r_guess)
    scale = abs(v_guess) ** 2
    step = 1.0 / factor
    bounds = [
        (max(a_guess - step, 0.0), min(a_guess + step, na - 1.0)),
        (max(r_guess - step, 0.0), min(r_guess + step, nr - 1.0)),
    ]
    if factor == 1 or bounds[0][1] <= bounds[0][0] or bounds[1][1] <= bounds[1][0]:
        return a_guess, r_guess, v_guess
    simplex = np.array(
        [[a_guess, r_guess], [a_guess + 0.3 * step, r_guess], [a_guess, r_guess + 0.3 * step]]
    )
    simplex = np.clip(simplex, [b[0] for b in bounds], [b[1] for b in bounds])
    res = _opt.minimize(
        lambda q: -(abs(value_at(q[0], q[1])) ** 2) / scale,
        np.array([a_guess, r_guess]),
        method="Nelder-Mead",
        bounds=bounds,
        options={"xatol": 1e-9, "fatol": 1e-15, "initial_simplex": simplex, "maxiter": 2000},
    )
    a_best, r_best = (float(v) for v in res.x)
    v_best = value_at(a_best, r_best)
    if abs(v_best) < abs(v_guess):
        return a_guess, r_guess, v_guess
    return a_best, r_best, v_best


# --------------------------------------------------------------------------------------------
# Theory and comparisons
# --------------------------------------------------------------------------------------------


def _weights_response(weights) -> tuple[float, float]:
    """``(irw_factor, pslr_db)`` of ``|DFT(weights)|`` against a rect weighting of that length.

    The DFT is zero-padded >= ``THEORY_PAD_FACTOR`` times, fine enough to measure on its grid.
    """
    w = np.asarray(weights)
    if w.ndim != 1 or w.size < 2:
        raise ValueError("weights must be 1-D with at least 2 samples")
    if not np.issubdtype(w.dtype, np.number) or not np.all(np.isfinite(w)):
        raise ValueError("weights must be finite numbers")
    if not np.any(w):
        raise ValueError("weights are all zero")
    n_fft = max(4096, 1 << math.ceil(math.log2(THEORY_PAD_FACTOR * w.size)))

    def measure(v: np.ndarray) -> tuple[float, float]:
        response = _fft.fftshift(_fft.fft(v, n=n_fft))
        p = response.real**2 + response.imag**2
        i_peak = int(np.argmax(p))
        irw, pslr_db, _ = _lobe_metrics(p, i_peak, float(i_peak), float(p[i_peak]), 10.0)
        return irw, pslr_db

    irw_w, pslr_db = measure(w.astype(np.complex128))
    irw_rect, _ = measure(np.ones(w.size, dtype=np.complex128))
    if not (math.isfinite(irw_w) and math.isfinite(irw_rect)):
        raise ValueError("the response of these weights has no measurable -3 dB width")
    return irw_w / irw_rect, pslr_db


def theoretical_irw_factor(weights: np.ndarray) -> float:
    """IRW broadening factor of an aperture (spectral) weighting.

    Parameters
    ----------
    weights : np.ndarray
        1-D weights across the aperture or spectrum (length >= 2).

    Returns
    -------
    float
        -3 dB width of ``|DFT(weights)|`` (zero-padded >= 64x) divided by that of a rectangular
        weighting of the same length: 1.0 for rect, ~1.63 for Hann, ~1.47 for Hamming
        (symmetric windows of length n span n - 1 intervals, hence a factor n / (n - 1)).

    Raises
    ------
    ValueError
        For empty, too short, non-finite or all-zero weights, or a response whose half-power
        level is not crossed.
    """
    return _weights_response(weights)[0]


def theoretical_pslr_db(weights: np.ndarray) -> float:
    """Peak sidelobe ratio (dB) of ``|DFT(weights)|`` (zero-padded >= 64x).

    Parameters
    ----------
    weights : np.ndarray
        1-D weights across the aperture or spectrum (length >= 2).

    Returns
    -------
    float
        PSLR in dB (about -13.26 for rect, -31.5 for Hann, -42.7 for Hamming).

    Raises
    ------
    ValueError
        For empty, too short, non-finite or all-zero weights.
    """
    return _weights_response(weights)[1]


def relative_rms(a: np.ndarray, b: np.ndarray) -> float:
    """Relative RMS difference ``||a - b||_2 / ||b||_2`` (float64 accumulation).

    Parameters
    ----------
    a : np.ndarray
        Array under test.
    b : np.ndarray
        Reference, same shape.

    Returns
    -------
    float
        The relative error.

    Raises
    ------
    ValueError
        If the shapes differ or the reference is all zero.
    """
    a = np.asarray(a)
    b = np.asarray(b)
    if a.shape != b.shape:
        raise ValueError(f"shape mismatch: {a.shape} vs {b.shape}")
    dtype = np.result_type(a.dtype, b.dtype, np.float64)
    a64 = a.astype(dtype)
    b64 = b.astype(dtype)
    ref = float(np.linalg.norm(b64.ravel()))
    if ref == 0:
        raise ValueError("reference is all zero: relative error undefined")
    return float(np.linalg.norm((a64 - b64).ravel())) / ref
