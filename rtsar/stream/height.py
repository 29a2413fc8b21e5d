"""Interferometric 3D in the stream: the second receiver focused in step with the main one.

Each auxiliary channel the height stage reads (``stage.channels``: the second receiver of
interferometric SAL, Zhao 2014 channels 3-4; or the S1, S2 channels of spatial amplitude
modulation, the INO 3D patent) goes through its own AO lens and shifting CCD, with the main
channel's configuration, pulse for pulse; the finished line blocks feed the stage
(rtsar.topo.stream.HeightStripStage, rtsar.topo.sam3d_strips.SamHeightStripStage), whose height
strips are published beside the image strips.
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
    """The auxiliary receivers' lenses and CCDs (one per channel the stage reads: ``rx1`` for
    InSAL, ``sam_s1``/``sam_s2`` for SAM) and the height strip stage."""

    def __init__(
        self,
        config: Config,
        stage,
        lens_backend: str,
        device: str | None,
        start_along_track_m: float,
    ):
        self.stage = stage  # rtsar.topo.stream.HeightStripStage or rtsar.topo.sam3d_strips.…
        self.channels = tuple(stage.channels)
        self.engines = {
            name: StreamProcessor(config, lens_backend, device, start_along_track_m)
            for name in self.channels
        }

    def compress(self, block: PulseBlock) -> dict:
        """Range lines of each auxiliary receiver for the pulses of ``block`` (aux entries)."""
        missing = [name for name in self.channels if name not in block.aux]
        if missing:
            raise ValueError(
                f"height strips need the auxiliary channel(s) {', '.join(missing)}; the source "
                f"delivers {sorted(block.aux) or 'none'}"
            )
        zero = bool(block.flagged.all())
        return {
            f"lines:{name}": engine.compress(block.aux[name], zero=zero)
            for name, engine in self.engines.items()
        }

    def correlate(self, main_lines: np.ndarray, aux: dict) -> HeightBatch | None:
        """The receivers' CCDs in step with the main one → the height strips finished."""
        lines = [self.engines[n].correlator.push(aux[f"lines:{n}"]) for n in self.channels]
        return self._batch(self.stage.process(main_lines, *lines))

    def flush(self, main_lines: np.ndarray) -> HeightBatch | None:
        """At the end of a stream: the CCDs' last lines and every height strip still held."""
        lines = [self.engines[n].correlator.flush() for n in self.channels]
        strips = self.stage.process(main_lines, *lines)
        return self._batch(strips + self.stage.flush())

    @staticmethod
    def _batch(strips: list) -> HeightBatch | None:
        return HeightBatch(strips) if strips else None
