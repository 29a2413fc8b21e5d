"""Phase, once: 2π, wrapping and phasors formed from reduced float64 phases.

Convention (used everywhere in rtsar): a wrapped phase lies in [-π, π).  Large phases (the
optical carrier 2π f0 τ reaches 1e9 rad) are formed in float64 and reduced modulo 2π before any
exponential or cast to single precision (docs/pages/reference/conventions.md).
"""

from __future__ import annotations

import math

import numpy as np

TWO_PI = 2.0 * math.pi


def wrap(phase_rad) -> np.ndarray:
    """Phase reduced to [-π, π) (float64)."""
    return (np.asarray(phase_rad, dtype=np.float64) + math.pi) % TWO_PI - math.pi


def phasor(phase_rad) -> np.ndarray:
    """exp(i·phase) with the phase reduced modulo 2π in float64 first (complex128)."""
    return np.exp(1j * np.mod(np.asarray(phase_rad, dtype=np.float64), TWO_PI))
