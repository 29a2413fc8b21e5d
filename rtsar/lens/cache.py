"""Measurements kept between runs: one JSON file per kind, in the user's cache folder.

The folder is ``$RTSAR_CACHE_DIR``, else ``$XDG_CACHE_HOME/rtsar``, else ``~/.cache/rtsar``.
Files are replaced atomically, so concurrent processes never read half a file; a file that
cannot be read (missing, damaged, another version's) counts as empty and is measured again.
``measuring`` lets one process at a time measure a kind (two surveys timed at once slowed each
other, and the one kept last was the contended one).
"""

from __future__ import annotations

import json
import math
import os
from contextlib import contextmanager
from pathlib import Path

try:
    import fcntl
except ImportError:  # not POSIX: measurements are not serialised between processes
    fcntl = None

__all__ = ["cache_dir", "measuring", "rates_or_none", "read_json", "write_json"]


def cache_dir() -> Path:
    """The folder of rtsar's cached measurements (not created here)."""
    own = os.environ.get("RTSAR_CACHE_DIR", "").strip()
    if own:
        return Path(own)
    xdg = os.environ.get("XDG_CACHE_HOME", "").strip()
    return (Path(xdg) if xdg else Path.home() / ".cache") / "rtsar"


def read_json(name: str) -> dict:
    """The cached object ``name`` (a file name), or {} when there is none to trust."""
    try:
        data = json.loads((cache_dir() / name).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def write_json(name: str, data: dict) -> Path | None:
    """Replace the cached object ``name``; None (nothing kept) where the folder is not writable."""
    folder = cache_dir()
    path = folder / name
    tmp = folder / f".{name}.{os.getpid()}.tmp"
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tmp.write_text(json.dumps(data, indent=1, sort_keys=True), encoding="utf-8")
        os.replace(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)
        return None
    return path


@contextmanager
def measuring(name: str, on_wait=None):
    """Hold the machine-wide lock of the cached object ``name`` while measuring it: a process
    that finds it held calls ``on_wait()`` once and waits (then reads what the other kept).
    No lock where the folder cannot be written or the system has no flock."""
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle = open(folder / f".{name}.lock", "a")  # noqa: SIM115 - held across the yield
    except OSError:
        handle = None
    if handle is None or fcntl is None:
        yield
        return
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if on_wait is not None:
                on_wait()
            fcntl.flock(handle, fcntl.LOCK_EX)
        yield
    finally:
        handle.close()  # releases the lock


def rates_or_none(found, sizes=None) -> dict[int, float] | None:
    """``{batch: pulses/s}`` from a cached ``found``, or None where it cannot be trusted.

    A cache is advice: an entry that is not a mapping of batch sizes to finite, positive
    rates (a damaged file, a hand edit, NaN from a failed timing), or that lacks one of the
    batch ``sizes`` asked for, is measured again rather than believed.
    """
    if not isinstance(found, dict) or not found:
        return None
    rates = {}
    for batch, rate in found.items():
        try:
            b, r = int(batch), float(rate)
        except (TypeError, ValueError, OverflowError):
            return None
        if b <= 0 or not math.isfinite(r) or r <= 0.0:
            return None
        rates[b] = r
    if sizes is not None and not set(int(b) for b in sizes) <= set(rates):
        return None
    return rates
