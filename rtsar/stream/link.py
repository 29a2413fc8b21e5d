"""Link health: a live source that delivers nothing is told, not waited on in silence.

An instrument that stops sending with its link open (a serial line gone quiet, a GNU Radio
flowgraph stalled, a publisher closed) leaves nothing to count: no gap until it comes back, no
error.  :class:`LinkWatch` times the silence between the source's batches: once it reaches
:func:`silence_threshold_s` (max(1 s, 10 pulse periods)) it is said ("link silent for X s since
pulse N", N the instrument's number of the last shot) and shown on the status line until shots
come again; the resumption is said too, with how long it lasted and the pulse numbers on either
side (the shots missed are ingest's gap), and every silence is counted (``link_silences``,
``link_silent_ms``: all silences told, in ms).  With ``timeout_s`` (``--link-timeout``) a
silence that long ends the run: ``failure`` says why and ``on_timeout`` stops the source.

The clock starts when the pipeline starts pulling from the source (:meth:`start`), not when the
pipeline is built: preparing the lens and the correlator is not silence of the link.
"""

from __future__ import annotations

import threading
import time

SILENCE_PULSES = 10  # a silence is told after this many pulse periods …
SILENCE_MIN_S = 1.0  # … and never before this long
CHECK_S = 0.1  # how often the watch looks


def silence_threshold_s(prf_hz: float) -> float:
    """The silence worth telling: max(1 s, 10 pulse periods)."""
    return max(SILENCE_MIN_S, SILENCE_PULSES / float(prf_hz))


def _pulse(seq: int | None) -> str:
    return "the start (no pulse yet)" if seq is None else f"pulse {seq % 2**64}"


class LinkWatch:
    """The silence of a live source (module docstring).  ``heard(first, last)`` after every
    batch (the instrument's numbers of its first and last shots), ``check()`` every
    :data:`CHECK_S` from a thread of its own (:meth:`run`), ``ended()`` when the source has
    ended (a timeout ends the silence it tells there).  Nothing is timed before ``start()``,
    called as the pipeline starts pulling from the source."""

    def __init__(self, prf_hz: float, notify=None, timeout_s: float | None = None, on_timeout=None):
        if timeout_s is not None and not timeout_s > 0:
            raise ValueError(f"--link-timeout must be > 0 seconds, got {timeout_s}")
        self.threshold_s = silence_threshold_s(prf_hz)
        self.notify = notify
        self.timeout_s = timeout_s
        self.on_timeout = on_timeout
        self.failure: str | None = None
        self.silences = 0
        self._told_s = 0.0  # the silences told and over, in seconds
        self._lock = threading.Lock()
        self._last_s: float | None = None  # the last batch (or the start); None: not started
        self._last_seq: int | None = None
        self._silent = False  # the current silence has been told
        self._ended = threading.Event()
        self._ended_s: float | None = None

    def _say(self, message: str) -> None:
        if self.notify is not None:
            self.notify(message)

    def start(self, now: float | None = None) -> None:
        """The pipeline starts pulling from the source: the silence is timed from here."""
        now = time.monotonic() if now is None else now
        with self._lock:
            if self._last_s is None:
                self._last_s = now

    def heard(self, first: int, last: int, now: float | None = None) -> None:
        """A batch came: the instrument's numbers of its first and last shots."""
        now = time.monotonic() if now is None else now
        with self._lock:
            if self._last_s is None:  # a batch before start(): the start is now
                self._last_s = now
            quiet_s, was, silent = now - self._last_s, self._last_seq, self._silent
            self._last_s, self._last_seq, self._silent = now, int(last), False
            if silent:
                self._told_s += quiet_s
        if silent:
            self._say(
                f"link resumed after {quiet_s:.1f} s silent ({_pulse(was)} → pulse "
                f"{int(first) % 2**64})"
            )

    def check(self, now: float | None = None) -> None:
        """Tell a silence that has reached the threshold; end the run at the timeout."""
        now = time.monotonic() if now is None else now
        with self._lock:
            if self._ended.is_set() or self._last_s is None:
                return
            quiet_s, since = now - self._last_s, self._last_seq
            tell = quiet_s >= self.threshold_s and not self._silent
            if tell:
                self._silent = True
                self.silences += 1
            timed_out = (
                self.timeout_s is not None and quiet_s >= self.timeout_s and self.failure is None
            )
            if timed_out:
                self._ended_s = now  # the run ends here: its silence is this long
                self.failure = (  # the true silence: the watch looks every CHECK_S
                    f"link silent for {quiet_s:.1f} s since {_pulse(since)} "
                    f"(--link-timeout {self.timeout_s:g})"
                )
        if tell:
            self._say(f"link silent for {quiet_s:.1f} s since {_pulse(since)}")
        if timed_out and self.on_timeout is not None:
            self.on_timeout()

    def state(self, now: float | None = None) -> dict | None:
        """The silence being told ({silent_s, since_pulse}), None while shots come; after the
        source's end, the silence it ended in."""
        now = time.monotonic() if now is None else now
        with self._lock:
            if self._ended_s is not None:
                now = min(now, self._ended_s)
            if not self._silent or self._last_s is None:
                return None
            seq = None if self._last_seq is None else self._last_seq % 2**64
            return {"silent_s": now - self._last_s, "since_pulse": seq}

    def counters(self, now: float | None = None) -> dict:
        state = self.state(now)
        silent_s = self._told_s + (state["silent_s"] if state else 0.0)
        return {"link_silences": self.silences, "link_silent_ms": int(round(1e3 * silent_s))}

    def ended(self) -> None:
        """The source has ended: no more silence to tell (a silence at its end stays)."""
        with self._lock:
            if self._ended_s is None:
                self._ended_s = time.monotonic()
        self._ended.set()

    def run(self) -> None:
        """Check every :data:`CHECK_S` until :meth:`ended` (the body of the watch's thread)."""
        while not self._ended.wait(CHECK_S):
            self.check()
