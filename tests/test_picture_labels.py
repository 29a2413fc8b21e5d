"""What the pictures say: axis labels, titles, offsets, colour bars and label placement read
from the figures the commands draw (issue 30: spotlight axes, bistatic before/after titles,
the projective z axis, height map axes, tradeoff labels)."""

import numpy as np
import pytest

from rtsar.app import quicklook
from rtsar.app.cli import main
from rtsar.presets import preset
from rtsar.sinks.image_file import ImageWriter, write_image


@pytest.fixture
def figures(monkeypatch):
    """Every figure a command saves, drawn, instead of written (its texts are read)."""
    saved = []

    def keep(fig, path, **kwargs):
        fig.canvas.draw()
        saved.append(fig)

    for module in ("rtsar.app.quicklook", "rtsar.app.cli.spot", "rtsar.app.tradeoff.report"):
        monkeypatch.setattr(f"{module}.save_figure", keep)
    return saved


def spot_image(path, channel="main", look="exact"):
    cfg = preset("crouch-spotlight")
    x = (np.arange(40) - 20) * 10e-6
    y = (np.arange(30) - 15) * 20e-6
    img = np.zeros((40, 30), np.complex64)
    img[25, 5] = 1  # a point at x > 0, y < 0
    spot = f'{{"channel": "{channel}", "look": "{look}", "rotation_rad": 0.0}}'
    write_image(path, img, x, y, cfg, spotlight=spot)


def test_a_spotlight_image_is_drawn_cross_range_x_across_down_range_y_up(tmp_path, figures):
    spot_image(tmp_path / "s.h5")
    assert main(["quicklook", str(tmp_path / "s.h5"), "-o", str(tmp_path / "s.png")]) == 0
    (ax, _) = figures[0].axes
    assert ax.get_xlabel() == "cross-range x [µm]" and ax.get_ylabel() == "down-range y [µm]"
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    assert x0 < x1 and y0 < y1  # y up
    assert (x0, x1) == pytest.approx((-205, 195)) and (y0, y1) == pytest.approx((-310, 290))
    shown = ax.images[0].get_array()
    assert shown.shape == (30, 40) and np.unravel_index(np.argmax(shown), shown.shape) == (5, 25)


def test_bistatic_before_and_after_carry_different_titles(tmp_path, figures):
    for look in ("monostatic", "exact"):
        spot_image(tmp_path / f"{look}.h5", "bistatic", look)
        assert main(["quicklook", str(tmp_path / f"{look}.h5"), "-o", str(tmp_path / "x.png")]) == 0
    before, after = (f.axes[0].get_title() for f in figures)
    assert "as if monostatic" in before and "uncorrected" in before
    assert "bistatic geometry" in after and "corrected" in after
    assert before.split(": ", 1)[1] != after.split(": ", 1)[1]
    words = quicklook.spotlight_words
    assert words("bistatic", "monostatic", "pfa") != words("bistatic", "exact", "pfa")


def test_the_projective_z_axis_of_flat_points_has_no_offset_and_a_colour_bar(
    tmp_path, figures, monkeypatch
):
    from rtsar.app.cli import spot
    from rtsar.spot.projective import Reconstruction

    rng = np.random.default_rng(1)
    flat = np.column_stack(
        [rng.uniform(-8e-3, 8e-3, 5), rng.uniform(-8e-3, 8e-3, 5), 4e-19 * rng.standard_normal(5)]
    )  # what --simulate spotlight-scene gives: z at the rounding error of a flat scene
    monkeypatch.setattr(spot, "_images_for_projective", lambda args: (None,) * 4 + (0.0, 1.57))
    monkeypatch.setattr(spot, "reconstruct_points", lambda *a: Reconstruction(flat, np.zeros(5)))
    out = tmp_path / "p.csv"
    assert main(["projective", "a.h5", "b.h5", "-o", str(out), "--png", "p.png"]) == 0
    fig = figures[0]
    ax = next(a for a in fig.axes if a.name == "3d")
    assert ax.zaxis.get_offset_text().get_text() == ""
    z0, z1 = ax.get_zlim()
    assert z1 - z0 >= 0.1 * 16 * 0.8  # mm: not a span of 1e-16
    ticks = [t.get_text() for t in ax.zaxis.get_ticklabels() if t.get_text()]
    assert ticks and not any("e-" in t or "×" in t for t in ticks), ticks
    bars = [a for a in fig.axes if a is not ax]
    assert len(bars) == 1 and bars[0].get_ylabel() == "out of plane z (mm)"


