"""Run a source through the pipeline with a ZeroMQ publisher and a live status line.

Shared by ``rtsar run`` (simulated scene or serial instrument) and ``rtsar replay``.  Ctrl-C stops
the source; what already arrived is still focused, published and (with ``-o``) written.  A stop
ends the run in bounded time: a recording (``--record``) that has not finished
rtsar.sinks.raw_record.HURRY_S after it is given up on, and the shots it may lack are counted.
"""

from __future__ import annotations

import math
import sys
import time

from ..focus.spec import correct_option
from ..params import Config
from ..scene.effects import REGISTRY as EFFECTS
from ..sinks.publish import STALL_TIMEOUT_S, ZmqPublisher
from ..sources.channel_map import ChannelMap
from ..stream.granularity import migration_words
from ..stream.pipeline import Pipeline, PipelineSettings
from . import signals
from .compile_notice import compile_notice
from .live_granularity import survey_and_compile
from .live_outputs import LiveOutputs
from .progress import terminal_line

# Counters that describe normal work; every other counter that is not zero is shown, so nothing
# that went wrong is hidden from the status line.
_NORMAL = {
    *("pulses_received", "pulses_accepted", "pulses_processed", "lines_out"),
    "strips_published",
    "height_strips_published",
    "correlator_block_lines",  # a state (rtsar.stream.growth); its changes are the news
    "frames_ok",
    "bytes_fed",
    "messages",  # GNU Radio messages received (rtsar.sources.zmq_in)
    "record_written",
}
_NORMAL_SUFFIXES = (
    ".pulses_in",
    ".pulses_out",
    ".shots_in",
    ".blocks_estimated",
    ".blocks_converged",
    ".reasons.converged",  # the PGA outcomes whose estimate is used
    ".reasons.window_floor",
    ".reasons.max_iterations",
)
_LABELS = {
    "dropped_pulses": "dropped",
    "gap_pulses": "gap-filled",
    "duplicates": "dup",
    "late_pulses": "late",
    "stray_pulses": "stray",
    "nonfinite_pulses": "NaN/Inf",
    "wrong_length_pulses": "bad length",
    "pulses_before_start": "sent before the first received",
    "marked_pulses": "zero pulses marked in the recording",
    "discontinuities": "restarts",
    "header_crc_errors": "header CRC errors",
    "payload_crc_errors": "payload CRC errors",
    "bad_headers": "bad headers",
    "wrong_length": "wrong-shape frames",
    "truncated_frames": "cut frames",
    "bytes_skipped": "bytes skipped",
    "link_drops": "link lost",
    "oversized_messages": "oversized messages refused",
    "layout_changes": "stream layout changes",
    "reconnects": "reconnected",
    "late_releases": "late releases",
    "subscriber_stalls": "stalled subscribers cut off",
    "messages_missed_by_stalled": "messages sent while one was cut off",
    "flagged_lines": "flagged lines",
    "link_silences": "link silences",
    "record_dropped": "not recorded",
    "record_unconfirmed": "not confirmed in the recording (it may lack them)",
    "image_lines_lost": "lines not written to -o",
    "swath_refused_messages": "refused swath messages",
    "correlator_growths": "correlator blocks grown (the work fell behind)",
    "correlator_shrinks": "correlator blocks shrunk back (room again)",
}


class RateWatch:
    """Says when the stream is processed slower than its source should deliver it.

    Rates are measured over windows of at least ``window_s``; two windows in a row below
    ``fraction`` of ``expected_hz`` give one warning (then at most one per ``repeat_s``)."""

    def __init__(self, expected_hz: float, say, window_s=2.0, fraction=0.9, repeat_s=30.0):
        self.expected_hz, self.say = float(expected_hz), say
        self.window_s, self.fraction, self.repeat_s = window_s, fraction, repeat_s
        self._mark: tuple[float, int] | None = None
        self._slow = 0
        self._said_s = -float("inf")

    def update(self, now_s: float, pulses: int) -> None:
        if self._mark is None:
            self._mark = (now_s, pulses)
            return
        t0, p0 = self._mark
        if now_s - t0 < self.window_s:
            return
        rate = (pulses - p0) / (now_s - t0)
        self._mark = (now_s, pulses)
        self._slow = self._slow + 1 if rate < self.fraction * self.expected_hz else 0
        if self._slow >= 2 and now_s - self._said_s >= self.repeat_s:
            self._said_s = now_s
            self.say(
                f"warning: processing {rate:,.0f} pulses/s, below the source's "
                f"{self.expected_hz:,.0f} Hz: this machine cannot keep up with this "
                "configuration live (see `rtsar bench`); record it and `rtsar replay REC.h5 "
                "--rate F` at a rate it can follow"
            )


