"""Quicklook PNG of a height map: colour by height in mm, masked pixels grey, colour bar in mm."""

from __future__ import annotations

import numpy as np

MASKED_GREY = (0.6, 0.6, 0.6, 1.0)


def height_colour_limits_mm(height_m, valid, percentile: float = 0.5) -> tuple[float, float]:
    """Colour range: the [p, 100 - p] percentiles of the valid heights, in mm (never empty)."""
    h = np.asarray(height_m, np.float64)[np.asarray(valid, bool)] * 1e3
    if h.size == 0:
        return -1.0, 1.0
    lo, hi = (float(v) for v in np.percentile(h, [percentile, 100.0 - percentile]))
    if hi - lo < 1e-6:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi


def save_height_quicklook(
    path,
    height_m,
    valid,
    azimuth_m,
    range_m,
    title: str = "",
    limits_mm: tuple[float, float] | None = None,
    cmap: str = "viridis",
) -> None:
    """Write a PNG: slant range across, along track down (mm from the first pixel), height colour.

    ``valid`` False → grey.  ``limits_mm``: colour range (default height_colour_limits_mm).
    Non-finite heights on valid pixels are refused (ValueError), never drawn silently.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    h = np.asarray(height_m, np.float64)
    v = np.asarray(valid, bool)
    if h.ndim != 2 or h.shape != v.shape or 0 in h.shape:
        raise ValueError(
            f"height and valid must be one non-empty 2-D shape, got {h.shape}, {v.shape}"
        )
    if len(azimuth_m) != h.shape[0] or len(range_m) != h.shape[1]:
        raise ValueError("azimuth_m and range_m must match the height map's axes")
    if not np.isfinite(h[v]).all():
        raise ValueError("height map holds non-finite values on valid pixels")
    lo, hi = limits_mm or height_colour_limits_mm(h, v)
    az = (np.asarray(azimuth_m, np.float64) - azimuth_m[0]) * 1e3
    rg = (np.asarray(range_m, np.float64) - range_m[0]) * 1e3
    da = az[1] - az[0] if len(az) > 1 else 1.0
    dr = rg[1] - rg[0] if len(rg) > 1 else 1.0
    extent = [rg[0] - dr / 2, rg[-1] + dr / 2, az[-1] + da / 2, az[0] - da / 2]
    colours = plt.get_cmap(cmap).with_extremes(bad=MASKED_GREY)
    shown = np.ma.array(h * 1e3, mask=~v)
    fig_h = min(10.0, max(3.0, 7.0 * h.shape[0] * abs(da) / max(h.shape[1] * abs(dr), 1e-9)))
    fig, ax = plt.subplots(figsize=(7, fig_h), dpi=100)
    im = ax.imshow(
        shown,
        cmap=colours,
        vmin=lo,
        vmax=hi,
        extent=extent,
        aspect="equal",
        interpolation="nearest",
    )
    ax.set_xlabel(f"slant range from {range_m[0]:.4f} m [mm]")
    ax.set_ylabel("along track [mm]")
    ax.set_title(title)
    fig.colorbar(im, ax=ax, label="height [mm]")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
