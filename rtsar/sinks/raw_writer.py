"""The recorder process of ``rtsar run --record``: it writes the raw shots' file, nothing else.

h5py serialises every HDF5 call of a process behind one lock: a recording written by a thread
of the run held that lock through each slow write, and the run's image writer (``-o``) waited
on it (a 16-line image write waited 3.2 s behind a 2 MB/s disk; the run dropped 2,016 pulses).
So the recording is written here, in a process of its own with its own HDF5 library: the run
hands its blocks over a pipe (rtsar.sinks.raw_pipe) from a thread that may wait on the pipe,
never on this process's writes (rtsar.sinks.raw_record).

Messages in: ``("init", settings)`` first, then ``("pulses", Shots)`` and ``("drop", first,
count)`` in stream order, ``("end", counters, complete)`` last.  Messages out:
``("done", items, lost)`` (the next ``items`` messages in have been handed to HDF5 (their
queue room is free), or lost when ``lost``), ``("saved", written, dropped)`` (the file's counts
of shot rows and of rows marked not recorded that are sure to be on disk: after each flush, a
failure and the close; a reader of the file finds at least these, and exactly these once the
file is closed), ``("failed", path, reason, kept)`` once when the disk refuses a write (the
recording ends; every later message is answered as lost), ``("closed",)`` after the file is
closed.
The run's death closes the pipe: what was received is written and the file is closed, marked
incomplete (``complete`` False), as a run that never sent its end.  Terminal signals (Ctrl-C,
SIGHUP, SIGTERM) are the run's to handle: this process ends when its pipe does.

The file itself, its datasets and attributes: rtsar.sinks.raw_file.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import traceback
from collections import deque

from .h5_output import WriteFailed
from .raw_file import RawFile, _Dropped
from .raw_pipe import receive, send

ROUND_S, ROUND_BYTES = 0.1, 4 << 20  # a round waits this long for this much (fewer HDF5 calls)
TAKE_BYTES = 32 << 20  # the most one round of writes takes


class Writer:
    """Read the run's messages (a thread), write them in rounds (the main thread)."""

    def __init__(self, fd_in: int, fd_out: int, claim_fd: int | None):
        self.stream = os.fdopen(fd_in, "rb", buffering=0)
        self.fd_out = fd_out
        self.claim_fd = claim_fd
        self.file: RawFile | None = None
        self.items: deque = deque()
        self.bytes = 0
        self.cond = threading.Condition()
        self.ending = False
        self.final = {"counters": {}, "complete": False}
        self.failed = False
        self._send_lock = threading.Lock()
        self._told_saved = (0, 0)

    def tell(self, message) -> None:
        with self._send_lock:
            try:
                send(self.fd_out, message)
            except OSError:  # the run is gone: nobody to tell
                pass

    # ---- the reader thread -------------------------------------------------------------------
    def read(self) -> None:
        try:
            while True:
                message = receive(self.stream)
                kind = message[0]
                if kind == "init":
                    self.file = RawFile(claim_fd=self.claim_fd, **message[1])
                    continue
                with self.cond:
                    if kind == "end":
                        self.final = {"counters": message[1], "complete": message[2]}
                        break
                    item = message[1] if kind == "pulses" else _Dropped(*message[1:])
                    if self.failed:
                        self.tell(("done", 1, True))
                        continue
                    self.items.append(item)
                    self.bytes += item.nbytes
                    self.cond.notify()
        except EOFError:  # the run died (or closed the pipe without its end): complete False
            pass
        finally:
            with self.cond:
                self.ending = True
                self.cond.notify()

    # ---- the writer (main thread) -------------------------------------------------------------
    def run(self) -> None:
        reader = threading.Thread(target=self.read, name="rtsar-record-read", daemon=True)
        reader.start()
        flush_s = 0.5
        while True:
            with self.cond:
                while not self.items and not self.ending:
                    if self.file is not None:
                        flush_s = self.file.flush_every_s
                    self.cond.wait(flush_s)
                    if self.file is not None and self.file.due():
                        break
                if self.items and self.bytes < ROUND_BYTES:  # a few larger writes
                    self.cond.wait_for(lambda: self.ending or self.bytes >= ROUND_BYTES, ROUND_S)
                items, size = self._take()
                ending = self.ending and not self.items
            if items:
                self._write(items)
            with self.cond:
                self.bytes -= size
            if self.file is not None and not self.failed:
                self._guarded(self.file.flush_if_due)
            self._tell_saved()
            if ending:
                break
        reader.join()
        if self.file is not None and not self.failed:
            self._guarded(lambda: self.file.close(**self.final))
        if self.file is not None:
            self.file.release()
        self._tell_saved()
        self.tell(("closed",))

    def _tell_saved(self) -> None:
        """The counts sure to be on disk, when they changed (rtsar.sinks.raw_file.RawFile)."""
        if self.file is not None and self.file.saved != self._told_saved:
            self._told_saved = self.file.saved
            self.tell(("saved", *self._told_saved))

    def _take(self) -> tuple[list, int]:
        items, size = [], 0
        while self.items and (not items or size < TAKE_BYTES):
            item = self.items.popleft()
            items.append(item)
            size += item.nbytes
        return items, size

    def _write(self, items: list) -> None:
        if self.failed:
            self.tell(("done", len(items), True))
            return
        ok = self._guarded(lambda: self.file.append(items))
        if ok:
            self.tell(("done", len(items), False))
        else:  # (what was queued behind them was answered by _guarded)
            self.tell(("done", len(items), True))

    def _guarded(self, work) -> bool:
        """Run a write; a failed one ends the recording: told once, every item still queued
        answered as lost, and every later one as it comes."""
        try:
            work()
            return True
        except WriteFailed as exc:
            with self.cond:
                self.failed = True
                queued = len(self.items)
                self.items.clear()
                self.bytes = 0
            if self.file is not None:  # (every row is on disk if its one close went through)
                self.file.note_saved()
                self._tell_saved()
            self.tell(("failed", str(exc.path), exc.reason, exc.kept))
            if queued:
                self.tell(("done", queued, True))
            return False


def main(argv: list[str]) -> int:
    for name in ("SIGINT", "SIGHUP", "SIGTERM"):  # the run's to handle (module docstring)
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), signal.SIG_IGN)
    fd_in, fd_out = int(argv[0]), int(argv[1])
    claim_fd = int(argv[2]) if len(argv) > 2 and int(argv[2]) >= 0 else None
    writer = Writer(fd_in, fd_out, claim_fd)
    try:
        writer.run()
    except BaseException as exc:  # a bug, not a disk: told to the run in one line, traced here
        traceback.print_exc()
        path = "" if writer.file is None else str(writer.file.path)
        writer.tell(("failed", path, f"the recorder process failed: {exc!r}", ""))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
