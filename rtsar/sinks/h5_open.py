"""Opening an HDF5 file to read, whatever state its writer left it in.

A complete file opens as it is.  A file a live stream is still writing (crash-safe SWMR mode,
rtsar.sinks.h5_output) refuses a plain open ("already open for write", or a lock) and opens in
SWMR mode.  A file shorter than its superblock says (HDF5's "truncated file") is either a
writer's whose disk filled or who was killed mid-flush (its metadata whole, its last rows
missing: rtsar.sinks.declared reads the rows it holds) or a copy cut short, whose metadata is
missing: opened in SWMR mode, such a file's first metadata read retries inside HDF5 for over
ten minutes, deaf to Ctrl-C and SIGTERM.  So a truncated file's metadata (every group and
dataset, their attributes and chunk indexes) is first read by a child process with a time
limit; where that does not finish, the file is refused in one line.  Anything else HDF5 cannot
open is "not an HDF5 file".  Every refusal is a ValueError naming the file.
"""

from __future__ import annotations

import ctypes
import re
import signal
import subprocess
import sys
from pathlib import Path

import h5py

from .name_claim import is_finishing, wait_while_finishing

# A finishing writer takes a few hundred ms (its final attributes); past this, the file opens
# as it is (a writer hung there: what it holds is read, or refused in one line).
FINISHING_WAIT_S = 10.0
PROBE_LIMIT_S = 15.0  # the child's reads take about 0.5 s (mostly Python's start), or for ever

_PROBE = """
import sys  # (built in: nothing read from this folder, which -c puts first on the path)
sys.path[:] = sys.argv[2].split("\\n")  # the caller's own path
import h5py
def walk(group):
    dict(group.attrs)
    for name in group:
        item = group[name]
        if isinstance(item, h5py.Group):
            walk(item)
            continue
        dict(item.attrs)
        if item.chunks is not None:  # the chunk index (metadata, checksummed), walked once
            item.id.chunk_iter(lambda info: None)
with h5py.File(sys.argv[1], "r", swmr=True) as f:
    walk(f)
"""


def open_for_reading(path: Path) -> h5py.File:
    """``path`` opened read-only (SWMR where a writer holds it or left it short); ValueError,
    one line, where it cannot be read.  A writer finishing the file (its final attributes:
    rtsar.sinks.name_claim) is waited for, at most FINISHING_WAIT_S, and where it began to
    while the file was opened, the file is opened again once it has finished."""
    wait_while_finishing(path, FINISHING_WAIT_S)
    f = _open(path)
    if is_finishing(path):
        f.close()
        wait_while_finishing(path, FINISHING_WAIT_S)
        f = _open(path)
    return f


def _open(path: Path) -> h5py.File:
    try:  # a damaged file: OSError, or RuntimeError where its superblock does not read
        return h5py.File(path, "r")
    except (OSError, RuntimeError) as exc:
        first = str(exc)
    cut = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", first)
    why = _unreadable_structure(path) if cut else None
    if why:
        held, whole = (int(n) for n in cut.groups())
        raise ValueError(f"{path}: truncated: it holds {held:,} of its {whole:,} bytes, {why}")
    if not (cut or re.search("already open for write|unable to lock file", first)):
        raise ValueError(f"{path}: not an HDF5 file ({first})")
    try:  # an image still being written by a live stream (crash-safe SWMR mode)
        return h5py.File(path, "r", swmr=True)
    except (OSError, RuntimeError):  # a writer died before it closed the file
        raise ValueError(
            f"{path}: its writer did not close it (killed?), and HDF5 refuses it until "
            f"`h5clear -s {path}` clears the writer's flag"
        ) from None


def _unreadable_structure(path: Path) -> str | None:
    """Why a child process could not read all of ``path``'s metadata in SWMR mode (None: it
    could).  The child imports from this process's own path (not the current folder's modules,
    which ``-c`` would put first; PYTHONPATH and user installs kept), dies with this process
    (Linux), and is killed after PROBE_LIMIT_S."""
    try:
        done = subprocess.run(
            [sys.executable, "-c", _PROBE, str(path), "\n".join(sys.path)],
            capture_output=True,
            text=True,
            timeout=PROBE_LIMIT_S,
            preexec_fn=_die_with_parent if sys.platform == "linux" else None,
        )
    except subprocess.TimeoutExpired:
        return (
            f"its structure cut off: its reads did not end in {PROBE_LIMIT_S:g} s (a copy or a "
            "download cut short?)"
        )
    if done.returncode == 0:
        return None
    said = (done.stderr.strip().splitlines() or ["no message"])[-1]
    return f"its structure unreadable ({said}; a copy or a download cut short?)"


def _die_with_parent() -> None:
    """In the child, before it runs: killed (SIGKILL) when its parent dies, even by SIGKILL,
    so that no probe spins on in HDF5's retries (Linux's PR_SET_PDEATHSIG)."""
    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG = 1