def lens_label(lens) -> str:
    """The lens in use, for the banner: "opencl lens", or the fallback and why."""
    if lens.fallback_reason:
        return "NumPy lens (OpenCL unavailable, see the warning above)"
    return "OpenCL lens" if lens.backend == "opencl" else "NumPy lens"


LATE_RELEASES_MEANING = (  # the summary's words and the web view's (webview/frames.py)
    "chunks of simulated shots sent over 1 ms after their time (no shot lost by it; the wait is "
    "in the latency)"
)


def problems(counters: dict) -> list[str]:
    """Every counter that is not zero and says something went wrong or was done about it."""
    out = []
    for key, value in counters.items():
        if not value or key in _NORMAL or key.endswith(_NORMAL_SUFFIXES):
            continue
        if key == "link_silent_ms":
            out.append(f"link silent {value / 1e3:.1f} s in all")
        else:
            out.append(f"{_LABELS.get(key, key)} {value}")
    return out


def end_reason(source, link, interrupted: BaseException | None) -> str:
    """Why a live stream ended, in words: the link timeout, the signal, else the source's own
    reason (idle, a link lost).  The source says "closed" in all three cases: it is closed by
    the run for the first two."""
    if link is not None and link.failure is not None:
        return f"--link-timeout {link.timeout_s:g}"
    if interrupted is not None:
        return signals.describe(interrupted)
    return getattr(source, "stop_reason", "") or ""


def link_words(state: dict) -> str:
    """A silence being told (rtsar.stream.link.LinkWatch.state) in words."""
    since = state["since_pulse"]
    return f"link silent for {state['silent_s']:.1f} s since " + (
        "the start (no pulse yet)" if since is None else f"pulse {since}"
    )


def format_status(d: dict, total: int | None = None) -> str:
    c = d["counters"]
    done = c.get("pulses_processed", 0)
    progress = f"/{total}" if total else ""
    bad = problems(c)
    median, p99 = d["latency_recent_median_ms"], d["latency_recent_p99_ms"]
    latency = (
        f"latency median {median:6.2f} ms p99 {p99:6.2f} ms"
        if math.isfinite(median)
        else "latency: no strip yet"
    )
    link = d.get("link")
    if link:  # said first: the rates and counters below are stale while nothing comes
        bad.insert(0, link_words(link).upper())
    return (
        f"t={d['elapsed_s']:6.1f} s  pulses {done}{progress}  {d['pulse_rate_hz']:8.0f} Hz  "
        f"lines {c.get('lines_out', 0)}  strips {c.get('strips_published', 0)}  {latency}  "
        + ("  ".join(bad) if bad else "no drops/gaps")
    )


def check_source_channels(source, corrections=None, height=None, fix=None) -> None:
    """Refuse, before any work, a --correct or --height stage that reads an auxiliary channel
    the source cannot deliver (``source.aux_channels()``; None: unknown before the stream, no
    check here): check_channels_delivered."""
    if _readers(corrections, height):
        have = source.aux_channels()
        if have is not None:
            check_channels_delivered(have, source.description, corrections, height, fix)


def _readers(corrections, height) -> list[tuple[str, tuple]]:
    """(option, channels) of each stage that reads auxiliary channels."""
    named = corrections.named if corrections else []
    readers = [(correct_option(name), stage.channels) for name, stage in named]
    if height is not None:
        readers.append((f"--height {height.kind}", tuple(height.channels)))
    return [(option, channels) for option, channels in readers if channels]


