"""A window of rows of an array-like (an h5py dataset, a CPHD channel's shots): read like it,
by slices or ``[...]``, and only where asked, so a window of a large file costs nothing until
read."""

from __future__ import annotations

import numpy as np


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
        if first is Ellipsis:  # as many whole axes as the rest leaves, the first among them
            fill = len(self.shape) - len(rest)
            if fill < 1:  # (``[..., k]`` of one axis: row k)
                return self[rest]
            first, rest = slice(None), (*(slice(None),) * (fill - 1), *rest)
        if isinstance(first, slice):
            rows = range(len(self))[first]  # the rows asked for, any step, within the window
            if len(rows) and rows.step < 0:  # read forwards (h5py's slices), then reversed
                forwards = self[(slice(rows[-1], rows[0] + 1, -rows.step), *rest)]
                return np.asarray(forwards)[::-1]
            lo = rows[0] if len(rows) else 0
            first = slice(lo + self._first, lo + len(rows) * rows.step + self._first, rows.step)
            if not len(rows):
                first = slice(self._first, self._first)
        elif not -len(self) <= int(first) < len(self):
            raise IndexError(f"row {first} of {len(self)}")
        else:
            first = int(first) % len(self) + self._first
        # a bare slice where nothing follows: a CPHD channel's shots take no tuple
        return self._ds[(first, *rest) if rest else first]
