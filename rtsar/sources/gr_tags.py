"""GNU Radio's stream-tag header on ZeroMQ messages, and the PMT values it carries.

Reference (read, not copied): GNU Radio's gr-zeromq ``lib/tag_headers.cc`` (``gen_tag_header``)
and gnuradio-runtime's ``pmt/pmt_serialize.cc`` / ``pmt_serial_tags.h``.  A ZMQ sink with "pass
tags" prepends to each message, in the host's byte order (little-endian on every platform GNU
Radio ships for): u16 magic 0x5FF0, u8 version (1; GNU Radio 3.9+ writes 2 with the same
layout), u64 offset (absolute index of the message's first item), u64 tag count, then per tag
u64 absolute offset and three serialised PMTs: key, value, source id.  PMT serialisation is
big-endian: a one-byte type tag, then — symbol: u16 length + bytes; int32: i32; int64 / uint64:
8 bytes; double: f64; complex: two f64; true/false/null: nothing; pair: car, cdr; tuple and
vector: u32 count + items; dict: a pair chain.  Uniform vectors are skipped whole (u8 subtype,
u8 pad count, pad bytes, u32 count, items).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

MAGIC = 0x5FF0
VERSIONS = (1, 2)
_HEADER = struct.Struct("<HBQQ")
_UVEC_ITEM_BYTES = {0: 1, 1: 1, 2: 2, 3: 2, 4: 4, 5: 4, 6: 8, 7: 8, 8: 4, 9: 8, 10: 8, 11: 16}
MAX_TAGS = 1 << 16  # more tags than this in one message: not a header rtsar trusts


@dataclass(frozen=True)
class Tag:
    offset: int  # absolute item index
    key: object
    value: object


class PmtError(ValueError):
    """A PMT or tag header that does not parse."""


MAX_PMT_DEPTH = 32  # nesting of pairs, tuples and dicts; a tag needs two or three levels


def read_pmt(buf: bytes, pos: int, depth: int = 0) -> tuple[object, int]:
    """One serialised PMT at ``pos``: (Python value, position after it).  Symbols → str,
    integers → int, doubles → float, complex → complex, tuples/vectors → tuple, pairs →
    (car, cdr), dicts → dict, null → None, uniform vectors → ("uvector", count).  Nesting
    deeper than MAX_PMT_DEPTH is a PmtError (a hostile message must not exhaust the stack)."""
    if depth > MAX_PMT_DEPTH:
        raise PmtError(f"PMT nested deeper than {MAX_PMT_DEPTH}")
    try:
        kind = buf[pos]
    except IndexError:
        raise PmtError("PMT cut short") from None
    pos += 1

    def take(fmt):
        nonlocal pos
        size = struct.calcsize(fmt)
        if pos + size > len(buf):
            raise PmtError("PMT cut short")
        out = struct.unpack_from(fmt, buf, pos)
        pos += size
        return out

    if kind in (0x00, 0x01):
        return kind == 0x00, pos
    if kind == 0x06:
        return None, pos
    if kind == 0x02:
        (n,) = take(">H")
        if pos + n > len(buf):
            raise PmtError("PMT symbol cut short")
        return buf[pos : pos + n].decode("utf-8", "replace"), pos + n
    if kind == 0x03:
        return take(">i")[0], pos
    if kind == 0x0D:
        return take(">q")[0], pos
    if kind == 0x0B:
        return take(">Q")[0], pos
    if kind == 0x04:
        return take(">d")[0], pos
    if kind == 0x05:
        re, im = take(">dd")
        return complex(re, im), pos
    if kind == 0x07:
        car, pos = read_pmt(buf, pos, depth + 1)
        cdr, pos = read_pmt(buf, pos, depth + 1)
        return (car, cdr), pos
    if kind in (0x08, 0x0C):
        (n,) = take(">I")
        if n > len(buf):
            raise PmtError("PMT tuple longer than its message")
        items = []
        for _ in range(n):
            item, pos = read_pmt(buf, pos, depth + 1)
            items.append(item)
        return tuple(items), pos
    if kind == 0x09:
        out = {}
        while True:  # a chain of pairs ((key . value) . rest), ending in null
            if pos < len(buf) and buf[pos] == 0x06:
                return out, pos + 1
            pair, pos = read_pmt(buf, pos, depth + 1)
            if not (isinstance(pair, tuple) and len(pair) == 2):
                raise PmtError("PMT dict entry is not a pair")
            try:
                out[pair[0]] = pair[1]
            except TypeError:  # a key that is a dict (or holds one): no Python dict takes it
                raise PmtError("PMT dict key is a dict") from None
    if kind == 0x0A:
        subtype, npad = take(">BB")
        pos += npad
        (n,) = take(">I")
        size = _UVEC_ITEM_BYTES.get(subtype & 0x7F)
        if size is None or pos + n * size > len(buf):
            raise PmtError("PMT uniform vector does not parse")
        return ("uvector", n), pos + n * size
    raise PmtError(f"unknown PMT type 0x{kind:02x}")


def parse_tag_header(buf: bytes) -> tuple[int, list[Tag], int]:
    """(offset of the first item, tags, header length) of a message from a GNU Radio ZMQ sink
    with pass_tags; PmtError when the message does not start with a valid header."""
    if len(buf) < _HEADER.size:
        raise PmtError("message too short for a GNU Radio tag header")
    magic, version, offset, ntags = _HEADER.unpack_from(buf, 0)
    if magic != MAGIC:
        raise PmtError(f"tag header magic 0x{magic:04x}, expected 0x{MAGIC:04x}")
    if version not in VERSIONS:
        raise PmtError(f"tag header version {version} unknown")
    if ntags > MAX_TAGS:
        raise PmtError(f"{ntags} tags in one header")
    pos, tags = _HEADER.size, []
    for _ in range(ntags):
        if pos + 8 > len(buf):
            raise PmtError("tag cut short")
        (tag_offset,) = struct.unpack_from("<Q", buf, pos)
        key, pos = read_pmt(buf, pos + 8)
        value, pos = read_pmt(buf, pos)
        _, pos = read_pmt(buf, pos)  # source id
        tags.append(Tag(tag_offset, key, value))
    return offset, tags, pos


def rx_time_s(value) -> float | None:
    """GNU Radio's ``rx_time`` value (uint64 whole seconds, double fraction) in seconds."""
    if isinstance(value, tuple) and len(value) == 2:
        whole, frac = value
        if isinstance(whole, int) and isinstance(frac, float):
            return whole + frac
    return None


# Writers: the same format, for tests, tools/gnuradio_flowgraph.py and fake GNU Radio sinks.
def pmt_symbol(text: str) -> bytes:
    data = text.encode()
    return b"\x02" + struct.pack(">H", len(data)) + data


def pmt_long(value: int) -> bytes:
    if -(1 << 31) <= value < (1 << 31):
        return b"\x03" + struct.pack(">i", value)
    return b"\x0d" + struct.pack(">q", value)


def pmt_rx_time(seconds: int, fraction: float) -> bytes:
    return (
        b"\x0c"
        + struct.pack(">I", 2)
        + b"\x0b"
        + struct.pack(">Q", seconds)
        + b"\x04"
        + struct.pack(">d", fraction)
    )


PMT_FALSE = b"\x01"


def tag_header(offset: int, tags: list[tuple[int, bytes, bytes]], version: int = 1) -> bytes:
    """A GNU Radio tag header: ``tags`` as (absolute offset, serialised key, serialised value);
    the source id is PMT false, as GNU Radio writes for tags without one."""
    out = [_HEADER.pack(MAGIC, version, offset, len(tags))]
    for tag_offset, key, value in tags:
        out += [struct.pack("<Q", tag_offset), key, value, PMT_FALSE]
    return b"".join(out)
