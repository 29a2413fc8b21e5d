"""The files a live run writes: its image (``-o IMG.h5``) and its raw shots (``--record
RAW.h5``), set up before the stream starts (their names claimed: a name another process is
writing is refused before any work) and reported at its end.

Each fails on its own: a disk that refuses the image ends the image, not the recording, nor
the run (rtsar.sinks.record.ImageFileSink), and the other way round (rtsar.sinks.raw_record).
The image is closed after the recording has ended (or been given up on: rtsar.sinks.raw_record
.HURRY_S after a stop), so the recording's counters it stores are final."""

from __future__ import annotations

from ..params import Config
from ..sinks.io import check_writable
from ..sinks.raw_record import ShotRecorder
from ..sinks.record import ImageFileSink


class LiveOutputs:
    """The image sink and the raw recorder of a run (either may be absent).  ``notify``: the
    run's one-line messages (a recording whose disk failed)."""

    def __init__(
        self,
        config: Config,
        source: str,
        output: str | None = None,
        record: str | None = None,
        start_along_track_m: float = 0.0,
        scene: dict | None = None,
        notify=None,
    ):
        self.output, self.record = output, record
        for path in (output, record):
            if path:
                check_writable(path)  # before anything starts, not at the first strip
        self.image: ImageFileSink | None = None
        self.raw: ShotRecorder | None = None
        try:
            if output:
                self.image = ImageFileSink(output, source, notify=notify)
            if record:
                self.raw = ShotRecorder(
                    record, config, scene, source, start_along_track_m, notify=notify
                )
                if self.image is not None:
                    self.image.settle = self._end_recording
        except BaseException:  # (the second name refused: the first one's claim goes too)
            self.release()
            raise

    def _end_recording(self, stats: dict) -> dict:
        """The recording ended (its end comes here, before the image's close): its counters."""
        self.raw.finish(stats.get("counters", {}))
        return self.raw.counters()

    def counters(self) -> dict:
        """The outputs' final counters (after the run's end), for its summary."""
        return {k: v for sink in self.sinks for k, v in sink.counters().items()}

    @property
    def sinks(self) -> list:
        return [s for s in (self.image, self.raw) if s is not None]

    def release(self) -> None:
        """At the end, however the run ended: claims no writer took are released, a recording
        whose end never came is closed (marked incomplete)."""
        if self.image is not None:
            self.image.recorder.release_claim()
        if self.raw is not None:
            self.raw.close()

    def report(self, counters: dict, config: Config, stream, err) -> int:
        """Say what was written; the exit status it calls for (0, 1 nothing came to write, 2
        a write the disk refused)."""
        status = 0
        if self.image is not None:
            if self.image.failure is not None:
                print(f"rtsar: error: {self.image.failure}", file=err)
                status = 2
            elif self.image.lines:
                print(f"wrote {self.output}: {self.image.lines} lines", file=stream)
            else:
                wrong = counters.get("wrong_length")
                print(
                    f"rtsar: no image written to {self.output}: no line was focused"
                    + (
                        f" ({wrong} frames of another shape than the configuration's "
                        f"{config.waveform.samples_per_shot} samples per shot (and the channel "
                        "map's channels): check --preset/--scene/--channel-map)"
                        if wrong
                        else ""
                    ),
                    file=err,
                )
                status = 1
        raw = self.raw
        if raw is not None:
            if raw.failure is not None:
                print(f"rtsar: error: {raw.failure}", file=err)
                print(_lost_recording(self.record, raw), file=stream)
                status = 2
            elif raw.written:
                missed = (
                    f"; {raw.dropped} not recorded (record_dropped: the disk fell behind; "
                    "marked in pulse_flags, zero rows)"
                    if raw.dropped
                    else ""
                )
                print(
                    f"wrote {self.record}: {raw.written} shots{missed}; `rtsar process "
                    f"{self.record}` or `rtsar replay {self.record}` focuses it again",
                    file=stream,
                )
            else:
                print(f"rtsar: no recording written to {self.record}: no shot came", file=err)
                status = max(status, 1)
        return status


def _lost_recording(path: str, raw: ShotRecorder) -> str:
    """What a recording that failed holds, in counts (rtsar.sinks.raw_record)."""
    unsure = (
        f"; {raw.unconfirmed} handed over and never confirmed (record_unconfirmed: the file "
        "may lack them)"
        if raw.unconfirmed
        else ""
    )
    return (
        f"{path}: {raw.written} shots confirmed on disk (record_written"
        + (", at least" if raw.unconfirmed else "")
        + f"), {raw.dropped} not recorded (record_dropped){unsure}"
    )
