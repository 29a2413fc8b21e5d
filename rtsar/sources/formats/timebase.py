"""A recording's clock on UTC: the collection start, the instant of ``time_s`` = 0.

rtsar's shot times (``time_s``) are relative; a recording carries ``collection_start_utc``
(ISO 8601, UTC, microseconds: ``2024-05-28T12:34:56.123456Z``), the time its pulse 0 was taken
(``rtsar simulate``: when the simulation began).  The exports turn it into CPHD's
Global/Timeline/CollectionStart, SICD's Timeline/CollectStart and SigMF's per-capture
``core:datetime``; their readers turn those back.  A recording made before it was kept has
none (None here): the exports then write UNKNOWN_EPOCH where the standard needs a time, and say
it is unknown.
"""

from __future__ import annotations

import datetime as dt
import re

UNKNOWN_EPOCH = dt.datetime(2000, 1, 1)  # written where a time is required and none is known
_FORMAT = "%Y-%m-%dT%H:%M:%S.%fZ"


def utc_now() -> dt.datetime:
    """The current UTC time (naive, as the formats' readers return it)."""
    return dt.datetime.now(dt.timezone.utc).replace(tzinfo=None)


def from_unix_s(seconds: float) -> dt.datetime:
    """A UNIX time (seconds) as naive UTC."""
    return dt.datetime.fromtimestamp(float(seconds), dt.timezone.utc).replace(tzinfo=None)


def format_utc(when: dt.datetime) -> str:
    """``when`` (naive UTC) as ISO 8601 with microseconds and a Z."""
    return when.strftime(_FORMAT)


def parse_utc(text, what: str = "collection_start_utc") -> dt.datetime:
    """An ISO 8601 UTC time (a Z or +00:00 suffix, or none) → naive UTC; ValueError naming
    ``what`` for anything else."""
    if isinstance(text, bytes):
        text = text.decode("utf-8", "replace")
    if not isinstance(text, str):
        raise ValueError(f"{what} must be an ISO 8601 time, got {text!r}")
    s = text.strip()
    if s.endswith(("Z", "z")):
        s = s[:-1] + "+00:00"
    # SigMF allows any number of fraction digits (nanoseconds); Python reads up to six.
    s = re.sub(r"(\.\d{6})\d+", r"\1", s)
    try:
        when = dt.datetime.fromisoformat(s)
    except ValueError:
        raise ValueError(f"{what} is not an ISO 8601 time: {text!r}") from None
    if when.tzinfo is not None:
        when = when.astimezone(dt.timezone.utc).replace(tzinfo=None)
    return when


def shifted(when: dt.datetime, seconds: float) -> dt.datetime:
    """``when`` plus ``seconds`` (to the microsecond)."""
    return when + dt.timedelta(seconds=float(seconds))
