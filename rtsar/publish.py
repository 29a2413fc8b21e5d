"""Image strips over ZeroMQ: the wire format, the publisher and a subscriber client.

Wire format (documented for users in README.md, "Strip protocol"): every message is multipart,

    frame 0  topic, ASCII: b"strip", b"stats" or b"end"
    frame 1  header, UTF-8 JSON object (fields in ``strip_header`` / the README)
    frame 2  payload (strip only): complex64 little-endian, C order [line_count, range_bins]

The publisher is an XPUB socket (PUB semantics, plus it sees subscriptions so a replay can wait
for its subscriber).  Delivery ``"drop"`` (live default): a subscriber that does not keep up
loses whole strips at its high-water mark, on its own connection only, and the pipeline never
waits; subscribers see the loss as a gap in ``seq`` and count it.  Delivery ``"lossless"``
(replay default; XPUB_NODROP): the publisher waits for the slowest subscriber, which
back-pressures the pipeline (a replay slows down; a live source drops pulses, counted).
"""

from __future__ import annotations

import json
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zmq
import zmq.auth

STRIP_FORMAT = "rtsar-strip"
STRIP_VERSION = 1
DEFAULT_ENDPOINT = "tcp://127.0.0.1:5555"
DELIVERIES = ("drop", "lossless")
_LOOPBACK = {"127.0.0.1", "localhost", "::1", "[::1]"}


def is_local_endpoint(endpoint: str) -> bool:
    """True for ipc://, inproc:// and tcp:// on a loopback address."""
    scheme = endpoint.split("://", 1)[0]
    if scheme in ("ipc", "inproc"):
        return True
    if scheme != "tcp":
        return False
    host = endpoint.split("://", 1)[1].rsplit(":", 1)[0]
    return host in _LOOPBACK or host.startswith("127.")


def _unix(pipeline, perf_s: float) -> float:
    return float(perf_s) + pipeline.clock_offset_s


def strip_header(strip, pipeline) -> dict:
    """The JSON header of a strip message (every field is described in README.md)."""
    rng = pipeline.engine.range_m
    n_lines, n_bins = strip.lines.shape
    return {
        "format": STRIP_FORMAT,
        "version": STRIP_VERSION,
        "stream_id": pipeline.stream_id,
        "seq": strip.seq,
        "first_line": strip.first_line,
        "line_count": n_lines,
        "range_bins": n_bins,
        "dtype": "complex64",
        "byte_order": "little",
        "azimuth_first_m": float(strip.azimuth_m[0]),
        "azimuth_step_m": pipeline.config.geometry.along_track_step_m,
        "range_first_m": float(rng[0]),
        "range_step_m": float(rng[1] - rng[0]) if len(rng) > 1 else 0.0,
        "first_pulse_arrival_unix_s": _unix(pipeline, strip.first_arrival_s),
        "last_pulse_arrival_unix_s": _unix(pipeline, strip.last_arrival_s),
        "publish_unix_s": time.time(),
        "flagged_lines": [list(r) for r in strip.flagged_lines],
        "counters": pipeline.counters(),
        "config": pipeline.config_dict,
    }


HEIGHT_FORMAT = "rtsar-height"
HEIGHT_VERSION = 1


def height_header(strip, seq: int, pipeline) -> dict:
    """The JSON header of a height message (3D imaging: rtsar.topo.stream.HeightStrip).

    Frames: topic ``height``, this header, heights float32 little-endian [line, bin] in metres
    (0 where not valid), validity uint8 [line, bin] (1 = valid: coherent, unwrapped).
    """
    rng = pipeline.engine.range_m
    n_lines, n_bins = strip.height_m.shape
    return {
        "format": HEIGHT_FORMAT,
        "version": HEIGHT_VERSION,
        "stream_id": pipeline.stream_id,
        "seq": seq,
        "first_line": strip.first_line,
        "line_count": n_lines,
        "range_bins": n_bins,
        "dtype": "float32",
        "valid_dtype": "uint8",
        "byte_order": "little",
        "units": "m",
        "aligned": bool(strip.aligned),
        "valid_fraction": float(np.mean(strip.valid)) if strip.valid.size else 0.0,
        "azimuth_first_m": float(pipeline.engine.azimuth_m(strip.first_line, 1)[0]),
        "azimuth_step_m": pipeline.config.geometry.along_track_step_m,
        "range_first_m": float(rng[0]),
        "range_step_m": float(rng[1] - rng[0]) if len(rng) > 1 else 0.0,
        "publish_unix_s": time.time(),
    }


@dataclass
class Message:
    """A received message: topic, header and the payload: a strip's image[line, range_bin]
    (complex), or a height message's height_m[line, range_bin] (float32) and ``valid``."""

    topic: str
    header: dict
    lines: np.ndarray | None = None
    valid: np.ndarray | None = None


