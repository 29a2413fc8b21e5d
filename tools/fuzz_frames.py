"""Fuzz the frame parser: random byte streams, fed in random pieces, must never break it.

    python tools/fuzz_frames.py [--streams 100000] [--seed 0] [--only INDEX] [--throughput]

Four kinds of stream, in turn: pure random bytes; random bytes strewn with sync words, headers
with a valid CRC but impossible fields, and valid headers followed by a wrong payload; valid frame
streams (random sizes, sample types and channel counts, garbage in between); and valid frame
streams mutated by byte flips, cuts, insertions and repeated pieces.  Each stream is fed in
pieces of random sizes.  Checked on every stream:

* ``feed`` never raises;
* every frame returned re-encodes to bytes that occur in the stream, so both its CRCs passed
  over bytes that were really sent;
* the buffer never exceeds one frame of ``max_payload_bytes``;
* every byte is accounted for: fed = returned frames + skipped + buffered;
* no frame is lost to a resynchronisation: every intact copy of a sent frame that is left in
  the (mutated) stream comes back, unless it lies inside a frame that came back or in the
  buffered tail (behind a valid header whose payload is still awaited);
* an unmutated frame stream comes back whole, in order.

Stream i is drawn from the seed (seed, i): ``--only i`` replays it.  ``--throughput`` measures the
parser on 1800-sample frames instead.
"""

from __future__ import annotations

import argparse
import sys
import time
import zlib
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from rtsar.sources.frame import (
    HEADER,
    OVERHEAD_BYTES,
    SAMPLE_TYPES,
    SYNC,
    FrameParser,
    encode_frame,
)

KINDS = ("random", "syncs", "frames", "mutated")
MAX_PAYLOAD_BYTES = 2048  # small, so that oversized lengths and the buffer bound are exercised


@dataclass
class FuzzStats:
    streams: Counter = field(default_factory=Counter)  # per kind
    bytes: int = 0
    frames: int = 0
    counters: Counter = field(default_factory=Counter)  # the parsers' counters, summed
    seconds: float = 0.0


def _random_frame(rng: np.random.Generator) -> bytes:
    channels = int(rng.integers(1, 4))
    count = int(rng.integers(1, 65))
    kind = "cf32" if rng.random() < 0.5 else "ci16"
    x = rng.standard_normal((channels, count, 2)) * (1.0 if kind == "cf32" else 3000.0)
    seq, stamp = (int(v) for v in rng.integers(0, 2**63, 2, dtype=np.uint64))
    return encode_frame(seq, stamp, x[..., 0] + 1j * x[..., 1], kind)


def _header(rng: np.random.Generator, valid_payload: bool) -> bytes:
    """A sync word and a header whose CRC passes; its fields are impossible unless
    ``valid_payload``, in which case a payload with a wrong CRC follows."""
    version, code, channels, count = 1, int(rng.choice(list(SAMPLE_TYPES.values()))), 1, 4
    if valid_payload:
        tail = rng.bytes(8 * count) + b"\0\0\0\0"
    else:
        tail = b""
        which = int(rng.integers(5))
        if which == 0:
            version = int(rng.integers(2, 256))
        elif which == 1:
            code = int(rng.choice([0, 3, 255]))
        elif which == 2:
            channels = 0
        elif which == 3:
            count = 0
        else:
            count = MAX_PAYLOAD_BYTES // 4 + 1  # one sample over the limit, for ci16
            code = 2
    head = HEADER.pack(version, code, channels, count, 0, 0)
    return SYNC + head + zlib.crc32(head).to_bytes(4, "little") + tail


def _insert(stream: bytes, piece: bytes, rng: np.random.Generator) -> bytes:
    at = int(rng.integers(0, len(stream) + 1))
    return stream[:at] + piece + stream[at:]


def make_stream(rng: np.random.Generator, kind: str) -> tuple[bytes, list[bytes]]:
    """A stream of the given kind and the frames that were put in it (before any mutation)."""
    if kind == "random":
        return rng.bytes(int(rng.integers(0, 3000))), []
    if kind == "syncs":
        stream = rng.bytes(int(rng.integers(0, 2000)))
        for _ in range(int(rng.integers(1, 8))):
            r = rng.random()
            if r < 0.5:
                piece = SYNC + rng.bytes(int(rng.integers(0, 40)))
            else:
                piece = _header(rng, valid_payload=r < 0.7)
            stream = _insert(stream, piece, rng)
        return stream, []
    frames = [_random_frame(rng) for _ in range(int(rng.integers(1, 8)))]
    parts = []
    for f in frames:
        if rng.random() < 0.3:
            parts.append(rng.bytes(int(rng.integers(0, 50))))
        parts.append(f)
    stream = b"".join(parts)
    if kind == "frames":
        return stream, frames
    for _ in range(int(rng.integers(1, 6))):
        r = rng.random()
        n = len(stream)
        if r < 0.35 and n:  # flip bytes
            b = bytearray(stream)
            for i in rng.integers(0, n, int(rng.integers(1, 4))):
                b[i] ^= int(rng.integers(1, 256))
            stream = bytes(b)
        elif r < 0.55 and n:  # cut a piece out
            a = int(rng.integers(0, n))
            stream = stream[:a] + stream[a + int(rng.integers(1, 200)) :]
        elif r < 0.7:  # insert garbage or a sync word
            piece = SYNC if rng.random() < 0.5 else rng.bytes(int(rng.integers(1, 30)))
            stream = _insert(stream, piece, rng)
        elif r < 0.85 and n:  # repeat a piece (a duplicated or re-sent fragment)
            a = int(rng.integers(0, n))
            stream = _insert(stream, stream[a : a + int(rng.integers(1, 300))], rng)
        elif n:  # truncate
            stream = stream[: int(rng.integers(0, n))]
    return stream, frames


