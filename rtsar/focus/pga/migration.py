"""Range migration inside a PGA block (rtsar.focus.pga.estimator): where points walk across range
bins during a block, as at crouch-sal (d = 10 µm, R = 1.5 m, cells of 50 µm: 0.7 cell over N =
2048 pulses, 2.8 over a 2N block), Crouch's per-bin rows would cut a point's history in pieces.

``curvature_m`` is the block centre's excess range ΔR_p (Psaltis & Wagner eq. 2, exact range),
``migration_corrected`` moves each pulse back by it (a sub-cell shift), ``row_half_width`` and
``rows`` make Crouch's rows coherent sums of 2w+1 bins that hold a point walking u·x/R, and
``walking_rows`` the narrow rows (2v+1 bins) that follow one point's walk.
"""

from __future__ import annotations

import math

import numpy as np

from ...params import Config


def curvature_m(config: Config, range_m: np.ndarray, pulses: int) -> np.ndarray:
    """ΔR_p of eq. (1) of the module docstring: [pulses, bins] float64 metres.

    sqrt(R² + x²) - R, x_p = (p - (P-1)/2)·d: the excess range of a scatterer at the block
    centre (Psaltis & Wagner eq. 2, exact range), written without cancellation for x ≪ R.
    """
    g = config.geometry
    x = ((np.arange(pulses) - 0.5 * (pulses - 1)) * g.along_track_step_m)[:, None]
    r = np.asarray(range_m, dtype=np.float64)[None, :]
    return x * x / (np.sqrt(r * r + x * x) + r)


def migration_corrected(x: np.ndarray, shift_cells: np.ndarray) -> np.ndarray:
    """Each pulse x[p, :] moved by -shift_cells[p] range cells (x[p, k + s_p] → bin k).

    A sub-cell shift of a band-limited range line: a linear phase across its DFT, the line
    zero-padded to twice its length so that nothing wraps round into the swath.  float64.
    """
    p, bins = x.shape
    m = 2 * bins
    spec = np.fft.fft(x, m, axis=1)
    f = np.fft.fftfreq(m)[None, :]  # cycles per cell
    cycles = np.mod(f * np.asarray(shift_cells, np.float64)[:, None], 1.0)
    return np.fft.ifft(spec * np.exp(2j * math.pi * cycles), axis=1)[:, :bins]


