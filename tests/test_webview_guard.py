"""Who may read ``rtsar view --http`` (issue 36, items 4 and 5): a page from another origin is
refused, a listed one admitted; a CURVE-encrypted stream is not re-served in clear unless the
operator chooses so; a token, when asked, is needed by the page and its WebSocket; browsers that
read nothing lose their slots, so sixteen of them cannot lock everybody else out.
"""

import asyncio
import contextlib
import os
import re
import socket
import struct
import subprocess
import sys
import time
import urllib.error
import urllib.request

import aiohttp
import numpy as np
import pytest
from conftest import free_port
from test_webview import stalled_browser, strip_header

from rtsar.app.cli import main
from rtsar.app.webview import server as server_module
from rtsar.app.webview.access import normalise_origin, read_token
from rtsar.app.webview.server import ViewServer


async def started(**options):
    """A server on a free port, the lines it said (unless ``say`` is given), its URL and its
    port."""
    said = []
    options.setdefault("say", said.append)
    view = ViewServer(f"tcp://127.0.0.1:{free_port()}", port=0, **options)
    url = await view.start()
    port = int(url.split("?")[0].rsplit(":", 1)[1].strip("/"))
    return view, said, url, port


async def handshake(session, url, origin=None, headers=None):
    """The status of a WebSocket handshake to ``url`` (101: admitted)."""
    try:
        ws = await session.ws_connect(url, origin=origin, headers=headers)
    except aiohttp.WSServerHandshakeError as exc:
        return exc.status
    await ws.close()
    return 101


def test_a_page_from_another_origin_is_refused_and_the_page_itself_admitted(capsys):
    async def scenario():
        view = ViewServer(f"tcp://127.0.0.1:{free_port()}", port=0)  # says on stderr
        url = await view.start()
        port = int(url.rsplit(":", 1)[1].strip("/"))
        ws_url = url + "ws"
        async with aiohttp.ClientSession() as session:
            evil = await handshake(session, ws_url, origin="http://evil.example")
            lines_after_one = capsys.readouterr().err.splitlines()
            other_port = await handshake(session, ws_url, origin=f"http://127.0.0.1:{port + 1}")
            https = await handshake(session, ws_url, origin=f"https://127.0.0.1:{port}")
            named = await handshake(session, ws_url, origin=f"http://localhost:{port}")
            own = await handshake(session, ws_url, origin=f"http://127.0.0.1:{port}")
            own_upper = await handshake(session, ws_url, origin=f"HTTP://127.0.0.1:{port}")
            no_origin = await handshake(session, ws_url)  # curl, Python: not a browser
            async with session.get(ws_url, headers={"Origin": "http://evil.example"}) as reply:
                status, body = reply.status, await reply.text()
        await view.stop()
        return (
            evil,
            lines_after_one,
            other_port,
            https,
            named,
            own,
            own_upper,
            no_origin,
            (status, body, view),
        )

    evil, said, other_port, https, named, own, own_upper, no_origin, plain = asyncio.run(scenario())
    assert (evil, other_port, https, named) == (403, 403, 403, 403)
    assert (own, own_upper, no_origin) == (101, 101, 101)
    assert len(said) == 1 and "'http://evil.example'" in said[0] and "--allow-origin" in said[0]
    status, body, view = plain
    assert status == 403 and body.count("\n") == 1 and "evil.example" in body
    assert view.refused == 5


def test_allow_origin_admits_the_listed_origins_only():
    listed = {normalise_origin("https://Proxy.Example/"), normalise_origin("http://[::1]:81")}
    assert listed == {"https://proxy.example:443", "http://[::1]:81"}

    async def scenario():
        view, said, url, port = await started(allowed_origins=listed)
        ws_url = url + "ws"
        async with aiohttp.ClientSession() as session:
            got = [
                await handshake(session, ws_url, origin=o)
                for o in (
                    "https://proxy.example",
                    "https://proxy.example:443",
                    "http://[::1]:81",
                    f"http://127.0.0.1:{port}",
                    "http://proxy.example",  # another scheme: another origin
                    "https://proxy.example:8443",
                    "null",  # a sandboxed frame or a file: page
                )
            ]
        await view.stop()
        return got

    assert asyncio.run(scenario()) == [101, 101, 101, 101, 403, 403, 403]