def decode(frames: list[bytes]) -> Message:
    """Parse one multipart message; ValueError on anything that is not a valid rtsar message."""
    if len(frames) < 2:
        raise ValueError(f"expected at least 2 frames, got {len(frames)}")
    topic = bytes(frames[0]).decode("ascii", "replace")
    try:
        header = json.loads(bytes(frames[1]))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"header is not JSON: {exc}") from None
    if not isinstance(header, dict):
        raise ValueError("header is not a JSON object")
    if topic == "height":
        return _decode_height(header, frames)
    if topic != "strip":
        return Message(topic, header)
    if header.get("format") != STRIP_FORMAT or header.get("version") != STRIP_VERSION:
        raise ValueError(f"not an {STRIP_FORMAT} v{STRIP_VERSION} strip")
    if len(frames) != 3:
        raise ValueError("a strip has 3 frames")
    shape = (int(header["line_count"]), int(header["range_bins"]))
    payload = bytes(frames[2])
    if header.get("dtype") != "complex64" or len(payload) != shape[0] * shape[1] * 8:
        raise ValueError(f"payload of {len(payload)} bytes does not match {shape} complex64")
    return Message(topic, header, np.frombuffer(payload, "<c8").reshape(shape))


def _decode_height(header: dict, frames: list[bytes]) -> Message:
    if header.get("format") != HEIGHT_FORMAT or header.get("version") != HEIGHT_VERSION:
        raise ValueError(f"not an {HEIGHT_FORMAT} v{HEIGHT_VERSION} message")
    if len(frames) != 4:
        raise ValueError("a height message has 4 frames")
    shape = (int(header["line_count"]), int(header["range_bins"]))
    h, v = bytes(frames[2]), bytes(frames[3])
    if len(h) != shape[0] * shape[1] * 4 or len(v) != shape[0] * shape[1]:
        raise ValueError(f"height payload does not match {shape}")
    height = np.frombuffer(h, "<f4").reshape(shape)
    return Message("height", header, height, np.frombuffer(v, np.uint8).reshape(shape).astype(bool))


class ZmqPublisher:
    """Pipeline sink publishing strips, stats and the end message on a ZeroMQ XPUB socket.

    ``curve_secret_key``: a secret-key file made by ``rtsar keygen`` (ZeroMQ CURVE: clients
    need the matching public key); without it, binding beyond loopback prints a warning.
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
            (warn or (lambda m: print(m, file=sys.stderr)))(
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
    def strip(self, strip, pipeline) -> None:
        self.send("strip", strip_header(strip, pipeline), strip.lines)

    def height(self, strip, seq: int, pipeline) -> None:
        payload = [strip.height_m.astype("<f4"), strip.valid.astype(np.uint8)]
        self.send("height", height_header(strip, seq, pipeline), payload)

    def stats(self, stats: dict, pipeline) -> None:
        self.send("stats", _stats_header(stats, pipeline))

    def end(self, stats: dict, pipeline) -> None:
        self.send("end", _stats_header(stats, pipeline))

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.socket.close()


def _stats_header(stats: dict, pipeline) -> dict:
    return {
        "format": "rtsar-stats",
        "version": STRIP_VERSION,
        "stream_id": pipeline.stream_id,
        "publish_unix_s": time.time(),
        "source": pipeline.source.description,
        **stats,
    }


class StripSubscriber:
    """Client: connect a SUB socket and receive :class:`Message` s.

    ``curve_server_key``: the publisher's public-key file when it uses CURVE.
    Counts ``strips``, ``missed_strips`` (gaps in seq) and ``bad_messages`` (undecodable).
    """

    def __init__(
        self,
        endpoint: str = DEFAULT_ENDPOINT,
        curve_server_key: str | Path | None = None,
        hwm_messages: int = 0,
        context: zmq.Context | None = None,
    ):
        ctx = context or zmq.Context.instance()
        self.socket = s = ctx.socket(zmq.SUB)
        s.setsockopt(zmq.LINGER, 0)
        s.setsockopt(zmq.RCVHWM, int(hwm_messages))
        if curve_server_key is not None:
            server_public, _ = zmq.auth.load_certificate(str(curve_server_key))
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
        self._next_seq: int | None = None

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
        if header.get("stream_id") != self.stream_id:
            self.stream_id = header.get("stream_id")
            self._next_seq = None
        seq = int(header["seq"])
        if self._next_seq is not None and seq > self._next_seq:
            self.counters["missed_strips"] += seq - self._next_seq
        self._next_seq = seq + 1
        self.counters["strips"] += 1

    def close(self) -> None:
        self.socket.close(0)


def new_stream_id() -> str:
    return uuid.uuid4().hex[:16]
