"""``rtsar measure IMG.h5``: the quality of an image you made, against the processor's theory.

Method (also in ``rtsar measure --help``):

* **Points.** Without ``--at``, point targets are the bright, isolated local maxima of |image|
  (rtsar.analysis.detect: within ``--threshold-db`` of the brightest pixel, ``--contrast-db``
  (20) above the 90th percentile of the ±8 resolution cells around them off their own cuts,
  the largest within ±1.5 theoretical IRWs, one per peak; closer than 4 cells to a brighter
  point, within 10 dB of it), brightest first.  With ``--at X,R [X,R ...]`` the brightest
  pixel within 2 resolution cells of (along track X, slant range R).
* **Peak, cuts, IRW, PSLR** (rtsar.analysis.point_target and .cut): a chip of ±12 theoretical
  IRWs (at least ±32 pixels, for the interpolation) is upsampled band-limited by 16 (FFT
  zero-padding) around the peak, which is then refined exactly; the azimuth and range cuts
  through it give the -3 dB widths (IRW, linear interpolation of the half-power crossings) and
  the PSLR (highest sidelobe outside the mainlobe within ±12 IRWs of the peak, even where the
  chip is wider; none when it is under NO_SIDELOBE_DB, rounding).  The mainlobe runs between
  the first nulls: the first minima walking outward from the half-power crossings.
* **ISLR** (rtsar.analysis.islr2d): one 2-D figure: sidelobe energy within ±10 IRWs on both
  axes, outside the null-to-null mainlobe rectangle, over the mainlobe's energy.
* **Theory** of the processor that made the image (its configuration, in the file), measured
  with the same rules: range, the window's response (IRW = 0.886 ρR × its broadening,
  ρR = c/2B); azimuth, the correlator's own response to a point (rtsar.analysis
  .azimuth_response: the mask with its window sliding along the exact range history, times the
  scene's antenna pattern with ``--scene``, or for a real instrument's echoes (an image of a
  recording ``rtsar import`` made: ``instrument_file``) the two-way sinc² of its configured
  antenna; ρA = λR/2L without a beam).
* **Notes** per point (``notes``, beside ``points``): a sidelobe-free cut, another found point
  on a cut or in the ISLR region (its PSLR/ISLR are then that point's), a cut or region cut
  short by the image edge.
* **Truth** (``--scene``, which must have the image's waveform and geometry): each point's
  offset from the nearest [[targets]] entry within 3 cells, in resolution cells (measured -
  true); a height image against the scene's [surface]: RMSE and bias of the valid heights and
  the valid fraction, on the pixels that see the surface without layover
  (rtsar.topo.insar.height_error).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..analysis.acceptance import SINC_IRW, range_weights
from ..analysis.azimuth_response import antenna_gain, azimuth_theory
from ..analysis.detect import find_point_targets
from ..analysis.islr2d import islr_2d_db, islr_2d_from_ratios_db, region_over_main
from ..analysis.point_target import analyse_point_target, image_centres
from ..analysis.theory import theoretical_irw_factor, theoretical_pslr_db
from ..ccd.base import azimuth_cell_m
from ..scene.effects import load_effects
from ..scene.effects.antenna import AntennaPattern
from ..scene.files import load_point_targets, load_scene, load_surface_scene
from ..sinks.image_file import image_config, read_heights, read_image
from ..sinks.io import write_text_when_complete
from ..spot.geometry import geometry_from_dict
from ..spot.pfa import PfaSettings, PolarFormatPlan
from ..topo.insar import height_error
from ..windows import impulse_response_width, window
from .measure_notes import NO_SIDELOBE_DB, point_notes, window_notes

POINT_KEYS = (
    "along_track_m",
    "range_m",
    "peak",
    "irw_azimuth_m",
    "irw_range_m",
    "pslr_azimuth_db",
    "pslr_range_db",
    "islr_db",
)
UPSAMPLE = 16
ISLR_EXTENT_IRW = 10.0
CHIP_IRW = 12.0  # the cuts span ±12 theoretical IRWs (PSLR is searched there) …
MIN_CHIP_PX = 32  # … and at least ±32 pixels (cut at ±16, a sampled sinc's first sidelobe
# read -13.20 dB for -13.26: the band-limited interpolation of a short cut errs)
SEARCH_CELLS = 2.0
TRUTH_CELLS = 3.0


def parse_at(text: str) -> tuple[float, float]:
    """``X,R`` (metres along track, slant range) → (x, r)."""
    parts = text.split(",")
    try:
        x, r = (float(p) for p in parts)
    except ValueError:
        raise ValueError(
            f"--at takes X,R in metres (along track, slant range), got {text!r}"
        ) from None
    if not (math.isfinite(x) and math.isfinite(r)):
        raise ValueError(f"--at takes finite metres, got {text!r}")
    return x, r


class Theory:
    """What the processor of ``config`` should give (module docstring), per slant range.

    ``gain(offset_m, range_m)``: the two-way antenna gain the scene simulated (None: none).
    """

    def __init__(self, config, gain=None):
        self.config, self.gain = config, gain
        rw = range_weights(config)
        rho_r = config.waveform.range_resolution_m
        self.irw_range_m = SINC_IRW * rho_r * theoretical_irw_factor(rw)
        self.pslr_range_db = theoretical_pslr_db(rw)
        self.range_ratio = region_over_main(rw, ISLR_EXTENT_IRW)

    def cell_m(self, slant_range_m: float) -> tuple[float, float]:
        """The resolution cells (ρA = λR/2L, L the aperture a column uses; ρR = c/2B) the search
        radii and offsets count in."""
        return azimuth_cell_m(self.config, slant_range_m), self.config.waveform.range_resolution_m

    def at(self, slant_range_m: float) -> dict:
        az = azimuth_theory(self.config, slant_range_m, self.gain, CHIP_IRW, ISLR_EXTENT_IRW)
        return {
            "irw_azimuth_m": az.irw_m,
            "irw_range_m": self.irw_range_m,
            "pslr_azimuth_db": az.pslr_db,
            "pslr_range_db": self.pslr_range_db,
            "islr_db": islr_2d_from_ratios_db(az.region_over_main, self.range_ratio),
        }


class SpotTheory:
    """What the polar-format processor should give for a spotlight image [x, y] (cross-range x
    as "azimuth", down-range y as "range"): each axis' window over the inscribed rectangle of
    k-space the image was formed from (rtsar.spot.pfa.PolarFormatPlan.cell_m: cells 2π/Δk,
    λ/2Δθ (Crouch eq. 9.5) and c/2B for a narrow sweep and band), rebuilt from the image's
    spotlight attributes (geometry, channel, look, settings)."""

    def __init__(self, config, spot: dict):
        try:
            settings = dict(spot.get("settings") or {})
            if settings.get("extent_m") is not None:
                settings["extent_m"] = tuple(settings["extent_m"])
            plan = PolarFormatPlan(
                config,
                geometry_from_dict(spot["geometry"]),
                spot.get("channel", "main"),
                PfaSettings(**settings),
                spot.get("look", "exact"),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"its spotlight attributes do not read: {exc}") from None
        self.rho_m = plan.cell_m()
        self.windows = (plan.settings.azimuth_window, plan.settings.range_window)
        weights = [window(w, 512) for w in self.windows]
        self.irw_m = tuple(
            impulse_response_width(w) * rho for rho, w in zip(self.rho_m, self.windows, strict=True)
        )
        self.pslr_db = tuple(theoretical_pslr_db(w) for w in weights)
        self.ratios = tuple(region_over_main(w, ISLR_EXTENT_IRW) for w in weights)

    def cell_m(self, _y_m: float) -> tuple[float, float]:
        return self.rho_m

    def at(self, _y_m: float) -> dict:
        return {
            "irw_azimuth_m": self.irw_m[0],
            "irw_range_m": self.irw_m[1],
            "pslr_azimuth_db": self.pslr_db[0],
            "pslr_range_db": self.pslr_db[1],
            "islr_db": islr_2d_from_ratios_db(*self.ratios),
        }


def _spacing(axis: np.ndarray, name: str) -> float:
    if len(axis) < 2:
        raise ValueError(f"the image has fewer than 2 samples along {name}: nothing to measure")
    return float(axis[1] - axis[0])


def _finite(v):
    return None if isinstance(v, float) and not math.isfinite(v) else v


def _sidelobe(pslr_db: float) -> float:
    """The PSLR, or NaN (reported null, with a note) where no sidelobe stands above rounding."""
    return pslr_db if pslr_db >= NO_SIDELOBE_DB else math.nan


def check_scene_matches(scene_cfg, image_cfg, scene, path) -> None:
    """ValueError naming the first setting where the scene's waveform or geometry differs from
    the image's: its truth and antenna pattern would describe another instrument."""
    mine, theirs = scene_cfg.to_dict(), image_cfg.to_dict()
    for part in ("waveform", "geometry"):
        for key, v in mine[part].items():
            w = theirs[part].get(key)
            same = v == w or (
                isinstance(v, float) and isinstance(w, float) and math.isclose(v, w, rel_tol=1e-9)
            )
            if not same:
                raise ValueError(
                    f"--scene {scene} does not match {path}: {part}.{key} is {v!r} in the scene, "
                    f"{w!r} in the image (give the scene the image was made from)"
                )


