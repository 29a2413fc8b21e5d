"""Interferometric 3D in the stream: the second receiver focused in step with the main one.

The auxiliary channel of the second receiver (Zhao 2014, channels 3-4; rtsar.instrument
SECOND_RECEIVER) goes through its own AO lens and shifting CCD, with the main channel's
configuration, pulse for pulse; each pair of finished line blocks feeds an
rtsar.topo.stream.HeightStripStage, whose height strips are published beside the image strips.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params import Config
from .engine import StreamProcessor
from .ingest import PulseBlock


@dataclass
class HeightBatch:
    """Height strips travelling to the publisher with the image lines (no queue units)."""

    strips: list

    def __len__(self) -> int:
        return 0


class HeightChannel:
    """The second receiver's lens and CCD and the height strip stage."""

    def __init__(
        self,
        config: Config,
        stage,
        channel: str,
        lens_backend: str,
        device: str | None,
        start_along_track_m: float,
    ):
        self.stage = stage  # rtsar.topo.stream.HeightStripStage
        self.channel = channel
        self.engine = StreamProcessor(config, lens_backend, device, start_along_track_m)

    def compress(self, block: PulseBlock) -> np.ndarray:
        """Range lines of the second receiver for the pulses of ``block``."""
        raw = block.aux.get(self.channel)
        if raw is None:
            raise ValueError(
                f"height strips need the auxiliary channel {self.channel!r}; the source "
                f"delivers {sorted(block.aux) or 'none'}"
            )
        return self.engine.compress(raw, zero=bool(block.flagged.all()))

    def correlate(self, main_lines: np.ndarray, lines2: np.ndarray) -> HeightBatch | None:
        """The second receiver's CCD in step with the main one → the height strips finished."""
        return self._batch(self.stage.process(main_lines, self.engine.correlator.push(lines2)))

    def flush(self, main_lines: np.ndarray) -> HeightBatch | None:
        """At the end of a stream: the CCD's last lines and every height strip still held."""
        strips = self.stage.process(main_lines, self.engine.correlator.flush())
        return self._batch(strips + self.stage.flush())

    @staticmethod
    def _batch(strips: list) -> HeightBatch | None:
        return HeightBatch(strips) if strips else None
