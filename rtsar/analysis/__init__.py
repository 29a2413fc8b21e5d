"""Measures shared by the tests and the reports: point-target analysis, image and phase errors,
timing.  ``acceptance`` (point targets focused by the engine against theory) is imported on its
own: it runs the simulator and the engine.
"""

from .cut import CutMetrics, analyse_cut
from .image_error import relative_rms
from .interpolation import upsample
from .point_target import PointTargetReport, analyse_point_target
from .theory import theoretical_irw_factor, theoretical_pslr_db

__all__ = [
    "CutMetrics",
    "PointTargetReport",
    "analyse_cut",
    "analyse_point_target",
    "relative_rms",
    "theoretical_irw_factor",
    "theoretical_pslr_db",
    "upsample",
]
