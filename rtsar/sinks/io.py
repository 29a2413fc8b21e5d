"""Recording and image files (HDF5).  Layouts are documented in README.md ("File formats").

Recording (``rtsar simulate``):  /shots complex64 [pulse, sample], /pulse_index int64 [pulse],
/time_s float64 [pulse], /along_track_m float64 [pulse], and (format version 2) one dataset
/channels/NAME complex64 [pulse, sample] per auxiliary channel of the shot (second receiver,
reference interferometer, HCN cell, reference-region receivers, modulation channels), and
/position_m float64 [pulse, 3] (x along track, y cross-track, z above the reference plane)
where the geometry has a platform height;
attributes format="rtsar-recording", format_version, config (JSON of the effective
configuration), scene (JSON), channels (JSON list of {name, samples_per_shot, sample_rate_hz,
dtype}; version 2), rtsar_version.  Version 1 files (main channel only) still read.

Image (``rtsar process``):  /image complex64 [azimuth, range], /azimuth_m, /range_m float64;
attributes format="rtsar-image", format_version, config (JSON), source, lens, correlator,
nonfinite_pulses (shots zeroed because they held NaN/Inf), complete (False while a stream is
written and in a file whose writer was killed).  With height strips (``--height insal``):
/height_m float32 [azimuth, range], /height_valid uint8 (1: coherent and unwrapped) and
/coherence float32, rows aligned with /image's.
Complex values are HDF5 compounds of two floats named r and i (h5py's convention).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from .. import __version__
from ..params import Config, config_from_dict
from ..scene.model import Scene, scene_from_dict

RECORDING_FORMAT = "rtsar-recording"
IMAGE_FORMAT = "rtsar-image"
FORMAT_VERSION = 1  # images
RECORDING_VERSION = 2  # 2: auxiliary channels under /channels


@contextmanager
def replace_when_complete(path: str | Path) -> Iterator[Path]:
    """Write to a temporary file beside ``path``, renamed to ``path`` only when the block ends
    without an exception; otherwise removed, so an existing ``path`` stays as it was and no
    partial file is left under its name (a partial recording or batch image has no value).

    The temporary file is created at once: an unwritable destination is reported before any
    work is done.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.partial-{os.getpid()}")
    try:
        tmp.open("xb").close()
    except OSError as exc:
        raise ValueError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        yield tmp
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)


