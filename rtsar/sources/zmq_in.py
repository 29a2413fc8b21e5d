"""Shots from a GNU Radio flowgraph: a ZMQ PUB Sink's stream of complex64 items.

Two layouts, told apart by the message length:

* one pulse per vector item (the sink's ``vlen`` = samples per shot): every S·8 bytes is a shot;
* a flat complex stream sliced by ``packet_len`` tags (the sink's "pass tags" on): a shot starts
  at each ``packet_len`` tag and holds its value's samples (another length than the configured
  S: counted in ``wrong_length``, dropped).

With pass tags, each message begins with GNU Radio's tag header (rtsar.sources.gr_tags): its
item offset numbers the shots (vector items: the item's offset; a flat stream: the packets'
starts, one shot per packet period, the smallest spacing of starts seen, so guard samples
between packets are no gap: seq = the previous packet's + round(Δoffset / period), the first
packet's offset // S), so a message lost on the way becomes a gap
that ingest zero-fills, as for serial frames; ``rx_time`` tags give the instrument clock
(later shots: rx_time + items / rate).
Without tags the shots are numbered as they come and timed by arrival.  A message that does not
parse is counted (``bad_messages``), never raised.  The socket connects to ``endpoint`` (GNU
Radio's sink binds); a multipart message (a sink with a topic key) uses its last part.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import zmq

from .base import ShotBatch, Source
from .gr_tags import PmtError, parse_tag_header, rx_time_s

COUNTERS = ("messages", "bad_messages", "wrong_length", "partial_samples")


class ZmqSource(Source):
    """Shots of ``samples_per_shot`` from a GNU Radio ZMQ PUB Sink at ``endpoint``.

    ``item_rate_hz``: samples per second of a flat stream (the shot's sample rate), used with
    ``shot_rate_hz`` (the PRF, for vector items) to time shots after an ``rx_time`` tag.
    Iteration ends on ``close()`` or after ``idle_timeout_s`` without a message.
    """

    live = True

    def __init__(
        self,
        endpoint: str,
        samples_per_shot: int,
        item_rate_hz: float,
        shot_rate_hz: float,
        idle_timeout_s: float | None = None,
        poll_s: float = 0.05,
        context: zmq.Context | None = None,
    ):
        super().__init__()
        self.endpoint = endpoint
        self.samples = int(samples_per_shot)
        self.item_rate_hz, self.shot_rate_hz = float(item_rate_hz), float(shot_rate_hz)
        self.idle_timeout_s = idle_timeout_s
        self.poll_s = poll_s
        self.description = f"GNU Radio ZMQ stream {endpoint}"
        self.counters = {name: 0 for name in COUNTERS}
        self._ctx = context or zmq.Context.instance()
        self._next_seq = 0  # untagged streams: shots numbered as they come
        self._pending = np.zeros(0, np.complex64)  # flat stream: samples of an unfinished shot
        self._pending_offset = 0
        self._pending_len: int | None = None
        self._pending_seq = 0
        self._last_start: tuple[int, int] | None = None  # (item offset, seq) of the last packet
        self._period: int | None = None  # items from one packet start to the next
        self._flat = False  # a packet_len tag was seen: a flat stream sliced by tags
        self._clock: tuple[int, float, bool] | None = None  # (item offset, rx_time, flat?)
        self.stop_reason = ""

    def aux_channels(self) -> tuple[str, ...]:
        """None of them: a ZMQ PUB Sink sends one complex item stream (a multipart message's last
        part; tags only number, cut and time the shots), so it carries the main channel only."""
        return ()

    def _time(self, offset: int, flat: bool) -> float:
        if self._clock is None:
            return float("nan")
        at, t, clock_flat = self._clock
        rate = self.item_rate_hz if clock_flat else self.shot_rate_hz
        if clock_flat != flat:  # a clock from the other layout: items differ
            return float("nan")
        return t + (offset - at) / rate

    def decode(self, payload: bytes) -> list[tuple[int, float, np.ndarray]]:
        """(seq, instrument time, samples) of the shots one message completes."""
        self.counters["messages"] += 1
        offset, tags, start = None, [], 0
        if len(payload) >= 2 and payload[:2] == b"\xf0\x5f":
            try:
                offset, tags, start = parse_tag_header(payload)
            except PmtError:
                self.counters["bad_messages"] += 1
                return []
        body = payload[start:]
        if len(body) % 8:
            self.counters["bad_messages"] += 1
            return []
        items = np.frombuffer(body, "<c8")
        packet = [t for t in tags if t.key == "packet_len" and isinstance(t.value, int)]
        self._flat = self._flat or bool(packet)
        for t in tags:
            if t.key == "rx_time" and rx_time_s(t.value) is not None:
                self._clock = (t.offset, rx_time_s(t.value), self._flat)
        if self._flat:
            return self._slice(offset or 0, items, packet)
        if len(items) % self.samples:
            self.counters["wrong_length"] += 1
            return []
        shots = items.reshape(-1, self.samples)
        if offset is None:
            first = self._next_seq
        else:
            first = offset  # vector items: the offset counts shots
        self._next_seq = first + len(shots)
        return [(first + i, self._time(first + i, False), s) for i, s in enumerate(shots)]

    def _packet_seq(self, offset: int) -> int:
        """The shot number of a packet starting at item ``offset`` (module docstring)."""
        if self._last_start is None:
            seq = offset // self.samples
        else:
            last, last_seq = self._last_start
            step = offset - last
            if step > 0 and (self._period is None or step < self._period):
                self._period = step
            seq = last_seq + max(1, round(step / self._period)) if step > 0 else last_seq + 1
        self._last_start = (offset, seq)
        return seq

    def _slice(self, offset: int, items: np.ndarray, packet) -> list:
        """Flat stream: cut the items at the packet_len tags into shots (module docstring)."""
        out = []
        if self._pending_len is not None and offset != self._pending_offset + len(self._pending):
            # Items went missing (a lost message): the unfinished shot cannot be completed.
            self.counters["partial_samples"] += len(self._pending)
            self._pending, self._pending_len = np.zeros(0, np.complex64), None
        starts = {t.offset: t.value for t in packet if offset <= t.offset < offset + len(items)}
        bounds = sorted({offset, *starts, offset + len(items)})
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            seg = items[a - offset : b - offset]
            if a in starts:  # a packet begins: one still unfinished is cut short
                self.counters["partial_samples"] += len(self._pending)
                self._pending, self._pending_offset, self._pending_len = seg, a, starts[a]
                self._pending_seq = self._packet_seq(a)
            elif self._pending_len is None:  # samples outside any packet
                self.counters["partial_samples"] += len(seg)
                continue
            else:
                self._pending = np.concatenate([self._pending, seg])
            if self._pending_len is not None and len(self._pending) >= self._pending_len:
                n = self._pending_len
                if n == self.samples:
                    t = self._time(self._pending_offset, True)
                    out.append((self._pending_seq, t, self._pending[:n]))
                else:
                    self.counters["wrong_length"] += 1
                self.counters["partial_samples"] += len(self._pending) - n
                self._pending, self._pending_len = np.zeros(0, np.complex64), None
        return out

    def __iter__(self) -> Iterator[ShotBatch]:
        sock = self._ctx.socket(zmq.SUB)
        sock.setsockopt(zmq.SUBSCRIBE, b"")
        sock.setsockopt(zmq.LINGER, 0)
        sock.connect(self.endpoint)
        last = time.monotonic()
        try:
            while not self._stop:
                if not sock.poll(int(self.poll_s * 1000)):
                    if self.idle_timeout_s and time.monotonic() - last > self.idle_timeout_s:
                        self.stop_reason = "idle"
                        return
                    continue
                shots = []
                while sock.poll(0) and len(shots) < 1024:
                    shots += self.decode(sock.recv_multipart()[-1])
                last = time.monotonic()
                if shots:
                    arrival = np.full(len(shots), time.perf_counter())
                    yield ShotBatch(
                        np.array([s[0] for s in shots], np.int64),
                        np.array([s[1] for s in shots], np.float64),
                        arrival,
                        np.stack([s[2] for s in shots]).astype(np.complex64),
                    )
            self.stop_reason = "closed"
        finally:
            sock.close()
