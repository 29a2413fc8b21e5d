"""Instrument files: a user's description (TOML) of a raw radar data block, for ``rtsar import``.

The file gives the radar, the acquisition geometry and the file holding the raw samples; names
carry SI units, and delays are counted from the centre of the transmitted pulse::

    [radar]
    carrier_hz = 5.3e9
    sample_rate_hz = 32.317e6
    chirp_rate_hz_per_s = -0.72135e12   # signed: negative is a down-chirp
    pulse_length_s = 41.75e-6
    prf_hz = 1256.98                    # optional: replica_file (a measured chirp, complex .npy)

    [geometry]
    effective_velocity_m_per_s = 7062.0
    window_start_s = 6.5956e-3          # two-way delay of the block's first range sample
    doppler_centroid_hz = -6900.0       # optional: estimated from the data when absent
    looking = "right"                   # optional: "right" (default) or "left"

    [data]
    file = "block.mat"                  # relative to this file's folder
    variable = "data"                   # the MATLAB (v5 or v7.3) variable
    first_range_cell = 760              # any key not read here is kept, in `extra`

Optional ``[geometry]`` keys: ``antenna_length_m``, ``first_pulse_time_s`` (or in ``[data]``).
Optional ``[data]`` keys: ``format`` (mat5, mat73, npy or raw; else told by the suffix and, for
``.mat``, the header), ``axes`` ("pulse,sample", the default, or "sample,pulse" for an array
stored transposed), ``agc_db_file`` (per-pulse receiver gain in dB, a float .npy); for raw binary
(``.bin``, ``.dat``, ``.raw``): ``sample_type``, ``pulses``, ``samples_per_pulse``,
``header_bytes`` (0) and ``byte_order`` ("little"); ``collection_start_utc`` (ISO 8601, the UTC
of time_s = 0; without it the recording has no known start).  A key rtsar does not read is kept
as provenance, unless it is a near miss of one it reads (rtsar.sources.formats.key_typos: a
letter or two from it, or it with a word left out).  Every problem is a one-line
``ValueError`` naming the TOML file and the key (and the data file where it is the data
file's).
"""

from __future__ import annotations

import datetime
import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .key_typos import near_miss
from .timebase import parse_utc

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

C_M_PER_S = 299_792_458.0
RADAR_KEYS = ("carrier_hz", "sample_rate_hz", "chirp_rate_hz_per_s", "pulse_length_s", "prf_hz")
GEOMETRY_KEYS = ("effective_velocity_m_per_s", "window_start_s")
OPTIONAL_GEOMETRY = ("doppler_centroid_hz", "looking", "antenna_length_m", "first_pulse_time_s")
FORMATS = ("mat5", "mat73", "npy", "raw")
RAW_KEYS = ("sample_type", "pulses", "samples_per_pulse", "header_bytes", "byte_order")
DATA_KEYS = (
    ("file", "variable", "format", "axes", "agc_db_file", "first_pulse_time_s")
    + ("collection_start_utc",)
    + RAW_KEYS
)
SAMPLE_TYPES = {"cf32": "c8", "cf64": "c16", "ci16": "i2", "ci8": "i1", "cu8": "u1"}
"""Raw sample types and their NumPy codes: ``cf32``/``cf64`` complex, the others I, Q pairs."""
CU8_OFFSET = 127.5
"""The zero of ``cu8`` samples (unsigned 8-bit I, Q, as RTL-SDR receivers write them)."""


@dataclass(frozen=True)
class InstrumentFile:
    """An instrument file, read and checked by ``read_instrument_file``; SI units."""

    path: Path
    carrier_hz: float
    sample_rate_hz: float
    chirp_rate_hz_per_s: float
    pulse_length_s: float
    prf_hz: float
    effective_velocity_m_per_s: float
    window_start_s: float
    doppler_centroid_hz: float | None
    looking: str
    antenna_length_m: float | None
    first_pulse_time_s: float | None
    data_file: Path
    variable: str | None
    data_format: str
    shape: tuple[int, int]
    extra: dict
    replica_file: Path | None
    agc_db_file: Path | None
    axes: str = "pulse,sample"
    """How the array is stored: "pulse,sample" (a row per pulse) or "sample,pulse"."""
    raw_layout: dict = field(default_factory=dict)
    """Raw binary only: sample_type, header_bytes, byte_order."""
    collection_start: datetime.datetime | None = None
    """The UTC of time_s = 0 (naive), where the file gives it."""


