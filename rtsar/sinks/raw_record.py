"""The raw shots of a live run, kept while it images (``rtsar run --record RAW.h5``).

A live scan could only be focused once, live; its recording lets it be focused again (another
correction, PGA, window, correlator) with ``rtsar process RAW.h5`` or ``rtsar replay RAW.h5``,
which give the live run's image.  What is recorded is the stream as ingest made it (rtsar.stream
.ingest): one row per pulse of the stream, in order, every channel the source delivers, the
zero pulses ingest inserted (gaps, restarts) and the shots it zeroed (NaN/Inf, wrong length)
where the live run had them; so the file is an ordinary recording
(docs/pages/reference/files.md) whose ``pulse_index`` counts the stream's pulses, and the
instrument's own numbers and clock are kept beside it:

* ``/instrument_seq`` int64 [pulse]: the instrument's pulse counter (u64 bits; 0 where none);
* ``/instrument_time_s`` float64 [pulse]: the instrument's clock (NaN where none);
* ``/pulse_flags`` uint8 [pulse]: 1 a zero pulse ingest inserted (no shot), 2 a shot ingest
  zeroed, 4 not recorded: the recorder's queue was full (``record_dropped``; its rows read as
  zeros, nothing of them was written).

The file is written by a process of its own (rtsar.sinks.raw_writer: h5py serialises every
HDF5 call of a process behind one lock, so a slow recording written by a thread stalled the
run's image writer) behind a queue bounded in bytes (``queue_bytes``; default
:func:`record_queue_bytes`; the bytes queued here and those handed to the process and not yet
written): the pipeline hands each block over without waiting, a thread here passes the blocks
on through a pipe, so a slow disk never stalls the imaging; a block that does not fit is not
recorded, counted (``record_dropped``) and marked.  A failed write (a full disk) ends the
recording, not the run: said at once through ``notify``, the rest counted as dropped; so does
the recorder process's death (killed: its file keeps the shots up to its last flush).  The
process ends with its pipe: a run killed at any moment leaves it to write what it received and
close the file, marked incomplete.  The file is crash-safe like the
live image (rtsar.sinks.live_file): a SIGKILL leaves a readable file with every shot up to its
last flush (every ``flush_every_s``).  Final attributes: ``complete`` (True only when the run's
end came and every pulse handed over has its row: none dropped), ``counters`` (JSON, the run's;
its ``record_*`` entries the file's own), ``record_written``, ``record_dropped``,
``record_dropped_runs`` (JSON [[first pulse, count], ...], the first :data:`MAX_RUNS_LISTED`).

What the run counts is what a reader of the file finds: ``record_written`` counts the rows the
process has confirmed on disk (flushed, or in the closed file), never rows merely handed to
HDF5; ``record_dropped`` the pulses sure not to be recorded.  Once the recording has ended,
``record_unconfirmed`` counts the rest: pulses handed over whose rows the process never
confirmed, because it died or was given up on (the file may hold some of them: then
``record_written`` is a lower bound); 0 after a clean close.  A stop (``hurry``: Ctrl-C, a
signal, the end of ``--duration``) gives the recording :data:`HURRY_S` to finish; a process
that has not finished by then (a hung disk) is killed, and the run goes on to its end.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import threading
import time
from collections import deque
from pathlib import Path

from ..child import module_argv
from ..params import Config
from ..stream.strips import StreamInfo, StripSink
from .h5_output import WriteFailed
from .name_claim import NameClaim
from .raw_file import (  # noqa: F401 (the file's constants, where they were)
    FLAGS_MEANING,
    INSERTED,
    MAX_RUNS_LISTED,
    NOT_RECORDED,
    ZEROED,
    Shots,
    _Dropped,
    add_run,
)
from .raw_pipe import receive, send, widen

QUEUE_S = 2.0  # seconds of the stream's main-channel shots the recorder's queue holds …
QUEUE_BYTES = (16 << 20, 256 << 20)  # … within these bounds
SEND_ITEMS = 64  # the most blocks passed on to the recorder process at one look
HURRY_S = 5.0  # after a stop, the most the recording is waited for; then its process is killed
GONE_S = 2.0  # after that kill, the most its pipes are waited on (a process stuck in the kernel)


def record_queue_bytes(config: Config) -> int:
    """The recorder's queue: :data:`QUEUE_S` seconds of main-channel shots at the PRF, within
    :data:`QUEUE_BYTES` (at psaltis-max, 10 kHz × 1800 samples: 256 MiB, 1.9 s)."""
    per_s = config.geometry.prf_hz * config.waveform.samples_per_shot * 8
    low, high = QUEUE_BYTES
    return int(min(high, max(low, QUEUE_S * per_s)))


def _writer_env() -> dict:
    """The recorder process runs this rtsar (the folder it was imported from comes first)."""
    env = dict(os.environ)
    root = str(Path(__file__).resolve().parents[2])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    return env


class ShotRecorder(StripSink):
    """Pipeline sink that records the pulse stream to ``path`` (module docstring).

    The name is claimed now (a second live writer of it is refused before any work) and the
    recorder process started (it does not wait for it: its start, ~0.3 s of imports, overlaps
    the run's); the file is made with the first pulses (their channels fix its datasets).
    ``notify``: one-line messages (a failed write).  ``close()`` ends it if the run's ``end``
    never came, within :data:`HURRY_S`."""

    wants_pulses = True
    ends_first = True  # the end message carries the rows the file got

    def __init__(
        self,
        path: str | Path,
        config: Config,
        scene: dict | None = None,
        source: str = "",
        start_along_track_m: float = 0.0,
        queue_bytes: int | None = None,
        flush_every_s: float = 0.5,
        notify=None,
    ):
        self.path = Path(path)
        self.capacity = int(queue_bytes or record_queue_bytes(config))
        self.notify = notify
        self._claim: NameClaim | None = NameClaim(self.path)
        self._items: deque = deque()  # blocks and drops not yet passed on
        self._sent: deque = deque()  # (first, count, nbytes, is a drop) passed on, not done
        self._bytes = 0  # bytes queued here or passed on and not yet written
        self._cond = threading.Condition()
        self._ending = False
        self._final: tuple | None = None
        self.written = 0  # pulses whose rows are confirmed on disk (shots, inserted zeros)
        self.dropped = 0  # pulses sure not to be recorded
        self.unconfirmed = 0  # at the end: pulses handed over, neither (module docstring)
        self.dropped_runs: list[list[int]] = []
        self.failure: WriteFailed | None = None
        self.gave_up = False  # killed after HURRY_S
        self._hurried_s: float | None = None  # when the run asked to hurry (monotonic)
        self._finishing_s = 0.0  # when finish() began (monotonic)
        self._heard_s = time.monotonic()  # the process's last answer
        self._ended: dict | None = None  # the final counters, once the recording has ended
        self._listened = threading.Event()  # the process's answers have all been read
        self._next_pulse = 0  # the stream's next pulse (checks the order)
        settings = {
            "path": str(self.path),
            "config": config.to_dict(),
            "scene": scene or {},
            "source": source,
            "start_along_track_m": float(start_along_track_m),
            "flush_every_s": float(flush_every_s),
            "claim_mark": str(self._claim.path),
        }
        self._settings = settings
        self._proc, self._fd_out, self._fd_in = self._start(self._claim.fd)
        self._feeder = threading.Thread(target=self._feed, name="rtsar-record", daemon=True)
        self._listener = threading.Thread(target=self._listen, name="rtsar-record-in", daemon=True)
        self._feeder.start()
        self._listener.start()

    def _start(self, claim_fd: int | None):
        """The recorder process, its pipes (to it, from it) and the claim's lock passed on."""
        to_r, to_w = os.pipe()
        from_r, from_w = os.pipe()
        widen(to_w)
        keep = (to_r, from_w) + (() if claim_fd is None else (claim_fd,))
        argv = module_argv("rtsar.sinks.raw_writer", str(to_r), str(from_w))
        argv.append(str(-1 if claim_fd is None else claim_fd))
        try:
            proc = subprocess.Popen(
                argv, pass_fds=keep, stdin=subprocess.DEVNULL, env=_writer_env()
            )
        except OSError as exc:
            for fd in (to_r, to_w, from_r, from_w):
                os.close(fd)
            self._claim.release()
            raise ValueError(f"cannot record {self.path}: {exc}") from None
        os.close(to_r)
        os.close(from_w)
        return proc, to_w, os.fdopen(from_r, "rb", buffering=0)

    # ---- the pipeline's side (never waits) -------------------------------------------------
    def pulses(self, block, info: StreamInfo) -> None:
        n = len(block)
        if not n:
            return
        if block.first_pulse != self._next_pulse:
            raise RuntimeError("the recorder was handed pulses out of order")
        self._next_pulse += n
        nbytes = _nbytes(block)
        with self._cond:
            fits = self._bytes + nbytes <= self.capacity or not self._bytes
            if self.failure is None and not self._ending and fits:
                self._items.append((block, nbytes, getattr(info, "collection_start_utc", None)))
                self._bytes += nbytes
                self._cond.notify_all()
            else:
                self._drop(block.first_pulse, n, mark=self.failure is None)

    def _drop(self, first: int, count: int, mark: bool) -> None:
        """Pulses not recorded: counted, listed, and (``mark``: while the file lives) marked in
        it.  Called with the lock held."""
        self.dropped += count
        add_run(self.dropped_runs, first, count)
        if mark:
            last = self._items[-1] if self._items else None
            if isinstance(last, _Dropped) and last.first + last.count == first:
                last.count += count
            else:
                self._items.append(_Dropped(first, count))
                self._cond.notify_all()

    def has_room(self, nbytes: int) -> bool:
        """Whether a block of ``nbytes`` would be queued now (``rtsar bench`` waits on it)."""
        with self._cond:
            return self._bytes + nbytes <= self.capacity or not self._bytes

    def counters(self) -> dict:
        """``record_written``, ``record_dropped``; once ended, ``record_unconfirmed`` too (their
        final values: module docstring)."""
        if self._ended is not None:
            return dict(self._ended)
        return {"record_written": self.written, "record_dropped": self.dropped}

    def end(self, stats: dict, info: StreamInfo) -> None:
        self.finish(stats.get("counters", {}))

    def hurry(self) -> None:
        """The run is being stopped: the recording has :data:`HURRY_S` from now to finish."""
        with self._cond:
            if self._hurried_s is None:
                self._hurried_s = time.monotonic()
            self._cond.notify_all()

    def finish(self, counters: dict | None = None, complete: bool = True) -> None:
        """Write what is queued, close the file with the final attributes, release the name;
        once hurried, give up after HURRY_S (the process killed).  A failure is kept in
        ``failure`` (and was told through ``notify``, but for the giving up: the run's end
        tells it).  A second call returns at once."""
        if self._ended is not None:
            return
        with self._cond:
            if not self._ending:
                self._final = ("end", counters or {}, complete)
                self._ending = True
                self._finishing_s = time.monotonic()
            self._cond.notify_all()
        if not self._settled():
            self._give_up()
        with self._cond:  # (the process released it, or died holding it)
            claim, self._claim = self._claim, None
        if claim is not None:
            claim.release()
        with self._cond:
            self.unconfirmed = self._next_pulse - self.written - self.dropped
            self._ended = {
                "record_written": self.written,
                "record_dropped": self.dropped,
                "record_unconfirmed": self.unconfirmed,
            }

    def close(self) -> None:
        """End the recording if the run's end never came (it stays marked incomplete), within
        :data:`HURRY_S`."""
        self.hurry()
        self.finish(complete=False)

    def _settled(self) -> bool:
        """Wait for the process to close the file and end (polled: a hurry may come meanwhile);
        False once hurried and HURRY_S have passed since the hurry and since the end began (a
        run that took long to drain its pipeline still gives the recording its HURRY_S)."""
        told = False
        while not self._listened.wait(0.05):
            hurried, now = self._hurried_s, time.monotonic()
            if hurried is not None:
                if now - max(hurried, self._finishing_s) >= HURRY_S:
                    return False
            elif not told and now - max(self._heard_s, self._finishing_s) >= HURRY_S:
                told = True  # (a run that ends by itself waits for its recording: says so)
                if self.notify is not None:
                    self.notify(
                        f"rtsar: waiting for --record {self.path} to finish (its process has "
                        f"not answered for {HURRY_S:g} s); Ctrl-C gives it up {HURRY_S:g} s later"
                    )
        self._feeder.join(GONE_S)  # (its pipe's reader has gone: it ends)
        try:
            self._proc.wait(GONE_S)  # (its pipe is closed: it is exiting)
        except subprocess.TimeoutExpired:
            self._kill()
        return True

    def _kill(self) -> None:
        with contextlib.suppress(OSError):  # (gone already)
            self._proc.kill()

    def _give_up(self) -> None:
        """The stop's deadline passed: the process is killed; what it never confirmed stays
        unconfirmed (the file may hold some of it), what it was never handed is dropped."""
        with self._cond:
            self.gave_up = True
            if self.failure is None:
                self.failure = WriteFailed(
                    self.path,
                    f"the recording did not finish within {HURRY_S:g} s of the stop (a stuck "
                    "disk?): its process was killed",
                    "the shots up to its last flush are saved, marked incomplete "
                    "(complete = False)",
                )
            self._drop_queued()
        self._kill()
        # Its pipes break with it, and the answers it sent before are still read; a process
        # stuck in the kernel (a dead disk) dies only when its write returns: not waited for.
        self._listened.wait(GONE_S)
        self._feeder.join(GONE_S)
        try:
            self._proc.wait(GONE_S)
        except subprocess.TimeoutExpired:
            pass

    def _drop_queued(self) -> None:
        """What is queued here will never be passed on: not recorded.  Called with the lock."""
        for x in self._items:
            if not isinstance(x, _Dropped):  # (a drop is counted already)
                self._drop(x[0].first_pulse, len(x[0]), mark=False)
                self._bytes -= x[1]
        self._items.clear()

    # ---- the threads that talk to the recorder process -------------------------------------
    def _feed(self) -> None:
        """Pass the queued blocks on, in order, then the end (rtsar.sinks.raw_writer)."""
        try:
            send(self._fd_out, ("init", self._settings))
            while True:
                with self._cond:
                    self._cond.wait_for(lambda: self._items or self._ending or self.failure)
                    if not self._items or self.failure is not None:
                        break
                    take = min(SEND_ITEMS, len(self._items))
                    items = [self._items.popleft() for _ in range(take)]
                    for x in items:  # before the send: its answer cannot come before it
                        drop = isinstance(x, _Dropped)
                        first, count = (x.first, x.count) if drop else (x[0].first_pulse, len(x[0]))
                        self._sent.append((first, count, 0 if drop else x[1], drop))
                for x in items:
                    if isinstance(x, _Dropped):
                        send(self._fd_out, ("drop", x.first, x.count))
                    else:
                        send(self._fd_out, ("pulses", Shots.of(x[0], x[2])))
            send(self._fd_out, self._final or ("end", {}, False))
        except OSError:  # the process is gone (its pipe broken): _listen tells it
            pass
        finally:
            os.close(self._fd_out)

    def _listen(self) -> None:
        """The process's answers: blocks handed to HDF5 or lost, rows saved, a failure, its end;
        its death."""
        try:
            self._answers()
        finally:
            self._listened.set()

    def _answers(self) -> None:
        closed = False
        try:
            while True:
                message = receive(self._fd_in)
                self._heard_s = time.monotonic()
                if message[0] == "done":
                    self._done(message[1], lost=message[2])
                elif message[0] == "saved":
                    with self._cond:
                        if self._ended is None:  # (given up: the counts are final)
                            self.written = int(message[1])
                elif message[0] == "failed":
                    self._fail(WriteFailed(message[1] or self.path, message[2], message[3]))
                elif message[0] == "closed":
                    closed = True
        except (EOFError, OSError):
            pass
        finally:
            self._fd_in.close()
        if not closed and self.failure is None:  # killed, or died before its end
            code = self._proc.wait()
            how = f"signal {-code}" if code < 0 else f"exit status {code}"
            kept = "the shots up to its last flush are saved, marked incomplete (complete = False)"
            self._fail(WriteFailed(self.path, f"the recorder process ended ({how})", kept))
        with self._cond:  # passed on, never answered: their room is free, their fate unknown
            self._bytes -= sum(nbytes for _, _, nbytes, _ in self._sent)
            self._sent.clear()
            self._cond.notify_all()

    def _done(self, items: int, lost: bool) -> None:
        """The next ``items`` blocks passed on are in HDF5's hands (counted once ``saved``
        says so), or ``lost`` (not recorded)."""
        with self._cond:
            for _ in range(min(items, len(self._sent))):
                first, count, nbytes, drop = self._sent.popleft()
                self._bytes -= nbytes
                if not drop and lost and self._ended is None:
                    self._drop(first, count, mark=False)
            self._cond.notify_all()

    def _fail(self, exc: WriteFailed) -> None:
        """The recording ended (a write the disk refused, the process's death): said once; what
        is queued here is not recorded, nor anything after."""
        with self._cond:
            if self.failure is not None:
                return
            self.failure = exc
            self._drop_queued()
            self._cond.notify_all()
        if self.notify is not None:
            self.notify(
                f"rtsar: --record {self.path} stopped: {exc}; the image goes on, the shots not "
                "written are counted (record_dropped)"
            )


def _nbytes(block) -> int:
    """Bytes a block holds in the queue (a block of inserted zero pulses: none)."""
    if block.inserted is not None and block.inserted.all():
        return 0
    return block.samples.nbytes + sum(a.nbytes for a in block.aux.values())
