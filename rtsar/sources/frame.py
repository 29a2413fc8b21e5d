"""The instrument frame: how one shot travels over a serial line or a socket, and its parser.

Every shot is one frame.  Multi-byte fields are little-endian (the sync word is four bytes sent
in the order shown, not an integer); floats are IEEE 754 binary32, integers two's complement.
Offsets are from the first sync byte::

    offset  size  field           type   meaning
    ------  ----  --------------  -----  -------------------------------------------------------
         0     4  sync            bytes  1A CF FC 1D (the CCSDS attached sync marker)
         4     1  version         u8     frame format version, 1
         5     1  sample_type     u8     1 = cf32 (float32 I, float32 Q: 8 bytes per sample)
                                         2 = ci16 (int16 I, int16 Q: 4 bytes per sample)
         6     2  channel_count   u16    channels in the payload, >= 1
         8     4  sample_count    u32    samples per channel, >= 1
        12     8  sequence        u64    instrument pulse counter
        20     8  timestamp_ns    u64    instrument clock at the shot (ns)
        28     4  header_crc      u32    CRC-32 of bytes 4..27 (the 24 header bytes, not the sync)
        32     P  payload                channel_count x sample_count samples, channel-major:
                                         channel 0 samples 0..n-1, then channel 1, ...; each
                                         sample is I then Q
    32 + P     4  payload_crc     u32    CRC-32 of the P payload bytes

    P = channel_count x sample_count x (8 for cf32, 4 for ci16);  frame length = 36 + P.

CRC-32 is the zlib / IEEE 802.3 / PNG one (polynomial 0x04C11DB7 reflected, initial value and
final XOR 0xFFFFFFFF; ``zlib.crc32``, ``binascii.crc32``; the CRC of b"123456789" is 0xCBF43926).

Frames may follow each other with or without bytes in between.  The receiver's rules:

* it looks for the sync word anywhere in the stream; a frame is accepted only when both CRCs
  pass, the version is 1, the sample type is known, both counts are >= 1 and P does not exceed the
  receiver's limit (64 MiB by default);
* a receiver that knows its stream (``samples_per_shot``, ``min_channels`` … ``max_channels``)
  rejects a CRC-valid header announcing any other shape at once, before buffering a byte of its
  payload (counted in ``wrong_length``): no header, true or false, can make it wait for more
  than one frame of the configured stream;
* after a failed check it resumes the search at the byte after the rejected sync word, so a sync
  word that turns up by chance inside the data costs one header CRC and nothing more;
* it never skips ahead by a length it read from a header whose CRC has not passed.

:class:`FrameParser` implements these rules on a stream fed in pieces of any size; it keeps at most
one frame's worth of bytes between calls; :meth:`FrameParser.finish` gives up, when the link
ends, on a frame whose payload never came and recovers the frames behind it.
:func:`encode_frame` is the sender's side.
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

import numpy as np

SYNC = b"\x1a\xcf\xfc\x1d"
VERSION = 1
HEADER = struct.Struct("<BBHIQQ")  # version, sample_type, channel_count, sample_count, seq, time
_CRC = struct.Struct("<I")
PREFIX_BYTES = len(SYNC) + HEADER.size + _CRC.size  # 32: everything before the payload
OVERHEAD_BYTES = PREFIX_BYTES + _CRC.size  # 36: a frame is this plus its payload
MAX_PAYLOAD_BYTES = 64 * 2**20

SAMPLE_TYPES = {"cf32": 1, "ci16": 2}  # name -> sample_type code
SAMPLE_BYTES = {"cf32": 8, "ci16": 4}
_BY_CODE = {code: (name, SAMPLE_BYTES[name]) for name, code in SAMPLE_TYPES.items()}
_U64 = 2**64

COUNTERS = (
    "frames_ok",  # frames whose both CRCs passed and that were returned
    "header_crc_errors",  # sync words followed by a header with a wrong CRC
    "payload_crc_errors",  # frames whose header passed but whose payload CRC did not
    "bad_headers",  # CRC-valid headers with an unknown version/sample type or bad lengths
    "wrong_length",  # CRC-valid headers of another shape than the configured stream's
    "truncated_frames",  # frames whose payload had not arrived when the link ended
    "bytes_skipped",  # bytes dropped while searching for a valid frame
    "bytes_fed",  # all bytes given to feed()
)


@dataclass(eq=False)
class Frame:
    """One decoded frame: samples[channel, sample] (complex64) and the header's fields."""

    sequence: int
    timestamp_ns: int
    version: int
    sample_type: str  # "cf32" or "ci16"
    samples: np.ndarray  # complex64[channel_count, sample_count]

    @property
    def nbytes(self) -> int:
        """Length of the frame on the wire."""
        return OVERHEAD_BYTES + self.samples.size * SAMPLE_BYTES[self.sample_type]


