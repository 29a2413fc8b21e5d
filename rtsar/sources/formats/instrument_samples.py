"""The samples an instrument file (rtsar.sources.formats.instrument_file) names, read block by
block as ``rtsar import`` takes them: MATLAB v5 loaded whole, v7.3 (HDF5) in h5py slices,
``.npy`` and raw binary memory-mapped; the DC offset, the pulses kept and the largest sample
measured in one pass."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from .instrument_file import CU8_OFFSET, SAMPLE_TYPES, InstrumentFile


def _complex(x: np.ndarray, offset: float = 0.0) -> np.ndarray:
    """complex128 from complex samples, a MATLAB compound (real, imag), or I, Q on the last axis."""
    if x.dtype.names is not None:
        return x["real"].astype(np.float64) + 1j * x["imag"].astype(np.float64)
    if np.iscomplexobj(x):
        return x.astype(np.complex128)
    out = np.empty(x.shape[:-1], np.complex128)
    out.real, out.imag = x[..., 0] - offset, x[..., 1] - offset
    return out


def _file_blocks(inst: InstrumentFile, block_pulses: int) -> Iterator[tuple[int, np.ndarray]]:
    """Blocks of the samples as the file holds them (no AGC), [pulse, sample]."""
    pulses = inst.shape[0]
    pulse_axis = 0 if inst.axes == "pulse,sample" else 1
    offset = 0.0
    if inst.data_format == "mat73":
        import h5py

        with h5py.File(inst.data_file, "r") as f:
            dset = f[inst.variable]  # MATLAB's array transposed: its pulse axis is the other one
            for p0 in range(0, pulses, block_pulses):
                p1 = min(p0 + block_pulses, pulses)
                yield p0, _complex(dset[p0:p1] if pulse_axis == 1 else dset[:, p0:p1].T)
        return
    if inst.data_format == "mat5":
        import scipy.io

        a = scipy.io.loadmat(inst.data_file, variable_names=[inst.variable])[inst.variable]
        if not np.iscomplexobj(a):
            why = f"{inst.data_file.name}: real {a.dtype}; complex samples are needed"
            raise ValueError(f"{inst.path}: data.variable: {why}")
    elif inst.data_format == "npy":
        a = np.load(inst.data_file, mmap_mode="r", allow_pickle=False)
    else:
        layout = inst.raw_layout
        kind = layout["sample_type"]
        dtype = np.dtype(SAMPLE_TYPES[kind]).newbyteorder("<>"[layout["byte_order"] == "big"])
        stored = inst.shape[:: 1 if pulse_axis == 0 else -1] + (() if kind[1] == "f" else (2,))
        a = np.memmap(inst.data_file, dtype, "r", layout["header_bytes"], stored)
        offset = CU8_OFFSET if kind == "cu8" else 0.0
    for p0 in range(0, pulses, block_pulses):
        x = a[p0 : p0 + block_pulses] if pulse_axis == 0 else a[:, p0 : p0 + block_pulses]
        yield p0, _complex(np.asarray(x if pulse_axis == 0 else np.swapaxes(x, 0, 1)), offset)


def iter_pulse_blocks(
    inst: InstrumentFile, block_pulses: int = 256, *, dc: complex = 0j
) -> Iterator[tuple[int, np.ndarray]]:
    """The raw array in blocks of pulses, in order, read lazily where the format allows.

    ``.npy`` is memory-mapped, raw binary read through ``np.memmap``, MATLAB v7.3 (HDF5) in
    h5py slices; a MATLAB v5 file is loaded once (that format cannot be read in part).  Raw
    samples are as their ``sample_type`` says: ``cf32``/``cf64`` complex (I, Q floats),
    ``ci16``/``ci8`` signed integers I, Q, ``cu8`` unsigned bytes I, Q whose zero, 127.5, is
    subtracted.

    Parameters
    ----------
    inst : InstrumentFile
    block_pulses : int
        Pulses per block (the last block may be shorter).
    dc : complex
        Subtracted from every sample before the AGC gain: the converter added it after the
        receiver's gain (``dc_offset``).

    Yields
    ------
    (int, ndarray)
        The block's first pulse, and its samples: complex128 ``[pulses, samples per pulse]``.
        With ``agc_db_file``, pulse p is multiplied by ``10**(-agc_db[p] / 20)``: the receiver
        applied that gain (in dB), and dividing it out restores the echo's level.
    """
    if isinstance(block_pulses, bool) or not isinstance(block_pulses, int) or block_pulses < 1:
        raise ValueError(f"block_pulses: {block_pulses!r}: a positive integer is needed")
    gain = None
    if inst.agc_db_file is not None:
        gain = 10.0 ** (-np.load(inst.agc_db_file).astype(np.float64) / 20.0)
    for p0, x in _file_blocks(inst, block_pulses):
        if dc:
            x -= dc
        if gain is not None:
            x *= gain[p0 : p0 + len(x), None]
        yield p0, x


def dc_offset(inst: InstrumentFile, block_pulses: int = 256) -> complex:
    """The mean of the samples as the file holds them (before any AGC), block by block, over
    the pulses whose samples are all finite: those the importer keeps (it zeroes the others).
    0 where no pulse is."""
    return dc_and_kept_pulses(inst, block_pulses)[0]


def dc_and_kept_pulses(inst: InstrumentFile, block_pulses: int = 256) -> tuple[complex, int, float]:
    """(:func:`dc_offset`, the number of pulses whose samples are all finite, the largest
    magnitude among them), in one pass."""
    total, count, kept_pulses, peak = 0j, 0, 0, 0.0
    for _, x in _file_blocks(inst, block_pulses):
        kept = x[np.isfinite(x).all(axis=1)]
        total += complex(kept.sum())
        count += kept.size
        kept_pulses += len(kept)
        if kept.size:
            peak = max(peak, float(np.abs(kept).max()))
    return (total / count if count else 0j), kept_pulses, peak


def load_replica(inst: InstrumentFile) -> np.ndarray | None:
    """The measured chirp replica (complex128, 1-D), or None when the file names none."""
    if inst.replica_file is None:
        return None
    return np.load(inst.replica_file, allow_pickle=False).astype(np.complex128)