class _Checker:
    """Checks the keys of one instrument file; ``fail`` makes its one-line errors."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, key: str, what: str) -> ValueError:
        return ValueError(f"{self.path}: {key}: {what}")

    def table(self, doc: dict, name: str, known: tuple | None = None) -> dict:
        table = doc.get(name)
        if not isinstance(table, dict):
            raise self.fail(f"[{name}]", "missing table")
        for key in table if known else ():
            if key not in known:
                raise self.fail(f"{name}.{key}", f"unknown key; known: {', '.join(known)}")
        return table

    def missing(self, section: str, table: dict, key: str, why: str = "missing") -> ValueError:
        """A required key absent, named with a key present that is a near miss of it (a new
        user's `varible` said only that data.variable was missing)."""
        near = [k for k in table if near_miss(k, key)]
        hint = f"; {section}.{near[0]} is a near miss of it (a typo?)" if near else ""
        return self.fail(f"{section}.{key}", why + hint)

    def number(self, section: str, table: dict, key: str, positive=True, required=True):
        name, value = f"{section}.{key}", table.get(key)
        if value is None:
            if required:
                raise self.missing(section, table, key)
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(name, f"{value!r}: a number is needed")
        if not math.isfinite(value) or (positive and value <= 0):
            raise self.fail(name, f"{value!r}: must be finite{' and > 0' if positive else ''}")
        return float(value)

    def integer(self, data: dict, key: str, default=None, minimum: int = 1) -> int:
        value = data.get(key, default)
        if value is None:
            raise self.missing("data", data, key, "missing (raw binary data needs it)")
        if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
            raise self.fail(f"data.{key}", f"{value!r}: an integer >= {minimum} is needed")
        return value

    def file(self, section: str, table: dict, key: str) -> Path | None:
        """A file the key names, relative to the instrument file's folder."""
        if key not in table:
            return None
        if not isinstance(table[key], str):
            raise self.fail(f"{section}.{key}", f"{table[key]!r}: a file name is needed")
        found = (self.path.parent / Path(table[key]).expanduser()).absolute()
        if found.is_dir():
            raise self.fail(f"{section}.{key}", f"{found}: a folder, not a file")
        if not found.is_file():
            relative = not Path(table[key]).is_absolute()
            where = " (relative to the instrument file's folder)" * relative
            raise self.fail(f"{section}.{key}", f"{found}: no such file{where}")
        return found

    def provenance(self, data: dict) -> dict:
        """The [data] keys rtsar does not read (kept as provenance), but none a near miss of
        one it reads (rtsar.sources.formats.key_typos)."""
        extra = {k: value for k, value in data.items() if k not in DATA_KEYS}
        for key in extra:
            near = [k for k in DATA_KEYS if near_miss(key, k)]
            if near:
                raise self.fail(
                    f"data.{key}",
                    f"unknown key, a near miss of {near[0]} (a typo?); [data] keys rtsar does "
                    "not read are kept as provenance, but not one so close to a key it reads",
                )
        return extra

    def npy(self, key: str, file: Path) -> np.ndarray:
        try:
            return np.load(file, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError) as exc:
            why = "pickled objects, not an array" if "allow_pickle" in str(exc) else exc
            raise self.fail(key, f"{file}: unreadable as .npy: {why}") from None

    def raw_layout(self, data: dict) -> dict:
        kind, order = data.get("sample_type"), data.get("byte_order", "little")
        if kind not in SAMPLE_TYPES:
            raise self.fail("data.sample_type", f"{kind!r}: one of {', '.join(SAMPLE_TYPES)}")
        if order not in ("little", "big"):
            raise self.fail("data.byte_order", f"{order!r}: little or big")
        header = self.integer(data, "header_bytes", 0, 0)
        return {"sample_type": kind, "header_bytes": header, "byte_order": order}


def _data_format(check: _Checker, data: dict, file: Path) -> str:
    if "format" in data:
        if data["format"] not in FORMATS:
            raise check.fail("data.format", f"{data['format']!r}: one of {', '.join(FORMATS)}")
        return data["format"]
    suffix = file.suffix.lower()
    if suffix == ".mat":  # v7.3 is HDF5 after a 512-byte header (MATLAB's "userblock")
        import h5py  # (HDF5's signature at 0, or after a user block of 512·2^k bytes)

        return "mat73" if h5py.is_hdf5(file) else "mat5"
    if suffix in (".npy", ".bin", ".dat", ".raw"):
        return "npy" if suffix == ".npy" else "raw"
    raise check.fail("data.format", f"{file.name}: unknown suffix; give one of {FORMATS}")


def _stored_shape(check: _Checker, data: dict, fmt: str, file: Path, variable) -> tuple:
    """The array's shape as stored (MATLAB's shape for .mat); complex samples checked."""
    if fmt in ("mat5", "mat73") and not isinstance(variable, str):
        why = "missing (a MATLAB file needs the variable's name)"
        raise check.missing("data", data, "variable", why)
    if fmt == "mat5":  # is it complex? seen on loading (iter_pulse_blocks)
        import scipy.io

        found = {name: shape for name, shape, _ in scipy.io.whosmat(str(file))}
        if variable not in found:
            names = ", ".join(sorted(found)) or "none"
            raise check.fail("data.variable", f"{variable!r} not in {file.name}; it has {names}")
        return tuple(found[variable])
    if fmt == "mat73":
        import h5py

        with h5py.File(file, "r") as f:
            dset = f.get(variable)
            if not isinstance(dset, h5py.Dataset):
                names = ", ".join(sorted(k for k in f if not k.startswith("#"))) or "none"
                raise check.fail(
                    "data.variable", f"{variable!r} not in {file.name}; it has {names}"
                )
            if dset.dtype.kind != "c" and set(dset.dtype.names or ()) != {"real", "imag"}:
                stored = "real" if dset.dtype.kind in "fiu" else "not complex:"
                raise check.fail(
                    "data.variable",
                    f"{file.name}: {variable!r} holds {stored} {dset.dtype} samples; complex "
                    "needed (MATLAB's compound of real and imag, or HDF5's complex as h5py "
                    "writes it)",
                )
            # HDF5 sees MATLAB's (column-major) array transposed; an array another tool wrote
            # [pulse, sample] in its own order is read with axes = "sample,pulse"
            return dset.shape[::-1]
    if fmt == "npy":
        a = check.npy("data.file", file)
        if a.ndim == 3 and a.shape[2] == 2 and not np.iscomplexobj(a):
            return a.shape[:2]  # I, Q along the last axis
        if a.ndim == 2 and not np.iscomplexobj(a):
            why = "complex samples are needed (or a last axis of 2: I, Q)"
            raise check.fail("data.file", f"{file}: real {a.dtype} array; {why}")
        return a.shape
    layout = check.raw_layout(data)
    pulses, samples = check.integer(data, "pulses"), check.integer(data, "samples_per_pulse")
    kind = layout["sample_type"]
    bytes_per_sample = np.dtype(SAMPLE_TYPES[kind]).itemsize * (1 if kind[1] == "f" else 2)
    expected = layout["header_bytes"] + pulses * samples * bytes_per_sample
    if file.stat().st_size != expected:
        size = file.stat().st_size
        raise check.fail("data.file", f"{file}: {size} bytes, expected {expected} from the keys")
    return (pulses, samples) if data.get("axes") != "sample,pulse" else (samples, pulses)


def read_instrument_file(path) -> InstrumentFile:
    """Read and check an instrument file, and what its data file holds (not the samples).

    Parameters
    ----------
    path : str or Path
        The TOML file.

    Returns
    -------
    InstrumentFile

    Raises
    ------
    ValueError
        ``'<file>: <key>: <what is wrong>'``: a syntax error, a missing or unknown key, a value
        out of range, parameters that contradict each other or the data file.
    """
    path = Path(path)
    check = _Checker(path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        why = getattr(exc, "strerror", None) or exc  # (not data.file: the TOML itself)
        raise ValueError(f"{path}: the instrument file cannot be read: {why}") from None
    except tomllib.TOMLDecodeError as exc:
        raise check.fail("TOML syntax", str(exc)) from None
    for name in doc:
        if name not in ("radar", "geometry", "data"):
            raise check.fail(name, "unknown table; known: [radar], [geometry], [data]")
    radar = check.table(doc, "radar", RADAR_KEYS + ("replica_file",))
    geometry = check.table(doc, "geometry", GEOMETRY_KEYS + OPTIONAL_GEOMETRY)
    data = check.table(doc, "data")
    v = {k: check.number("radar", radar, k) for k in RADAR_KEYS if k != "chirp_rate_hz_per_s"}
    v.update({k: check.number("geometry", geometry, k) for k in GEOMETRY_KEYS})
    chirp = v["chirp_rate_hz_per_s"] = check.number("radar", radar, "chirp_rate_hz_per_s", False)
    band_hz = abs(chirp) * v["pulse_length_s"]
    if chirp == 0:
        raise check.fail("radar.chirp_rate_hz_per_s", "0: a chirp's rate cannot be zero")
    if band_hz > v["sample_rate_hz"]:  # the chirp's band would not fit complex sampling
        why = f"|rate| x pulse_length_s = {band_hz:.6g} Hz exceeds sample_rate_hz"
        raise check.fail("radar.chirp_rate_hz_per_s", why)
    dc_hz = check.number("geometry", geometry, "doppler_centroid_hz", False, False)
    v["doppler_centroid_hz"] = dc_hz
    limit_hz = v["effective_velocity_m_per_s"] * v["carrier_hz"] / C_M_PER_S  # (2 v / lambda) / 2
    if dc_hz is not None and abs(dc_hz) >= limit_hz:
        why = (
            f"{dc_hz:g} Hz: |value| >= v / wavelength = {limit_hz:.6g} Hz, a 90 degree squint "
            f"(with radar.carrier_hz {v['carrier_hz']:g}, a wavelength of "
            f"{C_M_PER_S / v['carrier_hz']:.4g} m, and geometry.effective_velocity_m_per_s "
            f"{v['effective_velocity_m_per_s']:g}: one of the three is wrong)"
        )
        raise check.fail("geometry.doppler_centroid_hz", why)
    v["looking"] = geometry.get("looking", "right")
    if v["looking"] not in ("right", "left"):
        raise check.fail("geometry.looking", f"{v['looking']!r}: right or left")
    v["antenna_length_m"] = check.number("geometry", geometry, "antenna_length_m", required=False)
    if "first_pulse_time_s" in geometry and "first_pulse_time_s" in data:
        raise check.fail("data.first_pulse_time_s", "given in [geometry] as well")
    where = "geometry" if "first_pulse_time_s" in geometry else "data"
    v["first_pulse_time_s"] = check.number(where, doc[where], "first_pulse_time_s", False, False)

    if "file" not in data:
        raise check.missing("data", data, "file")
    file = v["data_file"] = check.file("data", data, "file")
    try:
        fmt = v["data_format"] = _data_format(check, data, file)
    except OSError as exc:
        raise check.fail("data.file", f"{file}: unreadable: {exc}") from None
    axes = v["axes"] = data.get("axes", "pulse,sample")
    if axes not in ("pulse,sample", "sample,pulse"):
        raise check.fail("data.axes", f'{axes!r}: "pulse,sample" or "sample,pulse"')
    for key in RAW_KEYS if fmt != "raw" else ():
        if key in data:
            raise check.fail(f"data.{key}", f"for raw binary data only, not {fmt}")
    if "variable" in data and fmt not in ("mat5", "mat73"):
        raise check.fail("data.variable", f"for MATLAB files only, not {fmt}")
    v["variable"] = data.get("variable") if fmt in ("mat5", "mat73") else None
    try:
        stored = _stored_shape(check, data, fmt, file, v["variable"])
    except ValueError as exc:
        if str(exc).startswith(f"{path}: "):
            raise
        raise check.fail("data.file", f"{file}: unreadable as {fmt}: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - a reader's every failure: the user's file is bad
        raise check.fail("data.file", f"{file}: unreadable as {fmt}: {exc}") from None
    if len(stored) != 2:
        raise check.fail("data.file", f"{file}: an array of shape {stored}; 2-D is needed")
    shape = v["shape"] = (int(stored[0]), int(stored[1]))[:: 1 if axes == "pulse,sample" else -1]
    if shape[0] < 2:
        raise check.fail("data.file", f"{file}: {shape[0]} pulse(s); at least 2 are needed")
    pulse_samples = v["pulse_length_s"] * v["sample_rate_hz"]
    if pulse_samples > shape[1]:
        why = f"{pulse_samples:.1f} samples, more than the {shape[1]} per pulse of {file.name}"
        raise check.fail("radar.pulse_length_s", why)

    replica = v["replica_file"] = check.file("radar", radar, "replica_file")
    if replica is not None:
        r = check.npy("radar.replica_file", replica)
        if r.ndim != 1 or not np.iscomplexobj(r) or r.size < 2:
            why = f"{r.dtype} {r.shape}: a complex 1-D array is needed"
            raise check.fail("radar.replica_file", f"{replica}: {why}")
    agc = v["agc_db_file"] = check.file("data", data, "agc_db_file")
    if agc is not None:
        g = check.npy("data.agc_db_file", agc)
        if g.shape != shape[:1] or g.dtype.kind not in "iuf" or not np.isfinite(g).all():
            why = f"{g.dtype} {g.shape}: finite gains in dB, one per pulse ({shape[0]}), needed"
            raise check.fail("data.agc_db_file", f"{agc}: {why}")
    v["raw_layout"] = check.raw_layout(data) if fmt == "raw" else {}
    v["extra"] = check.provenance(data)
    v["collection_start"] = _collection_start(check, data)
    return InstrumentFile(path=path, **v)


def _collection_start(check: _Checker, data: dict):
    """``data.collection_start_utc`` (the UTC of time_s = 0) as a naive UTC datetime; None when
    not given (the recording then has no known start, never the import's clock)."""
    if "collection_start_utc" not in data:
        return None
    text = data["collection_start_utc"]
    if isinstance(text, datetime.datetime):  # TOML's own date-time: an offset, or local
        if text.utcoffset() is None:
            raise check.fail("data.collection_start_utc", f"{text}: give its offset, e.g. Z")
        return text.astimezone(datetime.timezone.utc).replace(tzinfo=None)
    try:
        return parse_utc(str(text), "the value")
    except ValueError as exc:
        raise check.fail("data.collection_start_utc", str(exc)) from None
