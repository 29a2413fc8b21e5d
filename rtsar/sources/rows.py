"""A window of rows of an array-like (an h5py dataset, a CPHD channel's shots): read like it,
by slices or ``[...]``, and only where asked, so a window of a large file costs nothing until
read."""

from __future__ import annotations


class Rows:
    """``rows`` rows of a dataset from row ``first``, read like it (slices, ``[...]``): a live
    recording cut short (its whole rows), the part a replay was asked for (--start)."""

    def __init__(self, ds, rows: int, first: int = 0):
        self._ds, self._first = ds, int(first)
        self.shape = (int(rows), *ds.shape[1:])
        self.dtype, self.ndim = getattr(ds, "dtype", None), len(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key):
        first, rest = (key[0], key[1:]) if isinstance(key, tuple) else (key, ())
        if first is Ellipsis:
            first, rest = slice(None), ((Ellipsis,) if rest else ())
        if isinstance(first, slice):
            start, stop, step = first.indices(len(self))
            first = slice(start + self._first, stop + self._first, step)
        elif not -len(self) <= int(first) < len(self):
            raise IndexError(f"row {first} of {len(self)}")
        else:
            first = int(first) % len(self) + self._first
        return self._ds[(first, *rest)]
