"""A swath worker's loop (rtsar.stream.swath): take the setup, then pulse blocks, send lines back.

The coordinator can vanish two ways while a worker waits on it, and the worker ends on both
within its coordinator timeout (one line through ``log``, status 1):

* silence on the pulse socket: after the setup the coordinator beats to an idle worker every
  ``BEAT_S``, so no block and no beat for the timeout means it is gone;
* a send of lines that cannot go out: the coordinator stopped taking results (its downstream
  stalls: a wait without limit, as long as it lives) and the connection to it went down (closed
  by its death, or ZeroMQ's own heartbeat timed out on a lost host) and stayed down for the
  timeout.  The connection's state comes from a ZeroMQ socket monitor.
"""

from __future__ import annotations

import json
import os
import time
from collections import deque

import numpy as np
import zmq
from zmq.utils.monitor import recv_monitor_message

from ..params import config_from_dict
from .engine import Lines
from .swath import COORDINATOR_TIMEOUT_S, HWM_MESSAGES, SwathEngine, _json

LINK_BEAT_MS = 1000  # ZeroMQ heartbeat on the results connection (a host lost without a close)
NO_SETUP_TOLD_S = 10.0  # a worker with no setup after this long says so (once)
LINK_TIMEOUT_MS = 5000


class CoordinatorGone(Exception):
    """The coordinator no longer takes this worker's messages (the reason in words)."""


class Stopped(Exception):
    """The coordinator sent ``stop``: its run failed or was given up (the reason in words)."""


class _Inbox:
    """The worker's pulse socket.  While a send of lines waits, what arrives is read early (up
    to the high-water mark, so flow control holds) to see a ``stop``; the rest is handled
    afterwards, in order."""

    def __init__(self, ctx, endpoint: str):
        self.socket = s = ctx.socket(zmq.PAIR)  # the coordinator's takes one worker per index
        s.setsockopt(zmq.RCVHWM, HWM_MESSAGES)
        s.connect(endpoint)
        self._early: deque = deque()

    def poll(self, timeout_ms: int) -> bool:
        return bool(self._early) or bool(self.socket.poll(timeout_ms))

    def recv(self) -> list[bytes]:
        return self._early.popleft() if self._early else self.socket.recv_multipart(copy=True)

    def look_for_stop(self) -> None:
        """Raise Stopped if a ``stop`` has come (called while a send waits)."""
        while len(self._early) < HWM_MESSAGES and self.socket.poll(0):
            frames = self.socket.recv_multipart(copy=True)
            if frames[0] == b"stop":
                raise Stopped(_reason(frames))
            self._early.append(frames)


def _reason(frames: list[bytes]) -> str:
    return frames[1].decode("utf-8", "replace") if len(frames) > 1 else "no reason given"


class _Results:
    """The worker's PUSH of results to the coordinator, with the state of its connection."""

    def __init__(self, ctx, endpoint: str, timeout_s: float):
        self.socket = s = ctx.socket(zmq.PUSH)
        s.setsockopt(zmq.LINGER, 10_000)
        s.setsockopt(zmq.SNDHWM, HWM_MESSAGES)  # lines queue no deeper than pulses do
        s.setsockopt(zmq.HEARTBEAT_IVL, LINK_BEAT_MS)
        s.setsockopt(zmq.HEARTBEAT_TIMEOUT, LINK_TIMEOUT_MS)
        self._monitor = s.get_monitor_socket(zmq.EVENT_CONNECTED | zmq.EVENT_DISCONNECTED)
        s.connect(endpoint)
        self.endpoint, self.timeout_s = endpoint, timeout_s
        self._down_since = time.monotonic()  # not connected yet
        self.waiting = None  # called while a send waits (the inbox's look for a stop)

    def _read_events(self) -> None:
        while self._monitor.poll(0):
            event = recv_monitor_message(self._monitor)["event"]
            if event == zmq.EVENT_CONNECTED:
                self._down_since = None
            elif event == zmq.EVENT_DISCONNECTED and self._down_since is None:
                self._down_since = time.monotonic()

    def send(self, frames: list) -> None:
        """Send, waiting while the coordinator is connected (however long it takes); raise
        CoordinatorGone once the connection has been down for the timeout (0: wait)."""
        while not self.socket.poll(200, zmq.POLLOUT):
            if self.waiting is not None:
                self.waiting()
            self._read_events()
            down = self._down_since
            if self.timeout_s > 0 and down is not None:
                if time.monotonic() - down >= self.timeout_s:
                    raise CoordinatorGone(
                        f"the connection to the coordinator {self.endpoint} has been down for "
                        f"{self.timeout_s:g} s while lines waited to go"
                    )
        self.socket.send_multipart(frames, zmq.NOBLOCK)

    def close(self, linger_ms: int | None = None) -> None:
        if linger_ms is not None:
            self.socket.setsockopt(zmq.LINGER, linger_ms)
        self.socket.disable_monitor()
        self._monitor.close(0)
        self.socket.close()


