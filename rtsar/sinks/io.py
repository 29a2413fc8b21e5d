"""Recording files (HDF5).  Layouts: docs/pages/reference/files.md.

Recording (``rtsar simulate``):  /shots complex64 [pulse, sample], /pulse_index int64 [pulse],
/time_s float64 [pulse], /along_track_m float64 [pulse], and (format version 2) one dataset
/channels/NAME complex64 [pulse, sample] per auxiliary channel of the shot (second receiver,
reference interferometer, HCN cell, reference-region receivers, modulation channels), and
/position_m float64 [pulse, 3] (x along track, y cross-track, z above the reference plane)
where the geometry has a platform height; attributes format="rtsar-recording", format_version,
config (JSON of the effective configuration), scene (JSON), channels (JSON list of {name,
samples_per_shot, sample_rate_hz, dtype}; version 2), rtsar_version.  Version 1 files (main
channel only) still read.  A size declared is checked before a read (rtsar.sinks.declared).

Image files are rtsar.sinks.image_file; the helpers both share (file checks, an output's
temporary name until complete) are here.  Complex values: HDF5 compounds of floats r and i.
"""

from __future__ import annotations

import datetime
import json
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from .. import __version__
from ..params import Config, config_from_dict
from ..scene.model import Scene, recorded_scene
from ..sources.formats.foreign import telemetry_problem
from ..sources.formats.timebase import format_utc, parse_utc, utc_now
from ..sources.rows import Rows
from .declared import check_read, read_checked, readable_rows, stored_rows
from .h5_open import open_for_reading
from .h5_output import H5Output, WriteFailed, is_write_error, reason
from .name_claim import NameClaim
from .partials import partial_prefix

RECORDING_FORMAT = "rtsar-recording"
IMAGE_FORMAT = "rtsar-image"
FORMAT_VERSION = 1  # images (rtsar.sinks.image_file)
RECORDING_VERSION = 2  # 2: auxiliary channels under /channels


