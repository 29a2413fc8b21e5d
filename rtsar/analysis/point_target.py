"""A point target in a 2-D image: its 2-D peak and the azimuth and range cuts through it.

Conventions of the cuts (IRW, PSLR, ISLR, positions): rtsar.analysis.cut.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import fft as _fft
from scipy import optimize as _opt

from ..ccd.base import squint_cos_less_one
from ..lens.plan import range_axis_m
from .cut import CutMetrics, analyse_cut, finite_number
from .interpolation import band_centre_cycles, check_factor, synthesis_vector

#: Extent of the local 2-D upsampling around the brightest pixel (pixels each way).
_LOCAL_HALF_WIDTH_PX = 2


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
        Complex value at the interpolated 2-D peak (each cut's ``peak_phase_rad`` is its phase).
    peak_px : (float, float)
        The 2-D peak in (fractional) image pixels (row, column).
    centre_cycles : (float, float)
        The (azimuth, range) spectral centres, cycles a pixel, the chip was interpolated about:
        the ones declared, or those band_centre_cycles found (0: about zero).
    """

    azimuth: CutMetrics
    range: CutMetrics
    azimuth_m: float
    range_m: float
    peak_value: complex
    peak_px: tuple[float, float] = (math.nan, math.nan)
    centre_cycles: tuple[float, float] = (0.0, 0.0)


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
    near_m = finite_number(near_m, name)
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
    chip: int | tuple[int, int] = 64,
    upsample_factor: int = 16,
    *,
    islr_extent: float = 10.0,
    azimuth_centre_cycles: float | None = None,
    range_centre_cycles: float | None = None,
    pslr_extent: float | None = None,
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
    chip : int or (int, int), optional
        Chip half-size in pixels (default 64), or (azimuth, range) half-sizes.
    upsample_factor : int, optional
        Upsampling factor for the 2-D peak search and the cuts (default 16).
    islr_extent : float, optional
        ISLR sidelobe region half-width in IRWs (see :func:`analyse_cut`).
    azimuth_centre_cycles, range_centre_cycles : float or None, optional
        Centre of the image's spectrum along each axis, cycles a pixel, where the caller knows
        it (``image_centres(config)``): a squinted image keeps its Doppler centroid in azimuth,
        f_dc / PRF, and a range band 2 (cos θ - 1) δr / λ off zero.  The chip is brought to
        baseband before any band-limited interpolation (about zero a band across the DFT's
        split is cut in two, rtsar.analysis.interpolation) and the peak's phase restored.
        None: not known; a band the cut through the brightest pixel shows straddling the
        split is moved off it the same way (interpolation.band_centre_cycles), else none.
    pslr_extent : float or None, optional
        Half-width in IRWs of the PSLR's search (see :func:`analyse_cut`; default: the chip).

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
    chip_az, chip_rg = (chip, chip) if np.ndim(chip) == 0 else tuple(chip)
    for c in (chip_az, chip_rg):
        if isinstance(c, bool) or not isinstance(c, (int, np.integer)) or c < 1:
            raise ValueError(f"chip must be an integer >= 1 (or two), got {chip!r}")
    factor = check_factor(upsample_factor)

    if search_radius_m is None:
        radius_az, radius_rg = chip_az * abs(az_spacing), chip_rg * abs(rg_spacing)
    elif np.ndim(search_radius_m) == 0:
        radius_az = radius_rg = finite_number(search_radius_m, "search_radius_m")
    else:
        if len(search_radius_m) != 2:
            raise ValueError("search_radius_m must be (azimuth_radius_m, range_radius_m)")
        radius_az = finite_number(search_radius_m[0], "search_radius_m[0]")
        radius_rg = finite_number(search_radius_m[1], "search_radius_m[1]")
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

    a0, a1 = max(ia - chip_az, 0), min(ia + chip_az, n_az - 1) + 1
    r0, r1 = max(ir - chip_rg, 0), min(ir + chip_rg, n_rg - 1) + 1
    chip_img = img[a0:a1, r0:r1].astype(np.complex128)
    na, nr = chip_img.shape
    ca, cr = ia - a0, ir - r0
    # Spectra to baseband first: the declared centres, or where none is declared a band the
    # cut through the brightest pixel shows across the DFT's split (the target's cut: the
    # whole chip's spectrum is the clutter's).
    centre_a, centre_r = (
        float(given) if given is not None else band_centre_cycles(cut)
        for given, cut in (
            (azimuth_centre_cycles, chip_img[:, cr]),
            (range_centre_cycles, chip_img[ca]),
        )
    )
    if centre_a or centre_r:
        chip_img = chip_img * _carrier(na, centre_a, ca)[:, None] * _carrier(nr, centre_r, cr)
    spectrum_2d = _fft.fft2(chip_img)

    # 2-D upsampled grid of +-2 pixels around the brightest pixel (within the chip's data).
    def grid(c, n):
        lo = max(c - _LOCAL_HALF_WIDTH_PX, 0) * factor
        hi = min(c + _LOCAL_HALF_WIDTH_PX, n - 1) * factor
        return np.arange(lo, hi + 1) / factor

    ta, tr = grid(ca, na), grid(cr, nr)
    synth_a = np.stack([synthesis_vector(na, t) for t in ta])
    synth_r = np.stack([synthesis_vector(nr, t) for t in tr])
    local = synth_a @ spectrum_2d @ synth_r.T / (na * nr)
    ka, kr = np.unravel_index(int(np.argmax(np.abs(local))), local.shape)
    a_star, r_star, value = _refine_peak_2d(spectrum_2d, float(ta[ka]), float(tr[kr]), factor)
    value *= np.exp(2j * np.pi * (centre_a * (a_star - ca) + centre_r * (r_star - cr)))

    # Cuts through the refined peak, interpolated band-limited across the other axis.
    az_cut = _fft.fft(chip_img, axis=1) @ synthesis_vector(nr, r_star) / nr
    rg_cut = synthesis_vector(na, a_star) @ _fft.fft(chip_img, axis=0) / na
    # Each cut is measured about the 2-D peak, not its own maximum (a brighter neighbour on
    # the cut is then a sidelobe of it, not its mainlobe).
    az = analyse_cut(
        az_cut,
        az_spacing,
        az_origin + a0 * az_spacing,
        factor,
        islr_extent=islr_extent,
        peak_near=a_star,
        pslr_extent=pslr_extent,
        centre_cycles=0.0,  # the chip's spectra are at baseband now
    )
    rg = analyse_cut(
        rg_cut,
        rg_spacing,
        rg_origin + r0 * rg_spacing,
        factor,
        islr_extent=islr_extent,
        peak_near=r_star,
        pslr_extent=pslr_extent,
        centre_cycles=0.0,
    )
    phase = math.atan2(value.imag, value.real)  # the cuts' own are the baseband chip's
    az = replace(az, peak_index=az.peak_index + a0, peak_phase_rad=phase)
    rg = replace(rg, peak_index=rg.peak_index + r0, peak_phase_rad=phase)
    return PointTargetReport(
        azimuth=az,
        range=rg,
        azimuth_m=az_origin + (a0 + a_star) * az_spacing,
        range_m=rg_origin + (r0 + r_star) * rg_spacing,
        peak_value=value,
        peak_px=(float(a0 + a_star), float(r0 + r_star)),
        centre_cycles=(centre_a, centre_r),
    )


