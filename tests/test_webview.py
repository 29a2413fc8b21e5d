"""``rtsar view --http`` without a browser: the page's rows against a naive pooling, bounded
memory, several browsers, a stalled one, a publisher restart, the options and the assets.

The page itself, in a real browser beside ``rtsar run``: tests/test_webview_browser.py.
"""

import asyncio
import base64
import json
import os
import re
import socket
import struct
import time
from importlib import resources

import aiohttp
import numpy as np
import pytest
from conftest import free_port as _conftest_free_port

from rtsar.app.cli import main
from rtsar.app.cli.view import parse_http
from rtsar.app.webview.frames import Cursor, LiveFrames
from rtsar.app.webview.server import ViewServer
from rtsar.sinks.publish import ZmqPublisher


def strip_header(stream_id, seq, first_line, n_lines, bins, az0=10.0, az_step=0.5):
    """A strip header as the wire protocol has it (README "Strip protocol"), written out."""
    return {
        "format": "rtsar-strip",
        "version": 1,
        "stream_id": stream_id,
        "seq": seq,
        "first_line": first_line,
        "line_count": n_lines,
        "range_bins": bins,
        "dtype": "complex64",
        "byte_order": "little",
        "azimuth_first_m": az0 + first_line * az_step,
        "azimuth_step_m": az_step,
        "range_first_m": 1000.0,
        "range_step_m": 2.0,
        "flagged_lines": [],
        "counters": {"pulses_processed": 100 + seq, "dropped_pulses": 3},
        "config": {},
        "height_strips": False,
    }


def parse(message: bytes):
    """(header, rows, values) of a binary message, decoded from its documented layout."""
    n = struct.unpack("<I", message[:4])[0]
    head = json.loads(message[4 : 4 + n])
    assert (4 + n) % 8 == 0
    rows = np.frombuffer(message, "<f8", head["count"], 4 + n)
    values = np.frombuffer(
        message, "<f4", head["count"] * head["columns"], 4 + n + 8 * head["count"]
    )
    return head, rows.astype(int), values.reshape(head["count"], head["columns"])


