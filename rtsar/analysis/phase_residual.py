"""Residual phase of a correction against the injected truth, in radians.

Two figures: with the constant removed (a correction that must also hold the phase slope:
phase-to-retro, the reference region), and with constant and slope removed (autofocus, which
cannot see either: Crouch 2012, ch. 4), optionally per aperture-long window.
"""

from __future__ import annotations

import math

import numpy as np

from ..focus.pga.blocks import align_blocks
from ..phase import wrap


def constant_removed_rms_rad(estimate, truth) -> float:
    """Rms (radians) of the wrapped estimate - truth after removing its circular mean: the
    residual of a correction that must also hold the slope (phase-to-retro, reference region)."""
    d = wrap(np.asarray(estimate) - truth)
    d = wrap(d - np.angle(np.mean(np.exp(1j * d))))
    return float(np.sqrt(np.mean(d**2)))


def residual_rms_rad(
    estimate_rad: np.ndarray, truth_rad: np.ndarray, window_pulses: int | None = None
) -> float:
    """Rms of the residual (estimate - truth), radians, with constant and slope removed.

    The figure of merit of a correction against the injected truth.  Constant and linear phase
    are unobservable by autofocus (rtsar.focus.pga.estimator); they are fitted as phasor
    averages (rtsar.focus.pga.blocks.align_blocks) so a 2π step changes nothing, and the rms is
    of the residual wrapped to [-π, π).  ``window_pulses`` None: one fit over the whole record.
    ``window_pulses`` = N (the aperture): a fit per window of N pulses (windows every N/2
    pulses), the rms over all
    windows — what decides focus, since each image line sees N pulses and a slope left in one
    aperture only shifts that line.
    """
    e = np.asarray(estimate_rad, np.float64)
    t = np.asarray(truth_rad, np.float64)
    if e.shape != t.shape or e.ndim != 1:
        raise ValueError(f"estimate and truth must be 1-D of one length, got {e.shape}, {t.shape}")
    n = e.size if window_pulses is None else int(window_pulses)
    if n < 1:
        raise ValueError(f"window_pulses must be >= 1, got {window_pulses!r}")
    if e.size == 0:
        return 0.0
    n = min(n, e.size)
    starts = range(0, e.size - n + 1, max(1, n // 2))
    squares = []
    for s in starts:
        d = e[s : s + n] - t[s : s + n]
        a, c = align_blocks(d)
        r = wrap(d - a - c * np.arange(n))
        squares.append(float(np.mean(r * r)))
    return math.sqrt(sum(squares) / len(squares))
