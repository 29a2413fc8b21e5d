"""SIGTERM and SIGHUP end a command like Ctrl-C: what arrived is finished and files are closed.

The handlers raise :class:`Terminated` (a KeyboardInterrupt) in the main thread, so every
command's Ctrl-C path serves the other signals too; the exit status is 128 + the signal number
(130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP).

An OpenCL driver built on LLVM (PoCL, Intel's CPU runtime) puts its own handler on SIGINT and
SIGTERM when it loads, one the system resets to the default as it runs (``SA_RESETHAND``, not
blocking a second signal) before the handler hands the signal on and puts the previous one
back: a second signal within that moment killed ``rtsar run`` outright, nothing said, nothing
closed (3 runs in 70 of ``timeout -s INT``, which signals the process and then its group).
:func:`reclaim` puts rtsar's handlers back once the drivers are loaded, before the work that
a signal ends (the live run's stream, the block loops).

Inside :func:`deferred` (the block loops of simulate and process) a signal only sets a flag that
:func:`check` raises at the loop's next step: an exception raised at an arbitrary point could
land in a finalizer, where Python drops it ("Exception ignored …": a kill test saw simulate
finish and replace the old file after Ctrl-C or SIGTERM, 7 times in 40), or inside a numba
call (a SystemError traceback).  A second signal before that step is raised at once.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_installed = False  # install() has run in this process (reclaim() then puts it back)
_deferring = 0  # depth of deferred() blocks
_holding = 0  # depth of held() blocks
_pending: int | None = None  # a signal received inside one, not yet raised


class Terminated(KeyboardInterrupt):
    """A termination signal, raised where Ctrl-C would be."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _exception(signum: int) -> KeyboardInterrupt:
    return KeyboardInterrupt() if signum == signal.SIGINT else Terminated(signum)


def _raise(signum, frame):
    global _pending
    if _holding:  # held whole: the first kept for the end of the block, the rest with it
        _pending = signum if _pending is None else _pending
        return
    if _deferring and _pending is None:
        _pending = signum
        return
    _pending = None
    raise _exception(signum)


def install() -> None:
    """Route SIGINT, SIGTERM and SIGHUP through :func:`_raise` (main thread only; elsewhere a
    no-op): KeyboardInterrupt for Ctrl-C, :class:`Terminated` for the others."""
    global _installed
    if threading.current_thread() is not threading.main_thread():
        return
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        if hasattr(signal, name):
            signal.signal(getattr(signal, name), _raise)
    _installed = True


def reclaim() -> None:
    """rtsar's handlers put back where :func:`install` had put them (module docstring: an
    OpenCL driver's may have taken their place); nothing where it had not."""
    if _installed:
        install()


@contextmanager
def deferred() -> Iterator[None]:
    """Signals inside the block wait for :func:`check` (module docstring); one still waiting at
    the block's end is raised there."""
    global _deferring
    reclaim()  # (the lens is built by now: a driver's handlers go)
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
    check()


@contextmanager
def held() -> Iterator[None]:
    """As :func:`deferred`, a second signal too: a short step that must not stop half done (a
    pipeline's threads started: one left unstarted, the run's end would not wait for it)."""
    global _holding
    reclaim()
    _holding += 1
    try:
        yield
    finally:
        _holding -= 1
    check()


def check() -> None:
    """Raise the signal that arrived inside :func:`deferred`, if any."""
    global _pending
    if _pending is not None:
        signum, _pending = _pending, None
        raise _exception(signum)


def describe(exc: BaseException) -> str:
    signum = getattr(exc, "signum", None)
    return "interrupted" if signum is None else f"stopped by {signal.Signals(signum).name}"


def exit_status(exc: BaseException) -> int:
    """128 + the signal number (130 for Ctrl-C)."""
    return 128 + int(getattr(exc, "signum", signal.SIGINT))
