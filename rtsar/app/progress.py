"""Progress of long work on stderr: in place on a terminal, a line every few seconds in logs.

The rate and the ETA are measured from the first update on: the first batch can carry what
only a first batch costs (a kernel numba compiles on first use, a file opened, an FFT planned;
``rtsar simulate demo`` on a busy machine printed ``eta 124.6 s`` from a first batch that held
the simulator's compilation), so its line is not printed and its time is not extrapolated.
"""

from __future__ import annotations

import shutil
import sys
import time


class Progress:
    def __init__(
        self, total: int, label: str, unit: str = "pulses", stream=None, every_s: float = 5.0
    ):
        self.total, self.label, self.unit = max(1, int(total)), label, unit
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.every_s = 0.2 if self.tty else every_s
        self.t0 = time.perf_counter()
        self._first: tuple[int, float] | None = None  # (done, time) at the first update
        self._last = -1e9

    def update(self, done: int, extra: str = "", *, final: bool = False) -> None:
        now = time.perf_counter()
        if self._last == float("inf"):
            return
        last = final or done >= self.total
        if self._first is None and not last:
            self._first = (done, now)  # the rate is measured from here on
            return
        if now - self._last < self.every_s and not last:
            return
        self._last = now
        since, t_since = self._first if self._first is not None else (0, self.t0)
        if done <= since:  # nothing measured after the first batch: the whole run's rate
            since, t_since = 0, self.t0
        rate = (done - since) / max(now - t_since, 1e-9)
        eta = (self.total - done) / rate if rate > 0 else float("inf")
        msg = (
            f"{self.label}: {done}/{self.total} {self.unit} ({100 * done / self.total:5.1f} %), "
            f"{rate:,.{1 if rate < 10 else 0}f} {self.unit}/s, eta {eta:5.1f} s {extra}"
        )
        self.stream.write(terminal_line(msg) if self.tty else (msg + "\n"))
        self.stream.flush()
        if done >= self.total and not self.tty:
            self._last = float("inf")  # the final line is printed once

    def done(self, done: int, extra: str = "") -> None:
        if self._last != float("inf"):  # in logs update() may have printed the final line
            self.update(done, extra, final=True)
        if self.tty:
            self.stream.write("\n")


def terminal_line(text: str) -> str:
    """``text`` redrawn over the terminal's current line: cut to its width (a longer line wraps,
    and each redraw left a fragment above: a new user's 80 columns held 123-126 characters)
    and the rest of the line cleared."""
    width = shutil.get_terminal_size().columns
    return "\r" + text[: max(width - 1, 20)] + "\x1b[K"