@pytest.mark.parametrize("bad", ["proxy.example", "ftp://x", "http://x/path", "http://u@x", "*"])
def test_a_bad_allow_origin_is_one_line_and_status_2(bad, capsys):
    assert main(["view", "--http", "0", "--allow-origin", bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("rtsar: error: an origin is http(s)://")


def test_the_http_options_need_http(capsys):
    assert main(["view", "--png", "x.png", "--http-insecure"]) == 2
    assert main(["view", "--http", "0", "--http-token", "--http-insecure"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "--http-insecure applies to the page of --http only" in err[0]


def test_a_token_file_gives_its_first_line_and_a_weak_one_is_refused(tmp_path, capsys):
    good, short, spaced = tmp_path / "good", tmp_path / "short", tmp_path / "spaced"
    good.write_text("abcdefgh-ABCDEFGH_0123.x\nignored\n")
    short.write_text("abc123\n")
    spaced.write_text("a token with spaces in it\n")
    assert read_token(good) == "abcdefgh-ABCDEFGH_0123.x"
    for bad in (short, spaced, tmp_path / "missing"):
        assert main(["view", "--http", "0", "--http-token-file", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(e.startswith("rtsar: error: --http-token-file ") for e in err)


def test_refusals_and_cuts_are_said_once_then_counted():
    clock = iter([0.0, 1.0, 2.0, 3.0, 11.0])
    lines = []
    said = server_module.Said(lines.append, clock=lambda: next(clock))
    for _ in range(3):
        said("refused", "r")
    said("dropped", "d")  # another kind: its own line
    said("refused", "r")
    assert lines == ["r", "d", "r (and 2 more since the last such line)"]


def test_a_token_is_asked_by_the_page_its_status_and_its_socket():
    token = "t0ken-for-the-test-0123456789"

    async def scenario():
        view, said, url, port = await started(token=token)
        base = f"http://127.0.0.1:{port}/"
        got = {}
        async with aiohttp.ClientSession() as session:
            asks = (("none", ""), ("wrong", "?token=x"), ("right", f"?token={token}"))
            for name, path in (("page", ""), ("status", "status.json")):
                for how, suffix in asks:
                    async with session.get(base + path + suffix) as reply:
                        got[name, how] = reply.status
            ws = base + "ws"
            got["ws", "none"] = await handshake(session, ws)
            got["ws", "wrong"] = await handshake(session, ws + "?token=" + token[:-1])
            got["ws", "right"] = await handshake(session, ws + "?token=" + token)
            bearer = {"Authorization": f"Bearer {token}"}
            got["ws", "bearer"] = await handshake(session, ws, headers=bearer)
            async with session.get(base + "static/view.js") as reply:  # no image in it
                got["script", "none"] = reply.status
        await view.stop()
        return url, got

    url, got = asyncio.run(scenario())
    assert url.endswith(f"/?token={token}")
    assert got == {
        ("page", "none"): 403, ("page", "wrong"): 403, ("page", "right"): 200,
        ("status", "none"): 403, ("status", "wrong"): 403, ("status", "right"): 200,
        ("ws", "none"): 403, ("ws", "wrong"): 403, ("ws", "right"): 101, ("ws", "bearer"): 101,
        ("script", "none"): 200,
    }  # fmt: skip


@pytest.fixture(scope="module")
def curve_key(tmp_path_factory):
    folder = tmp_path_factory.mktemp("keys")
    assert main(["keygen", str(folder)]) == 0
    return str(folder / "rtsar.key")


def view_command(*options):
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    return [sys.executable, "-m", "rtsar", "view", endpoint, "--http", "127.0.0.1:0", *options]


def test_a_curve_stream_is_not_served_in_clear_without_the_operators_choice(curve_key):
    done = subprocess.run(
        view_command("--curve-server-key", curve_key), capture_output=True, text=True, timeout=60
    )
    err = done.stderr.strip().splitlines()
    assert done.returncode == 2 and len(err) == 1, done.stderr
    assert "CURVE-encrypted" in err[0] and "--http-token" in err[0] and "--http-insecure" in err[0]


@pytest.mark.parametrize("choice", ["--http-token", "--http-insecure"])
def test_a_curve_stream_is_served_with_a_token_or_by_choice(curve_key, choice):
    proc = subprocess.Popen(
        view_command("--curve-server-key", curve_key, choice), stderr=subprocess.PIPE, text=True
    )
    try:
        first = proc.stderr.readline()
        url = re.search(r"(http://\S+)", first).group(1)
        page = url.split("?")[0]

        def status(address):
            try:
                with urllib.request.urlopen(address, timeout=30) as reply:
                    return reply.status
            except urllib.error.HTTPError as exc:
                return exc.code

        got = status(url), status(page)
    finally:
        proc.terminate()
        proc.communicate(timeout=30)
    if choice == "--http-token":
        token = url.split("?token=")[1]
        assert re.fullmatch(r"[A-Za-z0-9_-]{32}", token) and got == (200, 403)
    else:
        assert "?" not in url and got == (200, 200)


def test_the_stall_bound_is_10_s():
    """The bound the docs and --help state (docs/pages/guide/live.md)."""
    assert server_module.STALL_S == 10.0
    view = ViewServer(f"tcp://127.0.0.1:{free_port()}")
    assert view.stall_s == 10.0 and view.ping_s == 2.5
    view._sub.close()


def bogus_pong(sock: socket.socket) -> None:
    """A masked pong frame with a payload no ping carried: reading nothing, faking life."""
    mask, payload = os.urandom(4), os.urandom(8)
    masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
    sock.sendall(struct.pack("!BB", 0x8A, 0x80 | len(payload)) + mask + masked)


@pytest.mark.parametrize("stream", [True, False], ids=["image-waiting", "no-stream"])
def test_sixteen_browsers_that_read_nothing_lose_their_slots(stream):
    """Sixteen sockets that never read (half of them sending pongs that echo no ping) hold
    every slot; each is cut after the bound (3 s here), and a new browser gets in and is sent
    the view.  With an image shown (more than the system buffers for a browser that reads
    nothing), each is cut while the server's send to it waits: the case that the old heartbeat
    never ended (issue 36, item 5)."""

    async def scenario():
        view, said, url, port = await started(lines=8192, stall_s=3.0)
        loop = asyncio.get_running_loop()
        idle = [await loop.run_in_executor(None, stalled_browser, port) for _ in range(16)]
        kept = list(view.browsers.values())
        async with aiohttp.ClientSession() as session:
            full = await handshake(session, url + "ws")
        if stream:  # 1024 rows of 1024 columns: the update is 4 MiB of float32 for each
            for seq in range(16):
                header = strip_header("s", seq, 512 * seq, 512, 1024)
                view.frames.add_strip(header, np.full((512, 1024), 3 + 4j, np.complex64))
        first = None
        async with aiohttp.ClientSession() as session:
            deadline = time.monotonic() + 60  # generous: the bound is what the code decides
            while first is None and time.monotonic() < deadline:
                for sock in idle[::2]:
                    with contextlib.suppress(OSError):  # once cut, the socket is reset
                        bogus_pong(sock)
                await asyncio.sleep(0.05)
                if not view.browsers:  # all sixteen cut
                    ws = await session.ws_connect(url + "ws", max_msg_size=0)
                    first = await ws.receive(timeout=30)
                    await ws.close()
        for sock in idle:
            sock.close()
        await view.stop()
        return full, first, kept, said, view.dropped

    full, first, kept, said, dropped = asyncio.run(scenario())
    assert full == 503  # the sixteen hold every slot at first
    assert first is not None and first.data.startswith('{"type": "stream"' if stream else "{")
    assert dropped == 16 and all(b.dropped for b in kept)
    assert re.search(
        r"read nothing for 3 s \([0-9.]+ MiB waiting for it; its slot is free", said[0]
    )
    if stream:  # cut while a send waited on it: more queued than the 64 KiB it may hold
        assert all(b.sending and b.buffered_bytes > 2**16 for b in kept)
