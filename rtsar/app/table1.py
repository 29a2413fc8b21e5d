"""Table 1 of Psaltis & Wagner (1981), regenerated from the physical-mode emulation.

``rtsar table1`` prints a Markdown table: each quantity of the paper's Table 1 with the paper's
values as printed (experimental processor / maximum possible) and the emulated ones, which come
from emulated devices and images, not from the paper's formulas:

* range resolution: c/2B of the preset and the -3 dB width (IRW) measured on an emulated point
  target (AO lens → physical CCD with the paper's well, bias and blooming, noise off);
* range cells: ``PhysicalCCD.range_cells`` of a device built for the paper's CCD width (320
  columns; 2400 for the maximum column), per carrier;
* azimuth resolution: L/N with N = ``PhysicalCCD.pulses_integrated`` for the paper's 512 rows,
  and the IRW measured on an emulated point target with that device;
* dynamic range, measured (``measure_dynamic_range``): the strongest point target that overflows
  no pixel (a bisection on its amplitude, noise off, so the limit is deterministic) against the
  noise of an empty scene through the paper's CCD (shot noise, 200 e- after double-correlated
  sampling, 12-bit ADC, blooming).  Two ratios: per pixel (largest charge swing above the bias
  over the rms charge noise of a pixel: the paper's definition) and in the image (peak
  amplitude over the rms noise per quadrature after the readout).

Resolution and dynamic range runs use the presets' geometry with fewer range cells (64), which
changes neither (same CCD rows, mask, well, bias and noise per pixel); the cell counts use devices
of the full width.  The report takes about 25 s on two busy cores (``--speed`` adds about 20 s).
"""

from __future__ import annotations

import json
import math
import sys
import time

import numpy as np

from ..analysis import analyse_point_target
from ..ccd.base import design_mask
from ..ccd.direct import DirectCorrelator
from ..ccd.physical import PhysicalCCD
from ..lens.numpy_lens import NumpyLens
from ..lens.plan import make_plan, range_axis_m
from ..params import Config
from ..physical.aocell import AOCell
from ..physical.carrier import pulses_integrated, range_cells
from ..physical.settings import PhysicalSettings, paper_ccd
from ..presets import preset
from ..scene import Simulator, point_scene
from ..sinks.io import check_writable, write_text_when_complete

# Psaltis & Wagner 1981, Table 1, as printed.
PAPER = {
    "range_resolution": ("ρR ≈ 10-20m", "ρR < 1m"),
    "range_cells": ("160 or 320", "1200"),
    "azimuth_resolution": ("N = 512 or 256, ρA ≈ 30-60m", "ρA ~ 15m"),
    "azimuth_cells": ("Not limited by the processor.", ""),
    "dynamic_range": ("Dynamic Range 250-300 : 1", "Dynamic Range 500 : 1"),
}
PAPER_ESTIMATE = 125_000 / 550  # the text after Table 1: max signal / sensitivity
CCD_EXPERIMENTAL = (512, 320)  # rows (shift direction) × columns of the experimental CCD
CCD_MAXIMUM_COLUMNS = {"range": 2400, "azimuth": 1200}  # 1200 range cells either way
REDUCED_BINS = 64


def _log(msg: str, t0: float) -> None:
    print(f"table1: {time.perf_counter() - t0:5.1f} s  {msg}", file=sys.stderr, flush=True)


def device_config(cfg: Config, carrier: str, ccd_rows: int, ccd_columns: int) -> Config:
    """The preset with the N pulses and B cells that a CCD of that size holds with a carrier."""
    return cfg.with_processor(
        aperture_pulses=pulses_integrated(ccd_rows, carrier),
        range_bins=range_cells(ccd_columns, carrier),
    )


