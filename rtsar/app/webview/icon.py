"""The live page's icon (served as /favicon.ico, so a browser's request for it is answered),
drawn here as a PNG: no image file in the package, no imaging library."""

from __future__ import annotations

import struct
import zlib

import numpy as np


def icon_png(size: int = 16) -> bytes:
    """The page's icon, drawn here: a grey PNG of ``size`` × ``size`` pixels, a waterfall's
    rows brighter towards the newest (the bottom) and one bright point target with its
    sidelobes.  Served as /favicon.ico, so a browser's request for it is answered."""
    y, x = np.mgrid[0:size, 0:size]
    grey = 30 + (90 * y) // max(size - 1, 1)
    cy, cx = size * 3 // 8, size * 5 // 8
    grey = np.where((y == cy) ^ (x == cx), 150, grey)  # the sidelobes: a cross
    grey = np.where((abs(y - cy) <= 1) & (abs(x - cx) <= 1), 255, grey).astype(np.uint8)
    raw = b"".join(b"\0" + row.tobytes() for row in grey)  # filter type 0 on each row

    def chunk(kind: bytes, data: bytes) -> bytes:
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    header = struct.pack(">IIBBBBB", size, size, 8, 0, 0, 0, 0)  # 8-bit grey, no interlace
    return b"".join(
        [b"\x89PNG\r\n\x1a\n", chunk(b"IHDR", header), chunk(b"IDAT", zlib.compress(raw))]
        + [chunk(b"IEND", b"")]
    )
