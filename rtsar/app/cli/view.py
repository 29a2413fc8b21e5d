"""``rtsar view``: the live strips in a window, a PNG snapshot, or a page for browsers (--http)."""

from __future__ import annotations

import sys
import warnings

from ...sinks.endpoint import is_local_endpoint
from ..view import view
from ..webview.access import new_token, normalise_origin, read_token
from .options import add_subscriber_options, die

DEFAULT_HTTP_HOST = "127.0.0.1"


def parse_http(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` (HOST default 127.0.0.1; ``[::1]:PORT`` for IPv6) → (host, port)."""
    host, sep, port = text.rpartition(":")
    if not sep:
        host = ""
    host = host.strip("[]") or DEFAULT_HTTP_HOST
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 <= number <= 65535:
        raise ValueError(f"--http takes [HOST:]PORT with a port 0-65535, got {text!r}")
    return host, number


def http_access(args) -> tuple[tuple[str, ...], str | None]:
    """(allowed origins, token) from the --http options; ValueError (one line) for a bad
    origin, an unreadable token file, two ways to give the token, or a CURVE-encrypted stream
    served with neither a token nor --http-insecure."""
    origins = tuple(normalise_origin(o) for o in args.allow_origin)
    if args.http_token and args.http_token_file:
        raise ValueError("give --http-token (a fresh token) or --http-token-file, not both")
    token = read_token(args.http_token_file) if args.http_token_file else None
    if args.http_token:
        token = new_token()
    if token is not None and args.http_insecure:
        raise ValueError("--http-insecure asks for no token: drop it or the token option")
    if args.curve_server_key and token is None and not args.http_insecure:
        raise ValueError(
            "the stream is CURVE-encrypted and --http would show its image in clear to whoever "
            "reaches the page: give --http-token (the page then asks for the token in the URL "
            "printed) or --http-insecure (serve it without one, your choice)"
        )
    return origins, token


def cmd_view(args) -> int:
    if args.lines < 1:
        return die(f"--lines must be >= 1, got {args.lines}")
    if args.timeout is not None and args.timeout <= 0:
        return die(f"--timeout must be > 0 seconds, got {args.timeout}")
    if not args.dynamic_range_db > 0:
        return die(f"--dynamic-range-db must be > 0, got {args.dynamic_range_db}")
    http_only = [
        name
        for name, given in (
            ("--allow-origin", args.allow_origin),
            ("--http-token", args.http_token),
            ("--http-token-file", args.http_token_file),
            ("--http-insecure", args.http_insecure),
        )
        if given
    ]
    if args.http is None and http_only:
        return die(f"{http_only[0]} applies to the page of --http only")
    if args.http is not None:
        if args.png:
            return die("give --http (a page for browsers) or --png (a snapshot), not both")
        host, port = parse_http(args.http)
        origins, token = http_access(args)
        if not is_local_endpoint(f"tcp://{host}:{port}"):
            who = (
                "whoever reaches it sees the image (no password"
                if token is None
                else ("the image and the token travel in clear (a token")
            )
            warnings.warn(
                f"serving the page on {host}:{port}, beyond loopback: {who}, no encryption)",
                UserWarning,
                stacklevel=1,
            )
        # Here, not above: aiohttp takes ~0.2 s to load and only --http needs it.
        from ..webview.server import serve

        def say(message: str) -> None:
            print(message, file=sys.stderr, flush=True)

        return serve(
            args.endpoint,
            host,
            port,
            args.lines,
            args.dynamic_range_db,
            args.curve_server_key,
            args.curve_client_key,
            say,
            allowed_origins=origins,
            token=token,
        )
    return view(
        args.endpoint,
        args.png,
        args.lines,
        args.dynamic_range_db,
        args.curve_server_key,
        args.timeout,
        curve_client_key=args.curve_client_key,
        true_aspect=args.true_aspect,
    )


def add_parsers(sub) -> None:
    s = sub.add_parser(
        "view",
        description="Show the newest image lines as a scrolling waterfall (dB re peak). "
        "A window needs a display; --png FILE waits for --lines lines and writes a snapshot; "
        "--http [HOST:]PORT serves a page (the waterfall with a colour bar and axes in metres, "
        "a true-aspect switch, the run's PRF, latency, what was lost (in red) or only noted, the "
        "source link's state, and the "
        "height strips of a 3D run) to up to 16 browsers at once, e.g. from a laptop: open "
        "http://HOST:PORT/.  Whoever reaches HOST:PORT sees the image; a web page from "
        "another origin does not (its WebSocket is refused, 403), and --http-token asks for a "
        "secret.  A CURVE-encrypted stream is served only with --http-token or "
        "--http-insecure.  It outlives publisher restarts (a new stream starts a new "
        "waterfall).  A viewer, or a browser, that cannot keep up skips frames; it never slows "
        "the processor and nothing queues up for it; a browser that reads nothing for 10 s "
        "loses its place.",
    )
    add_subscriber_options(s)
    s.add_argument("--png", metavar="FILE", help="write a snapshot PNG and exit")
    s.add_argument(
        "--http",
        metavar="[HOST:]PORT",
        help="serve the live page on HOST:PORT (HOST default 127.0.0.1, loopback only; "
        "0.0.0.0 for every interface, with a warning: the page has no password; port 0: "
        "any free port, printed) until Ctrl-C",
    )
    s.add_argument(
        "--allow-origin",
        action="append",
        default=[],
        metavar="ORIGIN",
        help="--http: also let pages from ORIGIN (http(s)://HOST[:PORT], e.g. a proxy's) open "
        "the view's WebSocket; repeatable (default: only the page's own origin, as the browser "
        "reached it; a client that sends no Origin, not a browser, is let in)",
    )
    s.add_argument(
        "--http-token",
        action="store_true",
        help="--http: make a fresh secret token that the page, its status and its WebSocket "
        "ask for (?token=... or Authorization: Bearer ...); the printed URL carries it",
    )
    s.add_argument(
        "--http-token-file",
        metavar="FILE",
        help="--http: the token is the first line of FILE (at least 16 letters, digits, - _ .), "
        "the same across restarts and out of the process list",
    )
    s.add_argument(
        "--http-insecure",
        action="store_true",
        help="--http of a CURVE-encrypted stream (--curve-server-key) without a token: "
        "whoever reaches the page sees the image in clear (refused unless you say so)",
    )
    s.add_argument(
        "--lines",
        type=int,
        default=8192,
        help="lines shown: the waterfall's length (default 8192: 5 s, 1280 m of the demo); "
        "the page pools them, largest |x|, into at most 1024 rows",
    )
    s.add_argument("--dynamic-range-db", type=float, default=50.0, help="dB shown (default 50)")
    s.add_argument(
        "--timeout",
        type=float,
        default=30.0,
        help="--png: give up after this many seconds of silence (default 30)",
    )
    s.add_argument(
        "--true-aspect",
        action="store_true",
        help="--png: "
        "one metre as long on both axes, so a focused point looks like a point (default: "
        "the image fills the figure; the axes' metres give the stretch; the page has a "
        "switch)",
    )
    s.set_defaults(func=cmd_view)