def measure_image(
    path: str | Path,
    scene: str | Path | None = None,
    at: list[tuple[float, float]] | None = None,
    threshold_db: float = -30.0,
    max_points: int = 20,
    contrast_db: float = 20.0,
) -> dict:
    """The report of ``rtsar measure`` (what ``--json`` writes): ``points`` (POINT_KEYS each),
    ``theory``, ``notes`` (a list of strings per point) and, with a scene, ``truth`` (one
    entry per point) and ``height``."""
    image, az, rg, attrs = read_image(path)
    if image.size == 0:
        raise ValueError(f"{path} holds no image lines")
    cfg = image_config(attrs, path)
    d_az, d_rg = _spacing(az, "azimuth"), _spacing(rg, "range")
    gain, targets, spot = None, None, "spotlight" in attrs
    if spot and scene is not None:
        raise ValueError(
            f"{path} is a spotlight image: its truth offsets are not measured yet (its frame "
            "turns with the collection); measure it without --scene"
        )
    if scene is not None:
        gain = scene_antenna_gain(scene, cfg, path)
        targets = load_point_targets(scene)
    elif attrs.get("instrument_file") and not spot:  # a real instrument's echoes: its beam
        gain = antenna_gain(AntennaPattern(cfg))
    if spot:
        try:
            theory = SpotTheory(cfg, json.loads(attrs["spotlight"]))
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
    else:
        theory = Theory(cfg, gain)
    centre_r = float(np.mean(rg))
    centre = theory.at(centre_r)
    cell_px = tuple(c / abs(d) for c, d in zip(theory.cell_m(centre_r), (d_az, d_rg), strict=True))
    irw_px = (centre["irw_azimuth_m"] / abs(d_az), centre["irw_range_m"] / abs(d_rg))
    found = find_point_targets(
        image, cell_px, threshold_db, contrast_db, irw_px=irw_px, max_points=max_points
    )
    if at:
        positions = list(at)
        for x, r in positions:
            if not (min(az) - abs(d_az) <= x <= max(az) + abs(d_az)) or not (
                min(rg) - abs(d_rg) <= r <= max(rg) + abs(d_rg)
            ):
                raise ValueError(
                    f"--at {x:g},{r:g} is outside the image (along track {az[0]:g} … {az[-1]:g} "
                    f"m, range {rg[0]:g} … {rg[-1]:g} m)"
                )
    else:
        positions = [(float(az[i]), float(rg[j])) for i, j in found]
    points, theories, truth, reports = [], [], [], []
    config = getattr(theory, "config", None)  # a spotlight image's theory has none: no squint
    centres = {} if config is None else image_centres(config)  # a spotlight image: found
    for x, r in positions:
        th = theory.at(r)
        chip = tuple(
            max(MIN_CHIP_PX, math.ceil(CHIP_IRW * th[key] / abs(d)))
            for key, d in (("irw_azimuth_m", d_az), ("irw_range_m", d_rg))
        )
        rho_a, rho_r = theory.cell_m(r)
        rep = analyse_point_target(
            image,
            az,
            rg,
            near_azimuth_m=x,
            near_range_m=r,
            search_radius_m=(SEARCH_CELLS * rho_a, SEARCH_CELLS * rho_r),
            chip=chip,
            upsample_factor=UPSAMPLE,
            islr_extent=ISLR_EXTENT_IRW,
            **centres,
            pslr_extent=CHIP_IRW,
        )
        widths = (rep.azimuth.irw_m, rep.range.irw_m)
        islr = (
            islr_2d_db(image, rep, d_az, d_rg, UPSAMPLE, ISLR_EXTENT_IRW)
            if all(math.isfinite(w) for w in widths)
            else math.nan  # no -3 dB width within the chip: not a point (reported as null)
        )
        values = (
            rep.azimuth_m,
            rep.range_m,
            abs(rep.peak_value),
            rep.azimuth.irw_m,
            rep.range.irw_m,
            _sidelobe(rep.azimuth.pslr_db),
            _sidelobe(rep.range.pslr_db),
            islr,
        )
        points.append({k: _finite(float(v)) for k, v in zip(POINT_KEYS, values, strict=True)})
        theories.append({k: _finite(float(v)) for k, v in th.items()})
        reports.append((rep, chip, th))
        if targets is not None:
            truth.append(_nearest(targets, rep.azimuth_m, rep.range_m, rho_a, rho_r))
    others = [(float(i), float(j)) for i, j in found]
    notes = point_notes(
        points, theories, reports, others, image.shape, (az, rg), CHIP_IRW, ISLR_EXTENT_IRW
    )
    if config is not None:  # an instrument's fixed window may cut an echo's chirp
        for mine, cut in zip(notes, window_notes(points, config), strict=True):
            mine.extend(cut)
    report = {
        "image": str(path),
        "method": {
            "upsample_factor": UPSAMPLE,
            "null_rule": "first minimum walking outward from each half-power crossing",
            "pslr": "highest sidelobe outside the null-to-null mainlobe within "
            f"±{CHIP_IRW:g} theoretical IRWs of the peak; null when none stands above "
            f"{NO_SIDELOBE_DB:g} dB",
            "islr": f"2-D: energy within ±{ISLR_EXTENT_IRW:g} IRWs on both axes outside the "
            "null-to-null mainlobe rectangle, over the mainlobe's",
            "axes": "spotlight image [x, y]: along_track_m and the azimuth figures are cross-range "
            "x, range_m and the range figures down-range y"
            if spot
            else "strip-map image [azimuth, range]",
            "azimuth_theory": f"2π/Δkx of the inscribed rectangle, window {theory.windows[0]}"
            if spot
            else "the correlator's response to a point: its windowed mask sliding "
            "along the exact range history"
            + (
                ", times the scene's antenna pattern"
                if gain is not None and scene
                else f", times the instrument's two-way beam (a uniform "
                f"{cfg.geometry.antenna_length_m:g} m aperture's sinc², the image's "
                "configuration: the instrument file's antenna, or where it gives none the one "
                "`rtsar import` assumed, whose Doppler band 2V/D is 0.75 PRF; the echoes are "
                "the instrument's: instrument_file)"
                if gain is not None
                else (
                    ", no antenna pattern (the scene has none)"
                    if scene
                    else ", no antenna pattern (give --scene for the scene's)"
                )
            ),
            "found": "given positions (--at)"
            if at
            else f"isolated local maxima within {threshold_db:g} dB of the brightest pixel, "
            f"{contrast_db:g} dB above their surroundings",
        },
        "points": points,
        "theory": theories,
        "notes": notes,
    }
    if targets is not None:
        report["truth"] = truth
        report["height"] = _height(path, scene, az, rg)
    return report


