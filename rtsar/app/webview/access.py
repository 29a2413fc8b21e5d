"""Who may read the live page: the WebSocket's Origin rule and the optional token.

Origin.  A browser names, in the ``Origin`` header of every WebSocket handshake, the page that
opens the socket; any web page may try to open one to ``127.0.0.1``, so the server admits a
browser only when that origin is the page's own (``http://`` + the ``Host`` header the browser
sent: scheme, host and port alike) or one the operator listed (``--allow-origin``).  A handshake
without an ``Origin`` is not a browser's (curl, Python): it is admitted, since such a client
can write any header it likes; the rule protects the people whose browsers visit other sites.

Token.  With ``--http-token`` the page, its status and the WebSocket ask for a secret, given as
``?token=…`` in the address (the printed URL carries it) or as ``Authorization: Bearer …``.
"""

from __future__ import annotations

import contextlib
import hmac
import secrets
from pathlib import Path
from urllib.parse import urlsplit

_DEFAULT_PORTS = {"http": 80, "https": 443}
MIN_TOKEN_CHARS = 16  # a shorter secret is refused: it would be guessed


def normalise_origin(text: str) -> str:
    """``scheme://host[:port]`` → ``scheme://host:port`` (lower case, the default port written
    out), the form two origins are compared in.  ValueError for anything else (a path, a user,
    another scheme)."""
    text = text.strip()
    try:
        parts = urlsplit(text)
        port = parts.port
    except ValueError:
        parts, port = None, None
    if (
        parts is None
        or parts.scheme not in _DEFAULT_PORTS
        or not parts.hostname
        or parts.username is not None
        or parts.path not in ("", "/")
        or parts.query
        or parts.fragment
    ):
        raise ValueError(f"an origin is http(s)://HOST[:PORT], got {text!r}")
    host = parts.hostname.lower()
    host = f"[{host}]" if ":" in host else host
    return f"{parts.scheme}://{host}:{port or _DEFAULT_PORTS[parts.scheme]}"


def origin_refusal(origin: str | None, host: str | None, allowed: frozenset[str]) -> str | None:
    """Why a WebSocket handshake with this ``Origin`` and ``Host`` is refused (one line), or
    None when it is admitted: no Origin (not a browser), the page's own origin, or a listed one
    (``allowed``: normalised origins)."""
    if origin is None:
        return None
    try:
        theirs = normalise_origin(origin)
    except ValueError:
        theirs = None
    own = None
    if host:
        with contextlib.suppress(ValueError):  # a Host that names no host
            own = normalise_origin(f"http://{host}")
    if theirs is not None and (theirs == own or theirs in allowed):
        return None
    shown = origin if len(origin) <= 80 else origin[:77] + "..."
    return (
        f"a page from {shown!r} may not read this view (not its own origin "
        f"{own or 'unknown'}; --allow-origin lists others)"
    )


def token_refusal(given: str | None, token: str | None) -> str | None:
    """Why a request with this token is refused (one line), or None (no token asked, or the
    right one: compared in constant time)."""
    if token is None:
        return None
    if given is None:
        return "this view asks for its token: open the URL that rtsar view printed"
    if not hmac.compare_digest(given.encode(), token.encode()):
        return "wrong token: open the URL that rtsar view printed"
    return None


def new_token() -> str:
    """A fresh secret for the page's address: 32 URL-safe characters (192 bits)."""
    return secrets.token_urlsafe(24)


def read_token(path: str | Path) -> str:
    """The token in the first line of ``path``; ValueError (one line) when the file cannot be
    read, or its token is shorter than MIN_TOKEN_CHARS or holds characters an address would
    have to escape."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"--http-token-file {path}: cannot read it ({exc})") from None
    lines = text.splitlines()
    token = lines[0].strip() if lines else ""
    if len(token) < MIN_TOKEN_CHARS or not all(
        c.isascii() and (c.isalnum() or c in "-_.") for c in token
    ):
        raise ValueError(
            f"--http-token-file {path}: the first line must be a token of at least "
            f"{MIN_TOKEN_CHARS} letters, digits, '-', '_' or '.' (e.g. from "
            "`python -c 'import secrets; print(secrets.token_urlsafe(24))'`)"
        )
    return token