def check_channels_delivered(have, description, corrections=None, height=None, fix=None) -> None:
    """One-line ValueError when a stage reads an auxiliary channel not in ``have`` (the source
    ``description`` delivers those): it names the option(s), the missing channel(s) and
    ``fix(missing)``, what gives the source that channel.  The stages also check every block
    (a stream that breaks its declaration)."""
    options, missing = [], []
    for option, channels in _readers(corrections, height):
        lack = [c for c in channels if c not in have]
        if lack:
            options.append(option)
            missing += [c for c in lack if c not in missing]
    if not missing:
        return
    held = ", ".join(have) if have else "the main channel only"
    raise ValueError(
        f"{' and '.join(options)} {'reads' if ' '.join(options).count('--') == 1 else 'read'} "
        "the auxiliary "
        f"channel{'s' if len(missing) > 1 else ''} {', '.join(missing)}, but the source "
        f"({description}) delivers {held}" + (f": {fix(missing)}" if fix else "")
    )


def _map_entries(missing, scene) -> tuple[list[str], bool]:
    """``NAME*K`` for each missing channel, K from the scene's map (K unknown: ``NAME*K``);
    True when some K is unknown."""
    try:
        known = dict(ChannelMap.for_scene(scene).entries) if scene is not None else {}
    except (ValueError, AttributeError):  # widths that do not fit frames, or no aux at all
        known = {}
    entries = [
        (name if known[name] == 1 else f"{name}*{known[name]}") if name in known else f"{name}*K"
        for name in missing
    ]
    return entries, any(name not in known for name in missing)


_K_WORDS = " (K: the frame channels each spans, its samples per shot / S)"


def serial_channel_fix(cmap, scene):
    """What --serial needs to deliver missing auxiliary channels: their entries in the map."""

    def fix(missing) -> str:
        entries, unknown = _map_entries(missing, scene)
        current = cmap.text if cmap is not None else "main"
        scene_map = None if scene is None else ChannelMap.for_scene(scene)
        default = (
            f"; or leave --channel-map out: --scene's map is {scene_map.text}"
            if scene_map is not None and all(n in scene_map.aux_names for n in missing)
            else ""
        )
        return (
            f"add {','.join(entries)} to --channel-map where the instrument's frames carry "
            f"{'it' if len(missing) == 1 else 'them'} (e.g. --channel-map "
            f"{current},{','.join(entries)}){_K_WORDS if unknown else ''}{default}"
        )

    return fix


def zmq_channel_fix(scene):
    """--zmq-in carries one complex stream: the channels cannot come that way."""

    def fix(missing) -> str:
        entries, unknown = _map_entries(missing, scene)
        return (
            "a GNU Radio ZMQ PUB Sink stream (--zmq-in) carries the main channel only; process "
            "without it, or send the shots with their channels as instrument frames: "
            f"--serial URL --channel-map main,{','.join(entries)}" + (_K_WORDS if unknown else "")
        )

    return fix


