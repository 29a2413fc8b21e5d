"""Messages between a live run and its recorder process (rtsar.sinks.raw_record, raw_writer).

A message is any picklable object; its NumPy arrays travel out of band (pickle protocol 5):
written from their own memory to the pipe and read into fresh buffers, never copied into the
pickle.  On the pipe: the pickle's length and the number of buffers (``<QI``), the pickle,
then each buffer as its length (``<Q``) and its bytes.  A pipe closed at the other end reads
as :class:`EOFError` (between messages or inside one: a writer that died mid-message).
"""

from __future__ import annotations

import fcntl
import os
import pickle
import struct

_HEAD = struct.Struct("<QI")
_SIZE = struct.Struct("<Q")
PIPE_BYTES = 1 << 20  # the pipe's buffer asked of Linux (fewer wake-ups at 144 MB/s)


def widen(fd: int) -> None:
    """Ask for a :data:`PIPE_BYTES` pipe buffer (Linux; elsewhere, or refused: the default)."""
    try:
        fcntl.fcntl(fd, getattr(fcntl, "F_SETPIPE_SZ", 1031), PIPE_BYTES)
    except OSError:
        pass


def _write_all(fd: int, data) -> None:
    view = memoryview(data).cast("B")
    while len(view):
        view = view[os.write(fd, view) :]


def send(fd: int, message) -> None:
    """Write one message (blocks while the pipe is full; BrokenPipeError: the reader is gone)."""
    buffers: list[pickle.PickleBuffer] = []
    body = pickle.dumps(message, protocol=5, buffer_callback=buffers.append)
    raws = [b.raw() for b in buffers]
    _write_all(fd, _HEAD.pack(len(body), len(raws)) + body)
    for raw in raws:
        _write_all(fd, _SIZE.pack(raw.nbytes))
        _write_all(fd, raw)


def _read_exact(stream, size: int) -> bytearray:
    data = bytearray(size)
    view, got = memoryview(data), 0
    while got < size:
        n = stream.readinto(view[got:])
        if not n:
            raise EOFError("the pipe was closed")
        got += n
    return data


def receive(stream):
    """Read one message from ``stream`` (an unbuffered binary file on the pipe); EOFError when
    the writer has closed it."""
    size, count = _HEAD.unpack(_read_exact(stream, _HEAD.size))
    body = _read_exact(stream, size)
    buffers = [
        _read_exact(stream, _SIZE.unpack(_read_exact(stream, _SIZE.size))[0]) for _ in range(count)
    ]
    return pickle.loads(body, buffers=buffers)
