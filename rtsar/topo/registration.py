"""Registration of the second receiver's image on the first (Zhao 2014, step II; Crouch ch. 6).

Integer offset from the peak of the intensity cross-correlation, sub-pixel offset by maximising
the mean local coherence; the slave is resampled by a Fourier shift along range and a windowed-
sinc FIR along azimuth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from ..phase import TWO_PI, phasor
from .looks import box_sum


@dataclass(frozen=True)
class Registration:
    """Slave line i + azimuth_px, bin j + range_px shows what the main shows at (i, j)."""

    azimuth_px: float
    range_px: float
    coherence: float | None = None  # mean local coherence after resampling (None: not measured)


def integer_offset(main: np.ndarray, slave: np.ndarray) -> tuple[int, int]:
    """Peak of the cross-correlation of the two intensity images (mean removed, zero padded)."""
    a = np.abs(np.asarray(main, np.complex128)) ** 2
    b = np.abs(np.asarray(slave, np.complex128)) ** 2
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"images must be 2-D and of one shape, got {a.shape} and {b.shape}")
    shape = (2 * a.shape[0], 2 * a.shape[1])
    spec = np.conj(np.fft.fft2(a - a.mean(), shape)) * np.fft.fft2(b - b.mean(), shape)
    c = np.fft.ifft2(spec).real  # c[d] = Σ_i a[i] b[i + d]
    i, j = np.unravel_index(int(np.argmax(c)), c.shape)
    return (
        int(i - shape[0]) if i >= shape[0] // 2 else int(i),
        int(j - shape[1]) if j >= shape[1] // 2 else int(j),
    )


def _sinc_taps(frac: float, taps: int) -> np.ndarray:
    """Lanczos-windowed sinc for x(n + frac), support t = -taps/2 + 1 … taps/2, unit DC gain."""
    t = np.arange(-taps // 2 + 1, taps // 2 + 1) - frac
    h = np.sinc(t) * np.sinc(t / (taps / 2))
    return h / h.sum()


def shift_image(image: np.ndarray, azimuth_px: float, range_px: float, taps: int = 16):
    """out[i, j] = image[i + azimuth_px, j + range_px] → (complex128 out, valid bool).

    Crouch ch. 6 ("Image Registration": Fourier-based shifting).  Range: Fourier shift of each
    line (zero padded to twice its length, so nothing wraps in).
    Azimuth: the integer part by indexing, the fraction by a ``taps``-point windowed sinc (a local
    operation, so a block of lines gives the same rows as the whole image ``taps``/2 lines away
    from the block's ends).  Rows and columns whose sample point falls outside the image are
    zero and not valid.  Both interpolate about zero frequency: an image whose band sits off
    zero (a squinted one's, rtsar.analysis.interpolation) needs its centre taken out first;
    the interferometric presets are broadside.
    """
    x = np.asarray(image, np.complex128)
    rows, cols = x.shape
    valid = np.ones(x.shape, bool)
    if range_px:
        n = 1 << (2 * cols - 1).bit_length()
        ramp = phasor(TWO_PI * np.fft.fftfreq(n) * range_px)
        x = np.fft.ifft(np.fft.fft(x, n, axis=1) * ramp, axis=1)[:, :cols]
    j = np.arange(cols) + range_px
    valid &= ((j >= 0) & (j <= cols - 1))[None, :]
    whole = math.floor(azimuth_px)
    frac = azimuth_px - whole
    if abs(frac) < 1e-9:
        offsets, h = np.array([whole]), np.ones(1)
    else:
        h = _sinc_taps(frac, taps)
        offsets = whole + np.arange(-taps // 2 + 1, taps // 2 + 1)
    # Near the first and last lines the kernel loses taps: the rest is renormalised to unit
    # gain, and the line stays valid while both neighbours of the sample point are inside.
    i = np.arange(rows)
    out = np.zeros_like(x)
    norm = np.zeros(rows)
    for hk, off in zip(h, offsets, strict=True):
        inside = (i + off >= 0) & (i + off <= rows - 1)
        out[inside] += hk * x[i[inside] + off]
        norm += np.where(inside, hk, 0.0)
    ok = (i + whole >= 0) & (i + whole + (1 if len(h) > 1 else 0) <= rows - 1)
    out[ok] /= norm[ok, None]
    valid &= ok[:, None]
    out[~valid] = 0
    return out, valid


def mean_coherence(main, slave, valid, window=(5, 5)) -> float:
    """Σ|Σ_w M S*| / Σ sqrt(Σ_w|M|² Σ_w|S|²) over valid pixels (slow fringes do not bias it)."""
    v = valid.astype(np.float64)
    cross = np.abs(box_sum(main * np.conj(slave) * v, window))
    power = np.sqrt(
        box_sum(np.abs(main) ** 2 * v, window) * box_sum(np.abs(slave) ** 2 * v, window)
    )
    den = float(power[valid].sum())
    return float(cross[valid].sum() / den) if den > 0 else 0.0


def estimate_registration(
    main, slave, subpixel: str = "both", window=(5, 5), taps: int = 16
) -> Registration:
    """Zhao step II: pixel offset (intensity correlation), then sub-pixel by coherence.

    ``subpixel``: "none" (Zhao's pixel-level registration), "range" or "both" axes refined, each
    by a bounded Brent search of ±0.6 pixel about the integer offset, two sweeps.
    """
    if subpixel not in ("none", "range", "both"):
        raise ValueError("subpixel must be 'none', 'range' or 'both'")
    m = np.asarray(main, np.complex128)
    s = np.asarray(slave, np.complex128)
    d = [float(v) for v in integer_offset(m, s)]

    def score(da, dr):
        shifted, ok = shift_image(s, da, dr, taps)
        return mean_coherence(m, shifted, ok, window)

    axes = {"none": (), "range": (1,), "both": (1, 0)}[subpixel]
    for _ in range(2 if len(axes) > 1 else 1):
        for axis in axes:
            centre = d[axis]

            def cost(v, axis=axis):
                trial = list(d)
                trial[axis] = v
                return -score(*trial)

            res = optimize.minimize_scalar(
                cost,
                bounds=(centre - 0.6, centre + 0.6),
                method="bounded",
                options={"xatol": 1e-3},
            )
            d[axis] = float(res.x)
    return Registration(d[0], d[1], score(d[0], d[1]))
