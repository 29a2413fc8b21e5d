"""The range swath split across processes: each worker runs the AO lens and the shifting CCD of
its own range columns; the coordinator merges their lines.

Range bins are independent in the azimuth correlation (Psaltis & Wagner 1981, eq. 5: every CCD
column integrates its own range cell behind its own mask column), so K workers, each with the
CCD columns [b_k, b_{k+1}) of the mask, together compute exactly the single process's image.
Every worker compresses whole pulses (the range FFT needs all samples) and keeps its columns;
the lens is the cheap half (docs/pages/reference/performance.md), the CCD the expensive one.

Transport (ZeroMQ, one context per process):

* coordinator → worker k: a PAIR socket the coordinator binds, one per worker, so every worker
  gets every pulse block.  A PAIR socket takes one peer: a second worker started with the same
  ``--index`` is refused by it (with PUSH it took every other block, without a setup).  Its
  high-water mark (``HWM_MESSAGES``) is the flow control: when a worker falls behind, the
  coordinator's send blocks, the pipeline's shot queue fills and a live source drops (counted)
  as it does in one process.
* workers → coordinator: one PULL socket the coordinator binds; each worker PUSHes its lines.
  Anything may connect to it: every message is checked before it is obeyed
  (rtsar.stream.swath_messages); one that is malformed, of no worker of this run, or a second
  worker's with an index taken, is refused in one line (``notify``), counted
  (``swath_refused_messages``), and the run goes on.

Messages are multipart: ``[b"setup", JSON]`` (configuration, columns, lens choice), ``[b"block",
JSON {first_pulse, count, zero}, samples]``, ``[b"beat"]``, ``[b"end"]``, ``[b"stop", reason]``
(the run ended without an end: the worker drops what it holds and exits); back: ``[b"hello",
JSON {index}]`` (a worker has started), ``[b"ready", JSON]``, ``[b"lines", JSON {index,
first_line, count}, lines]``, ``[b"done", JSON]``, ``[b"error", JSON]``.  The same worker
loop (rtsar.stream.swath_worker.serve) runs in a local process (``rtsar run --swath-workers K``
spawns them) or on another host (``rtsar swath-worker --connect``).

Liveness (ZeroMQ reconnects silently: a worker cannot see its coordinator die): from its setup
on, a worker sent nothing for ``BEAT_S`` gets a ``beat`` (no pulses; sent without waiting, skipped
when the worker's queue is full); a worker that hears nothing for its coordinator timeout, or
whose connection to it stays down that long while it sends its lines, ends (swath_worker).
The converse, a worker taking no pulses, is the coordinator's stall error.
"""

from __future__ import annotations

import json
import os
import subprocess
import threading
import time
from collections import deque

import numpy as np
import zmq

from ..ccd import processor_correlator
from ..ccd.base import design_mask
from ..child import module_argv
from ..lens import make_lens, make_plan
from ..params import Config
from ..samples import precision_dtype
from .engine import Lines
from .swath_messages import Refused, parse

HWM_MESSAGES = 8  # pulse blocks in flight per worker before the coordinator waits
SEND_SLICE_S = 0.2  # a waiting send looks for an abort this often
READY_TIMEOUT_S = 120.0  # a worker's first start compiles numba kernels and builds OpenCL
BEAT_S = 1.0  # the coordinator beats to a worker it has sent nothing for this long
COORDINATOR_TIMEOUT_S = 30.0  # a worker that hears nothing for this long after its setup ends
MIN_COORDINATOR_TIMEOUT_S = 3 * BEAT_S  # below it a loaded coordinator's beats may come too late
STOP_LINGER_MS = 1000  # how long closing waits for a "stop" to leave
MAX_REFUSALS_TOLD = 5  # refused results messages told one by one (all are counted)