def test_the_height_map_has_the_amplitude_image_axes(tmp_path, figures):
    cfg = preset("zhao-insal")
    rg = 2.3918 + np.arange(40) * 1.7e-4
    az = (np.arange(24) - 11.5) * 2e-4  # centred on 0, as an image's lines are
    path = tmp_path / "h.h5"
    w = ImageWriter(path, cfg, rg, heights=True)
    w.write(np.ones((24, 40), np.complex64), az)
    w.write_heights(0, np.full((24, 40), 1e-4, np.float32), np.ones((24, 40), bool))
    w.close()
    args = ["quicklook", str(path), "-o", str(tmp_path / "a.png"), "--height"]
    assert main(args + [str(tmp_path / "h.png")]) == 0
    amplitude, height = (f.axes[0] for f in figures)
    for get in ("get_xlabel", "get_ylabel", "get_xlim", "get_ylim"):
        assert getattr(amplitude, get)() == getattr(height, get)(), get
    assert amplitude.get_xlabel() == "slant range [mm]"
    assert amplitude.get_xlim()[0] == pytest.approx(2391.8 - 0.085)  # absolute range, in mm
    assert height.get_ylim() == pytest.approx((2.4, -2.4))  # along track from -2.4 mm


def test_tradeoff_labels_do_not_overlap(tmp_path, figures):
    from rtsar.app.tradeoff.report import plot
    from rtsar.app.tradeoff.scenes import TradeoffScene

    rows = []
    values = ["complex64", "complex128", "16", "32", "64", "rect", "hann"]
    for i, value in enumerate(values):
        far = i >= 5  # two far points spread the axes; five near-coincident ones overlapped
        rows.append(
            {
                "scene": "s",
                "knob": f"knob{i % 3}",
                "value": value,
                "default": i == 0,
                "front": i < 3,
                "us_per_pulse": 40.0 * (1 + 0.01 * i) * (30 ** (i - 4) if far else 1),
                "latency_p50_ms": (3.0 + 0.01 * i) * (10 ** (i - 4) if far else 1),
                "image_error": 1e-7 * (1 + 0.02 * i) * (1e3 ** (i - 4) if far else 1),
            }
        )
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.text import Text

    plot(rows, [TradeoffScene("s", "near points", preset("tiny"), [], [])], tmp_path / "t.png")
    fig = figures[0]
    FigureCanvasAgg(fig)  # the figure as saved (closed by plot: its canvas is gone)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        boxes = [Text.get_window_extent(t, renderer) for t in ax.texts]  # the words
        assert len(boxes) == len(rows)
        overlaps = [
            (ax.texts[i].get_text(), ax.texts[j].get_text())
            for i in range(len(boxes))
            for j in range(i + 1, len(boxes))
            if boxes[i].overlaps(boxes[j])
        ]
        assert not overlaps, overlaps


def _all_texts(fig, renderer):
    """(kind, text, window box) of every visible, non-empty text of the figure: point labels,
    tick labels (major and minor), axis labels, titles, legend entries."""
    from matplotlib.text import Text

    out = []
    for ax in fig.axes:  # a label's text, not its leader line
        out += [("label", t.get_text(), Text.get_window_extent(t, renderer)) for t in ax.texts]
        around = [ax.title, ax.xaxis.label, ax.yaxis.label]
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())  # the ticks drawn: within the view
            for tick in axis.get_major_ticks() + axis.get_minor_ticks():
                if lo <= tick.get_loc() <= hi:
                    around += [tick.label1, tick.label2]
        legend = ax.get_legend()
        if legend is not None:
            around += legend.get_texts()
        out += [
            ("axes", t.get_text(), t.get_window_extent(renderer))
            for t in around
            if t.get_visible() and t.get_text()
        ]
    return out


