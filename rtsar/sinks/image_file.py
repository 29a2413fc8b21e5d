"""Image files (HDF5): the focused image, written whole or line block by line block.

Image (``rtsar process``):  /image complex64 [azimuth, range], /azimuth_m, /range_m float64;
attributes format="rtsar-image", format_version, config (JSON), source, lens, correlator,
nonfinite_pulses (shots zeroed because they held NaN/Inf), complete (False while a stream is
written and in a file whose writer was killed).  With height strips (``--height insal``):
/height_m float32 [azimuth, range], /height_valid uint8 (1: coherent and unwrapped) and
/coherence float32, rows aligned with /image's.
Layout in docs/pages/reference/files.md.  Complex values are HDF5 compounds of two floats named r
and i (h5py's convention).
"""

from __future__ import annotations

import json
import os
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .. import __version__
from ..params import Config
from .h5_output import H5Output, WriteFailed, is_write_error, make_room, reason
from .io import (
    FORMAT_VERSION,
    IMAGE_FORMAT,
    open_checked,
    partial_prefix,
)
from .name_claim import NameClaim


def write_image(
    path: str | Path,
    image: np.ndarray,
    azimuth_m: np.ndarray,
    range_m: np.ndarray,
    config: Config,
    **attrs,
) -> None:
    """The whole image in one file (a full disk: WriteFailed, see rtsar.sinks.h5_output)."""
    out = H5Output(path)
    with out.writing() as f:
        f.create_dataset("image", data=np.asarray(image, np.complex64))
        f.create_dataset("azimuth_m", data=np.asarray(azimuth_m, np.float64))
        f.create_dataset("range_m", data=np.asarray(range_m, np.float64))
        f.attrs["format"] = IMAGE_FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["config"] = json.dumps(config.to_dict())
        f.attrs["rtsar_version"] = __version__
        for k, v in attrs.items():
            f.attrs[k] = v
    out.close()


