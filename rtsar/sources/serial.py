"""A live instrument on a serial line, a TCP socket or a pseudo-terminal, sending frames.

The bytes are read with pyserial's ``serial_for_url``, so ``url`` may be a device
(``/dev/ttyUSB0``, ``/dev/pts/5``), ``socket://host:port`` (the instrument, or
``tools/fake_instrument.py``, serves TCP) or ``loop://`` (tests).  The frame layout is in
:mod:`rtsar.sources.frame`.

A UART's baud rate bounds the shot rate: at 921 600 baud, 8N1 (92 160 bytes/s), a line carries
about 87 ci16 frames of 256 samples (1060 bytes) per second.  USB-CDC devices, pseudo-terminals
and sockets ignore the baud rate.

Opening a port discards what had already arrived (pyserial flushes the input; for socket:// it
reads and drops what is waiting), so the first frames an instrument sends the moment a
connection opens may be lost; the parser finds the next sync word as usual.

A lost link is never silent: it is counted (``link_drops``) and announced (``notify``).  With
``reconnect`` (the default for ``socket://``) the source reopens the link with a growing pause
(0.1 s doubling to 5 s, counted in ``reconnects``) and goes on; without it the source ends and
``failure`` says why, so the command can exit with an error.

An instrument that is not there yet is waited for: the first open is tried again (0.1 s doubling
to 1 s between tries) for ``connect_timeout_s`` (default 10 s for ``socket://``, where a
processor and an instrument started together race for the port; 0 for serial devices, where a
missing path is more often a typo than a device still coming up), said once through
``notify`` (a constructor argument, as the source has no other listener yet).

The parser knows the configured frame: ``samples_per_shot`` samples in exactly the channels
the shot takes (frame channel ``channel`` + 1 without a channel map, the map's frame channels
with one); a frame of another shape is rejected at its header, before its payload is
buffered (``wrong_length``), so no header, true or false, makes the parser hold more than one
frame of the configured stream.
(It took up to 64 channels: a CRC-valid false header claiming 64 held 63 true frames behind
it, a 12 s stall at 5 Hz.)  Each shape refused is said once (``notify``), with the fix.
"""

from __future__ import annotations

import io
import select
import threading
import time
from collections.abc import Iterator

import numpy as np
import serial

from .base import ShotBatch, Source
from .channel_map import ChannelMap
from .frame import MAX_PAYLOAD_BYTES, Frame, FrameParser

_READ_BYTES = 1 << 18  # most bytes taken in one read
_BACKOFF_S = (0.1, 5.0)  # first and longest pause between reconnection attempts
_CONNECT_WAIT_S = 10.0  # how long a socket:// instrument is waited for at the start


