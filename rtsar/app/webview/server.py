"""The page's server: aiohttp serves ``static/`` and one WebSocket per browser.

Why aiohttp: one well-kept asyncio package (aio-libs) gives both the HTTP server and the
WebSocket endpoint, with the send side's flow control exposed (``send_bytes`` waits while the
connection's buffer is over its limit), which is what keeps a slow browser from growing a queue;
no separate ASGI server is needed, and nothing is fetched from outside the package.

Threads: a subscriber thread receives the strips (rtsar.sinks.client) and updates
:class:`~rtsar.app.webview.frames.LiveFrames`; the event loop runs one task per browser, which
waits for a change, sends what changed since that browser's last update (at most
``updates_per_s`` times a second) and waits for its connection to take it.  A browser that
reads slowly therefore gets fewer, larger updates; what waits for it is one update at most.

Who reads (rtsar.app.webview.access): a WebSocket from another web page's origin is refused
(HTTP 403), and with a token the page, its status and the WebSocket ask for it.  A browser that
reads nothing for ``STALL_S`` seconds loses its slot: its socket is cut, not closed politely (a
polite close would wait for it to read what is queued).  Reading is shown by a pong that echoes
one of the random pings sent every ``STALL_S / 4`` (a client that reads nothing cannot echo
them), or by the bytes queued for it going down.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import secrets
import signal
import socket
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from errno import EADDRINUSE
from importlib import resources

from aiohttp import WSMsgType, web

from ...sinks.client import StripSubscriber
from .. import signals
from .access import origin_refusal, token_refusal
from .frames import Cursor, LiveFrames
from .icon import icon_png

STATIC = resources.files(__package__) / "static"
SILENCE_S = 5.0  # no message for this long: the page says the publisher is silent
MAX_BROWSERS = 16  # more at once are refused (HTTP 503): memory stays bounded
STALL_S = 10.0  # a browser that reads nothing for this long loses its slot
LOG_REPEAT_S = 10.0  # refusals and drops: one line of a kind at most this often, then a count
_CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css"}


@dataclass
class Browser:
    """One connected browser: messages sent to it, whether a send waits on it now, and its
    connection (``transport.get_write_buffer_size()``: what waits for it); when it last showed
    that it reads (``read_at``, event-loop seconds), the bytes queued for it when last looked at,
    the payloads of the last pings sent to it; whether it was cut for reading nothing."""

    transport: asyncio.BaseTransport | None
    peer: str = "?"
    read_at: float = 0.0
    sent: int = 0
    sending: bool = False
    buffered_bytes: int = 0
    pinged_at: float = -math.inf
    pings: deque = field(default_factory=lambda: deque(maxlen=8))
    dropped: bool = False


class Said:
    """Lines for the operator, one of a kind at most every LOG_REPEAT_S seconds; the next line
    of that kind says how many were left unsaid, so a page that retries in a loop cannot fill the
    terminal.  ``clock``: seconds, monotonic."""

    def __init__(self, say, clock=time.monotonic):
        self.say, self.clock = say, clock
        self._last: dict[str, float] = {}
        self._unsaid: dict[str, int] = {}

    def __call__(self, kind: str, line: str) -> None:
        now = self.clock()
        if now - self._last.get(kind, -math.inf) < LOG_REPEAT_S:
            self._unsaid[kind] = self._unsaid.get(kind, 0) + 1
            return
        self._last[kind] = now
        unsaid = self._unsaid.pop(kind, 0)
        self.say(line + (f" (and {unsaid} more since the last such line)" if unsaid else ""))


def _stderr(message: str) -> None:
    print(message, file=sys.stderr, flush=True)


WILDCARDS = ("0.0.0.0", "::", "")  # bind every interface: not an address a browser opens


def page_url(host: str, port: int) -> str:
    """The URL a browser opens: for a wildcard bind, this machine's name (0.0.0.0 is not an
    address to open from another machine)."""
    if host in WILDCARDS:
        host = socket.gethostname() or "localhost"
    host = f"[{host}]" if ":" in host else host
    return f"http://{host}:{port}/"


class ViewServer:
    """``rtsar view --http``: subscribe to ``endpoint`` and serve the live page on host:port.

    ``subscriber`` options as for :class:`StripSubscriber` (CURVE keys).  ``start`` runs in
    the caller's event loop and returns the page's URL (a port 0 is chosen by the system; the
    token, if any, in its query).  ``allowed_origins``: normalised origins
    (:func:`~rtsar.app.webview.access.normalise_origin`) admitted beside the page's own;
    ``token``: the secret the page and the WebSocket ask for (None: none asked); ``stall_s``: a
    browser that reads nothing for this long loses its slot; ``say``: one line for the operator
    (a refusal, a drop).
    """

    def __init__(
        self,
        endpoint: str,
        host: str = "127.0.0.1",
        port: int = 8080,
        lines: int = 8192,
        dynamic_range_db: float = 50.0,
        curve_server_key=None,
        curve_client_key=None,
        updates_per_s: float = 10.0,
        max_browsers: int = MAX_BROWSERS,
        allowed_origins=(),
        token: str | None = None,
        stall_s: float = STALL_S,
        say=_stderr,
    ):
        self.frames = LiveFrames(lines, endpoint=endpoint)
        self.host, self.port = host, int(port)
        self.dynamic_range_db = float(dynamic_range_db)
        self.interval_s = 1.0 / float(updates_per_s)
        self.max_browsers = int(max_browsers)
        self.browsers: dict[web.WebSocketResponse, Browser] = {}
        self.updates_sent = 0
        self.allowed_origins = frozenset(allowed_origins)
        self.token = token
        self.stall_s = float(stall_s)
        self.ping_s = self.stall_s / 4
        self.refused = 0  # handshakes and pages refused (origin, token)
        self.dropped = 0  # browsers cut for reading nothing
        self._said = Said(say)
        self._watcher: asyncio.Task | None = None
        self._slots = 0  # browsers connected or shaking hands
        self._sub = StripSubscriber(endpoint, curve_server_key, curve_client_key, hwm_messages=64)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed: asyncio.Event | None = None
        self._runner: web.AppRunner | None = None
        self.failure: str | None = None
        self._icon_png = icon_png()

    # ---- the subscriber thread -----------------------------------------------------------------
    def _receive(self) -> None:
        last = time.monotonic()
        said_silent = False
        try:
            while not self._stop.is_set():
                msg = self._sub.recv(0.2)
                now = time.monotonic()
                if msg is None:
                    if now - last > SILENCE_S and not said_silent:
                        self.frames.publisher_quiet(SILENCE_S)
                        said_silent = True
                        self._notify()
                    continue
                last, said_silent = now, False
                if msg.topic == "strip":
                    self.frames.add_strip(msg.header, msg.lines)
                    self.frames.add_status("", {}, self._sub.counters)
                elif msg.topic == "height":
                    self.frames.add_height(msg.header, msg.lines, msg.valid)
                elif msg.topic in ("stats", "end"):
                    self.frames.add_status(msg.topic, msg.header, self._sub.counters)
                self._notify()
        except Exception as exc:  # noqa: BLE001 - told on the page and by the command
            self.failure = f"{type(exc).__name__}: {exc}"
            self.frames.set_state(f"viewer failed: {self.failure}")
            self._notify()

    def _notify(self) -> None:
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed meanwhile
                loop.call_soon_threadsafe(self._wake)

    def _wake(self) -> None:
        if self._changed is not None:
            self._changed.set()
            self._changed = asyncio.Event()

    # ---- HTTP ----------------------------------------------------------------------------------
    def _refuse(self, request: web.Request, reason: str | None) -> None:
        """Refuse the request (HTTP 403, the reason as its one-line body) when there is a
        reason, and tell the operator."""
        if reason is None:
            return
        self.refused += 1
        self._said("refused", f"view: refused {request.path} to {request.remote}: {reason}")
        raise web.HTTPForbidden(text=reason + "\n")

    def _token_refusal(self, request: web.Request) -> str | None:
        given = request.query.get("token")
        scheme, _, value = request.headers.get("Authorization", "").partition(" ")
        if given is None and scheme.lower() == "bearer":
            given = value.strip()
        return token_refusal(given, self.token)

    async def _page(self, request: web.Request) -> web.Response:
        self._refuse(request, self._token_refusal(request))
        return self._file("index.html")

    async def _static(self, request: web.Request) -> web.Response:
        return self._file(request.match_info["name"])

    def _file(self, name: str) -> web.Response:
        suffix = name[name.rfind(".") :] if "." in name else ""
        path = STATIC / name
        if "/" in name or suffix not in _CONTENT_TYPES or not path.is_file():
            raise web.HTTPNotFound()
        text = path.read_text(encoding="utf-8")
        if name == "index.html":
            text = text.replace("{{DYNAMIC_RANGE_DB}}", f"{self.dynamic_range_db:g}")
        return web.Response(
            text=text,
            content_type=_CONTENT_TYPES[suffix],
            headers={"Cache-Control": "no-store", "Referrer-Policy": "no-referrer"},
        )

    async def _icon(self, request: web.Request) -> web.Response:
        return web.Response(
            body=self._icon_png,
            content_type="image/png",
            headers={"Cache-Control": "max-age=86400"},
        )

    async def _status(self, request: web.Request) -> web.Response:
        self._refuse(request, self._token_refusal(request))
        return web.json_response(self.frames.snapshot_status())

    async def _socket(self, request: web.Request) -> web.StreamResponse:
        origin = request.headers.get("Origin")
        host = request.headers.get("Host")
        self._refuse(request, origin_refusal(origin, host, self.allowed_origins))
        self._refuse(request, self._token_refusal(request))
        if self._slots >= self.max_browsers:
            raise web.HTTPServiceUnavailable(text=f"at most {self.max_browsers} browsers at once")
        self._slots += 1  # taken before the handshake's await: a burst cannot overshoot
        # autoping off: the pongs come to _read, which checks them against the pings sent
        ws = web.WebSocketResponse(autoping=False, max_msg_size=1 << 16)
        try:
            await ws.prepare(request)
        except BaseException:
            self._slots -= 1
            raise
        loop = asyncio.get_running_loop()
        browser = Browser(request.transport, str(request.remote), read_at=loop.time())
        self.browsers[ws] = browser
        self.frames.set_browsers(len(self.browsers))
        self._wake()
        reader = asyncio.ensure_future(self._read(ws, browser))
        cursor = Cursor()
        try:
            while not ws.closed and not reader.done():
                changed = self._changed
                messages = self.frames.updates(cursor)
                browser.sending = True
                for message in messages:
                    if isinstance(message, bytes):
                        await ws.send_bytes(message)  # waits while the browser is behind
                    else:
                        await ws.send_str(message)
                    browser.sent += 1
                    self.updates_sent += 1
                browser.sending = False
                if loop.time() - browser.pinged_at >= self.ping_s:
                    browser.pinged_at = loop.time()
                    browser.pings.append(secrets.token_bytes(8))
                    await ws.ping(browser.pings[-1])
                await asyncio.sleep(self.interval_s)
                if not changed.is_set():
                    with contextlib.suppress(asyncio.TimeoutError):
                        await asyncio.wait_for(changed.wait(), min(1.0, self.ping_s))
        except (ConnectionError, RuntimeError):
            pass  # the browser went away mid-send, or was cut by _watch
        finally:
            reader.cancel()
            self.browsers.pop(ws, None)
            self._slots -= 1
            self.frames.set_browsers(len(self.browsers))
            if not browser.dropped:
                try:  # a polite close, within the time a reading browser would need
                    await asyncio.wait_for(ws.close(), self.stall_s)
                except asyncio.TimeoutError:
                    if browser.transport is not None:
                        browser.transport.abort()
        return ws

    async def _read(self, ws: web.WebSocketResponse, browser: Browser) -> None:
        """Take the browser's messages until it closes: its pongs (a pong that echoes one of
        our pings shows that it read up to that ping) and its pings (answered)."""
        async for msg in ws:
            if msg.type == WSMsgType.PONG and msg.data in browser.pings:
                browser.read_at = asyncio.get_running_loop().time()
            elif msg.type == WSMsgType.PING:
                await ws.pong(msg.data)
            elif msg.type in (WSMsgType.ERROR, WSMsgType.CLOSE):
                break

    async def _watch(self) -> None:
        """Cut every browser that has shown no reading for ``stall_s``: no pong echoing a ping,
        and the bytes queued for it not going down.  Checked ten times per ``stall_s``."""
        loop = asyncio.get_running_loop()
        while True:
            await asyncio.sleep(self.stall_s / 10)
            now = loop.time()
            for browser in list(self.browsers.values()):
                transport = browser.transport
                queued = transport.get_write_buffer_size() if transport is not None else 0
                if queued < browser.buffered_bytes:
                    browser.read_at = now  # the system took some: the browser reads
                browser.buffered_bytes = queued
                if now - browser.read_at > self.stall_s and not browser.dropped:
                    browser.dropped = True
                    self.dropped += 1
                    self._said(
                        "dropped",
                        f"view: cut the browser at {browser.peer}: it read nothing for "
                        f"{self.stall_s:g} s ({queued / 2**20:.1f} MiB waiting for it; its "
                        "slot is free again)",
                    )
                    if transport is not None:
                        transport.abort()  # wakes its send; a close would wait for it to read

    def app(self) -> web.Application:
        app = web.Application()
        app.router.add_get("/", self._page)
        app.router.add_get("/static/{name}", self._static)
        app.router.add_get("/status.json", self._status)
        app.router.add_get("/favicon.ico", self._icon)
        app.router.add_get("/ws", self._socket)
        return app

    async def start(self) -> str:
        """Start the subscriber thread and the HTTP server; the page's URL."""
        self._loop = asyncio.get_running_loop()
        self._changed = asyncio.Event()
        self._runner = web.AppRunner(self.app(), handle_signals=False, access_log=None)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        try:
            await site.start()
        except OSError as exc:
            await self._runner.cleanup()
            self._runner = None  # (stop() then only closes the subscriber)
            hint = "; --http PORT names another (0: the system's choice)"
            hint *= exc.errno == EADDRINUSE  # (another program serves there)
            where = f"{self.host}:{self.port}"
            raise OSError(f"cannot serve on {where}: {exc.strerror}{hint}") from None
        port = self._runner.addresses[0][1]  # the port the system chose for a 0
        self._thread = threading.Thread(target=self._receive, name="view-subscriber", daemon=True)
        self._thread.start()
        self._watcher = asyncio.ensure_future(self._watch())
        query = f"?token={self.token}" if self.token is not None else ""
        return page_url(self.host, port) + query

    async def stop(self) -> None:
        self._stop.set()
        if self._watcher is not None:
            self._watcher.cancel()
        for ws in list(self.browsers):  # a browser that reads nothing does not hold the end
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(ws.close(), 1.0)
        if self._runner is not None:
            await self._runner.cleanup()
        if self._thread is not None:
            await asyncio.get_running_loop().run_in_executor(None, self._thread.join, 2.0)
        self._sub.close()