def simulate_lines(cfg: Config, amplitude: float, margin_lines: int, settings=None):
    """Range-compressed lines of one point target at the swath centre (AO cell, NumPy lens).

    Returns (lines complex64[pulse, bin], start_along_track_m, target_range_m).
    """

    plan = make_plan(cfg)
    rm = plan.range_m
    n, step = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    r0 = float(rm[len(rm) // 2] + 0.31 * (rm[1] - rm[0]))
    x0 = 0.23 * step
    start = x0 - (0.5 * (n - 1) + margin_lines) * step
    scene = point_scene(
        cfg, [x0], [r0], amplitude=[amplitude], seed=3, pulses=n + 2 * margin_lines,
        start_along_track_m=start,
    )  # fmt: skip
    shots = Simulator(scene).block(scene.pulses)
    shots = AOCell(cfg, settings).apply(shots)
    return NumpyLens(plan).compress(shots), start, r0, x0


def focus(cfg: Config, settings: PhysicalSettings, lines: np.ndarray, start_m: float):
    """Lines through a PhysicalCCD in one push, flushed → (image, azimuth_m, range_m, ccd).

    ``ccd.last_raw_e`` holds the charge of every packet read out by the push (e-, after the
    ADC), for the per-pixel measures.
    """
    rm = range_axis_m(cfg)
    ccd = PhysicalCCD(cfg, rm, settings)
    ccd.keep_raw = True
    parts = [ccd.push(lines)]
    raw = ccd.last_raw_e
    parts.append(ccd.flush())
    ccd.last_raw_e = raw
    image = np.concatenate(parts)
    n, step = cfg.processor.aperture_pulses, cfg.geometry.along_track_step_m
    az = start_m + (np.arange(len(image)) + 0.5 * (n - 1)) * step
    return image, az, rm, ccd


def measure_resolution(
    cfg: Config, settings: PhysicalSettings, amplitude: float = 0.5, bins: int = REDUCED_BINS
) -> dict:
    """IRW in range and azimuth of an emulated point target (``bins`` range cells).

    The detector keeps its well, bias and blooming but no noise: resolution is measured at
    high signal-to-noise ratio, with a target below the overflow limit (about 0.7).
    """
    settings = _quiet(settings)
    cfg = cfg.with_processor(range_bins=bins)
    step = cfg.geometry.along_track_step_m
    irw_lines = 0.8859 * cfg.azimuth_resolution_m() / step
    chip = max(32, int(math.ceil(4 * irw_lines)))
    lines, start, r0, x0 = simulate_lines(cfg, amplitude, chip + 8)
    image, az, rg, _ = focus(cfg, settings, lines, start)
    rho_a, rho_r = cfg.azimuth_resolution_m(), cfg.waveform.range_resolution_m
    rep = analyse_point_target(
        image, az, rg, near_azimuth_m=x0, near_range_m=r0,
        search_radius_m=(2 * rho_a, 2 * rho_r), chip=chip,
    )  # fmt: skip
    return {
        "range_irw_m": rep.range.irw_m,
        "azimuth_irw_m": rep.azimuth.irw_m,
        "range_resolution_m": rho_r,
        "azimuth_resolution_m": rho_a,
        "illuminated_length_m": cfg.geometry.illuminated_length_m,
        "pulses_integrated": cfg.processor.aperture_pulses,
        "l_over_n_m": cfg.geometry.illuminated_length_m / cfg.processor.aperture_pulses,
    }


def _quiet(settings: PhysicalSettings) -> PhysicalSettings:
    """The same detector (well, bias, scale, blooming) with every noise effect off."""
    return PhysicalSettings(
        carrier=settings.carrier,
        full_well_e=settings.full_well_e,
        bias_fraction=settings.bias_fraction,
        full_scale_amplitude=settings.full_scale_amplitude,
        seed=settings.seed,
        ccd=tuple(e for e in settings.ccd if e.name == "blooming"),
    )


def measure_dynamic_range(
    cfg: Config, settings: PhysicalSettings, iterations: int = 12, bins: int = REDUCED_BINS
) -> dict:
    """Dynamic range measured on emulated images (method in the module docstring).

    ``settings``: the detector with its noise; the saturation search uses the same well, bias
    and blooming with every noise effect off.
    """
    cfg = cfg.with_processor(range_bins=bins)
    margin = 64
    # Noise floor: an empty scene through the noisy detector.
    empty, start, _, _ = simulate_lines(cfg, 0.0, margin)
    image, _, _, ccd = focus(cfg, settings, empty, start)
    pixel = ccd.last_raw_e - ccd.bias_e  # packets of reference light alone
    sigma_e = float(np.sqrt(np.mean(pixel**2)))
    sigma_q = float(np.sqrt(0.5 * np.mean(np.abs(image) ** 2)))
    # Saturation: bisection on the amplitude of one target, noise off (linear lens: scale lines).
    quiet = _quiet(settings)
    unit, start, r0, x0 = simulate_lines(cfg, 1.0, margin)

    def run(a):
        img, _, _, dev = focus(cfg, quiet, unit * np.float32(a), start)
        return img, dev

    lo, hi = 1e-3, 1.0
    while run(hi)[1].pixel_overflows == 0:  # make sure hi overflows
        lo, hi = hi, 2 * hi
    for _ in range(iterations):
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if run(mid)[1].pixel_overflows == 0 else (lo, mid)
    a_max = lo
    img_max, dev = run(a_max)
    img_small, _ = run(a_max * 1e-2)
    peak_max = float(np.abs(img_max).max())
    peak_small = float(np.abs(img_small).max())
    compression_db = 20 * math.log10(peak_max / (100.0 * peak_small))
    above_bias_e = float(np.max(dev.last_raw_e - dev.bias_e))
    swing_e = peak_max * dev.electrons_per_unit  # the carrier's swing at the brightest pixel
    return {
        "a_max": a_max,
        "peak_amplitude": peak_max,
        "compression_db": compression_db,
        "swing_e": swing_e,
        "charge_above_bias_e": above_bias_e,
        "sigma_pixel_e": sigma_e,
        "sigma_image": sigma_q,
        "dr_pixel": swing_e / sigma_e,
        "dr_image": peak_max / sigma_q,
        "bias_e": float(dev.bias_e.max()),
        "full_well_e": settings.full_well_e,
        "range_cells": cfg.processor.range_bins,
    }


def _entry(cfg: Config, carrier: str, rows: int, columns: int, bins: int, log, what: str):
    dev_cfg = device_config(cfg, carrier, rows, columns)
    ccd = PhysicalCCD(dev_cfg, range_axis_m(dev_cfg), paper_ccd(carrier))
    entry = {"device": ccd.describe(), "config": dev_cfg.to_dict()}
    log(f"{what}, carrier in {carrier}: resolution")
    entry["resolution"] = measure_resolution(dev_cfg, paper_ccd(carrier), bins=bins)
    log(f"{what}, carrier in {carrier}: dynamic range")
    entry["dynamic_range"] = measure_dynamic_range(dev_cfg, paper_ccd(carrier), bins=bins)
    return entry


def table1_data(
    speed: bool = False,
    log=None,
    experimental: str = "psaltis-jpl",
    maximum: str = "psaltis-max",
    ccd: tuple[int, int] = CCD_EXPERIMENTAL,
    maximum_columns: int = CCD_MAXIMUM_COLUMNS["range"],
    bins: int = REDUCED_BINS,
) -> dict:
    """Every number of the report (a JSON-ready dict).

    ``experimental`` / ``maximum``: presets of the two columns; ``ccd`` = (rows, columns) of the
    experimental CCD; ``maximum_columns``: CCD width of the maximum column (range carrier);
    ``bins``: range cells of the resolution and dynamic-range runs.
    """
    t0 = time.perf_counter()
    log = log or (lambda msg: _log(msg, t0))
    exp_cfg, max_cfg = preset(experimental), preset(maximum)
    rows, cols = ccd
    data = {"experimental": {}, "maximum": {}, "paper": PAPER, "paper_estimate": PAPER_ESTIMATE}
    data["presets"] = {"experimental": experimental, "maximum": maximum}
    data["ccd"] = {"experimental": list(ccd), "maximum_columns": maximum_columns}
    for carrier in ("range", "azimuth"):
        data["experimental"][carrier] = _entry(
            exp_cfg, carrier, rows, cols, bins, log, "experimental"
        )
    rows_max = max_cfg.processor.aperture_pulses
    data["maximum"]["range"] = _entry(
        max_cfg, "range", rows_max, maximum_columns, bins, log, "maximum"
    )
    data["settings"] = {c: paper_ccd(c).to_dict() for c in ("range", "azimuth")}
    if speed:
        log("speed: physical register vs DirectCorrelator at 512 × 320")
        data["speed"] = measure_speed()
    log("done")
    return data


def measure_speed(pulses: int = 1024, batch: int = 64, repeats: int = 3) -> dict:
    """Pulses/s of the ideal DirectCorrelator and the physical CCD at psaltis-jpl size.

    Best of ``repeats`` passes of ``pulses`` random lines in batches of ``batch``.  The physical
    CCD is measured with the paper's 512 × 320 CCD (range carrier: N = 512, 160 cells; azimuth
    carrier: N = 256, 320 cells) and as a drop-in for psaltis-jpl (N = 512, 320 cells, range
    carrier: a 512 × 640 CCD), noise off and with the paper's detector.
    """

    cfg = preset("psaltis-jpl")
    rng = np.random.default_rng(5)
    lines = 0.01 * (rng.standard_normal((pulses, 320)) + 1j * rng.standard_normal((pulses, 320)))
    lines = lines.astype(np.complex64)

    def rate(make, width):
        best = 0.0
        for _ in range(repeats):
            corr = make()
            corr.push(lines[:batch, :width])  # warm up
            t0 = time.perf_counter()
            for i in range(0, pulses, batch):
                corr.push(lines[i : i + batch, :width])
            best = max(best, pulses / (time.perf_counter() - t0))
        return best

    out = {
        "direct_512x320": rate(lambda: DirectCorrelator(design_mask(cfg, range_axis_m(cfg))), 320)
    }
    cases = [
        ("range_512x320", "range", 512, 160), ("azimuth_512x320", "azimuth", 256, 320),
        ("range_dropin_512x640", "range", 512, 320),
    ]  # fmt: skip
    for name, carrier, n, b in cases:
        c = cfg.with_processor(aperture_pulses=n, range_bins=b)
        rm = range_axis_m(c)
        for label, s in (
            ("quiet", PhysicalSettings(carrier=carrier)),
            ("paper", paper_ccd(carrier)),
        ):
            out[f"{name}_{label}"] = rate(lambda c=c, rm=rm, s=s: PhysicalCCD(c, rm, s), b)
    return out


def _fmt(v: float, unit: str = "m") -> str:
    return f"{v:.3g} {unit}"


def table1_markdown(data: dict | None = None, speed: bool = False) -> str:
    """The report: Table 1 with the paper's values and the emulated ones (Markdown)."""
    data = data or table1_data(speed=speed)
    ex, mx = data["experimental"], data["maximum"]["range"]
    er, ea = ex["range"], ex["azimuth"]
    rows, cols = data["ccd"]["experimental"]
    names = data["presets"]

    def rr(e):
        r = e["resolution"]
        return f"c/2B = {_fmt(r['range_resolution_m'])}; IRW {_fmt(r['range_irw_m'])}"

    def ra(e):
        r = e["resolution"]
        return (
            f"N = {r['pulses_integrated']}: L/N = {_fmt(r['l_over_n_m'])}; "
            f"IRW {_fmt(r['azimuth_irw_m'])}"
        )

    def dr(e):
        d = e["dynamic_range"]
        return f"{d['dr_pixel']:.0f} : 1 per pixel, {d['dr_image']:.0f} : 1 in the image"

    p = data["paper"]
    table = [
        "| quantity | paper: experimental | paper: maximum possible | emulated: experimental "
        f"({names['experimental']}, {rows} × {cols} CCD) | emulated: maximum "
        f"({names['maximum']}) |",
        "|---|---|---|---|---|",
        f"| Range resolution ρR = c/2B | {p['range_resolution'][0]} | {p['range_resolution'][1]} "
        f"| {rr(er)} | {rr(mx)} |",
        f"| Number of range resolution elements | {p['range_cells'][0]} | {p['range_cells'][1]} "
        f"| {er['device']['range_cells']} (carrier in range) or {ea['device']['range_cells']} "
        f"(carrier in azimuth) | {mx['device']['range_cells']} (carrier in range, "
        f"{mx['device']['ccd_columns']} columns) |",
        f"| Azimuth resolution ρA = L/N | {p['azimuth_resolution'][0]} "
        f"| {p['azimuth_resolution'][1]} | {ra(er)} (carrier in range); {ra(ea)} (carrier in "
        f"azimuth) | {ra(mx)} |",
        f"| Number of azimuth resolution elements | {p['azimuth_cells'][0]} | | not limited: "
        "one line per pulse, streaming | not limited |",
        f"| Image quality: dynamic range | {p['dynamic_range'][0]} | {p['dynamic_range'][1]} "
        f"| {dr(er)} (carrier in range); {dr(ea)} (carrier in azimuth); the paper's estimate "
        f"125 000 / 550 ≈ {data['paper_estimate']:.0f} : 1 | {dr(mx)} (the same CCD) |",
    ]
    d = er["dynamic_range"]
    bins = er["dynamic_range"]["range_cells"]
    notes = [
        "",
        "How the emulated columns were obtained (`rtsar table1`, rtsar.physical):",
        "",
        "* ρR: c/2B of the preset; IRW = measured -3 dB width of a point target through AO lens "
        "and physical CCD (0.886·c/2B expected for an unweighted chirp).",
        f"* Range cells: `PhysicalCCD.range_cells` of devices built for {cols} CCD columns "
        f"({mx['device']['ccd_columns']} for the maximum column): the range carrier takes two "
        "columns per cell (I and Q, the reference a quarter fringe apart).",
        f"* ρA: L = λR/D illuminated; N = `PhysicalCCD.pulses_integrated` of {rows} CCD rows "
        "(the azimuth carrier exposes each pulse twice, two rows per pulse); IRW measured on "
        "the emulated point target (0.886·L/N expected, unweighted aperture).",
        f"* Dynamic range: the strongest point target that overflows no pixel (bisection on its "
        f"amplitude, noise off: {d['a_max']:.3g} of full scale, {d['compression_db']:+.2f} dB "
        f"from linear) against an empty scene through the paper's CCD (full well "
        f"{d['full_well_e']:.0f} e-, bias {d['bias_e']:.0f} e-, shot noise, 200 e- after "
        f"double-correlated sampling, 12-bit ADC (our assumption), blooming).  Per pixel (the "
        f"paper's definition): largest carrier swing {d['swing_e']:.0f} e- over "
        f"{d['sigma_pixel_e']:.0f} e- rms of a pixel (√(bias + 200²) adds in quadrature; the "
        "paper adds 350 + 200 = 550).  In the image: peak amplitude over the rms noise per "
        "quadrature after the readout, whose filter averages along azimuth.  The swing stays "
        "below the paper's 125 000 e- because the signal's own intensity (|s|² in eq. P1 of "
        "rtsar.physical.carrier) sits on the bias as well.",
        f"* Resolution and dynamic-range runs use {bins} range cells (same rows, mask, well and "
        "noise per pixel).  The maximum column's dynamic range uses the experimental CCD: the "
        "paper's 500 : 1 assumes a better detector.",
    ]
    if "speed" in data:
        s = data["speed"]
        notes.append(
            f"* Speed (pulses/s, best of 3, this machine): ideal DirectCorrelator 512 × 320 "
            f"{s['direct_512x320']:.0f}; physical CCD of 512 × 320 pixels, carrier in range "
            f"{s['range_512x320_quiet']:.0f} (noise off) / {s['range_512x320_paper']:.0f} "
            f"(paper's CCD), in azimuth {s['azimuth_512x320_quiet']:.0f} / "
            f"{s['azimuth_512x320_paper']:.0f}; drop-in for psaltis-jpl (512 × 640 pixels) "
            f"{s['range_dropin_512x640_quiet']:.0f} / {s['range_dropin_512x640_paper']:.0f}."
        )
    return "\n".join(table + notes) + "\n"


def add_arguments(parser) -> None:
    """Options of ``rtsar table1``."""
    parser.add_argument(
        "--out", metavar="FILE.md", help="write the Markdown table to FILE.md (default: stdout)"
    )
    parser.add_argument("--json", metavar="FILE", help="write every number (and settings) as JSON")
    parser.add_argument(
        "--speed",
        action="store_true",
        help="also measure the physical CCD's pulses/s against the ideal DirectCorrelator",
    )


def run(args) -> int:
    """``rtsar table1``: progress on stderr, the table on stdout (or --out)."""
    outputs = [p for p in (getattr(args, "out", None), getattr(args, "json", None)) if p]
    for path in outputs:
        check_writable(path)  # before the ~25 s of work
    data = table1_data(speed=getattr(args, "speed", False))
    text = table1_markdown(data)
    if getattr(args, "out", None):
        write_text_when_complete(args.out, text)
        print(f"wrote {args.out}", file=sys.stderr)
    else:
        sys.stdout.write(text)
    if getattr(args, "json", None):
        write_text_when_complete(args.json, json.dumps(data, indent=2, default=float))
        print(f"wrote {args.json}", file=sys.stderr)
    return 0
