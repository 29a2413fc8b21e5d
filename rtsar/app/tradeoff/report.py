"""The Pareto front of each scene and the tradeoff's Markdown table and plot."""

from __future__ import annotations

from pathlib import Path

from ..quicklook import file_pyplot, save_figure
from .measure import cost_ratio
from .scenes import TradeoffScene

# ---- the sweep ---------------------------------------------------------------------------------
FRONT_KEYS = ("us_per_pulse", "latency_p50_ms", "image_error", "az_irw_m", "az_pslr_db")


def pareto_front(rows: list[dict], keys=FRONT_KEYS):
    """Marks rows[i]["front"]: no other row of its scene is ≤ on every key and < on one."""
    for a in rows:
        a["front"] = not any(
            b is not a
            and b["scene"] == a["scene"]
            and all(b[k] <= a[k] for k in keys)
            and any(b[k] < a[k] for k in keys)
            for b in rows
        )
    return rows


def markdown(rows: list[dict], scenes: list[TradeoffScene]) -> str:
    out = []
    for scene in scenes:
        out.append(f"**{scene.key}**: {scene.description}\n")
        out.append(
            "| knob | value | pulses/s (passes' spread) | time vs default | × RT | "
            "latency p50 / p99 [ms] | image error | "
            "peak phase [mrad] | az. IRW [m] | az. / rg. IRW ratio | az. / rg. PSLR [dB] | "
            "az. / rg. ISLR [dB] | pos. error [cells] | front |"
        )
        out.append("|" + "---|" * 14)
        mine = [r for r in rows if r["scene"] == scene.key]
        base = next((r for r in mine if r["default"]), mine[0] if mine else None)
        for r in mine:
            name = f"**{r['value']}**" if r["default"] else r["value"]
            spread = f" (±{100 * r.get('spread', 0.0):.0f} %)"
            versus = "—" if r is base else cost_ratio(r, base)
            out.append(
                f"| {r['knob']} | {name} | {r['pulses_per_s']:,.0f}{spread} | {versus} | "
                f"{r['realtime_factor']:.1f} | {r['latency_p50_ms']:.1f} / "
                f"{r['latency_p99_ms']:.1f}{'' if r['keeps_up'] else ' (falls behind)'} | "
                f"{r['image_error']:.1e} | {1e3 * r['peak_phase_error_rad']:.2f} | "
                f"{r['az_irw_m']:.4g} | {r['az_irw_ratio']:.3f} / {r['rg_irw_ratio']:.3f} | "
                f"{r['az_pslr_db']:.1f} / {r['rg_pslr_db']:.1f} | "
                f"{r['az_islr_db']:.1f} / {r['rg_islr_db']:.1f} | "
                f"{r['position_error_cells']:.3f} | {'●' if r['front'] else ''} |"
            )
        out.append("")
    return "\n".join(out)


def plot(rows: list[dict], scenes: list[TradeoffScene], path: Path) -> None:
    """Pareto plot: image error against µs per pulse and against median latency, per scene."""
    plt = file_pyplot()
    fig, axes = plt.subplots(len(scenes), 2, figsize=(12, 4.8 * len(scenes)), squeeze=False)
    knobs = sorted({r["knob"] for r in rows})
    colours = {k: plt.cm.tab10(i % 10) for i, k in enumerate(knobs)}
    for row_axes, scene in zip(axes, scenes, strict=True):
        sel = [r for r in rows if r["scene"] == scene.key]
        for ax, xkey, xlabel in zip(
            row_axes,
            ("us_per_pulse", "latency_p50_ms"),
            ("cost [µs per pulse]", "median line latency at the PRF [ms]"),
            strict=True,
        ):
            for r in sel:
                if xkey == "us_per_pulse" and r.get("spread"):  # the passes' spread: its noise
                    ax.errorbar(
                        r[xkey] * (1 + r["spread"] / 2),
                        r["image_error"],
                        xerr=r[xkey] * r["spread"] / 2,
                        color=colours[r["knob"]],
                        lw=0.8,
                        zorder=2,
                    )
                ax.scatter(
                    r[xkey],
                    r["image_error"],
                    s=140 if r["default"] else 50,
                    marker="*" if r["default"] else "o",
                    color=colours[r["knob"]],
                    edgecolors="black" if r["front"] else "none",
                    linewidths=1.2,
                    zorder=3,
                )
            xs = [r[xkey] for r in sel]
            if max(xs) > 3 * min(xs):  # a log axis only where the values span a range
                ax.set_xscale("log")
            ax.set_yscale("log")
            for axis in (ax.xaxis, ax.yaxis):  # minor tick labels ("3×10¹") collided
                axis.set_minor_formatter(plt.NullFormatter())
            ax.set_xlabel(xlabel)
            ax.set_ylabel("image error vs float64 reference (relative RMS)")
            ax.set_title(f"{scene.key}: black outline = Pareto front, ★ = defaults", fontsize=9)
            ax.grid(True, which="both", alpha=0.3)
        handles = [
            plt.Line2D([], [], marker="o", ls="", color=colours[k], label=k)
            for k in knobs
            if any(r["knob"] == k for r in sel)
        ]
        row_axes[1].legend(handles=handles, fontsize=7, loc="best")
    fig.tight_layout()  # before the labels: they are placed on the final layout
    for row_axes, scene in zip(axes, scenes, strict=True):
        sel = [r for r in rows if r["scene"] == scene.key]
        for ax, xkey in zip(row_axes, ("us_per_pulse", "latency_p50_ms"), strict=True):
            place_labels(ax, [(r[xkey], r["image_error"], str(r["value"])) for r in sel])
    save_figure(fig, path, dpi=110)
    plt.close(fig)


