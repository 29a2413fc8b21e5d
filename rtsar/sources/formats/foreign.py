"""A recording read from another format (CPHD, SigMF), offered as rtsar.sinks.io.Recording is:
the same attributes and methods, so ``process`` and ``replay`` take it unchanged."""

from __future__ import annotations

import datetime
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ...params import Config
from ...scene.model import Scene, recorded_scene


@dataclass
class ForeignRecording:
    """Shots [pulse, sample] (any array-like that slices into complex64 blocks), per-pulse
    ``pulse_index`` and ``time_s``, auxiliary ``channels`` (name → array-like), the
    configuration and scene; ``closer`` releases the underlying file."""

    path: Path
    config: Config
    scene: dict
    pulses: int
    start_along_track_m: float
    shots: object
    pulse_index: np.ndarray
    time_s: np.ndarray
    channels: dict = field(default_factory=dict)
    position_m: np.ndarray | None = None
    closer: object = None
    collection_start: datetime.datetime | None = None  # UTC of time_s = 0 (None: unknown)
    notes: list = field(default_factory=list)  # one line each the reader has to say (warnings)
    attrs: dict = field(default_factory=dict)  # provenance kept with it (an imported block's)

    def batches(self, size: int) -> Iterator[np.ndarray]:
        for i in range(0, self.pulses, size):
            yield np.asarray(self.shots[i : i + size], np.complex64)

    def batches_with_aux(self, size: int, names=()) -> Iterator[tuple[np.ndarray, dict]]:
        for i in range(0, self.pulses, size):
            aux = {n: np.asarray(self.channels[n][i : i + size], np.complex64) for n in names}
            yield np.asarray(self.shots[i : i + size], np.complex64), aux

    def scene_object(self) -> Scene | None:
        return recorded_scene(self.scene, self.path)

    def close(self) -> None:
        if self.closer is not None:
            self.closer()
            self.closer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def telemetry_problem(cfg: Config, pulse_index, along_track_m) -> str | None:
    """What is wrong with a recording's pulse numbers and positions, None if nothing: the
    numbers increase, the positions follow the configured step (the image's azimuth axis
    depends on it), so no shot is missing, and the numbers then advance by one (a skip with a
    regular platform contradicts itself: process would read the file as gapless and replay
    would zero-fill the skip, two images of one file).  Every recording reader checks this."""
    # int64: an unsigned index that steps back would wrap (a "jump" of 2**32 - 1).
    pulse_index = np.asarray(pulse_index).astype(np.int64)
    along_track_m = np.asarray(along_track_m)
    if len(pulse_index) < 2:
        return None
    counted = np.diff(pulse_index)
    if not np.all(counted > 0):
        return "pulse_index must increase from shot to shot"
    steps = np.diff(along_track_m)
    if not np.allclose(steps, cfg.geometry.along_track_step_m, rtol=1e-6, atol=1e-9):
        return "along_track_m does not advance by the configured step"
    skips = np.flatnonzero(counted != 1)
    if len(skips):
        k = int(skips[0])
        jump = int(counted[k])
        return (
            f"pulse_index jumps by {jump} after shot {k} while along_track_m advances by one "
            "step: the file contradicts itself (a dropped shot moves both)"
        )
    return None
