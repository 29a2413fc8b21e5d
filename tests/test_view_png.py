"""``rtsar view --png``: Ctrl-C or a signal ends it with the signal's exit status (130 for
Ctrl-C), like every other command, keeping the lines that arrived (issue 37, item 6)."""

import signal
import subprocess
import sys

import numpy as np
import pytest
from conftest import free_port
from test_webview import strip_header

from rtsar.app import signals
from rtsar.app.view import Waterfall, _snapshot
from rtsar.sinks.wire import Message


def interrupt_view(args: list[str], ready) -> tuple[int, list[str], str]:
    """Start `rtsar view ARGS`, read stderr lines until ``ready(line)``, send Ctrl-C (SIGINT):
    (exit status, the lines read, the rest of stderr)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "rtsar", "view", *args], stderr=subprocess.PIPE, text=True
    )
    lines: list[str] = []
    try:
        while not (lines and ready(lines[-1])):
            line = proc.stderr.readline()
            assert line, "".join(lines)  # it ended before it was ready
            lines.append(line)
        proc.send_signal(signal.SIGINT)
        rest = proc.communicate(timeout=30)[1]
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return proc.returncode, lines, rest


def test_ctrl_c_before_any_line_exits_130_in_one_line(tmp_path):
    png = tmp_path / "v.png"
    endpoint = f"tcp://127.0.0.1:{free_port()}"  # no publisher: it waits
    status, lines, rest = interrupt_view([endpoint, "--png", str(png)], lambda line: True)
    assert lines[0].startswith("view: waiting for"), lines[0]
    assert status == 130, rest
    assert rest.splitlines() == [
        "view: interrupted",
        "view: no lines received; no snapshot written",
    ]
    assert not png.exists()


class Interrupted:
    """A subscriber that delivers ``strips`` then is interrupted by ``exc``."""

    endpoint = "tcp://test:1"
    counters = {"missed_strips": 0}

    def __init__(self, strips, exc):
        self.strips, self.exc = list(strips), exc

    def recv(self, timeout_s):
        if self.strips:
            return self.strips.pop(0)
        raise self.exc


@pytest.mark.parametrize(
    "exc, status", [(KeyboardInterrupt(), 130), (signals.Terminated(signal.SIGTERM), 143)]
)
def test_a_stopped_snapshot_holds_the_lines_that_arrived_and_exits_with_the_signal(
    tmp_path, exc, status
):
    lines = np.ones((16, 32), np.complex64)
    strips = [Message("strip", strip_header("s", k, 16 * k, 16, 32), lines) for k in range(3)]
    said = []

    class Stream:
        def write(self, text):
            said.append(text)

    png = tmp_path / "v.png"
    assert _snapshot(Interrupted(strips, exc), Waterfall(1024), str(png), 50.0, 5, Stream()) == (
        status
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"wrote {png}: 48 lines" in "".join(said)


def test_the_page_server_stopped_by_ctrl_c_exits_130(tmp_path):
    """`view --http` too: Ctrl-C is 130, as every command (it said 0)."""
    endpoint = f"tcp://127.0.0.1:{free_port()}"  # no publisher needed to serve the page
    serving = lambda line: "http://" in line  # noqa: E731 - the page's URL is told
    status, _, rest = interrupt_view([endpoint, "--http", "127.0.0.1:0"], serving)
    assert status == 130, rest
    assert "view: interrupted" in rest


def test_the_waterfall_keeps_the_last_lines_in_order_whatever_the_strips(rng):
    """The waterfall is a ring (each strip once rolled the whole buffer: the demo's snapshot
    fell behind, lost the stream's end and waited out its timeout): its image and positions
    are the last `lines` lines received, oldest first, for strips of any size."""
    fall, got = Waterfall(50), []
    first = 0
    for n in [3, 7, 1, 40, 2, 64, 5, 11, 50, 9]:  # some longer than the waterfall
        lines = (rng.standard_normal((n, 6)) + 1j).astype(np.complex64)
        fall.add(strip_header("s", 0, first, n, 6), lines)
        got.extend(lines)
        first += n
        k = min(len(got), 50)
        assert fall.filled == k
        np.testing.assert_array_equal(fall.image[-k:], np.array(got[-k:]))
        np.testing.assert_array_equal(fall.azimuth_m[-k:], 10.0 + 0.5 * np.arange(first - k, first))
        assert np.isnan(fall.azimuth_m[: 50 - k]).all()


def test_a_snapshot_says_the_strips_it_missed(tmp_path):
    lines = np.ones((16, 32), np.complex64)
    strips = [Message("strip", strip_header("s", k, 16 * k, 16, 32), lines) for k in (0, 1, 4)]
    said = []

    class Stream:
        def write(self, text):
            said.append(text)

    class Gappy(Interrupted):
        counters = {"missed_strips": 2}  # (seq 2 and 3: the subscriber counts them)

    png = tmp_path / "v.png"
    assert (
        _snapshot(Gappy(strips, KeyboardInterrupt()), Waterfall(1024), str(png), 50.0, 5, Stream())
        == 130
    )
    assert f"wrote {png}: 48 lines (2 strips missed" in "".join(said)
