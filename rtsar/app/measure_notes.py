"""What a reader of ``rtsar measure`` must know about each number: the notes beside a point.

A measured PSLR or ISLR is the point's own only when its cuts and its ISLR region hold nothing
else and lie inside the image.  Each point gets a list of plain sentences (``notes`` in the
JSON, parallel to ``points``; printed under the table):

* a cut without a sidelobe above NO_SIDELOBE_DB (its PSLR is null), and a theory without one;
* another found or measured point whose mainlobe crosses a cut within the chip, or lies in
  the ±10 IRW ISLR region: the PSLR / ISLR then measure that point;
* a cut or the ISLR region that the image edge cuts short;
* an ISLR more than CLUTTER_DB above its theory with no neighbour to blame: the energy about
  the point (clutter, speckle, noise) dominates, and the ISLR measures the scene, not the
  response;
* an echo whose chirp an instrument's fixed receive window cut (window_notes): its band is
  part of the chirp's, and its range width more than the theory's, which takes the whole.
"""

from __future__ import annotations

import math

import numpy as np

from ..lens.plan import chirp_fraction_held, range_axis_m

NO_SIDELOBE_DB = -100.0  # a "sidelobe" lower than this is rounding: complex64 images hold
# ~7 digits, and a noise-free point's cuts read -150 to -180 dB beyond a beam-limited response
SAME_POINT_IRW = 1.5  # a neighbour closer than this (both axes) is the point itself
AXES = ("azimuth", "range")
CLUTTER_DB = 10.0  # measured ISLR this far above its theory: the surroundings, not the response


def point_notes(points, theories, reports, neighbours_px, shape, axes, chip_irw, islr_extent):
    """Notes (lists of sentences) per point.

    ``reports``: (PointTargetReport, chip half-size in px per axis, theory dict) per point;
    ``neighbours_px``: (row, column) of the other points found in the image; ``axes``: the
    image's (azimuth_m, range_m) axes.
    """
    peaks = [rep.peak_px for rep, _, _ in reports]
    spacing = [abs(float(a[1] - a[0])) for a in axes]
    notes = []
    for i, (p, t, (_, chip, _)) in enumerate(zip(points, theories, reports, strict=True)):
        out = []
        for axis, key in zip(AXES, ("pslr_azimuth_db", "pslr_range_db"), strict=True):
            if p[key] is None:
                out.append(
                    f"no {axis} sidelobe above {NO_SIDELOBE_DB:g} dB within ±{chip_irw:g} IRWs: "
                    f"{axis} PSLR null"
                )
        if t["pslr_azimuth_db"] is None:
            out.append("theory: the correlator's azimuth response has no sidelobe")
        irw_px = [t[k] / s for k, s in zip(("irw_azimuth_m", "irw_range_m"), spacing, strict=True)]
        measured = [
            w / s if w is not None and math.isfinite(w) else th
            for w, s, th in zip(
                (p["irw_azimuth_m"], p["irw_range_m"]), spacing, irw_px, strict=True
            )
        ]
        region = [islr_extent * w for w in measured]
        searched = [min(c, chip_irw * w) for c, w in zip(chip, irw_px, strict=True)]
        near = _neighbours(i, peaks, neighbours_px, irw_px, searched, region, axes)
        out += near
        out += _edges(peaks[i], chip, region, irw_px, shape, chip_irw, islr_extent)
        above = _excess_db(p["islr_db"], t["islr_db"])
        if above is not None and above > CLUTTER_DB and not near:
            out.append(
                f"ISLR {above:.1f} dB above its theory with no other point near: the energy "
                "about the point (clutter, speckle, noise) dominates it, so it measures the "
                "scene, not the response"
            )
        notes.append(out)
    return notes


def _neighbours(i, peaks, neighbours_px, irw_px, chip, region, axes):
    out, seen = [], [peaks[i]]
    candidates = [q for j, q in enumerate(peaks) if j != i] + list(neighbours_px)
    for q in candidates:
        if any(
            abs(q[0] - s[0]) <= SAME_POINT_IRW * irw_px[0]
            and abs(q[1] - s[1]) <= SAME_POINT_IRW * irw_px[1]
            for s in seen
        ):
            continue  # this point, or one already named
        seen.append(q)
        d = [q[a] - peaks[i][a] for a in (0, 1)]
        in_region = all(abs(d[a]) <= region[a] + irw_px[a] for a in (0, 1))
        where = (
            f"{_at(axes[0], q[0]):.6g}, {_at(axes[1], q[1]):.6g} m "
            f"({abs(d[0]) / irw_px[0]:.1f} azimuth, {abs(d[1]) / irw_px[1]:.1f} range IRWs away)"
        )
        on_cut = None
        for a in (0, 1):
            other = 1 - a
            if abs(d[other]) <= irw_px[other] and abs(d[a]) <= chip[a]:
                on_cut = AXES[a]
        if on_cut is not None:
            also = " and the ISLR" if in_region else ""
            out.append(
                f"another point on the {on_cut} cut, at {where}: the {on_cut} PSLR{also} "
                "measure it, not this point's sidelobes"
            )
        elif in_region:
            out.append(f"another point in the ISLR region, at {where}: the ISLR counts it")
    return out


def _edges(peak, chip, region, irw_px, shape, chip_irw, islr_extent):
    out = []
    for a in (0, 1):
        room = min(peak[a], shape[a] - 1 - peak[a])  # pixels to the nearer edge
        # the cut's reach: ±chip_irw IRWs, within its chip (which has a least size in pixels)
        if room < min(chip[a], chip_irw * irw_px[a]):
            out.append(
                f"the {AXES[a]} cut ends at the image edge {room / irw_px[a]:.1f} IRWs from the "
                f"peak (of ±{chip_irw:g}): its PSLR sees only that far"
            )
        if room < region[a]:
            out.append(
                f"the ISLR region (±{islr_extent:g} IRWs) is cut short by the image edge in "
                f"{AXES[a]}: the ISLR counts less sidelobe energy than there is"
            )
    return out


def _excess_db(measured, theory) -> float | None:
    if measured is None or theory is None:
        return None
    if not (math.isfinite(measured) and math.isfinite(theory)):
        return None
    return float(measured - theory)


def _at(axis, index: float) -> float:
    return float(axis[0] + index * (axis[1] - axis[0]))


HELD_WHOLE = 0.99  # an echo with less of its chirp inside the receive window gets a note


def window_notes(points, config) -> list[list[str]]:
    """A sentence per point whose echo's chirp the receive window holds less than HELD_WHOLE
    of (rtsar.lens.plan.chirp_fraction_held at its range): on RADARSAT-1's block, the ship
    1.6 times the range theory sits where the window holds 55 % of its chirp."""
    held = chirp_fraction_held(config)
    if held.min() >= HELD_WHOLE:  # FMCW, or a window the plan took whole chirps from
        return [[] for _ in points]
    axis = range_axis_m(config)  # a pulsed plan's: increasing with the lag
    whole = axis[held >= HELD_WHOLE]
    span = f"{whole.min():.1f} … {whole.max():.1f} m" if len(whole) else "none"
    out = []
    for p in points:
        f = float(np.interp(p["range_m"], axis, held))
        out.append(
            [
                f"the receive window holds {100 * f:.0f} % of this echo's chirp (the whole chirp: "
                f"{span}): its band is that part of the chirp's, its range response up to "
                f"{1 / f:.2g} times the theory's width"
            ]
            if 0 < f < HELD_WHOLE
            else []
        )
    return out
