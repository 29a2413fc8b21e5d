"""The integrated sidelobe ratio of a point target in two dimensions, and its theory.

Definition (one number per point, as ``rtsar measure`` reports it): the chip around the peak is
upsampled band-limited in both axes (rtsar.analysis.interpolation); the *mainlobe* is the
rectangle between the first nulls of the azimuth cut and of the range cut through the peak
(the null rule of rtsar.analysis.cut); the *sidelobe region* is the rectangle of
±``islr_extent`` IRWs about the peak on each axis, less the mainlobe.  ISLR =
10 log10(sidelobe energy / mainlobe energy).

For a separable response (the processor's: range and azimuth compressions are independent) with
1-D mainlobe fractions ``M`` and in-region fractions ``T`` of the energy, this is
``(T_a T_r - M_a M_r) / (M_a M_r)``: -7.0 dB for two unweighted sincs with a ±10 IRW region,
where each 1-D cut alone gives -9.7 dB.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import fft as _fft

from .cut import mainlobe
from .interpolation import upsample
from .point_target import PointTargetReport
from .theory import THEORY_PAD_FACTOR

MAX_UPSAMPLED = 1024  # samples per axis of the upsampled chip (each axis' factor is lowered
# to fit; an axis longer than this is not upsampled: it holds ≥ 50 samples per IRW)


def islr_2d_db(
    image: np.ndarray,
    report: PointTargetReport,
    azimuth_spacing_m: float,
    range_spacing_m: float,
    upsample_factor: int = 16,
    islr_extent: float = 10.0,
) -> float:
    """2-D ISLR (dB, module docstring) of the point ``report`` found in ``image[azimuth, range]``.

    ``report`` gives the 2-D peak (pixels) and the IRWs (m); the spacings convert them to
    pixels.
    The region is clipped to the image; ``-inf`` without sidelobe energy, ``nan`` never.
    The chip is interpolated about the spectral centres the report's was
    (``report.centre_cycles``: a squinted image's, analyse_point_target).
    """
    img = np.asarray(image)
    irw_px = (
        report.azimuth.irw_m / abs(azimuth_spacing_m),
        report.range.irw_m / abs(range_spacing_m),
    )
    if not all(math.isfinite(v) and v > 0 for v in irw_px):
        raise ValueError("the point has no finite -3 dB width: no ISLR")
    centre = report.peak_px
    spans = []
    for axis in (0, 1):
        half = math.ceil(islr_extent * irw_px[axis]) + 2
        c = int(round(centre[axis]))
        spans.append((max(c - half, 0), min(c + half, img.shape[axis] - 1) + 1))
    chip = img[spans[0][0] : spans[0][1], spans[1][0] : spans[1][1]].astype(np.complex128)
    for axis, band in enumerate(report.centre_cycles):  # to baseband, as the report's chip
        if band:
            shape = (-1, 1) if axis == 0 else (1, -1)
            where = np.arange(spans[axis][0], spans[axis][1]).reshape(shape)
            chip *= np.exp(-2j * np.pi * band * where)
    # Per axis: a long, finely sampled axis needs no upsampling, a short coarse one its full
    # factor (one shared factor left a ~1 px/IRW range axis un-upsampled beside a 9000-line
    # azimuth chip: -8.6 dB for -7.0).  Memory: at most MAX_UPSAMPLED or the chip per axis.
    factor = [max(1, min(int(upsample_factor), MAX_UPSAMPLED // n)) for n in chip.shape]
    y = upsample(upsample(chip, factor[0], axis=0), factor[1], axis=1)
    y = y[: (chip.shape[0] - 1) * factor[0] + 1, : (chip.shape[1] - 1) * factor[1] + 1]  # no wrap
    p = y.real**2 + y.imag**2
    t = [(centre[a] - spans[a][0]) * factor[a] for a in (0, 1)]  # peak on the upsampled grid
    ia, ir = (min(max(int(round(v)), 0), n - 1) for v, n in zip(t, p.shape, strict=True))
    peak = float(p[ia, ir])
    main = [None, None]
    for axis, cut, i in ((0, p[:, ir], ia), (1, p[ia, :], ir)):
        # the mainlobe about the point's own peak (a brighter neighbour on a cut is sidelobe)
        f = factor[axis]
        i_peak = max(i - f, 0) + int(np.argmax(cut[max(i - f, 0) : i + f + 1]))
        _, lo, hi = mainlobe(cut, i_peak, float(cut[i_peak]))
        main[axis] = (0 if lo is None else lo, cut.size - 1 if hi is None else hi)
    if peak <= 0:
        raise ValueError("no power at the peak")
    idx = [np.arange(n) for n in p.shape]
    in_main = [(idx[a] >= main[a][0]) & (idx[a] <= main[a][1]) for a in (0, 1)]
    in_region = [np.abs(idx[a] - t[a]) <= islr_extent * irw_px[a] * factor[a] for a in (0, 1)]
    main_energy = float(p[np.ix_(in_main[0], in_main[1])].sum())
    region = np.outer(in_region[0], in_region[1]) & ~np.outer(in_main[0], in_main[1])
    side_energy = float(p[region].sum())
    return 10.0 * math.log10(side_energy / main_energy) if side_energy > 0 else -math.inf


def region_over_main(weights, islr_extent: float = 10.0) -> float:
    """Energy of ``|DFT(weights)|²`` (zero-padded) within ±``islr_extent`` IRWs of its peak over
    its null-to-null mainlobe's: ``T / M`` of the module docstring for one axis."""
    w = np.asarray(weights, np.complex128)
    n_fft = max(4096, 1 << math.ceil(math.log2(THEORY_PAD_FACTOR * w.size)))
    response = _fft.fftshift(_fft.fft(w, n=n_fft))
    p = response.real**2 + response.imag**2
    i_peak = int(np.argmax(p))
    irw, lo, hi = mainlobe(p, i_peak, float(p[i_peak]))
    lo, hi = (0 if lo is None else lo), (p.size - 1 if hi is None else hi)
    region = np.abs(np.arange(p.size) - i_peak) <= islr_extent * irw
    return float(p[region].sum()) / float(p[lo : hi + 1].sum())


def islr_2d_from_ratios_db(azimuth_ratio: float, range_ratio: float) -> float:
    """2-D ISLR (dB) of a separable response from each axis' in-region over mainlobe energy
    ratio (``T/M``): ``(T_a T_r - M_a M_r) / (M_a M_r) = (T_a/M_a)(T_r/M_r) - 1``; ``-inf``
    when neither axis has sidelobe energy."""
    excess = azimuth_ratio * range_ratio - 1.0
    return 10.0 * math.log10(excess) if excess > 0 else -math.inf


def theoretical_islr_2d_db(azimuth_weights, range_weights, islr_extent: float = 10.0) -> float:
    """2-D ISLR (dB) of the separable response of two aperture/spectral weightings, each taken
    as a fixed taper (module docstring: ``(T_a T_r - M_a M_r) / (M_a M_r)``)."""
    return islr_2d_from_ratios_db(
        region_over_main(azimuth_weights, islr_extent),
        region_over_main(range_weights, islr_extent),
    )
