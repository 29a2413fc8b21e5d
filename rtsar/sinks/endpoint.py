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
SCHEMES = ("tcp", "ipc", "inproc", "ws", "wss", "pgm", "epgm")  # ZeroMQ's for PUB/SUB
_WITH_PORT = ("tcp", "ws", "wss", "pgm", "epgm")


def is_local_endpoint(endpoint: str) -> bool:
    """True for ipc://, inproc:// and tcp:// on a loopback address."""
    scheme = endpoint.split("://", 1)[0]
    if scheme in ("ipc", "inproc"):
        return True
    if scheme != "tcp":
        return False
    host = endpoint.split("://", 1)[1].rsplit(":", 1)[0]
    return host in _LOOPBACK or host.startswith("127.")


def endpoint_error(endpoint: str) -> str | None:
    """Why ``endpoint`` cannot be a ZeroMQ endpoint (one phrase), or None where it can.

    Checked before a run starts: ZeroMQ itself takes ``tcp://host:99999`` modulo 2^16 and binds
    another port, so a subscriber given the number the user typed never connects. A TCP port is
    1-65535, or 0 / ``*`` for any free port where binding.
    """
    scheme, sep, rest = endpoint.partition("://")
    if not sep or scheme not in SCHEMES:
        return f"an endpoint is SCHEME://ADDRESS with SCHEME one of {', '.join(SCHEMES)}"
    if not rest or rest != rest.strip():
        return "the address after :// is empty or has spaces"
    if scheme not in _WITH_PORT:
        return None
    where = rest.split("/", 1)[0] if scheme in ("ws", "wss") else rest
    host, colon, port = where.rpartition(":")
    if not colon or not host:
        return f"a {scheme} endpoint is {scheme}://HOST:PORT"
    if port == "*":
        return None
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        return f"the port must be a number 0-65535 (or * for any free port), got {port!r}"
    return None
