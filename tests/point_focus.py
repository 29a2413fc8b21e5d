"""A block focused by rtsar's engine and its points measured, and a correlator fed in pieces:
what the range-migration tests compare (tests/test_doppler_migration.py,
tests/test_walk_deskew.py); three points focused by a squinted plan (tests/test_squint.py,
tests/test_sicd_squint.py)."""

from __future__ import annotations

import numpy as np

from rtsar.analysis.point_target import analyse_point_target, image_centres
from rtsar.lens import make_plan
from rtsar.scene import Simulator
from rtsar.scene.model import point_scene
from rtsar.stream.engine import process_block


def three_points_focused(cfg):
    """(scene, shots, image, azimuth_m, range_m, xs, rs): three points at closest-approach
    along-track xs and range rs (off the pixel grid, at bins 800, 1024 and 1240 of the plan)
    seen through the beam's main lobe, focused on the NumPy lens."""
    xs = np.array([3000.0, 3400.0, 3800.0])
    rs = make_plan(cfg).range_m[[800, 1024, 1240]] + np.array([1.3, 0.7, 2.1])
    scene = point_scene(cfg, xs, rs, effects=[("antenna_pattern", {"main_lobe_only": True})])
    shots = Simulator(scene).block(scene.pulses)
    image, az, rg = process_block(cfg, shots, "numpy", scene.start_along_track_m)
    return scene, shots, image, az, rg, xs, rs


def focus_points(cfg, shots, start_m, xs, rs, **processor):
    """PointTargetReports of the targets (xs, rs) in ``shots`` focused on the NumPy lens with
    ``cfg``'s processor changed by ``processor``."""
    img, az, rg = process_block(cfg.with_processor(**processor), shots, "numpy", start_m)
    return [
        analyse_point_target(
            img,
            az,
            rg,
            x,
            r,
            search_radius_m=(60.0, 20.0),
            **image_centres(cfg),
        )
        for x, r in zip(xs, rs, strict=True)
    ]


def pushed_in_pieces(ccd, lines, sizes=(37, 500, 1, 260)) -> np.ndarray:
    """``ccd``'s lines for ``lines`` pushed in pieces of ``sizes`` in turn, then flushed."""
    outs, i = [], 0
    while i < len(lines):
        n = sizes[len(outs) % len(sizes)]
        outs.append(ccd.push(lines[i : i + n]))
        i += n
    return np.concatenate([*outs, ccd.flush()])


def whole_and_in_pieces(cfg, shots):
    """(the correlator's class, its lines for the NumPy lens's lines of ``shots`` pushed at
    once, the same pushed in pieces, those lens lines): make_ccd's correlator of ``cfg``."""
    from rtsar.ccd import make_ccd
    from rtsar.lens import make_lens, make_plan

    plan = make_plan(cfg)
    lines = make_lens(plan, "numpy").compress(shots)
    whole, parts = make_ccd(cfg, plan.range_m), make_ccd(cfg, plan.range_m)
    try:
        a = np.concatenate([whole.push(lines), whole.flush()])
        return type(whole), a, pushed_in_pieces(parts, lines), lines
    finally:
        whole.close()
        parts.close()