def check_writable(path: str | Path) -> None:
    """ValueError now, before any work, when ``path`` could not be written later (its folder is
    missing or not writable, or it is a folder)."""
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise ValueError(f"cannot write {path}: it is a folder")
    if not folder.is_dir():
        raise ValueError(f"cannot write {path}: the folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ValueError(f"cannot write {path}: permission denied")


@contextmanager
def replace_when_complete(path: str | Path) -> Iterator[Path]:
    """Write to a temporary file beside ``path``, renamed to ``path`` only when the block ends
    without an exception; otherwise removed, so an existing ``path`` stays as it was and no
    partial file is left under its name (a partial recording or batch image has no value).
    A write the disk refused (:class:`~rtsar.sinks.h5_output.WriteFailed`, or an OSError
    ENOSPC, EDQUOT, EFBIG, EROFS) becomes ``WriteFailed``: ``cannot write PATH: REASON``.

    The temporary file is created at once: an unwritable destination is reported before any
    work is done.  Temporaries of ``path`` that killed runs left are removed first
    (rtsar.sinks.partials.remove_stale_partials).  The name is claimed for the whole write
    (rtsar.sinks.name_claim): a name a live writer holds is refused (ValueError), and a live
    writer starting meanwhile is refused it, so neither replaces the other's file.
    """
    path = Path(path)
    claim = NameClaim(path)  # (removes the stale temporaries)
    try:
        # The suffix kept: writers that go by it (matplotlib's savefig) see the right kind.
        fd, name = tempfile.mkstemp(
            prefix=partial_prefix(path), suffix=path.suffix, dir=path.parent
        )
    except OSError as exc:
        claim.release()
        raise ValueError(f"cannot write {path}: {exc.strerror or exc}") from None
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        # mkstemp makes the file owner-only; the finished file gets the mode any new file would.
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except WriteFailed as exc:  # told of the output, not of its temporary name
        tmp.unlink(missing_ok=True)
        raise (exc.naming(path) if exc.path == tmp else exc) from None
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if is_write_error(exc):  # a full disk under any writer: one line naming the output
            raise WriteFailed(path, reason(exc)) from None
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        claim.release()


def write_text_when_complete(path: str | Path, text: str) -> None:
    """``path.write_text(text)`` through :func:`replace_when_complete` (UTF-8)."""
    with replace_when_complete(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def describe_channels(config: Config, widths: dict[str, int]) -> str:
    """The ``channels`` attribute of a recording: JSON list of {name, samples_per_shot,
    sample_rate_hz, dtype} of each auxiliary channel (``widths``: name → samples per shot)."""
    fs, n = config.waveform.sample_rate_hz, config.waveform.samples_per_shot
    # every channel spans the shot's sweep: its rate scales with its length
    return json.dumps(
        [
            dict(name=name, samples_per_shot=int(w), sample_rate_hz=fs * w / n, dtype="complex64")
            for name, w in sorted(widths.items())
        ]
    )


class RecordingWriter:
    """Append shots (and their auxiliary channels) to a new recording; a context manager.

    The auxiliary channels are fixed by the first ``write``: every later write must carry the
    same names and lengths (ValueError otherwise), so no channel is ever silently dropped.
    ``collection_start`` (naive UTC; default: now) is the time of ``time_s`` = 0, kept as
    ``collection_start_utc`` (rtsar.sources.formats.timebase); ``"unknown"``: none kept.
    """

    def __init__(
        self,
        path: str | Path,
        config: Config,
        scene: dict | None = None,
        chunk_pulses: int = 64,
        collection_start=None,
    ):
        self.path = Path(path)
        self._out = H5Output(self.path)  # a failed write: WriteFailed, never a crash
        with self._out.writing():
            self._create(config, scene, chunk_pulses)
            if collection_start != "unknown":
                self._f.attrs["collection_start_utc"] = format_utc(collection_start or utc_now())

    def _create(self, config: Config, scene: dict | None, chunk_pulses: int) -> None:
        self._f = self._out.file
        s = config.waveform.samples_per_shot
        chunk = max(1, min(chunk_pulses, 1024))
        self._shots = self._f.create_dataset(
            "shots", (0, s), np.complex64, maxshape=(None, s), chunks=(chunk, s)
        )
        self._meta = {
            name: self._f.create_dataset(name, (0,), dtype, maxshape=(None,), chunks=(4096,))
            for name, dtype in (
                ("pulse_index", np.int64),
                ("time_s", np.float64),
                ("along_track_m", np.float64),
            )
        }
        a = self._f.attrs
        a["format"] = RECORDING_FORMAT
        a["format_version"] = RECORDING_VERSION
        a["config"] = json.dumps(config.to_dict())
        a["scene"] = json.dumps(scene or {})
        a["rtsar_version"] = __version__
        self._config = config
        self._chunk = chunk
        # Per-pulse 3-D platform position where the geometry has one (a platform height above
        # the reference plane): x along track, y cross-track, z up (rtsar.scene.relief's frame).
        self._position = None
        if config.geometry.platform_height_m > 0:
            self._position = self._f.create_dataset(
                "position_m", (0, 3), np.float64, maxshape=(None, 3), chunks=(4096, 3)
            )
        self._channels: dict[str, h5py.Dataset] | None = None  # fixed by the first write
        self.pulses = 0

    @property
    def channel_names(self) -> list[str]:
        """The auxiliary channels written (empty before the first write)."""
        return sorted(self._channels or {})

    def _make_channels(self, aux: dict) -> None:
        self._channels = {}
        group = self._f.create_group("channels")
        widths = {name: np.asarray(aux[name]).shape[-1] for name in sorted(aux)}
        for name, width in widths.items():
            self._channels[name] = group.create_dataset(
                name, (0, width), np.complex64, maxshape=(None, width), chunks=(self._chunk, width)
            )
        self._f.attrs["channels"] = describe_channels(self._config, widths)

    def write(
        self, samples: np.ndarray, pulse_index, time_s, along_track_m, aux: dict | None = None
    ) -> None:
        """Append shots; ``aux`` maps each auxiliary channel's name to [pulse, sample]."""
        samples = np.atleast_2d(samples)
        n = len(samples)
        aux = aux or {}
        if self._channels is None:
            with self._out.writing():
                self._make_channels(aux)
        if set(aux) != set(self._channels):
            raise ValueError(
                f"auxiliary channels {sorted(aux)} differ from the recording's "
                f"{sorted(self._channels)}"
            )
        end = self.pulses + n
        if samples.shape[1:] != self._shots.shape[1:]:
            raise ValueError(f"shots {samples.shape}, the recording's have {self._shots.shape[1]}")
        channels = {name: np.asarray(aux[name]) for name in self._channels}
        for name, values in channels.items():  # every check before any dataset grows
            width = self._channels[name].shape[1]
            if values.shape != (n, width):
                raise ValueError(f"channel {name!r}: {values.shape} for {n} shots of {width}")
        with self._out.writing():
            self._append(samples, pulse_index, time_s, along_track_m, channels, end)
        self.pulses = end

    def _append(self, samples, pulse_index, time_s, along_track_m, channels, end) -> None:
        n = end - self.pulses
        for name, ds in self._channels.items():
            ds.resize(end, axis=0)
            ds[self.pulses : end] = channels[name]
        self._shots.resize(end, axis=0)
        self._shots[self.pulses : end] = samples
        for name, values in (
            ("pulse_index", pulse_index),
            ("time_s", time_s),
            ("along_track_m", along_track_m),
        ):
            ds = self._meta[name]
            ds.resize(end, axis=0)
            ds[self.pulses : end] = np.atleast_1d(values)
        if self._position is not None:
            xyz = np.zeros((n, 3))
            xyz[:, 0] = np.atleast_1d(along_track_m)
            xyz[:, 2] = self._config.geometry.platform_height_m
            self._position.resize(end, axis=0)
            self._position[self.pulses : end] = xyz

    def close(self) -> None:
        """Close the file; WriteFailed when its last bytes cannot be written (then, and after
        any failed write, the file is closed once and left as it is)."""
        self._out.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


@dataclass
class Recording:
    """An open recording, checked: every dataset present, one entry per shot, shots of the
    configured length, pulse numbers increasing, positions on the configured step."""

    path: Path
    config: Config
    scene: dict
    pulses: int
    start_along_track_m: float
    _file: h5py.File
    pulse_index: np.ndarray | None = None  # int64[pulse]
    time_s: np.ndarray | None = None  # float64[pulse]
    channels: dict = field(default_factory=dict)  # auxiliary channel name → dataset
    collection_start: datetime.datetime | None = None  # UTC of time_s = 0 (None: not kept)

    @property
    def attrs(self) -> dict:
        """The file's attributes (a live recording's: complete, record_dropped, …)."""
        return dict(self._file.attrs)

    @property
    def pulse_flags(self) -> np.ndarray | None:
        """A live recording's per-pulse flags (uint8 [pulse]; rtsar.sinks.raw_record: 1 a zero
        pulse ingest inserted, 2 a shot ingest zeroed, 4 not recorded); None where not kept."""
        flags = self._file.get("pulse_flags")
        flags = None if flags is None else read_checked(flags, self.pulses, self.path)
        if flags is not None and len(flags) != self.pulses:
            raise ValueError(f"{self.path}: pulse_flags has {len(flags)} rows, not {self.pulses}")
        return None if flags is None else np.asarray(flags, np.uint8)

    @property
    def position_m(self) -> np.ndarray | None:
        """Per-pulse platform position [pulse, (x, y, z)] in metres; None where not recorded."""
        return self._file["position_m"][...] if "position_m" in self._file else None

    @property
    def shots(self):
        """The shots dataset [pulse, sample] (read lazily, block by block)."""
        shots = self._file["shots"]
        return shots if shots.shape[0] == self.pulses else Rows(shots, self.pulses)

    def batches(self, size: int) -> Iterator[np.ndarray]:
        """Shots in blocks of ``size`` pulses (the last block may be shorter)."""
        shots = self.shots  # (a recording cut short: its whole rows, not the rows beyond)
        for i in range(0, self.pulses, size):
            yield shots[i : i + size]

    def batches_with_aux(self, size: int, names=()) -> Iterator[tuple[np.ndarray, dict]]:
        """(shots, {channel: samples}) in blocks of ``size`` pulses; only the channels
        ``names`` are read (an oversampled HCN channel is 8× the shots' bytes)."""
        shots = self.shots
        for i in range(0, self.pulses, size):
            yield shots[i : i + size], {n: self.channels[n][i : i + size] for n in names}

    def scene_object(self) -> Scene | None:
        """The recorded scene as an rtsar.scene.Scene (None when the recording has none)."""
        return recorded_scene(self.scene, self.path)

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# What a file of the other kind is for, said where it was given for one (a new user's trial).
_FOCUS_IT = "; a recording: `rtsar process REC.h5 -o IMG.h5` focuses it"
_DRAW_IT = "; an image: `rtsar quicklook` draws it, `rtsar export IMG.h5 --sicd F` writes SICD"
_KIND_HINTS = {("rtsar-image", "rtsar-recording"): _FOCUS_IT}
_KIND_HINTS[("rtsar-recording", "rtsar-image")] = _DRAW_IT


def open_checked(path: str | Path, fmt: str) -> h5py.File:
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: no such file")
    f = open_for_reading(path)
    found = f.attrs.get("format")
    if found != fmt:
        f.close()
        hint = _KIND_HINTS.get((fmt, found), "")
        raise ValueError(f"{path}: expected an {fmt} file, found format={found!r}{hint}")
    newest = RECORDING_VERSION if fmt == RECORDING_FORMAT else FORMAT_VERSION
    if int(f.attrs.get("format_version", -1)) > newest:
        f.close()
        raise ValueError(f"{path}: format_version newer than this rtsar understands")
    return f


def _json_attr(f: h5py.File, name: str, default=None) -> dict:
    if name not in f.attrs:
        if default is not None:
            return default
        raise ValueError(f"the attribute {name!r} is missing")
    text = f.attrs[name]
    try:
        value = json.loads(text.decode() if isinstance(text, bytes) else str(text))
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"the attribute {name!r} is not JSON ({exc})") from None
    if not isinstance(value, dict):
        raise ValueError(f"the attribute {name!r} is not a JSON object")
    return value


def _dataset(f: h5py.File, name: str, ndim: int, kind: str) -> h5py.Dataset:
    if name not in f or not isinstance(f[name], h5py.Dataset):
        raise ValueError(f"the dataset {name!r} is missing")
    ds = f[name]
    kinds = {"complex": np.complexfloating, "int": np.integer, "float": np.floating}
    if ds.ndim != ndim or not np.issubdtype(ds.dtype, kinds[kind]):
        raise ValueError(f"the dataset {name!r} must be {ndim}-D {kind}, got {ds.shape} {ds.dtype}")
    return ds


def open_recording(path: str | Path) -> Recording:
    """Open and check a recording; ValueError naming the file and what is wrong with it."""
    f = open_checked(path, RECORDING_FORMAT)
    try:
        cfg = config_from_dict(_json_attr(f, "config"))
        scene = _json_attr(f, "scene", {})
        shots = _dataset(f, "shots", 2, "complex")
        pulses, samples = shots.shape
        if samples != cfg.waveform.samples_per_shot:
            raise ValueError(
                f"shots hold {samples} samples per shot; the configuration's waveform has "
                f"{cfg.waveform.samples_per_shot}"
            )
        names = (("pulse_index", "int"), ("time_s", "float"), ("along_track_m", "float"))
        meta = {name: _dataset(f, name, 1, kind) for name, kind in names}
        cut_short = not f.attrs.get("complete", True)  # a live recording cut short, or growing
        if cut_short:
            pulses = _whole_rows(f, meta)
        meta = {name: read_checked(ds, pulses) for name, ds in meta.items()}
        for name, values in meta.items():
            if len(values) != pulses:
                raise ValueError(f"{name} has {len(values)} entries for {pulses} shots")
            if not np.isfinite(values).all():
                raise ValueError(f"{name} holds non-finite values")
        channels = _channels(f, pulses, cut_short)
        if "position_m" in f:
            pos = _dataset(f, "position_m", 2, "float")
            if pos.shape != (pulses, 3):
                raise ValueError(f"position_m must be [{pulses}, 3], got {pos.shape}")
            check_read(pos)  # (its property reads it whole)
        problem = telemetry_problem(cfg, meta["pulse_index"], meta["along_track_m"])
        if problem:
            raise ValueError(problem)
        kept = f.attrs.get("collection_start_utc")
        collection_start = None if kept is None else parse_utc(kept)
    except (ValueError, KeyError, TypeError, OSError) as exc:
        f.close()
        raise ValueError(f"{path}: {exc}") from None
    start = float(meta["along_track_m"][0]) if pulses else 0.0
    return Recording(
        Path(path),
        cfg,
        scene,
        pulses,
        start,
        f,
        meta["pulse_index"],
        meta["time_s"],
        channels,
        collection_start,
    )


def _whole_rows(f: h5py.File, meta: dict) -> int:
    """The rows of a live recording (rtsar.sinks.raw_record) written whole: its writer killed
    (or still writing) may have grown some datasets further than others, and rows it had not
    finished read as zeros; ``pulse_index``, written last and counting 0, 1, 2, … there,
    says which rows are complete; a row its file does not store, or HDF5 cannot read, is not."""
    group = f["channels"] if isinstance(f.get("channels"), h5py.Group) else {}
    datasets = [f["shots"], *meta.values(), *group.values()]
    rows = readable_rows(datasets, min(stored_rows(meta["pulse_index"]), *map(len, datasets)))
    index = read_checked(meta["pulse_index"], rows)
    wrong = np.flatnonzero(index != index[0] + np.arange(rows)) if rows else []
    return int(wrong[0]) if len(wrong) else rows


def _channels(f: h5py.File, pulses: int, cut_short: bool = False) -> dict:
    """The auxiliary channel datasets of a version 2 recording, checked against ``channels``
    (``cut_short``: a live recording's, possibly longer than its whole rows)."""
    described = json.loads(f.attrs["channels"]) if "channels" in f.attrs else []
    if not isinstance(described, list) or not all(
        isinstance(c, dict) and isinstance(c.get("name"), str) for c in described
    ):
        raise ValueError("the attribute 'channels' must be a JSON list of {name, ...} objects")
    group = f.get("channels")
    found = sorted(group) if isinstance(group, h5py.Group) else []
    names = sorted(c["name"] for c in described)
    if found != names:
        raise ValueError(f"channels listed {names} but datasets under /channels are {found}")
    out = {}
    for name in names:
        ds = _dataset(group, name, 2, "complex")
        if ds.shape[0] != pulses and not (cut_short and ds.shape[0] > pulses):
            raise ValueError(f"channel {name!r} has {ds.shape[0]} shots for {pulses}")
        out[name] = ds if ds.shape[0] == pulses else Rows(ds, pulses)
    return out