def scene_antenna_gain(scene, cfg, path):
    """The two-way antenna gain the scene simulated (None where it has no antenna_pattern),
    after checking that the scene is of the image's instrument (one theory for ``measure``
    and the SICD export's declared azimuth width)."""
    sc = load_scene(scene)
    check_scene_matches(sc.config, cfg, scene, path)
    named = dict(sc.effects)
    if "antenna_pattern" not in named:
        return None
    return antenna_gain(load_effects([("antenna_pattern", named["antenna_pattern"])], cfg)[0])


def _nearest(targets, x: float, r: float, rho_a: float, rho_r: float) -> dict | None:
    """The scene's [[targets]] entry nearest (in cells) within TRUTH_CELLS, and the offset."""
    if len(targets.along_track_m) == 0:
        return None
    da = (x - targets.along_track_m) / rho_a
    dr = (r - targets.slant_range_m) / rho_r
    k = int(np.argmin(np.hypot(da, dr)))
    if math.hypot(da[k], dr[k]) > TRUTH_CELLS:
        return None
    return {
        "along_track_m": float(targets.along_track_m[k]),
        "range_m": float(targets.slant_range_m[k]),
        "offset_azimuth_cells": float(da[k]),
        "offset_range_cells": float(dr[k]),
    }


def _height(path, scene, az, rg) -> dict | None:
    """RMSE, bias and valid fraction of the image's heights against the scene's [surface]."""
    heights = read_heights(path)
    surface = load_surface_scene(scene)
    if heights is None or surface is None:
        return None
    h, valid = heights
    truth = surface.truth(az, rg)
    e = height_error(h.astype(np.float64), valid, truth.height_m, truth.scored)
    return {
        "rmse_m": e["rms_m"],
        "bias_m": e["bias_m"],
        "valid_fraction": e["coverage"],
        "pixels_scored": int(truth.scored.sum()),
    }


