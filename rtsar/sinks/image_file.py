"""Image files (HDF5): the focused image, written whole or line block by line block.

Image (``rtsar process``):  /image complex64 [azimuth, range], /azimuth_m, /range_m float64;
attributes format="rtsar-image", format_version, config (JSON), source, lens, correlator,
nonfinite_pulses (shots zeroed because they held NaN/Inf), complete (False while a stream is
written and in a file whose writer was killed); live images also stopped_by (the signal that
stopped the source, else "").  With height strips (``--height insal``):
/height_m float32 [azimuth, range], /height_valid uint8 (1: coherent and unwrapped) and
/coherence float32, rows aligned with /image's.
Layout in docs/pages/reference/files.md.  Complex values are HDF5 compounds of two floats named r
and i (h5py's convention).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .. import __version__
from ..params import Config, config_from_dict
from .declared import check_read, stored_rows
from .h5_output import H5Output
from .io import FORMAT_VERSION, IMAGE_FORMAT, open_checked
from .live_file import LiveFile
from .name_claim import NameClaim

HEIGHT_DATASETS = ("height_m", "height_valid", "coherence")  # [azimuth, range] each


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


def image_config(attrs: dict, path) -> Config:
    """The processor's configuration an image keeps (its ``config`` attribute): a one-line
    ValueError naming the file where it is missing or does not read."""
    text = attrs.get("config")
    if text is None:
        raise ValueError(
            f"{path}: no 'config' attribute (the processor's configuration, which rtsar "
            "process, run -o, replay -o and subscribe -o write)"
        )
    try:
        return config_from_dict(json.loads(text.decode() if isinstance(text, bytes) else text))
    except (TypeError, ValueError, KeyError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: its 'config' attribute does not read: {exc}") from None


def read_image(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """(image, azimuth_m, range_m, attributes).

    What the file holds is checked first (ValueError ``PATH: …`` in one line): ``image`` a
    complex 2-D dataset without NaN/Inf (rtsar zeroes such pulses, so a non-finite pixel is
    damage), the axes 1-D, finite and strictly increasing, ``range_m`` one entry per column,
    ``azimuth_m`` one per line, the height datasets (if any) one value per column, and every
    dataset's declared size one its file can hold and the machine's memory take
    (rtsar.sinks.declared).  Of a file still being written (``complete`` False: a live
    stream's, or one whose writer was killed), the lines both the image and its azimuth axis
    hold, and that the file stores: the writer grows them one after the other, and a reader
    may come between."""
    with open_checked(path, IMAGE_FORMAT) as f:
        try:
            image = _dataset(f, "image", 2, np.complexfloating, "complex")
            azimuth = _dataset(f, "azimuth_m", 1, np.floating, "float")
            range_ = _dataset(f, "range_m", 1, np.floating, "float")
            rows = _lines(image, azimuth, growing=not f.attrs.get("complete", True))
            if rows == 0 or image.shape[1] == 0:
                raise ValueError(f"an image of {rows} lines x {image.shape[1]} columns: nothing")
            if range_.shape[0] != image.shape[1]:
                raise ValueError(
                    f"range_m has {range_.shape[0]} entries for the image's {image.shape[1]} "
                    "columns"
                )
            _check_heights(f, image.shape[1])
            for ds, n in ((image, rows), (azimuth, rows), (range_, None)):
                check_read(ds, n)
            out = image[:rows], azimuth[:rows], range_[...], dict(f.attrs)
        except (KeyError, TypeError, OSError) as exc:  # h5py on a damaged file
            raise ValueError(f"{path}: {exc}") from None
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}") from None
    for name, values in zip(("image", "azimuth_m", "range_m"), out[:3], strict=True):
        bad = values.size - int(np.count_nonzero(np.isfinite(values)))
        if bad:
            raise ValueError(f"{path}: {name} holds {bad} NaN/Inf value(s) of {values.size}")
    for name, axis in (("azimuth_m", out[1]), ("range_m", out[2])):
        if axis.size > 1 and not np.all(np.diff(axis) > 0):
            raise ValueError(f"{path}: {name} does not increase from entry to entry")
    return out


def _lines(image, azimuth, growing: bool) -> int:
    """The image lines to read: all of them, ``azimuth_m`` holding one entry per line (an axis
    of another length is damage, never cut to fit); of a file still being written, the lines
    both hold that its storage backs (rtsar.sinks.declared.stored_rows)."""
    if growing:
        return min(stored_rows(image), stored_rows(azimuth))
    if azimuth.shape[0] != image.shape[0]:
        raise ValueError(
            f"azimuth_m has {azimuth.shape[0]} entries for the image's {image.shape[0]} lines"
        )
    return image.shape[0]


def _check_heights(f, columns: int) -> None:
    """The height strips (``--height``), where the file has them: ``height_m``,
    ``height_valid`` and (where kept) ``coherence`` 2-D, of the image's columns (their rows may
    differ from the image's: a row the strips did not reach is not valid)."""
    if "height_m" not in f:
        return
    for name in HEIGHT_DATASETS:
        ds = f.get(name)
        if ds is None and name == "coherence":
            continue
        if ds is None or not hasattr(ds, "dtype") or ds.ndim != 2 or ds.shape[1] != columns:
            shape = getattr(ds, "shape", "missing")
            raise ValueError(f"{name} must be [line, {columns} columns] as the image, got {shape}")


def _dataset(f, name: str, ndim: int, kind, said: str):
    """Dataset ``name``, checked: present, ``ndim``-D, of the ``kind`` of numbers."""
    ds = f.get(name)
    if ds is None or not hasattr(ds, "dtype"):
        raise ValueError(f"no {name} dataset: not a whole rtsar image")
    if ds.ndim != ndim or not np.issubdtype(ds.dtype, kind):
        raise ValueError(f"{name} must be {ndim}-D {said}, got {ds.shape} {ds.dtype}")
    return ds


def read_heights(path: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(height_m float32 [azimuth, range], valid bool) of an image file; None without heights.

    Rows the height strips have not reached yet (a stream cut short) are invalid.  The rows
    are the image's that :func:`read_image` reads, checked as it checks them (ValueError
    ``PATH: …``)."""
    with open_checked(path, IMAGE_FORMAT) as f:
        if "height_m" not in f:
            return None
        try:
            image = _dataset(f, "image", 2, np.complexfloating, "complex")
            azimuth = _dataset(f, "azimuth_m", 1, np.floating, "float")
            rows = _lines(image, azimuth, growing=not f.attrs.get("complete", True))
            _check_heights(f, image.shape[1])
            check_read(image, rows)  # (the 5 bytes a pixel made here: under its 8)
            n = min(rows, f["height_m"].shape[0], f["height_valid"].shape[0])
            for name in ("height_m", "height_valid"):
                check_read(f[name], n)
            h = np.zeros((rows, image.shape[1]), np.float32)
            v = np.zeros((rows, image.shape[1]), bool)
            h[:n], v[:n] = f["height_m"][:n], f["height_valid"][:n] != 0
        except (ValueError, KeyError, TypeError, OSError) as exc:
            raise ValueError(f"{path}: {exc}") from None
        return h, v


class ImageWriter:
    """Write an image file line block by line block (streams of any length, bounded memory).

    Same layout as :func:`write_image`; ``close(**attrs)`` adds the final attributes and sets
    ``complete`` to True.

    ``crash_safe=True`` (live streams: ``run -o``, ``subscribe -o``) writes through
    rtsar.sinks.live_file: in HDF5's SWMR mode, flushed at least every ``flush_every_s``, under
    a temporary name until its first lines are flushed, the name claimed for the whole run: a
    writer killed at any moment leaves a file that opens, holding every line flushed before the
    kill, with ``complete`` False.  Readers can open it while it is written.

    A write the disk refuses (full, quota) ends the file: WriteFailed, ``cannot write PATH: No
    space left on device``, a crash-safe file keeping its lines (the message says how many),
    readable, ``complete`` False.
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
        self.chunk_lines = int(chunk_lines)
        # Lines handed to write() and not yet in the datasets: they go in pieces of a chunk
        # or more (a 16-line strip at a time held the GIL for an HDF5 call 100 times a second
        # in a live run) and always before a flush or the close.
        self._pending: list[tuple[np.ndarray, np.ndarray]] = []
        self._pending_lines = 0
        self.height_lines = 0  # rows of height_m written (the highest row + 1)
        self._image = self._azimuth = self._height = self._valid = self._coherence = None
        self._file = LiveFile(
            self.path,
            lambda f: self._create(f, config, range_m, chunk_lines, heights, attrs),
            crash_safe=crash_safe,
            claim=claim,
            flush_every_s=flush_every_s,
            unit="lines",
            tidy=self._trim,
        )

    def _create(self, f, config: Config, range_m, chunk_lines: int, heights: bool, attrs) -> None:
        nr = len(range_m)
        self._image = f.create_dataset(
            "image", (0, nr), np.complex64, maxshape=(None, nr), chunks=(chunk_lines, nr)
        )
        self._azimuth = f.create_dataset(
            "azimuth_m", (0,), np.float64, maxshape=(None,), chunks=(4096,)
        )
        f.create_dataset("range_m", data=np.asarray(range_m, np.float64))
        self._height = self._valid = self._coherence = None
        if heights:  # created now: no dataset can be added once the file is in SWMR mode
            self._height, self._valid, self._coherence = (
                f.create_dataset(
                    name, (0, nr), dtype, maxshape=(None, nr), chunks=(chunk_lines, nr)
                )
                for name, dtype in (
                    ("height_m", np.float32),
                    ("height_valid", np.uint8),
                    ("coherence", np.float32),
                )
            )
        a = f.attrs
        a["format"] = IMAGE_FORMAT
        a["format_version"] = FORMAT_VERSION
        a["config"] = json.dumps(config.to_dict())
        a["rtsar_version"] = __version__
        a["complete"] = False
        for k, v in attrs.items():
            a[k] = v

    def _trim(self, lines: int) -> None:
        """After a failed write: the datasets back to the lines written whole (a write that
        failed after its resize would leave zero lines at the end)."""
        for ds, n in (
            (self._image, lines),
            (self._azimuth, lines),
            (self._height, self.height_lines),
            (self._valid, self.height_lines),
            (self._coherence, self.height_lines),
        ):
            if ds is not None and ds.shape[0] > n:  # (None: not created when it failed)
                ds.resize(n, axis=0)

    @property
    def lines(self) -> int:
        """Lines in the file's datasets."""
        return self._file.rows

    @property
    def saved_lines(self) -> int:
        """Lines sure to be on disk (crash-safe: flushed)."""
        return self._file.saved_rows

    @property
    def lines_handed(self) -> int:
        """Lines handed to :meth:`write`, in the datasets or waiting to go."""
        return self.lines + self._pending_lines

    def write(self, lines: np.ndarray, azimuth_m: np.ndarray) -> None:
        if not self._file.open:  # failed (its error again) or closed
            with self._file.writing():
                pass
        if not len(lines):
            return
        self._pending.append((np.asarray(lines), np.asarray(azimuth_m, np.float64)))
        self._pending_lines += len(lines)
        if (self.crash_safe and not self._file.named) or self._pending_lines >= self.chunk_lines:
            self._store()
        self.flush_if_due()

    def _store(self) -> None:
        """The pending lines into the datasets (the crash-safe file's first ones: its name)."""
        if not self._pending:
            return
        lines = np.concatenate([p[0] for p in self._pending])
        azimuth_m = np.concatenate([p[1] for p in self._pending])
        self._pending, self._pending_lines = [], 0
        start = self.lines
        end = start + len(lines)
        with self._file.writing():
            self._image.resize(end, axis=0)
            self._image[start:end] = lines
            self._azimuth.resize(end, axis=0)
            self._azimuth[start:end] = azimuth_m
        self._file.stored(end)

    def flush_if_due(self) -> None:
        """Crash-safe files: flush what was written if the last flush is ``flush_every_s`` old
        (called after every write, and by the writers' owners when a stream is idle)."""
        if (self._file.dirty or self._pending) and self._file.due():
            self.flush()

    def flush(self) -> None:
        """Everything handed so far to the disk (crash-safe: readable after a kill)."""
        self._store()
        self._file.flush()

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
        with self._file.writing():
            if end > self._height.shape[0]:
                for ds in (self._height, self._valid, self._coherence):
                    ds.resize(end, axis=0)
            self._height[row:end] = np.where(valid, height_m, 0.0)
            self._valid[row:end] = valid
            self._coherence[row:end] = 0.0 if coherence is None else coherence
        self.height_lines = max(self.height_lines, end)
        self._file.touched()
        self.flush_if_due()

    def close(self, **attrs) -> None:
        """Close with the final attributes; ``complete`` True unless ``complete=False`` given.
        WriteFailed when the disk refuses the last bytes; nothing after an earlier failure."""
        try:
            if self._file.open:
                self._store()
        finally:
            self._file.close(attrs)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close(complete=exc[0] is None)
