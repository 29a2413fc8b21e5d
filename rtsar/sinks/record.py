"""Reassemble published strips into an image file (``rtsar subscribe -o``, ``rtsar run -o``).

Strips are written as they come (bounded memory).  A strip that never arrived leaves zero lines
in the image; they are counted (``missing_lines``) and listed in the ``missing_line_runs``
attribute, never hidden — up to ``max_fill_bytes`` of zeros per gap.  A longer jump of
``first_line`` (a publisher's bug or a hostile one) is held until the next strip: if that one
continues from it, the jump is real, not filled but listed in ``line_jumps`` (the ``azimuth_m``
dataset keeps every written line's true position); if not, the strip is dropped and counted in
``stray_strips``, and the image goes on.  Strips of another stream (a restarted or second
publisher) are counted in ``other_stream_strips``, never written.  A strip that does not fit
the image (other range axis or line spacing than the first strip's, a configuration that does
not parse) is not written but counted in ``inconsistent_strips``.  Lines whose aperture held a
zero-filled pulse are listed in ``flagged_line_runs``.  The image starts at the first strip
received (a late subscriber's image starts late; the ``first_line`` attribute says where).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..params import config_from_dict
from ..sources.formats.timebase import format_utc, parse_utc
from ..stream.strips import StreamInfo, Strip, StripSink, join_run
from .h5_output import WriteFailed
from .image_file import ImageWriter
from .name_claim import NameClaim
from .wire import height_header, strip_header

MAX_FILL_BYTES = 64 << 20  # the most zeros written for one gap of missing lines


def collection_attrs(rec) -> dict:
    """The image attributes a recording passes on: its collection start (none where unknown),
    the SICD's Timeline/CollectStart (rtsar.sources.formats.timebase); and, for a real
    instrument's echoes (``rtsar import``), the instrument file they came with
    (``instrument_file``: seen through the instrument's own antenna beam, which ``rtsar
    measure`` then holds the image to)."""
    start = getattr(rec, "collection_start", None)
    out = {} if start is None else {"collection_start_utc": format_utc(start)}
    instrument = getattr(rec, "attrs", {}).get("instrument_file")
    return out | ({"instrument_file": str(instrument)} if instrument else {})


def collection_from_header(header: dict) -> dict:
    """The image attribute of a strip header's ``collection_start_utc`` (none where absent or
    not an ISO 8601 time: a header is never trusted to write a false time)."""
    text = header.get("collection_start_utc")
    try:
        return {"collection_start_utc": format_utc(parse_utc(text))}
    except ValueError:
        return {}


def processing_attrs(
    correlator: str, corrections=(), physical: dict | None = None, specs=()
) -> dict:
    """The image attributes that say how it was focused: ``correlator``; ``corrections`` (the
    stages, comma-separated, "" for none); ``correction_specs`` (JSON list of the
    ``--correct`` values as given, keys and all, in the order the stages run; "" for none);
    ``physical`` (JSON of the physical mode's settings where the emulated CCD ran in place of
    the correlator, else "")."""
    return {
        "correlator": correlator,
        "corrections": ",".join(corrections),
        "correction_specs": json.dumps(list(specs)) if specs else "",
        "physical": json.dumps(physical) if physical else "",
    }


def instrument_from_header(header: dict) -> dict:
    """The image attribute of a strip header's ``instrument_file`` (a real instrument's echoes:
    rtsar measure then holds the image to its beam); none where absent or empty."""
    name = header.get("instrument_file")
    return {"instrument_file": name} if isinstance(name, str) and name else {}


def processing_from_header(header: dict) -> dict:
    """lens + processing_attrs from a strip header's ``processing`` (rtsar.sinks.wire), what a
    subscriber's image records of how the strips were made; {} where it is absent or not of
    the types the publisher writes (never trusted further)."""
    p = header.get("processing")
    if not isinstance(p, dict):
        return {}
    lens, correlator, names, physical = (
        p.get(k) for k in ("lens", "correlator", "corrections", "physical")
    )
    specs = p.get("correction_specs", [])  # (absent from an older publisher's headers)
    if not (
        isinstance(lens, str)
        and isinstance(correlator, str)
        and isinstance(names, list)
        and all(isinstance(n, str) for n in names)
        and (physical is None or isinstance(physical, dict))
        and isinstance(specs, list)
        and all(isinstance(s, str) for s in specs)
    ):
        return {}
    return {"lens": lens, **processing_attrs(correlator, names, physical, specs)}


class StripRecorder:
    """Append strips (wire header + lines) to an image file, filling and counting gaps."""

    def __init__(self, path: str | Path, source: str, max_fill_bytes: int = MAX_FILL_BYTES):
        self.path = Path(path)
        self.source = source
        # The name is claimed now, when the run starts (a second live writer of it is refused
        # before any work), and handed to the file's writer at the first strip.
        self._claim: NameClaim | None = NameClaim(self.path)
        self.max_fill_bytes = int(max_fill_bytes)
        self.writer: ImageWriter | None = None
        self.stream_id: str | None = None
        self.first_line = 0
        self.next_line = 0
        self.lines_written = 0
        self.missing_lines = 0
        self.missing_runs: list[list[int]] = []
        self.line_jumps: list[list[int]] = []
        self.flagged_runs: list[list[int]] = []
        self.overlapping_strips = 0
        self.inconsistent_strips = 0
        self.height_strips = 0
        self.other_stream_strips = 0  # strips of another stream_id: counted, not written
        self.stray_strips = 0  # a far jump the next strip did not confirm: dropped
        self._candidate: tuple | None = None  # (header, lines) of an unconfirmed far jump
        self.height_kind = ""
        self.inconsistent_heights = 0
        self._early_heights: list = []  # height strips that came before the first image strip
        self.counters: dict = {}
        self.processing: dict = {}  # how the publisher focused the strips (first strip's header)

    def _axes(self, header: dict) -> tuple:
        return (
            header["range_bins"],
            header["range_first_m"],
            header["range_step_m"],
            header["azimuth_step_m"],
        )

    def add_strip(self, header: dict, lines: np.ndarray) -> None:
        """Write one strip (its header checked by rtsar.sinks.wire.check_strip_header)."""
        first = int(header["first_line"])
        if self.writer is None:
            try:
                cfg = config_from_dict(header["config"])
            except ValueError:
                self.inconsistent_strips += 1
                return
            nr = int(header["range_bins"])
            range_m = header["range_first_m"] + header["range_step_m"] * np.arange(nr)
            claim, self._claim = self._claim, None  # the writer releases it now
            self.writer = ImageWriter(
                self.path,
                cfg,
                range_m,
                crash_safe=True,
                claim=claim,
                heights=bool(header.get("height_strips", False)),
                source=self.source,
                first_line=first,
                **collection_from_header(header),
                **instrument_from_header(header),
            )
            self.stream_id = header.get("stream_id")
            self.processing = processing_from_header(header)
            kind = header.get("height_kind")
            self.height_kind = kind if isinstance(kind, str) and kind.isidentifier() else "unknown"
            self.first_line = self.next_line = first
            self._axes0 = self._axes(header)
            self._az0 = header["azimuth_first_m"] - first * header["azimuth_step_m"]
            self._daz = header["azimuth_step_m"]
            early, self._early_heights = self._early_heights, []
            for args in early:
                self.add_height(*args)
        if header.get("stream_id") != self.stream_id:
            self.other_stream_strips += 1  # a restarted or second publisher: not this image's
            return
        if self._axes(header) != self._axes0 or lines.shape[1] != self._axes0[0]:
            self.inconsistent_strips += 1
            return
        if self._candidate is not None:  # a jump far ahead: did the stream really move?
            held, self._candidate = self._candidate, None
            if first == int(held[0]["first_line"]) + len(held[1]):
                self._accept(*held)  # confirmed: this strip continues from it
            else:
                self.stray_strips += 1  # a number out of thin air: dropped
        first_gap = first - self.next_line
        if first_gap * lines.shape[1] * 8 > self.max_fill_bytes:
            self._candidate = (header, lines)  # held until the next strip says what it was
            return
        self._accept(header, lines)

    def _accept(self, header: dict, lines: np.ndarray) -> None:
        first = int(header["first_line"])
        if first < self.next_line:  # already written (should not happen on one connection)
            self.overlapping_strips += 1
            return
        if first > self.next_line:
            gap = first - self.next_line
            if gap * lines.shape[1] * 8 <= self.max_fill_bytes:
                self.missing_runs.append([self.next_line, gap])
                self.missing_lines += gap
                self._write(np.zeros((gap, lines.shape[1]), np.complex64))
            else:  # not filled: listed, the lines after it keep their true positions
                self.line_jumps.append([self.next_line, gap])
                self.next_line = first
        for first, count in header.get("flagged_lines", []):  # runs across strips joined
            join_run(self.flagged_runs, first, count)
        self.counters = header.get("counters", self.counters)
        self._write(lines)

    def add_height(
        self, header: dict, height_m: np.ndarray, valid: np.ndarray, coherence=None
    ) -> None:
        """Write one height strip (rtsar.sinks.wire.height_header) beside the image's lines;
        ``coherence`` None for a version 1 message (no coherence frame)."""
        w = self.writer
        if w is None:  # heights can overtake the first image strip: held until it comes
            held = sum(h.nbytes * 3 for _, h, _, _ in self._early_heights)
            if held + height_m.nbytes * 3 <= self.max_fill_bytes:
                self._early_heights.append((header, height_m, valid, coherence))
            else:
                self.inconsistent_heights += 1
            return
        if not w.has_heights or header.get("stream_id") != self.stream_id:
            self.inconsistent_heights += 1  # not announced, or another stream's
            return
        shape_ok = height_m.shape == valid.shape and height_m.shape[1] == self._axes0[0]
        if not shape_ok or (coherence is not None and coherence.shape != height_m.shape):
            self.inconsistent_heights += 1
            return
        lines = int(header["first_line"]) + np.arange(len(height_m))
        keep = lines >= self.first_line  # a late subscriber: lines before its image
        skipped = np.zeros(len(lines), np.int64)
        for start, gap in self.line_jumps:  # lines inside a jump have no image row
            keep &= ~((lines >= start) & (lines < start + gap))
            skipped += np.where(lines >= start + gap, gap, 0)
        rows = (lines - self.first_line - skipped)[keep]
        if not len(rows):
            self.inconsistent_heights += 1
            return
        limit = w.lines_handed + self.max_fill_bytes // 8 // height_m.shape[1]
        if rows[-1] >= limit:  # far beyond the image's rows: not obeyed
            self.inconsistent_heights += 1
            return
        coherence = None if coherence is None else coherence[keep]
        w.write_heights(int(rows[0]), height_m[keep], valid[keep], coherence)
        self.height_strips += 1

    def flush_if_due(self) -> None:
        """Flush what is written when it is due (a stream that went quiet keeps no unflushed
        lines for longer than the flush period)."""
        if self.writer is not None:
            self.writer.flush_if_due()

    def flush(self) -> None:
        """Every line written so far to the disk (crash-safe: readable after a kill)."""
        if self.writer is not None:
            self.writer.flush()

    def release_claim(self) -> None:
        """Give up the claim on the name if no writer took it (no strip came)."""
        if self._claim is not None:
            self._claim.release()
            self._claim = None

    def _write(self, lines: np.ndarray) -> None:
        j = self.next_line + np.arange(len(lines))
        self.writer.write(lines, self._az0 + j * self._daz)
        self.next_line += len(lines)
        self.lines_written += len(lines)

    def finish(self, final_counters: dict | None = None, **attrs) -> int:
        """Close the file (attributes: counters, gaps, flags); return the number of lines."""
        self.release_claim()
        if self.writer is None:
            return 0
        if self._candidate is not None:  # the stream ended on it: kept, as ingest keeps its last
            held, self._candidate = self._candidate, None
            self._accept(*held)
        counters = final_counters or self.counters
        self.writer.close(
            counters=json.dumps(counters),
            nonfinite_pulses=int(counters.get("nonfinite_pulses", 0)),
            missing_lines=self.missing_lines,
            missing_line_runs=json.dumps(self.missing_runs),
            line_jumps=json.dumps(self.line_jumps),
            inconsistent_strips=self.inconsistent_strips,
            other_stream_strips=self.other_stream_strips,
            stray_strips=self.stray_strips,
            flagged_line_runs=json.dumps(self.flagged_runs),
            **(
                {
                    "height_strips": self.height_strips,
                    "inconsistent_heights": self.inconsistent_heights,
                    "height_method": self.height_kind,
                }
                if self.writer.has_heights
                else {}
            ),
            **{**self.processing, **attrs},
        )
        return self.writer.lines


class ImageFileSink(StripSink):
    """Pipeline sink: record every strip, in process (lossless), to an image file.

    A write the disk refuses (full, quota) ends this file, not the run: said once through
    ``notify``, kept in ``failure``; the other outputs go on, and ``image_lines_lost`` counts
    the lines handed to it that the file is not sure to hold.  ``settle(stats)``, where given,
    is called at the end once every line is on disk and before the file is closed: it returns
    counters of outputs that end first (a recording's final ones), stored in place of the
    run's."""

    ends_first = True  # its lines on disk before a slow recording is waited for

    def __init__(self, path: str | Path, source: str, notify=None, settle=None):
        self.recorder = StripRecorder(path, source)
        self.lines = 0
        self.notify = notify
        self.settle = settle
        self.failure: WriteFailed | None = None
        self.lines_handed = 0

    def _guarded(self, work, tell: bool = True) -> None:
        """``work`` on the file unless it failed; a failure ends it (told at once if ``tell``;
        at the end, the run's report tells it)."""
        if self.failure is not None:
            return
        try:
            work()
        except WriteFailed as exc:
            self.failure = exc
            self.recorder.release_claim()
            if tell and self.notify is not None:
                self.notify(f"rtsar: -o {self.recorder.path} stopped: {exc}; the run goes on")

    def counters(self) -> dict:
        if self.failure is None:
            return {}
        writer = self.recorder.writer
        saved = 0 if writer is None else writer.saved_lines
        return {"image_lines_lost": max(0, self.lines_handed - saved)}

    def strip(self, strip: Strip, info: StreamInfo) -> None:
        self.lines_handed += len(strip.lines)
        header = strip_header(strip, info)
        self._guarded(lambda: self.recorder.add_strip(header, strip.lines))

    def stats(self, stats: dict, info: StreamInfo) -> None:  # periodic: flush a quiet stream
        self._guarded(self.recorder.flush_if_due)

    def height(self, strip, seq: int, info: StreamInfo) -> None:
        self._guarded(
            lambda: self.recorder.add_height(
                height_header(strip, seq, info), strip.height_m, strip.valid, strip.coherence
            )
        )

    def end(self, stats: dict, info: StreamInfo) -> None:
        counters = dict(stats["counters"])
        self._guarded(self.recorder.flush, tell=False)  # on disk before waiting on others
        if self.settle is not None:
            counters.update(self.settle(stats))
        counters.update(self.counters())

        def close() -> None:
            self.lines = self.recorder.finish(
                counters,
                lens=info.lens_backend,
                stopped_by=stats.get("stopped_by", ""),  # a signal: the source cut short
                **processing_attrs(
                    info.config.processor.correlator,
                    info.corrections,
                    info.physical,
                    info.correction_specs,
                ),
            )

        self._guarded(close, tell=False)