def write_json(report: dict, out: str | Path) -> None:
    write_text_when_complete(out, json.dumps(report, indent=1, allow_nan=False) + "\n")


def _length(v: float | None) -> str:
    if v is None:
        return "–"
    for unit, scale in (("km", 1e3), ("m", 1.0), ("mm", 1e-3), ("µm", 1e-6)):
        if abs(v) >= scale or unit == "µm":
            return f"{v / scale:.4g} {unit}"
    return f"{v:g}"  # pragma: no cover


def _db(v: float | None) -> str:
    return "–" if v is None else f"{v:.1f}"


def text_lines(report: dict) -> list[str]:
    """The report as a table: measured (theory) per point, then the truth and the heights."""
    spotlight = report["method"]["axes"].startswith("spotlight")
    names = ("cross range", "down range") if spotlight else ("along track", "range")
    short = ("cross", "down") if spotlight else ("azimuth", "range")
    out = [
        f"{report['image']}: {len(report['points'])} point(s) ({report['method']['found']}); "
        f"measured (theory: azimuth, {report['method']['azimuth_theory']})",
        f"{'#':>3}  {names[0] + ' [m]':>15} {names[1] + ' [m]':>15} {'peak |x|':>10}  "
        f"{'IRW ' + short[0]:<22}{'IRW ' + short[1]:<22}"
        f"{f'PSLR {short[0][:2]} / {short[1][:2]} [dB]':<31}ISLR 2-D [dB]",
    ]
    for i, (p, t) in enumerate(zip(report["points"], report["theory"], strict=True)):
        irw_a = f"{_length(p['irw_azimuth_m'])} ({_length(t['irw_azimuth_m'])})"
        irw_r = f"{_length(p['irw_range_m'])} ({_length(t['irw_range_m'])})"
        pslr = (
            f"{_db(p['pslr_azimuth_db'])} / {_db(p['pslr_range_db'])} "
            f"({_db(t['pslr_azimuth_db'])} / {_db(t['pslr_range_db'])})"
        )
        out.append(
            f"{i:3d}  {p['along_track_m']:15.9g} {p['range_m']:15.9g} "
            f"{p['peak']:10.4g}  {irw_a:<22}{irw_r:<22}{pslr:<31}"
            f"{_db(p['islr_db'])} ({_db(t['islr_db'])})"
        )
    for i, notes in enumerate(report.get("notes", [])):
        out += [f"{i:3d}  note: {n}" for n in notes]
    for i, t in enumerate(report.get("truth", [])):
        if t is None:
            out.append(f"{i:3d}  no scene target within {TRUTH_CELLS:g} cells")
        else:
            out.append(
                f"{i:3d}  scene target at {t['along_track_m']:g}, {t['range_m']:g} m: offset "
                f"{t['offset_azimuth_cells']:+.3f} azimuth, {t['offset_range_cells']:+.3f} "
                "range cells"
            )
    h = report.get("height")
    if h is not None:
        rmse = "–" if h["rmse_m"] is None else _length(h["rmse_m"])
        bias = "–" if h["bias_m"] is None else _length(h["bias_m"])
        out.append(
            f"heights against the scene's surface: RMSE {rmse}, bias {bias}, valid on "
            f"{h['valid_fraction']:.1%} of {h['pixels_scored']} pixels that see it"
        )
    return out
