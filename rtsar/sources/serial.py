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
from .frame import MAX_PAYLOAD_BYTES, Frame, FrameParser

_READ_BYTES = 1 << 18  # most bytes taken in one read


class SerialSource(Source):
    """Shots from frames arriving on ``url``: channel ``channel`` of each frame, in batches.

    A batch is yielded as soon as a read completes at least one frame (at most ``batch_frames``
    per batch); ``arrival_s`` is the perf_counter time at which that read returned.  Frames
    without ``samples_per_shot`` samples or without the channel are counted in
    ``counters["wrong_length"]`` and not yielded; the parser's counters
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
    ):
        super().__init__()
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
        self.url = url
        self.samples_per_shot = int(samples_per_shot)
        self.batch_frames = int(batch_frames)
        self.idle_timeout_s = idle_timeout_s
        self.channel = int(channel)
        self.poll_s = float(poll_s)
        self.parser = FrameParser(max_payload_bytes)
        self.counters = dict(self.parser.counters, wrong_length=0)
        self.description = f"serial instrument at {url}"
        self.stop_reason: str | None = None
        self._lock = threading.Lock()
        self._reading = False
        try:
            # Non-blocking reads: waiting is done by select() on the descriptor where there is
            # one, so a read returns whatever has arrived instead of waiting to fill a size.
            self.port = serial.serial_for_url(url, baudrate=baudrate, timeout=0)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ValueError(f"cannot open instrument port {url!r}: {exc}") from None
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

    def _batches(self, frames: list[Frame], arrival_s: float) -> Iterator[ShotBatch]:
        keep = [
            f
            for f in frames
            if f.samples.shape[1] == self.samples_per_shot and f.samples.shape[0] > self.channel
        ]
        self.counters["wrong_length"] += len(frames) - len(keep)
        for k in range(0, len(keep), self.batch_frames):
            part = keep[k : k + self.batch_frames]
            # u64 counters keep their bits in int64 (2**63 and above read as negative numbers).
            seq = np.array([f.sequence for f in part], np.uint64).view(np.int64)
            stamp_ns = np.array([f.timestamp_ns for f in part], np.uint64)
            samples = np.stack([f.samples[self.channel] for f in part])
            yield ShotBatch(seq, stamp_ns / 1e9, np.full(len(part), arrival_s), samples)

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
                    self.stop_reason = f"link closed: {exc}"
                    break
                finally:
                    with self._lock:
                        self._reading = False
                now = time.perf_counter()
                if not data:
                    if self.idle_timeout_s is not None and now - last_byte > self.idle_timeout_s:
                        self.stop_reason = f"no bytes for {self.idle_timeout_s:g} s"
                        break
                    continue
                last_byte = now
                frames = self.parser.feed(data)
                self.counters.update(self.parser.counters)
                yield from self._batches(frames, now)
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
