"""Quicklook PNGs: a complex image in dB relative to its peak, and a height map in mm.

Axes in metres (or the unit that suits the span).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
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


def to_db(image: np.ndarray, dynamic_range_db: float, white_at: float = 100.0) -> np.ndarray:
    """20·log10(|image| / ref), clipped to [-dynamic_range_db, 0] (all-zero image → floor):
    ref the ``white_at`` percentile of |image| (100: its peak; 99.9: a real scene's few bright
    points saturate and the rest of it shows)."""
    mag = np.abs(np.asarray(image))
    peak = float(mag.max()) if mag.size else 0.0
    if not np.isfinite(peak):
        raise ValueError("image holds non-finite values")
    ref = peak if white_at >= 100.0 else float(np.percentile(mag, white_at))
    if ref == 0.0:  # (a percentile of zeros: the peak, where there is one)
        ref = peak
    if ref == 0.0:
        return np.full(mag.shape, -dynamic_range_db)
    with np.errstate(divide="ignore"):
        db = 20.0 * np.log10(mag / ref)
    return np.clip(db, -dynamic_range_db, 0.0)


def reference_words(white_at: float) -> str:
    """The colour bar's words for the 0 dB reference."""
    return "dB re peak" if white_at >= 100.0 else f"dB re the {white_at:g}th percentile"


@dataclass(frozen=True)
class ImageAxes:
    """How an image[row, column] is drawn: extent (pixel edges), unit, labels, orientation.

    A strip-map image: slant range across, along track down, in the unit that suits the span.
    A spotlight image (image[x, y], rtsar spotlight): cross-range x across, down-range y up.
    The amplitude and the height map of one file are drawn on the same axes.
    """

    extent: tuple[float, float, float, float]
    unit: str
    scale: float
    xlabel: str
    ylabel: str
    transpose: bool  # draw image.T (spotlight: rows are x, drawn across)
    origin: str

    def shown(self, values: np.ndarray) -> np.ndarray:
        return values.T if self.transpose else values


def _unit(span_m: float) -> tuple[str, float]:
    for u, s in (("km", 1e3), ("m", 1.0), ("mm", 1e-3), ("µm", 1e-6)):
        if span_m >= 5 * s:
            return u, s
    return "m", 1.0


def image_axes(row_m, column_m, spotlight: bool = False) -> ImageAxes:
    """The axes of an image whose rows sit at ``row_m`` and columns at ``column_m``."""
    row_m = np.asarray(row_m, np.float64)
    column_m = np.asarray(column_m, np.float64)
    dr = (column_m[-1] - column_m[0]) / max(len(column_m) - 1, 1)
    da = (row_m[-1] - row_m[0]) / max(len(row_m) - 1, 1)
    if spotlight:  # x (rows) across, y (columns) up
        unit, scale = _unit(max(float(np.ptp(row_m)), float(np.ptp(column_m)), 1e-30))
        extent = (
            (row_m[0] - da / 2) / scale,
            (row_m[-1] + da / 2) / scale,
            (column_m[0] - dr / 2) / scale,
            (column_m[-1] + dr / 2) / scale,
        )
        return ImageAxes(
            extent, unit, scale, f"cross-range x [{unit}]", f"down-range y [{unit}]", True, "lower"
        )
    unit, scale = _unit(max(float(np.ptp(column_m)), 1e-30))
    # Pixel edges, half a step beyond the first and last pixel centres.
    extent = (
        (column_m[0] - dr / 2) / scale,
        (column_m[-1] + dr / 2) / scale,
        (row_m[-1] + da / 2) / scale,
        (row_m[0] - da / 2) / scale,
    )
    return ImageAxes(
        extent, unit, scale, f"slant range [{unit}]", f"along track [{unit}]", False, "upper"
    )


def spotlight_words(channel: str, look: str, method: str = "") -> str:
    """How a spotlight image was formed, for its title: the channel and, for a bistatic channel,
    whether its own geometry was used (the corrected image) or the monostatic one (not)."""
    how = f"{method}, " if method else ""
    if channel == "main":
        return f"spotlight {how}monostatic channel"
    if look == "monostatic":
        return f"spotlight {how}channel {channel} processed as if monostatic (uncorrected)"
    return f"spotlight {how}channel {channel} in its bistatic geometry (corrected)"


def _true_aspect_height(axes: ImageAxes) -> float:
    """The figure height (inches, 8 wide) at one metre = one metre, before any clamping."""
    e = axes.extent
    return 7.0 * abs(e[2] - e[3]) / max(abs(e[1] - e[0]), 1e-30) + 1.0


def _figure_height(axes: ImageAxes, shape, true_aspect: bool) -> float:
    if true_aspect:
        return min(12.0, max(3.0, _true_aspect_height(axes)))
    rows, cols = shape[::-1] if axes.transpose else shape
    return min(12.0, max(3.0, 8.0 * rows / max(cols, 1)))


