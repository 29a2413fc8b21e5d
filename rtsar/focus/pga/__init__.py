"""Phase gradient autofocus (Crouch 2012, eqs. 4.14-4.17) for the strip-map stream.

``estimator`` (one block), ``migration`` (points that walk in range inside a block), ``blocks``
(the stream's block layout and stitching), ``stream`` (the correction stage), ``reference`` (the
float64 batch version on a recording).
"""

from .doppler import CentroidLags, antenna_coherence, centroid_lags, centroid_std_rad
from .estimator import (
    COULD_NOT_ESTIMATE,
    ESTIMATED,
    NOTHING_TO_CORRECT,
    REASONS,
    BlockReport,
    PGASettings,
    deramp_cycles,
    estimate_block,
    remove_linear,
)
from .migration import curvature_m, migration_corrected, row_half_width
from .reference import pga_batch
from .stream import PGACounters, PGAStage

__all__ = [
    "COULD_NOT_ESTIMATE",
    "ESTIMATED",
    "NOTHING_TO_CORRECT",
    "REASONS",
    "BlockReport",
    "CentroidLags",
    "PGACounters",
    "PGASettings",
    "PGAStage",
    "antenna_coherence",
    "centroid_lags",
    "centroid_std_rad",
    "curvature_m",
    "deramp_cycles",
    "migration_corrected",
    "row_half_width",
    "estimate_block",
    "pga_batch",
    "remove_linear",
]
