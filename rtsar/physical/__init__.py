"""Physical mode: the processor as optical hardware rather than ideal arithmetic.

Psaltis & Wagner 1981: an AO cell of finite bandwidth and time aperture whose diffraction is
linear only for weak drive (``aocell``); a CCD that detects intensity on a bias with a spatial
carrier through a real, non-negative mask, with a full well, noise, quantization, fixed pattern
and blooming (``carrier`` derives it, ``register`` and ``detector`` emulate it); and the report
that regenerates the paper's Table 1 from the emulation (``table1``).  Every degradation is an
opt-in named effect (``settings``).
"""

from .aocell import AOCell
from .carrier import pulses_integrated, range_cells
from .detector import PhysicalCCD
from .settings import CARRIERS, PhysicalSettings, paper_ccd, settings_from_dict

__all__ = [
    "AOCell",
    "CARRIERS",
    "PhysicalCCD",
    "PhysicalSettings",
    "paper_ccd",
    "pulses_integrated",
    "range_cells",
    "settings_from_dict",
]
