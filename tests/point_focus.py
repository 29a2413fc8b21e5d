"""A block focused by rtsar's engine and its points measured, and a correlator fed in pieces:
what the range-migration tests compare (tests/test_doppler_migration.py,
tests/test_walk_deskew.py)."""

from __future__ import annotations

import numpy as np

from rtsar.analysis.point_target import analyse_point_target, image_centres
from rtsar.stream.engine import process_block


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