class RecordingWriter:
    """Append shots (and their auxiliary channels) to a new recording; a context manager.

    The auxiliary channels are fixed by the first ``write``: every later write must carry the
    same names and lengths (ValueError otherwise), so no channel is ever silently dropped.
    """

    def __init__(
        self, path: str | Path, config: Config, scene: dict | None = None, chunk_pulses: int = 64
    ):
        self.path = Path(path)
        self._f = h5py.File(self.path, "w")
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
        wf = self._config.waveform
        self._channels, described = {}, []
        group = self._f.create_group("channels")
        for name in sorted(aux):
            width = np.asarray(aux[name]).shape[-1]
            self._channels[name] = group.create_dataset(
                name, (0, width), np.complex64, maxshape=(None, width), chunks=(self._chunk, width)
            )
            described.append(
                {
                    "name": name,
                    "samples_per_shot": int(width),
                    # every channel spans the shot's sweep: its rate scales with its length
                    "sample_rate_hz": wf.sample_rate_hz * width / wf.samples_per_shot,
                    "dtype": "complex64",
                }
            )
        self._f.attrs["channels"] = json.dumps(described)

    def write(
        self, samples: np.ndarray, pulse_index, time_s, along_track_m, aux: dict | None = None
    ) -> None:
        """Append shots; ``aux`` maps each auxiliary channel's name to [pulse, sample]."""
        samples = np.atleast_2d(samples)
        n = len(samples)
        aux = aux or {}
        if self._channels is None:
            self._make_channels(aux)
        if set(aux) != set(self._channels):
            raise ValueError(
                f"auxiliary channels {sorted(aux)} differ from the recording's "
                f"{sorted(self._channels)}"
            )
        end = self.pulses + n
        for name, ds in self._channels.items():
            values = np.asarray(aux[name])
            if values.shape != (n, ds.shape[1]):
                raise ValueError(
                    f"channel {name!r}: {values.shape} for {n} shots of {ds.shape[1]} samples"
                )
            ds.resize(end, axis=0)
            ds[self.pulses : end] = values
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
        self.pulses = end

    def close(self) -> None:
        if self._f.id.valid:
            self._f.close()

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

    @property
    def position_m(self) -> np.ndarray | None:
        """Per-pulse platform position [pulse, (x, y, z)] in metres; None where not recorded."""
        return self._file["position_m"][...] if "position_m" in self._file else None

    @property
    def shots(self):
        """The shots dataset [pulse, sample] (read lazily, block by block)."""
        return self._file["shots"]

    def batches(self, size: int) -> Iterator[np.ndarray]:
        """Shots in blocks of ``size`` pulses (the last block may be shorter)."""
        for shots, _ in self.batches_with_aux(size):
            yield shots

    def batches_with_aux(self, size: int) -> Iterator[tuple[np.ndarray, dict]]:
        """(shots, {channel: samples}) in blocks of ``size`` pulses, every channel read."""
        shots = self._file["shots"]
        for i in range(0, self.pulses, size):
            aux = {name: ds[i : i + size] for name, ds in self.channels.items()}
            yield shots[i : i + size], aux

    def scene_object(self) -> Scene | None:
        """The recorded scene as an rtsar.scene.Scene (None when the recording has none)."""
        if not self.scene:
            return None
        try:
            return scene_from_dict(self.scene, name=self.scene.get("name", "scene"))
        except (ValueError, TypeError) as exc:
            raise ValueError(f"{self.path}: the recorded scene does not parse ({exc})") from None

    def close(self) -> None:
        self._file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def _open(path: str | Path, fmt: str) -> h5py.File:
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: no such file")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        try:  # an image still being written by a live stream (crash-safe SWMR mode)
            f = h5py.File(path, "r", swmr=True)
        except OSError:
            raise ValueError(f"{path}: not an HDF5 file ({exc})") from None
    found = f.attrs.get("format")
    if found != fmt:
        f.close()
        raise ValueError(f"{path}: expected an {fmt} file, found format={found!r}")
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
    f = _open(path, RECORDING_FORMAT)
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
        meta = {
            name: _dataset(f, name, 1, kind)[...]
            for name, kind in (
                ("pulse_index", "int"),
                ("time_s", "float"),
                ("along_track_m", "float"),
            )
        }
        for name, values in meta.items():
            if len(values) != pulses:
                raise ValueError(f"{name} has {len(values)} entries for {pulses} shots")
            if not np.isfinite(values).all():
                raise ValueError(f"{name} holds non-finite values")
        channels = _channels(f, pulses)
        if "position_m" in f:
            pos = _dataset(f, "position_m", 2, "float")
            if pos.shape != (pulses, 3):
                raise ValueError(f"position_m must be [{pulses}, 3], got {pos.shape}")
        if pulses > 1 and not np.all(np.diff(meta["pulse_index"]) > 0):
            raise ValueError("pulse_index must increase from shot to shot")
        if pulses > 1:
            # Shot 0's position and the step define the image's azimuth axis; a recording whose
            # positions do not follow the configured step is refused rather than mis-labelled.
            steps = np.diff(meta["along_track_m"])
            if not np.allclose(steps, cfg.geometry.along_track_step_m, rtol=1e-6, atol=0):
                raise ValueError("along_track_m does not advance by the configured step")
    except (ValueError, KeyError, TypeError, OSError) as exc:
        f.close()
        raise ValueError(f"{path}: {exc}") from None
    start = float(meta["along_track_m"][0]) if pulses else 0.0
    return Recording(
        Path(path), cfg, scene, pulses, start, f, meta["pulse_index"], meta["time_s"], channels
    )


