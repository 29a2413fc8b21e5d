"""Multilook windows over complex images: an exact-order box sum (streaming-safe) and a box mean.

``box_sum`` (InSAL, Zhao step V) adds shifted slices in a fixed order per pixel, so a block of
lines gives bit-identical rows to the whole image wherever the window fits: the height strips in
the stream equal the batch chain.  ``box_mean`` (SAM 3D) normalises by the pixels inside the
image at the edges.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def box_sum(x: np.ndarray, looks: tuple[int, int]) -> np.ndarray:
    """Σ of x over a looks[0] × looks[1] window centred on each pixel (zero outside the array).

    A sum of shifted slices in a fixed order per pixel, so a block of lines gives bit-identical
    rows to the whole image wherever the window fits in the block.
    """
    out = x
    for axis, n in enumerate(looks):
        if n < 1 or n % 2 == 0:
            raise ValueError(f"looks must be odd and >= 1, got {looks}")
        half = n // 2
        padded = np.zeros_like(out)
        size = out.shape[axis]
        for d in range(-half, half + 1):
            lo, hi = max(0, -d), min(size, size - d)
            if hi <= lo:
                continue
            dst = [slice(None)] * out.ndim
            src = [slice(None)] * out.ndim
            dst[axis], src[axis] = slice(lo, hi), slice(lo + d, hi + d)
            padded[tuple(dst)] += out[tuple(src)]
        out = padded
    return out


def box_mean(x: np.ndarray, looks: tuple[int, int]) -> np.ndarray:
    """Mean over a centred window of looks = (azimuth, range) pixels (odd sizes), cut at the edges.

    At an image edge the mean is over the window's pixels inside the image (no padding values).
    """
    la, lr = (int(v) for v in looks)
    if la < 1 or lr < 1 or la % 2 == 0 or lr % 2 == 0:
        raise ValueError(f"looks must be odd positive integers, got {looks!r}")
    x = np.asarray(x)
    out = x
    for axis, size in ((0, la), (1, lr)):
        if size == 1:
            continue
        ones = np.ones(out.shape[axis])
        kernel = np.ones(size)
        total = ndimage.convolve1d(out.real, kernel, axis=axis, mode="constant")
        if np.iscomplexobj(out):
            total = total + 1j * ndimage.convolve1d(out.imag, kernel, axis=axis, mode="constant")
        count = np.convolve(ones, kernel, mode="same")
        shape = [1] * out.ndim
        shape[axis] = -1
        out = total / count.reshape(shape)
    return out
