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
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
import time
from dataclasses import dataclass
from importlib import resources

from aiohttp import WSMsgType, web

from ...sinks.client import StripSubscriber
from .frames import Cursor, LiveFrames

STATIC = resources.files(__package__) / "static"
SILENCE_S = 5.0  # no message for this long: the page says the publisher is silent
MAX_BROWSERS = 16  # more at once are refused (HTTP 503): memory stays bounded
_CONTENT_TYPES = {".html": "text/html", ".js": "text/javascript", ".css": "text/css"}


@dataclass
class Browser:
    """One connected browser: messages sent to it, whether a send waits on it now, and its
    connection (``transport.get_write_buffer_size()``: what waits for it)."""

    transport: asyncio.BaseTransport | None
    sent: int = 0
    sending: bool = False


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
    the caller's event loop and returns the page's URL (a port 0 is chosen by the system).
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
    ):
        self.frames = LiveFrames(lines, endpoint=endpoint)
        self.host, self.port = host, int(port)
        self.dynamic_range_db = float(dynamic_range_db)
        self.interval_s = 1.0 / float(updates_per_s)
        self.max_browsers = int(max_browsers)
        self.browsers: dict[web.WebSocketResponse, Browser] = {}
        self.updates_sent = 0
        self._slots = 0  # browsers connected or shaking hands
        self._sub = StripSubscriber(endpoint, curve_server_key, curve_client_key, hwm_messages=64)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._changed: asyncio.Event | None = None
        self._runner: web.AppRunner | None = None
        self.failure: str | None = None

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
                        self.frames.set_state(f"no message for {SILENCE_S:g} s: publisher silent")
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
    async def _page(self, request: web.Request) -> web.Response:
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
            headers={"Cache-Control": "no-store"},
        )

    async def _status(self, request: web.Request) -> web.Response:
        return web.json_response(self.frames.snapshot_status())

    async def _socket(self, request: web.Request) -> web.StreamResponse:
        if self._slots >= self.max_browsers:
            raise web.HTTPServiceUnavailable(text=f"at most {self.max_browsers} browsers at once")
        self._slots += 1  # taken before the handshake's await: a burst cannot overshoot
        ws = web.WebSocketResponse(heartbeat=10.0, max_msg_size=1 << 16)
        try:
            await ws.prepare(request)
        except BaseException:
            self._slots -= 1
            raise
        browser = self.browsers[ws] = Browser(request.transport)
        self.frames.set_browsers(len(self.browsers))
        self._wake()
        reader = asyncio.ensure_future(self._read(ws))
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
                await asyncio.sleep(self.interval_s)
                if not changed.is_set():
                    with contextlib.suppress(asyncio.TimeoutError):
                        await asyncio.wait_for(changed.wait(), 1.0)
        except (ConnectionError, RuntimeError):
            pass  # the browser went away mid-send
        finally:
            reader.cancel()
            self.browsers.pop(ws, None)
            self._slots -= 1
            self.frames.set_browsers(len(self.browsers))
            await ws.close()
        return ws

    async def _read(self, ws: web.WebSocketResponse) -> None:
        """Take the browser's messages (none are expected) until it closes."""
        async for msg in ws:
            if msg.type in (WSMsgType.ERROR, WSMsgType.CLOSE):
                break

    def app(self) -> web.Application:
        app = web.Application()
        app.router.add_get("/", self._page)
        app.router.add_get("/static/{name}", self._static)
        app.router.add_get("/status.json", self._status)
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
            raise OSError(f"cannot serve on {self.host}:{self.port}: {exc.strerror}") from None
        port = self._runner.addresses[0][1]  # the port the system chose for a 0
        self._thread = threading.Thread(target=self._receive, name="view-subscriber", daemon=True)
        self._thread.start()
        return page_url(self.host, port)

    async def stop(self) -> None:
        self._stop.set()
        for ws in list(self.browsers):
            await ws.close()
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
) -> int:
    """Serve the page until Ctrl-C or a signal (exit status 0), or until the subscriber fails
    (1).  ``say`` prints the page's URL and the end."""

    async def main() -> int:
        server = ViewServer(
            endpoint, host, port, lines, dynamic_range_db, curve_server_key, curve_client_key
        )
        url = await server.start()
        where = " (all interfaces: this machine's name or address)" * (host in WILDCARDS)
        say(f"view: {url} shows the strips of {endpoint}{where} (Ctrl-C to stop)")
        try:
            while server.failure is None:
                await asyncio.sleep(0.5)
            say(f"view: the subscriber failed: {server.failure}")
            return 1
        finally:
            await server.stop()

    try:
        return asyncio.run(main())
    except KeyboardInterrupt:
        say("view: stopped")
        return 0
