"""The messages a swath coordinator takes on its results port, checked before any is obeyed.

The results port (a PULL socket the coordinator binds, rtsar.stream.swath) takes whatever
connects to it: the run's workers, a worker started twice with one ``--index``, a worker of
another run, anything at all.  A message is obeyed only if it is one of the kinds a worker
sends, with the parts that kind has, a header that decodes (UTF-8 JSON object) to the fields it
carries, and an index naming a worker of this run; the coordinator then checks it against what
that worker has sent so far (``hello`` and ``ready`` once, ``lines`` continuing its lines with
a payload of their size, ``done`` once).  Anything else is refused in one line
(:class:`Refused`), counted, and the run goes on.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

PARTS = {b"hello": 2, b"ready": 2, b"lines": 3, b"done": 2, b"error": 2}
MAX_SHOWN = 24  # bytes of an unknown message's first part quoted in the refusal


class Refused(ValueError):
    """A results message not obeyed: what it was, in words."""


@dataclass
class Result:
    """A results message that parsed: its kind ("lines", …), worker index and header; the
    payload of a "lines" message."""

    kind: str
    index: int
    head: dict
    payload: bytes | None = None


def _integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def parse(frames: list[bytes], workers: int) -> Result:
    """A message from the results port as a :class:`Result`, or :class:`Refused`."""
    kind = frames[0] if frames else b""
    if kind not in PARTS:
        shown = bytes(kind[:MAX_SHOWN])
        raise Refused(f"an unknown message ({shown!r}{'…' if len(kind) > MAX_SHOWN else ''})")
    name = kind.decode()
    if len(frames) != PARTS[kind]:
        raise Refused(f"a '{name}' message of {len(frames)} parts (it has {PARTS[kind]})")
    try:
        head = json.loads(bytes(frames[1]).decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise Refused(f"a '{name}' message whose header is not UTF-8 JSON") from None
    if not isinstance(head, dict):
        raise Refused(f"a '{name}' message whose header is not a JSON object")
    index = head.get("index")
    if not (_integer(index) and 0 <= index < workers):
        raise Refused(f"a '{name}' message for worker {index!r} (this run's are 0 … {workers - 1})")
    if kind == b"lines":
        first, count = head.get("first_line"), head.get("count")
        if not (_integer(first) and first >= 0 and _integer(count) and count > 0):
            raise Refused(f"a 'lines' message of worker {index} without a first line and count")
        return Result(name, index, head, bytes(frames[2]))
    if kind == b"error" and not isinstance(head.get("message"), str):
        raise Refused(f"an 'error' message of worker {index} without its message")
    return Result(name, index, head)
