"""Quicklook PNG of a complex image: |image| in dB relative to its peak, axes in metres."""

from __future__ import annotations

import numpy as np


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
    path, image, azimuth_m, range_m, dynamic_range_db: float = 50.0, title: str = ""
) -> None:
    """Write a PNG: range across, azimuth (along track) down, grey scale in dB."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    extent = [(range_m[0] - dr / 2) / scale, (range_m[-1] + dr / 2) / scale,
              (azimuth_m[-1] + da / 2) / scale, (azimuth_m[0] - da / 2) / scale]
    height = min(12.0, max(3.0, 8.0 * image.shape[0] / max(image.shape[1], 1)))
    fig, ax = plt.subplots(figsize=(8, height), dpi=100)
    im = ax.imshow(
        db,
        cmap="gray",
        vmin=-dynamic_range_db,
        vmax=0,
        extent=extent,
        aspect="auto",
        interpolation="nearest",
    )
    ax.set_xlabel(f"slant range [{unit}]")
    ax.set_ylabel(f"along track [{unit}]")
    ax.set_title(title)
    fig.colorbar(im, ax=ax, label="dB re peak")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
