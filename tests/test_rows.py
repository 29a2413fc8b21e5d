"""rtsar.sources.rows.Rows, a window of an array-like's rows, reads as NumPy reads the same
rows of the array: every slice (any step, out of range, negative), integers, and Ellipsis."""

import itertools

import h5py
import numpy as np
import pytest

from rtsar.sources.rows import Rows


@pytest.mark.parametrize("shape", [(20,), (20, 3), (20, 2, 2)])
def test_a_window_reads_as_numpy_reads_its_rows(tmp_path, shape):
    a = np.arange(np.prod(shape)).reshape(shape)
    with h5py.File(tmp_path / "a.h5", "w") as f:
        f["a"] = a
        for source, first, rows in itertools.product((a, f["a"]), (0, 3, 7), (0, 1, 5, 13)):
            window, want = Rows(source, rows, first), a[first : first + rows]
            keys = [slice(*k) for k in itertools.product((None, -30, -3, 0, 2, 30), repeat=2)]
            keys = [slice(k.start, k.stop, s) for k in keys for s in (None, 2, -1, -3)]
            keys += [(Ellipsis, 0)] * (rows > 0) + [(Ellipsis, slice(0, 2))]
            keys += [i for i in (0, -1, rows - 1) if rows]
            for key in keys:
                got = np.asarray(window[key])
                np.testing.assert_array_equal(got, want[key], err_msg=f"{source} {key}")
                assert got.shape == want[key].shape
            with pytest.raises(IndexError):
                window[rows]
