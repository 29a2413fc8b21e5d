"""The subscriber side of the strip protocol: a SUB socket that decodes and counts messages."""

from __future__ import annotations

import time
from pathlib import Path

import zmq
import zmq.auth

from .publish import DEFAULT_ENDPOINT, load_secret_key
from .wire import MAX_FRAME_BYTES, Message, decode


class StripSubscriber:
    """Client: connect a SUB socket and receive :class:`Message` s.

    ``curve_server_key``: the publisher's public-key file when it uses CURVE;
    ``curve_client_key``: this client's secret-key file when the publisher admits only known
    clients (``rtsar run --curve-clients DIR``).
    Counts ``strips``, ``missed_strips`` (gaps in seq) and ``bad_messages`` (undecodable).
    """

    def __init__(
        self,
        endpoint: str = DEFAULT_ENDPOINT,
        curve_server_key: str | Path | None = None,
        curve_client_key: str | Path | None = None,
        hwm_messages: int = 0,
        context: zmq.Context | None = None,
    ):
        ctx = context or zmq.Context.instance()
        self.socket = s = ctx.socket(zmq.SUB)
        s.setsockopt(zmq.LINGER, 0)
        s.setsockopt(zmq.RCVHWM, int(hwm_messages))
        # A message part larger than any strip can be drops the connection instead of filling
        # the memory (a header's numbers are checked, but the bytes arrive first).
        s.setsockopt(zmq.MAXMSGSIZE, MAX_FRAME_BYTES)
        if curve_client_key is not None and curve_server_key is None:
            raise ValueError("a CURVE client key needs the publisher's key (--curve-server-key)")
        if curve_server_key is not None:
            try:
                server_public, _ = zmq.auth.load_certificate(str(curve_server_key))
            except (OSError, ValueError) as exc:
                raise ValueError(f"{curve_server_key}: not a CURVE key file ({exc})") from None
            if curve_client_key is not None:  # a publisher that authenticates clients
                s.curve_publickey, s.curve_secretkey = load_secret_key(curve_client_key)
            else:
                s.curve_publickey, s.curve_secretkey = zmq.curve_keypair()
            s.curve_serverkey = server_public
        s.setsockopt(zmq.SUBSCRIBE, b"")
        try:
            s.connect(endpoint)
        except zmq.ZMQError as exc:
            s.close(0)
            raise ValueError(f"cannot connect to {endpoint}: {exc}") from None
        self.endpoint = endpoint
        self.counters = {"strips": 0, "missed_strips": 0, "bad_messages": 0}
        self.stream_id: str | None = None
        self._next_seq: dict[str, int] = {}  # stream_id → the seq expected next

    def recv(self, timeout_s: float | None = None) -> Message | None:
        """Next valid message, or None after ``timeout_s`` without one."""
        deadline = None if timeout_s is None else time.perf_counter() + timeout_s
        while True:
            left = None if deadline is None else max(0.0, deadline - time.perf_counter())
            wait = 100 if left is None else min(100, int(left * 1000))
            if not self.socket.poll(wait):
                if left is not None and left <= 0:
                    return None
                continue
            try:
                msg = decode(self.socket.recv_multipart())
            except ValueError:
                self.counters["bad_messages"] += 1
                continue
            if msg.topic == "strip":
                self._count(msg.header)
            return msg

    def _count(self, header: dict) -> None:
        """Gaps in ``seq`` per stream (a strip of another stream does not reset the count)."""
        stream = header.get("stream_id")
        if self.stream_id is None:
            self.stream_id = stream
        expected = self._next_seq.get(stream)
        seq = int(header["seq"])
        if expected is not None and seq > expected:
            self.counters["missed_strips"] += seq - expected
        self._next_seq[stream] = max(seq + 1, expected or 0)
        while len(self._next_seq) > 8:  # bounded: the oldest other streams are forgotten
            oldest = next(k for k in self._next_seq if k != self.stream_id)
            self._next_seq.pop(oldest)
        self.counters["strips"] += 1

    def close(self) -> None:
        self.socket.close(0)
