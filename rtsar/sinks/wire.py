"""The strip protocol on the wire: topics, JSON headers and payloads (docs/pages/reference/wire.md).

Every message is multipart,

    frame 0  topic, ASCII: b"strip", b"stats", b"end" or b"height"
    frame 1  header, UTF-8 JSON object (fields in ``strip_header`` / docs/pages/reference/wire.md)
    frame 2  payload (strip only): complex64 little-endian, C order [line_count, range_bins]
             (height: float32 heights [line, bin], then frame 3: uint8 validity)

``decode`` is the inverse of the headers and payloads built here; the publisher
(rtsar.sinks.publish) and the subscriber client (rtsar.sinks.client) share this module.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass

import numpy as np

from ..stream.strips import StreamInfo, Strip

STRIP_FORMAT = "rtsar-strip"
STRIP_VERSION = 1
HEIGHT_FORMAT = "rtsar-height"
HEIGHT_VERSION = 2  # 2: a fifth frame, the coherence (version 1 messages still decode)
STATS_FORMAT = "rtsar-stats"


def strip_header(strip: Strip, info: StreamInfo) -> dict:
    """The JSON header of a strip message (every field: docs/pages/reference/wire.md): the
    stream's fixed fields (strip_fixed_fields) and the strip's own (strip_own_fields)."""
    return {**strip_fixed_fields(info), **strip_own_fields(strip, info)}


def strip_fixed_fields(info: StreamInfo) -> dict:
    """The fields of a strip header that every strip of the stream ``info`` shares (a
    publisher encodes them once)."""
    rng = info.range_m
    return {
        "format": STRIP_FORMAT,
        "version": STRIP_VERSION,
        "stream_id": info.stream_id,
        "dtype": "complex64",
        "byte_order": "little",
        "azimuth_step_m": info.azimuth_step_m,
        "range_first_m": float(rng[0]),
        "range_step_m": float(rng[1] - rng[0]) if len(rng) > 1 else 0.0,
        "config": info.config_dict,
        "height_strips": info.heights,
        "height_kind": info.height_kind,
        "instrument_file": info.instrument_file,
        "processing": {
            "lens": info.lens_backend,
            "correlator": info.config.processor.correlator,
            "corrections": list(info.corrections),
            "correction_specs": list(info.correction_specs),
            "physical": info.physical,
        },
    }


def strip_own_fields(strip: Strip, info: StreamInfo) -> dict:
    """The fields of a strip header that are the strip's own (the collection start too: set
    once the first shot arrives, after the stream's info is made)."""
    n_lines, n_bins = strip.lines.shape
    return {
        "seq": strip.seq,
        "first_line": strip.first_line,
        "line_count": n_lines,
        "range_bins": n_bins,
        "azimuth_first_m": float(strip.azimuth_m[0]),
        "first_pulse_arrival_unix_s": info.unix_s(strip.first_arrival_s),
        "last_pulse_arrival_unix_s": info.unix_s(strip.last_arrival_s),
        "publish_unix_s": time.time(),
        "collection_start_utc": info.collection_start_utc,
        "flagged_lines": [list(r) for r in strip.flagged_lines],
        "counters": strip.counters,
    }


def height_header(strip, seq: int, info: StreamInfo) -> dict:
    """The JSON header of a height message (3D imaging: rtsar.topo.stream.HeightStrip).

    Frames: topic ``height``, this header, heights float32 little-endian [line, bin] in metres
    (0 where not valid), validity uint8 [line, bin] (1 = valid: coherent, unwrapped), and
    (version 2) the interferometric coherence float32 [line, bin].
    """
    rng = info.range_m
    n_lines, n_bins = strip.height_m.shape
    return {
        "format": HEIGHT_FORMAT,
        "version": HEIGHT_VERSION,
        "stream_id": info.stream_id,
        "seq": seq,
        "first_line": strip.first_line,
        "line_count": n_lines,
        "range_bins": n_bins,
        "dtype": "float32",
        "valid_dtype": "uint8",
        "coherence_dtype": "float32",
        "byte_order": "little",
        "units": "m",
        "aligned": bool(strip.aligned),
        "valid_fraction": float(np.mean(strip.valid)) if strip.valid.size else 0.0,
        "azimuth_first_m": float(info.azimuth_m(strip.first_line, 1)[0]),
        "azimuth_step_m": info.azimuth_step_m,
        "range_first_m": float(rng[0]),
        "range_step_m": float(rng[1] - rng[0]) if len(rng) > 1 else 0.0,
        "publish_unix_s": time.time(),
        "collection_start_utc": info.collection_start_utc,
    }


def stats_header(stats: dict, info: StreamInfo) -> dict:
    """The JSON header of a ``stats`` or ``end`` message: the stats dictionary and the run's id."""
    return {
        "format": STATS_FORMAT,
        "version": STRIP_VERSION,
        "stream_id": info.stream_id,
        "publish_unix_s": time.time(),
        "collection_start_utc": info.collection_start_utc,
        "source": info.source,
        **stats,
    }


