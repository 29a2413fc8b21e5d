"""The simulator in a process of its own, as an instrument is: a live run's simulated shots made
beside the processor, not in it (rtsar.sources.sim ``separate``).

Synthesising a shot of the built-in demo takes 150-270 µs of Python and NumPy (2-core AMD EPYC
Zen 3, issue 38), most of it holding the interpreter's lock: in the processor's process it took
up to 40 % of that lock at 1,600 pulses/s, and the stages waited for it (the demo's line
latency, median 6.0 ms with the simulator in process against 1.7-3.1 ms for the same shots
replayed).  Here a child process (``python -m rtsar.sources.sim_process ENDPOINT``) receives
the scene and the number of shots over a ZeroMQ PAIR socket, readies its kernels, says so,
then makes the shots in order, BLOCK_SHOTS a message, and sends them ahead of their time, about
AHEAD_MESSAGES queued at each end (ZeroMQ's high-water marks: the memory they take is
bounded).  The parent (``ShotFeed``) takes them as its pacer releases them; its arrival times
stay the schedule's.  The shots are the simulator's own, bit for bit (the scene is sent whole,
its seeds with it).

The socket is a Unix socket in a folder only this user can enter (loopback TCP where there
are none): both ends unpickle what they receive, so no other user may connect.  ``start``
returns once the child is ready (its kernels loaded), and a child that ends first is an error
with the last line it wrote; a failure later comes back as a message and is raised by
``ShotFeed.take`` with the child's words.  The child runs in a session of its own (the
terminal's Ctrl-C reaches the parent only, which ends it) and ends itself when its parent is
gone.
"""

from __future__ import annotations

import atexit
import os
import pickle
import shutil
import signal
import subprocess
import sys
import tempfile

import numpy as np
import zmq

from ..child import module_argv
from ..scene import Simulator

BLOCK_SHOTS = 16  # shots a message carries
AHEAD_MESSAGES = 4  # messages the child may have sent ahead of the parent's reading
POLL_MS = 200  # how often a waiting side looks whether the other is still there


class ShotFeed:
    """A child process making ``total`` shots of ``scene``; ``take(n)`` gives the next ``n``.

    ``start()`` launches it (its kernels load from numba's cache there, seconds on a first
    run); ``close()`` ends it.  ``stopped()`` (a callable) ends a wait in ``take`` early.
    """

    def __init__(self, scene, total: int, stopped=lambda: False):
        self.scene, self.total, self.stopped = scene, int(total), stopped
        self._ctx = zmq.Context.instance()
        self._sock = None
        self._process: subprocess.Popen | None = None
        self._errors = None  # the child's standard error, a temporary file
        self._folder: str | None = None  # the socket's private folder
        self._registered = False  # close() registered to run at exit
        self._samples = np.zeros((0, 0), np.complex64)
        self._aux: dict[str, np.ndarray] = {}
        self._at = 0  # shots taken of the block held
        self.received = 0  # shots received from the child

    def start(self) -> None:
        """Launch the child and wait until it is ready (seconds: it imports rtsar and loads
        the simulator's kernels); RuntimeError where it ends first."""
        if self._process is not None:
            return
        sock = self._ctx.socket(zmq.PAIR)
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.RCVHWM, AHEAD_MESSAGES)
        if os.name == "posix":  # a folder of this user's only (mkdtemp: mode 0700)
            self._folder = tempfile.mkdtemp(prefix="rtsar-sim-")
            endpoint = f"ipc://{os.path.join(self._folder, 'shots')}"
            sock.bind(endpoint)
        else:  # pragma: no cover - no Unix sockets
            endpoint = f"tcp://127.0.0.1:{sock.bind_to_random_port('tcp://127.0.0.1')}"
        self._sock = sock
        self._errors = tempfile.TemporaryFile()
        self._process = subprocess.Popen(
            module_argv("rtsar.sources.sim_process", endpoint),
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._errors,
            start_new_session=True,
        )  # fmt: skip
        if not self._registered:
            atexit.register(self.close)
            self._registered = True
        ready = self._wait(zmq.POLLOUT)
        if ready:
            sock.send(pickle.dumps((self.scene, self.total)))
            ready = self._wait(zmq.POLLIN)
        if not ready:  # stopped while the child started
            self.close()
            return
        kind, *rest = pickle.loads(sock.recv())
        if kind != "ready":
            self.close()
            raise RuntimeError(f"the simulator's process failed: {rest[0] if rest else kind}")

    def _wait(self, event: int) -> bool:
        """Wait until the socket can ``event``; False once stopped; RuntimeError where the
        child has ended meanwhile."""
        while not self._sock.poll(POLL_MS, event):
            if self.stopped():
                return False
            code = self._process.poll()
            if code is not None:
                why = self._why(code)
                self.close()
                raise RuntimeError(f"the simulator's process ended ({why})")
        return True

    def take(self, n: int) -> tuple[np.ndarray, dict[str, np.ndarray]] | None:
        """The next ``n`` shots (samples [n, S], {aux name: [n, S']}); None once stopped."""
        parts, aux_parts, need = [], [], n
        while need:
            if self._at == len(self._samples):
                if not self._receive():
                    return None
            k = min(need, len(self._samples) - self._at)
            parts.append(self._samples[self._at : self._at + k])
            aux_parts.append({a: v[self._at : self._at + k] for a, v in self._aux.items()})
            self._at += k
            need -= k
        if len(parts) == 1:
            return parts[0], aux_parts[0]
        names = aux_parts[0].keys()
        return np.concatenate(parts), {a: np.concatenate([p[a] for p in aux_parts]) for a in names}

    def _receive(self) -> bool:
        """The next block of shots from the child (False: stopped while waiting)."""
        if self._process is None:
            self.start()
        if self._sock is None or not self._wait(zmq.POLLIN):  # stopped (while starting)
            return False
        frames = self._sock.recv_multipart()
        kind, *rest = pickle.loads(frames[0])
        if kind == "error":
            raise RuntimeError(f"the simulator's process failed: {rest[0]}")
        if kind == "end":
            raise RuntimeError(f"the simulator's process made only {self.received} shots")
        first, names, shape, aux_shapes = rest
        if first != self.received:
            raise RuntimeError(f"the simulator's process sent shot {first}, not {self.received}")
        self._samples = np.frombuffer(frames[1], np.complex64).reshape(shape).copy()
        self._aux = {
            name: np.frombuffer(frame, np.complex64).reshape(s).copy()
            for name, frame, s in zip(names, frames[2:], aux_shapes, strict=True)
        }
        self._at = 0
        self.received += shape[0]
        return True

    def _why(self, code: int) -> str:
        words = f"exit status {code}"
        if self._errors is not None:
            self._errors.seek(0)
            lines = self._errors.read().decode(errors="replace").strip().splitlines()
            if lines:
                words += f": {lines[-1]}"
        return words

    def close(self) -> None:
        process, self._process = self._process, None
        if process is not None:
            if process.poll() is None:
                process.kill()
            process.wait()
        if self._sock is not None:
            self._sock.close(0)
            self._sock = None
        if self._errors is not None:
            self._errors.close()
            self._errors = None
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None


