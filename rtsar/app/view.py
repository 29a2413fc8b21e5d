"""``rtsar view``: the newest published lines as a live waterfall, or a PNG snapshot."""

from __future__ import annotations

import sys

import numpy as np

from ..sinks.client import StripSubscriber
from . import signals
from .quicklook import save_quicklook, to_db


class Waterfall:
    """The last ``lines`` image lines, newest at the bottom, in dB re the running peak.

    A ring: a strip's lines are written where the oldest were, and ``image`` / ``azimuth_m``
    put them in order when read.  (Each strip rolled the whole buffer: 21 MB for the demo's
    8192 × 320 lines, so at its 500 strips/s a snapshot fell behind, the publisher dropped the
    strips after, the `end` among them, and `view --png` waited out its timeout.)"""

    def __init__(self, lines: int):
        self.lines = int(lines)
        self._ring: np.ndarray | None = None
        self._az = np.full(self.lines, np.nan)
        self.range_m: np.ndarray | None = None
        self.filled = 0
        self._next = 0  # the ring's row the next line goes to

    def add(self, header: dict, lines: np.ndarray) -> None:
        nr = lines.shape[1]
        if self._ring is None or self._ring.shape[1] != nr:
            self._ring = np.zeros((self.lines, nr), np.complex64)
            self._az = np.full(self.lines, np.nan)
            self.range_m = header["range_first_m"] + header["range_step_m"] * np.arange(nr)
            self.filled, self._next = 0, 0
        k = min(len(lines), self.lines)
        az = header["azimuth_first_m"] + header["azimuth_step_m"] * np.arange(len(lines))
        rows = (self._next + np.arange(k)) % self.lines
        self._ring[rows] = lines[-k:]
        self._az[rows] = az[-k:]
        self._next = (self._next + k) % self.lines
        self.filled = min(self.lines, self.filled + k)

    def _ordered(self, a: np.ndarray) -> np.ndarray:
        return np.roll(a, -self._next, axis=0)

    @property
    def image(self) -> np.ndarray | None:
        """[lines, range bins], oldest first (zeros before the first line)."""
        return None if self._ring is None else self._ordered(self._ring)

    @property
    def azimuth_m(self) -> np.ndarray:
        """The lines' along-track positions, as ``image`` (NaN before the first line)."""
        return self._ordered(self._az)


def view(
    endpoint: str,
    png: str | None = None,
    lines: int = 1024,
    dynamic_range_db: float = 50.0,
    curve_server_key=None,
    timeout_s: float = 30.0,
    stream=None,
    curve_client_key=None,
    true_aspect: bool = False,
) -> int:
    """Live waterfall window, or with ``png`` a snapshot once ``lines`` lines have arrived
    (``true_aspect``: equal metres on both axes, see save_quicklook).  A snapshot stopped by
    Ctrl-C or a signal holds the lines that arrived, and the exit status is the signal's
    (rtsar.app.signals: 130 for Ctrl-C), as for every command."""
    stream = stream or sys.stderr
    sub = StripSubscriber(endpoint, curve_server_key, curve_client_key, hwm_messages=64)
    fall = Waterfall(lines)
    try:
        if png:
            return _snapshot(sub, fall, png, dynamic_range_db, timeout_s, stream, true_aspect)
        return _window(sub, fall, dynamic_range_db, stream)
    finally:
        sub.close()


def _snapshot(sub, fall, png, dynamic_range_db, timeout_s, stream, true_aspect=False) -> int:
    interrupted = None
    try:  # the line said inside: a Ctrl-C right after it is this block's
        print(f"view: waiting for {fall.lines} lines from {sub.endpoint} …", file=stream)
        while fall.filled < fall.lines:
            msg = sub.recv(timeout_s)
            if msg is None:
                print(f"view: no message for {timeout_s:g} s", file=stream)
                break
            if msg.topic == "strip":
                fall.add(msg.header, msg.lines)
            elif msg.topic == "end":
                break
    except KeyboardInterrupt as exc:
        interrupted = exc
        print(f"view: {signals.describe(exc)}", file=stream)
    if fall.filled == 0:
        print("view: no lines received; no snapshot written", file=stream)
        return 1 if interrupted is None else signals.exit_status(interrupted)
    k = fall.filled
    missed = sub.counters["missed_strips"]
    gaps = f", missed strips {missed}" if missed else ""
    save_quicklook(
        png,
        fall.image[-k:],
        fall.azimuth_m[-k:],
        fall.range_m,
        dynamic_range_db,
        title=f"{sub.endpoint}: last {k} lines{gaps}",
        true_aspect=true_aspect,
    )
    said = f" ({missed} strips missed: published while this view could not take them)"
    print(f"wrote {png}: {k} lines{said if missed else ''}", file=stream)
    return 0 if interrupted is None else signals.exit_status(interrupted)


def _window(sub, fall, dynamic_range_db, stream) -> int:
    import matplotlib
    import matplotlib.pyplot as plt

    if matplotlib.get_backend().lower() in ("agg", "pdf", "svg", "ps", "cairo", "template"):
        raise RuntimeError(
            f"no interactive display for matplotlib (backend {matplotlib.get_backend()}); "
            "use `rtsar view ENDPOINT --png FILE` for a snapshot"
        )
    fig, ax = plt.subplots(figsize=(9, 7))
    art = None
    print(f"view: {sub.endpoint} (close the window or Ctrl-C to stop)", file=stream)
    try:
        while plt.fignum_exists(fig.number):
            msg = sub.recv(0.05)
            if msg is not None and msg.topic == "strip":
                fall.add(msg.header, msg.lines)
                while (m := sub.recv(0)) is not None:  # catch up: draw only the newest state
                    if m.topic == "strip":
                        fall.add(m.header, m.lines)
            if fall.filled:
                db = to_db(fall.image, dynamic_range_db)
                if art is None:
                    rm = fall.range_m
                    art = ax.imshow(
                        db,
                        cmap="gray",
                        vmin=-dynamic_range_db,
                        vmax=0,
                        aspect="auto",
                        interpolation="nearest",
                        extent=[rm[0], rm[-1], fall.lines, 0],
                    )
                    ax.set_xlabel("slant range [m]")
                    ax.set_ylabel("lines ago")
                    fig.colorbar(art, ax=ax, label="dB re peak")
                else:
                    art.set_data(db)
                valid = fall.azimuth_m[~np.isnan(fall.azimuth_m)]
                ax.set_title(
                    f"along track {valid[0]:.1f} … {valid[-1]:.1f} m; "
                    f"missed strips {sub.counters['missed_strips']}"
                )
            plt.pause(0.05)
    except KeyboardInterrupt as exc:  # the window closed by Ctrl-C: 130, as every command
        return signals.exit_status(exc)
    return 0
