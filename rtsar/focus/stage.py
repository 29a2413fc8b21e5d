"""The interface every correction stage of the stream implements.

A stage runs either on the raw shots between ingest and the AO lens (``domain = "raw"``: it sees
the auxiliary channels, keeps the pulse count) or on the range-compressed pulses between the lens
and the shifting CCD (``domain = "lines"``: it may hold pulses back, ``latency_pulses`` of them,
and gives them back at ``flush``).  Pulse order is always kept.  Each stage counts what it could
not do; ``counter_values`` reports the counts (rtsar.focus.chain prefixes them with the stage's
name for the strip headers and the status line).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np

DOMAINS = ("raw", "lines")


class CorrectionStage(ABC):
    """One phase or chirp correction in the stream (see the module docstring)."""

    domain: ClassVar[str]  # one of DOMAINS
    channels: tuple[str, ...] = ()  # the auxiliary channels it reads (raw stages)
    counter_names: ClassVar[tuple[str, ...]] = ()  # integer attributes reported as counters

    @property
    def latency_pulses(self) -> int:
        """Pulses the stage holds back before releasing a pulse (0: per-pulse stages)."""
        return 0

    @abstractmethod
    def process(self, samples: np.ndarray, aux: dict) -> np.ndarray:
        """Correct a micro-batch [pulse, sample or bin]; return the pulses released."""

    def flush(self) -> np.ndarray | None:
        """At the end of a stream: the pulses still held (None: the stage holds none)."""
        return None

    def counter_values(self) -> dict[str, int]:
        """The stage's counters by name (default: its ``counter_names`` attributes)."""
        return {name: int(getattr(self, name)) for name in self.counter_names}
