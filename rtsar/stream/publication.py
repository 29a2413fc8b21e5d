"""The strip stage of the pipeline (rtsar.stream.pipeline): the image lines cut into strips and
published on every sink, by size or by deadline, and the run's statistics sent on the way.

A strip goes out when it holds ``strip_lines`` (with every line then waiting, up to
``strip_most_lines``), when its oldest line waited ``strip_deadline_s``, or when no line came
for a strip's time; the height strips of a 3D run go out in their order among the lines.  A
new stream info in the queue (the correlator's block changed, rtsar.stream.growth) first sends
the lines before it, under the old one (rtsar.stream.strips.StripAssembler).
"""

from __future__ import annotations

import math
import time

from .height import HeightBatch


def strip_stage(pipe) -> None:
    """The strip thread of ``pipe`` (an rtsar.stream.pipeline.Pipeline)."""
    last_stats = time.perf_counter()
    s, prf = pipe.settings, pipe.config.geometry.prf_hz
    strip_lines, deadline_s = s.strip_lines, s.strip_deadline_s
    strip_period_s = min(max(strip_lines / prf, 1e-3), pipe.stats_every_s / 4)
    strips = pipe.strips
    try:
        while True:
            wait_s = strips.wait_s(time.perf_counter(), deadline_s)  # the deadline's turn
            take = max(8 * strip_lines, s.strip_most_lines)
            blocks = pipe.q_image.get_batch(take, timeout=min(wait_s, strip_period_s))
            if blocks is None:
                break
            if not blocks:  # no new line for a strip's time (or a deadline): what is held
                while count := strips.due(math.inf, strips.held, strips.held, 0.0):
                    pipe._publish(count)
            now = time.perf_counter()
            for b in blocks:
                if isinstance(b, HeightBatch):
                    publish_heights(pipe, b)
                else:
                    strips.add(b, now)
            while count := strips.due(now, strip_lines, s.strip_most_lines, deadline_s):
                pipe._publish(count)
            now = time.perf_counter()
            if now - last_stats >= pipe.stats_every_s:
                last_stats = now
                pipe._send_stats()
        while count := strips.due(math.inf, strip_lines, strip_lines, 0.0):  # the rest
            pipe._publish(count)
    finally:
        pipe._send_stats(final=True)


def publish_heights(pipe, batch: HeightBatch) -> None:
    """The height strips of ``batch`` on every sink, numbered in order."""
    for strip in batch.strips:
        for sink in pipe.sinks:
            sink.height(strip, pipe._height_seq, pipe.info)
        pipe._height_seq += 1
        pipe.own["height_strips_published"] = pipe.own.get("height_strips_published", 0) + 1
