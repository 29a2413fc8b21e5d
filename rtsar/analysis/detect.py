"""Point targets found in an image: bright, isolated local maxima of ``|image|``.

A pixel is a candidate when it is the largest within ±``separation_irw`` impulse response
widths on each axis (1.5: two equal points that far apart are resolved, with a dip between
them), its power is within ``threshold_db`` of the image's brightest pixel, and it stands
``contrast_db`` above the 90th percentile of the power around it: the ±``background_cells``
box less the rows and columns within one cell of it (where a point's own sidelobes are; off
those cuts a separable response is a product of two sidelobes, < -26 dB), and the same within
±``neighbour_cells``.  Speckle of a diffuse area has local maxima everywhere, but none that
stand so far above their surroundings, also at the area's edges and corners (a tenth of the
box is enough), nor in a narrow stroke (which fills more than a tenth of the smaller box).

Candidates come brightest first, and one is kept per position: a candidate within the
separation of a point already kept is the same point (two equal pixels of one peak, a
plateau); one within ±``neighbour_cells`` of a brighter point is kept only within
``neighbour_db`` of it (fainter, it cannot be told from that point's sidelobes: a sinc's first
is at -13.3 dB, 1.6 IRWs out), and one on its row or column only 10 dB over the envelope of
an unweighted sinc's sidelobes there, 1/(π n)² at n cells (or within ``neighbour_db``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import ndimage

SIDELOBE_MARGIN = 10.0  # on a brighter point's cut, a point must stand 10 dB over the sinc's
# sidelobe envelope there (rect windows: two such points' sidelobes add to ~6 dB over it)


def find_point_targets(
    image: np.ndarray,
    cell_px: tuple[float, float],
    threshold_db: float = -30.0,
    contrast_db: float = 20.0,
    irw_px: tuple[float, float] | None = None,
    separation_irw: float = 1.5,
    neighbour_cells: float = 4.0,
    neighbour_db: float = 10.0,
    background_cells: float = 8.0,
    max_points: int = 20,
) -> list[tuple[int, int]]:
    """Pixels ``(row, column)`` of up to ``max_points`` point targets of ``image[azimuth, range]``.

    ``cell_px``: the resolution cell in pixels along (azimuth, range); ``irw_px``: the expected
    impulse response width in pixels (default 0.886 cells, an unweighted sinc's).
    """
    power = np.abs(np.asarray(image)).astype(np.float64) ** 2
    if power.ndim != 2 or power.size == 0:
        raise ValueError(f"image must be a non-empty 2-D array, got shape {power.shape}")
    if not np.all(np.isfinite(power)):
        raise ValueError("image holds non-finite values")
    top = float(power.max())
    if top == 0:
        return []
    if irw_px is None:
        irw_px = tuple(0.886 * c for c in cell_px)
    sep = [max(1, math.ceil(separation_irw * w)) for w in irw_px]
    local_max = power == ndimage.maximum_filter(power, size=(2 * sep[0] + 1, 2 * sep[1] + 1))
    rows, cols = np.nonzero(local_max & (power >= top * 10 ** (threshold_db / 10)))
    order = np.argsort(-power[rows, cols], kind="stable")  # brightest first, ties in pixel order
    box = [max(2, math.ceil(background_cells * c)) for c in cell_px]
    near = [max(1, math.ceil(c)) for c in cell_px]
    zone = [max(s, math.ceil(neighbour_cells * c)) for s, c in zip(sep, cell_px, strict=True)]
    fainter = 10 ** (-neighbour_db / 10)
    found: list[tuple[int, int]] = []
    for i in order:
        r, c = int(rows[i]), int(cols[i])
        if any(_kept_beside(r, c, power, kept, sep, zone, cell_px, fainter) for kept in found):
            continue
        level = max(_surroundings(power, r, c, b, near) for b in (box, zone))
        if power[r, c] >= 10 ** (contrast_db / 10) * level:
            found.append((r, c))
            if len(found) == max_points:
                break
    return found


def _surroundings(power, r, c, box, near) -> float:
    """The 90th percentile of the power within ±box pixels of (r, c), off its own row and
    column (±near)."""
    r0, c0 = max(r - box[0], 0), max(c - box[1], 0)
    around = power[r0 : r + box[0] + 1, c0 : c + box[1] + 1]
    off_row = np.abs(np.arange(around.shape[0]) + r0 - r) > near[0]
    off_col = np.abs(np.arange(around.shape[1]) + c0 - c) > near[1]
    off_axis = around[np.ix_(off_row, off_col)]
    if off_axis.size < 8:  # an image too small to look off the cuts: the whole box
        off_axis = around
    return float(np.percentile(off_axis, 90))


def _kept_beside(r, c, power, kept, sep, zone, cell_px, fainter) -> bool:
    """Whether candidate (r, c) is point ``kept`` again (within the separation) or too faint
    beside it to be told from its sidelobes: within the neighbour zone, or on one of its cuts
    (±``sep`` across) under ``fainter`` or 10 dB over a sinc's sidelobe envelope 1/(π n)² at
    n cells along it, whichever is lower."""
    dr, dc = abs(r - kept[0]), abs(c - kept[1])
    if dr <= sep[0] and dc <= sep[1]:
        return True
    if dr <= zone[0] and dc <= zone[1]:
        return power[r, c] < fainter * power[kept]
    if dr <= sep[0] or dc <= sep[1]:
        n = dc / cell_px[1] if dr <= sep[0] else dr / cell_px[0]
        return power[r, c] < min(fainter, SIDELOBE_MARGIN / (math.pi * n) ** 2) * power[kept]
    return False
