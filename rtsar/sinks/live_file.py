"""An HDF5 file written live that survives its writer's death (the image of ``run -o`` and
``subscribe -o``, the raw shots of ``run --record``).

``crash_safe=True``: the file is written in HDF5's single-writer/multiple-reader mode (SWMR) and
flushed at least every ``flush_every_s``: a writer killed at any moment (SIGKILL, an OOM kill, a
power cut after the disk has the data) leaves a file that opens, holding every row flushed
before the kill, with ``complete`` False.  The file is set up under a temporary name and takes
its own name once its first rows are flushed, so neither a half-made nor an empty file ever
carries the name (a writer killed before its first row leaves the earlier file there as it
was).  Readers can open it while it is written.  The name is claimed for the whole run
(rtsar.sinks.name_claim): a second live writer of it is refused.

A write the disk refuses (full, quota) ends the file (rtsar.sinks.h5_output): WriteFailed,
``cannot write PATH: No space left on device``, a crash-safe file keeping its rows (the message
says how many), readable, ``complete`` False.

Without ``crash_safe`` the file is a plain HDF5 file at ``path`` (a temporary name its owner
renames: rtsar.sinks.io.replace_when_complete).

The owner makes the datasets (``create(file)``, before SWMR mode: none can be added after),
writes rows inside :meth:`LiveFile.writing` and says how many rows are whole with
:meth:`LiveFile.stored`; ``tidy(rows)`` brings its datasets back to those rows after a failed
write.
"""

from __future__ import annotations

import os
import time
from contextlib import contextmanager
from pathlib import Path

from .h5_output import H5Output, WriteFailed, is_write_error, make_room, reason
from .name_claim import NameClaim
from .partials import partial_prefix

SWMR_LIBVER = ("v110", "v110")  # the oldest format SWMR writes: readers back to HDF5 1.10


