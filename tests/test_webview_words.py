"""What ``rtsar view --http``'s page says about the run (its status JSON, which the page shows as
it is): red only for what is missing, never "shots arriving" after the stream's end, and an
icon so a browser's request for one is answered (issue 37, item 5)."""

import asyncio
import io
import json
import time

import aiohttp
import numpy as np
import pytest
from conftest import free_port
from test_webview import strip_header

from rtsar.app import live
from rtsar.app.webview import server as server_module
from rtsar.app.webview.frames import (
    LINK_COUNTERS,
    LOST_WORDS,
    NOTED_WORDS,
    Cursor,
    LiveFrames,
    losses,
    notes,
)
from rtsar.app.webview.server import ViewServer
from rtsar.sinks.publish import ZmqPublisher

# The end counters of `rtsar run --duration 5` on a busy 2-core machine, as its page got them:
# the page said "drops, gaps: late releases 7430" in red, with nothing dropped.
BUSY_RUN = {
    "late_releases": 7430,
    "pulses_received": 8000,
    "pulses_accepted": 8000,
    "gap_pulses": 0,
    "gaps": 0,
    "discontinuities": 0,
    "duplicates": 0,
    "link_silences": 0,
    "link_silent_ms": 0,
    "dropped_pulses": 0,
    "pulses_processed": 8000,
    "lines_out": 7489,
    "flagged_lines": 0,
    "strips_published": 469,
}


def status_after(*messages) -> dict:
    """The status message a new browser gets after ``messages`` ((topic, header) pairs)."""
    frames = LiveFrames(lines=8)
    for topic, header in messages:
        frames.add_status(topic, header, {"strips": 1, "missed_strips": 0})
    (text,) = [m for m in frames.updates(Cursor()) if isinstance(m, str)]
    return json.loads(text)


def test_late_releases_are_noted_not_lost():
    status = status_after(("stats", {"counters": BUSY_RUN, "link": None}))
    assert status["lost"] == []  # the page paints nothing red
    (note,) = status["noted"]
    assert note.startswith("7430 late release(s): chunks of simulated shots sent over 1 ms")
    assert "no shot lost" in note


def test_flagged_lines_and_a_restart_are_noted_not_lost():
    restart = {"gap_pulses": 512, "gaps": 0, "discontinuities": 1, "flagged_lines": 40}
    assert losses(restart) == []
    assert notes(restart) == [
        "512 zero shot(s) clearing the picture at a restart of the shot count",
        "1 restart(s) of the shot count",
        "40 flagged line(s): lines whose aperture holds a zero-filled, zeroed or marked shot",
    ]


def test_dropped_missing_and_unrecorded_shots_are_lost():
    counters = {"dropped_pulses": 4, "gap_pulses": 30, "gaps": 2, "record_dropped": 7}
    assert losses(counters) == [
        "30 zero shot(s) in place of 2 gap(s) in the shot count",
        "4 shot(s) dropped (the processing queue was full)",
        "7 shot(s) not recorded",
    ]
    assert notes(counters) == []
    both = {"gap_pulses": 542, "gaps": 2, "discontinuities": 1}  # the restart's zeros inside
    assert losses(both) == [
        "542 zero shot(s) in place of 2 gap(s) in the shot count and 1 restart(s)"
    ]


@pytest.mark.parametrize("key", sorted(live._LABELS))
def test_every_counter_the_status_line_names_is_either_lost_or_noted(key):
    """A counter added to the run's status line without a decision here would be shown in
    black under "noted" whatever it counts: each has its words, in one list."""
    lists = [LOST_WORDS, NOTED_WORDS, LINK_COUNTERS, ("gap_pulses",)]
    assert sum(key in group for group in lists) == 1, key


