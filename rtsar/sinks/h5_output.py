"""HDF5 files being written, whose failed writes (a full disk, a quota, an I/O error) end in one
error line instead of a crash.

Why a plain ``h5py.File(path, "w")`` crashes there: HDF5 keeps the chunks of a dataset in a cache
(h5py: 8 MiB a dataset) and writes them when the dataset is closed.  When that write fails,
HDF5's dataset close (H5D_close) frees the dataset anyway and reports the failure, and the ID
keeps pointing at the freed memory; the next close of that ID (h5py's garbage collection, or
HDF5's own clean-up at interpreter exit) reads freed memory: a segmentation fault (h5py issues
914, 2160).  A failed close of the *file* is different: HDF5 >= 1.14 keeps the file object until
a close succeeds, so trying again is harmless.

So :func:`create` opens files without a raw-data chunk cache and without a sieve buffer (the
contiguous datasets' cache): every data write goes to the disk at once, fails there (where it
can be reported) and leaves nothing for a dataset's close to write; only the file's metadata is
written at its close.  :class:`H5Output` closes a file that failed exactly once (h5py's
``File.close``: its datasets first, which have nothing left to write, then the file), that
close's own error ignored, and turns the error into :class:`WriteFailed`: ``cannot write PATH:
No space left on device``.  Closing it any other way (letting the garbage collector close the
datasets after the file) can still fail inside a dataset's close: the last object of a file
closes the file.
"""

from __future__ import annotations

import errno
import os
import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import h5py

# Errors only a write gets (a full disk, a quota, a file size limit, a read-only disk); EIO is
# left out: a failing read of the input says it too.
WRITE_ERRNOS = {
    getattr(errno, name) for name in ("ENOSPC", "EDQUOT", "EFBIG", "EROFS") if hasattr(errno, name)
}


class WriteFailed(ValueError):
    """An output could not be written: ``cannot write PATH: REASON`` (one line; the CLI prints
    it as ``rtsar: error: …``, exit status 2 as for an unwritable folder)."""

    def __init__(self, path: str | Path, reason: str, kept: str = ""):
        self.path = Path(path)
        self.reason = reason
        self.kept = kept
        super().__init__(f"cannot write {path}: {reason}" + (f"; {kept}" if kept else ""))

    def naming(self, path: str | Path, kept: str | None = None) -> WriteFailed:
        """The same failure told of ``path`` (a temporary's final name)."""
        return WriteFailed(path, self.reason, self.kept if kept is None else kept)


def reason(exc: BaseException) -> str:
    """The operating system's words for a failed write ("No space left on device").  h5py puts
    the errno in an OSError's ``errno`` or, for a RuntimeError, only in the message."""
    code = getattr(exc, "errno", None)
    if not code:
        found = re.search(r"errno = (\d+)", str(exc))
        code = int(found.group(1)) if found else None
    if code:
        return os.strerror(code)
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def is_write_error(exc: BaseException) -> bool:
    """An OSError that only a write gets (ENOSPC, EDQUOT, EFBIG, EROFS)."""
    return isinstance(exc, OSError) and exc.errno in WRITE_ERRNOS


_LIBVER = {
    "earliest": h5py.h5f.LIBVER_EARLIEST,
    "v110": h5py.h5f.LIBVER_V110,
    "latest": h5py.h5f.LIBVER_LATEST,
}


