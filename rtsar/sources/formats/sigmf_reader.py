"""Read a SigMF recording (sigmf.org, 1.x) as rtsar shots, with the sigmf package.

The layout rtsar.sinks.exports.sigmf_export writes: ``cf32_le`` samples, shots of
``rtsar:samples_per_shot`` one after the other, the processing configuration in ``rtsar:config``
(or, for a recording made elsewhere, a configuration given by the caller), one annotation per
shot with ``rtsar:pulse_index`` / ``rtsar:time_s`` (missing: the shot number and p / PRF), and
the auxiliary channels listed in ``rtsar:channels``.  The samples are memory-mapped, never
converted: shots come back bit for bit.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ...params import config_from_dict
from .foreign import ForeignRecording, check_telemetry
from .requirements import require_formats

try:
    from sigmf import sigmffile
except ImportError:  # the optional extra "formats"
    sigmffile = None

RTSAR_EXTENSION = {"name": "rtsar", "version": "1.0.0", "optional": True}
SUFFIXES = (".sigmf-meta", ".sigmf-data", ".sigmf")


def sigmf_base(path: Path) -> Path | None:
    """The base name of a SigMF recording named by any of its files; None if not SigMF."""
    path = Path(path)
    for suffix in SUFFIXES:
        if path.name.lower().endswith(suffix):
            return path.with_name(path.name[: -len(suffix)])
    return None


def _load(base: Path):
    meta = base.with_name(base.name + ".sigmf-meta")
    if not meta.exists():
        raise ValueError(f"{meta}: no such file")
    try:
        handle = sigmffile.fromfile(str(meta), skip_checksum=True)
    except Exception as exc:  # sigmf raises its own error kinds on a malformed file
        raise ValueError(f"{meta}: not a SigMF recording ({exc})") from None
    g = handle.get_global_info()
    if g.get("core:datatype") != "cf32_le":
        raise ValueError(f"{meta}: core:datatype {g.get('core:datatype')!r}, rtsar reads cf32_le")
    if int(g.get("core:num_channels", 1)) != 1:
        raise ValueError(f"{meta}: interleaved channels are not read (one channel per file)")
    data = base.with_name(base.name + ".sigmf-data")
    if not data.exists():
        raise ValueError(f"{data}: no such file")
    return g, handle.get_annotations(), np.memmap(data, "<c8", mode="r")


def _shots(samples: np.ndarray, width: int, path) -> np.ndarray:
    if width < 1 or samples.size % width:
        raise ValueError(f"{path}: {samples.size} samples are not whole shots of {width}")
    return samples.reshape(-1, width)


def auxiliary_of(global_info: dict, base: Path) -> Path | None:
    """The base name of the recording whose auxiliary channel this SigMF file holds (an
    ``rtsar:channel`` file of an export, named ``BASE.CHANNEL``); None for a recording."""
    name = global_info.get("rtsar:channel")
    if not isinstance(name, str):
        return None
    suffix = "." + name
    main = base.name[: -len(suffix)] if base.name.endswith(suffix) else base.name
    return base.with_name(main)


def open_sigmf(path: str | Path, config=None) -> ForeignRecording:
    """Open a SigMF recording; ``config`` (rtsar.params.Config) where it carries none."""
    require_formats(sigmffile, "reading SigMF")
    base = sigmf_base(Path(path)) or Path(path)
    g, annotations, samples = _load(base)
    main = auxiliary_of(g, base)
    if main is not None:
        raise ValueError(
            f"{base}.sigmf-meta holds the auxiliary channel {g['rtsar:channel']!r} of a SigMF "
            f"export, not a recording: give its recording, {main}.sigmf-meta"
        )
    try:
        if "rtsar:config" in g:
            cfg = config_from_dict(g["rtsar:config"])
        elif config is not None:
            cfg = config
        else:
            raise ValueError(
                "no rtsar:config in the global object: rtsar reads the SigMF recordings that "
                "carry their configuration (`rtsar export --sigmf` writes it)"
            )
        width = int(g.get("rtsar:samples_per_shot", cfg.waveform.samples_per_shot))
        if width != cfg.waveform.samples_per_shot:
            raise ValueError(
                f"shots of {width} samples; the configuration's waveform has "
                f"{cfg.waveform.samples_per_shot}"
            )
        shots = _shots(samples, width, base)
        pulses = len(shots)
        per_shot = [a for a in annotations if "rtsar:pulse_index" in a]
        if per_shot and len(per_shot) != pulses:
            raise ValueError(f"{len(per_shot)} shot annotations for {pulses} shots")
        if per_shot:
            per_shot.sort(key=lambda a: a["core:sample_start"])
            index = np.array([a["rtsar:pulse_index"] for a in per_shot], np.int64)
            time_s = np.array([a["rtsar:time_s"] for a in per_shot], np.float64)
        else:
            index = np.arange(pulses, dtype=np.int64)
            time_s = index / cfg.geometry.prf_hz
        start = float(g.get("rtsar:start_along_track_m", 0.0))
        step = cfg.geometry.along_track_step_m
        along = (
            np.array([a["rtsar:along_track_m"] for a in per_shot])
            if per_shot and "rtsar:along_track_m" in per_shot[0]
            else start + step * np.arange(pulses)
        )
        check_telemetry(base, cfg, index, along)
        position = (
            np.array([a["rtsar:position_m"] for a in per_shot], np.float64)
            if per_shot and "rtsar:position_m" in per_shot[0]
            else None
        )
        channels = {}
        for c in g.get("rtsar:channels", []):
            _, _, aux = _load(base.with_name(c["file"]))
            channels[c["name"]] = _shots(aux, int(c["samples_per_shot"]), c["file"])
            if len(channels[c["name"]]) != pulses:
                raise ValueError(f"channel {c['name']!r} holds another number of shots")
        scene = g.get("rtsar:scene") or {}
        scene = json.loads(json.dumps(scene))
    except (ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{base}.sigmf-meta: {exc}") from None
    return ForeignRecording(
        base, cfg, scene, pulses, start, shots, index, time_s, channels, position
    )