def serve(
    shots_endpoint: str,
    results_endpoint: str,
    index: int,
    log=None,
    parent_pid: int | None = None,
    coordinator_timeout_s: float = COORDINATOR_TIMEOUT_S,
) -> int:
    """A worker: connect, take the setup, process blocks until "end"; 0 on a clean end.

    Before the setup it waits for its coordinator without limit (it may start first).  After
    it, a coordinator silent (no block, no beat) for ``coordinator_timeout_s`` (0: no limit), or
    whose connection stays down that long while lines wait to go, is gone: the worker says so
    through ``log`` and returns 1, dropping what it still holds.
    ``parent_pid``: a worker started by a coordinator ends when that process is gone.
    """
    ctx = zmq.Context()
    pull = _Inbox(ctx, shots_endpoint)
    results = _Results(ctx, results_endpoint, coordinator_timeout_s)
    results.waiting = pull.look_for_stop
    # Queued until the connection is made: the coordinator learns a worker of this index has
    # started (a second one is refused there, in one line).
    results.socket.send_multipart([b"hello", json.dumps({"index": index}).encode()], zmq.NOBLOCK)
    started = time.monotonic()
    engine = None
    limit = coordinator_timeout_s > 0
    heard_at = None  # when the last message was handled (None: no setup yet)
    gone = False
    try:
        while True:
            wait_s = 1.0
            if heard_at is not None and limit:
                wait_s = min(wait_s, heard_at + coordinator_timeout_s - time.monotonic())
            if not pull.poll(max(1, int(1000 * wait_s))):
                orphan = parent_pid is not None and os.getppid() != parent_pid
                silent = limit and heard_at is not None
                silent = silent and time.monotonic() - heard_at >= coordinator_timeout_s
                if engine is None and log and started is not None:
                    if time.monotonic() - started >= NO_SETUP_TOLD_S:
                        started = None  # said once
                        log(
                            f"swath worker {index}: no setup from {shots_endpoint} after "
                            f"{NO_SETUP_TOLD_S:g} s: its coordinator has not started yet, or "
                            f"another worker with --index {index} has its pulses (waiting on)"
                        )
                if not (orphan or silent):
                    continue
                gone = True  # nobody to deliver to
                if silent and log:
                    log(
                        f"swath worker {index}: no word from the coordinator {results_endpoint} "
                        f"for {coordinator_timeout_s:g} s (it is gone or cut off); ending "
                        "(--coordinator-timeout)"
                    )
                return 1
            frames = pull.recv()
            kind = frames[0]
            if kind == b"setup":
                setup = _json(frames[1])
                config = config_from_dict(setup["config"])
                engine = SwathEngine(
                    config, tuple(setup["columns"]), setup["lens_backend"], setup["device"]
                )
                shape = (config.waveform.samples_per_shot,)
                hello = {"index": index, "lens": engine.lens.backend}
                results.send([b"ready", json.dumps(hello).encode()])
            elif kind == b"beat":
                pass  # the coordinator is alive: heard_at is all a beat carries
            elif kind == b"block":
                if engine is None:
                    raise ValueError("a pulse block came before the setup")
                head = _json(frames[1])
                count = int(head["count"])
                shots = None
                if not head["zero"]:
                    dtype = np.dtype(head["dtype"])
                    shots = np.frombuffer(frames[2], dtype).reshape(count, *shape)
                _send_lines(results, index, engine.push(shots, count))
            elif kind == b"stop":  # the run failed or was given up: nothing to deliver to
                raise Stopped(_reason(frames))
            elif kind == b"end":
                _send_lines(results, index, engine.flush())
                results.send([b"done", json.dumps({"index": index}).encode()])
                return 0
            heard_at = time.monotonic()  # after the work: a long setup or block is no silence
    except Stopped as exc:
        gone = True
        if log:
            log(f"swath worker {index}: the coordinator stopped the run ({exc}); ending")
        return 1
    except CoordinatorGone as exc:
        gone = True
        if log:
            log(f"swath worker {index}: {exc}; ending (--coordinator-timeout)")
        return 1
    except Exception as exc:  # told to the coordinator, which stops the run with it
        try:
            results.send([b"error", json.dumps({"index": index, "message": f"{exc}"}).encode()])
        except CoordinatorGone:
            gone = True
        if log:
            log(f"swath worker {index}: {exc}")
        return 1
    finally:
        pull.socket.close(0)
        results.close(0 if gone else None)
        ctx.term()


def _send_lines(results: _Results, index: int, out: Lines) -> None:
    if len(out.lines):
        head = {"index": index, "first_line": out.first_line, "count": len(out.lines)}
        results.send([b"lines", json.dumps(head).encode(), out.lines.tobytes()])
