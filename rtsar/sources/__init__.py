"""Where shots come from: the simulator (paced), a recording (replay), a serial instrument."""

from .base import ShotBatch, Source

__all__ = ["ShotBatch", "Source"]
