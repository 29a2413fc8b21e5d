"""Run a source through the pipeline with a ZeroMQ publisher and a live status line.

Shared by ``rtsar run`` (simulated scene or serial instrument) and ``rtsar replay``.  Ctrl-C stops
the source; what already arrived is still focused, published and (with ``-o``) written.
"""

from __future__ import annotations

import sys
import time

from ..params import Config
from ..sinks.publish import ZmqPublisher
from ..sinks.record import ImageFileSink
from ..stream.pipeline import Pipeline, PipelineSettings


def format_status(d: dict, total: int | None = None) -> str:
    c = d["counters"]
    done = c.get("pulses_processed", 0)
    progress = f"/{total}" if total else ""
    problems = []
    for key, label in (
        ("dropped_pulses", "dropped"),
        ("gap_pulses", "gap-filled"),
        ("duplicates", "dup"),
        ("late_pulses", "late"),
        ("nonfinite_pulses", "NaN/Inf"),
        ("wrong_length_pulses", "bad length"),
        ("discontinuities", "jumps"),
        ("header_crc_errors", "header CRC errors"),
        ("payload_crc_errors", "payload CRC errors"),
        ("bad_headers", "bad headers"),
        ("wrong_length", "wrong-length frames"),
        ("late_releases", "late releases"),
    ):
        if c.get(key):
            problems.append(f"{label} {c[key]}")
    for key, value in c.items():  # correction stages: what they could not do
        if "." in key and value and ("not_" in key or "nonfinite" in key):
            problems.append(f"{key} {value}")
    return (
        f"t={d['elapsed_s']:6.1f} s  pulses {done}{progress}  {d['pulse_rate_hz']:8.0f} Hz  "
        f"lines {c.get('lines_out', 0)}  strips {c.get('strips_published', 0)}  "
        f"latency median {d['latency_recent_median_ms']:6.2f} ms p99 "
        f"{d['latency_recent_p99_ms']:6.2f} ms  "
        + ("  ".join(problems) if problems else "no drops/gaps")
    )


def run_stream(
    config: Config,
    source,
    settings: PipelineSettings,
    endpoint: str,
    delivery: str,
    start_along_track_m: float = 0.0,
    output: str | None = None,
    curve_secret_key=None,
    wait_subscribers: int = 0,
    total_pulses: int | None = None,
    stream=None,
    corrections=None,
    physical=None,
) -> int:
    """Run until the source ends or Ctrl-C; print status lines and a summary; return exit code."""
    stream = stream or sys.stdout
    publisher = ZmqPublisher(
        endpoint,
        delivery,
        curve_secret_key=curve_secret_key,
        warn=lambda message: print(message, file=sys.stderr),
    )
    sinks: list = [publisher]
    if output:
        sinks.append(ImageFileSink(output, source.description))
    tty = hasattr(stream, "isatty") and stream.isatty()
    last = [0.0]

    def show(d: dict) -> None:
        now = time.perf_counter()
        if d.get("final") or now - last[0] >= (0.5 if tty else 5.0):
            last[0] = now
            line = format_status(d, total_pulses)
            stream.write(("\r" + line + "  ") if tty else (line + "\n"))
            stream.flush()

    n = config.processor
    print(
        f"rtsar: {source.description}; CCD {n.aperture_pulses} x {n.range_bins}, "
        f"{n.correlator} correlator, {settings.lens_backend} lens, {settings.stages} stages, "
        f"strips of {settings.strip_lines} lines on {endpoint} ({delivery})"
        + (f"; corrections: {', '.join(corrections.names)}" if corrections else "")
        + (f"; physical CCD, carrier in {physical.carrier}" if physical else "")
        + (f"; {n.precision}" if n.precision != "complex64" else "")
        + (f"; range migration {n.range_migration_taps} taps" if n.range_migration_taps else ""),
        file=stream,
        flush=True,
    )
    interrupted = False
    try:
        if wait_subscribers:
            print(
                f"waiting for {wait_subscribers} subscriber(s) on {endpoint} …",
                file=stream,
                flush=True,
            )
            publisher.wait_for_subscribers(wait_subscribers)
        pipe = Pipeline(
            config,
            source,
            sinks,
            settings,
            start_along_track_m,
            on_stats=show,
            stats_every_s=0.5 if tty else 1.0,
            corrections=corrections,
            physical=physical,
        )
        pipe.start()
        try:
            stats = pipe.join()
        except KeyboardInterrupt:
            interrupted = True
            stream.write("\ninterrupted: the pulses already received are being finished\n")
            stats = pipe.join()
    except KeyboardInterrupt:  # while waiting for subscribers: nothing was processed
        return 130
    finally:
        publisher.close()
    if tty:
        stream.write("\n")
    d = stats.as_dict()
    c = d["counters"]
    print(
        f"done: {c['pulses_processed']} pulses in {d['elapsed_s']:.1f} s "
        f"({d['pulse_rate_hz']:,.0f} Hz), {c['lines_out']} lines in {c['strips_published']} "
        f"strips; latency median {d['latency_median_ms']:.2f} ms, p99 {d['latency_p99_ms']:.2f} "
        f"ms; dropped {c['dropped_pulses']}, gap-filled {c.get('gap_pulses', 0)}, "
        f"flagged lines {c['flagged_lines']}",
        file=stream,
    )
    if output:
        print(f"wrote {output}: {sinks[1].lines} lines", file=stream)
    return 130 if interrupted else 0