# Offsets (points) tried for a label, nearest first: beside its point, then rings further out.
_DIRECTIONS = [(1, 0.4), (1, -1), (-1, 0.4), (-1, -1), (0, 1.2), (0, -1.6), (1, 1.4), (-1, 1.4)]
_OFFSETS = [(r * dx, r * dy) for r in (5, 12, 20, 30, 42, 56, 72) for dx, dy in _DIRECTIONS]


def place_labels(ax, points, fontsize: float = 7) -> list:
    """Label ``points`` [(x, y, text)] so that no label covers another label, a marker, a
    tick label, the title, the legend, or leaves the axes (hence the figure).

    Each label takes the first offset of ``_OFFSETS`` where its box lies inside the axes and
    meets no box placed before (the markers', the tick labels', the title's and the legend's
    first); one that finds none takes the first offset that stays inside the axes.  A label
    moved beyond its neighbourhood gets a thin leader line.  Call it on the final layout
    (after tight_layout): overlaps are judged in display units.
    """
    from matplotlib.text import Text  # matplotlib loads only when a plot is drawn
    from matplotlib.transforms import Bbox

    fig = ax.figure
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    taken = []
    for x, y, _ in points:  # markers: a box of about their size
        px, py = ax.transData.transform((x, y))
        taken.append(Bbox.from_extents(px - 4, py - 4, px + 4, py + 4))
    taken += [t.get_window_extent(renderer) for t in _axes_texts(ax) if t.get_text()]
    legend = ax.get_legend()
    if legend is not None:
        taken.append(legend.get_window_extent(renderer))
    inside = ax.get_window_extent(renderer).shrunk(0.99, 0.99)
    labels = []
    for i, (x, y, text) in enumerate(points):
        own = taken[i]
        fallback = None
        for dx, dy in _OFFSETS:
            label = _annotate(ax, x, y, text, dx, dy, fontsize)
            label.update_positions(renderer)  # else its box is still at the display origin
            box = Text.get_window_extent(label, renderer).expanded(1.05, 1.1)  # text, not leader
            within = inside.contains(box.x0, box.y0) and inside.contains(box.x1, box.y1)
            if within and not any(box.overlaps(t) for t in taken if t is not own):
                break
            if within and fallback is None:
                fallback = (dx, dy)
            label.remove()
        else:  # no free place: the first one inside the axes (or the nearest)
            label = _annotate(ax, x, y, text, *(fallback or _OFFSETS[0]), fontsize)
            label.update_positions(renderer)
            box = Text.get_window_extent(label, renderer).expanded(1.05, 1.1)
        taken.append(box)
        labels.append(label)
    return labels


def _annotate(ax, x, y, text, dx, dy, fontsize):
    """``text`` at (dx, dy) points from (x, y); a thin leader line when moved far."""
    far = abs(dx) > 12 or abs(dy) > 12
    return ax.annotate(
        text,
        (x, y),
        xytext=(dx, dy),
        textcoords="offset points",
        fontsize=fontsize,
        ha="left" if dx > 0 else "right" if dx < 0 else "center",
        va="bottom" if dy >= 0 else "top",
        arrowprops={"arrowstyle": "-", "lw": 0.4, "color": "0.5"} if far else None,
        zorder=4,
    )


def _axes_texts(ax) -> list:
    """The texts drawn around an axes: its tick labels (major and minor), axis labels and
    title, visible ones only."""
    texts = [ax.title, ax.xaxis.label, ax.yaxis.label]
    for axis in (ax.xaxis, ax.yaxis):
        texts += drawn_tick_labels(axis)
    return [t for t in texts if t.get_visible()]


def drawn_tick_labels(axis) -> list:
    """The tick labels of ``axis`` that are drawn: its ticks within the view, labelled."""
    lo, hi = sorted(axis.get_view_interval())
    ticks = axis.get_major_ticks() + axis.get_minor_ticks()
    return [
        t
        for tick in ticks
        if lo <= tick.get_loc() <= hi
        for t in (tick.label1, tick.label2)
        if t.get_visible() and t.get_text()
    ]