def test_tradeoff_labels_clear_every_text_and_the_figure_edge(tmp_path, figures):
    """The rows of one `rtsar tradeoff --quick` run (tests/data): "256" sat on "512" and on a
    10⁻⁸ tick label, "512" ran past the right edge, the minor tick labels "3×10¹" / "4×10¹"
    overlapped, "nonuniform" touched "direct"."""
    import json
    from pathlib import Path

    from matplotlib.backends.backend_agg import FigureCanvasAgg

    from rtsar.app.tradeoff.report import plot
    from rtsar.app.tradeoff.scenes import TradeoffScene

    rows = json.loads((Path(__file__).parent / "data" / "tradeoff_quick_rows.json").read_text())
    plot(rows, [TradeoffScene("instrument", "quick", preset("tiny"), [], [])], tmp_path / "t.png")
    fig = figures[0]
    FigureCanvasAgg(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    texts = _all_texts(fig, renderer)
    assert sum(kind == "label" for kind, _, _ in texts) == 2 * len(rows)
    edge = fig.bbox
    for kind, text, box in texts:
        if kind == "label":
            assert edge.x0 <= box.x0 and box.x1 <= edge.x1, (text, "leaves the figure")
            assert edge.y0 <= box.y0 and box.y1 <= edge.y1, (text, "leaves the figure")
    overlaps = [
        (a[1], b[1])
        for i, a in enumerate(texts)
        for b in texts[i + 1 :]
        if "label" in (a[0], b[0]) or a[0] == b[0]  # a label against anything; ticks vs ticks
        if a[2].overlaps(b[2])
    ]
    assert not overlaps, overlaps


def test_white_at_a_percentile_saturates_the_few_bright_points_and_says_so(tmp_path, figures):
    """A real scene's quicklook drawn from its peak (a ship) left the land 44 dB down, mostly
    black (a new user's review of RADARSAT-1's).  --white-at P puts 0 dB at the P-th
    percentile of |image|: pixels above it saturate, the rest keep their dB, and the colour bar
    names the reference."""
    cfg = preset("tiny")
    rng = np.random.default_rng(3)
    img = (rng.rayleigh(1.0, (64, 64)) * 1e-3).astype(np.complex64)  # land, ~60 dB down
    img[10, 20] = 1.0  # one ship
    path = tmp_path / "img.h5"
    write_image(path, img, np.arange(64.0), 2000 + np.arange(64.0), cfg)
    mag = np.abs(img)
    ref = np.percentile(mag, 99)  # the reference, from NumPy's percentile
    db = quicklook.to_db(img, 30.0, 99.0)
    assert db.max() == 0.0 and np.mean(db == 0.0) >= 0.01  # the top 1 % saturates
    below = mag < ref
    expected = np.clip(20 * np.log10(mag[below] / ref), -30, 0)
    assert np.allclose(db[below], expected, atol=1e-4)
    assert np.array_equal(quicklook.to_db(img, 30.0), quicklook.to_db(img, 30.0, 100.0))
    assert quicklook.to_db(img, 30.0).max() == 0.0 and quicklook.to_db(img, 30.0)[10, 20] == 0
    out = tmp_path / "q.png"
    assert main(["quicklook", str(path), "-o", str(out), "--white-at", "99"]) == 0
    labels = [a.get_ylabel() for a in figures[-1].axes]
    assert "dB re the 99th percentile" in labels
    assert main(["quicklook", str(path), "-o", str(out)]) == 0
    assert "dB re peak" in [a.get_ylabel() for a in figures[-1].axes]
    assert main(["quicklook", str(path), "-o", str(out), "--white-at", "0"]) == 2
