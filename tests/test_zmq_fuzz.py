"""No message ends a `--zmq-in` run, and none costs unbounded memory (issue 28).

A deterministic fuzz of the GNU Radio message decoder (rtsar.sources.zmq_in): 100 000 messages
from a fixed seed, each a well-formed message of one of the layouts (vector items, a flat stream
cut by packet_len tags, rx_time tags, no header) mutated at random (bytes flipped, cut, spliced,
header fields and PMTs replaced), plus the cases seen to crash or grow before: an item offset
>= 2^63, a PMT dict whose key is a dict, a packet_len of 2^40, of -1 and of True, a huge
message.  The decoder is called directly (not through the counted safety net around it), and
every shot it gives goes through the batching the live loop uses.
"""

import struct
import threading
import time

import numpy as np
import pytest
import zmq

from rtsar.sources.gr_tags import pmt_long, pmt_rx_time, pmt_symbol, tag_header
from rtsar.sources.zmq_in import (
    COUNTERS,
    MAX_SEQ,
    QUEUE_BYTES,
    ZmqSource,
    default_max_message_bytes,
)

S = 16
FUZZ_MESSAGES = 100_000
SEED = 20240528


def _source(**kw):
    return ZmqSource("tcp://127.0.0.1:1", S, item_rate_hz=1e3, shot_rate_hz=10.0, **kw)


def _pmt_dict(key: bytes, value: bytes) -> bytes:
    """A PMT dict of one entry: type 0x09, the pair (key . value), null."""
    return b"\x09\x07" + key + value + b"\x06"


def _random_pmt(rng, depth=0) -> bytes:
    kind = int(rng.integers(0, 16))
    if depth > 3 or kind in (0, 1, 6):
        return bytes([kind if kind in (0, 1, 6) else 6])
    if kind == 2:
        n = int(rng.integers(0, 12))
        return b"\x02" + struct.pack(">H", n) + rng.bytes(n)
    if kind == 3:
        return b"\x03" + rng.bytes(4)
    if kind in (4, 11, 13):
        return bytes([kind]) + rng.bytes(8)
    if kind == 5:
        return b"\x05" + rng.bytes(16)
    if kind == 7:
        return b"\x07" + _random_pmt(rng, depth + 1) + _random_pmt(rng, depth + 1)
    if kind in (8, 12):
        n = int(rng.integers(0, 4))
        return (
            bytes([kind])
            + struct.pack(">I", n)
            + b"".join(_random_pmt(rng, depth + 1) for _ in range(n))
        )
    if kind == 9:
        return _pmt_dict(_random_pmt(rng, depth + 1), _random_pmt(rng, depth + 1))
    if kind == 10:
        n = int(rng.integers(0, 6))
        return b"\x0a" + bytes([int(rng.integers(0, 16)), 0]) + struct.pack(">I", n) + rng.bytes(n)
    return bytes([kind]) + rng.bytes(int(rng.integers(0, 9)))


