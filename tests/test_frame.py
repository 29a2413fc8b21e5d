"""The instrument frame: layout, round trips, rejection and resynchronisation, fuzzing."""

import struct
import zlib

import numpy as np
import pytest
from conftest import crandn
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tools_loader import load_tool

from rtsar.sources.frame import (
    OVERHEAD_BYTES,
    PREFIX_BYTES,
    SYNC,
    FrameParser,
    encode_frame,
    frame_bytes,
)


def _pieces(stream: bytes, cuts):
    """``stream`` cut at the (sorted) offsets ``cuts``."""
    edges = [0, *cuts, len(stream)]
    return [stream[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _crc(b: bytes) -> bytes:
    return struct.pack("<I", zlib.crc32(b))


def _by_the_table(version, code, channels, count, seq, stamp, payload: bytes) -> bytes:
    """A frame assembled field by field from the module docstring's table."""
    header = (
        bytes([version, code])
        + channels.to_bytes(2, "little")
        + count.to_bytes(4, "little")
        + seq.to_bytes(8, "little")
        + stamp.to_bytes(8, "little")
    )
    return bytes([0x1A, 0xCF, 0xFC, 0x1D]) + header + _crc(header) + payload + _crc(payload)


def test_crc_is_the_documented_one():
    assert zlib.crc32(b"123456789") == 0xCBF43926


def test_layout_matches_the_table(rng):
    x = crandn(rng, 2, 3, dtype=np.complex64)
    iq = np.stack([x.real, x.imag], axis=-1).astype("<f4")  # channel-major, I then Q
    want = _by_the_table(1, 1, 2, 3, 2**64 - 1, 123456789, iq.tobytes())
    assert encode_frame(2**64 - 1, 123456789, x) == want
    assert len(want) == frame_bytes(3, 2, "cf32") == OVERHEAD_BYTES + 2 * 3 * 8

    y = np.array([1.4 - 2.6j, -40000 + 40000j, 0.5 - 0.5j])
    ints = np.array([[1, -3], [-32768, 32767], [0, -0]], "<i2")  # rounded half-to-even, clipped
    assert encode_frame(7, 8, y, "ci16") == _by_the_table(1, 2, 1, 3, 7, 8, ints.tobytes())


@pytest.mark.parametrize("sample_type", ["cf32", "ci16"])
@pytest.mark.parametrize("shape", [(17,), (1, 5), (3, 11)])
def test_round_trip(rng, sample_type, shape):
    x = 1000 * crandn(rng, *shape)
    frames = FrameParser().feed(encode_frame(42, 10**18, x, sample_type))
    assert len(frames) == 1
    f = frames[0]
    assert (f.sequence, f.timestamp_ns, f.version, f.sample_type) == (42, 10**18, 1, sample_type)
    assert f.samples.dtype == np.complex64
    assert f.samples.shape == np.atleast_2d(x).shape
    want = np.atleast_2d(x).astype(np.complex64)
    if sample_type == "ci16":
        want = np.rint(want.real) + 1j * np.rint(want.imag)
    np.testing.assert_array_equal(f.samples, want)
    assert f.nbytes == len(encode_frame(42, 10**18, x, sample_type))


def test_cf32_carries_nonfinite_ci16_refuses():
    x = np.array([np.nan, np.inf * 1j, 1.0])
    (f,) = FrameParser().feed(encode_frame(0, 0, x))
    np.testing.assert_array_equal(f.samples[0], x.astype(np.complex64))
    with pytest.raises(ValueError, match="NaN or Inf"):
        encode_frame(0, 0, x, "ci16")


@pytest.mark.parametrize(
    "args, match",
    [
        ((-1, 0, [1j]), "sequence"),
        ((0, 2**64, [1j]), "timestamp_ns"),
        ((0, 0, np.zeros(0)), "non-empty"),
        ((0, 0, np.zeros((1, 2, 3))), "non-empty"),
        ((0, 0, [1j], "cu8"), "sample_type"),
    ],
)
def test_encode_refuses(args, match):
    with pytest.raises(ValueError, match=match):
        encode_frame(*args)


def _three_frames(rng):
    return [encode_frame(s, 0, crandn(rng, 8)) for s in (1, 2, 3)]


@pytest.mark.parametrize(
    "where, counter",
    [
        (4, "header_crc_errors"),
        (29, "header_crc_errors"),
        (40, "payload_crc_errors"),
        (-1, "payload_crc_errors"),
    ],
)
def test_crc_failures_are_counted_and_the_next_frame_found(rng, where, counter):
    a, b, c = _three_frames(rng)
    b = bytearray(b)
    b[where] ^= 0x10
    p = FrameParser()
    frames = p.feed(a + bytes(b) + c)
    assert [f.sequence for f in frames] == [1, 3]
    assert p.counters[counter] == 1
    assert p.counters["frames_ok"] == 2
    assert p.counters["bytes_skipped"] == len(b)
    assert p.buffered == 0


def _header_only(version=1, code=1, channels=1, count=4):
    head = struct.pack("<BBHIQQ", version, code, channels, count, 9, 9)
    return SYNC + head + _crc(head)


@pytest.mark.parametrize(
    "fields",
    [
        {"version": 2},
        {"code": 0},
        {"code": 3},
        {"channels": 0},
        {"count": 0},
        {"count": 1025},  # 8200 bytes, over the limit below
    ],
)
def test_bad_headers_are_counted(rng, fields):
    a, b, c = _three_frames(rng)
    p = FrameParser(max_payload_bytes=8192)
    frames = p.feed(a + _header_only(**fields) + b + c)
    assert [f.sequence for f in frames] == [1, 2, 3]
    assert p.counters["bad_headers"] == 1
    assert p.counters["bytes_skipped"] == PREFIX_BYTES


def test_garbage_does_not_grow_the_buffer(rng):
    p = FrameParser(max_payload_bytes=4096)
    garbage = rng.bytes(1 << 20).replace(SYNC, b"")
    for i in range(0, len(garbage), 4096):
        assert p.feed(garbage[i : i + 4096]) == []
        assert p.buffered <= 3
    # A valid header that promises the largest allowed payload, which never comes: at most one
    # frame is held, and a sync word inside the awaited payload is not searched for (yet).
    promise = _header_only(count=512)  # 4096 bytes
    p.feed(promise)
    for i in range(0, len(garbage), 1000):
        p.feed(SYNC + garbage[i : i + 1000])
        assert p.buffered <= OVERHEAD_BYTES + 4096
    c = p.counters
    assert c["frames_ok"] == 0
    assert c["bytes_fed"] == c["bytes_skipped"] + p.buffered


def test_frames_split_anywhere(rng):
    stream = b"".join(encode_frame(s, s, crandn(rng, 2, 30), "ci16") for s in range(20))
    p = FrameParser()
    got = [f for piece in _pieces(stream, range(1, len(stream), 7)) for f in p.feed(piece)]
    assert [f.sequence for f in got] == list(range(20))
    assert p.buffered == 0


# -- the property: intact frames come back exactly, corrupted ones are missing --------------------
_garbage = st.one_of(
    st.just(b""),
    st.binary(max_size=40),
    st.binary(max_size=12).map(lambda b: SYNC + b),  # a false sync word
    st.binary(min_size=2, max_size=2).map(lambda b: SYNC[:2] + b),
)


@settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(st.data())
def test_corrupt_frames_are_exactly_the_missing_ones(data):
    n = data.draw(st.integers(1, 150), label="frames")
    first = data.draw(st.integers(0, 2**64 - 1 - n), label="first sequence")
    sizes = data.draw(st.lists(st.integers(1, 40), min_size=n, max_size=n), label="samples")
    kinds = data.draw(
        st.lists(st.sampled_from(["cf32", "ci16"]), min_size=n, max_size=n), label="types"
    )
    n_bad = max(1, round(0.01 * n))
    bad = data.draw(st.sets(st.integers(0, n - 1), min_size=n_bad, max_size=n_bad), label="bad")
    rng = np.random.default_rng(data.draw(st.integers(0, 2**32 - 1), label="sample seed"))

    parts, sent, sync_lost = [], [], 0
    for k in range(n):
        parts.append(data.draw(_garbage, label="garbage"))
        x = 1000 * crandn(rng, 1 + k % 2, sizes[k])
        frame = bytearray(encode_frame(first + k, 5 * k, x, kinds[k]))
        if k in bad:
            at = data.draw(st.integers(0, len(frame) - 1), label="corrupt at")
            if data.draw(st.booleans(), label="cut short"):
                # The header may survive and promise a payload that runs into the next frames.
                del frame[at:]
            else:
                frame[at] ^= data.draw(st.integers(1, 255), label="xor")
            sync_lost += at < len(SYNC)
        else:
            if kinds[k] == "ci16":
                x = np.rint(x.real) + 1j * np.rint(x.imag)
            sent.append((first + k, x.astype(np.complex64)))
        parts.append(bytes(frame))
    parts.append(data.draw(_garbage, label="tail"))
    stream = b"".join(parts)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=40), label="cuts"))

    p = FrameParser()
    got = [f for piece in _pieces(stream, cuts) for f in p.feed(piece)]
    # Idle fill (no sync word) as long as the largest frame: a header cut short at the end of the
    # stream may still be waiting for its payload, with intact frames behind it.
    fill = bytes(frame_bytes(40, 2, "cf32"))
    got += p.feed(fill)

    assert [f.sequence for f in got] == [s for s, _ in sent]
    for f, (_, x) in zip(got, sent, strict=True):
        np.testing.assert_array_equal(f.samples, x)
    seqs = [first - 1, *(f.sequence for f in got), first + n]
    gaps = [b - a - 1 for a, b in zip(seqs[:-1], seqs[1:], strict=True)]
    assert sum(gaps) == n_bad  # the sequence gaps are exactly the bad frames

    c = p.counters
    assert c["frames_ok"] == n - n_bad
    assert c["bytes_fed"] == len(stream) + len(fill)
    assert c["bytes_fed"] == sum(f.nbytes for f in got) + c["bytes_skipped"] + p.buffered
    assert p.buffered < len(SYNC)
    assert c["bad_headers"] == 0  # neither a flipped byte nor a cut passes the header CRC
    # Each bad frame whose sync word survived fails one CRC; false sync words fail at most one.
    rejected = c["header_crc_errors"] + c["payload_crc_errors"]
    assert n_bad - sync_lost <= rejected <= stream.count(SYNC) - len(got)