def create(path: str | Path, mode: str = "w", libver=None, swmr: bool = False) -> h5py.File:
    """``h5py.File(path, mode, libver=libver)`` with no raw-data chunk cache and no sieve
    buffer (see the module's docstring): a failed write fails at the write, and closing a
    dataset writes nothing.  The datasets' chunks should be as long as the usual write.
    ``swmr`` with ``mode="r+"``: opened in HDF5's single-writer/multiple-reader mode (a writer
    that dies leaves a file SWMR readers open), without HDF5's file lock: the file is this
    process's own, being finished, and SWMR readers following it hold a shared lock that the
    writer's exclusive one would wait on and fail ("Resource temporarily unavailable")."""
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    if swmr and mode == "r+":
        fapl.set_file_locking(False, True)
    low, high = ("earliest", "latest") if libver is None else libver
    fapl.set_libver_bounds(_LIBVER[low], _LIBVER[high])
    mdc, slots, _, w0 = fapl.get_cache()
    fapl.set_cache(mdc, slots, 0, w0)
    fapl.set_sieve_buf_size(0)
    name = os.fsencode(path)
    if mode == "w":
        fid = h5py.h5f.create(name, h5py.h5f.ACC_TRUNC, fapl=fapl)
    elif mode == "r+":
        flags = h5py.h5f.ACC_RDWR | (h5py.h5f.ACC_SWMR_WRITE if swmr else 0)
        fid = h5py.h5f.open(name, flags, fapl=fapl)
    else:
        raise ValueError(f"mode must be 'w' or 'r+', got {mode!r}")
    return h5py.File(fid)


def make_room(path: str | Path, nbytes: int) -> None:
    """Allocate ``nbytes`` of disk past the end of ``path`` (zeros), so that an HDF5 file
    reopened there can grow by as much without asking the disk; HDF5 cuts the file back to what
    it uses when it closes it.  OSError when the disk refuses (full, quota, size limit)."""
    with open(path, "r+b") as fh:
        size = os.fstat(fh.fileno()).st_size
        try:
            os.posix_fallocate(fh.fileno(), size, nbytes)
        except AttributeError:  # no posix_fallocate (macOS): written zeros reserve it too
            fh.seek(size)
            fh.write(bytes(nbytes))


class H5Output:
    """An HDF5 file being written (:func:`create`); every operation on it goes through
    :meth:`writing`, which turns a failure into :class:`WriteFailed` after closing the file once.

    ``shown`` is the name errors give (the output's own name when ``path`` is a temporary one).
    After a failure, :meth:`writing` fails at once and :meth:`close` does nothing.
    """

    def __init__(self, path: str | Path, mode: str = "w", libver=None, shown=None, swmr=False):
        self.path = Path(path)
        self.shown = Path(shown or path)
        self.failed: WriteFailed | None = None
        self.closed_cleanly = False  # after a failure: whether the one close went through
        self._closed = False
        try:
            self.file = create(self.path, mode, libver, swmr)
        except (OSError, RuntimeError) as exc:
            self._closed = True
            self.failed = WriteFailed(self.shown, reason(exc))
            raise self.failed from None

    @property
    def open(self) -> bool:
        """Not closed yet (and not failed)."""
        return not self._closed

    @contextmanager
    def writing(self, tidy=None) -> Iterator[h5py.File]:
        """``with out.writing() as f:`` — HDF5 errors inside end the file (``tidy()`` first,
        its own errors ignored; then closed once) and raise :class:`WriteFailed`; other
        exceptions pass untouched."""
        if self.failed is not None:
            raise self.failed
        if self._closed:
            raise ValueError(f"{self.shown} is closed")
        try:
            yield self.file
        except (OSError, RuntimeError) as exc:
            self.failed = WriteFailed(self.shown, reason(exc))
            if tidy is not None and not self._closed:
                try:
                    tidy()
                except (OSError, RuntimeError, ValueError):
                    pass
            self._close_once()
            raise self.failed from None

    def close(self) -> None:
        """Close the file (its metadata is written now); nothing after a failure."""
        if self._closed:
            return
        with self.writing() as f:
            self._closed = True  # set first: a close that fails is never tried again
            f.close()
        self.closed_cleanly = True

    def _close_once(self) -> None:
        if self._closed:
            return
        self._closed = True
        try:
            self.file.close()
            self.closed_cleanly = True  # the metadata went to disk after all
        except (OSError, RuntimeError):  # the disk still refuses: the file stays as it is
            pass