def quicklook_figure(
    image,
    azimuth_m,
    range_m,
    dynamic_range_db: float = 50.0,
    title: str = "",
    true_aspect: bool | None = None,
    spotlight: bool = False,
    white_at: float = 100.0,
):
    """The figure of :func:`save_quicklook` (the caller closes it)."""
    plt = file_pyplot()

    if dynamic_range_db <= 0:
        raise ValueError("dynamic_range_db must be > 0")
    if not 0.0 < white_at <= 100.0:
        raise ValueError(f"white_at must be a percentile in (0, 100], got {white_at!r}")
    image = np.asarray(image)
    if image.ndim != 2 or image.shape[0] == 0 or image.shape[1] == 0:
        raise ValueError(f"image must be a non-empty 2-D array, got shape {image.shape}")
    if (len(azimuth_m), len(range_m)) != image.shape:  # never drawn on axes cut to fit
        raise ValueError(
            f"azimuth_m ({len(azimuth_m)}) and range_m ({len(range_m)}) must match the image's "
            f"{image.shape[0]} lines x {image.shape[1]} columns"
        )
    db = to_db(image, dynamic_range_db, white_at)
    axes = image_axes(azimuth_m, range_m, spotlight)
    if true_aspect is None:  # true aspect where it fits a figure, else fill it and say so
        true_aspect = _true_aspect_fits(axes)
    fig, ax = plt.subplots(figsize=(8, _figure_height(axes, image.shape, true_aspect)), dpi=100)
    im = ax.imshow(
        axes.shown(db),
        cmap="gray",
        vmin=-dynamic_range_db,
        vmax=0,
        extent=axes.extent,
        origin=axes.origin,
        aspect="equal" if true_aspect else "auto",
        interpolation="nearest",
    )
    ax.set_xlabel(axes.xlabel)
    ax.set_ylabel(axes.ylabel)
    ax.set_title(title)
    fig.colorbar(im, ax=ax, label=reference_words(white_at))
    fig.tight_layout()
    if not true_aspect and not 0.9 <= vertical_stretch(fig, ax, axes) <= 1.1:
        # Say how far the picture is from one metre = one metre: the two-line title moves the
        # axes, so the figure is laid out with it first, then the stretch read on the result.
        def said(k: float) -> str:
            return f"{title}\n(vertical axis drawn {k:.2g}x the horizontal's scale; " + (
                "--true-aspect for 1:1)"
            )

        ax.set_title(said(vertical_stretch(fig, ax, axes)), fontsize=9)
        fig.tight_layout()
        ax.set_title(said(vertical_stretch(fig, ax, axes)).lstrip("\n"), fontsize=9)
    return fig


def _true_aspect_fits(axes: ImageAxes) -> bool:
    """Whether one metre = one metre gives a figure between 3 and 12 inches tall (8 wide)."""
    return 3.0 <= _true_aspect_height(axes) <= 12.0


def vertical_stretch(fig, ax, axes: ImageAxes) -> float:
    """Inches per unit down the drawn image over inches per unit across: 1 at true aspect."""
    box = ax.get_position()
    width_in, height_in = box.width * fig.get_figwidth(), box.height * fig.get_figheight()
    e = axes.extent
    across, down = abs(e[1] - e[0]), abs(e[3] - e[2])
    return (height_in / max(down, 1e-30)) / (width_in / max(across, 1e-30))


def save_quicklook(
    path,
    image,
    azimuth_m,
    range_m,
    dynamic_range_db: float = 50.0,
    title: str = "",
    true_aspect: bool | None = None,
    spotlight: bool = False,
    white_at: float = 100.0,
) -> None:
    """Write a PNG: range across, azimuth (along track) down, grey scale in dB (0 dB, white, at
    the ``white_at`` percentile of |image|: its peak by default).

    ``true_aspect``: True, one metre is as long on both axes, so a focused point looks round;
    False, the image fills the figure; None (default), true aspect where that gives a figure
    3 to 12 inches tall, else filled, with the title saying how far one axis is stretched.
    ``spotlight``: an image[x, y] of rtsar spotlight, drawn cross-range x across, down-range y
    up (image_axes).
    """
    plt = file_pyplot()
    fig = quicklook_figure(
        image, azimuth_m, range_m, dynamic_range_db, title, true_aspect, spotlight, white_at
    )
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


def height_figure(
    height_m,
    valid,
    azimuth_m,
    range_m,
    title: str = "",
    limits_mm: tuple[float, float] | None = None,
    cmap: str = "viridis",
    true_aspect: bool | None = True,
):
    """The figure of :func:`save_height_quicklook` (the caller closes it)."""
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
    axes = image_axes(azimuth_m, range_m)  # the amplitude image's axes (quicklook_figure)
    if true_aspect is None:  # as quicklook_figure decides it, so the two pictures agree
        true_aspect = _true_aspect_fits(axes)
    colours = plt.get_cmap(cmap).with_extremes(bad=MASKED_GREY)
    shown = np.ma.array(h * 1e3, mask=~v)
    fig_h = _figure_height(axes, h.shape, true_aspect)
    fig, ax = plt.subplots(figsize=(7, min(10.0, fig_h)), dpi=100)
    im = ax.imshow(
        shown,
        cmap=colours,
        vmin=lo,
        vmax=hi,
        extent=axes.extent,
        origin=axes.origin,
        aspect="equal" if true_aspect else "auto",
        interpolation="nearest",
    )
    ax.set_xlabel(axes.xlabel)
    ax.set_ylabel(axes.ylabel)
    ax.set_title(title)
    fig.colorbar(im, ax=ax, label="height [mm]")
    fig.tight_layout()
    return fig


def save_height_quicklook(
    path,
    height_m,
    valid,
    azimuth_m,
    range_m,
    title: str = "",
    limits_mm: tuple[float, float] | None = None,
    cmap: str = "viridis",
    true_aspect: bool | None = True,
) -> None:
    """Write a PNG of a height map on the amplitude image's axes (slant range across, along
    track down, in the unit of the span; height colour, mm).

    ``valid`` False → grey.  ``limits_mm``: colour range (default height_colour_limits_mm).
    Non-finite heights on valid pixels are refused (ValueError), never drawn silently.
    """
    plt = file_pyplot()
    fig = height_figure(height_m, valid, azimuth_m, range_m, title, limits_mm, cmap, true_aspect)
    save_figure(fig, path)
    plt.close(fig)