def _channels(f: h5py.File, pulses: int) -> dict:
    """The auxiliary channel datasets of a version 2 recording, checked against ``channels``."""
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
        if ds.shape[0] != pulses:
            raise ValueError(f"channel {name!r} has {ds.shape[0]} shots for {pulses}")
        out[name] = ds
    return out


def write_image(
    path: str | Path,
    image: np.ndarray,
    azimuth_m: np.ndarray,
    range_m: np.ndarray,
    config: Config,
    **attrs,
) -> None:
    with h5py.File(path, "w") as f:
        f.create_dataset("image", data=np.asarray(image, np.complex64))
        f.create_dataset("azimuth_m", data=np.asarray(azimuth_m, np.float64))
        f.create_dataset("range_m", data=np.asarray(range_m, np.float64))
        f.attrs["format"] = IMAGE_FORMAT
        f.attrs["format_version"] = FORMAT_VERSION
        f.attrs["config"] = json.dumps(config.to_dict())
        f.attrs["rtsar_version"] = __version__
        for k, v in attrs.items():
            f.attrs[k] = v


def read_image(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    with _open(path, IMAGE_FORMAT) as f:
        return (f["image"][...], f["azimuth_m"][...], f["range_m"][...], dict(f.attrs))


def read_heights(path: str | Path) -> tuple[np.ndarray, np.ndarray] | None:
    """(height_m float32 [azimuth, range], valid bool) of an image file; None without heights.

    Rows the height strips have not reached yet (a stream cut short) are invalid."""
    with _open(path, IMAGE_FORMAT) as f:
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
    is set up under a temporary name and takes its own name once it is in that state, so no
    half-made file ever carries the name.  Readers can open it while it is written.
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
        **attrs,
    ):
        self.path = Path(path)
        self.crash_safe = crash_safe
        self.flush_every_s = float(flush_every_s)
        target = (
            self.path.with_name(f".{self.path.name}.partial-{os.getpid()}")
            if crash_safe
            else self.path
        )
        libver = ("v110", "v110") if crash_safe else None
        self._f = h5py.File(target, "w", libver=libver)
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
        self.height_lines = 0  # rows of height_m written (the highest row + 1)
        a = self._f.attrs
        a["format"] = IMAGE_FORMAT
        a["format_version"] = FORMAT_VERSION
        a["config"] = json.dumps(config.to_dict())
        a["rtsar_version"] = __version__
        a["complete"] = False
        for k, v in attrs.items():
            a[k] = v
        if crash_safe:
            self._f.swmr_mode = True  # from here on the file on disk is always readable
            os.replace(target, self.path)
        self._flushed_s = time.monotonic()
        self.lines = 0

    def write(self, lines: np.ndarray, azimuth_m: np.ndarray) -> None:
        end = self.lines + len(lines)
        self._image.resize(end, axis=0)
        self._image[self.lines : end] = lines
        self._azimuth.resize(end, axis=0)
        self._azimuth[self.lines : end] = azimuth_m
        self.lines = end
        if self.crash_safe and time.monotonic() - self._flushed_s >= self.flush_every_s:
            self._f.flush()
            self._flushed_s = time.monotonic()

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
        if end > self._height.shape[0]:
            for ds in (self._height, self._valid, self._coherence):
                ds.resize(end, axis=0)
        self._height[row:end] = np.where(valid, height_m, 0.0)
        self._valid[row:end] = valid
        self._coherence[row:end] = 0.0 if coherence is None else coherence
        self.height_lines = max(self.height_lines, end)

    def close(self, **attrs) -> None:
        """Close with the final attributes; ``complete`` True unless ``complete=False`` given."""
        if not self._f.id.valid:
            return
        attrs.setdefault("complete", True)
        if self.crash_safe:
            # Attributes cannot be added in SWMR mode: close (the data is safe from here on),
            # reopen in normal mode for the final attributes.
            self._f.close()
            self._f = h5py.File(self.path, "r+")
        for k, v in attrs.items():
            self._f.attrs[k] = v
        self._f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close(complete=exc[0] is None)
