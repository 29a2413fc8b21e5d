"""Quicklook PNGs: a complex image in dB relative to its peak, and a height map in mm.

Axes in metres (or the unit that suits the span).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..sinks.io import replace_when_complete


def file_pyplot():
    """matplotlib's pyplot on the file-only Agg backend (imported here: it takes a while)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, **kwargs) -> None:
    """``fig.savefig`` to a file name through replace_when_complete (a kill leaves the earlier
    file, never an empty or torn one); a file object is written directly."""
    if isinstance(path, (str, os.PathLike)):
        # The kind from the name the user gave (a name without a suffix: PNG, matplotlib's
        # default), not from the temporary name's.
        kwargs.setdefault("format", Path(path).suffix[1:].lower() or "png")
        with replace_when_complete(path) as tmp:
            fig.savefig(tmp, **kwargs)
    else:
        fig.savefig(path, **kwargs)


def to_db(image: np.ndarray, dynamic_range_db: float) -> np.ndarray:
    """20·log10(|image| / max|image|), clipped at -dynamic_range_db (all-zero image → floor)."""
    mag = np.abs(np.asarray(image))
    peak = float(mag.max()) if mag.size else 0.0
    if not np.isfinite(peak):
        raise ValueError("image holds non-finite values")
    if peak == 0.0:
        return np.full(mag.shape, -dynamic_range_db)
    with np.errstate(divide="ignore"):
        db = 20.0 * np.log10(mag / peak)
    return np.maximum(db, -dynamic_range_db)


def save_quicklook(
    path,
    image,
    azimuth_m,
    range_m,
    dynamic_range_db: float = 50.0,
    title: str = "",
    true_aspect: bool = False,
) -> None:
    """Write a PNG: range across, azimuth (along track) down, grey scale in dB.

    ``true_aspect``: one metre is as long on both axes, so a focused point looks round (the
    default fills the figure; the axes' metres say how much one axis is stretched).
    """
    plt = file_pyplot()

    if dynamic_range_db <= 0:
        raise ValueError("dynamic_range_db must be > 0")
    image = np.asarray(image)
    if image.ndim != 2 or image.shape[0] == 0 or image.shape[1] == 0:
        raise ValueError(f"image must be a non-empty 2-D array, got shape {image.shape}")
    db = to_db(image, dynamic_range_db)
    span = max(float(np.ptp(range_m)), 1e-30)
    unit, scale = ("m", 1.0)
    for u, s in (("km", 1e3), ("m", 1.0), ("mm", 1e-3), ("µm", 1e-6)):
        if span >= 5 * s:
            unit, scale = u, s
            break
    # Pixel edges, half a step beyond the first and last pixel centres.
    dr = (range_m[-1] - range_m[0]) / max(len(range_m) - 1, 1)
    da = (azimuth_m[-1] - azimuth_m[0]) / max(len(azimuth_m) - 1, 1)
    extent = [
        (range_m[0] - dr / 2) / scale,
        (range_m[-1] + dr / 2) / scale,
        (azimuth_m[-1] + da / 2) / scale,
        (azimuth_m[0] - da / 2) / scale,
    ]
    if true_aspect:
        ratio = abs(extent[2] - extent[3]) / max(abs(extent[1] - extent[0]), 1e-30)
        height = min(12.0, max(3.0, 7.0 * ratio + 1.0))
    else:
        height = min(12.0, max(3.0, 8.0 * image.shape[0] / max(image.shape[1], 1)))
    fig, ax = plt.subplots(figsize=(8, height), dpi=100)
    im = ax.imshow(
        db,
        cmap="gray",
        vmin=-dynamic_range_db,
        vmax=0,
        extent=extent,
        aspect="equal" if true_aspect else "auto",
        interpolation="nearest",
    )
    ax.set_xlabel(f"slant range [{unit}]")
    ax.set_ylabel(f"along track [{unit}]")
    ax.set_title(title)
    fig.colorbar(im, ax=ax, label="dB re peak")
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


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
    plt = file_pyplot()

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
    save_figure(fig, path)
    plt.close(fig)