def read_image(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """(image, azimuth_m, range_m, attributes).  Of a file still being written (SWMR), the
    lines both the image and its azimuth axis hold: the writer grows them one after the
    other, and a reader may come between."""
    with open_checked(path, IMAGE_FORMAT) as f:
        rows = min(f["image"].shape[0], f["azimuth_m"].shape[0])
        return (f["image"][:rows], f["azimuth_m"][:rows], f["range_m"][...], dict(f.attrs))


def read_heights(path: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(height_m float32 [azimuth, range], valid bool) of an image file; None without heights.

    Rows the height strips have not reached yet (a stream cut short) are invalid."""
    with open_checked(path, IMAGE_FORMAT) as f:
        if "height_m" not in f:
            return None
        rows = f["image"].shape[0]
        h = np.zeros(f["image"].shape, np.float32)
        v = np.zeros(f["image"].shape, bool)
        n = min(rows, f["height_m"].shape[0])
        h[:n], v[:n] = f["height_m"][:n], f["height_valid"][:n] != 0
        return h, v


class ImageWriter:
    """Write an image file line block by line block (streams of any length, bounded memory).

    Same layout as :func:`write_image`; ``close(**attrs)`` adds the final attributes and sets
    ``complete`` to True.

    ``crash_safe=True`` (live streams: ``run -o``, ``subscribe -o``) writes in HDF5's
    single-writer/multiple-reader mode, flushed at least every ``flush_every_s``: a writer killed
    at any moment (SIGKILL, an OOM kill, a power cut after the disk has the data) leaves a file
    that opens, holding every line flushed before the kill, with ``complete`` False.  The file
    is set up under a temporary name and takes its own name once its first lines are flushed,
    so neither a half-made nor an empty file ever carries the name (a writer killed before its
    first line leaves the earlier file there as it was).  Readers can open it while it is
    written.

    A write the disk refuses (full, quota) ends the file (rtsar.sinks.h5_output): WriteFailed,
    ``cannot write PATH: No space left on device``, a crash-safe file keeping its lines (the
    message says how many), readable, ``complete`` False.
    """

    def __init__(
        self,
        path: str | Path,
        config: Config,
        range_m: np.ndarray,
        chunk_lines: int = 64,
        crash_safe: bool = False,
        flush_every_s: float = 0.5,
        heights: bool = False,
        claim: NameClaim | None = None,
        **attrs,
    ):
        self.path = Path(path)
        self.crash_safe = crash_safe
        self.flush_every_s = float(flush_every_s)
        # Crash-safe: this run's claim on the name (rtsar.sinks.name_claim), taken here or
        # handed over by a recorder that took it when its run started; released at close.
        self._claim = claim
        if crash_safe and claim is None:
            self._claim = NameClaim(self.path)
        target = (
            self.path.with_name(partial_prefix(self.path) + "live") if crash_safe else self.path
        )
        self._target = target
        self.lines = 0  # lines in the file's datasets
        self.saved_lines = 0  # lines sure to be on disk (crash-safe: flushed)
        self.chunk_lines = int(chunk_lines)
        # Lines handed to write() and not yet in the datasets: they go in pieces of a chunk
        # or more (a 16-line strip at a time held the GIL for an HDF5 call 100 times a second
        # in a live run) and always before a flush or the close.
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        self._pending_lines = 0
        self.height_lines = 0  # rows of height_m written (the highest row + 1)
        self._image = self._azimuth = self._height = self._valid = self._coherence = None
        self._final = False  # crash-safe: the lines are closed, the final attributes follow
        libver = ("v110", "v110") if crash_safe else None
        self._out = None
        try:
            with self._reported():
                self._out = H5Output(target, libver=libver, shown=self.path)
            self._f = self._out.file
            with self._writing():
                self._create(config, range_m, chunk_lines, heights, attrs)
        except BaseException:  # (a WriteFailed has been told already: _failed)
            if self._out is not None and self._out.open:
                try:
                    self._out.close()
                except (OSError, RuntimeError, ValueError):  # the first error is the one told
                    pass
            if crash_safe and self._target != self.path:
                self._target.unlink(missing_ok=True)  # our temporary, no line in it
            self._release()
            raise
        self._flushed_s = time.monotonic()
        self._dirty = False

    def _create(self, config: Config, range_m, chunk_lines: int, heights: bool, attrs) -> None:
        nr = len(range_m)
        self._image = self._f.create_dataset(
            "image", (0, nr), np.complex64, maxshape=(None, nr), chunks=(chunk_lines, nr)
        )
        self._azimuth = self._f.create_dataset(
            "azimuth_m", (0,), np.float64, maxshape=(None,), chunks=(4096,)
        )
        self._f.create_dataset("range_m", data=np.asarray(range_m, np.float64))
        self._height = self._valid = self._coherence = None
        if heights:  # created now: no dataset can be added once the file is in SWMR mode
            self._height, self._valid, self._coherence = (
                self._f.create_dataset(
                    name, (0, nr), dtype, maxshape=(None, nr), chunks=(chunk_lines, nr)
                )
                for name, dtype in (
                    ("height_m", np.float32),
                    ("height_valid", np.uint8),
                    ("coherence", np.float32),
                )
            )
        a = self._f.attrs
        a["format"] = IMAGE_FORMAT
        a["format_version"] = FORMAT_VERSION
        a["config"] = json.dumps(config.to_dict())
        a["rtsar_version"] = __version__
        a["complete"] = False
        for k, v in attrs.items():
            a[k] = v
        if self.crash_safe:
            self._f.swmr_mode = True  # from here on the file on disk is always readable

    @contextmanager
    def _writing(self):
        """HDF5 work on the file: a failure (a full disk) ends the file, WriteFailed."""
        with self._reported(), self._out.writing(tidy=self._trim) as f:
            yield f

    @contextmanager
    def _reported(self):
        """A WriteFailed inside is told as :meth:`_failed` tells it (what stays of the file)."""
        try:
            yield
        except WriteFailed as exc:
            raise self._failed(exc) from None

    def _trim(self) -> None:
        """After a failed write: the datasets back to the lines written whole (a write that
        failed after its resize would leave zero lines at the end)."""
        if self._final:  # the final attributes' file: its datasets were closed whole
            return
        for ds, n in (
            (self._image, self.lines),
            (self._azimuth, self.lines),
            (self._height, self.height_lines),
            (self._valid, self.height_lines),
            (self._coherence, self.height_lines),
        ):
            if ds is not None and ds.shape[0] > n:  # (None: not created when it failed)
                ds.resize(n, axis=0)

    def _release(self) -> None:
        """Remove this run's mark on the name (crash-safe files)."""
        if self._claim is not None:
            self._claim.release()
            self._claim = None

    def _failed(self, exc: WriteFailed) -> WriteFailed:
        """A crash-safe file that failed: still under its temporary name (no line flushed), it
        is removed and an earlier file of the name stays; else what was written stays, readable,
        marked incomplete, and the error says how many lines."""
        if not self.crash_safe:
            return exc  # a temporary name, removed by its owner (replace_when_complete)
        self._release()
        if self._target != self.path:
            self._target.unlink(missing_ok=True)
            return exc.naming(self.path, kept="")
        if self._final and not self._out.closed_cleanly:
            # Its lines are all on disk, but the reopening for the final attributes marked the
            # file as being written (HDF5's superblock flag, SWMR), and no close could clear it.
            return exc.naming(
                self.path,
                kept=f"its {self.lines} lines are saved, marked incomplete; rtsar and SWMR "
                f"readers open it, other HDF5 readers once `h5clear -s {self.path}` clears "
                "the writer's flag",
            )
        if self._out.closed_cleanly:  # every line written went to disk, and the metadata too
            saved = f"its {self.lines} lines are saved"
        else:  # the last flush's lines are readable (SWMR); later ones may be lost
            saved = f"at least its first {self.saved_lines} lines are saved"
        return exc.naming(self.path, kept=f"{saved}, marked incomplete (complete = False)")

    @property
    def lines_handed(self) -> int:
        """Lines handed to :meth:`write`, in the datasets or waiting to go."""
        return self.lines + self._pending_lines

    def write(self, lines: np.ndarray, azimuth_m: np.ndarray) -> None:
        if not self._out.open:  # failed (its error again) or closed
            with self._writing():
                pass
        if not len(lines):
            return
        self._pending.append((np.asarray(lines), np.asarray(azimuth_m, np.float64)))
        self._pending_lines += len(lines)
        first = self.crash_safe and self._target != self.path
        if first or self._pending_lines >= self.chunk_lines:
            self._store()
        self.flush_if_due()

    def _store(self) -> None:
        """The pending lines into the datasets (the crash-safe file's first ones: its name)."""
        if not self._pending:
            return
        lines = np.concatenate([p[0] for p in self._pending])
        azimuth_m = np.concatenate([p[1] for p in self._pending])
        self._pending, self._pending_lines = [], 0
        end = self.lines + len(lines)
        with self._writing():
            self._image.resize(end, axis=0)
            self._image[self.lines : end] = lines
            self._azimuth.resize(end, axis=0)
            self._azimuth[self.lines : end] = azimuth_m
        self.lines = end
        self._dirty = True
        if self.crash_safe and self._target != self.path and end:
            self._flush()  # the first lines are on disk: the file takes its name
            with self._writing():
                os.replace(self._target, self.path)
            self._target = self.path

    def flush_if_due(self) -> None:
        """Crash-safe files: flush what was written if the last flush is ``flush_every_s`` old
        (called after every write, and by the writers' owners when a stream is idle)."""
        if self.crash_safe and (self._dirty or self._pending) and self._out.open:
            if time.monotonic() - self._flushed_s >= self.flush_every_s:
                self._flush()

    def _flush(self) -> None:
        self._store()
        with self._writing() as f:
            f.flush()
        self._flushed_s = time.monotonic()
        self._dirty = False
        self.saved_lines = self.lines

    @property
    def has_heights(self) -> bool:
        return self._height is not None

    def write_heights(
        self, row: int, height_m: np.ndarray, valid: np.ndarray, coherence=None
    ) -> None:
        """Heights of image rows ``row`` … (a height strip); rows never written stay invalid.
        ``coherence`` None (a version 1 height message): written as 0."""
        if self._height is None:
            raise ValueError("this image file was opened without heights")
        end = row + len(height_m)
        with self._writing():
            if end > self._height.shape[0]:
                for ds in (self._height, self._valid, self._coherence):
                    ds.resize(end, axis=0)
            self._height[row:end] = np.where(valid, height_m, 0.0)
            self._valid[row:end] = valid
            self._coherence[row:end] = 0.0 if coherence is None else coherence
        self.height_lines = max(self.height_lines, end)
        self._dirty = True
        self.flush_if_due()

    def close(self, **attrs) -> None:
        """Close with the final attributes; ``complete`` True unless ``complete=False`` given.
        WriteFailed when the disk refuses the last bytes; nothing after an earlier failure."""
        try:
            self._close(attrs)
        finally:
            self._release()

    def _close(self, attrs: dict) -> None:
        if not self._out.open:
            return
        self._store()
        complete = attrs.pop("complete", True)
        attrs["complete"] = complete  # written last: a failure before it leaves False
        if self.crash_safe:
            # Close (the lines are safe from here on), then reopen for the final attributes,
            # in SWMR mode again: a writer killed before that close ends leaves a file that
            # SWMR readers open, as one killed mid-stream does.  (Reopened normally, the file
            # would carry HDF5's open-for-writing flag, and no reader would open it until
            # `h5clear -s`.)
            with self._reported():
                self._out.close()
            self.saved_lines = self.lines
            self._final = True
            if self._target != self.path:  # closed before its first line
                try:
                    os.replace(self._target, self.path)
                except OSError as exc:
                    raise self._failed(WriteFailed(self.path, reason(exc))) from None
                self._target = self.path
            # Reopened, the file carries the writer's flag until it is closed, and a close
            # that fails (a full disk) would leave it to SWMR readers only: the room the final
            # attributes take is asked of the disk first, and without it the file stays as it
            # is now (every line, complete False, readable by all).
            try:
                make_room(self.path, _room_for(attrs))
            except OSError as exc:
                if not is_write_error(exc):
                    raise
                raise WriteFailed(
                    self.path,
                    reason(exc),
                    f"its {self.lines} lines are saved, marked incomplete (complete = False); "
                    "no room for the final attributes (counters, gaps)",
                ) from None
            with self._reported():
                self._out = H5Output(self.path, "r+", libver=("v110", "v110"), swmr=True)
            self._f = self._out.file
        with self._writing() as f:
            for k, v in attrs.items():
                f.attrs[k] = v
        with self._reported():
            self._out.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close(complete=exc[0] is None)


def _room_for(attrs: dict) -> int:
    """Bytes of disk to hold before adding ``attrs`` to a file: twice their text, plus HDF5's
    structures (object header, the heap and B-tree of many attributes)."""
    text = sum(len(str(k)) + len(str(v)) + 64 for k, v in attrs.items())
    return 2 * text + (64 << 10)
