"""Reassemble published strips into an image file (``rtsar subscribe -o``, ``rtsar run -o``).

Strips are written as they come (bounded memory).  A strip that never arrived leaves zero lines
in the image; they are counted (``missing_lines``) and listed in the ``missing_line_runs``
attribute, never hidden.  Lines whose aperture held a zero-filled pulse are listed in
``flagged_line_runs``.  The image starts at the first strip received (a late subscriber's image
starts late; the ``first_line`` attribute says where).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..params import config_from_dict
from ..stream.strips import StreamInfo, Strip, StripSink
from .io import ImageWriter
from .wire import strip_header


class StripRecorder:
    """Append strips (wire header + lines) to an image file, filling and counting gaps."""

    def __init__(self, path: str | Path, source: str):
        self.path = Path(path)
        self.source = source
        self.writer: ImageWriter | None = None
        self.stream_id: str | None = None
        self.first_line = 0
        self.next_line = 0
        self.missing_lines = 0
        self.missing_runs: list[list[int]] = []
        self.flagged_runs: list[list[int]] = []
        self.overlapping_strips = 0
        self.counters: dict = {}

    def add_strip(self, header: dict, lines: np.ndarray) -> None:
        first = int(header["first_line"])
        if self.writer is None:
            cfg = config_from_dict(header["config"])
            nr = int(header["range_bins"])
            range_m = header["range_first_m"] + header["range_step_m"] * np.arange(nr)
            self.writer = ImageWriter(self.path, cfg, range_m, source=self.source, first_line=first)
            self.stream_id = header.get("stream_id")
            self.first_line = self.next_line = first
            self._az0 = header["azimuth_first_m"] - first * header["azimuth_step_m"]
            self._daz = header["azimuth_step_m"]
        if header.get("stream_id") != self.stream_id:
            raise ValueError("a new stream started (publisher restarted); this image is closed")
        if first < self.next_line:  # already written (should not happen on one connection)
            self.overlapping_strips += 1
            return
        if first > self.next_line:
            gap = first - self.next_line
            self.missing_runs.append([self.next_line, gap])
            self.missing_lines += gap
            self._write(np.zeros((gap, lines.shape[1]), np.complex64))
        self.flagged_runs.extend(list(r) for r in header.get("flagged_lines", []))
        self.counters = header.get("counters", self.counters)
        self._write(lines)

    def _write(self, lines: np.ndarray) -> None:
        j = self.next_line + np.arange(len(lines))
        self.writer.write(lines, self._az0 + j * self._daz)
        self.next_line += len(lines)

    def finish(self, final_counters: dict | None = None, **attrs) -> int:
        """Close the file (attributes: counters, gaps, flags); return the number of lines."""
        if self.writer is None:
            return 0
        counters = final_counters or self.counters
        self.writer.close(
            counters=json.dumps(counters),
            nonfinite_pulses=int(counters.get("nonfinite_pulses", 0)),
            missing_lines=self.missing_lines,
            missing_line_runs=json.dumps(self.missing_runs),
            flagged_line_runs=json.dumps(self.flagged_runs),
            **attrs,
        )
        return self.writer.lines


class ImageFileSink(StripSink):
    """Pipeline sink: record every strip, in process (lossless), to an image file."""

    def __init__(self, path: str | Path, source: str):
        self.recorder = StripRecorder(path, source)
        self.lines = 0

    def strip(self, strip: Strip, info: StreamInfo) -> None:
        self.recorder.add_strip(strip_header(strip, info), strip.lines)

    def end(self, stats: dict, info: StreamInfo) -> None:
        self.lines = self.recorder.finish(
            stats["counters"],
            lens=info.lens_backend,
            correlator=info.config.processor.correlator,
        )
