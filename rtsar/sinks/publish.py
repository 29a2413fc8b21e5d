"""Image strips over ZeroMQ: the publisher, a pipeline sink (wire format: rtsar.sinks.wire).

The publisher is an XPUB socket (PUB semantics, plus it sees subscriptions so a replay can wait
for its subscriber).  Delivery ``"drop"`` (live default): a subscriber that does not keep up
loses whole strips at its high-water mark, on its own connection only, and the pipeline never
waits; subscribers see the loss as a gap in ``seq`` and count it.  Delivery ``"lossless"``
(replay default; XPUB_NODROP): the publisher waits for the slowest subscriber, which
back-pressures the pipeline (a replay slows down; a live source drops pulses, counted) — but
never for ever: a subscriber that has not taken a message for ``stall_timeout_s`` is cut off
(counted in ``subscriber_stalls``; delivery drops for it, and only for it, at its high-water
mark), and lossless delivery is tried again a second later.

What a cut-off subscriber misses cannot be known here: ZeroMQ leaves its connection out of
delivery, silently, from the first message it could not take until it has drained half its
queue, and a no-drop send then goes through without it (the probe a second later does too).
So every message sent from a cut-off on, while the subscribers then connected are all still
there, is counted in ``messages_missed_by_stalled``.  A subscriber that never reads again
misses these and also the messages already queued towards it when it stopped reading (sent,
so not counted: up to its high-water mark here, its own receive queue and the socket
buffers; a cold review saw 7,271 missed against 6,752 counted); for one that reads again the
count bounds what it missed after the cut-off.  Its own count of gaps in ``seq`` is exact.
(Counting only the messages sent in drop mode missed the silent ones: 752 counted for 1,881
missed.)  ``hurry`` (Ctrl-C, a signal, the end of ``--duration``) shortens the wait so that a
run always ends promptly.
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
from .endpoint import DEFAULT_ENDPOINT, DELIVERIES, STALL_TIMEOUT_S, is_local_endpoint
from .wire import height_header, stats_header, strip_fixed_fields, strip_own_fields

# Dropping delivery reads the subscriptions that arrived at most this often (lossless: at every
# send, its cut-off rule needs the count): a look that finds none raises zmq.Again, 26 µs a
# strip in the pipeline's thread on a busy 2-core machine, a tenth of a one-line strip's cost.
POLL_EVERY_S = 0.01


def _warn(message: str) -> None:
    warnings.warn(message, UserWarning, stacklevel=3)


def load_secret_key(path: str | Path) -> tuple[bytes, bytes]:
    """(public, secret) CURVE keys of a secret-key file made by ``rtsar keygen``."""
    try:
        public, secret = zmq.auth.load_certificate(str(path))
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a CURVE key file ({exc})") from None
    if secret is None:
        raise ValueError(f"{path}: not a secret-key file (the .key_secret one)")
    return public, secret


def authenticator(context: zmq.Context, clients: str | Path):
    """ZeroMQ's ZAP handler (pyzmq's ThreadAuthenticator) accepting only the CURVE clients whose
    public keys are in the folder ``clients``."""
    from zmq.auth.thread import ThreadAuthenticator

    folder = Path(clients)
    if not folder.is_dir() or not any(folder.glob("*.key")):
        raise ValueError(f"{folder}: no folder of client public keys (*.key from rtsar keygen)")
    auth = ThreadAuthenticator(context)
    auth.start()
    auth.configure_curve(domain="*", location=str(folder))
    return auth


class ZmqPublisher(StripSink):
    """Pipeline sink publishing strips, stats and the end message on a ZeroMQ XPUB socket.

    ``curve_secret_key``: a secret-key file made by ``rtsar keygen`` (ZeroMQ CURVE: clients
    need the matching public key); without it, binding beyond loopback warns (``warn``: a
    callable taking the message; default ``warnings.warn``).  ``curve_clients``: a folder of
    the public keys of the clients allowed to subscribe (ZeroMQ's ZAP, pyzmq's
    ThreadAuthenticator); without it any client holding the server key may subscribe.
    ``stall_timeout_s``: the longest a lossless send waits for a subscriber that reads nothing.
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
        stall_timeout_s: float = STALL_TIMEOUT_S,
        curve_clients: str | Path | None = None,
    ):
        if delivery not in DELIVERIES:
            raise ValueError(f"delivery must be one of {DELIVERIES}, got {delivery!r}")
        if not stall_timeout_s > 0:
            raise ValueError(f"stall_timeout_s must be > 0, got {stall_timeout_s!r}")
        if curve_clients is not None and curve_secret_key is None:
            raise ValueError("authenticating clients (curve_clients) needs a CURVE secret key")
        self.endpoint = endpoint
        self.delivery = delivery
        self.stall_timeout_s = float(stall_timeout_s)
        self.subscribers = 0
        self._polled_s = -float("inf")  # when send() last read the subscriptions
        self.sent = {"strip": 0, "stats": 0, "end": 0}
        self._config_obj, self._config_json = None, ""  # the stream's config, encoded once
        self._fixed_info, self._fixed_json = None, ""  # a strip header's fixed fields (strip)
        self.subscriber_stalls = 0  # times a subscriber that read nothing was cut off
        self.dropped_for_stalled = 0  # messages sent while a stalled subscriber was cut off
        self._left_out = 0  # subscribers at the last cut-off (> 0: one may still be left out)
        self._cut_off = False  # lossless, but a stalled subscriber is cut off
        self._probe_s = 0.0  # when to try lossless delivery again
        self._hurry = False
        self._hurry_s = 0.0
        self._auth = None
        ctx = context or zmq.Context.instance()
        self.socket = s = ctx.socket(zmq.XPUB)
        s.setsockopt(zmq.SNDHWM, int(hwm_messages))
        s.setsockopt(zmq.LINGER, int(linger_ms))
        # Every subscription and every unsubscription (also a subscriber that leaves) reaches us:
        # the subscriber count is right for --wait-subscribers.
        s.setsockopt(zmq.XPUB_VERBOSER, 1)
        if delivery == "lossless":
            s.setsockopt(zmq.XPUB_NODROP, 1)
        if curve_secret_key is not None:
            public, secret = load_secret_key(curve_secret_key)
            if curve_clients is not None:
                self._auth = authenticator(ctx, curve_clients)
            s.curve_secretkey, s.curve_publickey, s.curve_server = secret, public, True
        try:
            s.bind(endpoint)
        except zmq.ZMQError as exc:
            s.close(0)
            if self._auth is not None:
                self._auth.stop()
            hint = ""
            if exc.errno == zmq.EADDRINUSE:  # another run publishes there (rtsar's default)
                hint = "; another program publishes there: give --endpoint, or RTSAR_ENDPOINT"
            raise ValueError(f"cannot bind {endpoint}: {exc}{hint}") from None
        if curve_secret_key is None and not is_local_endpoint(endpoint):  # once it is bound
            (warn or _warn)(
                f"warning: publishing on {endpoint} beyond loopback without encryption "
                "(give a CURVE key made by `rtsar keygen` to encrypt)"
            )
        self.endpoint = s.getsockopt_string(zmq.LAST_ENDPOINT)  # resolves a port given as *
        self._closed = False

    def _poll_subscriptions(self, timeout_ms: int = 0) -> None:
        """Count the (un)subscriptions that have arrived, waiting up to ``timeout_ms`` for one.

        With a timeout the socket takes in every pending command first (a subscriber that left
        is one); without, the count may lag by a millisecond (ZeroMQ throttles that work on
        non-blocking calls) and costs nothing on the send path.
        """
        if timeout_ms:
            self.socket.poll(timeout_ms, zmq.POLLIN)
        while True:
            try:
                msg = self.socket.recv(zmq.NOBLOCK)
            except zmq.Again:
                return
            if msg[:1] == b"\x01":
                self.subscribers += 1
            elif msg[:1] == b"\x00":
                self.subscribers = max(0, self.subscribers - 1)

    def wait_for_subscribers(self, count: int, timeout_s: float | None = None, stop=None) -> bool:
        """Block until ``count`` subscriptions have arrived (True) or the timeout (False)."""
        deadline = None if timeout_s is None else time.perf_counter() + timeout_s
        self._poll_subscriptions(10)  # who has come and gone since the last look
        while self.subscribers < count:
            if stop is not None and stop():
                return False
            if deadline is not None and time.perf_counter() > deadline:
                return False
            self._poll_subscriptions(100)
        # Give the subscription a moment to be installed on every pipe before the first send.
        time.sleep(0.05)
        return True

    def send(self, topic: str, header: dict | bytes, payload=None) -> None:
        """Send one message; ``header`` a dict (or its JSON, encoded); ``payload`` a complex
        array (strips) or a list of typed arrays."""
        encoded = header if isinstance(header, bytes) else self._encode(header)
        frames = [topic.encode("ascii"), encoded]
        if isinstance(payload, list):
            frames.extend(np.ascontiguousarray(a).data for a in payload)
        elif payload is not None:
            frames.append(np.ascontiguousarray(payload, "<c8").data)
        now = time.perf_counter()
        if self.delivery != "drop" or now - self._polled_s >= POLL_EVERY_S:
            self._polled_s = now
            self._poll_subscriptions()
        if self.delivery == "drop":
            self.socket.send_multipart(frames, zmq.NOBLOCK)  # XPUB drops at HWM, never blocks
        else:
            self._send_lossless(frames)
            if self._left_out and self.subscribers < self._left_out:
                self._left_out = 0  # one has left since: taken to be the one cut off
            if self._left_out:  # a cut-off subscriber may still be left out (module docstring)
                self.dropped_for_stalled += 1
        self.sent[topic] = self.sent.get(topic, 0) + 1

    def _encode(self, header: dict) -> bytes:
        """The header as JSON; a strip's ``config`` (one dict for the whole stream, 0.8 kB)
        is encoded once and spliced in, not again for every strip."""
        config = header.get("config")
        if not isinstance(config, dict):
            return json.dumps(header).encode()
        if config is not self._config_obj:
            self._config_obj, self._config_json = config, json.dumps(config)
        rest = json.dumps({k: v for k, v in header.items() if k != "config"})
        return (
            f'{{"config": {self._config_json}' + (", " + rest[1:] if rest != "{}" else "}")
        ).encode()

    def _send_lossless(self, frames) -> None:
        """Wait for the slowest subscriber, at most ``stall_timeout_s`` (less when hurrying)."""
        s = self.socket
        now = time.perf_counter()
        if self._cut_off:
            if now < self._probe_s:  # a stalled subscriber is cut off: it misses this one
                s.send_multipart(frames, zmq.NOBLOCK)
                return
            s.setsockopt(zmq.XPUB_NODROP, 1)  # has it read or left? then lossless again
            self._cut_off = False
        deadline = now + self.stall_timeout_s
        while True:
            try:
                s.send_multipart(frames, zmq.NOBLOCK)
                return
            except zmq.Again:
                if self._hurry:  # set by another thread, maybe during this wait
                    deadline = min(deadline, max(now, self._hurry_s) + 0.2)
                left = deadline - time.perf_counter()
                if left <= 0:
                    break
                s.poll(int(min(100, 1000 * left)) + 1, zmq.POLLOUT)
                self._poll_subscriptions()
        # A subscriber has taken nothing for the whole wait: cut it off (drop at its high-water
        # mark, only for it) and try lossless delivery again in a second.
        s.setsockopt(zmq.XPUB_NODROP, 0)
        if not self._cut_off:
            self.subscriber_stalls += 1
        self._cut_off = True
        self._left_out = max(self.subscribers, 1)
        self._probe_s = time.perf_counter() + 1.0
        s.send_multipart(frames, zmq.NOBLOCK)

    def hurry(self) -> None:
        """The run is ending (Ctrl-C, a signal, --duration): wait for a stalled subscriber no
        longer than 0.2 s, and linger at most as long when closing."""
        self._hurry_s = time.perf_counter()
        self._hurry = True

    def counters(self) -> dict:
        return {
            "subscriber_stalls": self.subscriber_stalls,
            "messages_missed_by_stalled": self.dropped_for_stalled,
        }

    # ---- pipeline sink interface --------------------------------------------------------
    def strip(self, strip: Strip, info: StreamInfo) -> None:
        """The strip's message: its header's fields shared by the stream (rtsar.sinks.wire
        strip_fixed_fields) encoded once per stream info, the strip's own each time (a
        header encoded whole took 35 µs of the 1-2 line strips' 120-170, 2-core Zen 3)."""
        if info is not self._fixed_info:
            self._fixed_info = info
            self._fixed_json = json.dumps(strip_fixed_fields(info))[1:-1]
        own = json.dumps(strip_own_fields(strip, info))
        self.send("strip", f"{{{self._fixed_json}, {own[1:]}".encode(), strip.lines)

    def height(self, strip, seq: int, info: StreamInfo) -> None:
        payload = [
            strip.height_m.astype("<f4"),
            strip.valid.astype(np.uint8),
            strip.coherence.astype("<f4"),
        ]
        self.send("height", height_header(strip, seq, info), payload)

    def stats(self, stats: dict, info: StreamInfo) -> None:
        self.send("stats", stats_header(stats, info))

    def end(self, stats: dict, info: StreamInfo) -> None:
        self.send("end", stats_header(stats, info))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            if self._cut_off or self._hurry:  # do not wait on a subscriber that reads nothing
                self.socket.setsockopt(zmq.LINGER, 200)
            self.socket.close()
            if self._auth is not None:
                self._auth.stop()