def split_columns(range_bins: int, workers: int) -> list[tuple[int, int]]:
    """[b_k, b_{k+1}) of each worker: contiguous, as equal as possible, none empty."""
    if not 1 <= workers <= range_bins:
        raise ValueError(f"swath workers must be 1 … {range_bins} (the range bins), got {workers}")
    edges = np.linspace(0, range_bins, workers + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def parse_bind(bind: str) -> tuple[str, int | None]:
    """``HOST`` → (HOST, None); ``tcp://HOST:PORT`` → (HOST, PORT)."""
    if not bind.startswith("tcp://"):
        return bind, None
    host, _, port = bind[len("tcp://") :].rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65535:
        raise ValueError(f"swath endpoint must be HOST or tcp://HOST:PORT, got {bind!r}")
    return host, int(port)


def worker_endpoints(connect: str, index: int) -> tuple[str, str]:
    """(pulses, results) endpoints of worker ``index`` of a coordinator bound at tcp://H:P."""
    host, port = parse_bind(connect)
    if port is None:
        raise ValueError(f"--connect needs tcp://HOST:PORT, got {connect!r}")
    return f"tcp://{host}:{port + 1 + index}", f"tcp://{host}:{port}"


def _bind(socket, host: str, port: int | None) -> str:
    try:
        if port is None:
            port = socket.bind_to_random_port(f"tcp://{host}")
        else:
            socket.bind(f"tcp://{host}:{port}")
    except zmq.ZMQError as exc:
        where = f"tcp://{host}:{port if port is not None else '*'}"
        raise ValueError(f"swath workers: cannot listen on {where}: {exc}") from None
    return f"tcp://{host}:{port}"


def worker_env(workers: int) -> dict:
    """The environment of a worker started here: the cores shared out among the workers, so
    that K workers' numba and PoCL thread pools do not each claim every core (measured with
    tools/placement.py at psaltis-max on 2 cores, 2 workers: 0.34x real time with the default
    pools, 0.77x with one thread each).  Settings the user made are kept."""
    env = dict(os.environ)
    threads = str(max(1, (os.cpu_count() or 1) // max(1, workers)))
    for name in ("NUMBA_NUM_THREADS", "POCL_CPU_MAX_CU_COUNT"):
        env.setdefault(name, threads)
    return env


def check_splittable(config: Config) -> None:
    """The configurations a swath split computes exactly; ValueError for the rest."""
    if config.processor.range_migration_taps:
        raise ValueError(
            "--swath-workers with range_migration_taps > 0 is not supported: the migration "
            "mask couples neighbouring range columns across the workers' boundaries"
        )


class SwathEngine:
    """One worker's half: the full AO lens, then the CCD of columns [b0, b1)."""

    def __init__(self, config: Config, columns: tuple[int, int], lens_backend="auto", device=None):
        check_splittable(config)
        self.plan = make_plan(config)
        p = config.processor
        self.lens = make_lens(self.plan, lens_backend, device, p.precision, p.micro_batch)
        b0, b1 = columns
        mask = design_mask(config, self.plan.range_m)[:, b0:b1]
        self.correlator = processor_correlator(config.processor, mask)
        self.columns = (b0, b1)
        self.lines_out = 0

    def push(self, shots: np.ndarray | None, count: int) -> Lines:
        """``count`` pulses (``shots`` None: zero pulses, no lens launch) → the lines completed."""
        b0, b1 = self.columns
        if shots is None:
            lines = np.zeros((count, b1 - b0), self.lens.dtype)
        else:
            lines = np.ascontiguousarray(self.lens.compress(shots)[:, b0:b1])
        return self._emit(self.correlator.push(lines))

    def flush(self) -> Lines:
        return self._emit(self.correlator.flush())

    def _emit(self, lines: np.ndarray) -> Lines:
        out = Lines(self.lines_out, lines)
        self.lines_out += len(lines)
        return out


def _json(frame: bytes) -> dict:
    return json.loads(frame.decode("utf-8"))


class SwathWorkers:
    """The coordinator's end: send every pulse block to K workers, merge their lines.

    ``bind``: ``HOST`` (random ports) or ``tcp://HOST:PORT``: the results socket on PORT and
    worker k's pulse socket on PORT + 1 + k, so workers on other hosts know where to connect
    (``rtsar swath-worker --connect tcp://HOST:PORT --index k``).  ``spawn``: start the K
    workers here (``python -m rtsar swath-worker``), over loopback.  ``timeout_s``: the longest
    wait for a worker to take pulses, or to finish after the end, before the run stops with an
    error.  ``beat_s``: the beat period (module docstring), kept by a thread of this object's
    own; a lock per worker socket keeps it off a send in progress.
    """

    def __init__(
        self,
        config: Config,
        workers: int,
        lens_backend: str = "auto",
        device: str | None = None,
        spawn: bool = True,
        bind: str = "127.0.0.1",
        timeout_s: float = 10.0,
        beat_s: float = BEAT_S,
        notify=None,
    ):
        check_splittable(config)
        self.notify = notify  # one-line messages: a results message refused
        self.refused = 0  # results messages refused (swath_messages)
        self.config = config
        self.columns = split_columns(config.processor.range_bins, workers)
        self.timeout_s = timeout_s
        self.beat_s = beat_s
        self._locks = [threading.Lock() for _ in self.columns]  # per worker socket
        #: When worker k was last sent anything (None: no setup yet, no beat).
        self._sent_at: list[float | None] = [None] * len(self.columns)
        self._beats_off = threading.Event()  # set: beat no more (end sent, or closing)
        self._beater: threading.Thread | None = None
        self.dtype = np.dtype(precision_dtype(config.processor.precision))
        self._ctx = zmq.Context()
        self._procs: list[subprocess.Popen] = []
        self._pushes, self.shot_endpoints = [], []
        self._results = None
        self._closed = False
        self._aborted = False
        #: Set (to when) while the consumer of ``receive`` waits on the stages after it: the
        #: workers then wait on their results and take no pulses, which is not their stall.
        self.downstream_since: float | None = None
        try:
            self._start(bind, spawn, lens_backend, device, timeout_s)
        except BaseException:
            self.close(wait_s=0.0)  # no worker or socket outlives a failed start
            raise

    def _start(self, bind, spawn, lens_backend, device, timeout_s) -> None:
        config = self.config
        host, base = parse_bind(bind)
        if base is not None and base + len(self.columns) > 65535:
            raise ValueError(f"--swath-bind port {base} + {len(self.columns)} workers > 65535")
        self._results = self._ctx.socket(zmq.PULL)
        self.results_endpoint = _bind(self._results, host, base)
        for k in range(len(self.columns)):
            s = self._ctx.socket(zmq.PAIR)  # one worker per index (module docstring)
            s.setsockopt(zmq.SNDHWM, HWM_MESSAGES)
            s.setsockopt(zmq.LINGER, 0)
            self._pushes.append(s)
            self.shot_endpoints.append(_bind(s, host, base and base + 1 + k))
        if spawn:
            count = len(self.columns)
            for k, endpoint in enumerate(self.shot_endpoints):
                cmd = module_argv("rtsar", "swath-worker", "--shots", endpoint)
                cmd += ["--results", self.results_endpoint, "--index", str(k)]
                cmd += ["--parent-pid", str(os.getpid())]
                # A session of their own: a terminal's Ctrl-C goes to the coordinator alone,
                # which ends the stream; the workers then flush their CCDs and finish.
                proc = subprocess.Popen(
                    cmd, stdin=subprocess.DEVNULL, start_new_session=True, env=worker_env(count)
                )
                self._procs.append(proc)
        self._pending = [deque() for _ in self.columns]  # per worker: Lines not merged yet
        self._done = [False] * len(self.columns)
        self._hello: set[int] = set()  # workers that said they started
        self._ready: set[int] = set()  # workers set up
        self._lines_in = [0] * len(self.columns)  # per worker: the line it sends next
        self._heard_at, self._ended_at = time.monotonic(), None
        self.lines_out = 0
        setup = {"config": config.to_dict(), "lens_backend": lens_backend, "device": device}
        deadline = time.monotonic() + READY_TIMEOUT_S
        # From its setup on, a worker hears at least every beat_s: worker 0 waits meanwhile for
        # the others to connect (started by hand on other hosts) and to build their engines.
        self._beater = threading.Thread(target=self._beat_loop, name="swath-beat", daemon=True)
        self._beater.start()
        for k, ((b0, b1), s) in enumerate(zip(self.columns, self._pushes, strict=True)):
            # A worker connects once its process has started (seconds on a loaded machine).
            while not s.poll(500, zmq.POLLOUT):
                self._check_alive()
                if time.monotonic() > deadline:
                    raise RuntimeError(
                        f"swath workers did not connect within {READY_TIMEOUT_S:g} s "
                        f"(pulses on {', '.join(self.shot_endpoints)})"
                    )
            with self._locks[k]:
                s.send_multipart([b"setup", json.dumps({**setup, "columns": [b0, b1]}).encode()])
                self._sent_at[k] = time.monotonic()
        while len(self._ready) < len(self.columns):
            self._take(self._recv(deadline, "to start"))

    def send(self, first_pulse: int, samples: np.ndarray, zero: bool) -> None:
        """One block of pulses to every worker (waits while a worker is HWM blocks behind)."""
        samples = np.ascontiguousarray(samples)
        head = {"first_pulse": first_pulse, "count": len(samples), "zero": zero}
        head["dtype"] = samples.dtype.str
        frames = [b"block", json.dumps(head).encode()]
        if not zero:
            frames.append(samples.tobytes())
        for k, s in enumerate(self._pushes):
            self._send(k, s, frames)

    def end(self) -> None:
        """No more pulses: the workers flush their CCDs and say they are done."""
        self._beats_off.set()  # a worker reads nothing after its "end"
        for k, s in enumerate(self._pushes):
            self._send(k, s, [b"end"])
        self._ended_at = time.monotonic()

    def abort(self) -> None:
        """Another stage failed: a send waiting on a worker gives up within SEND_SLICE_S."""
        self._aborted = True

    def _send(self, k: int, socket, frames: list) -> None:
        """Send, waiting while worker k is HWM blocks behind: up to ``timeout_s`` (not counting
        time the consumer spends waiting on later stages, ``downstream_since``), in slices so
        that :meth:`abort` ends the wait."""
        with self._locks[k]:
            deadline = time.monotonic() + self.timeout_s
            while not socket.poll(int(1000 * SEND_SLICE_S), zmq.POLLOUT):
                if self._aborted:
                    raise RuntimeError("swath run aborted")
                now = time.monotonic()
                if self.downstream_since is not None:
                    deadline = max(deadline, now + self.timeout_s)
                elif now > deadline:
                    raise RuntimeError(
                        f"swath worker {k} took no pulses for {self.timeout_s:g} s "
                        "(stalled or gone)"
                    )
            socket.send_multipart(frames, copy=False)
            self._sent_at[k] = time.monotonic()

    def _beat_loop(self) -> None:
        """Every worker set up and sent nothing for ``beat_s`` gets a beat, never waiting: a
        send in progress (its lock held) or a full queue means that worker is being fed."""
        while not self._beats_off.wait(self.beat_s / 4):
            for k, s in enumerate(self._pushes):
                if not self._locks[k].acquire(blocking=False):
                    continue
                try:
                    sent_at = self._sent_at[k]
                    if sent_at is not None and time.monotonic() - sent_at >= self.beat_s:
                        try:
                            s.send_multipart([b"beat"], zmq.NOBLOCK)
                        except zmq.Again:
                            pass  # its queue is full: fed, not idle
                        self._sent_at[k] = time.monotonic()
                finally:
                    self._locks[k].release()

    @property
    def finished(self) -> bool:
        return all(self._done)

    def counters(self) -> dict:
        return {"swath_refused_messages": self.refused}

    def receive(self, timeout_s: float = 0.1) -> Lines | None:
        """Merged lines that every worker has delivered (None: none new within ``timeout_s``)."""
        if self._results.poll(int(1000 * timeout_s)):
            while True:
                self._take(self._results.recv_multipart())
                if not self._results.poll(0):
                    break
            self._heard_at = time.monotonic()
        else:
            self._check_alive()
            quiet_s = time.monotonic() - max(self._heard_at, self._ended_at or 0.0)
            if self._ended_at is not None and not self.finished and quiet_s > self.timeout_s:
                raise RuntimeError(
                    f"swath workers did not finish within {self.timeout_s:g} s of the end"
                )
        return self._merge()

    def _take(self, frames: list[bytes]) -> None:
        """Obey one results message, or refuse it (swath_messages) and go on."""
        try:
            self._obey(parse(frames, len(self.columns)))
        except Refused as exc:
            self.refused += 1
            if self.notify is not None and self.refused <= MAX_REFUSALS_TOLD:
                more = " (no more of these are told)" if self.refused == MAX_REFUSALS_TOLD else ""
                self.notify(
                    f"swath: refused {exc} on the results port {self.results_endpoint}; the "
                    f"run goes on{more}"
                )

    def _obey(self, m) -> None:
        k = m.index
        if m.kind == "lines":
            b0, b1 = self.columns[k]
            count, first = m.head["count"], m.head["first_line"]
            if first != self._lines_in[k] or self._done[k]:
                raise Refused(
                    f"a 'lines' message of worker {k} from line {first} (its next is "
                    f"{self._lines_in[k]}{', and it is done' if self._done[k] else ''})"
                )
            if len(m.payload) != count * (b1 - b0) * self.dtype.itemsize:
                raise Refused(f"a 'lines' message of worker {k} whose lines are not {count}")
            lines = np.frombuffer(m.payload, self.dtype).reshape(count, b1 - b0)
            self._pending[k].append(Lines(first, lines))
            self._lines_in[k] += count
        elif m.kind in ("hello", "ready", "done"):
            said = {"hello": self._hello, "ready": self._ready}.get(m.kind)
            if (said is not None and k in said) or (m.kind == "done" and self._done[k]):
                raise Refused(
                    f"a second '{m.kind}' of worker {k}: two workers started with --index {k}? "
                    "(its pulse socket takes one: the other gets nothing)"
                )
            if m.kind == "done":
                self._done[k] = True
            else:
                said.add(k)
        elif m.kind == "error":
            raise RuntimeError(f"swath worker {k} failed: {m.head['message']}")

    def _merge(self) -> Lines | None:
        """The lines every worker has, columns side by side, in worker order."""
        if any(not q for q in self._pending):
            return None
        first = self.lines_out
        count = min(sum(len(x.lines) for x in q) for q in self._pending)
        if count == 0:
            return None
        out = np.empty((count, self.config.processor.range_bins), self.dtype)
        for (b0, b1), q in zip(self.columns, self._pending, strict=True):
            row = 0
            while row < count:
                part = q[0]
                if part.first_line != first + row:
                    raise RuntimeError("swath workers delivered lines out of order")
                take = min(count - row, len(part.lines))
                out[row : row + take, b0:b1] = part.lines[:take]
                if take == len(part.lines):
                    q.popleft()
                else:
                    q[0] = Lines(part.first_line + take, part.lines[take:])
                row += take
        self.lines_out += count
        return Lines(first, out)

    def _recv(self, deadline: float, what: str) -> list[bytes]:
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise RuntimeError(f"swath workers did not answer {what} in time")
            if self._results.poll(int(1000 * min(left, 0.5))):
                return self._results.recv_multipart()
            self._check_alive()

    def _check_alive(self) -> None:
        for k, p in enumerate(self._procs):
            if p.poll() is not None and not self._done[k]:
                raise RuntimeError(f"swath worker {k} exited with status {p.returncode}")

    def close(self, wait_s: float = 5.0, reason: str = "") -> None:
        """Wait up to ``wait_s`` (in all) for the workers started here, kill the rest, close
        the sockets.  Call it once no thread sends or receives any more.  Unless every worker
        is done (the run failed or was given up), the workers are sent a ``stop`` with
        ``reason``, so that those on other hosts end now, not after their coordinator timeout:
        a worker whose queue is full is sent it again while its lines are taken and dropped
        (up to STOP_LINGER_MS), and learns it from that timeout only if it still takes none.
        (CI, 2026-11-29: a failed coordinator's stop refused by a full queue left a worker
        waiting its 60 s timeout.)"""
        if self._closed:
            return
        self._closed = True
        self._beats_off.set()
        if self._beater is not None:
            self._beater.join()  # within beat_s / 4: it never waits on a socket
        reason = reason or "the coordinator ended before the end of the stream"
        wanted = self._to_stop()
        told = self._tell_stop(reason, wanted)
        untold = wanted - told  # their queues were full
        # A worker blocked sending its lines reads its stop once they go, and takes pulses
        # again, which makes room for a stop its full queue refused: take the lines (dropped)
        # and send those stops again meanwhile.
        if told or untold:
            until = time.monotonic() + STOP_LINGER_MS / 1000
            while time.monotonic() < until:
                if untold:
                    now_told = self._tell_stop(reason, untold)
                    told, untold = told | now_told, untold - now_told
                if self._results.poll(50):
                    self._results.recv_multipart(copy=False)  # dropped: the run has failed
        deadline = time.monotonic() + wait_s
        for p in self._procs:
            try:
                p.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        for k, s in enumerate(self._pushes):
            s.close(STOP_LINGER_MS if k in told else 0)
        if self._results is not None:
            self._results.close(0)
        self._ctx.term()

    def _to_stop(self) -> set[int]:
        """The workers a ``stop`` goes to: those set up, unless all are done (or none started)."""
        if not hasattr(self, "_done") or self.finished:
            return set()
        return {k for k in range(len(self._pushes)) if self._sent_at[k] is not None}

    def _tell_stop(self, reason: str, workers: set[int]) -> set[int]:
        """Send ``stop`` to ``workers`` without waiting; those it went to."""
        told = set()
        for k in sorted(workers):
            try:
                self._pushes[k].send_multipart([b"stop", reason.encode()], zmq.NOBLOCK)
                told.add(k)
            except zmq.ZMQError:  # its queue is full or it is gone: its timeout tells it
                pass
        return told