def frame_bytes(sample_count: int, channel_count: int = 1, sample_type: str = "cf32") -> int:
    """Length on the wire of a frame of ``channel_count`` x ``sample_count`` samples."""
    return OVERHEAD_BYTES + channel_count * sample_count * SAMPLE_BYTES[sample_type]


def encode_frame(sequence: int, timestamp_ns: int, samples, sample_type: str = "cf32") -> bytes:
    """One frame holding ``samples`` (complex, [channels, n] or [n] for one channel).

    ``ci16`` rounds I and Q to the nearest integer and clips them to [-32768, 32767]; NaN or Inf
    cannot be represented and raise ValueError (``cf32`` carries them as they are).
    """
    if sample_type not in SAMPLE_TYPES:
        raise ValueError(f"sample_type must be one of {sorted(SAMPLE_TYPES)}, got {sample_type!r}")
    for name, value in (("sequence", sequence), ("timestamp_ns", timestamp_ns)):
        if not 0 <= value < _U64:
            raise ValueError(f"{name} must fit in an unsigned 64-bit integer, got {value!r}")
    x = np.asarray(samples)
    if x.ndim == 1:
        x = x[np.newaxis]
    if x.ndim != 2 or x.size == 0:
        raise ValueError(f"samples must be a non-empty [channels, n] or [n] array, got {x.shape}")
    channels, count = x.shape
    if channels >= 2**16 or count >= 2**32:
        raise ValueError(f"{channels} channels x {count} samples do not fit the header fields")
    if sample_type == "cf32":
        payload = np.ascontiguousarray(x, dtype="<c8").tobytes()
    else:
        if not np.isfinite(x).all():
            raise ValueError("ci16 cannot represent NaN or Inf samples")
        iq = np.empty((channels, count, 2), "<i2")
        iq[..., 0] = np.clip(np.rint(x.real), -32768, 32767)
        iq[..., 1] = np.clip(np.rint(x.imag), -32768, 32767)
        payload = iq.tobytes()
    header = HEADER.pack(
        VERSION, SAMPLE_TYPES[sample_type], channels, count, int(sequence), int(timestamp_ns)
    )
    return b"".join(
        (
            SYNC,
            header,
            _CRC.pack(zlib.crc32(header)),
            payload,
            _CRC.pack(zlib.crc32(payload)),
        )
    )


