"""What the live page shows, kept in bounded memory whatever the browsers do.

The waterfall is a ring of ``rows`` display rows.  Display row ``g`` pools the image lines
``g·k … g·k + k - 1`` (``k = lines_per_row``, numbered from the stream's first line, so a
row holds the same lines whichever strip brought them) and groups of ``c`` range bins
(``c = bins_per_column``), keeping the largest ``|x|`` of each group: a point target stays as
bright as it is, however much the picture is reduced.  Heights are pooled the same way, as the
mean of the valid heights (a row with none is not valid).  Rows are sent to a browser in dB
(``20 log10 |x|``; the page takes them re the peak of the rows it shows).

A browser holds a :class:`Cursor`: :meth:`LiveFrames.updates` gives it every row that changed
since its last call (all the rows shown when it is new or the stream changed), never more: a
browser that reads slowly gets fewer, larger updates (it skips frames) and nothing queues up
for it here.  Memory: two rings of ``rows × columns`` floats, whatever the run's length.

Messages for the page (rtsar.app.webview.server sends them over a WebSocket):

* text, JSON ``{"type": "stream", …}``: the stream's id and axes (sent when it starts or a
  publisher restarts with a new ``stream_id``); ``{"type": "status", …}``: the run's counters,
  and in words (:func:`losses`, :func:`notes`, :func:`link_words`) what the page shows: ``lost``
  (painted red: shots, frames, lines or messages that are missing), ``noted`` (counters that say
  something happened but nothing is missing: late releases, flagged lines …), ``link`` (the
  source's link: ``text`` and ``alarm``, red while the source is silent);
* binary: a uint32 little-endian length ``L``, a JSON header of ``L`` bytes (``kind`` "image"
  or "height", ``newest`` row, ``count``, ``columns``), padded with spaces to a multiple of 8,
  then ``count`` float64 row numbers and ``count × columns`` float32 values (dB, or metres of
  height with NaN where not valid).
"""

from __future__ import annotations

import json
import math
import struct
import threading
import time
from dataclasses import dataclass

import numpy as np

from ..live import LATE_RELEASES_MEANING, problems

FLOOR_DB = -300.0  # an empty pixel (no line there): below any dynamic range shown
MAX_ROWS = 1024  # display rows: the page's canvas height in pixels
MAX_COLUMNS = 1024  # display columns


@dataclass
class Cursor:
    """How far one browser has been brought up to date."""

    epoch: int = -1
    image_tick: int = 0
    height_tick: int = 0
    status_tick: int = 0