def row_half_width(config: Config, range_m: np.ndarray, pulses: int, cells: float) -> int:
    """w of the rows (2w+1 bins summed) that hold a migrating point across a block; 0: none.

    After the block centre's curvature is removed, a point u along track from the centre walks
    u·x/R in range; for |u| ≤ P·d/2 (a point inside the block's own extent) that is at most
    4ΔR_edge over the block, so rows of ±w = ceil(2ΔR_edge / cell) + 1 bins keep it (the +1:
    the main lobe's half-width).  0 when the
    block-edge curvature ΔR_edge is below ``cells`` of a range cell (no migration to handle).
    """
    r = np.asarray(range_m, dtype=np.float64)
    if r.size < 2:
        return 0
    edge_cells = float(curvature_m(config, r[:1], pulses)[0, 0]) / abs(r[1] - r[0])
    if not edge_cells > cells:
        return 0
    return min(int(math.ceil(2.0 * edge_cells)) + 1, (r.size - 1) // 2)


def rows(x: np.ndarray, w: int) -> np.ndarray:
    """Coherent sums of 2w+1 neighbouring bins, row k centred on bin k (edges: fewer bins).

    The range-compressed peak has one phase across its main lobe (a zero-phase sinc), so a point
    walking inside a row keeps its phase and nearly its amplitude there.
    """
    if w == 0:
        return x
    c = np.cumsum(np.pad(x, ((0, 0), (w + 1, w))), axis=1)
    return c[:, 2 * w + 1 :] - c[:, : -(2 * w + 1)]


def walking_rows(
    config: Config,
    xc: np.ndarray,
    range_m: np.ndarray,
    rows: np.ndarray,
    image_bins: np.ndarray,
    row_energy: np.ndarray,
    w: int,
    v: int = 1,
    energy_share: tuple[float, float] = (0.7, 1.3),
) -> tuple[np.ndarray, np.ndarray]:
    """Narrow rows that follow each bright point's range walk across the block.

    ``xc[pulse, bin]``: the block with its centre's curvature removed; ``rows``: the bright
    rows' centre bins; ``image_bins``: the block-image bin of each row's brightest pixel once
    focused.  After the curvature is removed, a point u along track from the block centre sits at
    R + u²/(2R) - u·x_p/R, a walk of -u·x_p/(R·cell) cells, and its deramped history is a tone of
    2ud/(λR) cycles per pulse (eq. 1 of the module docstring), so the image bin gives u up to
    the alias step λR/(2d) (and up to the slope the error still has over the block, which PGA
    cannot see: ~0.4 cell of walk at the block edge for 0.08 rad/pulse, inside the 2v+1 bins).
    The nearest alias and every other whose walk stays within the row (≤ w + 1 cells at the
    block edge) are tried with both signs (so the axis direction does not matter): the row's
    neighbourhood is moved back by the walk (``migration_corrected``) and the 2v+1 bins about
    the point summed; the candidate holding the most energy is kept.  That is the point's energy
    with the noise of 2v+1 bins instead of 2w+1 (+7 dB at crouch-sal's w = 7).  It is used only
    if its energy is within ``energy_share`` of its 2w+1-bin row's ``row_energy``: a bright row
    is ≥ 6 dB over the noise rows, so a narrow row that follows its point keeps ≥ 0.8 of it; one
    that loses the point on the way holds less, one that caught a brighter neighbour's walk
    more.  Rows in order of brightness; one whose 2v+1 bins overlap a kept row's is left out
    (the same point again).  Returns (histories [pulses, points] complex128, their range bins;
    none: shape [pulses, 0]).
    """
    g = config.geometry
    pulses, nb = xc.shape
    d = g.along_track_step_m
    x_m = (np.arange(pulses) - 0.5 * (pulses - 1)) * d
    cell_m = range_m[1] - range_m[0]  # signed: an axis may decrease
    out, where = [], []
    for k, n, e_row in zip(rows.tolist(), image_bins.tolist(), row_energy.tolist(), strict=True):
        alias_m = g.wavelength_m * range_m[k] / (2 * d)
        u0_m = (n if n < pulses / 2 else n - pulses) / pulses * alias_m
        u_max_m = (w + 1) * abs(cell_m) * 2 * range_m[k] / (pulses * d)
        m_lo, m_hi = math.ceil((-u_max_m - u0_m) / alias_m), math.floor((u_max_m - u0_m) / alias_m)
        candidates = {u0_m + m * alias_m for m in range(min(m_lo, 0), max(m_hi, 0) + 1)}
        lo, hi = max(0, k - w - 2), min(nb, k + w + 3)
        best = None
        for u_m, sign in ((u, s) for u in sorted(candidates) for s in (1.0, -1.0)):
            moved = migration_corrected(xc[:, lo:hi], sign * u_m * x_m / (range_m[k] * cell_m))
            b = int(np.argmax((moved.real**2 + moved.imag**2).sum(axis=0)))
            row = moved[:, max(0, b - v) : b + v + 1].sum(axis=1)
            energy = float((row.real**2 + row.imag**2).sum())
            if best is None or energy > best[0]:
                best = (energy, row, lo + b)
        share = best[0] / e_row if e_row > 0 else 0.0
        apart = all(abs(best[2] - c) > 2 * v for c in where)
        if energy_share[0] <= share <= energy_share[1] and apart:
            out.append(best[1])
            where.append(best[2])
    if not out:
        return np.zeros((pulses, 0), np.complex128), np.zeros(0, np.intp)
    return np.stack(out, axis=1), np.array(where, dtype=np.intp)
