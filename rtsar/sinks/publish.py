"""Image strips over ZeroMQ: the publisher, a pipeline sink (wire format: rtsar.sinks.wire).

The publisher is an XPUB socket (PUB semantics, plus it sees subscriptions so a replay can wait
for its subscriber).  Delivery ``"drop"`` (live default): a subscriber that does not keep up
loses whole strips at its high-water mark, on its own connection only, and the pipeline never
waits; subscribers see the loss as a gap in ``seq`` and count it.  Delivery ``"lossless"``
(replay default; XPUB_NODROP): the publisher waits for the slowest subscriber, which
back-pressures the pipeline (a replay slows down; a live source drops pulses, counted).
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path

import numpy as np
import zmq
import zmq.auth

from ..stream.strips import StreamInfo, Strip, StripSink
from .wire import height_header, stats_header, strip_header

DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"
DELIVERIES = ("drop", "lossless")
_LOOPBACK = {"127.0.0.1", "localhost", "::1", "[::1]"}


def _warn(message: str) -> None:
    warnings.warn(message, UserWarning, stacklevel=3)


def is_local_endpoint(endpoint: str) -> bool:
    """True for ipc://, inproc:// and tcp:// on a loopback address."""
    scheme = endpoint.split("://", 1)[0]
    if scheme in ("ipc", "inproc"):
        return True
    if scheme != "tcp":
        return False
    host = endpoint.split("://", 1)[1].rsplit(":", 1)[0]
    return host in _LOOPBACK or host.startswith("127.")


class ZmqPublisher(StripSink):
    """Pipeline sink publishing strips, stats and the end message on a ZeroMQ XPUB socket.

    ``curve_secret_key``: a secret-key file made by ``rtsar keygen`` (ZeroMQ CURVE: clients
    need the matching public key); without it, binding beyond loopback warns (``warn``: a
    callable taking the message; default ``warnings.warn``).
    """

    def __init__(
        self,
        endpoint: str = DEFAULT_ENDPOINT,
        delivery: str = "drop",
        hwm_messages: int = 1000,
        linger_ms: int = 2000,
        curve_secret_key: str | Path | None = None,
        context: zmq.Context | None = None,
        warn=None,
    ):
        if delivery not in DELIVERIES:
            raise ValueError(f"delivery must be one of {DELIVERIES}, got {delivery!r}")
        self.endpoint = endpoint
        self.delivery = delivery
        self.subscribers = 0
        self.sent = {"strip": 0, "stats": 0, "end": 0}
        ctx = context or zmq.Context.instance()
        self.socket = s = ctx.socket(zmq.XPUB)
        s.setsockopt(zmq.SNDHWM, int(hwm_messages))
        s.setsockopt(zmq.LINGER, int(linger_ms))
        s.setsockopt(zmq.XPUB_VERBOSE, 1)  # every subscription reaches us (subscriber count)
        if delivery == "lossless":
            s.setsockopt(zmq.XPUB_NODROP, 1)
        if curve_secret_key is not None:
            public, secret = zmq.auth.load_certificate(str(curve_secret_key))
            if secret is None:
                raise ValueError(f"{curve_secret_key}: not a secret-key file")
            s.curve_secretkey, s.curve_publickey, s.curve_server = secret, public, True
        elif not is_local_endpoint(endpoint):
            (warn or _warn)(
                f"warning: publishing on {endpoint} beyond loopback without encryption "
                "(give a CURVE key made by `rtsar keygen` to encrypt)"
            )
        try:
            s.bind(endpoint)
        except zmq.ZMQError as exc:
            s.close(0)
            raise ValueError(f"cannot bind {endpoint}: {exc}") from None
        self.endpoint = s.getsockopt_string(zmq.LAST_ENDPOINT)  # resolves a port given as *
        self._closed = False

    def _poll_subscriptions(self, timeout_ms: int = 0) -> None:
        while self.socket.poll(timeout_ms, zmq.POLLIN):
            msg = self.socket.recv()
            if msg[:1] == b"\x01":
                self.subscribers += 1
            elif msg[:1] == b"\x00":
                self.subscribers = max(0, self.subscribers - 1)
            timeout_ms = 0

    def wait_for_subscribers(self, count: int, timeout_s: float | None = None, stop=None) -> bool:
        """Block until ``count`` subscriptions have arrived (True) or the timeout (False)."""
        deadline = None if timeout_s is None else time.perf_counter() + timeout_s
        while self.subscribers < count:
            if stop is not None and stop():
                return False
            if deadline is not None and time.perf_counter() > deadline:
                return False
            self._poll_subscriptions(100)
        # Give the subscription a moment to be installed on every pipe before the first send.
        time.sleep(0.05)
        return True

    def send(self, topic: str, header: dict, payload=None) -> None:
        """Send one message; ``payload`` a complex array (strips) or a list of typed arrays."""
        frames = [topic.encode("ascii"), json.dumps(header).encode()]
        if isinstance(payload, list):
            frames.extend(np.ascontiguousarray(a).data for a in payload)
        elif payload is not None:
            frames.append(np.ascontiguousarray(payload, "<c8").data)
        self._poll_subscriptions()
        if self.delivery == "drop":
            self.socket.send_multipart(frames, zmq.NOBLOCK)  # XPUB drops at HWM, never blocks
        else:
            while True:  # lossless: wait for the slowest subscriber
                try:
                    self.socket.send_multipart(frames, zmq.NOBLOCK)
                    break
                except zmq.Again:
                    self.socket.poll(100, zmq.POLLOUT)
                    self._poll_subscriptions()
        self.sent[topic] = self.sent.get(topic, 0) + 1

    # ---- pipeline sink interface --------------------------------------------------------
    def strip(self, strip: Strip, info: StreamInfo) -> None:
        self.send("strip", strip_header(strip, info), strip.lines)

    def height(self, strip, seq: int, info: StreamInfo) -> None:
        payload = [strip.height_m.astype("<f4"), strip.valid.astype(np.uint8)]
        self.send("height", height_header(strip, seq, info), payload)

    def stats(self, stats: dict, info: StreamInfo) -> None:
        self.send("stats", stats_header(stats, info))

    def end(self, stats: dict, info: StreamInfo) -> None:
        self.send("end", stats_header(stats, info))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.socket.close()