def pool_columns(values: np.ndarray, per_column: int, how: str) -> np.ndarray:
    """``values[line, bin]`` → ``[line, column]``, groups of ``per_column`` bins (the last one
    may be shorter): ``how`` "max" or "sum"."""
    n_lines, n_bins = values.shape
    n_cols = -(-n_bins // per_column)
    pad = n_cols * per_column - n_bins
    if pad:
        values = np.concatenate([values, np.zeros((n_lines, pad), values.dtype)], axis=1)
    grouped = values.reshape(n_lines, n_cols, per_column)
    return grouped.max(axis=2) if how == "max" else grouped.sum(axis=2)


def encode_rows(kind: str, newest: int, rows: np.ndarray, values: np.ndarray) -> bytes:
    """One binary message (module docstring): the row numbers and their values."""
    head = json.dumps(
        {"kind": kind, "newest": int(newest), "count": len(rows), "columns": values.shape[1]}
    ).encode()
    head += b" " * ((-(4 + len(head))) % 8)
    return b"".join(
        [
            struct.pack("<I", len(head)),
            head,
            np.asarray(rows, "<f8").tobytes(),
            np.ascontiguousarray(values, "<f4").tobytes(),
        ]
    )


class _Ring:
    """``rows`` slots of pooled values; slot ``g % rows`` holds display row ``g`` (``tag``)."""

    def __init__(self, rows: int, columns: int, planes: int):
        self.tag = np.full(rows, -1, np.int64)
        self.tick = np.zeros(rows, np.int64)
        self.data = np.zeros((planes, rows, columns), np.float32)
        self.newest = -1

    def window(self) -> np.ndarray:
        """The slots of the rows shown: the ``rows`` newest row numbers that hold data."""
        n = len(self.tag)
        return np.flatnonzero((self.tag >= 0) & (self.tag > self.newest - n))


class LiveFrames:
    """The page's state: the waterfall and height rings and the status (thread-safe).

    ``lines``: image lines shown (the waterfall's length); ``max_rows`` / ``max_columns``:
    the most display rows and columns (lines and bins are pooled beyond).
    """

    def __init__(
        self,
        lines: int = 8192,
        max_rows: int = MAX_ROWS,
        max_columns: int = MAX_COLUMNS,
        endpoint: str = "",
    ):
        if lines < 1 or max_rows < 1 or max_columns < 1:
            raise ValueError("lines, max_rows and max_columns must be >= 1")
        self.lines = int(lines)
        self.lines_per_row = -(-self.lines // max_rows)
        self.rows = -(-self.lines // self.lines_per_row)
        self.max_columns = int(max_columns)
        self.endpoint = endpoint
        self._lock = threading.Lock()
        self.epoch = 0
        self.stream: dict | None = None
        self._image: _Ring | None = None
        self._height: _Ring | None = None
        self._tick = 0
        self._status_tick = 0
        self.status: dict = {"state": "waiting for the publisher", "endpoint": endpoint}
        self.strips = 0

    # ---- from the subscriber thread ------------------------------------------------------
    def _start_stream(self, header: dict) -> None:
        bins = int(header["range_bins"])
        per_col = -(-bins // self.max_columns)
        cols = -(-bins // per_col)
        az_step = float(header["azimuth_step_m"])
        line0 = float(header["azimuth_first_m"]) - int(header["first_line"]) * az_step
        k = self.lines_per_row
        self.epoch += 1
        self.stream = {
            "type": "stream",
            "epoch": self.epoch,
            "stream_id": header["stream_id"],
            "rows": self.rows,
            "columns": cols,
            "lines_per_row": k,
            "bins_per_column": per_col,
            "range_bins": bins,
            # centre of display row g: row0 + g·row_step; of column j: column0 + j·column_step
            "row0_m": line0 + 0.5 * (k - 1) * az_step,
            "row_step_m": k * az_step,
            "column0_m": float(header["range_first_m"])
            + 0.5 * (per_col - 1) * float(header["range_step_m"]),
            "column_step_m": per_col * float(header["range_step_m"]),
            "line_step_m": az_step,
            "range_step_m": float(header["range_step_m"]),
            "height_strips": bool(header.get("height_strips", False)),
        }
        self._image = _Ring(self.rows, cols, 1)
        self._height = _Ring(self.rows, cols, 2)  # planes: sum of valid heights, their count

    def _same_stream(self, header: dict) -> bool:
        s = self.stream
        return (
            s is not None
            and s["stream_id"] == header["stream_id"]
            and s["range_bins"] == int(header["range_bins"])
        )

    def _groups(self, first_line: int, n_lines: int):
        """(display row, first, stop) of each group of a strip's lines (indices in the strip)."""
        k = self.lines_per_row
        for g in range(first_line // k, (first_line + n_lines - 1) // k + 1):
            yield g, max(g * k - first_line, 0), min((g + 1) * k - first_line, n_lines)

    def _put(self, ring: _Ring, g: int, values: np.ndarray, combine: str) -> None:
        if g <= ring.newest - self.rows:  # older than every row shown
            return
        slot = g % self.rows
        if ring.tag[slot] != g:
            ring.tag[slot] = g
            ring.data[:, slot] = values
        elif combine == "max":
            np.maximum(ring.data[:, slot], values, out=ring.data[:, slot])
        else:
            ring.data[:, slot] += values
        ring.tick[slot] = self._tick
        ring.newest = max(ring.newest, g)

    def add_strip(self, header: dict, lines: np.ndarray) -> None:
        """A decoded strip message (rtsar.sinks.wire): its lines join their display rows."""
        mags = np.abs(lines)
        with self._lock:
            if not self._same_stream(header):
                self._start_stream(header)
            self._tick += 1
            per_col = self.stream["bins_per_column"]
            for g, a, b in self._groups(int(header["first_line"]), len(lines)):
                pooled = pool_columns(mags[a:b].max(axis=0, keepdims=True), per_col, "max")
                self._put(self._image, g, pooled, "max")
            self.strips += 1
            counters = header.get("counters", {})
            self.status.update(state="live", stream_id=header["stream_id"], counters=counters)
            self._heard(header)
            self._status_tick = self._tick

    def add_height(self, header: dict, height_m: np.ndarray, valid: np.ndarray) -> None:
        """A decoded height message: the mean valid height of each display pixel."""
        with self._lock:
            if self.stream is None or self.stream["stream_id"] != header.get("stream_id"):
                return  # heights before their stream's first strip: shown from the next ones
            if height_m.shape[1] != self.stream["range_bins"]:
                return
            self._tick += 1
            per_col = self.stream["bins_per_column"]
            h = np.where(valid, height_m, 0.0).astype(np.float32)
            v = valid.astype(np.float32)
            for g, a, b in self._groups(int(header["first_line"]), len(h)):
                s = pool_columns(h[a:b].sum(axis=0, keepdims=True), per_col, "sum")
                c = pool_columns(v[a:b].sum(axis=0, keepdims=True), per_col, "sum")
                self._put(self._height, g, np.stack([s, c])[:, 0], "sum")

    def _heard(self, header: dict) -> None:
        """A message from the publisher: it is not quiet; one of a stream other than the one
        that ended (a new run) means the stream is no longer ended.  Either way the state said
        for it (publisher silent, stream ended) no longer holds: live."""
        ended = self.status.get("ended_stream")
        new_run = ended is not None and header.get("stream_id") != ended
        if self.status.get("publisher_quiet") or new_run:
            self.status["state"] = "live"
        self.status["publisher_quiet"] = False
        if new_run:
            self.status["ended_stream"] = None

    def add_status(self, topic: str, header: dict, subscriber_counters: dict) -> None:
        """A ``stats`` or ``end`` message, or only the subscriber's own counters (topic "")."""
        with self._lock:
            self._tick += 1
            if topic in ("stats", "end"):
                self._heard(header)
                keep = ("pulse_rate_hz", "elapsed_s", "latency_recent_median_ms")
                keep += ("latency_recent_p99_ms", "latency_median_ms", "latency_p99_ms")
                for key in keep:
                    v = header.get(key)
                    if isinstance(v, (int, float)) and math.isfinite(v):
                        self.status[key] = float(v)
                if isinstance(header.get("counters"), dict):
                    self.status["counters"] = header["counters"]
                self.status["source"] = str(header.get("source", ""))[:200]
                if "link" in header:  # the silence being told, or null while shots come
                    self.status["link_silent"] = _silence(header["link"])
                if topic == "end":
                    self.status["state"] = "stream ended"
                    self.status["ended_stream"] = str(header.get("stream_id", ""))
            self.status["viewer"] = dict(subscriber_counters)
            self.status["updated_unix_s"] = time.time()
            self._status_tick = self._tick

    def set_state(self, state: str) -> None:
        with self._lock:
            self._tick += 1
            self.status["state"] = state
            self._status_tick = self._tick

    def publisher_quiet(self, silence_s: float) -> None:
        """No message for ``silence_s``: said in the state unless the stream has ended (then
        silence is what the end said), and the link's last word no longer holds."""
        with self._lock:
            self._tick += 1
            self.status["publisher_quiet"] = True
            if self.status.get("ended_stream") is None:
                self.status["state"] = f"no message for {silence_s:g} s: publisher silent"
            self._status_tick = self._tick

    # ---- from the server's event loop ------------------------------------------------------
    def set_browsers(self, count: int) -> None:
        with self._lock:
            self._tick += 1
            self.status["browsers"] = int(count)
            self._status_tick = self._tick

    def updates(self, cursor: Cursor) -> list:
        """Messages (str or bytes) bringing ``cursor``'s browser up to date; moves the cursor."""
        out: list = []
        with self._lock:
            tick = self._tick
            if self.stream is not None and cursor.epoch != self.epoch:
                cursor.epoch, cursor.image_tick, cursor.height_tick = self.epoch, -1, -1
                out.append(json.dumps(self.stream))
            if self.stream is not None:
                ring = self._image
                slots = ring.window()
                slots = slots[ring.tick[slots] > cursor.image_tick]
                if slots.size:
                    mag = ring.data[0, slots].astype(np.float64)
                    with np.errstate(divide="ignore"):
                        db = np.where(mag > 0, 20.0 * np.log10(np.where(mag > 0, mag, 1.0)), 0)
                    db[mag <= 0] = FLOOR_DB
                    out.append(encode_rows("image", ring.newest, ring.tag[slots], db))
                ring = self._height
                slots = ring.window()
                slots = slots[ring.tick[slots] > cursor.height_tick]
                if slots.size:
                    s, c = ring.data[0, slots], ring.data[1, slots]
                    with np.errstate(invalid="ignore", divide="ignore"):
                        mean = np.where(c > 0, s / np.where(c > 0, c, 1.0), np.nan)
                    out.append(encode_rows("height", ring.newest, ring.tag[slots], mean))
                cursor.image_tick = cursor.height_tick = tick
            if self._status_tick > cursor.status_tick:
                status = page_status(dict(self.status, type="status"))
                out.append(json.dumps(status, allow_nan=False))
                cursor.status_tick = tick
        return out

    def snapshot_status(self) -> dict:
        """The status as the page gets it (``/status.json``)."""
        with self._lock:
            return page_status(self.status)


# Counters that say something is missing (red on the page), and those that say something
# happened with nothing missing (noted in black), each in words that say what it counts.  The
# link's own counters are told in the link's row (link_words); gap_pulses: see losses.
LOST_WORDS = {
    "dropped_pulses": "{n} shot(s) dropped (the processing queue was full)",
    "stray_pulses": "{n} stray shot(s) dropped (numbered outside the run and any restart)",
    "nonfinite_pulses": "{n} shot(s) zeroed (NaN/Inf samples)",
    "wrong_length_pulses": "{n} shot(s) zeroed (the wrong number of samples)",
    "marked_pulses": "{n} shot(s) with no data (marked so in the recording)",
    "payload_crc_errors": "{n} frame(s) discarded (payload CRC)",
    "bad_headers": "{n} frame(s) discarded (a header of an unknown kind)",
    "wrong_length": "{n} frame(s) or message(s) discarded (another shape than the stream's)",
    "truncated_frames": "{n} frame(s) cut short when the link ended",
    "oversized_messages": "{n} oversized message(s) refused",
    "messages_missed_by_stalled": "{n} message(s) sent while a stalled subscriber was cut off",
    "record_dropped": "{n} shot(s) not recorded",
    "record_unconfirmed": "{n} shot(s) not confirmed in the recording (it may lack them)",
    "image_lines_lost": "{n} line(s) not written to -o",
}
NOTED_WORDS = {
    "late_releases": "{n} late release(s): " + LATE_RELEASES_MEANING,
    "flagged_lines": "{n} flagged line(s): lines whose aperture holds a zero-filled, zeroed "
    "or marked shot",
    "duplicates": "{n} duplicate shot(s) set aside (a copy of one already in)",
    "late_pulses": "{n} late shot(s) set aside (their place was already zero-filled)",
    "discontinuities": "{n} restart(s) of the shot count",
    "pulses_before_start": "{n} shot(s) of the scan before the first one received",
    "header_crc_errors": "{n} sync word(s) without a valid header",
    "bytes_skipped": "{n} byte(s) skipped looking for frames",
    "layout_changes": "{n} change(s) of the stream's layout",
    "subscriber_stalls": "{n} stalled subscriber(s) cut off",
    "swath_refused_messages": "{n} swath message(s) refused (malformed or of no worker)",
    "correlator_growths": "{n} growth(s) of the correlator's block (the work fell behind)",
    "correlator_shrinks": "{n} shrink(s) of the correlator's block back (room again)",
}
LINK_COUNTERS = ("link_silences", "link_silent_ms", "link_drops", "reconnects")


def _count(counters: dict, key: str) -> int:
    value = counters.get(key, 0)
    return int(value) if isinstance(value, (int, float)) and math.isfinite(value) else 0


def losses(counters: dict) -> list[str]:
    """What is missing, in words, from the run's counters: what the page paints red.

    ``gap_pulses`` counts the zero shots put in for numbers that never came (``gaps`` such
    jumps) and those put in at a restart of the count (``discontinuities``, no shot missing):
    a loss when there was a gap."""
    out = []
    gaps, filled = _count(counters, "gaps"), _count(counters, "gap_pulses")
    if gaps and filled:
        restarts = _count(counters, "discontinuities")
        out.append(
            f"{filled} zero shot(s) in place of {gaps} gap(s) in the shot count"
            + (f" and {restarts} restart(s)" if restarts else "")
        )
    for key, words in LOST_WORDS.items():
        if n := _count(counters, key):
            out.append(words.format(n=n))
    return out


def notes(counters: dict) -> list[str]:
    """Every other counter that is not zero (nothing missing), in words: shown, not red."""
    out = []
    if not _count(counters, "gaps") and (filled := _count(counters, "gap_pulses")):
        out.append(f"{filled} zero shot(s) clearing the picture at a restart of the shot count")
    for key, value in counters.items():
        if key in LOST_WORDS or key in LINK_COUNTERS or key in ("gaps", "gap_pulses"):
            continue
        if key in NOTED_WORDS:
            if n := _count(counters, key):
                out.append(NOTED_WORDS[key].format(n=n))
        else:  # normal work is left out; any other counter in the run's own words
            out.extend(problems({key: value}))
    return out


def link_words(status: dict) -> dict:
    """The source's link, as the page's row says it: ``text``, and ``alarm`` (red) while the
    source is silent.  After the stream's end, or while this viewer hears nothing from the
    publisher, the last word of a stats message (shots arriving) no longer holds."""
    quiet = status.get("link_silent")
    alarm = False
    if status.get("ended_stream") is not None:
        text = "the stream ended: no more shots"
    elif status.get("publisher_quiet"):
        text = "not known: no message from the publisher"
    elif quiet:
        alarm = True
        since = quiet["since_pulse"]
        text = f"SILENT for {quiet['silent_s']:.1f} s since " + (
            "the start (no pulse yet)" if since is None else f"pulse {since}"
        )
    elif "link_silent" in status:
        text = "shots arriving"
    else:
        text = "not told by the publisher (yet)"
    c = status.get("counters", {})
    if n := _count(c, "link_silences"):
        text += f"; silent {n} time(s), {_count(c, 'link_silent_ms') / 1e3:.1f} s in all"
    if n := _count(c, "link_drops"):
        text += f"; lost {n} time(s)"
    if n := _count(c, "reconnects"):
        text += f"; reconnected {n} time(s)"
    return {"text": text, "alarm": alarm}


def page_status(status: dict) -> dict:
    """``status`` with the words the page shows (module docstring), as strict JSON allows."""
    counters = status.get("counters", {})
    out = dict(status, lost=losses(counters), noted=notes(counters), link=link_words(status))
    return _finite(json.loads(json.dumps(out, default=str)))


def _finite(value):
    """``value`` with every non-finite float replaced by None (JSON has no NaN)."""
    if isinstance(value, dict):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _silence(state) -> dict | None:
    """A stats message's ``link`` ({silent_s, since_pulse} while the source is silent, else
    null), checked: anything else reads as no silence."""
    if not isinstance(state, dict):
        return None
    silent_s, since = state.get("silent_s"), state.get("since_pulse")
    if not isinstance(silent_s, (int, float)) or not math.isfinite(silent_s):
        return None
    return {"silent_s": float(silent_s), "since_pulse": since if isinstance(since, int) else None}
