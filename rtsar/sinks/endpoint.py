"""Where and how strips are published: the default endpoint, which endpoints stay on this host,
the delivery modes and the longest a lossless send waits.

Kept apart from the publisher (ZeroMQ) so the command line can name them without loading it.
The default endpoint is ``$RTSAR_ENDPOINT`` where set (two instruments' processors on one host,
or a test session beside a running demo), else tcp://127.0.0.1:5555.
"""

from __future__ import annotations

import os

DEFAULT_ENDPOINT = os.environ.get("RTSAR_ENDPOINT", "").strip() or "tcp://127.0.0.1:5555"
STALL_TIMEOUT_S = 2.0  # the longest a lossless send waits for a subscriber that reads nothing
DELIVERIES = ("drop", "lossless")
_LOOPBACK = {"127.0.0.1", "localhost", "::1", "[::1]"}


def is_local_endpoint(endpoint: str) -> bool:
    """True for ipc://, inproc:// and tcp:// on a loopback address."""
    scheme = endpoint.split("://", 1)[0]
    if scheme in ("ipc", "inproc"):
        return True
    if scheme != "tcp":
        return False
    host = endpoint.split("://", 1)[1].rsplit(":", 1)[0]
    return host in _LOOPBACK or host.startswith("127.")