def test_fuzz_small():
    """A few thousand streams of tools/fuzz_frames.py (the full run is 1e5: see its doc)."""
    fuzz = load_tool("fuzz_frames")
    stats = fuzz.fuzz(4000, seed=1)
    assert sum(stats.streams.values()) == 4000
    assert stats.frames > 0
    for name in ("header_crc_errors", "payload_crc_errors", "bad_headers", "bytes_skipped"):
        assert stats.counters[name] > 0, name


def _false_header(samples: int, channels: int = 1) -> bytes:
    """A sync word and a CRC-valid header announcing a payload that never follows."""
    import struct
    import zlib

    header = struct.pack("<BBHIQQ", 1, 1, channels, samples, 7, 0)
    return b"\x1a\xcf\xfc\x1d" + header + struct.pack("<I", zlib.crc32(header))


def test_a_false_header_of_another_shape_holds_nothing():
    # A CRC-valid header announcing 60 MiB, then intact frames: a parser that knows the stream's
    # shot refuses the header at once, and the frames behind it come out in the same call.
    shots = [encode_frame(k, k, np.full(16, k, np.complex64)) for k in range(5)]
    p = FrameParser(samples_per_shot=16, max_channels=4)
    got = p.feed(_false_header(2_000_000, 4) + b"".join(shots))
    assert [f.sequence for f in got] == list(range(5))
    assert p.counters["wrong_length"] == 1 and p.buffered == 0


def test_frames_behind_a_header_whose_payload_never_came_are_recovered_at_the_end():
    # A header of an allowed shape (4 channels) whose payload is cut by the link holds up to one
    # such frame of bytes, here two intact one-channel frames; when the link ends, finish()
    # gives up on the cut frame and returns the intact frames behind it.
    shots = [encode_frame(k, k, np.full(16, k, np.complex64)) for k in range(3)]
    p = FrameParser(samples_per_shot=16, max_channels=4)
    got = p.feed(_false_header(16, 4) + shots[1] + shots[2])
    assert got == [] and p.buffered > 0
    got = p.finish()
    assert [f.sequence for f in got] == [1, 2]
    assert p.counters["truncated_frames"] == 1 and p.buffered == 0
    c = p.counters
    assert c["bytes_fed"] == sum(f.nbytes for f in got) + c["bytes_skipped"]
