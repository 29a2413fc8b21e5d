"""The sizes a file declares, checked before a reader allocates them (issue 36).

An HDF5 dataset declares its shape, and a chunked one may declare far more rows than it
stores: 2**34 rows with a few chunks written is a 250 KB file, and reading it whole asks numpy
for 128 GiB.  Before a whole read, :func:`check_read` compares the bytes the read makes (rows ×
the row's values × itemsize) with

* what the file can back: the dataset's allocated storage, never more than the file's own size,
  plus one chunk (the chunk a live writer may have grown and not filled yet).  Only a dataset
  stored raw is bounded so; a compressed, external or virtual one's storage bounds nothing;
* the machine's memory (its physical memory, ``os.sysconf``; unknown: not checked).

A size over either is a ValueError in one line naming the dataset and both sizes; the readers'
handlers put the file's name in front (``PATH: shots declares …``), and the CLI prints it as
``rtsar: error: …`` with exit status 2.
"""

from __future__ import annotations

import math
import os

import h5py


def physical_memory_bytes() -> int | None:
    """The machine's physical memory (pages × page size), or None where the system does not
    say (no ``os.sysconf``)."""
    try:
        pages, size = os.sysconf("SC_PHYS_PAGES"), os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
    return pages * size if pages > 0 and size > 0 else None


def size_words(nbytes: int) -> str:
    """``nbytes`` in the binary unit that suits it: "128 GiB", "32 KiB", "17 bytes"."""
    for unit, scale in (("PiB", 2**50), ("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes / 1024:.3g} KiB" if nbytes >= 1024 else f"{nbytes} bytes"


def check_declared(
    name: str, shape, itemsize: int, held_bytes: int | None = None, spare_bytes: int = 0
) -> int:
    """The bytes of an array of ``shape`` × ``itemsize`` that ``name`` declares (Python ints:
    no overflow), or a ValueError when they are more than ``held_bytes`` (what the file holds
    for it; None: not known) and ``spare_bytes`` (what a live writer may not have filled yet),
    or more than the machine's memory."""
    shape = tuple(int(n) for n in shape)
    nbytes = math.prod(shape) * int(itemsize)
    dims = " × ".join(f"{n:,}" for n in shape)
    said = f"{name} declares {dims} values of {int(itemsize)} bytes ({size_words(nbytes)})"
    if held_bytes is not None and nbytes > held_bytes + spare_bytes:
        raise ValueError(
            f"{said}, but the file holds {size_words(held_bytes)} for it: a size the file "
            "cannot back (damaged or forged)"
        )
    memory = physical_memory_bytes()
    if memory is not None and nbytes > memory:
        raise ValueError(f"{said}, more than this machine's memory ({size_words(memory)})")
    return nbytes


def stored_bytes(ds: h5py.Dataset) -> int | None:
    """The bytes an HDF5 dataset's values can come from in its file: its allocated storage, at
    most the file's size; None for a dataset whose storage bounds nothing (compressed or
    otherwise filtered, external, virtual)."""
    dcpl = ds.id.get_create_plist()
    if dcpl.get_layout() == h5py.h5d.VIRTUAL or dcpl.get_external_count() or dcpl.get_nfilters():
        return None
    return min(ds.id.get_storage_size(), ds.file.id.get_filesize())


def _chunk_bytes(ds: h5py.Dataset) -> int:
    """One chunk's bytes (0: not chunked): what a live writer may have grown and not filled."""
    return math.prod(ds.chunks) * ds.dtype.itemsize if ds.chunks else 0


def stored_rows(ds: h5py.Dataset) -> int:
    """The most rows (first axis) of ``ds`` its file can back (:func:`stored_bytes` and one
    chunk): all its rows where its storage bounds nothing."""
    held = stored_bytes(ds)
    row = math.prod(ds.shape[1:]) * ds.dtype.itemsize
    if held is None or row == 0:
        return len(ds)
    return min(len(ds), (held + _chunk_bytes(ds)) // row)


def check_read(ds: h5py.Dataset, rows: int | None = None, name: str | None = None) -> None:
    """Before ``ds[:rows]`` (``rows`` None: ``ds[...]``): :func:`check_declared` with what
    the file holds (:func:`stored_bytes`, one chunk spare); ``name``: the dataset's path."""
    shape = tuple(ds.shape) if rows is None else (int(rows), *ds.shape[1:])
    said = name or ds.name.lstrip("/")
    check_declared(said, shape, ds.dtype.itemsize, stored_bytes(ds), _chunk_bytes(ds))


def read_checked(ds: h5py.Dataset, rows: int | None = None, path=None):
    """``ds[:rows]`` (``rows`` None: the whole dataset) after :func:`check_read` of the rows it
    has; ``path``, where given, named in front of the error (for callers without a handler
    that names the file)."""
    try:
        check_read(ds, None if rows is None else min(int(rows), len(ds)))
    except ValueError as exc:
        raise (ValueError(f"{path}: {exc}") if path is not None else exc) from None
    return ds[:rows]


def readable_rows(datasets, rows: int) -> int:
    """The first ``rows`` rows, or fewer: as many as every dataset of ``datasets`` reads without
    HDF5's OSError.  A writer killed inside a flush can leave a file whose last rows' storage
    HDF5 refuses ("len not positive after adjustment for EOA"), though the rows before read;
    the longest readable prefix is found by bisection (a read of one row a step: about
    log2(rows) rows read a dataset, where its last row fails; one where it reads).  It assumes
    what HDF5 refuses is a tail (a killed writer's last rows): a refused row between readable
    ones is not looked for."""

    def reads(ds, row: int) -> bool:
        try:
            ds[row : row + 1]
        except OSError:
            return False
        return True

    for ds in datasets:
        if rows and not reads(ds, rows - 1):
            good, bad = 0, rows - 1  # the rows before ``good`` read (none yet); ``bad`` does not
            while bad - good > 0:
                middle = (good + bad) // 2
                good, bad = (middle + 1, bad) if reads(ds, middle) else (good, middle)
            rows = good
    return rows
