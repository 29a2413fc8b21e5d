"""Point targets found in an image: bright, isolated local maxima of ``|image|``.

A pixel is a candidate when it is the largest within ±``separation_cells`` resolution cells on
each axis, its power is within ``threshold_db`` of the image's brightest pixel, and it stands
``contrast_db`` above the 90th percentile of the power around it: the ±``background_cells``
box less the rows and columns within one cell of it (where a point's own sidelobes are; off
those cuts a separable response is a product of two sidelobes, < -26 dB).  Speckle of a
diffuse area has local maxima everywhere, but none that stand so far above their
surroundings, also at the area's edges and corners (a tenth of the box is enough).
Candidates come brightest first.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage


def find_point_targets(
    image: np.ndarray,
    cell_px: tuple[float, float],
    threshold_db: float = -30.0,
    contrast_db: float = 20.0,
    separation_cells: float = 4.0,
    background_cells: float = 8.0,
    max_points: int = 20,
) -> list[tuple[int, int]]:
    """Pixels ``(row, column)`` of up to ``max_points`` point targets of ``image[azimuth, range]``.

    ``cell_px``: the resolution cell in pixels along (azimuth, range).
    """
    power = np.abs(np.asarray(image)).astype(np.float64) ** 2
    if power.ndim != 2 or power.size == 0:
        raise ValueError(f"image must be a non-empty 2-D array, got shape {power.shape}")
    if not np.all(np.isfinite(power)):
        raise ValueError("image holds non-finite values")
    top = float(power.max())
    if top == 0:
        return []
    sep = [max(1, math.ceil(separation_cells * c)) for c in cell_px]
    local_max = power == ndimage.maximum_filter(power, size=(2 * sep[0] + 1, 2 * sep[1] + 1))
    rows, cols = np.nonzero(local_max & (power >= top * 10 ** (threshold_db / 10)))
    order = np.argsort(power[rows, cols])[::-1]
    box = [max(2, math.ceil(background_cells * c)) for c in cell_px]
    near = [max(1, math.ceil(c)) for c in cell_px]
    found: list[tuple[int, int]] = []
    for i in order:
        r, c = int(rows[i]), int(cols[i])
        r0, c0 = max(r - box[0], 0), max(c - box[1], 0)
        around = power[r0 : r + box[0] + 1, c0 : c + box[1] + 1]
        off_row = np.abs(np.arange(around.shape[0]) + r0 - r) > near[0]
        off_col = np.abs(np.arange(around.shape[1]) + c0 - c) > near[1]
        off_axis = around[np.ix_(off_row, off_col)]
        if off_axis.size < 8:  # an image too small to look off the cuts: the whole box
            off_axis = around
        level = float(np.percentile(off_axis, 90))
        if power[r, c] >= 10 ** (contrast_db / 10) * level:
            found.append((r, c))
            if len(found) == max_points:
                break
    return found