class SerialSource(Source):
    """Shots from frames arriving on ``url``: channel ``channel`` of each frame, in batches;
    with ``channel_map`` (rtsar.sources.channel_map) every channel of the shot, the auxiliary
    ones in ``ShotBatch.aux``.

    A batch is yielded as soon as a read completes at least one frame (at most ``batch_frames``
    per batch); ``arrival_s`` is the perf_counter time at which that read returned.  Frames
    of another shape than the configured one (``samples_per_shot`` samples, the channels the
    shot takes) are refused by the parser at their header and counted in
    ``counters["wrong_length"]``; the parser's counters
    (``rtsar.sources.frame.COUNTERS``) are mirrored in ``counters``.

    Iteration ends when ``close()`` is called (within ``poll_s``), when the link goes away (the
    peer closes the socket, the device disappears) or after ``idle_timeout_s`` without a byte;
    ``stop_reason`` says which.  Garbage on the line is skipped and counted, never raised.
    """

    live = True

    def __init__(
        self,
        url: str,
        samples_per_shot: int,
        baudrate: int = 921_600,
        batch_frames: int = 64,
        idle_timeout_s: float | None = None,
        channel: int = 0,
        poll_s: float = 0.05,
        max_payload_bytes: int = MAX_PAYLOAD_BYTES,
        reconnect: bool | None = None,
        channel_map: ChannelMap | None = None,
        connect_timeout_s: float | None = None,
        notify=None,
    ):
        super().__init__()
        self.notify = notify
        if not samples_per_shot >= 1:
            raise ValueError(f"samples_per_shot must be >= 1, got {samples_per_shot!r}")
        if not batch_frames >= 1:
            raise ValueError(f"batch_frames must be >= 1, got {batch_frames!r}")
        if not channel >= 0:
            raise ValueError(f"channel must be >= 0, got {channel!r}")
        if idle_timeout_s is not None and not idle_timeout_s > 0:
            raise ValueError(f"idle_timeout_s must be > 0 or None, got {idle_timeout_s!r}")
        if not poll_s > 0:
            raise ValueError(f"poll_s must be > 0, got {poll_s!r}")
        if url.startswith("socket://"):
            host, _, port = url[len("socket://") :].partition("?")[0].rpartition(":")
            if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
                raise ValueError(
                    f"{url!r}: a socket:// instrument is socket://HOST:PORT, PORT 1-65535"
                )
        if connect_timeout_s is None:
            connect_timeout_s = _CONNECT_WAIT_S if url.startswith("socket://") else 0.0
        if not connect_timeout_s >= 0:
            raise ValueError(f"connect_timeout_s must be >= 0, got {connect_timeout_s!r}")
        self.url = url
        self.samples_per_shot = int(samples_per_shot)
        self.batch_frames = int(batch_frames)
        self.idle_timeout_s = idle_timeout_s
        self.channel = int(channel)
        self.channel_map = channel_map
        self.poll_s = float(poll_s)
        self.frame_channels = channel + 1 if channel_map is None else channel_map.frame_channels
        self.parser = FrameParser(
            max_payload_bytes, self.samples_per_shot, self.frame_channels, self.frame_channels
        )
        self._shapes_told: set[tuple[int, int]] = set()
        self.counters = dict(self.parser.counters, link_drops=0, reconnects=0)
        self.description = f"serial instrument at {url}" + (
            f" (channels {channel_map.text})" if channel_map is not None else ""
        )
        self.stop_reason: str | None = None
        self.reconnect = url.startswith("socket://") if reconnect is None else bool(reconnect)
        self.baudrate = baudrate
        self._lock = threading.Lock()
        self._reading = False
        self._first_open(float(connect_timeout_s))

    def _first_open(self, wait_s: float) -> None:
        """Open the link, trying again for ``wait_s`` seconds (an instrument still starting);
        a ValueError naming the port and the last error after that."""
        end = time.perf_counter() + wait_s
        pause = _BACKOFF_S[0]
        told = False
        while True:
            try:
                self._open()
                break
            except (serial.SerialException, OSError, ValueError) as exc:
                left = end - time.perf_counter()
                if left <= 0:
                    waited = f" (waited {wait_s:g} s: --connect-timeout)" if wait_s > 0 else ""
                    raise ValueError(
                        f"cannot open instrument port {self.url!r}{waited}: {exc}"
                    ) from None
                if not told:
                    self._say(
                        f"instrument at {self.url} not there yet ({exc}); "
                        f"waiting up to {wait_s:g} s for it"
                    )
                    told = True
                time.sleep(min(pause, left))
                pause = min(2 * pause, 1.0)
        if told:
            self._say(f"instrument link to {self.url} open")

    def aux_channels(self) -> tuple[str, ...]:
        """The channel map's auxiliary channels (none without a map: frame channel
        ``channel`` is the shot)."""
        return () if self.channel_map is None else tuple(self.channel_map.aux_names)

    def _open(self) -> None:
        # Non-blocking reads: waiting is done by select() on the descriptor where there is
        # one, so a read returns whatever has arrived instead of waiting to fill a size.
        self.port = serial.serial_for_url(self.url, baudrate=self.baudrate, timeout=0)
        try:
            self._fd: int | None = self.port.fileno()
        except (AttributeError, OSError, io.UnsupportedOperation):
            self._fd = None  # loop:// and other handlers without a descriptor
            self.port.timeout = self.poll_s

    def _read(self) -> bytes:
        """What has arrived, waiting at most ``poll_s`` for the first byte."""
        port = self.port
        if self._fd is None:
            return port.read(max(1, port.in_waiting))
        ready, _, _ = select.select([self._fd], [], [], self.poll_s)
        return port.read(_READ_BYTES) if ready else b""

    def _tell_refused_shape(self) -> None:
        """The first time frames of a shape are refused (at most 3 shapes), say which and what
        the configured frame is: an instrument sending more channels than the map names."""
        shape = self.parser.refused_shape
        if shape is None or shape in self._shapes_told or len(self._shapes_told) >= 3:
            return
        self._shapes_told.add(shape)
        channels, samples = shape
        self._say(
            f"frames of {channels} channel{'s' * (channels != 1)} x {samples} samples refused "
            f"(wrong_length): the configured frame is {self.frame_channels} channel"
            f"{'s' * (self.frame_channels != 1)} x {self.samples_per_shot} samples "
            "(--channel-map names every channel a frame carries; --preset/--scene the samples)"
        )

    def _batches(self, frames: list[Frame], arrival_s: float) -> Iterator[ShotBatch]:
        if self.parser.counters["wrong_length"] != self.counters.get("wrong_length", 0):
            self._tell_refused_shape()
        self.counters.update(self.parser.counters)  # the parser refused other shapes
        for k in range(0, len(frames), self.batch_frames):
            part = frames[k : k + self.batch_frames]
            # u64 counters keep their bits in int64 (2**63 and above read as negative numbers).
            seq = np.array([f.sequence for f in part], np.uint64).view(np.int64)
            stamp_ns = np.array([f.timestamp_ns for f in part], np.uint64)
            arrival = np.full(len(part), arrival_s)
            if self.channel_map is None:
                samples = np.stack([f.samples[self.channel] for f in part])
                yield ShotBatch(seq, stamp_ns / 1e9, arrival, samples)
            else:
                m = self.channel_map
                samples, aux = m.unpack(np.stack([f.samples[: m.frame_channels] for f in part]))
                yield ShotBatch(seq, stamp_ns / 1e9, arrival, samples, aux)

    def _reopen(self, last_byte: float) -> bool:
        """Reopen the link, pausing longer after each failure; False when the source is closed
        or the idle timeout passes first."""
        pause = _BACKOFF_S[0]
        while True:
            with self._lock:
                if self._stop:
                    return False
            idle = time.perf_counter() - last_byte
            if self.idle_timeout_s is not None and idle > self.idle_timeout_s:
                self.stop_reason = f"no bytes for {self.idle_timeout_s:g} s (link down)"
                return False
            try:
                with self._lock:
                    self._open()
            except (serial.SerialException, OSError, ValueError):
                time.sleep(pause)
                pause = min(2 * pause, _BACKOFF_S[1])
                continue
            self.counters["reconnects"] += 1
            self._say(f"instrument link to {self.url} reopened")
            return True

    def __iter__(self) -> Iterator[ShotBatch]:
        last_byte = time.perf_counter()
        try:
            while True:
                with self._lock:
                    if self._stop or not self.port.is_open:
                        self.stop_reason = self.stop_reason or "closed"
                        break
                    self._reading = True
                try:
                    data = self._read()
                except (serial.SerialException, OSError) as exc:
                    data = None
                    lost = str(exc) or type(exc).__name__
                finally:
                    with self._lock:
                        self._reading = False
                now = time.perf_counter()
                if data is None:  # the link went away: the frames behind a cut one, then …
                    yield from self._batches(self.parser.finish(), now)
                    self.counters["link_drops"] += 1
                    with self._lock:
                        stopping = self._stop
                        self.port.close()
                    if stopping:
                        self.stop_reason = "closed"
                        break
                    if not self.reconnect:
                        self.stop_reason = self.failure = f"instrument link lost: {lost}"
                        self._say(self.failure)
                        break
                    self._say(f"instrument link lost ({lost}); reconnecting")
                    if not self._reopen(last_byte):
                        self.failure = self.failure or (
                            None if self._stop else f"instrument link lost: {lost}"
                        )
                        break
                    continue
                if not data:
                    if self.idle_timeout_s is not None and now - last_byte > self.idle_timeout_s:
                        self.stop_reason = f"no bytes for {self.idle_timeout_s:g} s"
                        break
                    continue
                last_byte = now
                yield from self._batches(self.parser.feed(data), now)
            yield from self._batches(self.parser.finish(), time.perf_counter())
        finally:
            with self._lock:
                self.port.close()

    def close(self) -> None:
        """Stop iterating (within ``poll_s``) and close the port."""
        with self._lock:
            super().close()
            # A read in progress in the iterating thread closes the port itself when it returns.
            if not self._reading:
                self.port.close()