class LiveFile:
    """One HDF5 output being written (module docstring).  ``unit``: what a row is, in the
    messages ("lines", "shots"); ``claim``: a claim on the name taken earlier (a recorder that
    claimed it when its run started), else one is taken here (crash-safe files)."""

    def __init__(
        self,
        path: str | Path,
        create,
        crash_safe: bool = True,
        claim: NameClaim | None = None,
        flush_every_s: float = 0.5,
        unit: str = "lines",
        tidy=None,
    ):
        self.path = Path(path)
        self.crash_safe = crash_safe
        self.flush_every_s = float(flush_every_s)
        self.unit = unit
        self._tidy = tidy
        self.rows = 0  # rows the owner has stored whole
        self.saved_rows = 0  # rows sure to be on disk (crash-safe: flushed)
        self.final = False  # crash-safe: the rows are closed, the final attributes follow
        self._dirty = False
        self._claim = claim
        if crash_safe and claim is None:
            self._claim = NameClaim(self.path)
        self._target = (
            self.path.with_name(partial_prefix(self.path) + "live") if crash_safe else self.path
        )
        self._out = None
        try:
            with self.reported():
                self._out = H5Output(
                    self._target, libver=SWMR_LIBVER if crash_safe else None, shown=self.path
                )
            self.file = self._out.file
            with self.writing():
                create(self.file)
                if crash_safe:
                    self.file.swmr_mode = True  # from here on the file on disk is readable
        except BaseException:  # (a WriteFailed has been told already: _failed)
            if self._out is not None and self._out.open:
                try:
                    self._out.close()
                except (OSError, RuntimeError, ValueError):  # the first error is the one told
                    pass
            if crash_safe and self._target != self.path:
                self._target.unlink(missing_ok=True)  # our temporary, no row in it
            self.release()
            raise
        self._flushed_s = time.monotonic()

    @property
    def open(self) -> bool:
        """Not closed, not failed."""
        return self._out.open

    @property
    def named(self) -> bool:
        """The file carries its own name (a crash-safe file: once its first rows are flushed)."""
        return self._target == self.path

    @contextmanager
    def writing(self):
        """HDF5 work on the file: a failure (a full disk) ends the file, WriteFailed."""
        with self.reported(), self._out.writing(tidy=self._trim) as f:
            yield f

    @contextmanager
    def reported(self):
        """A WriteFailed inside is told as :meth:`_failed` tells it (what stays of the file)."""
        try:
            yield
        except WriteFailed as exc:
            raise self._failed(exc) from None

    def _trim(self) -> None:
        if not self.final and self._tidy is not None:  # (final: the datasets were closed whole)
            self._tidy(self.rows)

    def release(self) -> None:
        """Remove this run's mark on the name (crash-safe files)."""
        if self._claim is not None:
            self._claim.release()
            self._claim = None

    def _failed(self, exc: WriteFailed) -> WriteFailed:
        """A crash-safe file that failed: still under its temporary name (no row flushed), it is
        removed and an earlier file of the name stays; else what was written stays, readable,
        marked incomplete, and the error says how many rows."""
        if not self.crash_safe:
            return exc  # a temporary name, removed by its owner (replace_when_complete)
        self.release()
        if self._target != self.path:
            self._target.unlink(missing_ok=True)
            return exc.naming(self.path, kept="")
        if self.final and not self._out.closed_cleanly:
            # Its rows are all on disk, but the reopening for the final attributes marked the
            # file as being written (HDF5's superblock flag, SWMR), and no close could clear it.
            return exc.naming(
                self.path,
                kept=f"its {self.rows} {self.unit} are saved, marked incomplete; rtsar and SWMR "
                f"readers open it, other HDF5 readers once `h5clear -s {self.path}` clears "
                "the writer's flag",
            )
        if self._out.closed_cleanly:  # every row written went to disk, and the metadata too
            self.saved_rows = self.rows
            saved = f"its {self.rows} {self.unit} are saved"
        else:  # the last flush's rows are readable (SWMR); later ones may be lost
            saved = f"at least its first {self.saved_rows} {self.unit} are saved"
        return exc.naming(self.path, kept=f"{saved}, marked incomplete (complete = False)")

    def stored(self, rows: int) -> None:
        """The owner's datasets now hold ``rows`` whole rows; a crash-safe file's first ones are
        flushed at once and the file takes its name."""
        self.rows = int(rows)
        self._dirty = True
        if self.crash_safe and not self.named and self.rows:
            self.flush()
            with self.writing():
                os.replace(self._target, self.path)
            self._target = self.path

    def touched(self) -> None:
        """Something besides whole rows was written (heights): flushed when due."""
        self._dirty = True

    def due(self) -> bool:
        """A crash-safe file whose last flush is ``flush_every_s`` old (and that changed)."""
        return (
            self.crash_safe
            and self._out.open
            and time.monotonic() - self._flushed_s >= self.flush_every_s
        )

    def flush(self) -> None:
        with self.writing() as f:
            f.flush()
        self._flushed_s = time.monotonic()
        self._dirty = False
        self.saved_rows = self.rows

    @property
    def dirty(self) -> bool:
        return self._dirty

    def close(self, attrs: dict) -> None:
        """Close with the final attributes (``complete`` last, True unless given False);
        WriteFailed when the disk refuses the last bytes; nothing after an earlier failure.
        The claim on the name is released in every case."""
        try:
            self._close(dict(attrs))
        finally:
            self.release()

    def _close(self, attrs: dict) -> None:
        if not self._out.open:
            return
        complete = attrs.pop("complete", True)
        attrs["complete"] = complete  # written last: a failure before it leaves False
        if self.crash_safe:
            # Close (the rows are safe from here on), then reopen for the final attributes, in
            # SWMR mode again: a writer killed before that close ends leaves a file that SWMR
            # readers open, as one killed mid-stream does.  (Reopened normally, the file would
            # carry HDF5's open-for-writing flag, and no reader would open it until `h5clear
            # -s`.)
            if self._claim is not None:  # readers wait until the claim is released
                self._claim.finishing()
            with self.reported():
                self._out.close()
            self.saved_rows = self.rows
            self.final = True
            if self._target != self.path:  # closed before its first row
                try:
                    os.replace(self._target, self.path)
                except OSError as exc:
                    raise self._failed(WriteFailed(self.path, reason(exc))) from None
                self._target = self.path
            # Reopened, the file carries the writer's flag until it is closed, and a close that
            # fails (a full disk) would leave it to SWMR readers only: the room the final
            # attributes take is asked of the disk first, and without it the file stays as it
            # is now (every row, complete False, readable by all).
            try:
                make_room(self.path, _room_for(attrs))
            except OSError as exc:
                if not is_write_error(exc):
                    raise
                raise WriteFailed(
                    self.path,
                    reason(exc),
                    f"its {self.rows} {self.unit} are saved, marked incomplete (complete = "
                    "False); no room for the final attributes (counters, gaps)",
                ) from None
            with self.reported():
                self._out = H5Output(self.path, "r+", libver=SWMR_LIBVER, swmr=True)
            self.file = self._out.file
        with self.writing() as f:
            for k, v in attrs.items():
                f.attrs[k] = v
        with self.reported():
            self._out.close()


def _room_for(attrs: dict) -> int:
    """Bytes of disk to hold before adding ``attrs`` to a file: twice their text, plus HDF5's
    structures (object header, the heap and B-tree of many attributes)."""
    text = sum(len(str(k)) + len(str(v)) + 64 for k, v in attrs.items())
    return 2 * text + (64 << 10)
