"""SIGTERM and SIGHUP end a command like Ctrl-C: what arrived is finished and files are closed.

The handlers raise :class:`Terminated` (a KeyboardInterrupt) in the main thread, so every
command's Ctrl-C path serves the other signals too; the exit status is 128 + the signal number
(130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP).
"""

from __future__ import annotations

import signal
import threading


class Terminated(KeyboardInterrupt):
    """A termination signal, raised where Ctrl-C would be."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raise(signum, frame):
    raise Terminated(signum)


def install() -> None:
    """Route SIGTERM and SIGHUP to :class:`Terminated` (main thread only; elsewhere a no-op)."""
    if threading.current_thread() is not threading.main_thread():
        return
    for name in ("SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _raise)


def describe(exc: BaseException) -> str:
    signum = getattr(exc, "signum", None)
    return "interrupted" if signum is None else f"stopped by {signal.Signals(signum).name}"


def exit_status(exc: BaseException) -> int:
    """128 + the signal number (130 for Ctrl-C)."""
    return 128 + int(getattr(exc, "signum", signal.SIGINT))