@dataclass
class Message:
    """A received message: topic, header and the payload: a strip's image[line, range_bin]
    (complex), or a height message's height_m[line, range_bin] (float32) and ``valid``."""

    topic: str
    header: dict
    lines: np.ndarray | None = None
    valid: np.ndarray | None = None
    coherence: np.ndarray | None = None  # height messages of version 2


MAX_RANGE_BINS = 1 << 16  # the widest strip a subscriber accepts
MAX_LINES = 1 << 16  # the most lines in one strip
MAX_COUNT = (1 << 53) - 1  # seq and line numbers: integers every JSON reader keeps exactly
MAX_FRAME_BYTES = 1 << 30  # the largest message part a subscriber accepts (ZMQ_MAXMSGSIZE)


def _int(header: dict, key: str, low: int = 0, high: int | None = None) -> int:
    v = header.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or v < low or (high is not None and v > high):
        bound = f"{low} … {high}" if high is not None else f">= {low}"
        raise ValueError(f"header field {key!r} must be an integer {bound}, got {v!r}")
    return v


def _float(header: dict, key: str) -> float:
    v = header.get(key)
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ValueError(f"header field {key!r} must be a finite number, got {v!r}")
    return float(v)


def check_strip_header(header: dict) -> None:
    """ValueError naming the field when a strip header is not what ``strip_header`` writes."""
    if header.get("format") != STRIP_FORMAT or header.get("version") != STRIP_VERSION:
        raise ValueError(f"not an {STRIP_FORMAT} v{STRIP_VERSION} strip")
    if not isinstance(header.get("stream_id"), str):
        raise ValueError("header field 'stream_id' must be a string")
    _int(header, "seq", 0, MAX_COUNT)
    _int(header, "first_line", 0, MAX_COUNT)
    _int(header, "line_count", 1, MAX_LINES)
    _int(header, "range_bins", 1, MAX_RANGE_BINS)
    for key in ("azimuth_first_m", "azimuth_step_m", "range_first_m", "range_step_m"):
        _float(header, key)
    if header.get("dtype") != "complex64" or header.get("byte_order", "little") != "little":
        raise ValueError("strips carry little-endian complex64 lines")
    runs = header.get("flagged_lines", [])
    if not isinstance(runs, list) or not all(
        isinstance(r, list)
        and len(r) == 2
        and all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in r)
        for r in runs
    ):
        raise ValueError("header field 'flagged_lines' must be a list of [first_line, count]")
    counters = header.get("counters", {})
    if not isinstance(counters, dict) or not all(
        isinstance(k, str) and isinstance(v, int) and not isinstance(v, bool)
        for k, v in counters.items()
    ):
        raise ValueError("header field 'counters' must map names to integers")
    if not isinstance(header.get("config"), dict):
        raise ValueError("header field 'config' must be an object")


def decode(frames: list[bytes]) -> Message:
    """Parse one multipart message; ValueError on anything that is not a valid rtsar message."""
    if len(frames) < 2:
        raise ValueError(f"expected at least 2 frames, got {len(frames)}")
    topic = bytes(frames[0]).decode("ascii", "replace")
    try:
        header = json.loads(bytes(frames[1]))
    except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"header is not JSON: {type(exc).__name__}") from None
    if not isinstance(header, dict):
        raise ValueError("header is not a JSON object")
    if topic == "height":
        return _decode_height(header, frames)
    if topic != "strip":
        return Message(topic, header)
    check_strip_header(header)
    if len(frames) != 3:
        raise ValueError("a strip has 3 frames")
    shape = (header["line_count"], header["range_bins"])
    payload = bytes(frames[2])
    if header.get("dtype") != "complex64" or len(payload) != shape[0] * shape[1] * 8:
        raise ValueError(f"payload of {len(payload)} bytes does not match {shape} complex64")
    return Message(topic, header, np.frombuffer(payload, "<c8").reshape(shape))


def _decode_height(header: dict, frames: list[bytes]) -> Message:
    version = header.get("version")
    if header.get("format") != HEIGHT_FORMAT or version not in (1, HEIGHT_VERSION):
        raise ValueError(f"not an {HEIGHT_FORMAT} v1 or v{HEIGHT_VERSION} message")
    if not isinstance(header.get("stream_id"), str):
        raise ValueError("header field 'stream_id' must be a string")
    _int(header, "seq", 0, MAX_COUNT)
    _int(header, "first_line", 0, MAX_COUNT)
    count = 4 if version == 1 else 5
    if len(frames) != count:
        raise ValueError(f"a height message of version {version} has {count} frames")
    shape = (
        _int(header, "line_count", 1, MAX_LINES),
        _int(header, "range_bins", 1, MAX_RANGE_BINS),
    )
    n = shape[0] * shape[1]
    h, v = bytes(frames[2]), bytes(frames[3])
    c = bytes(frames[4]) if count == 5 else None  # nothing is allocated from the header's numbers
    if len(h) != 4 * n or len(v) != n or (c is not None and len(c) != 4 * n):
        raise ValueError(f"height payload does not match {shape}")
    return Message(
        "height",
        header,
        np.frombuffer(h, "<f4").reshape(shape),
        np.frombuffer(v, np.uint8).reshape(shape).astype(bool),
        None if count == 4 else np.frombuffer(c, "<f4").reshape(shape),
    )