class FrameParser:
    """Turns a byte stream fed in pieces of any size into :class:`Frame` s (rules: module doc).

    ``counters`` (see ``COUNTERS``) tally what was accepted and rejected; at every moment
    ``bytes_fed == sum of accepted frame lengths + bytes_skipped + buffered``.  The buffer kept
    between calls holds less than one frame of ``max_payload_bytes`` (less than 4 bytes while no
    sync word is in sight), so a stream of garbage does not grow it.
    """

    def __init__(
        self,
        max_payload_bytes: int = MAX_PAYLOAD_BYTES,
        samples_per_shot: int | None = None,
        max_channels: int | None = None,
        min_channels: int = 1,
    ):
        if not max_payload_bytes >= 1:
            raise ValueError(f"max_payload_bytes must be >= 1, got {max_payload_bytes!r}")
        for name, v in (("samples_per_shot", samples_per_shot), ("max_channels", max_channels)):
            if v is not None and not v >= 1:
                raise ValueError(f"{name} must be >= 1 or None, got {v!r}")
        self.samples_per_shot = samples_per_shot
        self.max_channels = max_channels
        self.min_channels = int(min_channels)
        most = max_payload_bytes
        if samples_per_shot is not None:  # the largest frame the configured stream can send
            most = min(
                most, (max_channels or 2**16 - 1) * samples_per_shot * max(SAMPLE_BYTES.values())
            )
        self.max_payload_bytes = int(most)
        self.counters: dict[str, int] = dict.fromkeys(COUNTERS, 0)
        self.refused_shape: tuple[int, int] | None = None  # (channels, samples): the last refused
        self._buf = bytearray()

    @property
    def buffered(self) -> int:
        """Bytes held until more data arrives."""
        return len(self._buf)

    def feed(self, data) -> list[Frame]:
        """Append ``data`` (bytes-like) to the stream; return the frames it completed, in order."""
        buf = self._buf
        buf += data
        c = self.counters
        c["bytes_fed"] += len(data)
        size = len(buf)
        frames: list[Frame] = []
        pos = 0  # bytes before pos are consumed (accepted or skipped)
        skipped = 0
        with memoryview(buf) as view:
            while True:
                i = buf.find(SYNC, pos)
                if i < 0:
                    # Keep the last 3 bytes: they may be the start of a sync word.
                    keep = max(pos, size - len(SYNC) + 1)
                    skipped += keep - pos
                    pos = keep
                    break
                skipped += i - pos
                pos = i
                if size - i < PREFIX_BYTES:
                    break  # wait for the header
                start = i + len(SYNC)
                (header_crc,) = _CRC.unpack_from(buf, start + HEADER.size)
                if zlib.crc32(view[start : start + HEADER.size]) != header_crc:
                    c["header_crc_errors"] += 1
                    skipped += 1
                    pos = i + 1
                    continue
                version, code, channels, count, sequence, timestamp = HEADER.unpack_from(buf, start)
                kind = _BY_CODE.get(code)
                nbytes = channels * count * (kind[1] if kind else 0)
                if version != VERSION or nbytes == 0:
                    c["bad_headers"] += 1
                    skipped += 1
                    pos = i + 1
                    continue
                if (
                    nbytes > self.max_payload_bytes
                    or (self.samples_per_shot is not None and count != self.samples_per_shot)
                    or (self.max_channels is not None and channels > self.max_channels)
                    or channels < self.min_channels
                ):
                    c["wrong_length" if self.samples_per_shot else "bad_headers"] += 1
                    self.refused_shape = (channels, count)
                    skipped += 1
                    pos = i + 1
                    continue
                p0 = i + PREFIX_BYTES
                p1 = p0 + nbytes
                if size < p1 + _CRC.size:
                    break  # wait for the payload; its length is trusted, the header CRC passed
                (payload_crc,) = _CRC.unpack_from(buf, p1)
                if zlib.crc32(view[p0:p1]) != payload_crc:
                    c["payload_crc_errors"] += 1
                    skipped += 1
                    pos = i + 1
                    continue
                # Decoded into new arrays: no view of the buffer may outlive this loop.
                if kind[0] == "cf32":
                    x = np.frombuffer(view, "<c8", channels * count, p0).astype(np.complex64)
                else:
                    # int16 I,Q pairs -> float32 I,Q pairs, which is the layout of complex64.
                    x = np.frombuffer(view, "<i2", 2 * channels * count, p0).astype(np.float32)
                    x = x.view(np.complex64)
                frames.append(
                    Frame(sequence, timestamp, version, kind[0], x.reshape(channels, count))
                )
                pos = p1 + _CRC.size
        del buf[:pos]
        c["bytes_skipped"] += skipped
        c["frames_ok"] += len(frames)
        return frames

    def finish(self) -> list[Frame]:
        """At the end of the link: give up on a frame whose payload never came (counted in
        ``truncated_frames``) and return the intact frames found in the bytes behind it; the
        rest of the buffer is counted as skipped.  The parser is empty afterwards."""
        frames: list[Frame] = []
        while self._buf:
            before = len(self._buf)
            frames += self.feed(b"")
            if len(self._buf) == before:  # waiting for bytes that will not come
                if len(self._buf) >= PREFIX_BYTES and self._buf.startswith(SYNC):
                    self.counters["truncated_frames"] += 1
                del self._buf[:1]
                self.counters["bytes_skipped"] += 1
        return frames