def test_after_the_end_the_link_no_longer_says_shots_arriving():
    frames = LiveFrames(lines=8)
    cursor = Cursor()

    def status():
        return json.loads([m for m in frames.updates(cursor) if isinstance(m, str)][-1])

    lines = np.ones((4, 16), np.complex64)
    frames.add_strip(strip_header("run-1", 0, 0, 4, 16), lines)
    frames.add_status("stats", {"stream_id": "run-1", "link": None, "counters": {}}, {})
    assert status()["link"] == {"text": "shots arriving", "alarm": False}
    frames.add_status("end", {"stream_id": "run-1", "link": None, "counters": {}}, {})
    ended = {"text": "the stream ended: no more shots", "alarm": False}
    at_end = status()
    assert at_end["link"] == ended and at_end["state"] == "stream ended"
    frames.publisher_quiet(5.0)  # silence after the end is what the end said
    after = status()
    assert after["link"] == ended and after["state"] == "stream ended", after
    frames.add_status("stats", {"stream_id": "run-2", "link": None, "counters": {}}, {})
    again = status()  # a new run's stats, before its first strip
    assert again["link"]["text"] == "shots arriving" and again["state"] == "live"
    frames.add_strip(strip_header("run-2", 0, 0, 4, 16), lines)
    frames.publisher_quiet(5.0)  # no end, no message: the last stats no longer holds
    quiet = status()
    assert quiet["link"]["text"] == "not known: no message from the publisher", quiet
    assert quiet["state"] == "no message for 5 s: publisher silent"
    frames.add_status("stats", {"stream_id": "run-2", "link": None, "counters": {}}, {})
    back = status()  # stats again (a source that sends no shot still has its stats told)
    assert back["state"] == "live" and back["link"]["text"] == "shots arriving", back


def test_a_silent_source_is_red_and_its_counters_in_words():
    counters = {"link_silences": 2, "link_silent_ms": 3500, "reconnects": 1}
    status = status_after(
        ("stats", {"link": {"silent_s": 2.5, "since_pulse": 4799}, "counters": counters})
    )
    assert status["link"] == {
        "text": "SILENT for 2.5 s since pulse 4799; silent 2 time(s), 3.5 s in all; "
        "reconnected 1 time(s)",
        "alarm": True,
    }
    assert status["lost"] == [] and status["noted"] == []


def test_the_server_keeps_stream_ended_through_the_silence_after_it(monkeypatch):
    """The page read "no message for 5 s: publisher silent" and "shots arriving" 5 s after
    the publisher's end message."""
    monkeypatch.setattr(server_module, "SILENCE_S", 0.3)
    endpoint = f"tcp://127.0.0.1:{free_port()}"

    async def scenario():
        view = ViewServer(endpoint, port=0, say=lambda line: None)
        await view.start()
        pub = ZmqPublisher(endpoint, linger_ms=0)
        try:
            deadline = time.monotonic() + 20
            seq = 0
            while view.frames.strips == 0:  # until the subscription has reached the publisher
                assert time.monotonic() < deadline, "no strip reached the viewer"
                lines = np.ones((4, 16), np.complex64)
                pub.send("strip", strip_header("run-1", seq, 4 * seq, 4, 16), lines)
                seq += 1
                await asyncio.sleep(0.05)
            pub.send("end", {"format": "rtsar-stats", "stream_id": "run-1", "link": None})
            while view.frames.snapshot_status()["state"] != "stream ended":
                assert time.monotonic() < deadline, view.frames.snapshot_status()
                await asyncio.sleep(0.01)
            while True:  # until the viewer has heard nothing for 0.3 s, or the state changed
                status = view.frames.snapshot_status()
                if status.get("publisher_quiet") or status["state"] != "stream ended":
                    return status
                assert time.monotonic() < deadline, status
                await asyncio.sleep(0.05)
        finally:
            pub.close()
            await view.stop()

    status = asyncio.run(scenario())
    assert status["state"] == "stream ended"
    assert status["link"]["text"] == "the stream ended: no more shots"


def test_the_page_has_an_icon_drawn_here():
    """A browser asks for /favicon.ico: it got a 404 (an error in its console)."""
    from PIL import Image

    async def scenario():
        view = ViewServer(f"tcp://127.0.0.1:{free_port()}", port=0, token="t" * 20)
        url = await view.start()
        base = url.split("?")[0]
        try:
            async with aiohttp.ClientSession() as session:
                async with session.get(url) as page:
                    html = await page.text()
                async with session.get(base + "favicon.ico") as icon:  # no token needed
                    return html, icon.status, icon.content_type, await icon.read()
        finally:
            await view.stop()

    html, status, kind, body = asyncio.run(scenario())
    assert '<link rel="icon" type="image/png" href="favicon.ico">' in html
    assert status == 200 and kind == "image/png"
    image = Image.open(io.BytesIO(body))
    assert image.size == (16, 16) and image.mode == "L"
    grey = np.asarray(image)
    assert grey.max() == 255 and grey.min() < 64  # a bright point on darker rows
