"""Progress of long work on stderr: in place on a terminal, a line every few seconds in logs."""

from __future__ import annotations

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
        self._last = -1e9

    def update(self, done: int, extra: str = "") -> None:
        now = time.perf_counter()
        if self._last == float("inf"):
            return
        if now - self._last < self.every_s and done < self.total:
            return
        self._last = now
        rate = done / max(now - self.t0, 1e-9)
        eta = (self.total - done) / rate if rate > 0 else float("inf")
        msg = (
            f"{self.label}: {done}/{self.total} {self.unit} ({100 * done / self.total:5.1f} %), "
            f"{rate:,.{1 if rate < 10 else 0}f} {self.unit}/s, eta {eta:5.1f} s {extra}"
        )
        self.stream.write(("\r" + msg + "   ") if self.tty else (msg + "\n"))
        self.stream.flush()
        if done >= self.total and not self.tty:
            self._last = float("inf")  # the final line is printed once

    def done(self, done: int, extra: str = "") -> None:
        if self._last != float("inf"):  # in logs update() may have printed the final line
            self._last = -1e9
            self.update(done, extra)
        if self.tty:
            self.stream.write("\n")