def serve(
    endpoint: str,
    host: str,
    port: int,
    lines: int,
    dynamic_range_db: float,
    curve_server_key=None,
    curve_client_key=None,
    say=print,
    allowed_origins=(),
    token: str | None = None,
) -> int:
    """Serve the page until Ctrl-C or a signal (exit status 128 + its number: 130 for Ctrl-C),
    or until the subscriber fails (1).  ``say`` prints the page's URL (with its token), the
    refusals and drops, and the end.  ``allowed_origins``, ``token``: as for
    :class:`ViewServer`."""

    async def main() -> int:
        # A signal only asks the loop to end (raised anywhere, one left asyncio tracebacks)
        loop = asyncio.get_running_loop()
        stopped = _ask_to_stop_on_signals(loop)
        server = None
        try:
            server = ViewServer(
                endpoint,
                host,
                port,
                lines,
                dynamic_range_db,
                curve_server_key,
                curve_client_key,
                allowed_origins=allowed_origins,
                token=token,
                say=say,
            )
            url = await server.start()
            where = " (all interfaces: this machine's name or address)" * (host in WILDCARDS)
            say(f"view: {url} shows the strips of {endpoint}{where} (Ctrl-C to stop)")
            while server.failure is None and not stopped:
                await asyncio.sleep(0.1)
            if stopped:
                raise _signal_exception(stopped[0])
            say(f"view: the subscriber failed: {server.failure}")
            return 1
        finally:
            try:
                if server is not None:  # (one that did not start: its subscriber closed)
                    await server.stop()
            finally:
                _restore_signals(loop)
            if server is not None and (server.refused or server.dropped):  # counted
                say(
                    f"view: {server.refused} request(s) refused (origin, token), "
                    f"{server.dropped} browser(s) cut for reading nothing"
                )

    try:
        return asyncio.run(main())
    except KeyboardInterrupt as exc:  # 130 for Ctrl-C, 128 + N for a signal: as every command
        say(f"view: {signals.describe(exc)}")
        return signals.exit_status(exc)


_CAUGHT = [getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)]


def _ask_to_stop_on_signals(loop) -> list[int]:
    """SIGINT, SIGTERM and SIGHUP noted in the list returned (the loop's own handlers, where
    the platform has them), not raised: the serve loop ends at its next step."""
    stopped: list[int] = []
    for signum in _CAUGHT:
        with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
            loop.add_signal_handler(signum, stopped.append, signum)
    return stopped


def _restore_signals(loop) -> None:
    """The loop's handlers removed (asyncio leaves the system's defaults) and rtsar's put back,
    the signals held back between the two (one that comes then goes to rtsar's)."""
    mask = getattr(signal, "pthread_sigmask", lambda how, signums: None)  # (POSIX only)
    mask(getattr(signal, "SIG_BLOCK", 0), _CAUGHT)
    try:
        for signum in _CAUGHT:
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.remove_signal_handler(signum)
        signals.install()
    finally:
        mask(getattr(signal, "SIG_UNBLOCK", 1), _CAUGHT)


def _signal_exception(signum: int) -> KeyboardInterrupt:  # as rtsar.app.signals raises it
    return KeyboardInterrupt() if signum == signal.SIGINT else signals.Terminated(signum)