def naive_rows(lines_by_index: dict, k: int, c: int, bins: int) -> dict:
    """Display row g → max |x| over lines g·k … g·k+k-1 and groups of c bins, loop by loop."""
    out = {}
    for i, line in lines_by_index.items():
        g = i // k
        row = out.setdefault(g, np.zeros(-(-bins // c)))
        for j in range(bins):
            row[j // c] = max(row[j // c], abs(complex(line[j])))
    return out


def test_rows_pool_lines_and_bins_by_their_largest_magnitude(rng):
    frames = LiveFrames(lines=60, max_rows=20, max_columns=4)  # 3 lines a row, 3 bins a column
    assert (frames.lines_per_row, frames.rows) == (3, 20)
    bins, lines = 10, {}
    # strips of 4 lines (not a multiple of 3), one arriving late, one missing (seq 3)
    order = [0, 1, 2, 5, 4, 6]
    for seq in order:
        data = (rng.standard_normal((4, bins)) + 1j * rng.standard_normal((4, bins))).astype(
            np.complex64
        )
        frames.add_strip(strip_header("a", seq, 4 * seq, 4, bins), data)
        lines.update({4 * seq + i: data[i] for i in range(4)})
    msgs = frames.updates(Cursor())
    stream = json.loads(msgs[0])
    assert stream["columns"] == 4 and stream["bins_per_column"] == 3
    assert stream["row_step_m"] == pytest.approx(1.5)
    assert stream["row0_m"] == pytest.approx(10.0 + 0.5)  # centre of lines 0, 1, 2
    assert stream["column0_m"] == pytest.approx(1002.0)  # centre of bins 0, 1, 2
    head, rows, db = parse(msgs[1])
    expect = naive_rows(lines, 3, 3, bins)
    assert head["newest"] == max(expect) == 27 // 3
    assert sorted(rows) == sorted(expect)  # the rows of the missing strip's lines: partial
    for r, v in zip(rows, db, strict=True):
        np.testing.assert_allclose(v, 20 * np.log10(expect[r]), rtol=0, atol=1e-4)
    assert frames.updates(Cursor(epoch=frames.epoch, image_tick=10**9, status_tick=10**9)) == []


def test_memory_is_bounded_and_only_changed_rows_are_sent(rng):
    frames = LiveFrames(lines=64, max_rows=16, max_columns=8)
    cursor = Cursor()
    frames.add_strip(strip_header("a", 0, 0, 16, 8), np.ones((16, 8), np.complex64))
    frames.updates(cursor)
    sizes = []
    for seq in range(1, 400):
        frames.add_strip(strip_header("a", seq, 16 * seq, 16, 8), np.ones((16, 8), np.complex64))
        sizes.append(sum(a.nbytes for a in (frames._image.data, frames._height.data)))
        if seq == 200:
            first = [m for m in frames.updates(cursor) if isinstance(m, bytes)]
            # a slow browser: 199 strips since its last update, one message with the rows shown
            assert parse(first[0])[0]["count"] == frames.rows == 16
    assert len(set(sizes)) == 1
    frames.add_strip(strip_header("a", 400, 6400, 1, 8), np.ones((1, 8), np.complex64))
    frames.updates(cursor)
    frames.add_strip(strip_header("a", 401, 6401, 1, 8), np.ones((1, 8), np.complex64))
    (update,) = [m for m in frames.updates(cursor) if isinstance(m, bytes)]
    head, rows, _ = parse(update)
    assert list(rows) == [6401 // 4]  # the one row that changed


def test_a_new_stream_id_starts_a_new_waterfall():
    frames = LiveFrames(lines=32, max_rows=32)
    frames.add_strip(strip_header("first", 0, 0, 8, 4), np.ones((8, 4), np.complex64))
    cursor = Cursor()
    frames.updates(cursor)
    frames.add_strip(strip_header("second", 0, 0, 4, 6), np.full((4, 6), 2, np.complex64))
    msgs = frames.updates(cursor)
    stream = json.loads(msgs[0])
    assert stream["stream_id"] == "second" and stream["columns"] == 6
    head, rows, db = parse(msgs[1])
    assert list(rows) == [0, 1, 2, 3] and np.allclose(db, 20 * np.log10(2))


def test_heights_are_the_mean_of_the_valid_ones():
    frames = LiveFrames(lines=8, max_rows=4, max_columns=2)  # 2 lines a row, 2 bins a column
    frames.add_strip(strip_header("h", 0, 0, 4, 4), np.ones((4, 4), np.complex64))
    h = np.arange(16, dtype=np.float32).reshape(4, 4) * 1e-3
    valid = np.ones((4, 4), bool)
    valid[0:2, 0:2] = False  # row 0, column 0: nothing valid
    valid[2, 2] = False
    frames.add_height({"stream_id": "h", "first_line": 0}, h, valid)
    msgs = frames.updates(Cursor())
    head, rows, mean = parse(msgs[2])
    assert head["kind"] == "height" and list(rows) == [0, 1]
    assert np.isnan(mean[0, 0])
    assert mean[0, 1] == pytest.approx(np.mean(h[0:2, 2:4]))
    assert mean[1, 1] == pytest.approx(np.mean([h[2, 3], h[3, 2], h[3, 3]]))


def test_status_carries_rate_latency_drops_and_link_counters():
    frames = LiveFrames(lines=8)
    frames.add_status(
        "stats",
        {
            "pulse_rate_hz": 1600.0,
            "latency_recent_median_ms": 8.0,
            "latency_recent_p99_ms": float("nan"),
            "counters": {"pulses_processed": 10, "dropped_pulses": 4, "link_drops": 1},
            "source": "serial",
        },
        {"strips": 3, "missed_strips": 1},
    )
    (msg,) = frames.updates(Cursor())
    status = json.loads(msg)  # strict JSON: NaN becomes null
    assert status["pulse_rate_hz"] == 1600.0 and "latency_recent_p99_ms" not in status
    assert status["lost"] == ["4 shot(s) dropped (the processing queue was full)"]
    assert status["link"]["text"].endswith("; lost 1 time(s)")
    assert status["viewer"]["missed_strips"] == 1


def test_the_link_state_is_a_silence_or_none_never_a_raw_null():
    """From a cold review: the page's status read "link: link null, link_silences 0" on a
    simulated run (the stats message's `link: null` shown as a counter)."""
    frames = LiveFrames(lines=8)
    frames.add_status("stats", {"link": None, "counters": {"link_silences": 0}}, {})
    assert json.loads(frames.updates(Cursor())[0])["link_silent"] is None
    frames.add_status("stats", {"link": {"silent_s": 2.5, "since_pulse": 4799}}, {})
    assert json.loads(frames.updates(Cursor())[0])["link_silent"] == {
        "silent_s": 2.5, "since_pulse": 4799}  # fmt: skip
    frames.add_status("stats", {"link": {"silent_s": "x"}}, {})  # malformed: no silence
    assert json.loads(frames.updates(Cursor())[0])["link_silent"] is None


def test_parse_http():
    assert parse_http("8080") == ("127.0.0.1", 8080)
    assert parse_http(":0") == ("127.0.0.1", 0)
    assert parse_http("0.0.0.0:9000") == ("0.0.0.0", 9000)
    assert parse_http("[::1]:81") == ("::1", 81)
    for bad in ("x", "host:", "1:99999", "-1"):
        with pytest.raises(ValueError, match="HOST:"):
            parse_http(bad)


def test_view_http_refusals_are_one_line(capsys):
    assert main(["view", "--http", "nope"]) == 2
    assert main(["view", "--http", "0", "--png", "x.png"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(e.startswith("rtsar: error:") for e in err)


def test_the_page_fetches_nothing_from_outside_the_package():
    static = resources.files("rtsar.app.webview") / "static"
    names = {p.name for p in static.iterdir()}
    assert {"index.html", "view.js", "view.css"} <= names
    for name in names:
        text = (static / name).read_text(encoding="utf-8")
        assert not re.search(r"(https?:)?//[a-z0-9.-]+\.[a-z]{2,}/", text, re.I), name
        assert "@import" not in text and "<iframe" not in text


def free_port() -> int:
    return _conftest_free_port()


def stalled_browser(port: int) -> socket.socket:
    """A WebSocket client that shakes hands and then never reads (a frozen browser tab)."""
    s = socket.create_connection(("127.0.0.1", port))
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    key = base64.b64encode(os.urandom(16)).decode()
    request = (
        f"GET /ws HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
        f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n"
    )
    s.sendall(request.encode())
    reply = b""
    while b"\r\n\r\n" not in reply:
        reply += s.recv(1)
    assert reply.startswith(b"HTTP/1.1 101")
    return s


async def restarted(endpoint: str) -> ZmqPublisher:
    """A publisher on the endpoint a closed one held (its port is free again within ~1 s)."""
    for _ in range(40):
        try:
            pub = ZmqPublisher(endpoint, linger_ms=0)
            await asyncio.sleep(0.3)  # the viewer's subscription comes back
            return pub
        except ValueError:
            await asyncio.sleep(0.05)
    raise AssertionError(f"{endpoint} stayed bound")


def test_server_feeds_several_browsers_survives_a_restart_and_a_stalled_one_waits_alone():
    endpoint = f"tcp://127.0.0.1:{free_port()}"

    async def scenario():
        # stall_s: the stalled browser stays while looked at (its cut: test_webview_guard.py)
        server = ViewServer(endpoint, port=0, lines=256, updates_per_s=50, stall_s=600)
        url = await server.start()
        port = int(url.rsplit(":", 1)[1].strip("/"))
        stalled = await asyncio.get_running_loop().run_in_executor(None, stalled_browser, port)
        pub = ZmqPublisher(endpoint, linger_ms=0)
        got = {0: [], 1: []}
        async with aiohttp.ClientSession() as session:
            async with session.get(url) as page:
                assert page.status == 200 and "waterfall" in await page.text()
            sockets = [await session.ws_connect(url + "ws") for _ in range(2)]

            async def listen(i, ws):
                async for msg in ws:
                    got[i].append(msg.data)

            tasks = [asyncio.ensure_future(listen(i, ws)) for i, ws in enumerate(sockets)]
            await asyncio.sleep(0.3)  # the subscriptions reach the publisher
            lines = np.full((16, 512), 3 + 4j, np.complex64)
            for seq in range(300):  # ~2.4 MB of display rows for each browser
                pub.send("strip", strip_header("run-1", seq, 16 * seq, 16, 512), lines)
                await asyncio.sleep(0.002)
            await asyncio.sleep(0.5)
            stalled_state = [b for b in server.browsers.values() if b.sending]
            buffered = [b.transport.get_write_buffer_size() for b in stalled_state]
            sent = sorted(b.sent for b in server.browsers.values())
            pub.close()
            pub = await restarted(endpoint)  # the publisher restarts: a new stream id
            for seq in range(3):
                pub.send("strip", strip_header("run-2", seq, 16 * seq, 16, 64), lines[:, :64])
                await asyncio.sleep(0.01)
            pub.send("end", {"format": "rtsar-stats", "stream_id": "run-2", "counters": {}})
            deadline = time.monotonic() + 5
            while time.monotonic() < deadline and not all(
                any('"stream ended"' in m for m in g if isinstance(m, str)) for g in got.values()
            ):
                await asyncio.sleep(0.05)
            status = server.frames.snapshot_status()
            for ws in sockets:
                await ws.close()
            await asyncio.gather(*tasks)
        pub.close()
        stalled.close()
        await server.stop()
        return got, stalled_state, buffered, sent, status

    got, stalled_state, buffered, sent, status = asyncio.run(scenario())
    # The stalled browser: one send waits on it (the others went on: they were sent more),
    # and what waits for it in this process is less than two full updates (the rest is the
    # system's socket buffers, bounded by the system).
    assert len(stalled_state) == 1 and stalled_state[0].sent == sent[0] < sent[1]
    assert buffered[0] < 2 * 256 * 512 * 4
    assert status["state"] == "stream ended" and status["browsers"] == 3
    for messages in got.values():
        streams = [json.loads(m) for m in messages if isinstance(m, str) and '"stream"' in m]
        assert [s["stream_id"] for s in streams] == ["run-1", "run-2"]
        rows = [parse(m) for m in messages if isinstance(m, bytes)]
        last_first_run = [r for r in rows if r[2].shape[1] == 512][-1]
        assert last_first_run[0]["newest"] == 300 * 16 // 1 - 1  # 1 line a row at 256 lines
        assert np.allclose(last_first_run[2], 20 * np.log10(5.0), atol=1e-5)
        assert rows[-1][2].shape[1] == 64 and rows[-1][0]["newest"] == 47


def test_the_readme_defaults_16_browsers_and_8192_lines_in_1024_rows():
    from rtsar.app.webview import server

    frames = LiveFrames()
    assert (frames.lines, frames.lines_per_row, frames.rows) == (8192, 8, 1024)
    assert server.MAX_BROWSERS == 16

    async def one_too_many():
        view = ViewServer(f"tcp://127.0.0.1:{free_port()}", port=0, max_browsers=1)
        url = await view.start()
        async with aiohttp.ClientSession() as session:
            first = await session.ws_connect(url + "ws")
            with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                await session.ws_connect(url + "ws")
            await first.close()
        await view.stop()
        return refused.value.status

    assert asyncio.run(one_too_many()) == 503


def test_a_wildcard_bind_prints_an_address_a_browser_can_open():
    """From a cold review: `--http 0.0.0.0:0` printed http://0.0.0.0:PORT/ as the page."""
    import socket

    from rtsar.app.webview.server import page_url

    assert page_url("0.0.0.0", 8080) == f"http://{socket.gethostname()}:8080/"
    assert page_url("127.0.0.1", 81) == "http://127.0.0.1:81/"
    assert page_url("::1", 81) == "http://[::1]:81/"


@pytest.mark.parametrize("signals_sent", [("SIGINT", "SIGINT"), ("SIGTERM", "SIGINT")])
def test_two_signals_in_a_row_end_the_page_in_two_lines(tmp_path, signals_sent):
    """A new user's review: `timeout -s INT` (which may signal twice) left 79 lines of asyncio
    tracebacks in 2 of 25 stops; the second signal landed while the server stopped.  A signal
    now only asks the serve loop to end."""
    import os
    import signal
    import subprocess
    import sys
    import time

    args = [sys.executable, "-m", "rtsar", "view", "--http", "0"]
    args += ["--endpoint", f"ipc://{tmp_path}/none"]
    view = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert "shows the strips of" in view.stdout.readline()
        for name in signals_sent:
            os.kill(view.pid, getattr(signal, name))
            time.sleep(0.02)
        out, _ = view.communicate(timeout=30)
    finally:
        view.kill()
    first = signals_sent[0]
    assert view.returncode == 128 + getattr(signal, first)
    said = "view: interrupted" if first == "SIGINT" else f"view: stopped by {first}"
    assert out.strip().splitlines() == [said], out


def test_a_page_that_cannot_be_served_leaves_rtsars_signal_handlers(capsys):
    """A cold review: where the port was taken, the loop's signal handlers were added and never
    removed, and asyncio left the system's defaults (SIGTERM then killed without a word)."""
    import signal
    import socket

    from rtsar.app import signals
    from rtsar.app.webview.server import serve

    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    taken = socket.socket()
    try:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        signals.install()
        # the port in use: the line names the way out (a new user's trial found none)
        with pytest.raises(OSError, match="cannot serve on .*--http PORT names another"):
            serve("ipc:///tmp/rtsar-none", "127.0.0.1", taken.getsockname()[1], 64, 50.0)
        for signum in before:
            assert signal.getsignal(signum) is signals._raise, signum
    finally:
        taken.close()
        for signum, handler in before.items():
            signal.signal(signum, handler)
