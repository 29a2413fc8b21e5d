"""A live writer's claim on its output name, held for the whole run (rtsar.sinks.image_file).

A live image file takes its name with its first lines and grows under it; two live writers of
one name would each rename their file over the other's, and one run's lines would end in no
file.  The claim is an empty hidden file beside the output, named like the writer's temporaries
(rtsar.sinks.partials.partial_prefix), under an exclusive ``flock`` that the system drops when the
process dies, however it dies: a claim whose lock is held refuses the name to another writer,
one left unlocked by a dead writer is removed by the next.

A crash-safe file's last step closes it and opens it again for its final attributes
(rtsar.sinks.live_file); a reader that opens it meanwhile can read them half written (h5py:
"bad version number for attribute message", seen within a second of killing ``rtsar run``: the
recorder process finishing the recording).  The writer says so in its claim (``finishing``),
and a reader waits for the claim's release before it opens the file (``wait_while_finishing``).
"""

from __future__ import annotations

import fcntl
import glob
import os
import time
from pathlib import Path

from .partials import partial_prefix, remove_stale_partials

FINISHING = b"finishing"  # the claim's content while its writer writes the final attributes


class NameClaim:
    """This process's claim on ``path`` (module docstring): the file ``.NAME.partial-
    OWNER-writing``, empty (FINISHING once its writer finishes), locked until
    :meth:`release`.  ValueError when another running process holds a claim on the name.
    Temporaries of the name that killed writers left are removed first
    (rtsar.sinks.partials.remove_stale_partials)."""

    def __init__(self, path: str | Path):
        path = Path(path)
        remove_stale_partials(path)
        self.path = path.with_name(partial_prefix(path) + "writing")
        self._fd = None
        try:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise ValueError(f"cannot write {path}: {exc.strerror or exc}") from None
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:  # our own mark, locked: this process writes the name already
            os.close(self._fd)
            self._fd = None
            raise ValueError(f"cannot write {path}: this process is writing it already") from None
        except OSError:  # a file system without locks: the marks alone tell (as in _held)
            pass
        # Made first, then compared: of two writers starting together, at least one sees the
        # other (often both do, and both refuse; never do both go on).
        refusal = _refusal(path, mine=self.path)
        if refusal:
            self.release()
            raise ValueError(refusal)

    @classmethod
    def adopted(cls, mark: str | Path, fd: int) -> NameClaim:
        """The claim another process of the run took (``mark``, its locked ``fd`` passed on:
        the recorder process of ``run --record``); the lock holds while either keeps it."""
        claim = cls.__new__(cls)
        claim.path, claim._fd = Path(mark), fd
        return claim

    @property
    def fd(self) -> int | None:
        """The locked descriptor (None once released)."""
        return self._fd

    def finishing(self) -> None:
        """The writer's last step begins (module docstring): readers wait for the release."""
        if self._fd is not None:
            try:
                os.pwrite(self._fd, FINISHING, 0)
            except OSError:  # (readers then open as they would have)
                pass

    def release(self) -> None:
        if self._fd is not None:
            self.path.unlink(missing_ok=True)
            os.close(self._fd)  # the lock goes with it
            self._fd = None


def check_unclaimed(path: str | Path) -> None:
    """ValueError, before any work, when another running rtsar process holds a claim on
    ``path`` (it is writing it live): every writer of a file asks, so that none replaces a file
    being written (rtsar.app.cli.outputs.check_outputs_spare_inputs)."""
    refusal = _refusal(Path(path))
    if refusal:
        raise ValueError(refusal)


def wait_while_finishing(path: str | Path, most_s: float, poll_s: float = 0.02) -> float:
    """Seconds waited, at most ``most_s``, while another process's claim on ``path`` says it is
    finishing the file (module docstring); 0 where none is.  A reader's look changes nothing:
    it needs no write access (another account's reader waits too) and removes no mark; a mark
    it cannot lock (a file system without locks) is not waited for, as nothing would end it."""
    start = time.monotonic()
    while time.monotonic() - start < most_s and is_finishing(path):
        time.sleep(poll_s)
    return time.monotonic() - start


def is_finishing(path: str | Path) -> bool:
    """Whether another process's claim on ``path`` says it is finishing the file now."""
    path = Path(path)
    prefix, mine = f".{path.name}.partial-", partial_prefix(path)
    marks = path.parent.glob(glob.escape(prefix) + "*-writing")
    return any(_finishing(m) for m in marks if not m.name.startswith(mine))


def _finishing(mark: Path) -> bool:
    """A running writer holds ``mark`` and it says FINISHING (read only; never removed)."""
    try:
        fd = os.open(mark, os.O_RDONLY)
    except OSError:  # removed meanwhile (released), or not ours to read
        return False
    try:
        if os.pread(fd, len(FINISHING), 0) != FINISHING:
            return False
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)  # taken: no writer holds it
    except BlockingIOError:
        return True
    except OSError:  # no locks here: a dead writer's mark would be waited for every time
        return False
    finally:
        os.close(fd)
    return False


def _refusal(path: Path, mine: Path | None = None) -> str | None:
    """Why ``path`` may not be written: another running process's claim on it (``mine``: this
    process's own mark, not counted); None when no other holds one."""
    start = f".{path.name}.partial-"
    for other in sorted(path.parent.glob(glob.escape(start) + "*-writing")):
        if other != mine and _held(other):
            host, _, pid = other.name[len(start) : -len("-writing")].rpartition(".")
            return (
                f"cannot write {path}: another rtsar process (pid {pid} on "
                f"{host.split('@')[0]}) is writing it now; give another name"
            )
    return None


def _held(mark: Path) -> bool:
    """Whether a running process holds ``mark``'s lock; an unheld mark is removed."""
    try:
        fd = os.open(mark, os.O_RDWR)
    except OSError:  # removed meanwhile, or not ours to open: not in the way
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    except OSError:  # a file system without locks: trust the mark
        return True
    finally:
        os.close(fd)
    mark.unlink(missing_ok=True)  # its writer is gone
    return False
