"""``rtsar subscribe``: receive published strips and write them into an image file."""

from __future__ import annotations

import signal
import sys
import time

from ..sinks.client import StripSubscriber
from ..sinks.io import check_writable
from ..sinks.record import StripRecorder
from . import signals


def subscribe(
    endpoint: str,
    output: str,
    curve_server_key=None,
    timeout_s: float | None = None,
    curve_client_key=None,
    stream=None,
) -> int:
    """Write every strip received into ``output`` until the stream's end message, Ctrl-C, or
    ``timeout_s`` without a message.  Missed strips become zero lines, counted and listed.
    Exit status 0 once the end came, 1 when the timeout stopped it first (or nothing came),
    128 + n after signal n."""
    stream = stream or sys.stderr
    check_writable(output)  # before listening, not at the first strip
    sub = StripSubscriber(endpoint, curve_server_key, curve_client_key, hwm_messages=0)
    rec = StripRecorder(output, endpoint)
    final = None
    stopped_by = ""  # the publisher's source stopped by a signal (its end message says)
    interrupted = None
    print(f"subscribe: connected to {endpoint}; writing {output} (Ctrl-C to stop)", file=stream)
    last = time.perf_counter()
    try:
        quiet_since = time.perf_counter()
        while True:
            msg = sub.recv(0.5)  # in slices: a quiet stream still gets its lines flushed
            if msg is None:
                rec.flush_if_due()
                if timeout_s is not None and time.perf_counter() - quiet_since >= timeout_s:
                    print(f"subscribe: no message for {timeout_s:g} s, stopping", file=stream)
                    break
                continue
            quiet_since = time.perf_counter()
            if msg.topic == "strip":
                rec.add_strip(msg.header, msg.lines)
            elif msg.topic == "height":
                rec.add_height(msg.header, msg.lines, msg.valid, msg.coherence)
            elif msg.topic == "end" and rec.writer is None:  # (a spotlight publisher's too)
                print("subscribe: the publisher's stream ended before any strip", file=stream)
                break
            elif msg.topic == "end":
                if msg.header.get("stream_id") == rec.stream_id:
                    counters = msg.header.get("counters")
                    final = counters if is_counters(counters) else rec.counters
                    stopped_by = msg.header.get("stopped_by", "")  # a signal's name only
                    named = isinstance(stopped_by, str) and stopped_by in signal.Signals.__members__
                    stopped_by = stopped_by if named else ""
                    break
            now = time.perf_counter()
            if now - last > 2.0:
                last = now
                print(
                    f"subscribe: strips {sub.counters['strips']}, lines {rec.lines_written}, "
                    f"missed strips {sub.counters['missed_strips']}",
                    file=stream,
                )
    except KeyboardInterrupt as exc:
        interrupted = exc
    finally:
        lines = rec.finish(
            final,
            missed_strips=sub.counters["missed_strips"],
            stopped_by=stopped_by,
            complete=final is not None,
        )
        sub.close()
    if interrupted is not None:
        status = signals.exit_status(interrupted)
    else:  # 1: --timeout stopped it before the stream's end (its publisher gone or stalled)
        status = 0 if final is not None else 1
    if rec.writer is None:
        print(
            "subscribe: no strip received; nothing written"
            + (
                f" (bad messages {sub.counters['bad_messages']})"
                if sub.counters["bad_messages"]
                else ""
            ),
            file=stream,
        )
        return status or 1
    odd = [
        f"{label} {value}"
        for label, value in (
            ("bad messages", sub.counters["bad_messages"]),
            ("strips that did not fit the image", rec.inconsistent_strips),
            ("line-number jumps not filled", len(rec.line_jumps)),
            ("repeated strips", rec.overlapping_strips),
            ("strips of another stream (a restarted publisher?)", rec.other_stream_strips),
            ("strips far ahead that the next did not confirm", rec.stray_strips),
        )
        if value
    ]
    print(
        f"wrote {output}: {lines} lines from line {rec.first_line}; strips received "
        f"{sub.counters['strips']}, missed {sub.counters['missed_strips']} "
        f"({rec.missing_lines} zero lines)"
        + (f"; {', '.join(odd)}" if odd else "")
        + ("" if final is not None else "; the stream's end was not seen"),
        file=stream,
    )
    return status


def is_counters(value) -> bool:
    """A counters object as the strip protocol defines it: names to integers."""
    return isinstance(value, dict) and all(
        isinstance(k, str) and isinstance(v, int) and not isinstance(v, bool)
        for k, v in value.items()
    )