def azimuth_carrier_cycles(config) -> float:
    """The azimuth spectrum's centre of an image a configuration focuses, cycles per line in
    [-1/2, 1/2): its Doppler centroid over the PRF (lines are one pulse apart; 0 broadside)."""
    g = config.geometry
    return float(np.mod(g.doppler_centroid_hz / g.prf_hz + 0.5, 1.0) - 0.5)


def range_carrier_cycles(config) -> float:
    """The range spectrum's centre of an image a configuration focuses, cycles per bin: the
    mask's phase (4π/λ)(sqrt(R² + u²) - R) with u = R tan θ at a column's beam centre
    changes by (4π/λ)(cos θ - 1) a metre of range, 2 (cos θ - 1) δr / λ cycles a bin of δr
    (RADARSAT-1: -0.063; the focused points measure -0.064), in [-1/2, 1/2); 0 broadside."""
    r = range_axis_m(config)
    step_m = float(r[1] - r[0]) if len(r) > 1 else 0.0
    g = config.geometry
    cycles = 2.0 * squint_cos_less_one(config) * step_m / g.wavelength_m
    return float(np.mod(cycles + 0.5, 1.0) - 0.5)


def image_centres(config) -> dict:
    """analyse_point_target's declared spectral centres of an image a configuration focuses:
    ``analyse_point_target(..., **image_centres(cfg))``."""
    return {
        "azimuth_centre_cycles": azimuth_carrier_cycles(config),
        "range_centre_cycles": range_carrier_cycles(config),
    }


def _carrier(n: int, centre: float, origin: int) -> np.ndarray:
    """exp(-i2π centre (k - origin)), k = 0 … n-1: moves a spectrum centred at ``centre`` to 0."""
    return np.exp(-2j * np.pi * centre * (np.arange(n) - origin))


def _refine_peak_2d(spectrum_2d: np.ndarray, a_guess: float, r_guess: float, factor: int):
    """Maximise the band-limited 2-D interpolant within one upsampled step of the guess."""
    na, nr = spectrum_2d.shape

    def value_at(a, r):
        return complex(synthesis_vector(na, a) @ spectrum_2d @ synthesis_vector(nr, r) / (na * nr))

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