def _well_formed(rng, state) -> bytes:
    """A message of one of the layouts, continuing the stream ``state`` describes."""
    layout = int(rng.integers(0, 4))
    if layout == 0:  # vector items
        n = int(rng.integers(1, 4))
        body = rng.standard_normal(2 * n * S).astype(np.float32).tobytes()
        state["vec"] += n
        return tag_header(state["vec"] - n, []) + body
    if layout == 1:  # untagged
        return rng.standard_normal(2 * S * int(rng.integers(0, 3))).astype(np.float32).tobytes()
    # a flat stream: packets of S (sometimes another length), cut across messages
    a = state["flat"]
    n = int(rng.integers(1, 3 * S))
    tags = [
        (
            p,
            pmt_symbol("packet_len"),
            pmt_long(S if rng.random() < 0.9 else int(rng.integers(1, 40))),
        )
        for p in range((a + S - 1) // S * S, a + n, S)
    ]
    if layout == 3:
        tags.append((a, pmt_symbol("rx_time"), pmt_rx_time(int(rng.integers(0, 1 << 40)), 0.5)))
    state["flat"] = a + n
    body = rng.standard_normal(2 * n).astype(np.float32).tobytes()
    return tag_header(a, tags, version=int(rng.integers(1, 3))) + body


def _mutated(rng, msg: bytes) -> bytes:
    b = bytearray(msg)
    kind = int(rng.integers(0, 9))
    if kind == 0 and b:  # flip bytes
        for i in rng.integers(0, len(b), int(rng.integers(1, 6))):
            b[i] = int(rng.integers(0, 256))
    elif kind == 1:  # cut
        del b[int(rng.integers(0, len(b) + 1)) :]
    elif kind == 2 and len(b) >= 11:  # the item offset, anywhere in u64
        b[3:11] = struct.pack("<Q", int(rng.integers(0, 1 << 63)) * int(rng.integers(1, 3)))
    elif kind == 3 and len(b) >= 19:  # the tag count
        b[11:19] = struct.pack("<Q", int(rng.integers(0, 1 << 17)))
    elif kind == 4:  # a header of random tags
        ntags = int(rng.integers(0, 4))
        head = struct.pack(
            "<HBQQ", 0x5FF0, int(rng.integers(0, 4)), int(rng.integers(0, 1 << 40)), ntags
        )
        for _ in range(ntags):
            head += struct.pack("<Q", int(rng.integers(0, 1 << 40)))
            head += b"".join(_random_pmt(rng) for _ in range(3))
        b = bytearray(head + bytes(b[-8 * int(rng.integers(0, 6)) :] if b else b""))
    elif kind == 5:  # spliced: a piece of itself inserted somewhere
        i, j = sorted(rng.integers(0, len(b) + 1, 2))
        k = int(rng.integers(0, len(b) + 1))
        b[k:k] = b[i:j]
    elif kind == 6:  # random bytes behind the magic
        b = bytearray(b"\xf0\x5f" + rng.bytes(int(rng.integers(0, 64))))
    # kinds 7, 8: unchanged (the stream must still make shots)
    return bytes(b)


def _targeted() -> list[bytes]:
    """The messages seen to crash or grow memory before (issue 28), each valid but for that."""
    body = np.zeros(S, np.complex64).tobytes()
    dict_key = _pmt_dict(pmt_symbol("k"), pmt_long(1))  # a dict used as a dict's key
    return [
        tag_header(1 << 63, []) + body,  # item offset >= 2^63
        tag_header((1 << 64) - 1, []) + body,
        tag_header(0, [(0, pmt_symbol("x"), _pmt_dict(dict_key, pmt_long(2)))]) + body,
        tag_header(0, [(0, pmt_symbol("packet_len"), pmt_long(1 << 40))]) + body,
        tag_header(S, [(S, pmt_symbol("packet_len"), pmt_long(-1))]) + body,
        tag_header(2 * S, [(2 * S, pmt_symbol("packet_len"), b"\x00")]) + body,  # True
        tag_header(3 * S, [(3 * S, pmt_symbol("rx_time"), pmt_long(5))]) + body,
    ]


@pytest.mark.slow
def test_decoder_fuzz_100k_messages_raises_nothing_and_holds_one_shot_at_most():
    rng = np.random.default_rng(SEED)
    src = _source()
    state = {"vec": 0, "flat": 0}
    raised, shots, most_held = [], 0, 0
    messages = _targeted() + [_mutated(rng, _well_formed(rng, state)) for _ in range(FUZZ_MESSAGES)]
    for msg in messages:
        try:
            out = src.decode(msg)
            batches = list(src.batches(out))
        except Exception as exc:  # noqa: BLE001 - what the test counts
            raised.append(repr(exc))
            continue
        shots += sum(len(b) for b in batches)
        for b in batches:
            assert b.samples.shape[1:] == (S,) and b.seq.min() >= 0 and b.seq.max() <= MAX_SEQ
        p = src._packet
        held = 0 if p is None or p["parts"] is None else sum(len(x) for x in p["parts"])
        most_held = max(most_held, held)
    assert raised == [], f"{len(raised)} exceptions, first: {raised[:3]}"
    assert src.counters["messages"] == len(messages) >= FUZZ_MESSAGES
    assert src.counters["decoder_errors"] == 0
    assert shots > FUZZ_MESSAGES // 10  # the unmutated messages still make shots
    for kind in ("bad_messages", "bad_offsets", "bad_tags", "bad_packet_len", "wrong_length"):
        assert src.counters[kind] > 0, kind  # every kind of refusal was exercised
    assert most_held <= S  # a flat stream's unfinished shot: never more than a shot's samples


def test_targeted_messages_are_counted_by_kind():
    src = _source()
    msgs = _targeted()
    for m in msgs[:3]:
        assert src.decode(m) == []
    # A bad tag changes nothing: the body is still read as the stream's layout (vector items).
    assert [len(src.decode(m)) for m in msgs[3:]] == [1, 1, 1, 1]
    c = src.counters
    assert c["bad_offsets"] == 2  # offsets 2^63 and 2^64 - 1
    assert c["bad_messages"] == 1  # the dict keyed by a dict
    assert c["bad_packet_len"] == 2  # 2^40 and -1
    assert c["bad_tags"] == 2  # packet_len True, rx_time a long
    # In a flat stream, a packet_len of 2^40 followed by a long stream holds nothing: its items
    # are skipped.
    src = _source()
    for a in (0, S):  # two packets: the stream is flat
        good = tag_header(a, [(a, pmt_symbol("packet_len"), pmt_long(S))])
        assert len(src.decode(good + np.ones(S, np.complex64).tobytes())) == 1
    big = tag_header(2 * S, [(2 * S, pmt_symbol("packet_len"), pmt_long(1 << 40))])
    src.decode(big + np.zeros(S, np.complex64).tobytes())
    a, chunk = 3 * S, np.zeros(4096, np.complex64).tobytes()
    for _ in range(200):  # 800 k items of the packet, contiguous
        assert src.decode(tag_header(a, []) + chunk) == []
        a += 4096
    assert src._packet["parts"] is None and src._packet["have"] == a - 2 * S
    assert src.counters["bad_packet_len"] == 1 and src.counters["partial_samples"] == 0
    # The next packet_len tag of the right length starts shots again.
    good = tag_header(a, [(a, pmt_symbol("packet_len"), pmt_long(S))])
    assert len(src.decode(good + np.ones(S, np.complex64).tobytes())) == 1


def _vector(seq: int, n: int = 2) -> bytes:
    return tag_header(seq, []) + np.full(n * S, seq, np.complex64).tobytes()


@pytest.mark.parametrize("length", [-1, 1 << 40, True, S, S + 3])
def test_one_packet_len_tag_does_not_change_how_a_vector_stream_is_read(length):
    """From a cold review: one message with a packet_len tag, even a refused one, switched the
    decoder to a flat stream for good; every later vector message was thrown away (300 pulses
    sent, 50 processed).  Now one message, refused or not, is read alone and changes nothing."""
    src = _source()
    value = b"\x00" if length is True else pmt_long(length)
    got = []
    for i in range(20):
        if i == 10:
            hostile = tag_header(2 * i, [(2 * i, pmt_symbol("packet_len"), value)])
            got += src.decode(hostile + np.zeros(2 * S, np.complex64).tobytes())
        got += src.decode(_vector(2 * i))
    seqs = sorted({s for s, _, _ in got})
    assert set(range(40)) <= set(seqs)
    assert src._flat is False and src.counters["layout_changes"] == 0


def test_the_layout_changes_only_on_consistent_evidence():
    """A flat stream keeps its layout through a message of whole shots (or a lost message);
    a flowgraph restarted with vector items is read as vector items after three messages, and
    the change is counted."""
    src = _source()
    out, a = [], 0
    for _ in range(6):  # packets of S in messages of 3 S / 2 items
        n = 3 * S // 2
        tags = [(p, pmt_symbol("packet_len"), pmt_long(S)) for p in range(a, a + n) if p % S == 0]
        out += src.decode(tag_header(a, tags) + np.ones(n, np.complex64).tobytes())
        a += n
        if a == 3 * n:  # a stray message of whole shots
            assert src.decode(_vector(5)) == []
    assert src._flat is True and len(out) == 8
    vec = [src.decode(_vector(2 * i)) for i in range(6)]
    # The first follows no message in shots (no evidence: read as the flat stream); each
    # later one is evidence and read as vector items; the third in a row sets the layout.
    assert [len(v) for v in vec] == [0, 2, 2, 2, 2, 2]
    assert src._flat is False and src.counters["layout_changes"] == 1


def test_one_message_leaves_in_batches_of_the_configured_size():
    src = _source(batch_shots=5)
    shots = src.decode(tag_header(0, []) + np.zeros(23 * S, np.complex64).tobytes())
    sizes = [len(b) for b in src.batches(shots)]
    assert sizes == [5, 5, 5, 5, 3]


def test_a_message_over_the_receive_limit_is_refused_counted_and_the_stream_goes_on():
    """The socket's receive limit (from the shot size) refuses a message of 4 MiB without
    holding it; ZeroMQ drops that connection, counted in oversized_messages, and rtsar
    reconnects: the shots sent after it arrive."""
    limit = default_max_message_bytes(S)
    assert limit == (1 << 20) + 256 * S * 8
    ctx = zmq.Context()
    pub = ctx.socket(zmq.XPUB)
    pub.setsockopt(zmq.XPUB_VERBOSE, 1)  # every (re)subscription is told
    port = pub.bind_to_random_port("tcp://127.0.0.1")
    src = ZmqSource(f"tcp://127.0.0.1:{port}", S, 1e3, 10.0, idle_timeout_s=1.5, context=ctx)
    said = []
    src.notify = said.append

    def send():
        pub.recv()  # subscribed
        pub.send(tag_header(0, []) + np.zeros(2 * S, np.complex64).tobytes())
        # Taken by the source before the big one: ZeroMQ drops the unread messages of the
        # connection it closes (on a loaded machine the first one could still be waiting).
        deadline = time.monotonic() + 5
        while src.counters["messages"] < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        pub.send(b"\0" * (4 << 20))  # over the limit
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:  # until the subscriber has connected again
            if pub.poll(50) and pub.recv()[:1] == b"\x01":
                break
        pub.send(tag_header(7, []) + np.ones(S, np.complex64).tobytes())

    t = threading.Thread(target=send, daemon=True)
    t.start()
    seq = np.concatenate([b.seq for b in src])
    t.join(5)
    pub.close(0)
    ctx.term()
    assert list(seq) == [0, 1, 7]
    # Counted by kind: a refused message, not a lost link (both were link_drops before).
    assert src.counters["oversized_messages"] == 1 and "limit" in said[0]
    assert src.counters["link_drops"] == 0
    assert src.counters["messages"] == 2  # the big one never reached the decoder


def test_zeromq_queues_a_bounded_number_of_bytes_and_the_loss_shows_as_gaps():
    """From a cold review: the SUB socket kept ZeroMQ's default queue of 1000 messages (4.7 GB
    at psaltis-max's message limit; a flood took a run from 339 MB to 2.27 GB).  The queue is now
    QUEUE_BYTES // the message limit: a stalled subscriber holds that much, the sink drops the
    rest at its own limit, and the tagged shots that arrive say how many were lost."""
    big = ZmqSource("tcp://127.0.0.1:1", 1800, 1e6, 1e3)
    assert 50 <= big.queue_messages <= QUEUE_BYTES // default_max_message_bytes(1800)
    shots, n_messages, s_big = 32, 60, 4096  # messages of 1 MiB, limit 9.4 MB, a queue of 3
    limit = default_max_message_bytes(s_big)
    ctx = zmq.Context()
    pub = ctx.socket(zmq.XPUB)
    pub.setsockopt(zmq.SNDHWM, 2)  # a sink that drops what its subscriber does not take
    port = pub.bind_to_random_port("tcp://127.0.0.1")
    src = ZmqSource(
        f"tcp://127.0.0.1:{port}",
        s_big,
        1e6,
        1e3,
        idle_timeout_s=1.0,
        context=ctx,
        queue_bytes=3 * limit,
    )
    assert src.queue_messages == 3
    body = np.zeros(shots * s_big, np.complex64).tobytes()
    resumed = threading.Event()

    def send():
        pub.recv()  # subscribed
        for i in range(n_messages):
            pub.send(tag_header(i * shots, []) + body)
            time.sleep(0.02)
        resumed.wait(10)
        time.sleep(0.3)
        pub.send(tag_header(n_messages * shots, []) + body)

    t = threading.Thread(target=send, daemon=True)
    t.start()
    seqs = []
    for b in src:
        if not seqs:
            time.sleep(2.0)  # stalled while the flowgraph sends the rest
            resumed.set()
        seqs += list(b.seq)
    t.join(5)
    pub.close(0)
    ctx.term()
    sent = (n_messages + 1) * shots
    assert seqs == sorted(seqs) and seqs[-1] == sent - 1  # the last one arrives
    assert len(seqs) // shots < 30  # of 61: ZeroMQ's queues, the sockets' buffers, no more
    assert sent - len(seqs) == (seqs[-1] + 1) - len(set(seqs))  # what was lost is a gap


@pytest.mark.parametrize("name", COUNTERS)
def test_every_counter_starts_at_zero(name):
    assert _source().counters[name] == 0