def scene_channel_fix(missing) -> str:
    """A simulated scene makes an auxiliary channel only with the effect of that name."""
    effects = [n for n in missing if n in EFFECTS]
    if len(effects) == len(missing):
        named = " and ".join(f'[[effects]] name = "{n}"' for n in effects)
        return f"add {named} to the scene (docs/pages/guide/scenes.md)"
    return "add the effect that makes them to the scene (docs/pages/guide/scenes.md)"


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
    stall_timeout_s: float = STALL_TIMEOUT_S,
    curve_clients=None,
    expected_rate_hz: float | None = None,
    height=None,
    channel_fix=None,
    record: str | None = None,
    scene: dict | None = None,
    link_timeout_s: float | None = None,
    granularity=None,
) -> int:
    """Run until the source ends, Ctrl-C or a signal; print status lines and a summary.

    Exit status: 0 when the stream ended cleanly, 1 when the source failed (an instrument link
    lost for good, silent for ``link_timeout_s``) or nothing could be written to ``output`` or
    ``record``, 2 when the disk refused the image or the recording (or the recording was
    given up on), 128 + the signal number when interrupted (130 for Ctrl-C).  ``record``: the
    raw shots' file (rtsar.sinks.raw_record; ``scene``, the scene's dict, goes into it).
    ``expected_rate_hz``: the rate the source should deliver (a simulation's PRF, a paced
    replay's): a slower stream is warned about.  ``channel_fix(missing)``: how to give the
    source the auxiliary channels a stage reads and it lacks (check_source_channels, before
    anything starts).  ``granularity``: a live_granularity.GranularityRequest, or None."""
    try:
        check_source_channels(source, corrections, height, channel_fix)
    except ValueError:
        source.close()  # a port already open is let go at once
        raise
    stream = stream or sys.stdout
    err = sys.stderr

    def say(message: str) -> None:  # a message on its own line, the status line goes on after
        stream.write(("\n" if tty else "") + message + "\n")
        stream.flush()

    tty = hasattr(stream, "isatty") and stream.isatty()
    source.notify = say
    # The files first: a name another process writes is refused before a socket is bound.
    files = LiveOutputs(
        config, source.description, output, record, start_along_track_m, scene, notify=say
    )
    try:
        publisher = ZmqPublisher(
            endpoint,
            delivery,
            curve_secret_key=curve_secret_key,
            warn=lambda message: print(message, file=err),
            stall_timeout_s=stall_timeout_s,
            curve_clients=curve_clients,
        )
    except BaseException:
        files.release()
        raise
    sinks: list = [publisher, *files.sinks]
    last = [0.0]

    watch = None if expected_rate_hz is None else RateWatch(expected_rate_hz, say)

    def show(d: dict) -> None:
        now = time.perf_counter()
        if watch is not None and not d.get("final"):
            watch.update(d["elapsed_s"], d["counters"].get("pulses_processed", 0))
        final, every_s = bool(d.get("final")), 0.5 if tty else 5.0
        # The end's line, unless a line just said the same (on a terminal it overwrites it)
        if (final and (tty or now - last[0] >= 1.0)) or now - last[0] >= every_s:
            last[0] = now
            line = format_status(d, total_pulses)
            stream.write(terminal_line(line) if tty else (line + "\n"))
            stream.flush()

    interrupted = None
    # numba's first compilation of a kernel is told (the whole run: a stall mid-stream too)
    streaming = []  # once the stream runs, a line of its own beside the status line (say)
    compiling = compile_notice(
        lambda m: say(f"rtsar: {m}") if streaming else print(f"rtsar: {m}", file=stream, flush=True)
    )
    compiling.__enter__()
    try:
        print("rtsar: preparing the lens and the correlator …", file=stream, flush=True)
        survey_and_compile(
            settings,
            config,
            physical,
            source,
            lambda m: print(f"rtsar: {m} …", file=stream, flush=True),
            granularity,
        )
        if settings.swath_workers:
            print(
                f"rtsar: starting {settings.swath_workers} swath workers (each loads rtsar and "
                "builds its lens: seconds, more on a busy machine) …"
                if settings.swath_spawn
                else f"rtsar: waiting for {settings.swath_workers} swath workers: run `rtsar "
                f"swath-worker --connect {settings.swath_bind} --index k` for k = 0 … "
                f"{settings.swath_workers - 1}",
                file=stream,
                flush=True,
            )
        getattr(source, "prepare", lambda: None)()  # a simulated source readies its kernels
        chosen = None
        if granularity is not None:
            note = lambda m: print(f"rtsar: {m}", file=stream, flush=True)  # noqa: E731
            source_s = source.cost_per_pulse_s() if hasattr(source, "cost_per_pulse_s") else 0.0
            config, settings, _, chosen = granularity.apply(
                config, settings, physical, height, note, source_s
            )
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
            height=height,
            notify=say,
            link_timeout_s=link_timeout_s,
        )
        n = config.processor
        print(
            f"rtsar: {source.description}; CCD {n.aperture_pulses} x {n.range_bins}, "
            f"{'emulated CCD' if physical else n.correlator + ' correlator'}, "
            f"{lens_label(pipe.engine.lens)}, "
            + (
                f"lens + CCD in {settings.swath_workers} swath worker processes, "
                if settings.swath_workers
                else f"{settings.stages} stages, "
            )
            + f"strips of {settings.strip_lines} line{'s' * (settings.strip_lines != 1)} on "
            f"{endpoint} ({delivery})"
            + (f"; corrections: {', '.join(corrections.names)}" if corrections else "")
            + (f"; physical CCD, carrier in {physical.carrier}" if physical else "")
            + (f"; height strips of {height.strip_lines} lines" if height is not None else "")
            + (f"; {n.precision}" if n.precision != "complex64" else "")
            + (migration_words(n) if n.range_migration_taps else ""),
            file=stream,
            flush=True,
        )
        if getattr(pipe.engine.lens, "choice", None):
            print(f"rtsar: lens: {pipe.engine.lens.choice}", file=stream, flush=True)
        for line in (chosen or "").splitlines():  # the correlator's, then the granularity's
            print(f"rtsar: {line}", file=stream, flush=True)
        if wait_subscribers:
            waiting = f"waiting for {wait_subscribers} subscriber(s) on {endpoint} …"
            print(waiting, file=stream, flush=True)
            publisher.wait_for_subscribers(wait_subscribers)
        streaming.append(True)
        try:
            with signals.held():  # started whole: a Ctrl-C meanwhile is raised after it
                pipe.start()
            stats = pipe.join()
        except KeyboardInterrupt as exc:
            if not pipe.stats.started_s:  # came before the start began: nothing started
                raise
            interrupted = exc
            pipe.interrupted(exc)  # (join did already, but not for one raised before it)
            say(f"{signals.describe(exc)}: the pulses already received were finished")
            stats = pipe.join()
    except KeyboardInterrupt as exc:  # before the stream started: nothing was processed
        said = f"{signals.describe(exc)} before the stream started: no shot processed"
        print(f"rtsar: {said}, no file written", file=stream, flush=True)
        return signals.exit_status(exc)
    finally:
        compiling.__exit__(None, None, None)
        publisher.close()
        files.release()  # (a run that never started: its claims on the names go)
    if tty:
        stream.write("\n")
    d = stats.as_dict()
    c = d["counters"]
    c.update(files.counters())  # final: taken when the outputs had ended, not before
    latency = (
        f"latency median {d['latency_median_ms']:.2f} ms, p99 {d['latency_p99_ms']:.2f} ms"
        if math.isfinite(d["latency_median_ms"])
        else "no strip, so no latency"
    )
    print(
        f"done: {c['pulses_processed']} pulses in {d['elapsed_s']:.1f} s "
        f"({d['pulse_rate_hz']:,.0f} Hz), {c['lines_out']} lines in {c['strips_published']} "
        f"strips; {latency}; dropped {c['dropped_pulses']}, gap-filled {c.get('gap_pulses', 0)}, "
        f"flagged lines {c['flagged_lines']}",
        file=stream,
    )
    bad = problems({k: v for k, v in c.items() if k != "late_releases"})
    if bad:
        print("counted: " + ", ".join(bad), file=stream)
    if c.get("late_releases"):  # no loss: said apart from the counters that are
        print(f"noted: late releases {c['late_releases']}, {LATE_RELEASES_MEANING}", file=stream)
    silent = pipe.link.state() if pipe.link is not None else None
    if silent:  # the stream ended in a silence that had been told
        why = end_reason(source, pipe.link, interrupted)
        print(
            f"{link_words(silent)} when the stream ended" + (f" ({why})" if why else ""),
            file=stream,
        )
    status = files.report(c, config, stream, err)
    failure = source.failure or (pipe.link.failure if pipe.link is not None else None)
    if failure:
        print(f"rtsar: the stream did not end cleanly: {failure}", file=err)
        status = max(status, 1)
    return signals.exit_status(interrupted) if interrupted is not None else status
