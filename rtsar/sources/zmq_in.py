"""Shots from a GNU Radio flowgraph: a ZMQ PUB Sink's stream of complex64 items.

Two layouts, told apart by the message length:

* one pulse per vector item (the sink's ``vlen`` = samples per shot): every S·8 bytes is a shot;
* a flat complex stream sliced by ``packet_len`` tags (the sink's "pass tags" on): a shot starts
  at each ``packet_len`` tag and holds its value's samples.

With pass tags, each message begins with GNU Radio's tag header (rtsar.sources.gr_tags): its
item offset numbers the shots (vector items: the item's offset; a flat stream: the packets'
starts, one shot per packet period, the smallest spacing of starts seen that holds a shot
(>= S items: a short packet cannot shrink it), so guard samples between packets are no gap:
seq = the previous packet's + round(Δoffset / period), the first packet's offset // S), so a
message lost on the way becomes a gap that ingest zero-fills, as for serial frames; ``rx_time``
tags give the instrument clock (later shots: rx_time + items / rate).
The numbers count from the flowgraph's item 0 (``seq_origin``): a subscriber that joins late
keeps every shot's position along track, and ingest counts the shots it missed
(rtsar.stream.ingest, ``pulses_before_start``).  Without tags the shots are numbered as they
come and timed by arrival.

No message can end the run, and what one costs is bounded, whatever arrives:

* the socket refuses a message over ``max_message_bytes`` (default: a tag-header allowance of
  MAX_HEADER_BYTES plus MESSAGE_SHOTS shots; ZeroMQ then drops that connection, rtsar connects
  again, counted in ``oversized_messages``; a connection lost otherwise is a ``link_drops``);
* ZeroMQ queues at most QUEUE_BYTES of messages unread (RCVHWM = QUEUE_BYTES // the message
  limit, not its default of 1000 messages); a subscriber that falls behind loses messages
  there, silently on ZeroMQ's side: tagged shots come numbered, so ingest counts the loss as
  gap-filled pulses; untagged shots (numbered as they come) cannot tell;
* the layout (vector items or a flat stream) is set by consistent evidence, never by one
  message (``ZmqSource._layout``): a refused ``packet_len`` tag is no evidence at all;
* a flat stream's unfinished shot holds at most S samples: a packet of another length is
  counted (``wrong_length``) and its samples skipped, never held; a ``packet_len`` beyond
  MAX_PACKET_SAMPLES (rtsar.params.MAX_SAMPLES_PER_SHOT) or below 1 is refused
  (``bad_packet_len``) and its samples skipped the same way;
* one message's shots leave in batches of at most ``batch_shots``.

Every message that cannot be used is counted by kind (COUNTERS) and dropped.  The socket
connects to ``endpoint`` (GNU Radio's sink binds); a multipart message (a sink with a topic key)
uses its last part.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator

import numpy as np
import zmq
import zmq.utils.monitor

from ..params import MAX_SAMPLES_PER_SHOT
from .base import ShotBatch, Source
from .gr_tags import PmtError, parse_tag_header, rx_time_s

COUNTERS = (
    "messages",  # messages received
    "bad_messages",  # a tag header that does not parse, or a body that is not whole items
    "bad_offsets",  # an item offset whose shot number passes 2^63 - 1 (int64): dropped
    "bad_tags",  # a packet_len or rx_time tag whose value is not of its kind: ignored
    "wrong_length",  # messages (vector items) or packets of another length than a shot
    "bad_packet_len",  # packet_len < 1 or > MAX_PACKET_SAMPLES: refused, its samples skipped
    "partial_samples",  # samples of packets cut short, or outside any packet
    "oversized_messages",  # a message over max_message_bytes: refused, ZeroMQ dropped the link
    "link_drops",  # the connection dropped otherwise (the flowgraph stopped or restarted)
    "layout_changes",  # the stream's layout (vector items / flat) changed on consistent evidence
    "decoder_errors",  # a message the decoder failed on (a bug: never expected)
)
MAX_SEQ = (1 << 63) - 1  # shot numbers travel as int64
MAX_PACKET_SAMPLES = MAX_SAMPLES_PER_SHOT
MAX_HEADER_BYTES = 1 << 20  # tag headers: GNU Radio's carry a few tags of tens of bytes
MESSAGE_SHOTS = 256  # shots one message may carry (GNU Radio sends a work call's buffer)
BATCH_SHOTS = 64
QUEUE_BYTES = 256 << 20  # what ZeroMQ may queue for us: RCVHWM = QUEUE_BYTES // message limit
FLAT_EVIDENCE = 2  # messages with a valid packet_len tag that make the stream flat
VECTOR_EVIDENCE = 3  # messages in a row of whole shots numbered in shots that make it vector
RETRY_WAIT_S = 0.25  # after a drop: how long ZeroMQ has to say it reconnects by itself


def default_max_message_bytes(samples_per_shot: int) -> int:
    """The receive-size limit for shots of ``samples_per_shot`` (module docstring)."""
    return MAX_HEADER_BYTES + MESSAGE_SHOTS * int(samples_per_shot) * 8


class ZmqSource(Source):
    """Shots of ``samples_per_shot`` from a GNU Radio ZMQ PUB Sink at ``endpoint``.

    ``item_rate_hz``: samples per second of a flat stream (the shot's sample rate), used with
    ``shot_rate_hz`` (the PRF, for vector items) to time shots after an ``rx_time`` tag.
    ``max_message_bytes`` (None: :func:`default_max_message_bytes`) and ``batch_shots`` bound
    what one message costs, ``queue_bytes`` what ZeroMQ queues unread.  Iteration ends on
    ``close()`` or after ``idle_timeout_s`` without a message.
    """

    live = True
    seq_origin = 0  # tagged shots are numbered from the flowgraph's item 0

    def __init__(
        self,
        endpoint: str,
        samples_per_shot: int,
        item_rate_hz: float,
        shot_rate_hz: float,
        idle_timeout_s: float | None = None,
        poll_s: float = 0.05,
        context: zmq.Context | None = None,
        max_message_bytes: int | None = None,
        batch_shots: int = BATCH_SHOTS,
        queue_bytes: int = QUEUE_BYTES,
    ):
        super().__init__()
        self.endpoint = endpoint
        self.samples = int(samples_per_shot)
        self.item_rate_hz, self.shot_rate_hz = float(item_rate_hz), float(shot_rate_hz)
        self.idle_timeout_s = idle_timeout_s
        self.poll_s = poll_s
        self.max_message_bytes = int(max_message_bytes or default_max_message_bytes(self.samples))
        self.batch_shots = max(1, int(batch_shots))
        # ZeroMQ queues whole messages (RCVHWM, default 1000): at most queue_bytes of them.
        self.queue_messages = max(2, int(queue_bytes) // self.max_message_bytes)
        self.description = f"GNU Radio ZMQ stream {endpoint}"
        self.counters = {name: 0 for name in COUNTERS}
        self._ctx = context or zmq.Context.instance()
        self._next_seq = 0  # untagged streams: shots numbered as they come
        # Flat stream: the packet being cut (its samples held only when it is a shot's length).
        self._packet: dict | None = None  # {"start", "length", "seq", "have", "parts"}
        self._last_start: tuple[int, int] | None = None  # (item offset, seq) of the last packet
        self._period: int | None = None  # items from one packet start to the next
        self._flat: bool | None = None  # the layout consistent evidence set (None: not yet)
        self._flat_votes = 0  # messages with a valid packet_len tag, no vector evidence between
        self._vector_run = 0  # vector evidence, messages in a row
        self._prev: tuple[int, int] | None = None  # (item offset, items) of the last message
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

    def _layout(self, offset: int | None, n_items: int, valid_packet_len: bool) -> bool:
        """Whether this message is cut as a flat stream (True) or read as vector items.

        Evidence, per message: *vector* when it is a whole number of shots and either has no
        tag header or its item offset follows the previous message's in shots (offset + shots,
        where a flat stream's follows in items); *flat* when it carries a ``packet_len`` tag of
        a valid length.  A refused tag is no evidence.  The stream's layout is set by
        FLAT_EVIDENCE flat messages without vector evidence between them, or VECTOR_EVIDENCE
        vector messages in a row, so no single message can change how the stream is read
        (``layout_changes`` counts the changes).  A message with evidence is read as it says;
        one without, by the stream's layout (before there is one: flat when it continues a
        packet left open, else vector items).
        """
        vector = n_items > 0 and n_items % self.samples == 0
        if offset is not None:
            prev, self._prev = self._prev, (offset, n_items)
            by_items = prev is not None and offset == prev[0] + prev[1]
            by_shots = prev is not None and offset == prev[0] + prev[1] // self.samples
            vector = vector and by_shots and not by_items
        evidence = "vector" if vector else "flat" if valid_packet_len else None
        if evidence == "vector":
            self._vector_run, self._flat_votes = self._vector_run + 1, 0
            if self._vector_run >= VECTOR_EVIDENCE:
                self._set_layout(False)
        elif evidence == "flat":
            self._vector_run, self._flat_votes = 0, self._flat_votes + 1
            if self._flat_votes >= FLAT_EVIDENCE:
                self._set_layout(True)
        if evidence is not None:
            return evidence == "flat"
        if self._flat is not None:
            return self._flat
        p = self._packet
        return p is not None and offset is not None and offset == p["start"] + p["have"]

    def _set_layout(self, flat: bool) -> None:
        if self._flat is not None and self._flat != flat:
            self.counters["layout_changes"] += 1
            self._say(
                f"the stream from {self.endpoint} now reads as "
                + ("a flat stream cut by packet_len tags" if flat else "vector items")
            )
        self._flat = flat

    def decode(self, payload: bytes) -> list[tuple[int, float, np.ndarray]]:
        """(seq, instrument time, samples) of the shots one message completes; a message that
        cannot be used is counted (COUNTERS) and gives none."""
        self.counters["messages"] += 1
        offset, tags, start = None, [], 0
        if len(payload) >= 2 and payload[:2] == b"\xf0\x5f":
            try:
                offset, tags, start = parse_tag_header(payload)
            except PmtError:
                self.counters["bad_messages"] += 1
                return []
            if offset > MAX_SEQ:
                self.counters["bad_offsets"] += 1
                return []
        body = memoryview(payload)[start:]
        if len(body) % 8:
            self.counters["bad_messages"] += 1
            return []
        items = np.frombuffer(body, "<c8")
        packet = [t for t in tags if t.key == "packet_len"]
        typed = [t for t in packet if isinstance(t.value, int) and not isinstance(t.value, bool)]
        valid = [t for t in typed if 1 <= t.value <= MAX_PACKET_SAMPLES]
        self.counters["bad_tags"] += len(packet) - len(typed)
        self.counters["bad_packet_len"] += len(typed) - len(valid)
        flat = self._layout(offset, len(items), bool(valid))
        for t in tags:
            if t.key == "rx_time":
                seconds = rx_time_s(t.value)
                if seconds is None or not math.isfinite(seconds):
                    self.counters["bad_tags"] += 1
                else:
                    self._clock = (t.offset, seconds, flat)
        if flat:
            return self._slice(offset or 0, items, typed)
        self._cut()  # vector items: a packet left open cannot go on through them
        if len(items) % self.samples:
            self.counters["wrong_length"] += 1
            return []
        shots = items.reshape(-1, self.samples)
        first = self._next_seq if offset is None else offset  # vector items: offset counts shots
        if first + len(shots) - 1 > MAX_SEQ:
            self.counters["bad_offsets"] += 1
            return []
        self._next_seq = first + len(shots)
        return [(first + i, self._time(first + i, False), s) for i, s in enumerate(shots)]

    def _packet_seq(self, offset: int) -> int:
        """The shot number of a packet starting at item ``offset`` (module docstring)."""
        if self._last_start is None:
            seq = offset // self.samples
        else:
            last, last_seq = self._last_start
            step = offset - last
            # The period is the smallest spacing a whole shot fits in (>= S items): a short or
            # refused packet (packet_len 10) may cost its own number, never the stream's scale.
            if step >= self.samples and (self._period is None or step < self._period):
                self._period = step
            if self._period is None:  # no spacing a shot fits yet: one number per packet
                self._period = self.samples
            seq = last_seq + max(1, round(step / self._period)) if step > 0 else last_seq + 1
        self._last_start = (offset, seq)
        return seq

    def _start_packet(self, offset: int, length: int) -> None:
        """A packet_len tag at ``offset``: the packet before it, unfinished, is cut short."""
        self._cut()
        if 1 <= length <= MAX_PACKET_SAMPLES and length != self.samples:  # refused: counted
            self.counters["wrong_length"] += 1
        seq = self._packet_seq(offset)
        keep = length == self.samples and seq <= MAX_SEQ
        if length == self.samples and not keep:
            self.counters["bad_offsets"] += 1
        self._packet = {"start": offset, "length": length, "seq": seq, "have": 0}
        self._packet["parts"] = [] if keep else None  # None: counted, its samples skipped

    def _cut(self) -> None:
        """The current packet ends unfinished: a shot's samples received so far are partial."""
        p = self._packet
        if p is not None and p["parts"] is not None:
            self.counters["partial_samples"] += p["have"]
        self._packet = None

    def _slice(self, offset: int, items: np.ndarray, packet) -> list:
        """Flat stream: cut the items at the packet_len tags into shots (module docstring)."""
        out = []
        p = self._packet
        if p is not None and offset != p["start"] + p["have"]:
            self._cut()  # items went missing (a lost message): the packet cannot be completed
        end = offset + len(items)
        starts = {t.offset: t.value for t in packet if offset <= t.offset < end}
        bounds = sorted({offset, *starts, end})
        for a, b in zip(bounds[:-1], bounds[1:], strict=True):
            if a in starts:
                self._start_packet(a, starts[a])
            p = self._packet
            if p is None:  # samples outside any packet
                self.counters["partial_samples"] += b - a
                continue
            take = min(b - a, max(p["length"] - p["have"], 0))
            if p["parts"] is not None:
                p["parts"].append(items[a - offset : a - offset + take])
            p["have"] += take
            if take < b - a:  # the packet is whole and items follow it outside any packet
                self.counters["partial_samples"] += b - a - take
            if p["have"] >= p["length"]:
                if p["parts"] is not None:
                    samples = np.concatenate(p["parts"])
                    out.append((p["seq"], self._time(p["start"], True), samples))
                self._packet = None
        return out

    def _safe_decode(self, payload: bytes) -> list:
        """:meth:`decode`, and a failure of its own counted, not raised (a stream that one
        message could end would be a denial of service; the fuzz test keeps this at 0)."""
        try:
            return self.decode(payload)
        except Exception:  # noqa: BLE001 - counted, the run goes on
            self.counters["decoder_errors"] += 1
            self._packet = None
            return []

    def batches(self, shots: list) -> Iterator[ShotBatch]:
        """The decoded shots in ShotBatches of at most ``batch_shots``."""
        arrival = time.perf_counter()
        for i in range(0, len(shots), self.batch_shots):
            part = shots[i : i + self.batch_shots]
            yield ShotBatch(
                np.array([s[0] for s in part], np.int64),
                np.array([s[1] for s in part], np.float64),
                np.full(len(part), arrival),
                np.stack([s[2] for s in part]).astype(np.complex64),
            )

    def __iter__(self) -> Iterator[ShotBatch]:
        sock = self._ctx.socket(zmq.SUB)
        sock.setsockopt(zmq.SUBSCRIBE, b"")
        sock.setsockopt(zmq.LINGER, 0)
        sock.setsockopt(zmq.MAXMSGSIZE, self.max_message_bytes)
        sock.setsockopt(zmq.RCVHWM, self.queue_messages)
        monitor = sock.get_monitor_socket(zmq.EVENT_DISCONNECTED | zmq.EVENT_CONNECT_RETRIED)
        poller = zmq.Poller()
        poller.register(sock, zmq.POLLIN)
        poller.register(monitor, zmq.POLLIN)
        sock.connect(self.endpoint)
        last = time.monotonic()
        try:
            while not self._stop:
                ready = dict(poller.poll(int(self.poll_s * 1000)))
                if monitor in ready and self._link_dropped(monitor):
                    # ZeroMQ does not reconnect after a protocol error (a message over the
                    # limit): connect again here.
                    try:
                        sock.disconnect(self.endpoint)
                    except zmq.ZMQError:  # the endpoint's session is already gone
                        pass
                    sock.connect(self.endpoint)
                if sock not in ready:
                    if self.idle_timeout_s and time.monotonic() - last > self.idle_timeout_s:
                        self.stop_reason = "idle"
                        return
                    continue
                shots = []
                while sock.poll(0) and len(shots) < self.batch_shots:
                    shots += self._safe_decode(sock.recv_multipart()[-1])
                last = time.monotonic()
                yield from self.batches(shots)
            self.stop_reason = "closed"
        finally:
            sock.disable_monitor()
            monitor.close()
            sock.close()

    def _link_dropped(self, monitor) -> bool:
        """Count the disconnections the monitor reports, by kind; whether one was a refused
        message.  ZeroMQ reconnects by itself after a connection is lost (it reports a retry
        at once) but not after a protocol error, which a message over MAXMSGSIZE is."""
        refused = False
        while monitor.poll(0):
            event = zmq.utils.monitor.parse_monitor_message(monitor.recv_multipart())["event"]
            if event != zmq.EVENT_DISCONNECTED:
                continue
            self._cut()
            retried = False
            while monitor.poll(int(RETRY_WAIT_S * 1000)):
                kind = zmq.utils.monitor.parse_monitor_message(monitor.recv_multipart())
                if kind["event"] == zmq.EVENT_CONNECT_RETRIED:
                    retried = True
                    break
            if retried:
                self.counters["link_drops"] += 1
                self._say(f"the connection to {self.endpoint} dropped (the flowgraph stopped?)")
            else:
                refused = True
                self.counters["oversized_messages"] += 1
                self._say(
                    f"a message from {self.endpoint} over the {self.max_message_bytes:,}-byte "
                    "limit was refused (ZeroMQ drops the connection); reconnecting"
                )
        return refused