def check_stream(
    stream: bytes, sent: list[bytes], whole: bool, rng: np.random.Generator, stats: FuzzStats
) -> None:
    """Feed ``stream`` in random pieces; raise AssertionError if any check fails.

    ``sent``: the frames put in the stream; ``whole``: the stream holds them unmutated."""
    parser = FrameParser(MAX_PAYLOAD_BYTES)
    limit = OVERHEAD_BYTES + MAX_PAYLOAD_BYTES
    frames = []
    pos = 0
    while pos < len(stream):
        n = int(rng.integers(1, 2 ** int(rng.integers(1, 13)) + 1))
        frames += parser.feed(stream[pos : pos + n])
        pos += n
        if parser.buffered > limit:
            raise AssertionError(f"buffer holds {parser.buffered} bytes, more than {limit}")
    encoded = [encode_frame(f.sequence, f.timestamp_ns, f.samples, f.sample_type) for f in frames]
    # Where the returned frames were: the parser scans forward and accepts the first valid frame
    # it meets, so each is the first occurrence of its bytes after the end of the previous one.
    spans = []
    end = 0
    for e in encoded:
        start = stream.find(e, end)
        if start < 0:
            raise AssertionError("a returned frame does not occur in the stream")
        end = start + len(e)
        spans.append((start, end))
    starts = {a for a, _ in spans}
    pending = len(stream) - parser.buffered
    for e in sent:
        at = stream.find(e)
        while 0 <= at < pending:
            if at not in starts and not any(a < at < b for a, b in spans):
                raise AssertionError(f"an intact frame at byte {at} was not returned")
            at = stream.find(e, at + 1)
    c = parser.counters
    accounted = sum(len(e) for e in encoded) + c["bytes_skipped"] + parser.buffered
    if c["bytes_fed"] != len(stream) or accounted != len(stream):
        raise AssertionError(f"{len(stream)} bytes fed, {accounted} accounted for ({c})")
    if c["frames_ok"] != len(frames):
        raise AssertionError(f"frames_ok = {c['frames_ok']}, {len(frames)} returned")
    if whole and encoded != sent:
        raise AssertionError(f"{len(sent)} frames sent, {len(encoded)} came back or differ")
    stats.bytes += len(stream)
    stats.frames += len(frames)
    stats.counters.update(c)


def fuzz(streams: int, seed: int = 0, first: int = 0) -> FuzzStats:
    """Run streams ``first`` .. ``first + streams - 1``; raise AssertionError naming the first
    stream that fails."""
    stats = FuzzStats()
    t0 = time.perf_counter()
    for i in range(first, first + streams):
        rng = np.random.default_rng([seed, i])
        kind = KINDS[i % len(KINDS)]
        stream, sent = make_stream(rng, kind)
        try:
            check_stream(stream, sent, kind == "frames", rng, stats)
        except Exception as exc:
            raise AssertionError(f"stream {i} ({kind}, seed {seed}): {exc}") from exc
        stats.streams[kind] += 1
    stats.seconds = time.perf_counter() - t0
    return stats


def throughput(
    frames: int = 20000, samples: int = 1800, chunk: int = 65536, sample_type: str = "cf32"
) -> tuple[float, float]:
    """Parser speed on a stream of ``frames`` frames fed in ``chunk``-byte pieces:
    (frames/s, bytes/s), best of three."""
    rng = np.random.default_rng(0)
    scale = 1.0 if sample_type == "cf32" else 3000.0
    pool = [
        encode_frame(
            i,
            i,
            scale * (rng.standard_normal(samples) + 1j * rng.standard_normal(samples)),
            sample_type,
        )
        for i in range(64)
    ]
    stream = b"".join(pool[i % len(pool)] for i in range(frames))
    pieces = [stream[i : i + chunk] for i in range(0, len(stream), chunk)]
    best = float("inf")
    for _ in range(3):
        parser = FrameParser()
        t0 = time.perf_counter()
        for piece in pieces:
            parser.feed(piece)
        best = min(best, time.perf_counter() - t0)
        if parser.counters["frames_ok"] != frames:
            raise AssertionError("the throughput stream did not parse")
    return frames / best, len(stream) / best


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("--streams", type=int, default=100_000, help="streams to try (default 1e5)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", type=int, metavar="INDEX", help="replay stream INDEX alone")
    ap.add_argument("--throughput", action="store_true", help="measure the parser's speed")
    args = ap.parse_args(argv)
    if args.throughput:
        for kind in SAMPLE_TYPES:
            for chunk in (4096, 65536, 1 << 20):
                fps, bps = throughput(chunk=chunk, sample_type=kind)
                print(
                    f"{kind} 1800 samples, {chunk:>7d}-byte reads: "
                    f"{fps:9.0f} frames/s  {bps / 1e6:7.1f} MB/s"
                )
        return 0
    first, count = (args.only, 1) if args.only is not None else (0, args.streams)
    try:
        stats = fuzz(count, args.seed, first)
    except AssertionError as exc:
        print(f"FAILED: {exc}", file=sys.stderr)
        return 1
    kinds = ", ".join(f"{stats.streams[k]} {k}" for k in KINDS)
    print(f"{sum(stats.streams.values())} streams ({kinds}) in {stats.seconds:.1f} s")
    print(f"{stats.bytes / 1e6:.1f} MB fed, {stats.frames} frames returned")
    print("counters: " + ", ".join(f"{k}={v}" for k, v in sorted(stats.counters.items())))
    return 0


if __name__ == "__main__":
    sys.exit(main())
