"""Export a recording as SigMF (Signal Metadata Format 1.x, sigmf.org), with the sigmf package.

``OUT.sigmf-data`` holds the main channel's shots one after the other, ``cf32_le`` (bit for bit
the recording's complex64, but a shot holding NaN/Inf: zeros, counted, as ``process`` images
it).  ``OUT.sigmf-meta`` has one capture per shot, its receive window
(``core:sample_start`` = p·S; ``core:datetime`` = the recording's collection start + the shot's
time, where the recording kept one, rtsar.sources.formats.timebase; the carrier as
``core:frequency``, at most 1 THz by SigMF's schema, and as the global ``rtsar:carrier_hz``),
so generic tools see each gated window as a stream of its own, and one annotation per shot
(``core:sample_start`` = p·S, ``core:sample_count`` = S) under the
``rtsar`` extension namespace: ``rtsar:pulse_index``, ``rtsar:time_s``,
``rtsar:along_track_m`` and, where recorded, ``rtsar:position_m``.  The global object carries
``rtsar:prf_hz``, ``rtsar:chirp`` (kind, bandwidth, duration, rate),
``rtsar:samples_per_shot``, ``rtsar:config`` and ``rtsar:scene`` (JSON objects), and
``rtsar:channels``: every auxiliary channel of a version 2 recording is a SigMF recording of its
own beside it, ``OUT.NAME.sigmf-data``/``-meta`` (its own sample rate and shot length), listed
there by name and file.  rtsar.sources.formats.sigmf_reader reads all of it back.  Also global:
``rtsar:collection_start_utc`` ("unknown" where the recording kept none, as the CPHD export's),
and ``rtsar:provenance``: what ``rtsar import`` recorded of a real instrument's block (its
files, the DC offset removed, the Doppler centroid's source and the data's estimate).

A spotlight recording (rtsar.spot) keeps its geometry in ``rtsar:scene`` and its per-shot
``rtsar:along_track_m`` is the arc position R₀θ_n; each annotation adds the station's position
on the arc, ``rtsar:station_position_m`` (the spotlight frame of rtsar.spot.geometry: x
cross-range, y down-range, z out of the collection plane, origin at the scene centre), and the
bistatic channel's global ``rtsar:receiver_position_m``, so the true geometry travels per shot.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import numpy as np

from ... import __version__
from ...sources.formats.cphd_reader import spot_geometry_of
from ...sources.formats.requirements import require_formats
from ...sources.formats.sigmf_reader import RTSAR_EXTENSION, sigmf_base
from ...sources.formats.timebase import format_utc, shifted
from ..io import replace_when_complete
from .screen import zero_nonfinite

try:
    from sigmf import SigMFFile
except ImportError:  # the optional extra "formats"
    SigMFFile = None

BLOCK = 4096  # shots copied at a time
SIGMF_MAX_FREQUENCY_HZ = 1e12  # the schema's bound on core:frequency


PROVENANCE_ATTRS = (  # what `rtsar import` did to a real instrument's samples, and from what
    "instrument_file",
    "instrument_data_file",
    "instrument_extra",
    "dc_offset_removed",
    "doppler_centroid_source",
    "doppler_centroid_estimated_hz",
    "nonfinite_pulses_zeroed",
)


def provenance_of(rec) -> dict:
    """The recording's provenance attributes (PROVENANCE_ATTRS) as JSON values: a SigMF copy of
    an imported block says where its samples came from and what was done to them."""
    attrs = getattr(rec, "attrs", {})
    out = {}
    for key in PROVENANCE_ATTRS:
        if key in attrs:
            value = attrs[key]
            value = value.tolist() if hasattr(value, "tolist") else value
            if isinstance(value, float) and not np.isfinite(value):
                value = None  # (no estimate: JSON has no NaN)
            extra = key == "instrument_extra" and isinstance(value, str)  # (an h5 attribute)
            out[key] = json.loads(value) if extra else value
    return out


def _chirp(cfg) -> dict:
    wf = cfg.waveform
    duration = getattr(wf, "pulse_duration_s", None) or wf.chirp_duration_s
    return {
        "kind": wf.kind,
        "bandwidth_hz": wf.bandwidth_hz,
        "duration_s": duration,
        "rate_hz_per_s": wf.chirp_rate_hz_per_s,
    }


def _files(base: Path) -> tuple[Path, Path]:
    """(data, metadata) file names of a SigMF recording named ``base``."""
    return base.with_name(base.name + ".sigmf-data"), base.with_name(base.name + ".sigmf-meta")


def _captures(rec, width: int) -> list[dict]:
    """One capture per shot of ``width`` samples: its first sample, carrier and UTC time."""
    carrier = rec.config.geometry.carrier_hz
    # SigMF's schema bounds core:frequency to 1 THz: an optical carrier (lidar) is given only
    # as rtsar:carrier_hz.
    freq = {"core:frequency": carrier} if carrier <= SIGMF_MAX_FREQUENCY_HZ else {}
    start = getattr(rec, "collection_start", None)
    time_s = np.asarray(rec.time_s, np.float64)
    return [
        {
            "core:sample_start": p * width,
            **freq,
            **({} if start is None else {"core:datetime": format_utc(shifted(start, time_s[p]))}),
        }
        for p in range(rec.pulses)
    ]


def _write_channel(files, shots, sample_rate_hz, global_extra, annotations, rec) -> int:
    """Write one SigMF pair to ``files`` = (data, metadata) paths (the temporary ones); returns
    how many shots held NaN/Inf (written as zeros, rtsar.sinks.exports.screen)."""
    data, meta_path = files
    nonfinite = 0
    with open(data, "wb") as f:
        for i in range(0, rec.pulses, BLOCK):
            block, bad = zero_nonfinite(np.asarray(shots[i : i + BLOCK], np.complex64))
            nonfinite += bad
            # f.write, not ndarray.tofile: a full disk is an OSError with its errno (ENOSPC)
            # that names the output; tofile's says only "N requested and M written".
            f.write(np.ascontiguousarray(block, "<c8").data)
    meta = SigMFFile(
        data_file=None,  # written by us beside its final name: none to check or name
        global_info={
            "core:datatype": "cf32_le",
            "core:sample_rate": float(sample_rate_hz),
            "core:recorder": f"rtsar {__version__}",
            "core:description": f"rtsar recording {rec.path.name}",
            "core:extensions": [RTSAR_EXTENSION],
            "rtsar:carrier_hz": rec.config.geometry.carrier_hz,
            **global_extra,
        },
        skip_checksum=True,
    )
    # Captures and annotations (one per shot each, in sample order) set at once: the sigmf
    # package's add_annotation re-sorts the whole list on every call (154 s for 60 000 shots).
    full = dict(meta.ordered_metadata())
    full[SigMFFile.CAPTURE_KEY] = _captures(rec, int(shots.shape[1]))
    full[SigMFFile.ANNOTATION_KEY] = [
        {**md, "core:sample_start": int(start), "core:sample_count": int(length)}
        for start, length, md in sorted(annotations, key=lambda a: a[0])
    ]
    meta.set_metadata(full)
    meta.validate()
    with open(meta_path, "w") as fp:
        meta.dump(fp, pretty=True)
        fp.write("\n")
    return nonfinite


def write_sigmf(rec, path: str | Path) -> dict:
    """Write recording ``rec`` (rtsar.sinks.io.Recording) as SigMF at ``path`` (the base name,
    or a name ending in .sigmf-meta/.sigmf-data); returns the files written."""
    require_formats(SigMFFile, "SigMF export")
    base = sigmf_base(Path(path)) or Path(path)
    with contextlib.ExitStack() as stack:
        # Every file is written beside its name and all are renamed into place when the last is
        # complete (the data files first, then the metadata that describes them): a run that
        # dies leaves the files that were there and no partial one, and an export of a SigMF
        # recording onto itself reads its samples whole (an in-place write truncated them).
        names = [_files(base.with_name(f"{base.name}.{n}")) for n in rec.channels] + [_files(base)]
        order = [m for _, m in names] + [d for d, _ in names]  # renamed in reverse: data first
        tmp = {p: stack.enter_context(replace_when_complete(p)) for p in order}
        files = [(tmp[d], tmp[m]) for d, m in names]
        return _write_all(rec, base, files)


def _write_all(rec, base: Path, files: list) -> dict:
    """The channels' pairs, then the shots' (``files``: their temporary paths, in that order)."""
    cfg = rec.config
    s = cfg.waveform.samples_per_shot
    index = np.asarray(rec.pulse_index, np.int64)
    time_s = np.asarray(rec.time_s, np.float64)
    along = rec.start_along_track_m + cfg.geometry.along_track_step_m * np.arange(rec.pulses)
    position = rec.position_m
    spot = spot_geometry_of(rec.scene, rec.path)
    station = None if spot is None else spot.station_m()
    if station is not None and len(station) != rec.pulses:
        raise ValueError(
            f"{rec.path}: {rec.pulses} shots, the spotlight geometry plans {len(station)}"
        )
    channels, nonfinite = [], {}
    start = getattr(rec, "collection_start", None)
    for (name, ds), pair in zip(rec.channels.items(), files, strict=False):
        width = ds.shape[1]
        cbase = base.with_name(f"{base.name}.{name}")
        rate = cfg.waveform.sample_rate_hz * width / s
        extra = {"rtsar:channel": name, "rtsar:samples_per_shot": int(width)}
        if spot is not None and spot.bistatic and name == "bistatic":
            extra["rtsar:receiver_position_m"] = [float(v) for v in spot.receiver_m()]
        nonfinite[name] = _write_channel(
            pair,
            ds,
            rate,
            extra,
            [(p * width, width, {"rtsar:pulse_index": int(index[p])}) for p in range(rec.pulses)],
            rec,
        )
        channels.append({"name": name, "file": cbase.name, "samples_per_shot": int(width)})
    annotations = []
    for p in range(rec.pulses):
        md = {
            "rtsar:pulse_index": int(index[p]),
            "rtsar:time_s": float(time_s[p]),
            "rtsar:along_track_m": float(along[p]),
        }
        if position is not None:
            md["rtsar:position_m"] = [float(v) for v in position[p]]
        if station is not None:
            md["rtsar:station_position_m"] = [float(v) for v in station[p]]
        annotations.append((p * s, s, md))
    nonfinite["main"] = _write_channel(
        files[-1],
        rec.shots,
        cfg.waveform.sample_rate_hz,
        {
            "rtsar:prf_hz": cfg.geometry.prf_hz,
            "rtsar:chirp": _chirp(cfg),
            "rtsar:samples_per_shot": int(s),
            "rtsar:config": cfg.to_dict(),
            "rtsar:scene": json.loads(json.dumps(rec.scene or {})),
            "rtsar:start_along_track_m": float(rec.start_along_track_m),
            "rtsar:channels": channels,
            "rtsar:collection_start_utc": "unknown" if start is None else format_utc(start),
            "rtsar:provenance": provenance_of(rec),
        },
        annotations,
        rec,
    )
    return {
        "base": str(base),
        "start_known": start is not None,
        "shots": rec.pulses,
        "channels": [c["name"] for c in channels],
        "nonfinite": {name: n for name, n in nonfinite.items() if n},
    }
