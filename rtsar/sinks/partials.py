"""The hidden temporary names of outputs being written, and whose they are.

An output is written under ``.NAME.partial-HOST@NS.PID-…`` beside its final name (an output
complete only at its end, rtsar.sinks.io.replace_when_complete; a live file until its first
rows, rtsar.sinks.live_file; a live writer's claim on the name, rtsar.sinks.name_claim).  The
owner part says which host, PID namespace and process wrote it, so the temporaries a killed
writer left can be told from a running writer's and removed.
"""

from __future__ import annotations

import glob
import os
import socket
from pathlib import Path


def partial_prefix(path: Path) -> str:
    """Start of the hidden temporary name of an output of ``path`` written by this process:
    ``.NAME.partial-OWNER-`` with OWNER = HOST@NS.PID, the host, the PID namespace and the
    process (what tells :func:`remove_stale_partials` whose it is; no host name holds "@")."""
    return f".{path.name}.partial-{_owner_of_pid(os.getpid())}-"


def remove_stale_partials(path: str | Path) -> list[Path]:
    """Delete the temporary files of ``path`` left by writers that are no longer running (a
    SIGKILL, a power cut): those of this host and PID namespace whose process has ended;
    returns them.  Another host's (a shared folder), another container's (another PID
    namespace) and a running process's are kept: they may still become the file."""
    path = Path(path)
    start = f".{path.name}.partial-{_owner_of_pid(None)}"
    removed = []
    for stale in path.parent.glob(glob.escape(start) + "*"):
        pid = stale.name[len(start) :].split("-", 1)[0]
        if pid.isdigit() and not _running(int(pid)):
            try:
                stale.unlink()
            except FileNotFoundError:  # another run removed it first
                continue
            except OSError:  # not ours to delete: left as it was
                continue
            removed.append(stale)
    return removed


def _owner_of_pid(pid: int | None) -> str:
    """HOST@NS.PID (HOST@NS. for None): NS is this process's PID namespace (0 where unknown),
    so that a process of another container with the same host name never reads our PIDs."""
    host = socket.gethostname().replace("/", "_").replace("@", "_") or "host"
    try:
        ns = os.stat("/proc/self/ns/pid").st_ino
    except OSError:
        ns = 0
    return f"{host}@{ns}." + ("" if pid is None else str(pid))


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True
