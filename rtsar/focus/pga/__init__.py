"""Phase gradient autofocus (Crouch 2012, eqs. 4.14-4.17) for the strip-map stream.

``estimator`` (one block), ``blocks`` (the stream's block layout and stitching), ``stream`` (the
correction stage), ``reference`` (the float64 batch version on a recording).
"""

from .estimator import (
    ESTIMATED,
    REASONS,
    BlockReport,
    PGASettings,
    deramp_cycles,
    estimate_block,
    remove_linear,
)
from .reference import pga_batch
from .stream import PGACounters, PGAStage

__all__ = [
    "ESTIMATED",
    "REASONS",
    "BlockReport",
    "PGACounters",
    "PGASettings",
    "PGAStage",
    "deramp_cycles",
    "estimate_block",
    "pga_batch",
    "remove_linear",
]
