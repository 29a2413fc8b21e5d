"""How the pipeline runs (its threads, queues, batches, workers); the processing is the Config."""

from __future__ import annotations

from dataclasses import dataclass

STAGE_LAYOUTS = ("split", "fused", "overlapped")
# Stages fed as fast as they go (a recording replayed at "max") take up to this many
# micro-batches at a time; a stream with a rate, one (its latency counts, and the granularity
# a live run chooses caps its calls at one).  Larger calls come only while behind, and a
# replay at "max" is always behind: it wants throughput.  psaltis-max's
# nonuniform pipeline at max rate, 2-core Xeon, ten alternated rounds, 9 of 10 faster with
# takes of 256 than of 64 pulses, mean 18.6 against 17.0 thousand pulses/s, while the
# correlator alone was no faster at pushes of 256 (fewer lens launches and hand-offs).
REPLAY_TAKE_BATCHES = 4


@dataclass
class PipelineSettings:
    """How the pipeline runs (the processing itself is the Config)."""

    lens_backend: str = "auto"
    device: str | None = None
    stages: str = "split"  # split: lens and CCD threads; fused, overlapped: one (STAGE_LAYOUTS)
    strip_lines: int = 16  # lines per published strip
    strip_most_lines: int = 0  # > strip_lines: lines waiting go out together, up to this many
    strip_deadline_s: float | None = None  # a partial strip goes out once a line waited this long
    lens_align: int = 0  # > 1: the lens waits for the pulses that complete a block of this many
    lens_hold_s: float = 0.0  # … at most this long (the granularity's: 2 blocks at the run's rate)
    lens_align_from: int = 0  # … counted from this pulse (a grown block: rtsar.stream.growth)
    lens_cpu_below: int = 0  # > 1: an OpenCL lens's calls of fewer pulses on SciPy's FFT
    grow_blocks: tuple = ()  # the correlator's block and larger ones to grow to when behind …
    grow_rate_hz: float = 0.0  # … block periods counted at this rate (rtsar.stream.growth)
    queue_pulses: int = 0  # capacity of each queue (0: 8 apertures of pulses)
    max_batch: int = 0  # most pulses per lens launch / CCD push (0: take_cap's default)
    max_gap_pulses: int = 0  # longest zero-filled gap; beyond it a restart (0: one aperture)
    deadline: bool = False  # the run has a deadline: once the source ends, nobody is waited on
    swath_workers: int = 0  # > 0: lens + CCD in that many processes, a range slice each (swath)
    swath_spawn: bool = True  # start them here (False: they connect from elsewhere)
    swath_bind: str = "127.0.0.1"  # HOST or tcp://HOST:PORT: where the coordinator listens

    def take_cap(self, micro_batch: int, paced: bool) -> int:
        """Most pulses a stage takes at a time: ``max_batch`` where set; else the config's
        micro-batch for shots that come at a rate (an instrument, a paced replay: their
        latency), REPLAY_TAKE_BATCHES of them for a replay as fast as it goes (throughput)."""
        return self.max_batch or micro_batch * (1 if paced else REPLAY_TAKE_BATCHES)

    def __post_init__(self):
        if self.stages not in STAGE_LAYOUTS:
            raise ValueError(f"stages must be one of {STAGE_LAYOUTS}, got {self.stages!r}")
        if self.strip_lines < 1:
            raise ValueError("strip_lines must be >= 1")
        if self.strip_deadline_s is not None and not self.strip_deadline_s >= 0:
            raise ValueError(f"strip_deadline_s must be >= 0, got {self.strip_deadline_s!r}")
        if self.swath_workers and self.stages != "split":
            raise ValueError(f"--swath-workers runs lens and CCD in the workers: not {self.stages}")
