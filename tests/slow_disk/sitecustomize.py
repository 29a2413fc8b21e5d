"""A slow disk for the tests, without LD_PRELOAD: with RTSAR_TEST_SLOW_BPS set, every h5py
dataset write to a file whose name holds "SLOW" takes its bytes / RTSAR_TEST_SLOW_BPS seconds,
holding h5py's lock as a slow HDF5 write does (h5py serialises all HDF5 calls of a process).
Python loads this module at start-up when this folder is on PYTHONPATH (the `site` module)."""

import os

_BPS = os.environ.get("RTSAR_TEST_SLOW_BPS")

if _BPS:
    import time

    import h5py
    import numpy as np
    from h5py._objects import phil

    _write = h5py.Dataset.__setitem__

    def _slow_write(self, key, value):
        if "SLOW" in os.path.basename(self.file.filename):
            with phil:  # as a pwrite inside H5Dwrite: every HDF5 call of the process waits
                time.sleep(np.asarray(value).nbytes / float(_BPS))
                return _write(self, key, value)
        return _write(self, key, value)

    h5py.Dataset.__setitem__ = _slow_write