def _send(sock, frames, parent: int) -> bool:
    """Send, waiting while the parent reads slower (high-water mark); False once it is gone."""
    while True:
        try:
            sock.send_multipart(frames, zmq.NOBLOCK)
            return True
        except zmq.Again:
            if os.getppid() != parent:
                return False
            sock.poll(POLL_MS, zmq.POLLOUT)


def serve(endpoint: str) -> int:
    """The child: receive (scene, total), send the shots in blocks, then ("end",)."""
    parent = os.getppid()
    sock = zmq.Context.instance().socket(zmq.PAIR)
    sock.setsockopt(zmq.LINGER, 1000)
    sock.setsockopt(zmq.SNDHWM, AHEAD_MESSAGES)
    sock.connect(endpoint)
    while not sock.poll(POLL_MS, zmq.POLLIN):
        if os.getppid() != parent:
            return 1
    scene, total = pickle.loads(sock.recv())
    try:
        sim = Simulator(scene)
        sim.prepare()
        if not _send(sock, [pickle.dumps(("ready",))], parent):
            return 1
        p = 0
        while p < total:
            n = min(BLOCK_SHOTS, total - p)
            samples, aux = sim.block_with_aux(n)
            names = sorted(aux)
            arrays = [np.ascontiguousarray(samples, np.complex64)]
            arrays += [np.ascontiguousarray(aux[a], np.complex64) for a in names]
            head = ("shots", p, names, arrays[0].shape, [a.shape for a in arrays[1:]])
            if not _send(sock, [pickle.dumps(head), *(a.data for a in arrays)], parent):
                return 1
            p += n
    except Exception as exc:  # said by the parent, with the child's words
        _send(sock, [pickle.dumps(("error", f"{type(exc).__name__}: {exc}"))], parent)
        return 1
    _send(sock, [pickle.dumps(("end",))], parent)
    # Stay until the parent ends this process: its last blocks may still wait in the queues
    # (a process that exits drops what its socket had not yet delivered), and it reads them at
    # its pulse rate.
    while os.getppid() == parent:
        sock.poll(POLL_MS, zmq.POLLIN)
    return 0


def main(argv: list[str]) -> int:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent ends it (were it in the group)
    if len(argv) != 1:
        sys.stderr.write("usage: python -m rtsar.sources.sim_process ENDPOINT\n")
        return 2
    return serve(argv[0])


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
